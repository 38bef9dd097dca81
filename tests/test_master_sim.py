"""The master against the in-process simulated bus: start-up, cyclic data, recovery, counters."""

import pytest

from profidrive_cli import BusError
from profidrive_cli.dp.poller import Master
from profidrive_cli.dp.station import SlaveConfig
from profidrive_cli.fdl.timing import BusParams
from profidrive_cli.link import open_link
from profidrive_cli.sim.faults import FaultPlan

URL = "sim://?stations=3:fuji-g1,7:yaskawa"
FUJI = SlaveConfig(ident=0xFD01, cfg=bytes.fromhex("F3F1"), wd_ms=200)


@pytest.fixture
def master():
    link = open_link(URL)
    m = Master(link, BusParams.for_baud(19200, retries=1))
    yield m
    link.close()


def test_fdl_status_finds_exactly_the_plant(master):
    found = [a for a in range(0, 127) if a != 2 and master.fdl_status(a) is not None]
    assert found == [3, 7]


def test_start_up_sequence_and_data_exchange(master):
    states = []
    master.on_event = lambda a, e: states.append(e.data) if e.kind == "state" else None
    master.add_station(3, FUJI)
    master.bring_up(3)
    assert states == ["set_prm", "chk_cfg", "check", "data_exchange"]
    inputs = master.exchange(3, bytes(12))
    assert len(inputs) == 12
    d = master.slave_diag(3)
    assert d.ready and d.master == 2 and d.has("WD_On")


def test_cfg_fault_reported_in_words(master):
    master.add_station(7, SlaveConfig(ident=0x00CA, cfg=b"\xF1"))
    with pytest.raises(BusError, match="configuration fault"):
        master.bring_up(7, timeout=2, fail_fast=True)


def test_wrong_ident_reported(master):
    master.add_station(7, SlaveConfig(ident=0x1111, cfg=bytes.fromhex("5F6F")))
    with pytest.raises(BusError, match="parameter fault"):
        master.bring_up(7, timeout=2, fail_fast=True)


def test_absent_station(master):
    master.add_station(9, FUJI)
    with pytest.raises(BusError, match="no answer"):
        master.bring_up(9, timeout=0.2)
    assert master.fdl.counters[9].no_answer >= 1


@pytest.mark.parametrize("kind,counter", [("drop", "retries"), ("flip", "illegal"),
                                           ("wrongsa", "illegal"), ("late", "retries")])
def test_injected_reply_faults_are_counted_and_survived(master, kind, counter):
    plan = master.link.bus.faults = FaultPlan()
    master.add_station(3, FUJI)
    master.bring_up(3)
    c = master.fdl.counters[3]
    before = c.as_dict()
    plan.inject_next(3, kind)
    master.exchange(3, bytes(12))
    assert plan.counts[kind] == 1
    assert c.as_dict()[counter] == before[counter] + 1
    assert c.data_exchanges == before["data_exchanges"] + 1      # the retry brought the data
    assert master.stations[3].in_data_exchange


def test_noise_before_reply_is_counted_without_retry(master):
    plan = master.link.bus.faults = FaultPlan()
    master.add_station(3, FUJI)
    master.bring_up(3)
    c = master.fdl.counters[3]
    r0, i0 = c.retries, c.illegal
    plan.inject_next(3, "noise")
    master.exchange(3, bytes(12))
    assert (c.retries, c.illegal) == (r0, i0 + 1)


def test_power_cycle_is_recovered_and_counted(master):
    master.add_station(3, FUJI)
    master.bring_up(3)
    master.link.bus.slave(3).power_cycle(master.link.now())
    master.exchange(3, bytes(12))          # answered RS: station restarts
    for _ in range(10):
        master.exchange(3, bytes(12))
    c = master.fdl.counters[3]
    assert c.rs == 1 and c.reparams == 1
    assert master.stations[3].in_data_exchange


def test_watchdog_on_sim_expires_when_master_is_silent(master):
    import time
    master.add_station(3, FUJI)
    master.bring_up(3)
    slave = master.link.bus.slave(3)
    slave.tick(master.link.now() + 0.25)          # 250 ms later, watchdog 200 ms
    assert slave.state == "Wait_Prm"
    master.exchange(3, bytes(12))
    assert master.fdl.counters[3].rs == 1


def test_release_leaves_station_waiting_for_parameters(master):
    master.add_station(3, FUJI)
    master.bring_up(3)
    master.release(3)
    assert master.link.bus.slave(3).state == "Wait_Prm"


def test_global_control_clear_reaches_slaves(master):
    master.add_station(3, FUJI)
    master.bring_up(3)
    n = master.link.bus.stats.requests
    master.global_control(0x02)
    assert master.link.bus.stats.requests == n + 1
