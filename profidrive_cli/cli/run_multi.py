"""pdrive run 3,4,5: the option types that take a list ("3,4,5", "--hz 30,20,25"), the checks of the
options a run of several drives takes, one question for all stations on a real port, and the rendering
(render_multi.py). The run itself is session/multirun.py."""

from __future__ import annotations

import math
import sys
from typing import TYPE_CHECKING

import click

from profidrive_cli import UsageError
from profidrive_cli.cli.common import confirm_real_port
from profidrive_cli.drives.base import DriveError

if TYPE_CHECKING:
    from profidrive_cli.cli.common import BusOptions
    from profidrive_cli.api.station import DriveStation

#: a --hz / --percent value: one number, or one per station
Speeds = float | tuple[float, ...]


class StationsType(click.ParamType["int | tuple[int, ...]", object]):
    """ADDRESS or ADDRESS,ADDRESS,...: an int for one station (as before), a tuple for several."""
    name = "address"

    def convert(self, value: object, param: click.Parameter | None,
                ctx: click.Context | None) -> int | tuple[int, ...]:
        if isinstance(value, (int, tuple)):
            return value
        text = str(value)
        if "," not in text:
            return click.INT.convert(text, param, ctx)  # type: ignore[arg-type]  # int() parses a str; click types INT's input as SupportsInt only
        items = [t.strip() for t in text.split(",")]
        if any(not t for t in items):
            self.fail(f"{text!r}: an empty station in the list", param, ctx)
        out = tuple(click.INT.convert(t, param, ctx) for t in items)  # type: ignore[arg-type]  # (as above)
        for a in out:
            if not 0 <= a <= 125:
                self.fail(f"station address {a} outside 0..125", param, ctx)
        dup = sorted({a for a in out if out.count(a) > 1})
        if dup:
            self.fail(f"station {dup[0]} given twice", param, ctx)
        return out


class SpeedsType(click.ParamType["Speeds", object]):
    """A number, or numbers separated by commas (one per station): a float or a tuple of floats."""
    name = "float"

    def convert(self, value: object, param: click.Parameter | None, ctx: click.Context | None) -> Speeds:
        if isinstance(value, (float, int, tuple)):
            return value
        text = str(value)
        if "," not in text:
            return click.FLOAT.convert(text, param, ctx)  # type: ignore[arg-type]  # float() parses a str; click types FLOAT's input as SupportsFloat only
        return tuple(click.FLOAT.convert(t.strip(), param, ctx)  # type: ignore[arg-type]  # (as above)
                     for t in text.split(","))


STATIONS = StationsType()
SPEEDS = SpeedsType()

#: options of `run` a run of several drives does not take (name, refused when this is true)
_ONE_STATION_ONLY = ("--torque", "--torque-limit", "--log", "--reconnect", "--monitor", "--profile",
                     "--ppo", "--format", "--plot")


def single_checks(hz: Speeds | None, percent: Speeds | None, sync: bool) -> None:
    """`run ADDRESS`: lists and --sync belong to several stations."""
    for name, v in (("--hz", hz), ("--percent", percent)):
        if isinstance(v, tuple):
            raise UsageError(f"{name}: {len(v)} values for one station; give one")
    if sync:
        raise UsageError("--sync: give several stations (run 3,4,5 --sync)")


def _speeds(name: str, v: Speeds, n: int) -> list[float]:
    vals = list(v) if isinstance(v, tuple) else [v] * n
    if len(vals) != n:
        raise UsageError(f"{name}: {len(vals)} values for {n} stations; give one for all or one each")
    for x in vals:
        if not math.isfinite(x):
            raise UsageError(f"{name}: not a number")
    return vals


