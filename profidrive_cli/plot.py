"""Plots of a run: speed reference and actual over time, and the monitors (current, voltage, ...)
beneath, one panel per unit. matplotlib does the drawing (an optional extra: `pip install
'profidrive-cli[plot]'`); it is imported only here and only when a plot is made, with the Agg backend
(no screen needed). Plain data in, SVG or PNG bytes out: this module imports no layer of pdrive, so
the run command and the checklist's HTML report share it.

    trace = Trace("station 3, fuji-opc-g1-pdp: run 30 Hz")
    trace.add(t, reference=30.0, actual=12.5, monitors={"d002 [A]": 3.4})
    trace.band = (29.5, 30.5, "tolerance 30 ± 0.5 Hz")      # what a checklist step expected
    trace.deadlines.append((15.0, "deadline: within 15 s"))
    svg = render(trace, "svg")

Layout: the legends stand outside the axes, to their right (they never cover a curve); the phase
marks are dotted lines with their names in a band above the axes (never across the data); a
step's tolerance band is a shaded span with its own gid ("tolerance-band"), its deadline a dash-dot
line ("deadline"), both in the legend.
"""

from __future__ import annotations

import io
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from profidrive_cli import UsageError

if TYPE_CHECKING:                                   # pragma: no cover
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

#: file suffix -> matplotlib format
FORMATS = {".svg": "svg", ".png": "png"}

#: at most this many points per series are drawn (evenly thinned, first and last kept): a screen has
#: fewer pixels, and a run of hours at 100 cycles/s must not make a file of megabytes
MAX_POINTS = 4000

#: a trace keeps at most this many samples in memory (older ones are thinned by half when full)
MAX_SAMPLES = 200_000

INSTALL_HINT = "pip install 'profidrive-cli[plot]'"

#: PNG resolution: a 9-inch wide figure is 990 pixels
DPI = 110


