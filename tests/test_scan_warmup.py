"""Warm-up at a fair price (issue 38): Baud_Search as the standard has it, and a scan that finds a
slave still searching the rate for at most twice its one-probe traffic.

The model (sim/slave.py SimSlave.baud_search): a station still searching the baud rate takes it from
the first valid telegram (SD1, SD2, SD3: requests, replies, broadcasts -- to any station) once it has
missed `warmup` of them and searched `warmup_s` seconds; `sim://?warmup=3:4` / `warmup=3:0.5s`.
The scan (dp/scan.py): a quick pass, a second pass over the silent addresses, and asked again only
while the line has carried fewer than WAKE_TELEGRAMS (10) telegrams.

Every count below is by hand from those rules: the default plant is stations 3..7, the master 2,
a full scan 0..126 sends 126 FDL status requests in its quick pass.
The real data: ../shared/testdata/external/pyprofibus26-et200s-startup.txt (read from there).
"""

import json
import os
import subprocess
import sys

import pytest

from profidrive_cli.dp import scan as scan_mod
from profidrive_cli.dp.poller import Master
from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.timing import BusParams
from profidrive_cli.link import open_link
from profidrive_cli.sim.plant import build_bus

from conftest import SHARED
from test_warmup import _capture_lines

ET200S = os.path.join(SHARED, "testdata", "external", "pyprofibus26-et200s-startup.txt")
needs_capture = pytest.mark.skipif(not os.path.isfile(ET200S), reason=f"{ET200S} not present")

#: the default plant's stations, and the quick pass of a full scan (0..126 but the master, 2)
PLANT = [3, 4, 5, 6, 7]
QUICK = 126


def _master(url, baud=19200, retries=1):
    return Master(open_link(url, baud), BusParams.for_baud(baud, retries=retries))


def _scan(url, first=0, last=126, quick=False, baud=19200):
    m = _master(url, baud)
    try:
        found = scan_mod.scan(m, first, last, quick=quick)
        return {e.address: e.unanswered for e in found}, m.link.bus.stats.requests, m
    finally:
        m.link.close()


# -- the simulated line: every station hears every valid telegram -----------------------------------

def test_the_line_counts_every_valid_telegram_once():
    """An FDL status request and its SD1 answer: 2 telegrams; a Set_Prm answered by SC: 1 (an SC is
    no SD1/SD2/SD3); a broadcast: 1; a request to an empty address: 1; a garbled one: 0."""
    bus = build_bus("sim://?stations=3:fuji-g1")
    line = bus.line
    bus.receive(F.encode(F.make(3, 2, F.request_fc(F.FDL_STATUS))), 0.0)
    assert line.telegrams == 2
    prm = F.encode(F.make(3, 2, F.request_fc(F.SRD_HIGH, fcb=True), b"\x80\x01\x01\x0b\xFD\x01\x00",
                          61, 62))
    reply = bus.receive(prm, 1.0)
    assert [r.octets for r in reply] == [b"\xE5"] and line.telegrams == 3
    bus.receive(F.encode(F.make(F.BROADCAST, 2, F.request_fc(F.SDN_HIGH), b"\x00\x00", 58, 62)), 2.0)
    assert line.telegrams == 4
    bus.receive(F.encode(F.make(9, 2, F.request_fc(F.FDL_STATUS))), 3.0)
    assert line.telegrams == 5
    bad = bytearray(F.encode(F.make(3, 2, F.request_fc(F.FDL_STATUS))))
    bad[4] ^= 0xFF                                      # a wrong FCS
    bus.receive(bytes(bad), 4.0)
    assert line.telegrams == 5


def test_a_searching_station_takes_the_rate_from_telegrams_to_others():
    """warmup=4:2 on a plant of 3 and 4: an exchange with 3 is two telegrams (request, answer); the
    next request to 4 is the 3rd telegram on the line: answered at once."""
    bus = build_bus("sim://?stations=3:fuji-g1,4:fuji-pdp3&warmup=4:2")
    assert len(bus.receive(F.encode(F.make(3, 2, F.request_fc(F.FDL_STATUS))), 0.0)) == 1
    assert len(bus.receive(F.encode(F.make(4, 2, F.request_fc(F.FDL_STATUS))), 1.0)) == 1
    assert bus.slave(4).stats["ignored_warmup"] == 0


