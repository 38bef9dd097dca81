"""run --plot (cli/run_plot.py, plot.py) and the checklist's HTML report (checklist/report_html.py,
checklist/steptrace.py).

Expected values: what the run asked for (30 Hz on a drive whose max frequency is 60 Hz by the
profile's default F03), the figure geometry from plot.py's documented size (9 in at 110 dpi), the
number of run/stop steps in the checklist text, and hand arithmetic for the trace conversions."""

from __future__ import annotations

import json
import struct
import sys
import xml.etree.ElementTree as ET
from html.parser import HTMLParser
from types import SimpleNamespace

import pytest
from click.testing import CliRunner

from profidrive_cli import UsageError
from profidrive_cli.cli.main import cli

pytest.importorskip("matplotlib")       # the test extra installs it; CI always has it

SVG_NS = "{http://www.w3.org/2000/svg}"


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args], env={"PDRIVE_PORT": ""})


def svg_texts(data: bytes) -> set[str]:
    root = ET.fromstring(data)
    return {"".join(t.itertext()).strip() for t in root.iter(SVG_NS + "text")}


# ---------------------------------------------------------------------------------------------
# plot.py on its own
# ---------------------------------------------------------------------------------------------


def test_a_trace_renders_labelled_axes_and_one_panel_per_monitor_unit():
    from profidrive_cli.plot import Trace, render
    tr = Trace(title="station 3: run 30 Hz")
    for i in range(50):
        tr.add(i * 0.1, 30.0, min(30.0, i * 1.0), {"M11 current [A]": 2.0 + i * 0.01, "M12 voltage [V]": 100 + i})
    texts = svg_texts(render(tr, "svg"))
    assert {"speed [Hz]", "time [s]", "reference", "actual", "station 3: run 30 Hz"} <= texts
    assert {"M11 current [A]", "M12 voltage [V]", "A", "V"} <= texts      # two monitor panels, by unit


