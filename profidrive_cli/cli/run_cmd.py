"""pdrive run: a drive at a speed (or a torque) with a live view, its monitors, and the safe stop on
every exit. The loop itself is session/live.py (Live); here: the options, the keys and the rendering.
The shared drive-command plumbing (options, session, confirmation) is in drive_cmds.py; rendering in
render_drive.py; torque checks in run_torque.py."""

from __future__ import annotations

import math
import sys
from typing import TYPE_CHECKING, Any, Callable

import click

from profidrive_cli import UsageError
from profidrive_cli.cli import render_drive as R
from profidrive_cli.cli import run_multi, run_plot, run_torque
from profidrive_cli.cli.common import BusOptions, bus_options
from profidrive_cli.cli.drive_cmds import _confirmer, _session, run_ending
from profidrive_cli.cli.drive_opts import _terminations, drive_options
from profidrive_cli.drives.base import DriveError
from profidrive_cli.outfile import check_output_path
from profidrive_cli.api.station import NOT_REACHED, Live, end_status, fault_name

if TYPE_CHECKING:
    from profidrive_cli.api.station import Sample
    from profidrive_cli.api.station import DriveStation
    from profidrive_cli.api.station import Monitors


@click.command("run")
@click.argument("address", required=False, type=run_multi.STATIONS, metavar="[ADDRESS[,ADDRESS...]]")
@drive_options
@click.option("--hz", type=run_multi.SPEEDS, default=None,
              help="Speed reference in Hz (negative = reverse); with several stations one for all or "
                   "one each (30,20,25).")
@click.option("--percent", type=run_multi.SPEEDS, default=None,
              help="Speed reference in % of the max frequency (one for all or one each).")
@click.option("--reverse", is_flag=True, help="Run in reverse.")
@click.option("--torque", "torque", type=float, default=None, metavar="PERCENT",
              help="Torque control with this reference in % of rated torque (negative or --reverse = "
              "reverse); the speed, if given, is sent as the speed reference. Toyo and Yaskawa only.")
@click.option("--torque-limit", "torque_limit", type=float, default=None, metavar="PERCENT",
              help="Speed run with this torque limit in % of rated torque (Yaskawa only).")
@click.option("--duration", type=float, default=None, metavar="S",
              help="Seconds from the start command to the stop (default: until q / Ctrl-C).")
@click.option("--fmax", type=float, default=None, metavar="HZ",
              help="Max frequency for Hz <-> % when the layout has no parameter channel.")
@click.option("--cycle-hz", type=float, default=None, metavar="RATE",
              help="Data_Exchange rate (default: the fastest the bus allows, at most 100/s; 50/s on sim://).")
@click.option("--yes", is_flag=True, help="Do not ask before running a drive on a real port.")
@click.option("--log", "log_path", default=None, metavar="FILE.csv", help="CSV of every cycle.")
@click.option("--plot", "plot_path", default=None, metavar="FILE.svg|FILE.png",
              help="Plot reference, actual and the monitors over time, written when the run ends "
                   "(needs matplotlib: pip install 'profidrive-cli[plot]').")
@click.option("--reconnect", "reconnect_s", type=float, default=None, metavar="S", is_flag=False,
              flag_value=60.0, help="When the port goes away, wait up to S s (default 60) for it to "
              "come back and resume data exchange; the drive, stopped meanwhile by its watchdog, is "
              "not restarted.")
@click.option("--monitor", "monitor_spec", default=None, metavar="CODE[,CODE...]|default",
              help="Monitor values to read while running (the card's codes, e.g. d002,d013; 'default': "
                   "the profile's set), shown live, in --json and in the --log CSV.")
@click.option("--sync", is_flag=True,
              help="Several stations: Global_Control Sync (and Freeze) so each cycle's outputs take "
                   "effect in the same instant; only where every station's GSD allows it.")
