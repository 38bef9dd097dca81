"""Fault injection on the simulated bus and the master's accounting of each fault, up to a soak of
60 s of simulated traffic with every fault type at a steady rate across the five default stations."""

import pytest

from profidrive_cli import UsageError
from profidrive_cli.dp.poller import Master
from profidrive_cli.dp.station import SlaveConfig
from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.master import NO_ANSWER, REPLY, FdlMaster, format_counters
from profidrive_cli.fdl.timing import BusParams
from profidrive_cli.link import open_link
from profidrive_cli.sim.faults import KINDS, FaultPlan
from profidrive_cli.sim.plant import build_bus

FUJI = SlaveConfig(ident=0xFD01, cfg=bytes.fromhex("F3F1"), wd_ms=500)


def _master(url="sim://?stations=3:fuji-g1,7:yaskawa", baud=19200, retries=1):
    link = open_link(url, baud)
    return Master(link, BusParams.for_baud(baud, retries=retries))


def _all_stations(m, wd_ms=500):
    for a, s in sorted(m.link.bus.slaves.items()):
        m.add_station(a, SlaveConfig(ident=s.model.ident, cfg=s.model.real_cfg(), wd_ms=wd_ms))
        m.bring_up(a)


# -- the receiver: a corrupt reply costs exactly one illegal frame and one retry ------------------

def _reply_with_tricky_data():
    # data octets that look like start delimiters (SC, SD1, SD2, SD3, SD4) and an ED
    data = bytes([0xE5, 0x10, 0x68, 0xA2, 0xDC, 0x16, 0x00, 0xFF, 0x68, 0x05, 0x05, 0x68])
    return F.encode(F.Frame(F.SD2, 2, 3, F.response_fc(F.DL), data))


def test_every_single_bit_flip_costs_one_illegal_and_one_retry():
    good = _reply_with_tricky_data()
    for i in range(1, len(good)):
        for bit in range(8):
            bad = bytearray(good)
            bad[i] ^= 1 << bit
            fm = FdlMaster(BusParams.for_baud(19200, retries=1))
            fm.request(3, F.SRD_HIGH, bytes(12), now=0.0, expect_octets=21)
            assert fm.feed(bytes(bad), 0.001) is None, (i, bit)
            retry = fm.expire(1.0)
            assert isinstance(retry, tuple)
            out = fm.feed(good, 1.001)
            assert out.kind == REPLY and out.frame.data == good[7:-2], (i, bit)
            assert (out.retries, out.illegal) == (1, 1), (i, bit)


def test_flipped_sc_is_one_illegal_and_one_retry():
    fm = FdlMaster(BusParams.for_baud(19200, retries=1))
    for bit in range(8):
        fm.request(3, F.SRD_HIGH, b"\x01", 0x3D, 0x3E, now=0.0, expect_octets=1)
        assert fm.feed(bytes([0xE5 ^ (1 << bit)]), 0.0) is None
        fm.expire(1.0)
        out = fm.feed(b"\xE5", 1.0)
        assert out.frame.is_sc and (out.retries, out.illegal) == (1, 1)


def test_noise_before_a_good_reply_is_one_illegal_without_retry():
    good = _reply_with_tricky_data()
    fm = FdlMaster(BusParams.for_baud(19200, retries=1))
    fm.request(3, F.SRD_HIGH, bytes(12), now=0.0, expect_octets=21)
    out = fm.feed(b"\x55\x00\x33" + good, 0.001)
    assert out.kind == REPLY and (out.retries, out.illegal) == (0, 1)


def test_corrupt_reply_spoils_the_attempt_until_idle():
    """After a broken telegram nothing more is taken in that attempt, not even a good frame."""
    good = _reply_with_tricky_data()
    bad = bytearray(good)
    bad[8] ^= 0x04
    fm = FdlMaster(BusParams.for_baud(19200, retries=0))
    fm.request(3, F.SRD_HIGH, bytes(12), now=0.0, expect_octets=21)
    assert fm.feed(bytes(bad) + good, 0.001) is None
    out = fm.expire(1.0)
    assert out.kind == NO_ANSWER and out.illegal == 1
    c = fm.counters[3]
    assert (c.no_answer, c.illegal, c.retries) == (1, 1, 0)


# -- one injection at a time through the whole master ---------------------------------------------

