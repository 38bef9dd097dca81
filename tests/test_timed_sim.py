"""The wire-timed simulated bus (timing=wire / timing=virtual) and the master's idle times on it.

timing=virtual runs the same wire time on a simulated clock, so the times below are exact and the
tests are not at the mercy of the machine's load; timing=wire (real clock) is only checked for
protocol rules (no TSYN violation, no collision), never for durations.
"""

import pytest

from profidrive_cli import UsageError
from profidrive_cli.dp.poller import Master
from profidrive_cli.dp.scan import scan
from profidrive_cli.dp.station import SlaveConfig
from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.timing import BusParams, frame_octets, transaction_wire_time
from profidrive_cli.link import open_link
from profidrive_cli.sim.bus import wire_limit
from profidrive_cli.sim.plant import build_bus


def _master(url, baud, retries=1):
    link = open_link(url, baud)
    return Master(link, BusParams.for_baud(baud, retries=retries, link_latency=0.02))


def _configs(bus, n=5):
    return {a: SlaveConfig(ident=s.model.ident, cfg=s.model.real_cfg())
            for a, s in list(sorted(bus.slaves.items()))[:n]}


def test_sim_link_knows_it_has_no_latency():
    m = _master("sim://?timing=virtual", 19200)
    assert m.params.link_latency == 0.0 and not m.link.instant and m.link.latency == 0.0
    m.link.close()


@pytest.mark.parametrize("quick", [True, False])
@pytest.mark.parametrize("baud", [19200, 187500])
def test_scan_on_virtual_clock_takes_exactly_the_wire_limit(baud, quick):
    m = _master(f"sim://?baud={baud}&timing=virtual", baud)
    bus = m.link.bus
    bus.log = []
    t0 = m.link.now()
    found = scan(m, 0, 126, quick=quick)
    took = m.link.now() - t0
    assert [e.address for e in found] == [3, 4, 5, 6, 7]
    p = m.params
    limit = wire_limit(bus.log, p)
    # the limit counts TID1 after the last reply too
    assert limit - p.tid1_seconds - 1e-6 <= took <= limit + 1e-6
    # and the limit is what the timing parameters say for 121 empty addresses + 5 stations; a live
    # list's quick pass sends one FDL status per empty address (no retry where nothing answered),
    # its second pass one more single one (dp/scan.py: a slave in Baud_Search heard the quick pass)
    absent = 127 - 1 - 5
    per = 1 if quick else 2
    fdl = 5 * transaction_wire_time(p, 6, 6) + \
        absent * per * transaction_wire_time(p, 6, None, attempts=1)
    diag = sum(transaction_wire_time(p, frame_octets(0, True), frame_octets(len(s.diag().encode()), True))
               for s in bus.slaves.values())
    assert limit == pytest.approx(fdl + diag, rel=1e-9)
    assert bus.stats.tsyn_violations == 0 and bus.stats.collisions == 0
    m.link.close()


@pytest.mark.parametrize("n", [1, 5])
def test_data_exchange_cycle_on_virtual_clock_is_the_wire_limit(n):
    baud = 187500
    m = _master(f"sim://?baud={baud}&timing=virtual", baud)
    bus = m.link.bus
    for a, c in _configs(bus, n).items():
        m.add_station(a, c)
        m.bring_up(a)
    bus.log = []
    t0 = m.link.now()
    for _ in range(50):
        assert m.poll() == n
    took = m.link.now() - t0
    p = m.params
    per_round = sum(transaction_wire_time(p, frame_octets(st.output_len), frame_octets(st.input_len))
                    for st in m.stations.values())
    assert took == pytest.approx(50 * per_round, rel=1e-6)
    assert wire_limit(bus.log, p) == pytest.approx(took, rel=1e-6)
    assert bus.stats.tsyn_violations == 0 and bus.stats.collisions == 0
    m.link.close()


def test_min_tsdr_from_set_prm_is_honoured():
    baud = 19200
    m = _master(f"sim://?stations=3:fuji-g1&baud={baud}&timing=virtual", baud)
    bus = m.link.bus
    m.add_station(3, SlaveConfig(ident=0xFD01, cfg=bytes.fromhex("F3F1"), min_tsdr=40))
    m.bring_up(3)
    assert bus.slave(3).min_tsdr == 40 and bus.slave(3).reply_delay_bits == 40
    bus.log = []
    m.exchange(3, bytes(12))
    (tm, who_m, req), (ts, who_s, rep) = bus.log
    assert (who_m, who_s) == ("M", "S")
    tsdr_bits = (ts - (tm + m.params.chars(len(req)))) * baud
    assert tsdr_bits == pytest.approx(40, abs=1e-6)
    m.link.close()


def test_station_response_time_from_url_and_min_tsdr_zero_keeps_it():
    bus = build_bus("sim://?stations=3:fuji-g1&timing=virtual&tsdr=25")
    s = bus.slave(3)
    assert s.reply_delay_bits == 25          # own time above the default min TSDR 11
    s.min_tsdr = 50
    assert s.reply_delay_bits == 50


