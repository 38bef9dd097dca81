"""Issue 25 steps 4 and 5: one coordinator of several stations on one bus cycle (session/group.py) and
one live loop of run and jog (session/live.py), each rule written once. Read from the source (ast) and
checked on a fake session (no bus): the loop's verdicts."""

from __future__ import annotations

import ast
from pathlib import Path
from types import SimpleNamespace

import pytest

from profidrive_cli.session.live import NOT_REACHED, SETTLE_S, SETTLE_SAMPLES, Live, Reach, default_tolerance

PKG = Path(__file__).resolve().parent.parent / "profidrive_cli"


def _imports(path: Path) -> list[str]:
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module:
            out.append(node.module)
        elif isinstance(node, ast.Import):
            out.extend(a.name for a in node.names)
    return out


def _calls(name: str) -> list[str]:
    """file:line of every call of `name` (a plain name or an attribute) in the package."""
    out = []
    for f in sorted(PKG.rglob("*.py")):
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.Call):
                fn = node.func
                called = fn.id if isinstance(fn, ast.Name) else fn.attr if isinstance(fn, ast.Attribute) else ""
                if called == name:
                    out.append(f"{f.relative_to(PKG)}:{node.lineno}")
    return out


@pytest.mark.parametrize("module", ["run_cmd.py", "jog_cmd.py"])
def test_the_run_and_jog_commands_import_nothing_of_the_protocol_stack(module):
    bad = [m for m in _imports(PKG / "cli" / module)
           if m.split(".")[1:2] in (["fdl"], ["link"], ["dp"])]
    assert bad == []


def test_one_group_cycle_one_reached_rule():
    # the rounds are made by the Group only; "reached" is written once (Reach in session/live.py)
    # and every place that judges it builds one: run (Live), run 3,4,5, Drive.run(wait=True), the
    # checklist's run step (alone and together)
    assert [c.split(":")[0] for c in _calls("GroupCycle")] == ["session/group.py"]
    defs = [f"{f.relative_to(PKG)}" for f in PKG.rglob("*.py")
            for node in ast.walk(ast.parse(f.read_text()))
            if isinstance(node, ast.ClassDef) and node.name == "Reach"]
    assert defs == ["session/live.py"]
    users = {c.split(":")[0] for c in _calls("Reach") + _calls("of_run")}
    assert users == {"session/live.py", "session/multirun.py", "api/drive.py",
                     "checklist/steps/run.py", "checklist/steps/together.py"}


@pytest.mark.parametrize("ref, tol", [
    (50.0, 0.5),              # 1 % of 50 %
    (-50.0, 0.5),
    (2.0, 0.05),              # near zero: 0.05 % of the max frequency
    (0.0, 0.05),
])
def test_runs_band_is_one_percent_or_a_twentieth_percent_near_zero(ref, tol):
    assert default_tolerance(ref) == pytest.approx(tol)


# -- the reached rule on hand-made samples (issue 34) ------------------------------------------------

def _fed(ref, tol, samples, start=None, dt=0.05):
    """A Reach fed `samples` one every dt s from t = 0."""
    r = Reach(ref, tol, start=start, t0=0.0)
    for i, v in enumerate(samples):
        r.feed(i * dt, v)
    return r


def test_settled_in_the_band_is_reached_from_when_it_entered():
    # ref 50 %, band +-0.5 %: 49.7 enters at t = 0.10 s; 3 samples in a row (SETTLE_SAMPLES) over
    # 0.10 s (SETTLE_S) by t = 0.20 s: reached, counted from the entry
    assert (SETTLE_SAMPLES, SETTLE_S) == (3, 0.1)
    r = _fed(50.0, 0.5, [0.0, 25.0, 49.7, 50.0, 50.1])
    assert r.reached and r.reached_after == pytest.approx(0.10) and not r.overshoot


