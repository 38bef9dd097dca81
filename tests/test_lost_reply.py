"""Replies lost on the wire (issue 12 findings 7 and 8), through the simulated bus with the fault
plan dropping replies: the FCB restart after a failed transaction, and a station that is still in
Data_Exchange after a few silent cycles is resumed, not re-parameterised."""

import pytest

from profidrive_cli.dp.poller import Master
from profidrive_cli.dp.station import MAX_SILENT, SlaveConfig
from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.timing import BusParams
from profidrive_cli.link import open_link
from profidrive_cli.sim.faults import FaultPlan
from profidrive_cli.sim.model import SlaveModel
from profidrive_cli.sim.slave import SimSlave

ECHO_IDENT = 0x1234
ECHO_CFG = bytes([0x31])          # 2 bytes in + out (reference §3.2: bits 5..4 = 11, length 1 + 1)


class EchoModel(SlaveModel):
    """Inputs = the outputs of the request being executed: a stale reply shows as old data."""

    def __init__(self):
        super().__init__(ECHO_IDENT, {"echo": ECHO_CFG})
        self.executed: list[bytes] = []
        self.left: list[str] = []

    def data_exchange(self, outputs, now):
        self.executed.append(bytes(outputs))
        return bytes(outputs)

    def on_leave_data_exchange(self, now, reason):
        self.left.append(reason)


def _echo_master(timing="instant", retries=1, wd_ms=500):
    link = open_link(f"sim://?stations=3:fuji-g1&timing={timing}")
    bus = link.bus
    slave = SimSlave(3, EchoModel())
    slave.response_bits = bus.tsdr_bits
    bus.slaves = {3: slave}
    m = Master(link, BusParams.for_baud(19200, retries=retries))
    m.add_station(3, SlaveConfig(ident=ECHO_IDENT, cfg=ECHO_CFG, wd_ms=wd_ms))
    m.bring_up(3)
    return m, bus, slave


def _count_set_prm(bus):
    n = [0]
    orig = bus._dispatch

    def spy(req, t):
        if req.dsap == 61:                  # Set_Prm (reference §3: DSAP 61)
            n[0] += 1
        return orig(req, t)
    bus._dispatch = spy
    return n


@pytest.mark.parametrize("timing", ["instant", "virtual"])
def test_after_a_failed_transaction_no_stale_input_is_marked_fresh(timing):
    m, bus, slave = _echo_master(timing, retries=1)
    plan = bus.faults = FaultPlan()
    st = m.stations[3]
    fresh = []
    for n in range(1, 40):
        if n in (5, 17, 18, 30):
            plan.inject_next(3, "drop")         # first attempt and its one retry: no answer
            plan.inject_next(3, "drop")
        out = n.to_bytes(2, "big")
        st.set_outputs(out)
        st.fresh_inputs = False
        m.step(st)
        if st.fresh_inputs:
            fresh.append(n)
            assert st.inputs == out, (n, st.inputs)     # a fresh input is this cycle's echo
    assert fresh == [n for n in range(1, 40) if n not in (5, 17, 18, 30)]
    # every output reached the drive, in order: none was swallowed by the repeat cache. 18 comes
    # twice: it is the restart telegram after 17 failed (FCV=0), and a retry with FCV=0 carries no
    # repetition check (reference §2.3), so the slave executes it again (the same outputs)
    executed = [int.from_bytes(o, "big") for o in slave.model.executed if any(o)]
    assert executed == list(range(1, 19)) + list(range(18, 40))
    c = m.fdl.counters[3]
    assert (c.retries, c.no_answer) == (4, 4)
    assert plan.expected_counters(3)["failed_attempts"] == c.retries + c.no_answer == 8
    assert c.reparams == 0 and st.in_data_exchange
