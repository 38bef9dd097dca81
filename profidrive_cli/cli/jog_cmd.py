"""pdrive jog — the card's own jog function: held key on a terminal (deadman), --duration for scripts.

All protocol and safety logic lives in session/ (DriveStation.jog / release_jog / stop, the safe stop
on every exit in DriveStation.close, the loop in live.py); this module parses the command line, refuses
a station whose card has no jog before anything is sent, asks before a real port, reads the keys and
renders (render_drive.py).
"""

from __future__ import annotations

import math
import sys
import time
from typing import TYPE_CHECKING, Any, Callable

import click

from profidrive_cli import UsageError
from profidrive_cli.cli import render_drive as R
from profidrive_cli.cli.common import BusOptions, bus_options, err
from profidrive_cli.cli.drive_cmds import _confirmer, _session, run_ending
from profidrive_cli.cli.drive_opts import _terminations, drive_options
from profidrive_cli.drives.base import DriveError
from profidrive_cli.api.station import Live

if TYPE_CHECKING:
    from profidrive_cli.api.station import Sample
    from profidrive_cli.api.station import DriveStation

#: On a terminal the jog runs while a key is held: the terminal repeats a held key (after its
#: auto-repeat delay, typically 250-600 ms); no key for this long counts as released and stops.
DEADMAN_S = 0.75


def _refuse_or_confirm(opts: BusOptions, yes: bool, what: str) -> Callable[[DriveStation], None]:
    """before_connect: a card without jog is refused (exit 2) before the confirmation and before any
    telegram to the station; then the real-port question."""
    confirm = _confirmer(opts, yes, what)

    def before(session: DriveStation) -> None:
        from profidrive_cli.drives.jog import jog_refusal
        assert session.profile is not None      # identify() chose it before the before-connect call
        why = jog_refusal(session.profile, session.layout)
        if why is not None:
            raise UsageError(why)
        confirm(session)
    return before


@click.command("jog")
@click.argument("address", required=False, type=int)
@click.option("--reverse", is_flag=True, help="Jog in reverse.")
@click.option("--duration", type=float, default=None, metavar="S",
              help="Jog for S seconds, then stop (needed when not on a terminal).")
@click.option("--yes", is_flag=True, help="Do not ask before jogging a drive on a real port.")
@drive_options
@bus_options
@_terminations
def jog_cmd(opts: BusOptions, address: int | None, reverse: bool, duration: float | None, yes: bool,
            profile_name: str | None, ppo: int | None, fmt: str | None, watchdog_ms: int) -> None:
    """Jog a drive with the card's own jog function; a safe stop on every exit.

    On a terminal: hold space to jog (releasing the key stops it, deadman), q quits. With --duration S
    (scripts, --json) it jogs S seconds and stops. Cards without jog over the bus are refused (exit 2).
    """
    if duration is not None and (not math.isfinite(duration) or duration <= 0):
        raise UsageError(f"--duration {duration:g} must be a number above 0 s")
    interactive = duration is None and not opts.json and sys.stdin.isatty() and sys.stdout.isatty()
    if duration is None and not interactive:
        raise UsageError("jog without a terminal to hold a key on: give --duration S")
    mode = "json" if opts.json else ("live" if sys.stdout.isatty() else "text")
    direction = "reverse" if reverse else "forward"
    # cycle_hz=None: paced like `run` (session/cycle.default_cycle_hz), not as fast as the CPU goes
    session = _session(opts, address, profile_name, ppo, fmt, watchdog_ms, cycle_hz=None,
                       before=_refuse_or_confirm(opts, yes, f"jog the drive {direction}"))
    view = R.RunView(mode)
    end: dict[str, Any] = {"reason": "", "stop": None}
    lives: list[Live] = []

    def stopping(sample: Sample) -> None:
        if not view.phase.startswith("stopping"):
            view.set_phase("stopping")
        view.update(sample)
    session.on_sample = stopping
    with run_ending(session, view, end, lambda: (bool(lives) and lives[0].started) or session.motion.may_run):
        with session as s:
            assert s.profile is not None        # the open session has its profile
            fmax_hz, src = s.motion.fmax()
            speed = s.motion.jog_speed()
            view.start({"address": s.address, "ident": f"0x{s.ident:04X}", "profile": s.profile.name,
                        "family": s.profile.family, "title": s.profile.title, "layout": s.layout,
                        "fmax_hz": fmax_hz, "fmax_source": src, "direction": direction,
                        "jog_speed": None if speed is None else
                        {"code": speed.code, "value": speed.value, "unit": speed.unit},
                        "cycle_hz_target": round(s.cycle_hz, 3), "wire_hz": round(s.wire_hz, 3),
                        "watchdog_ms": s.watchdog_ms, "duration_s": duration, "warnings": s.warnings})
            if speed is not None and mode != "json":
                err.print(f"jog speed: {speed.code} = {R.value_text(speed.value, speed.unit)}")
            live = Live(s, lambda: s.motion.jog(reverse), release=s.motion.release_jog, duration=duration,
                        on_sample=view.update, on_phase=view.set_phase)
            lives.append(live)
            if interactive:
                _held_key(live, view, reverse)
            else:
                live.begin("jog starting", "jogging")
                live.loop()
                end["peak_hz"] = live.peak_hz
            end["reason"] = live.reason
            live.finish()
    if lives and lives[0].exit_code:
        raise DriveError(f"station {session.address}: {end['reason']}; the drive is stopped")


def _held_key(live: Live, view: R.RunView, reverse: bool) -> None:
    """Hold space to jog, release stops (DEADMAN_S without a repeated key), q quits."""
    view.hint = f"hold space to jog ({'reverse' if reverse else 'forward'}) · release stops · q quits"
    view.set_phase("ready: hold space to jog")
    keys = R.KeyReader()
    keys.__enter__()
    last_key = [0.0]

    def on_cycle(live: Live) -> bool:
        pressed = keys.keys()
        if "q" in pressed:
            return True
        now = time.monotonic()
        if "space" in pressed:
            last_key[0] = now
            if not live.running:
                live.resume("jog starting", "jogging (release the key to stop)")
                last_key[0] = time.monotonic()
        elif live.running and now - last_key[0] > DEADMAN_S:
            live.pause("stopping (key released)",
                       "stopped ({how}) — hold space to jog again, q quits")
        return False
    live.on_cycle = on_cycle
    try:
        live.loop()
    finally:
        keys.__exit__(None, None, None)