@bus_options
@_terminations
def run_cmd(opts: BusOptions, address: int | tuple[int, ...] | None, profile_name: str | None,
            ppo: int | None, fmt: str | None, watchdog_ms: int, hz: run_multi.Speeds | None,
            percent: run_multi.Speeds | None, reverse: bool, torque: float | None,
            torque_limit: float | None, duration: float | None, fmax: float | None,
            cycle_hz: float | None, yes: bool, log_path: str | None, reconnect_s: float | None,
            monitor_spec: str | None, sync: bool, plot_path: str | None) -> None:
    """Run a drive at a speed (or a torque) and show it live; stops it safely on every exit.
    Several stations (3,4,5) run together on one bus cycle, each stopped on every exit.

    Keys (on a terminal): up/down change the speed (the torque with --torque), r reverses, space
    stops/starts, q quits.
    """
    if isinstance(address, tuple):
        return run_multi.run_several(
            opts, address, hz=hz, percent=percent, reverse=reverse, duration=duration, fmax=fmax,
            cycle_hz=cycle_hz, yes=yes, watchdog_ms=watchdog_ms, sync=sync,
            refused={"--torque": torque, "--torque-limit": torque_limit, "--log": log_path,
                     "--reconnect": reconnect_s, "--monitor": monitor_spec,
                     "--profile": profile_name, "--ppo": ppo, "--format": fmt, "--plot": plot_path})
    run_multi.single_checks(hz, percent, sync)
    assert not isinstance(hz, tuple) and not isinstance(percent, tuple)     # single_checks refused lists
    for name, v in (("--hz", hz), ("--percent", percent), ("--fmax", fmax), ("--duration", duration),
                    ("--cycle-hz", cycle_hz), ("--torque", torque), ("--torque-limit", torque_limit)):
        if v is not None and not math.isfinite(v):
            raise UsageError(f"{name}: not a number")
    if percent is not None and not -100.0 <= percent <= 100.0:
        raise UsageError(f"--percent {percent:g} is outside -100..100")
    if duration is not None and duration <= 0:
        raise UsageError(f"--duration {duration:g} must be above 0 s")
    if cycle_hz is not None and not 0 < cycle_hz <= 10000:
        raise UsageError(f"--cycle-hz {cycle_hz:g} must be in 0..10000 (exclusive of 0)")
    if fmax is not None and fmax <= 0:
        raise UsageError(f"--fmax {fmax:g} must be above 0 Hz")
    interactive = not opts.json and sys.stdin.isatty() and sys.stdout.isatty()
    mode = "json" if opts.json else ("live" if sys.stdout.isatty() else "text")
    torque, percent, what = run_torque.prepare(hz, percent, reverse, torque, torque_limit)
    if log_path is not None:                 # checked before the bus is opened: nothing moves first
        check_output_path(log_path, "--log")
    plotter = run_plot.RunPlot.prepare(plot_path)          # also before the bus: matplotlib, the path
    mons: list[Monitors] = []                # --monitor: checked before anything is asked or written

    def before(sess: DriveStation) -> None:
        from profidrive_cli.api.station import setup_monitors
        mons.extend([setup_monitors(sess, monitor_spec)] if monitor_spec is not None else [])
        _confirmer(opts, yes, what + (mons[0].question_note() if mons else ""))(sess)
    session = _session(opts, address, profile_name, ppo, fmt, watchdog_ms, cycle_hz=cycle_hz,
                       before=run_torque.guard(before, torque, torque_limit), log=log_path)
    view = R.RunView(mode)
    if plotter is not None:
        plotter.attach(view)
    end: dict[str, Any] = {"reason": "", "stop": None, "failed": False, "problem": None}
    lives: list[Live] = []

    def stopping(sample: Sample) -> None:    # every stop, also the one on any exit, stays visible
        view.monitors = None                 # no monitor reads during the stop: show none stale
        if not view.phase.startswith("stopping"):
            view.set_phase("stopping")
        view.update(sample)
    session.on_sample = stopping
    with run_ending(session, view, end, lambda: bool(lives) and lives[0].started,
                    extra=lambda: _run_extra(lives, mons)), run_plot.written_at_the_end(plotter, session):
        with session as s:
            assert s.profile is not None        # the open session has its profile
            s.motion.check_torque(torque, torque_limit)          # the card's reason before anything shows
            if fmax is None:      # the config file's: used where the drive's own is not readable,
                cfg = opts.station_defaults(s.address)     # else only checked against it (warning)
                fmax = cfg.get("fmax") if not s.motion.fmax_readable else cfg.peek("fmax")
            fmax_hz, src = s.motion.fmax(fmax)
            if mons:
                mons[0].map_cyclic()            # before the start; restored after the stop
            if percent is not None:
                pct = percent
            else:
                assert hz is not None           # run_torque.prepare gave a percent where no --hz
                pct = s.motion.percent_for_hz(hz, fmax)
            if reverse:
                pct = -abs(pct)
            view.start({"address": s.address, "ident": f"0x{s.ident:04X}", "profile": s.profile.name,
                        "family": s.profile.family, "title": s.profile.title, "layout": s.layout,
                        "fmax_hz": fmax_hz, "fmax_source": src, "reference_percent": round(pct, 4),
                        "reference_hz": round(pct * fmax_hz / 100.0, 3),
                        "cycle_hz_target": round(s.cycle_hz, 3), "wire_hz": round(s.wire_hz, 3),
                        "watchdog_ms": s.watchdog_ms, "duration_s": duration, "warnings": s.warnings,
                        **run_torque.header(torque, torque_limit),
                        **({"monitors": R.monitor_header(mons[0])} if mons else {})})
            view.monitors = mons[0] if mons else None
            view.fault_name = lambda code: fault_name(s.profile, code)
            if interactive:
                view.hint = "up/down speed · r reverse · space stop/start · q quit"

            def start() -> Sample:
                if torque_limit is not None or live.torque is not None:
                    return s.motion.start_torque(live.torque, torque_limit, live.percent)
                return s.motion.start(live.percent)

            def on_sample(sample: Sample) -> None:
                if mons:
                    mons[0].poll(sample)         # one monitor read per loop, round robin
                    view.monitors = mons[0]      # shown again after a stop (space) and start
                view.update(sample)
            live = Live(s, start, duration=duration, reconnect_s=reconnect_s, judge=torque is None,
                        must_reach=torque is None, percent=pct, torque=torque, on_sample=on_sample,
                        on_phase=view.set_phase)
            lives.append(live)
            live.begin()
            keys = R.KeyReader() if interactive else None
            if keys is not None:
                keys.__enter__()
                live.on_cycle = _keys(keys, 100.0 / fmax_hz if hz is not None else 1.0)  # 1 Hz or 1 %
            try:
                live.loop()
            finally:
                if keys is not None:
                    keys.__exit__(None, None, None)
            end["reason"] = live.reason
            if live.failed:
                end["failed"], end["problem"] = True, live.problem
            live.finish()
            end["reason"], end["problem"] = live.reason, end["problem"] and live.problem  # a trip's code, read at the stop
    if lives and lives[0].exit_code:
        live = lives[0]
        why = end["reason"]
        if end["problem"] == NOT_REACHED:
            act = f"; actual {live.short_of:.2f} Hz at the end" if live.short_of is not None else ""
            why = (f"{NOT_REACHED} ({live.percent * fmax_hz / 100.0:g} Hz) within {duration:g} s{act}")
        raise DriveError(f"station {session.address}: {why}; the drive is stopped")


