"""What a drive did during a checklist step, cycle by cycle, for the HTML report's plots.

record(drive) shadows the Drive's cycle() for the length of a step (every status a step sees comes
through it: start, status, the run and stop loops) and keeps (time, actual Hz, actual %, reference
%) per cycle, bounded; the reference only while the drive is asked to turn (its stop() and start()
are shadowed too: from a stop, or in fault, the row has none, so the plot's reference ends there). to_plot_trace() turns it into a plot.Trace in Hz where the drive reports Hz
(the max frequency derived from its own Hz/% pair, no parameter read), else in %. With the step's
`expected` (StepResult.expected) the plot also shows what the step asked for: the tolerance band
around the speed it was to reach and the deadline (`within`), so a failed step's picture shows why.
"""

from __future__ import annotations

import contextlib
from typing import TYPE_CHECKING, Any, Callable, Iterator

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.drives.base import Drive, DriveStatus
    from profidrive_cli.plot import Trace

#: one cycle: (t, speed_hz, speed_percent, reference_percent)
Row = tuple[float, "float | None", "float | None", "float | None"]

#: step types whose trace is plotted (the ones that move the drive)
PLOTTED = ("run", "stop", "jog")

#: at most this many cycles are kept per step (a later cycle replaces every other one: halved)
MAX_CYCLES = 50_000


class StepTrace:
    def __init__(self) -> None:
        self.rows: list[Row] = []       # (t, speed_hz, speed_percent, reference_percent)
        self._stride = 1
        self._n = 0

    def add(self, t: float, st: DriveStatus, stopping: bool = False) -> None:
        """One cycle's status; stopping: the drive is being stopped (no reference is kept from the
        stop's start, nor while it is in fault: the plot shows what the drive was asked)."""
        self._n += 1
        if (self._n - 1) % self._stride:
            return
        ref = None if stopping or getattr(st, "fault", False) else st.reference_percent
        self.rows.append((t, st.speed_hz, st.speed_percent, ref))
        if len(self.rows) >= MAX_CYCLES:
            self.rows = self.rows[::2]
            self._stride *= 2

    def __len__(self) -> int:
        return len(self.rows)


@contextlib.contextmanager
def record(drive: Drive) -> Iterator[StepTrace]:
    """Yield a StepTrace filled with every cycle `drive` makes inside the block."""
    tr = StepTrace()
    inner = drive.cycle
    ch = drive.channel
    t0 = ch.now()
    stopping = [False]                 # a stop was asked (until the next start)

    def cycle() -> DriveStatus:
        st = inner()
        tr.add(ch.now() - t0, st, stopping[0])
        return st

    def marking(own: Callable[..., DriveStatus], asked_to_stop: bool) -> Callable[..., DriveStatus]:
        def call(*a: Any, **kw: Any) -> DriveStatus:       # stop(...) / start(...) as the Drive takes them
            stopping[0] = asked_to_stop
            return own(*a, **kw)
        return call

    # every Drive has start() and stop() (drives/base.py): a stop asked ends the reference's trace
    shadowed: dict[str, tuple[Callable[..., DriveStatus], Callable[..., DriveStatus]]] = {
        "cycle": (inner, cycle), "stop": (drive.stop, marking(drive.stop, True)),
        "start": (drive.start, marking(drive.start, False))}
    for name, (_, mine) in shadowed.items():
        setattr(drive, name, mine)
    try:
        yield tr
    finally:
        for name, (own, _) in shadowed.items():
            try:
                delattr(drive, name)       # the class's own method again
            except AttributeError:
                setattr(drive, name, own)


def to_plot_trace(tr: StepTrace, title: str, expected: dict[str, Any] | None = None) -> Trace:
    from profidrive_cli.plot import Trace
    rows = tr.rows
    fmax = None
    for _, hz, pct, _ in rows:
        if hz is not None and pct is not None and abs(pct) > 1.0:
            fmax = hz * 100.0 / pct
            break
    hz_ok = fmax is not None and all(r[1] is not None or r[2] is None for r in rows)
    out = Trace(title=title, speed_unit="Hz" if hz_ok else "%")
    for t, hz, pct, ref in rows:
        if hz_ok and fmax is not None:                      # (hz_ok: fmax known)
            out.add(t, None if ref is None else ref * fmax / 100.0, hz if hz is not None else None)
        else:
            out.add(t, ref, pct)
    if expected:
        _expectations(out, expected, fmax)
    return out


def _expectations(out: Trace, expected: dict[str, Any], fmax: float | None) -> None:
    """The band and the deadline of a run step ({speed, unit, tolerance, within_s}), the band of a
    jog ({speed_hz, tolerance}), the deadline of a stop ({stopped, within_s}), in the plot's unit.
    The deadline is counted from the start of the step's trace (the step's own clock starts a cycle
    or two later: a few tens of ms)."""
    speed, unit = expected.get("speed"), expected.get("unit")
    if speed is None and expected.get("speed_hz") is not None:
        speed, unit = expected["speed_hz"], "Hz"
    tol = expected.get("tolerance")
    if speed is not None and tol is not None:
        k: float | None = 1.0
        if unit != out.speed_unit:                         # Hz <-> % by the drive's own pair
            k = (None if fmax is None else
                 fmax / 100.0 if out.speed_unit == "Hz" else 100.0 / fmax)
        if k is not None:
            u = out.speed_unit
            c, w = float(speed) * k, float(tol) * k
            out.band = (c - w, c + w, f"tolerance {c:g} ± {w:.3g} {u}")
    within = expected.get("within_s")
    if within is not None:
        out.deadlines.append((float(within), f"deadline: within {float(within):g} s"))


__all__ = ["record", "to_plot_trace", "StepTrace", "PLOTTED"]