def test_an_overshoot_is_not_reached_and_names_its_figures():
    # from below to 51.0 %: 1.0 % beyond the reference, twice the 0.5 % band: an overshoot. Words in
    # Hz of a 60 Hz drive: 50 % = 30 Hz, 51 % = 30.6 Hz, 0.5 % = 0.3 Hz
    r = _fed(50.0, 0.5, [0.0, 20.0, 40.0, 49.8, 50.4, 51.0])
    r.unit, r.scale = "Hz", 0.6
    assert r.overshoot and not r.reached and r.peak == 51.0
    assert r.overshoot_words() == "overshoot: reference 30 Hz, peak actual 30.6 Hz, tolerance ± 0.3 Hz"


def test_passing_through_the_reference_is_not_reaching_it():
    # on its way to 100 % the actual crosses 50 % once, two samples inside the band: not settled
    r = _fed(50.0, 0.5, [0.0, 25.0, 49.9, 50.2, 75.0, 100.0])
    assert not r.reached
    assert r.overshoot and r.peak == 100.0              # and beyond it: said


def test_a_jump_over_the_band_between_two_samples_is_an_overshoot():
    r = _fed(50.0, 0.5, [0.0, 40.0, 60.0])
    assert r.overshoot and not r.reached


def test_an_undershoot_on_the_way_down_is_an_overshoot_too():
    # from 100 % down to 50 %: the far side is below the band
    r = _fed(50.0, 0.5, [75.0, 50.3, 49.2], start=100.0)
    assert r.overshoot and r.peak == 49.2


def test_falling_back_on_the_near_side_is_no_overshoot_and_settling_starts_again():
    # in the band at 0.00-0.05 s, out below (48 %) at 0.10, in again from 0.15: reached from 0.15
    r = _fed(50.0, 0.5, [49.8, 49.9, 48.0, 49.9, 50.0, 50.1])
    assert not r.overshoot and r.reached_after == pytest.approx(0.15)


def test_a_start_inside_the_band_counts_as_coming_from_zero():
    assert _fed(50.0, 0.5, [50.0, 50.0, 51.0]).overshoot           # above: beyond
    assert not _fed(50.0, 0.5, [50.0, 50.0, 49.0]).overshoot       # below: back towards zero
    assert _fed(-50.0, 0.5, [-50.0, -51.0]).overshoot              # reverse: beyond is below
    assert not _fed(0.0, 0.05, [0.0, 1.0, -1.0]).overshoot         # reference 0: no far side


def test_settling_needs_its_time_at_a_fast_cycle_too():
    # 100 cycles/s: 3 samples span only 0.02 s; settled once 0.1 s have passed in the band
    r = _fed(50.0, 0.5, [50.0] * 10, dt=0.01)
    assert not r.reached
    r.feed(0.10, 50.0)
    assert r.reached and r.reached_after == 0.0


# -- the loop on a fake session --------------------------------------------------------------------

def _sample(t, act, ref=50.0, fault=False, code=None):
    return SimpleNamespace(t=t, reference_percent=ref, actual_percent=act, actual_hz=act / 2.0,
                           fmax_hz=200.0, status=SimpleNamespace(fault=fault, fault_code=code))


class FakeSession:
    """A station that is its own Motion: poll() hands out the given samples, one a cycle; stop() stops."""

    def __init__(self, samples):
        self.samples = list(samples)
        self.may_run = False
        self.stop_report = None
        self.final_status = None
        self.stops = 0
        self.profile = None
        self.stop_status = None             # the status the stop reads (StopReport.status)
        self.sampled = []
        self.motion = self                  # the station and its Motion in one fake

    def sample(self, st):
        self.sampled.append(st)
        return st

    def poll(self):
        return self.samples.pop(0)

    def stop(self):
        self.stops += 1
        self.may_run = False
        self.stop_report = SimpleNamespace(how="normal", stopped=True, status=self.stop_status)
        return self.stop_report

    def set_reference(self, percent):
        pass