def test_the_url_takes_seconds_too():
    bus = build_bus("sim://?warmup=3:0.5s,5:2")
    assert (bus.slave(3).warmup, bus.slave(3).warmup_s) == (0, 0.5)
    assert (bus.slave(5).warmup, bus.slave(5).warmup_s) == (2, 0.0)
    assert not bus.slave(4).searching and bus.slave(3).searching


@pytest.mark.parametrize("bad", ["3:xs", "3:-1s", "3:nans", "3:4000s", "3:s"])
def test_bad_seconds_are_a_usage_error(bad):
    from profidrive_cli import UsageError
    with pytest.raises(UsageError, match="warmup="):
        build_bus(f"sim://?warmup={bad}")


# -- the ET200S of pyprofibus #26, reproduced ------------------------------------------------------

def _capture():
    """(direction, octets) of each telegram line of the #26 capture (test_warmup.py reads it)."""
    return _capture_lines()


@needs_capture
def test_a_scan_of_its_address_reproduces_the_et200s_start_up():
    """A master that talks to station 5 alone (as pyprofibus did): the line carries only its
    requests. warmup=5:4 -- the four unanswered FDL status requests of the capture -- and a scan of
    address 5: the first seven telegrams on the simulated line are the capture's, octet for octet
    (five FDL status requests from 2 to 5, the answer `10 02 05 00 07 16`, the Slave_Diag
    request), and the scan says 4 unanswered."""
    cap = _capture()[:7]
    m = _master("sim://?stations=5:toyo&warmup=5:4")
    bus = m.link.bus
    bus.log = []
    found = scan_mod.scan(m, 5, 5)
    m.link.close()
    assert [(e.address, e.unanswered) for e in found] == [(5, 4)]
    got = [("M->S" if who == "M" else "S->M", octets) for _, who, octets in bus.log[:7]]
    assert got == cap


@needs_capture
def test_the_whole_capture_gets_answers_where_the_et200s_answered():
    """The capture's requests in order to a simulated station 5 (warmup=5:4): a request is answered
    exactly where the capture has an answer after it (the last request's answer is not in the
    file: left out)."""
    cap = _capture()
    bus = build_bus("sim://?stations=5:toyo&warmup=5:4")
    requests = [(i, o) for i, (d, o) in enumerate(cap) if d == "M->S"][:-1]
    answered = [bool(bus.receive(o, float(k))) for k, (_, o) in enumerate(requests)]
    expected = [i + 1 < len(cap) and cap[i + 1][0] == "S->M" for i, _ in requests]
    assert answered == expected
    assert answered[:5] == [False] * 4 + [True]


# -- the scan: found, and at most twice the one-probe traffic ----------------------------------------

def test_the_default_scan_finds_it_within_twice_the_one_probe_traffic():
    """warmup=3:4 on the default plant. One-probe traffic: the quick pass's 126 FDL status + a
    Slave_Diag to each of the 5 stations = 131. The scan: the quick pass 126 (3 is silent: its
    probe is the 3rd telegram, after the probes to 0 and 1), the second pass one to each of the
    126 - 4 = 122 silent addresses (3 answers it), then 5 Slave_Diag: 253 <= 2 x 131."""
    late, requests, _ = _scan("sim://?warmup=3:4")
    assert late == {3: 1, 4: 0, 5: 0, 6: 0, 7: 0}
    assert requests == QUICK + (QUICK - 4) + 5 == 253
    assert requests <= 2 * (QUICK + 5)


def test_an_empty_bus_costs_twice_the_quick_pass():
    _, requests, _ = _scan("sim://?stations=")
    assert requests == 2 * QUICK
    _, requests, _ = _scan("sim://?stations=", quick=True)
    assert requests == QUICK


def test_quick_misses_a_station_the_traffic_has_not_woken_yet():
    """--quick stays at one request per address: warmup=3:4 -- its probe is the 3rd telegram,
    missed -- 126 + 4 Slave_Diag."""
    late, requests, _ = _scan("sim://?warmup=3:4", quick=True)
    assert late == {4: 0, 5: 0, 6: 0, 7: 0}
    assert requests == QUICK + 4


