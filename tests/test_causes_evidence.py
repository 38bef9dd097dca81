"""Causes and the evidence that supports them (issue 34), on a passive listener's counts
(bustools/passive_live.py LiveList -> bustools/causes.py likely_causes, the rules `scan --watch`
shares: tests/test_watch_causes.py). Telegrams are built with fdl.frames and fed at chosen times;
every expected figure is counted by hand in the comments."""

from __future__ import annotations

import json

from profidrive_cli.bustools.causes import SILENT_AFTER, likely_causes
from profidrive_cli.bustools.passive_live import LiveList, bus_load_percent
from profidrive_cli.dp.capture import Capture, PcapWriter
from profidrive_cli.fdl import frames as F

from conftest import run_main

M = 2


def req_dx(da, fcb=False):
    return F.encode(F.make(da, M, F.request_fc(F.SRD_HIGH, fcb, True), b"\x00\x00"))


def rep(sa):
    return F.encode(F.make(M, sa, F.response_fc(F.DL), b"\x00\x00"))


def fdl_status(da):
    return F.encode(F.make(da, M, F.request_fc(F.FDL_STATUS)))


def live_of(timed):
    cap = Capture()
    live = LiveList()
    for t, octets in timed:
        for c in cap.feed(octets, t):
            live.feed(c)
    return live


def rounds(t0, n, order, answers):
    """n rounds 0.1 s apart from t0: a Data_Exchange to each station of `order`, 2 ms apart, a new
    FCB each round; answers(t, station) says whether it answers (1 ms after its request)."""
    timed = []
    for r in range(n):
        t = round(t0 + 0.1 * r, 6)
        for i, a in enumerate(order):
            tr = round(t + 0.002 * i, 6)
            timed.append((tr, req_dx(a, fcb=r % 2 == 1)))
            if answers(tr, a):
                timed.append((round(tr + 0.001, 6), rep(a)))
    return timed


def test_answers_from_before_the_silence_began_are_no_evidence():
    # the blind spot: station 6 answers last at 0.901 s, station 5 at 0.903 s -- after 6's last
    # answer but before 6's silence began (its first unanswered request, 1.000 s). From 1.0 s on the
    # master asks only 6, six rounds, and nobody answers. Nothing shows the line alive during 6's
    # silence: 6 is not blamed "while the others answer"
    timed = rounds(0.0, 10, (6, 5), lambda t, a: True)
    timed += rounds(1.0, 6, (6,), lambda t, a: False)
    causes = likely_causes(live_of(timed))
    assert not any("while the others answer" in c.title for c in causes), causes
    assert not any(c.stations for c in causes), causes
    (c,) = causes
    assert c.title.startswith("no station answered since 1.000 s: the line")


def test_every_station_silent_from_one_round_on_blames_none():
    # stations 5, 6, 7 polled in that order; in the round at 1.0 s station 5 answers (1.001 s), then
    # the line goes: 6 (1.002 s) and 7 (1.004 s) get no answer, and every round after that neither
    # (1.1 .. 1.5 s). 6's silence began at 1.002 s: 5's answer 1 ms before it is no answer during it
    def answers(t, a):
        return t < 1.0 or (a == 5 and t < 1.1)
    causes = likely_causes(live_of(rounds(0.0, 16, (5, 6, 7), answers)))
    assert not any(c.stations for c in causes), causes
    (c,) = causes
    assert c.title.startswith("no station answered since 1.002 s: the line, the master's adapter")
    # 6: rounds 1.0 .. 1.5 unanswered = 6; 5: 1.1 .. 1.5 = 5; 7: 1.0 .. 1.4 = 5 (its request at
    # 1.504 s is the last telegram: unanswered only once a next request or token shows it)
    assert c.evidence == ("station 5: 5 rounds in a row unanswered since 1.100 s",
                          "station 6: 6 rounds in a row unanswered since 1.002 s",
                          "station 7: 5 rounds in a row unanswered since 1.004 s",
                          "no other station answered after that")


def test_a_station_silent_for_rounds_while_the_others_answer_is_named():
    # station 6 answers nothing from 1.0 s on (rounds 1.0 .. 1.3: SILENT_AFTER = 4 of them), 5 and 7
    # answer in each of those rounds: 6 named, with the span and who answered in it
    assert SILENT_AFTER == 4
    causes = likely_causes(live_of(rounds(0.0, 14, (5, 6, 7), lambda t, a: a != 6 or t < 1.0)))
    assert causes[0].stations == (6,)
    assert causes[0].title.startswith("station 6 stopped answering while the others answer")
    assert causes[0].evidence == ("station 6: 4 rounds in a row unanswered since 1.002 s (last answer "
                                  "at 0.903 s)", "stations 5, 7 answered after its silence began")
    # three rounds are not enough
    causes = likely_causes(live_of(rounds(0.0, 13, (5, 6, 7), lambda t, a: a != 6 or t < 1.0)))
    assert not any(c.stations for c in causes), causes