@pytest.mark.parametrize("timing", ["instant", "virtual"])
@pytest.mark.parametrize("kind,delta", [
    ("drop", {"retries": 1}), ("late", {"retries": 1}), ("flip", {"retries": 1, "illegal": 1}),
    ("wrongsa", {"retries": 1, "illegal": 1}), ("noise", {"illegal": 1}),
    ("powercycle", {"rs": 1, "reparams": 1}), ("drivetrip", {"dh": 1}),
])
def test_each_injection_is_counted_exactly(timing, kind, delta):
    m = _master(f"sim://?stations=3:fuji-g1,7:yaskawa&timing={timing}")
    plan = m.link.bus.faults = FaultPlan()
    m.add_station(3, FUJI)
    m.bring_up(3)
    for _ in range(3):
        m.exchange(3, bytes(12))
    c = m.fdl.counters[3]
    before = c.as_dict()
    plan.inject_next(3, kind)
    for _ in range(12):
        m.exchange(3, bytes(12))
    assert plan.counts[kind] == 1 and sum(plan.counts.values()) == 1
    after = c.as_dict()
    for k in ("retries", "no_answer", "illegal", "rs", "rr", "ue", "reparams", "dh"):
        assert after[k] - before[k] == delta.get(k, 0), k
    assert m.stations[3].in_data_exchange
    assert plan.expected_counters(3) == {
        "illegal": delta.get("illegal", 0), "failed_attempts": delta.get("retries", 0),
        "rs": delta.get("rs", 0), "reparams": delta.get("reparams", 0), "dh": delta.get("dh", 0)}
    m.link.close()


def test_drop_with_retries_used_up_is_a_no_answer():
    m = _master(retries=1)
    plan = m.link.bus.faults = FaultPlan()
    m.add_station(3, FUJI)
    m.bring_up(3)
    c = m.fdl.counters[3]
    plan.inject_next(3, "drop")
    plan.inject_next(3, "drop")
    m.exchange(3, bytes(12))
    assert (c.retries, c.no_answer) == (1, 1)
    assert plan.expected_counters(3)["failed_attempts"] == c.retries + c.no_answer
    m.exchange(3, bytes(12))
    assert m.stations[3].in_data_exchange and c.reparams == 0


def test_drive_trip_reaches_the_drive_and_the_diagnosis_is_read():
    m = _master()
    plan = m.link.bus.faults = FaultPlan(trip_codes={3: "OC2"})
    m.add_station(3, FUJI)
    m.bring_up(3)
    c = m.fdl.counters[3]
    diag0 = c.diag_reads
    plan.inject_next(3, "drivetrip")
    m.exchange(3, bytes(12))          # answered DH
    m.exchange(3, bytes(12))          # the master reads Slave_Diag first
    model = m.link.bus.slave(3).model
    assert model.state.name == "FAULT" and model.alarm_log[0][1] == "OC2"
    assert c.dh == 1 and c.diag_reads == diag0 + 1
    assert not m.link.bus.slave(3).diag_pending


def test_wrongsa_is_never_applied_to_a_short_acknowledge():
    bus = build_bus("sim://?stations=3:fuji-g1")
    plan = bus.faults = FaultPlan()
    plan.inject_next(3, "wrongsa")
    req = F.Frame(F.SD2, 3, 2, F.request_fc(F.SRD_HIGH), bytes.fromhex("B8 01 01 0B FD 01 00"), 61, 62)
    (r,) = bus.receive(F.encode(req), 0.0)          # Set_Prm: SC reply
    assert r.octets == b"\xE5" and plan.counts["wrongsa"] == 0 and plan.queue == [(3, "wrongsa")]


def test_station_faults_only_hit_data_exchange_and_not_repeats():
    m = _master()
    plan = m.link.bus.faults = FaultPlan({"powercycle": 1.0})
    m.add_station(3, FUJI)
    m.bring_up(3)                     # start-up requests are never power-cycled
    assert plan.counts["powercycle"] == 0
    m.step(m.stations[3])             # one Data_Exchange: power-cycled, answered RS
    assert plan.counts["powercycle"] == 1 and m.fdl.counters[3].rs == 1
    m.link.bus.faults = plan = FaultPlan({"drivetrip": 1.0})
    m.bring_up(3)
    plan.inject_next(3, "drop")       # the DH reply is dropped: the retry is an FCB repeat
    m.step(m.stations[3])
    assert plan.counts == {**{k: 0 for k in KINDS}, "drivetrip": 1, "drop": 1}
    c = m.fdl.counters[3]
    assert (c.dh, c.retries) == (1, 1)


def test_only_limits_injection():
    m = _master()
    m.link.bus.faults = plan = FaultPlan({"drop": 0.5, "flip": 0.5}, only={7})
    m.add_station(3, FUJI)
    m.bring_up(3)
    for _ in range(50):
        m.exchange(3, bytes(12))
    assert sum(plan.counts.values()) == 0 and m.fdl.counters[3].retries == 0


# -- URL keys --------------------------------------------------------------------------------------

def test_url_keys_build_a_plan():
    bus = build_bus("sim://?drop=0.1&flip=0.2&powercycle=0.01&drivetrip=0.02&late_ms=50"
                    "&tripcode=7:EF0&only=3,7&seed=9")
    p = bus.faults
    assert p.rates == {"drop": 0.1, "flip": 0.2, "powercycle": 0.01, "drivetrip": 0.02}
    assert p.late_s == pytest.approx(0.05) and p.only == {3, 7}
    assert p.trip_codes == {3: "OC1", 7: "EF0"}      # 3 gets its family default


