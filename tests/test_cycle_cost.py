"""The drive layer's per-cycle work (issue 16): the session's rate metering keeps its window as
exchanges come in (no walk over 4,096 timestamps per cycle), and the codecs decode status words and
compute control words with plain ints (no enum.Flag arithmetic per cycle). Results are checked by
hand-calculated rates; the cost by what the code does, never by timing."""

import sys

import pytest

from profidrive_cli.cli.common import BusOptions
from profidrive_cli.drives.profidrive.words import Ctw, Stw
from profidrive_cli.session import DriveStation
from profidrive_cli.session.cycle import MeteredChannel


class Clocked:
    """A CyclicChannel whose exchanges happen at times the test sets."""

    def __init__(self):
        self.t = 0.0

    def now(self):
        return self.t

    def exchange(self, outputs):
        return bytes(len(outputs))


def run_at(ch, inner, start, hz, count):
    for i in range(count):
        inner.t = start + i / hz
        ch.exchange(b"\0\0")


# -- rate metering ----------------------------------------------------------------------------------

def test_rate_over_the_last_two_seconds():
    inner = Clocked()
    ch = MeteredChannel(inner)
    assert ch.rate == 0.0
    run_at(ch, inner, 0.0, 100.0, 1)
    assert ch.rate == 0.0                         # one exchange: no interval yet
    run_at(ch, inner, 0.0, 100.0, 301)            # 0 .. 3.00 s at 100 Hz
    # the window holds 1.00 .. 3.00 s: 201 exchanges, 200 intervals in 2 s
    assert ch.rate == pytest.approx(100.0)
    assert ch.cycles == 302


def test_rate_follows_a_change_of_pace():
    inner = Clocked()
    ch = MeteredChannel(inner)
    run_at(ch, inner, 0.0, 100.0, 300)            # 0 .. 2.99 s at 100 Hz
    run_at(ch, inner, 10.0, 2.0, 3)               # a pause, then 10.0, 10.5, 11.0 s
    # everything before 9.0 s has left the window: 2 intervals in 1 s
    assert ch.rate == pytest.approx(2.0)


def test_rate_is_capped_at_the_last_4096_exchanges():
    inner = Clocked()
    ch = MeteredChannel(inner)
    run_at(ch, inner, 0.0, 10000.0, 10000)        # 1 s at 10 kHz: more than 4096 in the window
    # 4096 timestamps, 4095 intervals of 0.1 ms
    assert ch.rate == pytest.approx(10000.0)


def test_rate_keeps_only_the_window():
    """The window is trimmed as exchanges come in, so reading the rate (every cycle of a live view)
    costs the same at any pace: after 3 s at 100 Hz only the last 2 s (201 exchanges) are kept
    (the old metering kept 301 and walked them back on every read)."""
    inner = Clocked()
    ch = MeteredChannel(inner)
    run_at(ch, inner, 0.0, 100.0, 301)
    assert len(ch._times) == 201
    assert ch._times[0] == pytest.approx(1.0) and ch._times[-1] == pytest.approx(3.0)


# -- no enum.Flag arithmetic per cycle ------------------------------------------------------------

LAYER = ("profidrive_cli.drives", "profidrive_cli.session")


@pytest.fixture
def flag_ops_forbidden(monkeypatch):
    """Record the Ctw / Stw (IntFlag) operators the drive layer or the session call while on."""
    calls = []
    on = [False]

    def guard(cls, name):
        real = getattr(cls, name)

        def op(*a):
            caller = sys._getframe(1).f_globals.get("__name__", "")
            if on[0] and caller.startswith(LAYER):
                calls.append((name, caller, sys._getframe(1).f_lineno))
            return real(*a)
        return op

    # enum copies the operators into every Flag class: guard them where they are looked up
    for cls in (Ctw, Stw):
        for name in ("__and__", "__rand__", "__or__", "__ror__", "__xor__", "__rxor__",
                     "__invert__"):
            monkeypatch.setattr(cls, name, guard(cls, name))
    return on, calls


@pytest.mark.parametrize("address", [3, 4, 5, 6, 7])
def test_a_cycle_does_no_flag_arithmetic(sim, flag_ops_forbidden, address):
    on, calls = flag_ops_forbidden
    m = BusOptions("sim://", "19200", 2, None, None, False, False, 0, False).open_master()
    with DriveStation(m, address, handle_signals=False, cycle_hz=0) as s:
        s.motion.start(20.0)
        on[0] = True
        samples = [s.motion.poll() for _ in range(200)]
        on[0] = False
        assert any(x.status.running for x in samples)
        assert calls == []