def _drawn(tr):
    """The figure render() saves, laid out (Agg), with its axes' boxes in display units."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from profidrive_cli.plot import figure
    fig = figure(tr)
    FigureCanvasAgg(fig)
    fig.draw_without_rendering()
    return fig


def _ramp_with_phases():
    from profidrive_cli.plot import Trace
    tr = Trace(title="station 3: run 30 Hz")
    for i in range(60):                       # the ramp ends at the reference, where a legend
        t = i * 0.1                           # in a corner of the axes would lie on the curves
        tr.add(t, 30.0, min(30.0, 10.0 * t) if t < 5 else 30.0 - 20.0 * (t - 5),
               {"M11 current [A]": 2.0 + i * 0.01})
    tr.mark(0.0, "running")
    tr.mark(5.0, "stopping")
    tr.mark(5.5, "stopped")                   # close to the previous one: its own line of the band
    return tr


def test_legends_stand_outside_the_axes():
    fig = _drawn(_ramp_with_phases())
    for ax in fig.axes:
        box, leg = ax.get_window_extent(), ax.get_legend().get_window_extent()
        assert leg.x0 >= box.x1, (leg, box)          # to the right of the plotting area


def test_phase_names_stand_in_a_band_above_the_axes_not_across_the_data():
    fig = _drawn(_ramp_with_phases())
    ax = fig.axes[0]
    box = ax.get_window_extent()
    names = [a for a in ax.texts if a.get_text() in ("running", "stopping", "stopped")]
    assert sorted(a.get_text() for a in names) == ["running", "stopped", "stopping"]
    extents = [a.get_window_extent() for a in names]
    assert all(e.y0 >= box.y1 for e in extents), (extents, box)       # above the data
    assert ax.title.get_window_extent().y0 >= max(e.y1 for e in extents)   # under the title
    for i, a in enumerate(extents):                                   # and not on each other
        assert not any(a.overlaps(b) for b in extents[i + 1:])


def test_a_band_and_a_deadline_are_drawn_and_named():
    from profidrive_cli.plot import render
    tr = _ramp_with_phases()
    tr.band = (29.5, 30.5, "tolerance 30 ± 0.5 Hz")
    tr.deadlines.append((2.0, "deadline: within 2 s"))
    svg = render(tr, "svg")
    root = ET.fromstring(svg)
    ids = {g.get("id") for g in root.iter(SVG_NS + "g")}
    assert {"tolerance-band", "deadline"} <= ids
    assert {"tolerance 30 ± 0.5 Hz", "deadline: within 2 s"} <= svg_texts(svg)   # in the legend


def test_png_has_the_documented_width():
    from profidrive_cli.plot import Trace, render
    tr = Trace()
    tr.add(0.0, 10.0, 0.0)
    tr.add(1.0, 10.0, 10.0)
    png = render(tr, "png")
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", png[16:24])          # IHDR
    assert width == 990                                       # 9 in at 110 dpi


def test_thinning_keeps_the_first_and_last_point_and_the_limit():
    from profidrive_cli.plot import MAX_POINTS, _thin
    idx = _thin(100_001)
    assert idx[0] == 0 and idx[-1] == 100_000 and len(idx) <= MAX_POINTS
    assert _thin(10) == list(range(10))


def test_a_long_trace_is_halved_not_grown_without_bound(monkeypatch):
    from profidrive_cli import plot
    monkeypatch.setattr(plot, "MAX_SAMPLES", 8)
    tr = plot.Trace()
    for i in range(100):
        tr.add(float(i), 1.0, 1.0)
    assert len(tr) < 8
    assert tr.t[0] == 0.0 and tr.t == sorted(tr.t)          # still in time order from the start


def test_monitor_columns_stay_aligned_with_time_when_a_monitor_appears_late():
    from profidrive_cli.plot import Trace
    tr = Trace()
    tr.add(0.0, 1.0, 0.0)
    tr.add(0.1, 1.0, 0.5, {"M09 [Hz]": 0.4})
    tr.add(0.2, 1.0, 1.0)
    assert tr.monitors["M09 [Hz]"] == [None, 0.4, None]


@pytest.mark.parametrize("name", ["run.jpg", "run", "run.pdf"])
def test_plot_format_follows_the_extension_svg_or_png_only(name):
    from profidrive_cli.plot import plot_format
    with pytest.raises(UsageError, match=r"\.svg or \.png"):
        plot_format(name)


# ---------------------------------------------------------------------------------------------
# run --plot
# ---------------------------------------------------------------------------------------------


def test_run_plot_draws_the_ramp_and_the_stop(tmp_path):
    out = tmp_path / "run.svg"
    # F07 = 2 s from 0 to 60 Hz: 30 Hz after 1 s, within the 1.5 s (a ramp to draw, then the stop)
    r = run("run", "3", "--hz", "30", "--duration", "1.5", "--plot", out, "--port", "sim://?set=3:F07=2",
            "--json")
    assert r.exit_code == 0, r.output
    texts = svg_texts(out.read_bytes())
    assert {"speed [Hz]", "reference", "actual", "running", "stopping"} <= texts
    assert any("30" in t for t in texts if t.startswith("station 3"))     # the title names the reference
    # the JSON stream on stdout is untouched by the plot (its note goes to stderr)
    events = [json.loads(x)["event"] for x in r.stdout.splitlines()]
    assert events[0] == "start" and events[-1] == "end"


def test_run_plot_records_every_sample_the_run_shows(tmp_path, monkeypatch):
    from profidrive_cli.cli import run_plot
    seen = {}
    real = run_plot.RunPlot.write

    def spy(self):
        seen["trace"] = self.trace
        return real(self)
    monkeypatch.setattr(run_plot.RunPlot, "write", spy)
    r = run("run", "3", "--hz", "30", "--duration", "4", "--plot", tmp_path / "run.png", "--port", "sim://",
            "--json")
    assert r.exit_code == 0, r.output
    tr = seen["trace"]
    # fuji-g1 on the simulator: F07 = 6 s from 0 to 60 Hz, so 30 Hz after 3 s; then the stop to 0
    assert max(v for v in tr.actual if v is not None) == pytest.approx(30.0, abs=0.5)
    assert tr.actual[-1] == pytest.approx(0.0, abs=0.5)
    assert set(v for v in tr.reference if v is not None) == {30.0}
    assert [m[1] for m in tr.marks] == ["running", "stopping", "stopped"]
    assert tr.t == sorted(tr.t)
    # issue 34: the reference ends where the stop begins (the drive is asked to stop, whatever its
    # reference word still holds): every point after the "stopping" mark has none (the mark's own
    # point is the run's last sample again, drawn without it)
    t_stop = next(t for t, word in tr.marks if word == "stopping")
    after = [ref for t, ref in zip(tr.t, tr.reference) if t > t_stop]
    assert after and all(ref is None for ref in after)
    assert [ref for t, ref in zip(tr.t, tr.reference) if t < t_stop][-1] == 30.0


def test_run_plot_after_a_trip_draws_no_reference_from_the_trip_on():
    # the data handed to the plotter: a view fed running samples, a tripped one, then the stop
    from profidrive_cli.cli.run_plot import RunPlot
    view = SimpleNamespace(header={"address": 6, "profile": "moeller", "reference_hz": 20.0},
                           monitors=None, update=lambda *a, **kw: None, set_phase=lambda *a, **kw: None)
    plot = RunPlot("x.svg")
    plot.attach(view)

    def smp(t, hz, fault=False):
        return SimpleNamespace(t=t, reference_hz=20.0, actual_hz=hz, status=SimpleNamespace(fault=fault))
    view.set_phase("running", smp(0.0, 0.0))
    view.update(smp(0.5, 10.0))
    view.update(smp(1.0, 0.0, fault=True))             # tripped: the output is off
    view.set_phase("stopping", smp(1.0, 0.0, fault=True))
    view.set_phase("stopped", smp(1.2, 0.0, fault=True))
    assert plot.trace.reference == [20.0, 20.0, None, None, None]


def test_step_traces_end_the_reference_at_the_stop():
    # a checklist step's rows (the HTML report's plot): from the drive's stop() on, and in fault,
    # no reference; a start() draws it again
    from profidrive_cli.checklist.steptrace import record, to_plot_trace

    class St:
        def __init__(self, pct, fault=False):
            self.speed_hz, self.speed_percent, self.reference_percent = pct * 0.6, pct, 50.0
            self.fault = fault

    class D:
        channel = SimpleNamespace(now=lambda: 0.0)
        seq = [St(25.0), St(50.0), St(40.0), St(0.0), St(20.0), St(0.0, fault=True)]

        def cycle(self):
            return self.seq.pop(0)

        def stop(self, mode="normal", wait=True):
            return self.cycle()

        def start(self, timeout=None):
            return self.cycle()
    d = D()
    with record(d) as tr:
        d.cycle()
        d.cycle()
        d.stop()                                        # the stop's own cycles: no reference
        d.cycle()
        d.start()
        d.cycle()                                       # in fault: none either
    pt = to_plot_trace(tr, "t")
    assert [r[3] for r in tr.rows] == [50.0, 50.0, None, None, 50.0, None]
    assert pt.reference == [pytest.approx(30.0), pytest.approx(30.0), None, None, pytest.approx(30.0), None]


def test_without_matplotlib_run_plot_says_how_to_get_it_and_nothing_moves(tmp_path, monkeypatch, sim):
    monkeypatch.setitem(sys.modules, "matplotlib", None)        # import matplotlib -> ImportError
    r = run("run", "3", "--hz", "30", "--duration", "1", "--plot", tmp_path / "run.svg",
            "--port", "sim://?stations=3:fuji-g1")
    assert isinstance(r.exception, UsageError)
    assert "pip install 'profidrive-cli[plot]'" in str(r.exception)
    assert not (tmp_path / "run.svg").exists()
    assert not sim                                              # no simulated bus was even opened


def test_run_plot_into_a_missing_directory_is_refused_before_the_bus_opens(tmp_path, sim):
    r = run("run", "3", "--hz", "30", "--duration", "1", "--plot", tmp_path / "nodir" / "run.svg",
            "--port", "sim://?stations=3:fuji-g1")
    assert isinstance(r.exception, UsageError) and "--plot" in str(r.exception)
    assert not sim


def test_a_plot_that_cannot_be_written_keeps_the_old_file(tmp_path, monkeypatch):
    from profidrive_cli import outfile
    old = tmp_path / "run.svg"
    old.write_text("old plot")

    def full(*a, **k):
        raise outfile.OutputWriteError("--plot run.svg: write failed: No space left on device")
    monkeypatch.setattr(outfile, "write_bytes_atomic", full)
    # F07 0.1 s: the 10 Hz are reached within the 0.5 s, a good run (one that is not: exit 1 anyway)
    r = run("run", "3", "--hz", "10", "--duration", "0.5", "--plot", old, "--port", "sim://?set=3:F07=0.1")
    assert isinstance(r.exception, outfile.OutputWriteError)     # exit 1 after a good run
    assert old.read_text() == "old plot"


# ---------------------------------------------------------------------------------------------
# the checklist's HTML report
# ---------------------------------------------------------------------------------------------

CHECKLIST = """\
name: HTML report
port: sim://
stations:
  - address: 3
    profile: fuji-g1
