"""`pdrive monitor report` (profidrive_cli/monitor/report.py): the JSON document for a station over a
window (expected values built by hand), the text and HTML renderings (escaped, self-contained),
--since's forms and its refusals."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from profidrive_cli import UsageError
from profidrive_cli.monitor.model import BusSample, MonEvent, Sample, StationInfo
from profidrive_cli.monitor.report import parse_since, report, report_html, report_text
from profidrive_cli.monitor.store import History, Reader

# 2026-12-04 22:00:00 UTC
T = 1796421600.0


@pytest.fixture
def utc(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    monkeypatch.setenv("TZ", "UTC")
    time.tzset()
    yield
    monkeypatch.undo()
    time.tzset()


def counts(exchanges: int, retries: int, no_answer: int = 0) -> dict[str, int]:
    return {"exchanges": exchanges, "retries": retries, "no_answer": no_answer, "illegal": 0,
            "reparams": 0}


def build(d: Path) -> None:
    h = History(d)
    h.begin_run(T - 3600, "/dev/ttyUSB0", 1_500_000)
    h.write(stations=[StationInfo(T - 3600, 5, 0x80B5, "sinamics", "data exchange"),
                      StationInfo(T - 3600, 7, None, None, "data exchange")])
    # station 5: one sample before the window, two in it, one after it
    for t, c in ((T - 120, counts(600, 9)), (T, counts(600, 2)), (T + 60, counts(580, 3, 1)),
                 (T + 3600, counts(600, 50))):
        h.write(samples=[Sample(t, 60.0, 5, "data exchange", c),
                         Sample(t, 60.0, 7, "data exchange", counts(600, 0))],
                bus=BusSample(t, 60.0, 7000, 1200, 0))
    name, _ = h.save_capture(T + 30, "rr5", [(0.0, b"\x10\x05\x02\x7d\x84\x16")], T + 30)
    h.write(events=[
        MonEvent(T - 60, "rr", 5, "before the window"),
        MonEvent(T + 30, "rr", 5, "retry limit <script>alert(1)</script>", "the cable at station 5",
                 ("retries 3 in 60 s", "only station 5"), 2, name),
        MonEvent(T + 45, "lost", 7, "station 7 lost"),
        MonEvent(T + 50, "nr", 5, "no answer", None, (), 0, "000099-gone.pcap"),
    ])
    h.end_run(T + 7200, "SIGTERM")
    h.close()


def test_report_for_a_station_over_a_window(tmp_path: Path, utc: None) -> None:
    build(tmp_path)
    r = Reader(tmp_path)
    try:
        doc = report(r, T, T + 600, station=5)
    finally:
        r.close()
    assert doc == {
        "store": str(tmp_path),
        "window": {"since": T, "until": T + 600, "since_iso": "2026-12-04T22:00:00+00:00",
                   "until_iso": "2026-12-04T22:10:00+00:00"},
        "station": 5,
        "runs": [{"id": 1, "started": T - 3600, "ended": T + 7200, "port": "/dev/ttyUSB0",
                  "baud": 1_500_000, "end_reason": "SIGTERM"}],
        "stations": [{"station": 5, "ident": 0x80B5, "ident_hex": "0x80B5", "profile": "sinamics",
                      "first_seen": T - 3600, "last_seen": T - 3600, "state": "data exchange",
                      "totals": {"exchanges": 600 + 580, "retries": 2 + 3, "no_answer": 1,
                                 "illegal": 0, "reparams": 0, "samples": 2, "seconds": 120.0}}],
        "events": [
            {"id": 4, "t": T + 50, "t_iso": "2026-12-04T22:00:50+00:00", "kind": "nr",
             "station": 5, "text": "no answer", "cause": None, "evidence": [], "repeats": 0,
             "capture": "000099-gone.pcap", "capture_present": False},
            {"id": 2, "t": T + 30, "t_iso": "2026-12-04T22:00:30+00:00", "kind": "rr",
             "station": 5, "text": "retry limit <script>alert(1)</script>",
             "cause": "the cable at station 5",
             "evidence": ["retries 3 in 60 s", "only station 5"], "repeats": 2,
             "capture": "000001-rr5.pcap", "capture_present": True},
        ],
        "events_total": 2,
        "events_listed": 2,
        "events_by_kind": {"nr": 1, "rr": 1},
    }
    json.dumps(doc)                                    # JSON-ready as it is


def test_report_of_all_stations_and_the_whole_history(tmp_path: Path, utc: None) -> None:
    build(tmp_path)
    r = Reader(tmp_path)
    try:
        doc = report(r, None, None)
    finally:
        r.close()
    assert [s["station"] for s in doc["stations"]] == [5, 7]
    assert doc["stations"][1]["totals"]["exchanges"] == 4 * 600
    assert doc["stations"][0]["totals"]["retries"] == 9 + 2 + 3 + 50
    assert doc["events_by_kind"] == {"lost": 1, "nr": 1, "rr": 2} and doc["events_total"] == 4
    assert doc["window"] == {"since": None, "until": None, "since_iso": None, "until_iso": None}
    text = report_text(doc)
    lines = text.splitlines()
    assert lines[0] == f"history {tmp_path}: the beginning .. now"
    assert ("2026-12-04T22:00:30+00:00  station 5   rr       retry limit <script>alert(1)</script>"
            "  likely: the cable at station 5  [000001-rr5.pcap]") in lines
    assert "2026-12-04T22:00:50+00:00  station 5   nr       no answer  [000099-gone.pcap, removed]" \
        in lines
    # one line per event, oldest first
    ev_lines = [ln for ln in lines if ln.startswith("2026-")]
    assert [ln.split()[3] for ln in ev_lines] == ["rr", "rr", "lost", "nr"]


def test_report_html_escapes_and_is_self_contained(tmp_path: Path, utc: None) -> None:
    build(tmp_path)
    r = Reader(tmp_path)
    try:
        page = report_html(report(r, None, None))
    finally:
        r.close()
    assert "<script>" not in page and "<script" not in page.lower()
    assert "retry limit &lt;script&gt;alert(1)&lt;/script&gt;" in page
    assert "http://" not in page and "https://" not in page and "src=" not in page
    assert page.startswith("<!DOCTYPE html>") and page.rstrip().endswith("</html>")
    assert "000099-gone.pcap (removed)" in page


def test_parse_since_forms(utc: None) -> None:
    now = T + 0.5
    assert parse_since("2026-12-04", now) == T - 22 * 3600
    assert parse_since("2026-12-04T22:00", now) == T
    assert parse_since("2026-12-04 22:00", now) == T
    assert parse_since("2026-12-04T22:00:30", now) == T + 30
    assert parse_since("90s", now) == now - 90
    assert parse_since("30m", now) == now - 1800
    assert parse_since("12h", now) == now - 12 * 3600
    assert parse_since("7d", now) == now - 7 * 86400
    assert parse_since("1.5h", now) == now - 5400


@pytest.mark.parametrize("bad", ["", "yesterday", "7", "7w", "-3h", "2026-13-01", "2026-12-04T25:00",
                                 "12 h ago", "2026/12/04"])
def test_parse_since_refusals(bad: str) -> None:
    with pytest.raises(UsageError) as e:
        parse_since(bad, T)
    text = str(e.value)
    assert "\n" not in text and text.startswith("--since ")
    assert "2026-12-04T22:00" in text and "12h" in text
