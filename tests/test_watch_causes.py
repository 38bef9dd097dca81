"""scan --watch names likely causes with their evidence (issue 27, "causes with evidence"): from the
stations' categories and counters (bustools/causes.py watch_causes), in the table and in the JSON."""

from __future__ import annotations

import json

from profidrive_cli.bustools.buswatch import WatchedStation
from profidrive_cli.bustools.causes import watch_causes

from test_exit_codes import pdrive


def _st(addr, category="data exchange", passes=3, **counters):
    c = {"requests": 100, "retries": 0, "no_answer": 0, "illegal": 0, "reparams": 0}
    c.update(counters)
    return WatchedStation(addr, "slave", 0xFD01, "", category, counters=c, seen_passes=passes)


def test_a_silent_station_while_the_others_answer_comes_first():
    causes = watch_causes([_st(3), _st(4, "no answer", no_answer=9), _st(5)])
    assert causes[0].stations == (4,)
    assert causes[0].title.startswith("station 4 stopped answering while the others answer")
    assert "stations 3, 5 answer" in causes[0].evidence


def test_repeats_on_one_station_of_four_are_concentrated():
    # 9 + 1 = 10 repeats in all, 9 on station 6: 90 % >= 80 % on 1 of 4 stations (at most half)
    causes = watch_causes([_st(3), _st(4, retries=1), _st(5), _st(6, retries=5, illegal=4)])
    (c,) = causes
    assert c.stations == (6,) and "(90 % of 10)" in c.title


def test_corrupt_replies_from_most_stations_point_at_the_line():
    # 2 + 2 + 2 + 2 = 8 corrupt on all four: spread (no two hold 80 %), so the line
    causes = watch_causes([_st(a, illegal=2) for a in (3, 4, 5, 6)])
    (c,) = causes
    assert c.title.startswith("corrupt replies from most stations")


def test_a_reparameterised_and_a_misconfigured_station():
    causes = watch_causes([_st(3, reparams=2), _st(4, "configuration fault")])
    titles = [c.title for c in causes]
    assert any(t.startswith("station 4 refuses its configuration") for t in titles)
    assert any(t.startswith("station 3 left data exchange and was parameterised again 2 time(s)")
               for t in titles)


def test_a_healthy_bus_has_no_cause():
    assert watch_causes([_st(a) for a in (3, 4, 5)]) == []


def test_scan_watch_json_carries_the_causes(capsys, monkeypatch):
    # station 4 is unplugged 0.5 s into the bus's traffic (sim URL unplug=4@0.5): found by the
    # first scan, it stops answering while 3 and 5 go on
    code, out, err = pdrive(capsys, monkeypatch, "scan", "--port", "sim://?timing=virtual&unplug=4@0.5",
                            "--watch", "--duration", "3", "--interval", "1", "--json", "--from", "3",
                            "--to", "5")
    assert code == 0, err
    events = [json.loads(line) for line in out.splitlines()]
    end = events[-1]
    assert end["event"] == "end"
    assert any(c["stations"] == [4] and c["title"].startswith("station 4 stopped answering")
               for c in end["causes"]), end["causes"]
