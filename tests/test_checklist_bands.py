"""Checklist tolerances, both sides of every band: a run step's hold band (a speed that sags below,
or overshoots above, the band while holding fails the step; one that stays inside passes), and a
read step's `tolerance:` (pass inside, fail outside, above and below the expected value).

The drive is the simulated Fuji FRENIC (station 3, PPO1) on DirectChannel; the disturbance is put
into the simulated motor itself (its output frequency after each tick), so the runner sees it only
through the status and actual words, as it would on the wire. Expected outcomes are worked by hand
from the step's band: target ± tolerance."""

import contextlib

import pytest

from profidrive_cli.checklist.runner import FAILED, NOT_RUN, PASSED, Runner, StationHandle
from direct_session import direct_session
from profidrive_cli.checklist.spec import load_checklist_text
from profidrive_cli.drives import make_drive
from profidrive_cli.sim.direct import DirectChannel
from profidrive_cli.sim.plant import make_model

HEAD = """\
name: t
stations:
  - {name: c1, address: 3, profile: fuji-g1}
steps:
"""


def run_text(text, disturb=None):
    """Run the checklist; `disturb(model)` may change the simulated drive before the steps."""
    cl = load_checklist_text(text, "t.yaml")
    models = {}

    @contextlib.contextmanager
    def open_station(spec):
        model = models.setdefault(spec.address, make_model(spec.profile))
        if disturb is not None:
            disturb(model)
        ch = DirectChannel(model, spec.profile.layouts[spec.layout].cfg)
        d = make_drive(ch, spec.profile, spec.layout)
        yield StationHandle(d, {"address": spec.address, "ident": model.ident,
                                "profile": spec.profile.name, "layout": spec.layout, "gsd": None},
                            direct_session(d, spec))
    return Runner(cl, open_station).run()


def drift_after_reaching(target_hz, offset_hz, after_s=0.5, for_s=2.0):
    """The motor reaches `target_hz`, then `after_s` later its speed moves to target + offset for
    `for_s` seconds (a load that pulls it down, a regenerating load that pushes it up), inside the
    step's 3 s hold; afterwards the drive follows its ramp again (and can be stopped)."""
    def disturb(model):
        real_tick = model.tick
        seen = {}

        def tick(now):
            real_tick(now)
            if "at" not in seen and abs(model.freq - target_hz) < 0.05:   # the reference: 1/0x4000 of fmax steps
                seen["at"] = now
            if "at" in seen and after_s <= now - seen["at"] < after_s + for_s:
                model.freq = target_hz + offset_hz
        model.tick = tick
    return disturb


RUN = HEAD + """\
  - write: {param: F07, value: 1.0}
  - write: {param: F08, value: 1.0}
  - run: {hz: %s, tolerance: 0.5, duration: 3}
  - stop: {within: 5}
"""


# (target Hz, where the speed goes while holding, the run step's outcome)
HOLD = [
    (20, -1.0, FAILED),    # sags to 19 Hz: 1 Hz below, outside 20 ± 0.5
    (20, +1.0, FAILED),    # overshoots to 21 Hz: outside above
    (20, -0.3, PASSED),    # 19.7 Hz: inside
    (20, +0.3, PASSED),    # 20.3 Hz: inside
    (-20, +1.0, FAILED),   # reverse: -19 Hz, the magnitude sags
    (-20, -1.0, FAILED),   # reverse: -21 Hz, overshoot
]


@pytest.mark.parametrize("target,offset,outcome", HOLD)
def test_hold_band_is_checked_on_both_sides(target, offset, outcome):
    spec = f"{abs(target)}" + (", direction: reverse" if target < 0 else "")
    res = run_text(RUN % spec, drift_after_reaching(target, offset))
    steps = res.stations[0].steps
    run = steps[2]
    assert run.status == outcome, run.message
    if outcome == FAILED:
        assert "left the band" in run.message
        assert run.measured["actual_hz"] == pytest.approx(target + offset, abs=0.05)
        assert steps[3].status == NOT_RUN and not res.passed
    else:
        assert res.passed
        # the hold saw the drift: its extreme on that side is target + offset
        key = "hold_max" if offset > 0 else "hold_min"
        assert run.measured[key] == pytest.approx(target + offset, abs=0.05)


# F07 is written 3.0 s, then read with expect / tolerance
READS = [
    ("expect: 3.5, tolerance: 0.6", PASSED),   # |3.0 - 3.5| = 0.5 <= 0.6
    ("expect: 2.5, tolerance: 0.6", PASSED),   # below the expected value, inside
    ("expect: 3.5, tolerance: 0.5", PASSED),   # on the edge of the band
    ("expect: 3.5, tolerance: 0.4", FAILED),   # 0.5 > 0.4: outside, the value is below
    ("expect: 2.5, tolerance: 0.4", FAILED),   # outside, the value is above
    ("expect: 3.1", FAILED),                   # no tolerance: half a wire step (0.05 s) only
    ("expect: 3.0", PASSED),
]


@pytest.mark.parametrize("args,outcome", READS)
def test_read_tolerance_both_sides(args, outcome):
    res = run_text(HEAD + "  - write: {param: F07, value: 3.0}\n"
                   f"  - read: {{param: F07, {args}}}\n")
    r = res.stations[0].steps[1]
    assert r.status == outcome, r.message
    assert r.measured["value"] == 3.0
    if outcome == FAILED:
        assert "F07 = 3 s, expected" in r.message


def test_reversing_counts_the_target_once_the_speed_has_crossed_zero():
    """A reversing run step: the speed must pass standstill before the target counts. At a low cycle
    rate (a loaded machine, a slow bus) no sample may land inside ± tolerance of zero: crossing to
    the target's sign is the same proof. Here the simulated motor jumps from +1.5 to -1.5 Hz, so no
    sample is within ± 0.5 Hz of zero; the step must still pass (it failed after `within` s)."""
    def disturb(model):
        real_tick = model.tick
        seen = {}

        def tick(now):
            real_tick(now)
            if model.freq > 9.0:
                seen["forward"] = True              # the first step reached its speed
            if seen.get("forward") and 0.0 < model.freq < 1.5:
                model.freq = -1.5                   # on the way back: across zero in one jump
        model.tick = tick
    text = HEAD + """\
  - write: {param: F07, value: 1.0}
  - write: {param: F08, value: 1.0}
  - run: {hz: 10, tolerance: 0.5}
  - run: {hz: 10, direction: reverse, tolerance: 0.5, within: 10}
  - stop: {within: 5}
"""
    res = run_text(text, disturb)
    steps = res.stations[0].steps
    assert [s.status for s in steps[2:5]] == [PASSED, PASSED, PASSED], [s.message for s in steps]