def test_a_request_repeated_at_once_is_one_round():
    # station 5 polled with FDL status (no FCB to tell a retry): each round the master asks twice
    # in a row (a try and its retry, the same telegram), then station 6, which answers. 4 rounds,
    # 8 unanswered requests: 4 rounds in a row, and the lost() count is reached at the 4th round
    timed = [(0.0, fdl_status(5)), (0.001, b"\xE5")]
    for r in range(4):
        t = 0.1 + 0.1 * r
        timed += [(t, fdl_status(5)), (t + 0.01, fdl_status(5)), (t + 0.02, req_dx(6, r % 2 == 0)),
                  (t + 0.021, rep(6))]
    live = live_of(timed)
    st = live.stations[5]
    assert (st.counters["no_answer"], st.silent, st.silent_since) == (8, 4, 0.1)


def test_repeats_spread_over_the_stations_are_the_line_and_gap_addresses_are_no_stations():
    # stations 5, 6, 7 in data exchange; each round the master also asks one empty address (8, 9, ...
    # 27: 20 rounds, FDL status, never answered). Repeats (the same FCB again after a lost reply):
    # station 5 in rounds 3 and 11, station 6 in rounds 5 and 15, station 7 in round 8: 2 + 2 + 1 =
    # 5 on 3 of 3 stations, the most on 5: 2 of 5 = 40 %. The 20 empty addresses are no stations:
    # not "the other 22 station(s)", and they do not make 3 stations "at most half" of the line
    lost = {(3, 5), (11, 5), (5, 6), (15, 6), (8, 7)}
    timed = []
    for r in range(20):
        t = 0.1 * r
        for i, a in enumerate((5, 6, 7)):
            tr = t + 0.01 * i
            fcb = r % 2 == 1
            if (r, a) in lost:                       # the reply lost, the retry answered
                timed += [(tr, req_dx(a, fcb)), (tr + 0.003, req_dx(a, fcb)), (tr + 0.004, rep(a))]
            else:
                timed += [(tr, req_dx(a, fcb)), (tr + 0.001, rep(a))]
        timed.append((t + 0.05, fdl_status(8 + r)))
    causes = likely_causes(live_of(timed))
    (c,) = causes
    assert c.stations == ()
    assert c.title.startswith("repeats spread over the line (5 on 3 of 3 stations)")
    assert c.evidence == ("station 5: 2 retries, 0 corrupt replies, 2 unanswered",
                          "station 6: 2 retries, 0 corrupt replies, 2 unanswered",
                          "station 7: 1 retries, 0 corrupt replies, 1 unanswered",
                          "5 repeats on 3 of 3 stations, the most on station 5: 2 (40 %)")


def test_a_bus_load_over_100_percent_is_unknown():
    # 1000 octets in 0.01 s at 19200 bit/s: 11,000 bit in 192 bit times = 5,729 % -- impossible, so
    # the rate is not the line's: unknown. 12 Mbit/s: 11,000 / 120,000 = 9.17 %
    assert bus_load_percent(1000, 0.01, 19200) is None
    assert bus_load_percent(1000, 0.01, 12_000_000) == 9.17


def _fast_pcap(path):
    # 1000 FDL status requests (6 octets) each answered SC (1 octet), 10 us apart: 7000 octets in
    # 9.991 ms -- a 12 Mbit/s line (7000 x 11 bit = 77,000 bit = 6.4 ms of it)
    with open(path, "wb") as fh:
        w = PcapWriter(fh)
        for i in range(1000):
            w.write(i * 1e-5, fdl_status(5))
            w.write(i * 1e-5 + 1e-6, b"\xE5")


def test_live_from_a_file_without_a_rate_says_the_load_is_unknown(capsys, monkeypatch, tmp_path,
                                                                  no_config_at_all):
    # issue 34: the default rate (19.2 kbit/s) is no rate of the file's line; at it the file's
    # octets were 7000 x 11 / (19200 x 0.009991) = 40,141 %
    cap = tmp_path / "fast.pcap"
    _fast_pcap(cap)
    r = run_main(capsys, monkeypatch, "sniff", "--from-file", cap, "--live", "--json")
    assert r.exit_code in (0, None), r.stderr
    end = json.loads(r.output.splitlines()[-1])
    assert end["event"] == "live" and end["final"] and end["bus_load_percent"] is None
    r = run_main(capsys, monkeypatch, "sniff", "--from-file", cap, "--live")
    assert "bus load unknown (no baud rate: --baud)" in r.output
    # with the line's rate given: 77,000 bit / (12e6 x 0.009991 s) = 64.2 %
    r = run_main(capsys, monkeypatch, "sniff", "--from-file", cap, "--live", "--json", "--baud", "12M")
    end = json.loads(r.output.splitlines()[-1])
    assert end["bus_load_percent"] == 64.22