def _live(samples, **kw):
    s = FakeSession(samples)
    phases = []

    def start():
        s.may_run = True
        return _sample(0.0, 0.0)
    kw.setdefault("percent", 50.0)
    live = Live(s, start, on_phase=lambda words, sample: phases.append(words), **kw)
    return live, s, phases


def test_a_run_that_reaches_its_reference_and_ends_at_its_duration():
    # inside the band (50 +- 0.5 %) from 1.0 s, three samples by 2.0 s: reached after 1.0 s
    live, s, phases = _live([_sample(0.5, 25.0), _sample(1.0, 49.8), _sample(1.5, 50.0),
                             _sample(2.0, 50.0)], duration=2.0, judge=True, must_reach=True)
    live.begin()
    assert live.loop() == 0
    assert live.reached_after == 1.0 and live.reason == "duration 2 s reached" and not live.failed
    live.finish()
    assert s.stops == 1 and phases == ["starting", "running", "stopping", "stopped"]


def test_a_run_that_does_not_reach_its_reference_in_its_duration_fails():
    live, _, _ = _live([_sample(1.0, 20.0), _sample(2.0, 30.0)], duration=2.0, judge=True,
                       must_reach=True)
    live.begin()
    assert live.loop() == 1
    assert (live.failed, live.problem, live.short_of) == (True, NOT_REACHED, 15.0)


def test_a_trip_ends_the_loop_with_its_code():
    live, _, _ = _live([_sample(0.5, 10.0), _sample(1.0, 0.0, fault=True, code="OC1")], duration=5.0)
    live.begin()
    assert live.loop() == 1
    assert live.reason == "the drive tripped (OC1)" and live.problem == "tripped (OC1)"


def test_a_trip_without_a_code_is_named_by_the_stop_and_the_profile():
    # the cycle's words say "fault" only (Moeller PPO: no code); the stop reads E01, and the
    # profile's alarm table names it as `pdrive faults` does: "E01 Inverter overcurrent"
    from profidrive_cli.drives.profile import load_profile
    live, s, phases = _live([_sample(0.5, 10.0), _sample(1.0, 0.0, fault=True)], duration=5.0)
    s.profile = load_profile("moeller")
    s.stop_status = SimpleNamespace(fault=True, fault_code="E01")
    live.begin()
    assert live.loop() == 1 and live.reason == "the drive tripped"
    live.finish()
    assert live.reason == "the drive tripped (E01): Inverter overcurrent"
    assert live.problem == "tripped (E01): Inverter overcurrent"
    assert s.sampled == [s.stop_status]                 # the last line shows the stop's status


def test_an_overshoot_ends_the_run_at_once_with_its_figures():
    # 50 % of a 200 Hz drive (the fake: actual_hz = % / 2): 100 Hz +- 1 Hz; 52 % = 104 Hz is beyond
    live, _, _ = _live([_sample(0.5, 30.0), _sample(1.0, 50.2), _sample(1.5, 52.0), _sample(2.0, 50.0)],
                       duration=5.0, judge=True, must_reach=True)
    live.begin()
    assert live.loop() == 1 and live.failed and live.last.t == 1.5
    assert live.problem == live.reason == ("overshoot: reference 100 Hz, peak actual 104 Hz, "
                                           "tolerance ± 1 Hz")
    assert live.reached_after is None


def test_on_cycle_quits_the_loop():
    live, _, _ = _live([_sample(0.5, 10.0), _sample(1.0, 10.0)], duration=5.0, judge=True,
                       must_reach=True, on_cycle=lambda lv: lv.last.t >= 0.5)
    live.begin()
    assert live.loop() == 0 and live.reason == "q pressed" and not live.failed


def test_a_torque_run_is_not_judged_on_its_speed():
    live, _, _ = _live([_sample(1.0, 10.0)], duration=1.0, judge=True, must_reach=False)
    live.begin()
    assert live.loop() == 0 and live.reason == "duration 1 s reached" and not live.failed
