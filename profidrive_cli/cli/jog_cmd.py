"""pdrive jog — the card's own jog function: held key on a terminal (deadman), --duration for scripts.

All protocol and safety logic lives in session/ (DriveSession.jog / release_jog / stop, and the safe
stop on every exit in DriveSession.close); this module parses the command line, refuses a station
whose card has no jog before anything is sent, asks before a real port, and renders (render_drive.py).
"""

from __future__ import annotations

import math
import sys
import time

import click

from profidrive_cli import UsageError
from profidrive_cli.cli import render_drive as R
from profidrive_cli.cli.common import bus_options
from profidrive_cli.cli.drive_cmds import (_confirmer, _session, _terminations, drive_options,
                                          run_ending)
from profidrive_cli.drives.base import DriveError

#: On a terminal the jog runs while a key is held: the terminal repeats a held key (after its
#: auto-repeat delay, typically 250-600 ms); no key for this long counts as released and stops.
DEADMAN_S = 0.75


def _refuse_or_confirm(opts, yes: bool, what: str):
    """before_connect: a card without jog is refused (exit 2) before the confirmation and before any
    telegram to the station; then the real-port question."""
    confirm = _confirmer(opts, yes, what)

    def before(session):
        from profidrive_cli.drives.jog import jog_refusal
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
def jog_cmd(opts, address, reverse, duration, yes, profile_name, ppo, fmt, watchdog_ms):
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
    end: dict = {"reason": "", "stop": None}
    jogged = False
    exit_code = 0

    def stopping(sample):
        if not view.phase.startswith("stopping"):
            view.set_phase("stopping")
        view.update(sample)
    session.on_sample = stopping
    with run_ending(session, view, end, lambda: jogged or session.may_run):
        with session as s:
            fmax_hz, src = s.fmax()
            speed = s.jog_speed()
            view.start({"address": s.address, "ident": f"0x{s.ident:04X}", "profile": s.profile.name,
                        "family": s.profile.family, "title": s.profile.title, "layout": s.layout,
                        "fmax_hz": fmax_hz, "fmax_source": src, "direction": direction,
                        "jog_speed": None if speed is None else
                        {"code": speed.code, "value": speed.value, "unit": speed.unit},
                        "cycle_hz_target": round(s.cycle_hz, 3), "wire_hz": round(s.wire_hz, 3),
                        "watchdog_ms": s.watchdog_ms, "duration_s": duration, "warnings": s.warnings})
            if speed is not None and mode != "json":
                R.err.print(f"jog speed: {speed.code} = {R.value_text(speed.value, speed.unit)}")
            if interactive:
                end["reason"], exit_code = _held_key(s, view, reverse)
            else:
                view.set_phase("jog starting")
                sample = s.jog(reverse)
                jogged = True
                t_start = sample.t
                view.set_phase("jogging", sample)
                peak = None
                while True:
                    sample = s.poll()
                    view.update(sample)
                    if sample.actual_hz is not None and (peak is None or abs(sample.actual_hz) > abs(peak)):
                        peak = sample.actual_hz
                    if sample.status.fault:
                        end["reason"] = "the drive tripped" + (f" ({sample.status.fault_code})"
                                                               if sample.status.fault_code else "")
                        exit_code = 1
                        break
                    if sample.t - t_start >= duration:
                        end["reason"] = f"duration {duration:g} s reached"
                        break
                end["peak_hz"] = peak
            if s.may_run:
                view.set_phase("stopping", s.release_jog())
                s.stop()
                if s.stop_report.how in ("normal", "coast"):
                    view.set_phase("stopped", s._sample(s.final_status) if s.final_status else None)
    if exit_code:
        raise DriveError(f"station {session.address}: {end['reason']}; the drive is stopped")


def _held_key(s, view, reverse: bool) -> tuple[str, int]:
    """Hold space to jog, release stops (DEADMAN_S without a repeated key), q quits."""
    view.hint = f"hold space to jog ({'reverse' if reverse else 'forward'}) · release stops · q quits"
    view.set_phase("ready: hold space to jog")
    keys = R.KeyReader()
    keys.__enter__()
    jogging = False
    last_key = 0.0
    try:
        while True:
            sample = s.poll()
            view.update(sample)
            if sample.status.fault:
                return ("the drive tripped" + (f" ({sample.status.fault_code})"
                                               if sample.status.fault_code else "")), 1
            pressed = keys.keys()
            if "q" in pressed:
                return "q pressed", 0
            now = time.monotonic()
            if "space" in pressed:
                last_key = now
                if not jogging:
                    view.set_phase("jog starting")
                    s.jog(reverse)
                    jogging = True
                    view.set_phase("jogging (release the key to stop)")
                    last_key = time.monotonic()
            elif jogging and now - last_key > DEADMAN_S:
                view.set_phase("stopping (key released)", s.release_jog())
                rep = s.stop()
                jogging = False
                view.set_phase(f"stopped ({rep.how}) — hold space to jog again, q quits")
    finally:
        keys.__exit__(None, None, None)
