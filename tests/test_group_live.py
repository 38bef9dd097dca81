"""Issue 25 steps 4 and 5: one coordinator of several stations on one bus cycle (session/group.py) and
one live loop of run and jog (session/live.py), each rule written once. Read from the source (ast) and
checked on a fake session (no bus): the loop's verdicts."""

from __future__ import annotations

import ast
from pathlib import Path
from types import SimpleNamespace

import pytest

from profidrive_cli.session.live import NOT_REACHED, Live, at_reference

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


def test_one_group_cycle_one_at_reference():
    # the rounds are made by the Group only; "at reference" is written once
    assert [c.split(":")[0] for c in _calls("GroupCycle")] == ["session/group.py"]
    defs = [f"{f.relative_to(PKG)}" for f in PKG.rglob("*.py")
            for node in ast.walk(ast.parse(f.read_text()))
            if isinstance(node, ast.FunctionDef) and node.name == "at_reference"]
    assert defs == ["session/live.py"]
    from profidrive_cli.api import drive
    assert drive.at_reference is at_reference


@pytest.mark.parametrize("ref, act, at", [
    (50.0, 49.5, True),       # 1 % of 50 % = 0.5 %: on the edge
    (50.0, 49.4, False),
    (-50.0, -50.4, True),
    (0.0, 0.05, True),        # near zero: 0.05 % of the max frequency
    (0.0, -0.06, False),
    (None, 1.0, False),
    (1.0, None, False),
])
def test_at_reference_is_one_percent_or_a_twentieth_percent_near_zero(ref, act, at):
    assert at_reference(ref, act) is at


# -- the loop on a fake session --------------------------------------------------------------------

def _sample(t, act, ref=50.0, fault=False, code=None):
    return SimpleNamespace(t=t, reference_percent=ref, actual_percent=act, actual_hz=act / 2.0,
                           status=SimpleNamespace(fault=fault, fault_code=code))


class FakeSession:
    """poll() hands out the given samples, one a cycle; stop() stops."""

    def __init__(self, samples):
        self.samples = list(samples)
        self.may_run = False
        self.stop_report = None
        self.final_status = None
        self.stops = 0

    def poll(self):
        return self.samples.pop(0)

    def stop(self):
        self.stops += 1
        self.may_run = False
        self.stop_report = SimpleNamespace(how="normal", stopped=True)
        return self.stop_report

    def set_reference(self, percent):
        pass


def _live(samples, **kw):
    s = FakeSession(samples)
    phases = []

    def start():
        s.may_run = True
        return _sample(0.0, 0.0)
    live = Live(s, start, on_phase=lambda words, sample: phases.append(words), **kw)
    return live, s, phases


def test_a_run_that_reaches_its_reference_and_ends_at_its_duration():
    live, s, phases = _live([_sample(0.5, 25.0), _sample(1.0, 49.8), _sample(2.0, 50.0)],
                            duration=2.0, judge=True, must_reach=True)
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


def test_on_cycle_quits_the_loop():
    live, _, _ = _live([_sample(0.5, 10.0), _sample(1.0, 10.0)], duration=5.0, judge=True,
                       must_reach=True, on_cycle=lambda lv: lv.last.t >= 0.5)
    live.begin()
    assert live.loop() == 0 and live.reason == "q pressed" and not live.failed


def test_a_torque_run_is_not_judged_on_its_speed():
    live, _, _ = _live([_sample(1.0, 10.0)], duration=1.0, judge=True, must_reach=False)
    live.begin()
    assert live.loop() == 0 and live.reason == "duration 1 s reached" and not live.failed
