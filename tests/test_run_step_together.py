"""The `run` step's `together: true` field (checklist/steps/run.py hands such a step to together.py):
its validation (file:line, the title in words, the stations it names) and the hand-over, in process.
The runs themselves over a pty are in tests/test_run_multi.py."""

from types import SimpleNamespace

import pytest

from profidrive_cli.checklist.spec import ChecklistError, load_checklist_text
from profidrive_cli.checklist.steps import run as run_step

HEAD = """\
name: t
stations:
  - {name: c1, address: 3, profile: fuji-g1}
  - {name: c2, address: 4, profile: fuji-pdp3}
steps:
"""
FIRST = 6          # the line of the first step after HEAD


def step_of(text, station=0):
    return load_checklist_text(HEAD + text, "t.yaml").stations[station].steps[0]


def test_together_names_every_station_when_the_step_names_none():
    s = step_of("  - run: {hz: 10, together: true}\n")
    assert s.args["together"] is True and s.args["together_stations"] is None
    assert s.title == "run forward at 10 Hz (± 0.5 Hz within 10 s), together with every station, then stop"


def test_together_with_the_steps_own_stations():
    s = step_of("  - run: {hz: 10, together: true}\n    stations: [c1, c2]\n")
    assert s.args["together_stations"] == ["c1", "c2"]
    assert s.title.endswith(", together with c1, c2, then stop")


def test_without_together_the_step_is_a_plain_run():
    s = step_of("  - run: {hz: 10, together: false}\n")
    assert "together" not in s.args and "together" not in s.title
    s = step_of("  - run: {hz: 10}\n")
    assert "together" not in s.args


def test_together_must_be_true_or_false_at_its_line():
    with pytest.raises(ChecklistError) as ei:
        load_checklist_text(HEAD + "  - run:\n      hz: 10\n      together: 3\n", "t.yaml")
    assert f"t.yaml:{FIRST + 2}: step 1 (run): together must be true or false, got 3" in \
        [str(e) for e in ei.value.errors]


def test_a_run_together_leaves_the_drives_stopped_for_the_steps_after_it():
    # run together stops every drive at its end: the state the validation hands to the later steps
    # says not running (a plain run leaves them running)
    state = {}
    check = SimpleNamespace(fields=lambda rs, body, allowed, *a, **k: body,
                            num=lambda rs, d, key, default=None, **k: d.get(key, default),
                            fail=lambda line, msg: pytest.fail(msg))
    from profidrive_cli.datafile import LineDict
    body = LineDict({"hz": 10, "together": True})
    body.line, body.key_lines = 6, {}
    st = load_checklist_text(HEAD + "  - note: x\n", "t.yaml").stations[0]
    rs = SimpleNamespace(index=1, body_line=6, stations=None)
    run_step.STEP.validate(check, st, rs, body, state)
    assert state["running"] is False
    body["together"] = False
    run_step.STEP.validate(check, st, rs, body, state)
    assert state["running"] is True


def test_a_together_step_is_handed_to_together_py_with_everything(monkeypatch):
    from profidrive_cli.checklist.steps import together
    got = {}

    def fake(*args):
        got["args"] = args
        return "done together"
    monkeypatch.setattr(together, "execute", fake)
    a = {"unit": "hz", "speed": 10.0, "direction": "forward", "duration": 0.0, "tolerance": 0.5,
         "within": 10.0, "together": True, "together_stations": None}
    run, sr, d, h = object(), object(), object(), object()
    r = SimpleNamespace(step=SimpleNamespace(args=a))
    assert run_step.STEP.execute(run, sr, r, d, h) == "done together"
    assert got["args"] == (run, sr, r, d, h, a, run_step.run_measured)


def test_a_trip_while_another_drive_still_accelerates_fails_both_in_words():
    # c1 trips at its first cycle while c2 is still on its way to 10 Hz: a trip ends the run for all.
    # c2 never reached the band: its outcome says why, in words (it was an internal TypeError: the
    # message formatted the time to the band, None, with :.2f, and c1's trip was lost with it)
    from profidrive_cli.checklist.steps import together
    from profidrive_cli.drives.base import DriveStatus

    class Clock:
        t = 0.0

        def now(self):
            return self.t

    clock = Clock()

    class FakeDrive:
        channel = clock

        def __init__(self, trips):
            self.trips, self.hz = trips, 0.0

        def max_frequency(self):
            return 50.0

        def _st(self, running=True):
            fault = self.trips and clock.t > 0
            return DriveStatus("fault" if fault else "operation", running and not fault, fault, {},
                               self.hz * 2, self.hz, fault_code="OC1" if fault else None)

        def status(self):
            return self._st(running=False)

        def set_speed_hz(self, hz):
            pass

        def start(self, timeout):
            return self._st()

        def cycle(self):
            clock.t += 0.01
            self.hz += 0.1
            return self._st()

    a = {"unit": "hz", "speed": 10.0, "direction": "forward", "duration": 0.0, "tolerance": 0.5,
         "within": 10.0}
    stopped = SimpleNamespace(how="normal", stopped=True)
    drives = [together._Drive(n, FakeDrive(trips), SimpleNamespace(address=ad, motion=SimpleNamespace(stop_report=stopped)), a)
              for n, ad, trips in (("c1", 3, True), ("c2", 4, False))]
    run = SimpleNamespace(progress=lambda *args: None)
    together._reach_and_hold(run, None, None, a, drives, SimpleNamespace(end_round=lambda: None))
    c1, c2 = (x.result(a, "the other", lambda *args: {}) for x in drives)
    assert c1[:2] == (False, "the drive tripped while accelerating (OC1)")
    assert c2[0] is False
    assert c2[1] == "not in the band when the run ended: c1 tripped (a trip ends the run for all)"