def test_reply_octets_arrive_one_by_one_at_wire_time():
    link = open_link("sim://?stations=3:fuji-g1&baud=19200&timing=virtual", 19200)
    ser, bus = link.ser, link.bus
    req = F.encode(F.Frame(F.SD1, 3, 2, F.request_fc(F.FDL_STATUS)))
    t0 = link.now()
    link.write(req)
    char = bus.params.chars(1)
    first = t0 + len(req) * char + 11 / 19200 + char       # request, TSDR, one character
    ser.sim_sleep(first - t0 - 1e-6)
    assert ser.in_waiting == 0
    ser.sim_sleep(2e-6)
    assert ser.in_waiting == 1
    ser.sim_sleep(2 * char)
    assert ser.in_waiting == 3
    got = link.read(link.now() + 1.0)           # what is there now
    assert got == bytes.fromhex("10 02 03")
    got += link.read(link.now() + 1.0)          # waits for the first of the rest, takes what came
    while len(got) < 6:
        got += link.read(link.now() + 1.0)
    assert got == bytes.fromhex("10 02 03 00 05 16")
    link.close()


def test_a_reply_is_complete_at_its_end_days_into_a_virtual_clock():
    """The spin the monitor's virtual plant met 6 h 15 min into a run: a one-octet reply (an SC at
    19.2 kbit/s: 11 bits = 572.9 us) whose end, start + char time, lost more than 1e-9 of an octet to
    rounding; at its end it is complete, at any clock, and not one octet earlier."""
    from profidrive_cli.sim.bus import Reply
    char_s = 11 / 19200
    for start in (0.0, 22510.069374999995, 604800.123456789, 3.15e7 + 0.7):
        r = Reply(start, b"\xe5", char_s)
        assert r.due(r.end) == 1, start
        assert r.due(start + 0.999 * char_s) == 0, start
        two = Reply(start, b"\x00\x01", char_s)
        assert two.due(two.end) == 2 and two.due(start + char_s * 1.999) == 1, start


def test_bus_flags_tsyn_violation_and_collision():
    bus = build_bus("sim://?stations=3:fuji-g1&baud=19200&timing=wire")
    p = bus.params
    req = F.encode(F.Frame(F.SD1, 3, 2, F.request_fc(F.FDL_STATUS)))
    (reply,) = bus.receive(req, 0.0)
    assert reply.end == pytest.approx(p.chars(6) + 11 / 19200 + p.chars(6))
    # sending before the reply is complete: a collision
    bus.receive(req, reply.end - p.chars(2))
    assert bus.stats.collisions == 1 and bus.stats.cancelled == 1
    bus.flush()
    (reply,) = bus.receive(req, 1.0)                                 # a clean start again
    # 20 bit times after the end of a reply: less than TSYN (33)
    bus.flush()
    bus.receive(req, reply.end + 20 / 19200)
    assert bus.stats.tsyn_violations == 1
    # 33 bit times after: fine
    bus.flush()
    end = bus.busy_until
    bus.receive(req, end + 33.5 / 19200)
    assert bus.stats.tsyn_violations == 1 and bus.stats.collisions == 1


def test_pdrives_master_keeps_tsyn_on_the_real_clock():
    """timing=wire on the real clock: the master waits TID1/TSYN itself (counts, not durations)."""
    baud = 187500
    m = _master(f"sim://?baud={baud}&timing=wire", baud)
    bus = m.link.bus
    found = scan(m, 0, 12)
    assert [e.address for e in found] == [3, 4, 5, 6, 7]
    for a, c in _configs(bus).items():
        m.add_station(a, c)
        m.bring_up(a)
    for _ in range(20):
        m.poll()
    m.global_control(0x00)                 # SDN: TID2 before the next request
    m.poll()
    assert bus.stats.tsyn_violations == 0
    assert bus.stats.collisions == 0
    assert all(st.in_data_exchange for st in m.stations.values())
    m.link.close()


def test_global_control_keeps_tid2_on_virtual_clock():
    m = _master("sim://?stations=3:fuji-g1&timing=virtual", 19200)
    bus = m.link.bus
    m.add_station(3, SlaveConfig(ident=0xFD01, cfg=bytes.fromhex("F3F1")))
    m.bring_up(3)
    bus.log = []
    m.global_control(0x00)
    m.exchange(3, bytes(12))
    (t_gc, _, gc), (t_req, _, _), _ = bus.log
    gap_bits = (t_req - (t_gc + m.params.chars(len(gc)))) * 19200
    assert gap_bits >= m.params.max_tsdr - 1e-6
    assert bus.stats.tsyn_violations == 0
    m.link.close()


@pytest.mark.parametrize("url,msg", [("sim://?timing=slow", "timing must be"),
                                     ("sim://?tsdr=5", "tsdr=5 outside"),
                                     ("sim://?tsdr=x", "whole numbers")])
def test_timing_url_errors(url, msg):
    with pytest.raises(UsageError, match=msg):
        build_bus(url)


def test_station_channel_keeps_its_period_from_the_first_cycle():
    m = _master("sim://?stations=3:fuji-g1&timing=virtual", 19200)
    m.add_station(3, SlaveConfig(ident=0xFD01, cfg=bytes.fromhex("F3F1")))
    m.bring_up(3)
    ch = m.channel(3, 0.05)
    starts = []
    real = m.exchange

    def timed(address, outputs=None):
        starts.append(m.link.now())
        return real(address, outputs)
    m.exchange = timed
    for _ in range(10):
        ch.exchange(bytes(12))
    gaps = [b - a for a, b in zip(starts, starts[1:])]
    assert gaps == pytest.approx([0.05] * 9, abs=1e-9)
    m.link.close()