@pytest.mark.parametrize("url,msg", [
    ("sim://?drop=2", "outside 0..1"), ("sim://?powercycle=x", "not a number"),
    ("sim://?tripcode=3", "ADDRESS:CODE"), ("sim://?tripcode=9:OC1", "not on the bus"),
    ("sim://?drivetrip=0.1&tripcode=3:NOPE", "unknown for station 3"),
    ("sim://?late_ms=abc", "not a number"), ("sim://?late_ms=0", "must be > 0"),
])
def test_url_key_errors(url, msg):
    with pytest.raises(UsageError, match=msg):
        build_bus(url)


def test_format_counters_is_compact():
    assert format_counters({"requests": 12, "retries": 1, "illegal": 2, "rs": 0}) == \
        "12 req, 1 retry, 2 illegal"


# -- the soak ------------------------------------------------------------------------------------

RATES = {"noise": 0.004, "flip": 0.004, "drop": 0.004, "late": 0.004, "wrongsa": 0.004,
         "powercycle": 0.002, "drivetrip": 0.002}


def _soak(m, until):
    while not until():
        m.poll()


def _check_accounting(m, plan):
    bus = m.link.bus
    for a, st in m.stations.items():
        c = m.fdl.counters[a]
        e = plan.expected_counters(a)
        assert st.in_data_exchange, (a, st.state, st.last_error)
        assert c.illegal == e["illegal"], a
        assert c.retries + c.no_answer == e["failed_attempts"], a
        assert c.rs == e["rs"] and c.reparams == e["reparams"], a
        assert c.dh == e["dh"], a
        assert c.rr == 0 and c.ue == 0, a
        assert bus.slave(a).stats["watchdog_expired"] == 0, a
    for k in KINDS:
        assert plan.counts[k] >= 5, (k, plan.counts)     # every kind was really exercised


def test_soak_60_s_of_simulated_traffic_with_every_fault():
    """60 s of traffic on the virtual-time bus at 187.5 kbit/s (about 19 000 requests): the clock
    is the bus's, so watchdogs and drive ramps run on the simulated time, exactly."""
    m = _master("sim://?baud=187500&timing=virtual", 187500)
    _all_stations(m)
    plan = m.link.bus.faults = FaultPlan(RATES, seed=7)
    t0 = m.link.now()
    _soak(m, lambda: m.link.now() - t0 >= 60.0)
    # a few clean rounds so that every station has come back
    m.link.bus.faults = None
    for _ in range(30):
        m.poll()
    assert sum(st.counters.data_exchanges for st in m.stations.values()) > 15000
    _check_accounting(m, plan)


def test_soak_on_the_instant_bus():
    """The same on the instant bus for a fixed number of cycles (watchdog widened: real clock)."""
    m = _master("sim://", 19200)
    _all_stations(m, wd_ms=10000)
    plan = m.link.bus.faults = FaultPlan(RATES, seed=11)
    n = [0]

    def enough():
        n[0] += 1
        return n[0] > 4000
    _soak(m, enough)
    m.link.bus.faults = None
    for _ in range(30):
        m.poll()
    _check_accounting(m, plan)


# -- the counters in pdrive scan / diag -------------------------------------------------------------

def test_scan_and_diag_show_the_injected_faults_in_their_counters():
    import json

    from click.testing import CliRunner

    from profidrive_cli.cli.main import cli
    url = "sim://?stations=3:fuji-g1,4:fuji-pdp3&noise=1&only=3"
    r = CliRunner().invoke(cli, ["scan", "--port", url, "--json"])
    assert r.exit_code == 0, r.output
    st = {s["station"]: s["counters"] for s in json.loads(r.output)["stations"]}
    # noise before each of station 3's two replies (FDL status, Slave_Diag)
    assert (st[3]["requests"], st[3]["illegal"], st[3]["retries"]) == (2, 2, 0)
    assert (st[4]["requests"], st[4]["illegal"], st[4]["retries"]) == (2, 0, 0)
    r = CliRunner().invoke(cli, ["scan", "--port", "sim://?stations=3:fuji-g1&noise=1", "--to", "5"])
    assert r.exit_code == 0, r.output
    assert "counters" in r.output and "2 req, 2" in r.output and "illegal" in r.output   # may wrap
    r = CliRunner().invoke(cli, ["diag", "3", "--port", "sim://?stations=3:fuji-g1&drop=0.5&seed=3",
                                 "--retries", "5"])
    assert r.exit_code == 0, r.output
    line = [ln for ln in r.output.splitlines() if ln.startswith("counters:")][0]
    assert "2 req" in line and "retry" in line
