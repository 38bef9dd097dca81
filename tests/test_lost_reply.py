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


def _silent_cycles(m, plan, st, retries=1):
    """Drop every reply of MAX_SILENT Data_Exchange requests (each with its retries)."""
    for _ in range(MAX_SILENT * (1 + retries)):
        plan.inject_next(3, "drop")
    for _ in range(MAX_SILENT):
        assert st.in_data_exchange
        m.step(st)
    assert st.state == "absent" and not plan.queue


@pytest.mark.parametrize("timing", ["instant", "virtual"])
def test_silence_shorter_than_the_watchdog_resumes_data_exchange_without_set_prm(timing):
    m, bus, slave = _echo_master(timing, retries=1, wd_ms=500)
    plan = bus.faults = FaultPlan()
    set_prm = _count_set_prm(bus)
    st = m.stations[3]
    t0 = m.link.now()
    _silent_cycles(m, plan, st)
    if timing == "virtual":
        assert m.link.now() - t0 < 0.5          # the silence really was shorter than the watchdog
    for n in range(1, 6):
        assert m.exchange(3, bytes([0, n])) == bytes([0, n])
    assert st.in_data_exchange and st.fresh_inputs
    assert set_prm[0] == 0                      # no Set_Prm reached the bus
    c = m.fdl.counters[3]
    assert c.reparams == 0 and c.no_answer == MAX_SILENT
    assert slave.model.left == []               # the station never left data exchange
    assert slave.stats["watchdog_expired"] == 0 and slave.state == "Data_Exch"


def test_silence_on_a_yaskawa_drive_does_not_trip_it():
    link = open_link("sim://?stations=7:yaskawa&timing=virtual")
    m = Master(link, BusParams.for_baud(19200, retries=1))
    slave = link.bus.slave(7)
    m.add_station(7, SlaveConfig(ident=slave.model.ident, cfg=slave.model.real_cfg(), wd_ms=500))
    m.bring_up(7)
    left = []
    orig = slave.model.on_leave_data_exchange
    slave.model.on_leave_data_exchange = lambda now, why: (left.append(why), orig(now, why))
    plan = link.bus.faults = FaultPlan()
    set_prm = _count_set_prm(link.bus)
    st = m.stations[7]
    out = st.outputs
    for _ in range(MAX_SILENT * 2):
        plan.inject_next(7, "drop")
    for _ in range(MAX_SILENT + 5):
        m.exchange(7, out)
    assert st.in_data_exchange and left == [] and set_prm[0] == 0
    assert m.fdl.counters[7].reparams == 0 and m.fdl.counters[7].no_answer == MAX_SILENT
    link.close()


def test_silence_longer_than_the_watchdog_reparameterises_as_before():
    m, bus, slave = _echo_master("virtual", retries=1, wd_ms=500)
    plan = bus.faults = FaultPlan()
    set_prm = _count_set_prm(bus)
    st = m.stations[3]
    _silent_cycles(m, plan, st)
    m.link.sleep(0.6)                           # nothing reaches the station for > 500 ms
    for n in range(1, 4):
        assert m.exchange(3, bytes([0, n])) == bytes([0, n])
    assert slave.stats["watchdog_expired"] == 1 and slave.model.left == ["watchdog"]
    assert set_prm[0] == 1 and m.fdl.counters[3].reparams == 1
    assert st.in_data_exchange


def test_silence_with_the_station_locked_by_another_master_is_not_resumed():
    """Diag from a station now parameterised by master 5: not ours to resume."""
    from profidrive_cli.dp import services as S
    from profidrive_cli.dp.station import ABSENT, StationMachine
    from profidrive_cli.fdl.master import Outcome
    sm = StationMachine(3, SlaveConfig(ident=ECHO_IDENT, cfg=ECHO_CFG, wd_ms=500), 2)
    sm.state, sm._was_in_dx = "data_exchange", True
    dx = sm.next_request(0.0)
    for _ in range(MAX_SILENT):
        sm.on_outcome(dx, Outcome("no answer"), 0.0)
    assert sm.state == ABSENT
    req = sm.next_request(0.0)
    assert req.service == "Slave_Diag"
    # st1 0, st2 0x0C (WD_On + fixed), master 5, ident ours: in data exchange, but with master 5
    diag = S.SlaveDiag(0x00, 0x0C, 0x00, 5, ECHO_IDENT, b"").encode()
    reply = F.Frame(F.SD2, 2, 3, F.response_fc(F.DL), diag, 0x3E, 0x3C)
    sm.on_outcome(req, Outcome("reply", reply), 0.0)
    assert sm.state == "locked"
    # the same with master 2 (us): resumed
    sm2 = StationMachine(3, SlaveConfig(ident=ECHO_IDENT, cfg=ECHO_CFG, wd_ms=500), 2)
    sm2.state, sm2._was_in_dx = "data_exchange", True
    for _ in range(MAX_SILENT):
        sm2.on_outcome(dx, Outcome("no answer"), 0.0)
    diag = S.SlaveDiag(0x00, 0x0C, 0x00, 2, ECHO_IDENT, b"").encode()
    sm2.on_outcome(req, Outcome("reply", F.Frame(F.SD2, 2, 3, F.response_fc(F.DL), diag, 0x3E, 0x3C)),
                   0.0)
    assert sm2.state == "data_exchange" and sm2.counters.reparams == 0
    # with Prm_Req (st2 0x05, master 0xFF: watchdog expired): start-up again, one reparam
    sm3 = StationMachine(3, SlaveConfig(ident=ECHO_IDENT, cfg=ECHO_CFG, wd_ms=500), 2)
    sm3.state, sm3._was_in_dx = "data_exchange", True
    for _ in range(MAX_SILENT):
        sm3.on_outcome(dx, Outcome("no answer"), 0.0)
    diag = S.SlaveDiag(0x02, 0x05, 0x00, 0xFF, ECHO_IDENT, b"").encode()
    sm3.on_outcome(req, Outcome("reply", F.Frame(F.SD2, 2, 3, F.response_fc(F.DL), diag, 0x3E, 0x3C)),
                   0.0)
    assert sm3.state == "set_prm" and sm3.counters.reparams == 1


def test_lost_replies_over_a_real_pty_never_reparameterise():
    """The same through a real byte path: `pdrive sim --pty` dropping 70 % of the replies (so
    requests regularly end without any answer and silences of MAX_SILENT cycles happen), a
    watchdog far longer than any silence: the station is resumed each time, never re-parameterised."""
    import json
    import subprocess
    import sys

    sim = subprocess.Popen([sys.executable, "-m", "profidrive_cli", "sim", "--pty", "--json", "--plant",
                            "sim://?stations=3:fuji-g1&drop=0.7&seed=3"],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        port = json.loads(sim.stdout.readline())["port"]
        link = open_link(port, 19200)
        m = Master(link, BusParams.for_baud(19200, retries=1, link_latency=0.02))
        m.add_station(3, SlaveConfig(ident=0xFD01, cfg=bytes.fromhex("F3F1"), wd_ms=5000))
        m.bring_up(3, timeout=30)
        states = []
        m.on_event = lambda a, e: states.append(e.data) if e.kind == "state" else None
        st = m.stations[3]
        resumed = 0
        for _ in range(150):
            m.step(st)
            if st.state == "absent":
                m.bring_up(3, timeout=30)
                resumed += 1
        c = m.fdl.counters[3]
        link.close()
    finally:
        sim.terminate()
        sim.wait(10)
    assert resumed >= 1, c                       # silences did happen (seeded drops)
    assert c.reparams == 0 and "set_prm" not in states, (c, states)
    assert c.no_answer >= MAX_SILENT
