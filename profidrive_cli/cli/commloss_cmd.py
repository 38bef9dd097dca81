"""pdrive commloss-test: the comm-loss acceptance test (session/commloss.py does the work; this
module parses the options, asks before a real port and renders: text, or --json as JSON Lines)."""

from __future__ import annotations

import math
import sys
from typing import TYPE_CHECKING, Any

import click
from rich.markup import escape

from profidrive_cli import UsageError
from profidrive_cli.cli.common import BusOptions, bus_options, emit_json, out
from profidrive_cli.cli.drive_cmds import _confirmer, _session
from profidrive_cli.cli.drive_opts import _terminations, drive_options

if TYPE_CHECKING:
    from profidrive_cli.api.station import CommLossResult


@click.command("commloss-test")
@click.argument("address", required=False, type=int)
@click.option("--hz", type=float, default=20.0, show_default=True, help="Speed to run at before the break.")
@click.option("--mode", type=click.Choice(["silence", "clear"]), default="silence", show_default=True,
              help="silence: the master stops talking to the station; clear: Global_Control "
                   "Clear_Data, then all-zero outputs.")
@click.option("--timeout", type=float, default=None, metavar="S",
              help="How long past the expected bound to keep watching for a late reaction "
                   "(default: half the bound, at least 2 s).")
@click.option("--tolerance", type=float, default=None, metavar="S",
              help="Tolerance added to the limit (default 0.25 s + half the watchdog).")
@click.option("--start-timeout", type=float, default=None, metavar="S",
              help="How long to wait for the drive to reach --hz (default 2 x its acceleration time "
                   "for that speed + 5 s; 120 s where that cannot be read).")
@click.option("--ack", is_flag=True, help="Acknowledge the comm-loss fault afterwards.")
@click.option("--cycle-hz", type=float, default=None, metavar="RATE",
              help="Data_Exchange rate (default: the fastest the bus allows).")
@click.option("--yes", is_flag=True, help="Do not ask before running a drive on a real port.")
@drive_options
@bus_options
@_terminations
def commloss_cmd(opts: BusOptions, address: int | None, hz: float, mode: str, timeout: float | None,
                 tolerance: float | None, start_timeout: float | None, ack: bool, cycle_hz: float | None,
                 yes: bool, profile_name: str | None, ppo: int | None, fmt: str | None,
                 watchdog_ms: int) -> None:
    """Comm-loss acceptance test: run at --hz, break the link, measure the drive's reaction.

    The limit is watchdog + configured delay + stop time + tolerance (the drive's configured
    reaction is read from the drive). PASS when a look that came back by the limit saw the drive
    stopped or tripped; FAIL when a look at or after the limit saw it running, or when it is set to
    keep running without a master; INCONCLUSIVE when the figures cannot decide (the verdict says
    why and what to change). Exit 1 unless PASS. The drive is left stopped; its fault is
    acknowledged only with --ack.
    """
    for name, v in (("--hz", hz), ("--timeout", timeout), ("--tolerance", tolerance),
                    ("--start-timeout", start_timeout), ("--cycle-hz", cycle_hz)):
        if v is not None and not math.isfinite(v):
            raise UsageError(f"{name} must be a number")
    from profidrive_cli.api.station import check_commloss_args as check_args, run_commloss
    check_args(hz, mode, timeout, tolerance, start_timeout)     # before the bus is opened
    session = _session(opts, address, profile_name, ppo, fmt, watchdog_ms, cycle_hz=cycle_hz,
                       before=_confirmer(opts, yes, f"comm-loss test: run at {hz:g} Hz, then break "
                                                    f"the link ({mode})"))
    events = emit_json if opts.json else _text_event
    with session as s:
        assert s.profile is not None            # the open session has its profile
        if not opts.json:
            out.print(escape(f"station {s.address} ({s.profile.name}): comm-loss test, mode {mode}, "
                             f"{hz:g} Hz, watchdog {s.watchdog_ms:g} ms"))
        else:
            assert s.ident is not None          # the open session read the station's ident
            emit_json({"event": "start", "station": s.address, "ident": s.ident,
                       "ident_hex": f"0x{s.ident:04X}", "profile": s.profile.name, "mode": mode,
                       "reference_hz": hz, "watchdog_s": s.watchdog_ms / 1000.0})
        res = run_commloss(s, hz, mode, timeout=timeout, ack=ack, on_event=events,
                           tolerance=tolerance, start_timeout=start_timeout)
    if not opts.json:
        _text_result(res)
    if not res.passed:
        sys.exit(1)


def _text_event(ev: dict[str, Any]) -> None:
    kind = ev.get("event")
    if kind == "reaction":
        out.print(escape(f"  configured reaction: {ev['words']}"))
        for w in ev.get("warnings") or []:
            out.print(escape(f"  note: {w}"))
        lim = ev["limit"]
        out.print(escape(f"  limit: {ev['expected_s']:.3f} s = watchdog {lim['watchdog_s']:.3f} + delay "
                         f"{lim['delay_s']:.3f} + stop {lim['stop_s']:.3f} + tolerance "
                         f"{lim['tolerance_s']:.3f}"))
    elif kind == "at_speed":
        out.print(f"  at speed: {ev['actual_hz']} Hz")
    elif kind == "silence":
        out.print(f"  master silent for {ev['hold_s']:.2f} s")
    elif kind == "clear":
        out.print("  Global_Control Clear_Data sent; outputs zero")
    elif kind == "back":
        out.print(f"  master back after {ev['after_s']:.2f} s"
                  + ("" if ev["watchdog_expired"] else " (the station had not left data exchange)"))


def _f(v: float | None) -> str:
    return "-" if v is None else f"{v:.3f} s"


def _measured(res: CommLossResult) -> str:
    if not res.reacted:
        return "no stop or trip seen (still running)"
    return (f"{res.measured_s:.3f} s at the latest (the first look that saw it came back then; "
            f"not before {res.not_before_s:.3f} s)")


def _text_result(res: CommLossResult) -> None:
    rows = [("watchdog", f"{res.watchdog_ms:g} ms"),
            ("configured reaction", res.reaction.words),
            ("limit", res.limit.words() if res.limit else _f(res.expected_s)),
            ("last seen running", "-" if res.last_running_s is None else
             f"{res.last_running_s:.3f} s (the look went out then)"),
            ("measured", _measured(res)),
            ("final state", (res.final_state or "-") + (f" ({res.fault_code})" if res.fault_code else "")),
            ("acknowledged", "yes" if res.acknowledged else "no")]
    if res.stop and res.stop.get("needed"):
        rows.append(("stopped by pdrive", f"{res.stop['how']} stop, {res.stop['seconds']:.2f} s"))
    for k, v in rows:
        out.print(escape(f"  {k:<20} {v}"))
    out.print(escape(res.verdict))
