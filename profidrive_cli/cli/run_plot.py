"""run --plot FILE.svg|png: every sample the run's view shows (also those of the stop) goes into a
plot.Trace, the reference only while the drive is asked to turn (none from the stop's start or a trip); the file is written when the run ends, whatever way it ends (the plot of a trip or a
Ctrl-C is the one wanted), through a temporary file renamed into place. Checked before the bus is
opened: matplotlib installed, the suffix, the path writable — nothing moves for a plot that cannot
be drawn."""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterator

from profidrive_cli.cli.common import err
from profidrive_cli.outfile import OutputWriteError, check_output_path

if TYPE_CHECKING:
    from profidrive_cli.cli.render_drive import RunView
    from profidrive_cli.api.station import Sample
    from profidrive_cli.api.station import DriveStation
    from profidrive_cli.api.station import Monitors


class RunPlot:
    def __init__(self, path: str) -> None:
        from profidrive_cli.plot import Trace
        self.path = path
        self.trace = Trace()
        self._phase = ""

    @classmethod
    def prepare(cls, path: str | None) -> "RunPlot | None":
        if path is None:
            return None
        from profidrive_cli.plot import plot_format, require_matplotlib
        plot_format(path)
        require_matplotlib()
        check_output_path(path, "--plot")
        return cls(path)

    def attach(self, view: RunView) -> None:
        """Record every sample the view is given, and mark its phases (starting, stopping, ...)."""
        update, set_phase = view.update, view.set_phase

        def recording_update(sample: Sample, *a: Any, **kw: Any) -> None:
            self.add(sample, view.monitors)
            return update(sample, *a, **kw)

        def recording_phase(phase: str, sample: Sample | None = None, *a: Any, **kw: Any) -> None:
            word = phase.split(" ")[0]
            if sample is not None and word != self._phase and word in ("running", "stopping", "stopped"):
                self.trace.mark(sample.t, word)
            self._phase = word
            if sample is not None:
                self.add(sample, view.monitors)
            return set_phase(phase, sample, *a, **kw)

        view.update = recording_update  # type: ignore[method-assign]  # the recorder wraps this view's own method
        view.set_phase = recording_phase  # type: ignore[method-assign]  # (as above)
        self.view = view

    def add(self, sample: Sample, mons: Monitors | None) -> None:
        if not self.trace.title and getattr(self.view, "header", None):
            h = self.view.header
            self.trace.title = (f"station {h.get('address')} ({h.get('profile')}): reference "
                                f"{h.get('reference_hz')} Hz")
        values: dict[str, float | None] = {}
        if mons is not None:
            for c in mons.codes:
                v = mons.values[c]
                if isinstance(v.value, (int, float)):
                    label = f"{c} {v.name}" if v.name else c
                    values[f"{label} [{v.unit}]" if v.unit else label] = v.value
        self.trace.add(sample.t, None if self.stopping(sample) else sample.reference_hz,
                       sample.actual_hz, values)

    def stopping(self, sample: Sample) -> bool:
        """The drive is no longer asked to turn: the stop has begun (phase stopping / stopped, also
        a pause by space) or it tripped. Its reference word may still hold the speed; the plot
        draws no reference from here, so the figure shows what the drive was asked."""
        return self._phase in ("stopping", "stopped") or bool(getattr(sample.status, "fault", False))

    def write(self) -> Path:
        from profidrive_cli.plot import write_plot
        return write_plot(self.trace, self.path)


@contextlib.contextmanager
def written_at_the_end(plotter: RunPlot | None, session: DriveStation) -> Iterator[None]:
    """Write the plot after the run (and its stop), on every way out. A plot that cannot be written
    after a good run is exit 1 (like --log); after a failed run it is a warning, the run's own
    error stays the one reported."""
    if plotter is None:
        yield
        return
    failed = True
    try:
        yield
        failed = False
    finally:
        if len(plotter.trace):
            try:
                p = plotter.write()
                err.print(f"plot: {p}", markup=False)
            except OutputWriteError as e:
                if not failed:
                    raise
                err.print(f"warning: {e}", markup=False)


__all__ = ["RunPlot", "written_at_the_end"]
