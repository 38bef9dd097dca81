"""Warm-up and Baud_Search (issue 26): a slave that ignores its first telegrams and answers later.

The real data: a Siemens ET200S (ident 0x806A, station 5) left four FDL status requests of pyprofibus
unanswered at 19.2 kbit/s and answered the 5th (GitHub mbuesch/pyprofibus issue #26; restated as octets
in ../shared/testdata/external/pyprofibus26-et200s-startup.txt, read from there, never copied). The
five GSD files in gsd/ declare Auto_Baud_supp = 1 (the slave searches the rate: Baud_Search, IEC 61158).

`sim://?warmup=3:4` makes station 3 miss the first 4 valid telegrams on its line, to any station
(sim/slave.py SimSlave.baud_search: Baud_Search takes the rate from any telegram on the line);
`diag`, `io`, the drive commands' start-up and `--baud auto` for a named station send up to
dp/scan.py's WARMUP_PROBES (5: the pyprofibus #26 figure) FDL status requests to wake it, and a
scan's second pass asks every silent address again after the quick pass's traffic
(tests/test_scan_warmup.py has the scan's counts).
"""

import json
import os
import subprocess
import sys

import pytest

from profidrive_cli import UsageError
from profidrive_cli.dp import scan as scan_mod
from profidrive_cli.dp.poller import Master
from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.timing import BusParams
from profidrive_cli.link import open_link
from profidrive_cli.sim.plant import build_bus

from conftest import SHARED

ET200S = os.path.join(SHARED, "testdata", "external", "pyprofibus26-et200s-startup.txt")
needs_capture = pytest.mark.skipif(not os.path.isfile(ET200S), reason=f"{ET200S} not present")


def _capture_lines():
    """(direction, octets) of each telegram line of the #26 capture."""
    out = []
    with open(ET200S, encoding="utf-8") as f:
        for line in f:
            if line.startswith("#") or not line.strip():
                continue
            direction, octets, _ = line.rstrip("\n").split("\t", 2)
            out.append((direction, bytes.fromhex(octets)))
    return out


def _run(*args):
    p = subprocess.run([sys.executable, "-m", "profidrive_cli", *args], capture_output=True,
                       text=True, stdin=subprocess.DEVNULL, timeout=120)
    return p.returncode, p.stdout, p.stderr


def _master(url, baud=19200, retries=1):
    return Master(open_link(url, baud), BusParams.for_baud(baud, retries=retries))


# -- the real start-up: four unanswered FDL status requests, the 5th answered -----------------------

@needs_capture
def test_the_et200s_capture_has_four_unanswered_requests_then_the_answer():
    lines = _capture_lines()
    first_reply = next(i for i, (d, _) in enumerate(lines) if d == "S->M")
    requests = lines[:first_reply]
    assert len(requests) == 5                                   # the file: 1st..5th try
    assert {o for _, o in requests} == {bytes.fromhex("10 05 02 49 50 16")}
    # the pyprofibus #26 figure is dp/scan.py's bound: five requests wake that slave
    assert scan_mod.WARMUP_PROBES == len(requests)


@needs_capture
def test_simulated_station_in_baud_search_answers_the_capture_like_the_et200s():
    """The capture's own request octets (FDL status, master 2 -> station 5) to a simulated station 5
    with warmup=5:4: silent four times, the 5th answered with an SD1 FDL status reply from 5 to 2,
    as the ET200S did (its reply: `10 02 05 00 07 16`, FC 0x00 passive station OK)."""
    lines = _capture_lines()
    req = lines[0][1]
    real_reply = next(o for d, o in lines if d == "S->M")
    bus = build_bus("sim://?stations=5:toyo&warmup=5:4")
    answers = [bus.receive(req, float(i)) for i in range(5)]
    assert [len(a) for a in answers] == [0, 0, 0, 0, 1]
    got, _ = F.parse(answers[4][0].octets)
    real, _ = F.parse(real_reply)
    assert (got.sd, got.da, got.sa, got.fc & 0x0F) == (real.sd, real.da, real.sa, real.fc & 0x0F)
    assert bus.slave(5).stats["ignored_warmup"] == 4


# -- the URL option --------------------------------------------------------------------------------

def test_warmup_url_sets_each_station():
    bus = build_bus("sim://?warmup=3:4,5:2")
    assert {a: s.warmup for a, s in bus.slaves.items()} == {3: 4, 4: 0, 5: 2, 6: 0, 7: 0}
    bus = build_bus("sim://?warmup=3:1&warmup=6:7")          # the key may repeat too
    assert (bus.slave(3).warmup, bus.slave(6).warmup) == (1, 7)


@pytest.mark.parametrize("url", ["sim://?warmup=3", "sim://?warmup=3:x", "sim://?warmup=x:4",
                                 "sim://?warmup=3:-1", "sim://?warmup=200:4", "sim://?warmup=9:4"])
def test_bad_warmup_is_a_usage_error_naming_the_option(url):
    with pytest.raises(UsageError) as e:
        build_bus(url)
    assert "warmup=" in str(e.value)


def test_bad_warmup_on_the_command_line_is_one_line_exit_2():
    code, out, err = _run("scan", "--port", "sim://?warmup=3:x")
    assert code == 2 and out == ""
    lines = [x for x in err.splitlines() if x.strip()]
    assert len(lines) == 1 and "warmup=3:x" in lines[0] and "Traceback" not in err