steps:
  - write: {param: F07, value: 1}
  - write: {param: F08, value: 1}
  - run: {hz: 20, duration: 0.3}
  - run: {hz: 10, direction: reverse, within: 15}
  - stop
  - faults: none
"""


class _Tags(HTMLParser):
    def __init__(self):
        super().__init__()
        self.tags: list[str] = []
        self.text: list[str] = []

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)

    def handle_data(self, data):
        self.text.append(data)


def _html(tmp_path, text=CHECKLIST):
    cl = tmp_path / "c.yaml"
    cl.write_text(text)
    rep = tmp_path / "r.html"
    r = run("checklist", "run", cl, "--yes", "--report", rep)
    return r, rep


def test_the_html_report_has_the_verdict_the_steps_and_a_plot_per_moving_step(tmp_path):
    r, rep = _html(tmp_path)
    assert r.exit_code == 0, r.output
    p = _Tags()
    p.feed(rep.read_text())
    text = " ".join(p.text)
    assert "PASSED" in text and "HTML report" in text
    assert p.tags.count("svg") == 3                  # two run steps and one stop step moved the drive
    assert p.tags.count("h3") == 3
    assert "script" not in p.tags and "link" not in p.tags     # self-contained: nothing fetched or run
    assert text.count("passed") >= 6                 # each of the six steps passed


def test_the_html_report_of_a_failing_run_shows_failed(tmp_path):
    r, rep = _html(tmp_path, CHECKLIST.replace("faults: none", "faults: {expect: OC1}"))
    assert r.exit_code == 1
    assert "FAILED" in rep.read_text()


def test_a_failed_run_steps_plot_shows_the_band_and_the_deadline(tmp_path):
    # F07 6 s from 0 to F03 60 Hz (the profile's defaults, the sim ramps with F07): 20 Hz take 2 s,
    # so "within 1" fails; its plot must show the band it missed (20 ± 0.5 Hz) and the 1 s deadline
    text = CHECKLIST.replace("  - write: {param: F07, value: 1}\n", "").replace(
        "run: {hz: 20, duration: 0.3}", "run: {hz: 20, within: 1}")
    r, rep = _html(tmp_path, text)
    assert r.exit_code == 1
    html = rep.read_text()
    step = html[html.index("<h3>Step 2: run forward at 20 Hz"):]
    assert "failed" in step[:step.index("</h3>")]
    svg = step[step.index("<svg"):step.index("</svg>") + 6]
    root = ET.fromstring(svg)
    assert {"tolerance-band", "deadline"} <= {g.get("id") for g in root.iter(SVG_NS + "g")}
    texts = {"".join(t.itertext()).strip() for t in root.iter(SVG_NS + "text")}
    assert {"tolerance 20 ± 0.5 Hz", "deadline: within 1 s"} <= texts


def test_step_expectations_become_the_band_and_deadline_in_the_plots_unit():
    from profidrive_cli.checklist.steptrace import StepTrace, to_plot_trace

    class St:
        def __init__(self, hz, pct, ref):
            self.speed_hz, self.speed_percent, self.reference_percent = hz, pct, ref
    tr = StepTrace()
    tr.add(0.0, St(0.0, 0.0, 50.0))
    tr.add(1.0, St(15.0, 25.0, 50.0))       # 15 Hz is 25 %: max frequency 60 Hz
    pt = to_plot_trace(tr, "t", {"speed": 50.0, "unit": "%", "tolerance": 1.0, "within_s": 15})
    assert pt.speed_unit == "Hz"            # 50 % ± 1 % of 60 Hz = 30 ± 0.6 Hz
    assert pt.band[:2] == (pytest.approx(29.4), pytest.approx(30.6))
    assert pt.deadlines == [(15.0, "deadline: within 15 s")]
    pt = to_plot_trace(tr, "t", {"stopped": True, "within_s": 5})      # a stop: no band
    assert pt.band is None and pt.deadlines == [(5.0, "deadline: within 5 s")]


def test_without_matplotlib_the_html_report_is_written_and_says_how_to_get_plots(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    r, rep = _html(tmp_path)
    assert r.exit_code == 0, r.output
    html = rep.read_text()
    assert "<svg" not in html and "pip install 'profidrive-cli[plot]'" in html


def test_html_escapes_what_the_checklist_says(tmp_path):
    r, rep = _html(tmp_path, CHECKLIST.replace("name: HTML report", "name: \"<b>bold</b> & co\""))
    assert r.exit_code == 0, r.output
    html = rep.read_text()
    assert "&lt;b&gt;bold&lt;/b&gt; &amp; co" in html and "<b>bold</b>" not in html


def test_step_traces_convert_percent_to_hz_from_the_drives_own_pair():
    from profidrive_cli.checklist.steptrace import StepTrace, to_plot_trace

    class St:
        def __init__(self, hz, pct, ref):
            self.speed_hz, self.speed_percent, self.reference_percent = hz, pct, ref
    tr = StepTrace()
    tr.add(0.0, St(0.0, 0.0, 50.0))
    tr.add(1.0, St(15.0, 25.0, 50.0))       # 15 Hz is 25 %: max frequency 60 Hz, so 50 % is 30 Hz
    pt = to_plot_trace(tr, "t")
    assert pt.speed_unit == "Hz"
    assert pt.reference == [pytest.approx(30.0), pytest.approx(30.0)]
    assert pt.actual == [0.0, 15.0]


def test_step_traces_stay_in_percent_when_the_drive_reports_no_hz():
    from profidrive_cli.checklist.steptrace import StepTrace, to_plot_trace

    class St:
        speed_hz = None

        def __init__(self, pct, ref):
            self.speed_percent, self.reference_percent = pct, ref
    tr = StepTrace()
    tr.add(0.0, St(10.0, 20.0))
    pt = to_plot_trace(tr, "t")
    assert pt.speed_unit == "%" and pt.actual == [10.0] and pt.reference == [20.0]


def test_recording_leaves_the_drive_as_it_was():
    from profidrive_cli.checklist.steptrace import record

    class Ch:
        def now(self):
            return 0.0

    class St:
        speed_hz, speed_percent, reference_percent = 5.0, 10.0, 10.0

    st = St()

    class D:                           # a Drive's cycle, start and stop (drives/base.py)
        channel = Ch()

        def cycle(self):
            return st

        def start(self):
            return "started"

        def stop(self):
            return "stopped"
    d = D()
    with record(d) as tr:
        assert d.cycle() is st and d.cycle() is st
    assert len(tr) == 2 and tr.rows[0] == (0.0, 5.0, 10.0, 10.0)
    assert "cycle" not in vars(d) and d.cycle() is st        # the class's own method again
    assert not {"start", "stop"} & set(vars(d)) and (d.start(), d.stop()) == ("started", "stopped")


def test_run_plot_with_several_stations_is_refused_before_anything_moves(tmp_path, sim):
    r = run("run", "3,4", "--hz", "20", "--duration", "1", "--plot", tmp_path / "m.svg",
            "--port", "sim://?stations=3:fuji-g1,4:fuji-pdp3")
    assert isinstance(r.exception, UsageError) and "--plot: one station only" in str(r.exception)
    assert not sim and not (tmp_path / "m.svg").exists()


@pytest.mark.parametrize("trace", [False, True])
def test_steps_are_traced_only_when_a_report_will_plot_them(trace):
    import contextlib

    from profidrive_cli.checklist.runner import Runner, StationHandle
    from direct_session import direct_session
    from profidrive_cli.checklist.spec import load_checklist_text
    from profidrive_cli.drives import make_drive
    from profidrive_cli.sim.direct import DirectChannel
    from profidrive_cli.sim.plant import make_model
    cl = load_checklist_text(CHECKLIST, "c.yaml")

    @contextlib.contextmanager
    def open_station(spec):
        model = make_model(spec.profile)
        d = make_drive(DirectChannel(model, spec.profile.layouts[spec.layout].cfg), spec.profile, spec.layout)
        yield StationHandle(d, {"address": spec.address, "ident": model.ident, "profile": spec.profile.name,
                                "layout": spec.layout, "gsd": None}, direct_session(d, spec))
    steps = Runner(cl, open_station, trace_steps=trace).run().stations[0].steps
    moved = [r for r in steps if r.step.type in ("run", "stop")]
    assert len(moved) == 3 and all(r.status == "passed" for r in moved)
    assert all((r.trace is not None and len(r.trace) > 1) == trace for r in moved)
    assert all(r.trace is None for r in steps if r.step.type not in ("run", "stop"))