@pytest.mark.parametrize("missed, found", [(10, True), (11, False)])
def test_quick_finds_one_the_traffic_before_its_probe_woke(missed, found):
    """Decided: --quick does not try to wake anyone, but the traffic of its own pass does. Before
    the probe to 7 the line carried the probes to 0, 1, 3, 4, 5, 6 (6) and the answers of 3..6 (4):
    10 telegrams. A station 7 that misses 10 answers; one that misses 11 is missed (the answers
    count: the probes alone are 6)."""
    late, _, _ = _scan(f"sim://?warmup=7:{missed}", quick=True)
    assert (7 in late) is found and late.get(7, 0) == 0


def test_a_narrow_range_gets_the_bounded_extra():
    """An address is asked again while its last request went out after fewer than WAKE_TELEGRAMS
    (10) telegrams on the line. One empty address: requests after 0, 1, ..., 10 telegrams = 11.
    Three (3..5): pass 1 after 0, 1, 2; pass 2 after 3, 4, 5; pass 3 after 6, 7, 8; pass 4 after
    9, 10, 11 (4 and 5 are done); pass 5: 3 after 12 = 13 requests."""
    assert scan_mod.WAKE_TELEGRAMS == 10
    _, requests, _ = _scan("sim://?stations=", 3, 3)
    assert requests == 11
    _, requests, _ = _scan("sim://?stations=", 3, 5)
    assert requests == 13
    for first, last in ((0, 0), (3, 5), (0, 9), (0, 20), (100, 126)):
        n = last - first + 1 - (first <= 2 <= last)
        _, requests, _ = _scan("sim://?stations=", first, last)
        assert requests <= 2 * n + scan_mod.WAKE_TELEGRAMS, (first, last)


def test_the_count_starts_from_what_the_master_sent_before():
    """The master's own requests before the scan are telegrams the slave heard: after 10 FDL status
    requests to 9 (empty), a scan of 3 alone asks twice, not 11 times."""
    m = _master("sim://?stations=")
    for _ in range(10):
        assert scan_mod.probe(m, 9) is None
    assert scan_mod.scan(m, 3, 3) == []
    assert m.fdl.counters[3].requests == 2
    m.link.close()


# -- the time-based search ------------------------------------------------------------------------

def test_a_search_that_takes_time_is_found_by_the_second_pass():
    """warmup=3:1s on a virtual-clock 19.2k bus: the quick pass takes at least its 122 silent
    addresses' request (6 octets, 66 bit) and slot time (100 bit): 122 x 166 / 19200 s = 1.05 s > 1 s,
    so the second pass's request to 3 comes after its search reached the rate; its quick-pass
    request (the 3rd, about 20 ms in) did not."""
    late, _, _ = _scan("sim://?timing=virtual&baud=19200&warmup=3:1s")
    assert late == {3: 1, 4: 0, 5: 0, 6: 0, 7: 0}
    late, _, _ = _scan("sim://?timing=virtual&baud=19200&warmup=3:1s", quick=True)
    assert 3 not in late


def test_time_alone_fixes_nothing_and_the_scan_does_not_wait_for_it():
    """warmup=3:600s: a whole scan (253 requests, each at most a request, slot time, the longest
    reply and TID1: well under 600 s at 19.2k on the virtual clock) ends before its search does."""
    late, _, m = _scan("sim://?timing=virtual&baud=19200&warmup=3:600s")
    assert 3 not in late and m.link.now() < 600.0


# -- end to end ------------------------------------------------------------------------------------

def _run(*args):
    p = subprocess.run([sys.executable, "-m", "profidrive_cli", *args], capture_output=True,
                       text=True, stdin=subprocess.DEVNULL, timeout=120)
    return p.returncode, p.stdout, p.stderr


def test_scan_command_lists_it_and_quick_does_not():
    code, out, err = _run("scan", "--port", "sim://?warmup=3:4", "--json")
    assert code == 0, err
    assert {s["station"]: s["unanswered_before"] for s in json.loads(out)["stations"]} == \
        {3: 1, 4: 0, 5: 0, 6: 0, 7: 0}
    code, out, err = _run("scan", "--port", "sim://?warmup=3:4", "--json", "--quick")
    assert code == 0, err
    assert [s["station"] for s in json.loads(out)["stations"]] == [4, 5, 6, 7]