def test_a_broadcast_is_heard_and_not_answered():
    """Baud_Search takes the rate from any valid telegram on the line: a Global_Control broadcast
    (SD2) counts as one of the 2 telegrams station 3 misses; the next request to it is the 2nd
    (missed, no answer), the one after it the 3rd (answered)."""
    bus = build_bus("sim://?stations=3:fuji-g1&warmup=3:2")
    gc = F.encode(F.make(F.BROADCAST, 2, F.request_fc(F.SDN_HIGH), b"\x00\x00", 58, 62))
    assert bus.receive(gc, 0.0) == []
    assert bus.slave(3).warmup == 2                      # (the setting is kept)
    req = F.encode(F.make(3, 2, F.request_fc(F.FDL_STATUS)))
    assert [len(bus.receive(req, 1.0 + i)) for i in range(2)] == [0, 1]
    assert bus.slave(3).stats["ignored_warmup"] == 1


# -- scan ------------------------------------------------------------------------------------------

def test_scan_wakes_a_station_in_baud_search_and_says_how_late():
    """Station 3 misses 4 telegrams: at its quick-pass probe the line has carried 2 (the probes to
    0 and 1; the master is 2), so that one is the 3rd, missed; by the second pass the line has
    carried far more than 4: it answers its second request, after 1 unanswered."""
    m = _master("sim://?warmup=3:4")
    found = scan_mod.scan(m, 0, 126)
    assert [e.address for e in found] == [3, 4, 5, 6, 7]
    late = {e.address: e.unanswered for e in found}
    assert late == {3: 1, 4: 0, 5: 0, 6: 0, 7: 0}
    assert found[0].ident == 0xFD01 and found[0].diag is not None   # FUJIFD01.GSD Ident_Number
    m.link.close()


def test_quick_scan_misses_it_one_request_per_address():
    """Its quick-pass probe is the 3rd telegram on the line (after the probes to 0 and 1)."""
    m = _master("sim://?warmup=3:4")
    found = scan_mod.scan(m, 0, 126, quick=True)
    assert [e.address for e in found] == [4, 5, 6, 7]
    m.link.close()


def test_the_warmup_is_bounded():
    """A scan of address 3 alone: the requests to 3 are the only telegrams on the line. It is asked
    until it has been asked once after WAKE_TELEGRAMS (10) telegrams: the requests 1..11, the 11th
    after 10. A slave that misses 11 telegrams (it would answer the 12th) is not waited for; one
    that misses 10 answers the 11th."""
    m = _master(f"sim://?warmup=3:{scan_mod.WAKE_TELEGRAMS + 1}")
    found = scan_mod.scan(m, 3, 3)
    assert found == []
    assert m.fdl.counters[3].requests == scan_mod.WAKE_TELEGRAMS + 1 == 11
    m.link.close()
    m = _master(f"sim://?warmup=3:{scan_mod.WAKE_TELEGRAMS}")
    found = scan_mod.scan(m, 3, 3)
    assert [(e.address, e.unanswered) for e in found] == [(3, 10)]
    m.link.close()


def test_requests_per_empty_address_quick_and_full():
    """Hand count on an empty bus (no stations, master 2, addresses 0..126): the quick pass one FDL
    status to each of the 126 others, the full scan two (the second pass; it begins after 126
    telegrams, more than WAKE_TELEGRAMS: no extra)."""
    for quick, per in ((True, 1), (False, 2)):
        m = _master("sim://?stations=")
        assert scan_mod.scan(m, 0, 126, quick=quick) == []
        assert m.link.ser.bus.stats.requests == 126 * per
        m.link.close()


def test_scan_text_and_json_say_the_station_answered_late():
    code, out, err = _run("scan", "--port", "sim://?warmup=3:4")
    assert code == 0, err
    assert "station 3 answered after 1 unanswered request (baud-rate search)" in out
    assert "station 4 answered" not in out
    code, out, err = _run("scan", "--port", "sim://?warmup=3:4", "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert {s["station"]: s["unanswered_before"] for s in doc["stations"]} == \
        {3: 1, 4: 0, 5: 0, 6: 0, 7: 0}              # (see test_scan_wakes_...: the quick pass's one)


# -- first contact of the other commands ------------------------------------------------------------

def test_status_survives_a_station_in_baud_search():
    """The drive commands' first Slave_Diag (with its retry: 2 telegrams) then FDL status probes
    wake it; before, `status 3` ended "station 3 does not answer"."""
    code, out, err = _run("status", "3", "--port", "sim://?warmup=3:4", "--json")
    assert code == 0, err
    assert json.loads(out)["station"] == 3


def test_diag_survives_a_station_in_baud_search():
    code, out, err = _run("diag", "3", "--port", "sim://?warmup=3:4", "--json")
    assert code == 0, err
    assert json.loads(out)["ident"] == 0xFD01


def test_first_contact_is_bounded_too():
    """2 Slave_Diag telegrams (1 retry) + WARMUP_PROBES FDL status: a slave ignoring more stays
    absent, with the usual one line."""
    ignored = 2 + scan_mod.WARMUP_PROBES
    code, out, err = _run("status", "3", "--port", f"sim://?warmup=3:{ignored}")
    assert code == 1 and "station 3 does not answer" in err


def test_baud_auto_wakes_a_named_station():
    code, out, err = _run("status", "3", "--json", "--baud", "auto", "--port",
                          "sim://?baud=187500&stations=3:fuji-g1&warmup=3:4")
    assert code == 0, err
    assert "baud rate 187.5k (station 3 answered)" in err