def _keys(keys: R.KeyReader, step: float) -> Callable[[Live], bool]:
    """The keys of a run on a terminal, once per cycle: up/down change the speed by `step` % (the
    torque by 1 %), r reverses, space stops / starts, q quits (returns True)."""
    def on_cycle(live: Live) -> bool:
        quit_now = False
        for k in keys.keys():
            if k == "q":
                quit_now = True
            elif k in ("up", "down", "r") and live.running and live.torque is not None:
                step_t = 1.0 if k == "up" else -1.0
                live.set_torque(-live.torque if k == "r" else max(-100.0, min(100.0, live.torque + step_t)))
            elif k in ("up", "down") and live.running:
                pct = live.percent
                live.set_reference(max(-100.0, min(100.0, pct + (step if k == "up" else -step) *
                                                   (1 if pct >= 0 else -1))))
            elif k == "r" and live.running:
                live.set_reference(-live.percent)
            elif k == "space":
                if live.running:
                    live.pause("stopping (space)", "stopped ({how}) — space starts, q quits")
                else:
                    live.resume("starting", "running")
        return quit_now
    return on_cycle


def _run_extra(lives: list[Live], mons: list[Monitors]) -> dict[str, Any]:
    d: dict[str, Any] = {"reached_after_s": lives[0].reached_after if lives else None}
    if lives:
        # the fault the run ended with, named as `pdrive faults` names it (the stop reads the code)
        s = lives[0].session
        fs = end_status(s)
        code = fs.fault_code if fs is not None and fs.fault else None
        d["fault_code"], d["fault_name"] = code, fault_name(s.profile, code)
    if mons:
        d["monitors"], d["monitors_dropped"] = mons[0].to_dict(), mons[0].dropped
    return d