def require_matplotlib(what: str = "--plot") -> None:
    """UsageError (exit 2) naming the extra when matplotlib is not installed. Call it before the bus
    is opened: nothing may move for a plot that cannot be drawn."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise UsageError(f"{what} needs matplotlib, which is not installed: {INSTALL_HINT}") from None


def plot_format(path: str | os.PathLike[str], what: str = "--plot") -> str:
    from profidrive_cli.outfile import format_by_suffix
    return format_by_suffix(path, FORMATS, what, ".svg or .png")


@dataclass
class Trace:
    """Samples of one run: time (s), speed reference and actual (in `speed_unit`), monitor values by
    label ("d002 [A]"), and marks (time, text) such as "stop"."""
    title: str = ""
    speed_unit: str = "Hz"
    t: list[float] = field(default_factory=list)
    reference: list[float | None] = field(default_factory=list)
    actual: list[float | None] = field(default_factory=list)
    #: label -> list of values (None: not read yet)
    monitors: dict[str, list[float | None]] = field(default_factory=dict)
    marks: list[tuple[float, str]] = field(default_factory=list)
    band: tuple[float, float, str] | None = None            # (low, high, label): the speed band a step expected
    deadlines: list[tuple[float, str]] = field(default_factory=list)      # (time, label): by when it expected it
    _stride: int = 1
    _skip: int = 0

    def add(self, t: float, reference: float | None = None, actual: float | None = None,
            monitors: dict[str, float | None] | None = None) -> None:
        if self._skip:
            self._skip -= 1
            return
        self._skip = self._stride - 1
        n = len(self.t)
        self.t.append(t)
        self.reference.append(reference)
        self.actual.append(actual)
        for label, v in (monitors or {}).items():
            col = self.monitors.get(label)
            if col is None:
                col = self.monitors[label] = [None] * n
            col.append(v)
        for col in self.monitors.values():
            if len(col) < n + 1:
                col.append(None)
        if len(self.t) >= MAX_SAMPLES:
            self._halve()

    def mark(self, t: float, text: str) -> None:
        self.marks.append((t, text))

    def __len__(self) -> int:
        return len(self.t)

    def _halve(self) -> None:
        self.t = self.t[::2]
        self.reference = self.reference[::2]
        self.actual = self.actual[::2]
        self.monitors = {k: v[::2] for k, v in self.monitors.items()}
        self._stride *= 2


def _thin(n: int) -> list[int]:
    if n <= MAX_POINTS:
        return list(range(n))
    step = (n - 1) / (MAX_POINTS - 1)
    return sorted({int(round(i * step)) for i in range(MAX_POINTS)})


def _unit_of(label: str) -> str:
    if label.endswith("]") and "[" in label:
        return label[label.rindex("[") + 1:-1]
    return ""


def render(trace: Trace, fmt: str = "svg", width_in: float = 9.0) -> bytes:
    """The figure as SVG or PNG bytes: speed on top, one panel per monitor unit below, shared time axis."""
    import matplotlib
    fig = figure(trace, width_in)
    buf = io.BytesIO()
    meta = {"Date": None} if fmt == "svg" else {}          # reproducible SVG: no timestamp
    # SVG text stays text (searchable, small, the browser's font), not outlines
    with matplotlib.rc_context({"svg.fonttype": "none"}):
        fig.savefig(buf, format=fmt, dpi=DPI, metadata=meta)
    return buf.getvalue()


def figure(trace: Trace, width_in: float = 9.0) -> Figure:
    """The matplotlib Figure that render() saves (Agg backend)."""
    require_matplotlib()
    import matplotlib
    matplotlib.use("Agg", force=True)
    from matplotlib.figure import Figure

    idx = _thin(len(trace.t))
    t = [trace.t[i] for i in idx]
    units: dict[str, list[str]] = {}
    for label, col in trace.monitors.items():
        if any(col[i] is not None for i in idx):
            units.setdefault(_unit_of(label), []).append(label)
    panels = 1 + len(units)
    fig = Figure(figsize=(width_in, 3.2 + 2.0 * (panels - 1)), layout="constrained")
    axes = fig.subplots(panels, 1, sharex=True, squeeze=False)[:, 0]

    ax = axes[0]
    if trace.band is not None:
        lo, hi, text = trace.band
        ax.axhspan(lo, hi, color="tab:green", alpha=0.18, linewidth=0, label=text,
                   gid="tolerance-band")
    if any(v is not None for v in trace.reference):
        ax.plot(t, [_nan(trace.reference[i]) for i in idx], label="reference", color="tab:blue",
                linestyle="--", drawstyle="steps-post")
    ax.plot(t, [_nan(trace.actual[i]) for i in idx], label="actual", color="tab:orange")
    for dt, text in trace.deadlines:
        ax.axvline(dt, color="tab:red", linewidth=1.2, linestyle="-.", label=text, gid="deadline")
    ax.set_ylabel(f"speed [{trace.speed_unit}]")
    ax.grid(True, alpha=0.3)
    _legend_outside(ax)
    for mt, _ in trace.marks:
        for a in axes:
            a.axvline(mt, color="grey", linewidth=0.8, linestyle=":")
    rows = _mark_rows(trace.marks, t)
    for (mt, text), row in zip(trace.marks, rows):
        # in a band above the axes, left-aligned on its line: above the data, never across it
        ax.annotate(text, (mt, 1.0), xycoords=("data", "axes fraction"), xytext=(2, 3 + 10 * row),
                    textcoords="offset points", fontsize=8, color="dimgrey", va="bottom", ha="left",
                    annotation_clip=False, gid="phase-label")
    if trace.title:
        ax.set_title(trace.title, pad=8 + 10 * (max(rows) + 1 if rows else 0))

    for ax, (unit, labels) in zip(axes[1:], sorted(units.items())):
        for label in labels:
            col = trace.monitors[label]
            ax.plot(t, [_nan(col[i]) for i in idx], label=label)
        ax.set_ylabel(unit or "value")
        ax.grid(True, alpha=0.3)
        _legend_outside(ax)
    axes[-1].set_xlabel("time [s]")
    return fig


def _legend_outside(ax: Axes) -> None:
    """The legend to the right of the axes (constrained layout makes room): it covers no curve."""
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, fontsize=8,
              frameon=False)


def _mark_rows(marks: list[tuple[float, str]], t: list[float]) -> list[int]:
    """The line of the band each phase name goes on: the next line up when it would start within
    12 % of the time axis of the previous name on that line (names of close phases do not overlap)."""
    if not marks:
        return []
    times = [m[0] for m in marks] + list(t[:1]) + list(t[-1:])
    span = (max(times) - min(times)) or 1.0
    rows: list[int] = []
    last: dict[int, float] = {}
    for mt, _ in marks:
        row = 0
        while row in last and mt - last[row] < 0.12 * span:
            row += 1
        last[row] = mt
        rows.append(row)
    return rows


def _nan(v: float | None) -> float:
    return float("nan") if v is None else v


def write_plot(trace: Trace, path: str | os.PathLike[str], what: str = "--plot") -> Path:
    """Render and write: a temporary file beside `path`, renamed over it when complete."""
    from profidrive_cli.outfile import write_bytes_atomic
    return write_bytes_atomic(path, render(trace, plot_format(path, what)), what=what)


__all__ = ["Trace", "render", "figure", "write_plot", "require_matplotlib", "plot_format", "INSTALL_HINT", "FORMATS"]