def run_several(opts: BusOptions, addresses: tuple[int, ...], *, hz: Speeds | None, percent: Speeds | None,
                reverse: bool, duration: float | None, fmax: float | None, cycle_hz: float | None,
                yes: bool, watchdog_ms: int, sync: bool, refused: dict[str, object]) -> None:
    """The options' checks (nothing is sent before they pass), then the run; DriveError (exit 1) when
    a drive did not reach its speed or did not stop."""
    from profidrive_cli.cli.render_drive import KeyReader
    from profidrive_cli.cli.render_multi import MultiView
    from profidrive_cli.api.station import MultiRun
    given = [k for k in _ONE_STATION_ONLY if refused.get(k) not in (None, False)]
    if given:
        raise UsageError(f"{given[0]}: one station only; not with several stations "
                         f"({','.join(map(str, addresses))})")
    if (hz is None) == (percent is None):
        raise UsageError("give the speed: --hz or --percent (one for all, or one per station)")
    n = len(addresses)
    if hz is not None:
        refs = [("hz", v) for v in _speeds("--hz", hz, n)]
    else:
        assert percent is not None          # one of --hz / --percent (checked above)
        refs = [("percent", v) for v in _speeds("--percent", percent, n)]
        for _, v in refs:
            if not -100.0 <= v <= 100.0:
                raise UsageError(f"--percent {v:g} is outside -100..100")
    for name, x in (("--duration", duration), ("--cycle-hz", cycle_hz), ("--fmax", fmax)):
        if x is not None and (not math.isfinite(x) or x <= 0):
            raise UsageError(f"{name} must be a number above 0")
    if cycle_hz is not None and cycle_hz > 10000:
        raise UsageError(f"--cycle-hz {cycle_hz:g} must be in 0..10000 (exclusive of 0)")
    for a in addresses:
        opts.check_station(a)               # 0..125 and not the master's own address
    interactive = not opts.json and sys.stdin.isatty() and sys.stdout.isatty()
    view = MultiView("json" if opts.json else ("live" if sys.stdout.isatty() else "text"))
    keys: list[KeyReader] = []

    def confirm(sessions: list[DriveStation]) -> None:
        names = []
        for s in sessions:
            assert s.profile is not None    # identified before the question
            names.append(f"{s.address} ({s.profile.name})")
        what = ", ".join(names)
        speeds = ", ".join(f"{v:g}{' Hz' if k == 'hz' else ' %'}" for k, v in refs)
        confirm_real_port(opts.port, yes, f"run {len(sessions)} drives — stations {what} at {speeds}"
                                          f"{' (reverse)' if reverse else ''} on {opts.port}")

    def should_quit() -> bool:
        if not keys:
            return False
        return "q" in keys[0].keys()

    def message(text: str) -> None:
        from rich.markup import escape
        from profidrive_cli.cli.common import err
        err.print(escape(text))

    # the stations through the front door: the run takes its sessions from the bus (Bus.session)
    # and closes it at its end; the close here only covers a way out before the run (a no-op after)
    bus = opts.open_bus()
    try:
        run = MultiRun(bus, list(addresses), refs, reverse=reverse, fmax=fmax, duration=duration,
                       watchdog_ms=watchdog_ms, cycle_hz=cycle_hz, sync=sync, confirm=confirm,
                       should_quit=should_quit, on_start=view.start, on_phase=view.set_phase,
                       on_sample=view.update, on_end=view.finish, on_message=message)
        if interactive:
            view.hint = "q stops every drive and quits"
            k = KeyReader()
            k.__enter__()
            keys.append(k)
        try:
            code = run.run()
        finally:
            if keys:
                keys[0].__exit__(None, None, None)
    finally:
        bus.close()
    if code:
        bad = [f"station {r.address}: {r.problem}" for r in run.runs
               if r.problem and f"station {r.address}" not in run.reason]
        raise DriveError(f"{run.reason or 'run of several drives'}" + (f" ({'; '.join(bad)})" if bad else "")
                         + ("; every drive is stopped" if run.end_dict()["stopped"] else
                            "; NOT every drive is confirmed stopped"))
