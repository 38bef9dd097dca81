"""The safe stop's escalation time, end to end through DriveStation on the simulated bus.

A drive that does not come to a stop is coasted after 1.5 x its deceleration time (scaled by the
speed it was running at) + 3 s, at least 5 s and at most 600 s; 30 s when the deceleration time
cannot be read (docs/commands.md "the safe stop"; session/ package doc). The expected
times below are worked by hand from that rule, and the session's own clock (the virtual-time
simulator) measures how long it really waited before coasting.
"""

import pytest

from profidrive_cli.cli.common import BusOptions
from profidrive_cli.session import DriveStation

URL = "sim://?timing=virtual"


def open_session(address, **kw):
    m = BusOptions(URL, "19200", 2, None, None, False, False, 0, False).open_master()
    kw.setdefault("handle_signals", False)
    kw.setdefault("watchdog_ms", 5000)     # a few cycles a second: the watchdog must outlast them
    kw.setdefault("cycle_hz", 4)
    return DriveStation(m, address, **kw)


def stuck_stop(sim, address):
    """The drive's ramp-down never ends (a stuck brake chopper, a load driving it): only a coast
    stop brings it to rest. The acceleration stays short."""
    model = sim[URL].slaves[address].model
    acc = model.ramp_times()[0]
    model.ramp_times = lambda: (acc, 1e9, 1e9)
    return model


def set_ramps(address, accel_code, decel_code, decel_s):
    with open_session(address, cycle_hz=0) as s:
        s.params.write(accel_code, 0.1)
        s.params.write(decel_code, decel_s)


def escalate(sim, address, percent, **kw):
    """Run at `percent` of fmax, make the normal stop hang, leave the session: the StopReport."""
    s = open_session(address, **kw)
    with s:
        s.motion.start(percent)
        for _ in range(40):                          # 10 s at 4 Hz: well past the 0.1 s ramp up
            smp = s.motion.poll()
        assert smp.status.running
        assert smp.status.speed_percent == pytest.approx(percent, abs=0.5)
        stuck_stop(sim, address)
    return s.motion.stop_report


# (deceleration time F08 in s, speed in % of fmax, expected wait before coasting in s)
CASES = [
    (10.0, 100.0, 18.0),       # 1.5 * 10 + 3
    (20.0, 50.0, 18.0),        # 1.5 * 20 * 0.5 + 3: the ramp from half speed takes half as long
    (1.0, 100.0, 5.0),         # 1.5 * 1 + 3 = 4.5 -> the 5 s floor
    (0.0, 100.0, 5.0),         # 3 s -> the floor
    (396.0, 100.0, 597.0),     # just under the cap
    (500.0, 100.0, 600.0),     # 753 s -> the 600 s cap
]


@pytest.mark.parametrize("decel,percent,expected", CASES)
def test_coast_after_the_escalation_time(sim, decel, percent, expected):
    set_ramps(3, "F07", "F08", decel)
    r = escalate(sim, 3, percent)
    assert r.how == "coast" and r.stopped
    assert f"not stopped after {expected:g} s" in r.message
    # the wait really lasted that long on the session's clock (a few 0.25 s cycles of slack:
    # the last wait cycle and the coast itself)
    assert expected <= r.seconds <= expected + 1.0


def test_no_deceleration_time_known_waits_30_s(sim):
    r = escalate(sim, 3, 100.0, ppo=3)              # PPO3: no parameter channel to read F08 with
    assert r.how == "coast" and r.stopped
    assert "not stopped after 30 s" in r.message
    assert 30.0 <= r.seconds <= 31.0
