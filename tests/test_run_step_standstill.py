"""The run step's standstill rule when it reverses a turning drive at a low cycle rate
(checklist/steps/run.py): the target counts only after the actual has passed standstill — a sample
within ± tolerance of zero, or a magnitude that fell by more than the tolerance and rose again by more
than it. A drive that reports the commanded direction with the speed's magnitude (Yaskawa does) shows
the target's sign while it still decelerates, and a noisy actual (± 0.6 Hz here) can come within the
band of the target then: those samples must not count.

Scripted by hand, one sample per second (a 1 Hz cycle), tolerance 0.5 Hz, +10 Hz -> -10 Hz:
    t=1 -9.8   magnitude fell by 0.2 (< 0.5): not yet; inside the band, but before standstill
    t=2 -10.4  rose by 0.6 from 9.8, but the fall was only 0.2: not standstill
    t=3 -9.4   fell by 0.6 from 10 (> 0.5) ...
    t=4 -9.7   ... and rose by 0.3 (< 0.5): not standstill; inside the band
    t=5 -5.0   decelerating
    t=6 -0.2   within the tolerance of zero: standstill
    t=7 -5.0
    t=8 -9.9   the target, after standstill: reached 8 s after the command (settled in the band by
               t=10, the third sample there: issue 34's rule)
"""

from types import SimpleNamespace

import pytest

from profidrive_cli.checklist.steps.run import STEP as RUN

AFTER_COMMAND = [-9.8, -10.4, -9.4, -9.7, -5.0, -0.2, -5.0, -9.9] + [-10.0] * 5


class Clock:
    def __init__(self):
        self.t = 0.0

    def now(self):
        return self.t


class ScriptedDrive:
    """A drive turning at +10 Hz that reports the scripted actual speeds, one per cycle, each cycle
    one second later (after set_speed_hz)."""

    def __init__(self):
        self.channel = Clock()
        self.commanded = False
        self.script = list(AFTER_COMMAND)

    def _st(self, hz):
        return SimpleNamespace(running=True, fault=False, fault_code=None, state="S4 operation",
                               speed_hz=hz, speed_percent=hz * 100.0 / 60.0, stopped=False)

    def status(self):
        return self._st(10.0) if not self.commanded else self.cycle()

    def set_speed_hz(self, hz):
        assert hz == -10.0
        self.commanded = True

    def cycle(self):
        self.channel.t += 1.0
        return self._st(self.script.pop(0))

    def max_frequency(self):
        return 60.0


def test_reversal_counts_the_target_only_after_standstill_at_a_low_cycle_rate():
    d = ScriptedDrive()
    step = SimpleNamespace(args={"unit": "hz", "speed": 10.0, "direction": "reverse", "duration": 0.0,
                                 "tolerance": 0.5, "within": 30.0})
    r = SimpleNamespace(step=step, expected={}, measured={})
    run = SimpleNamespace(progress=lambda *a: None)
    msg = RUN.execute(run, None, r, d, None)
    assert r.measured["reached_after_s"] == pytest.approx(8.0)
    # settled (session/live.py Reach: 3 samples in a row in the band) at t=10: -9.9, -10.0, -10.0
    assert r.measured["actual_hz"] == pytest.approx(-10.0)
    assert "after 8.00 s" in msg


class Accelerating(ScriptedDrive):
    """Standing at 0 Hz; after set_speed_hz(+10) it reports the scripted speeds."""

    def __init__(self, script):
        super().__init__()
        self.script = list(script)

    def status(self):
        return self._st(0.0) if not self.commanded else self.cycle()

    def set_speed_hz(self, hz):
        self.commanded = True


def _run_step(d):
    from profidrive_cli.checklist.steps.base import StepFailed
    step = SimpleNamespace(args={"unit": "hz", "speed": 10.0, "direction": "forward", "duration": 0.0,
                                 "tolerance": 0.5, "within": 30.0})
    r = SimpleNamespace(step=step, expected={}, measured={})
    with pytest.raises(StepFailed) as e:
        RUN.execute(SimpleNamespace(progress=lambda *a: None), None, r, d, None)
    return str(e.value), r


def test_the_run_step_fails_an_overshoot_with_its_figures():
    # issue 34, the one rule (session/live.py Reach): 10 Hz +- 0.5 Hz; 9.8 is inside, 10.7 beyond it
    msg, r = _run_step(Accelerating([5.0, 9.8, 10.7, 10.0, 10.0, 10.0]))
    assert msg == "overshoot: reference 10 Hz, peak actual 10.7 Hz, tolerance ± 0.5 Hz"
    assert r.measured["reached_after_s"] is None


def test_the_run_step_does_not_take_a_pass_through_for_reached():
    # 9.9 and 10.2 inside the band on the way to 20 Hz: two samples, not settled -- and beyond it
    msg, r = _run_step(Accelerating([5.0, 9.9, 10.2, 15.0, 20.0]))
    assert msg.startswith("overshoot: reference 10 Hz, peak actual 15 Hz")
