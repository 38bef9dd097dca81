"""Issue 37's soak in virtual time: `pdrive monitor` on the virtual plant (sim/virtual_line.py) for
seven virtual days of a faulty line, in a separate process, with a 2 MiB disk bound.

The plant (URL below): five stations (the default plant), the master's cycle CYCLE_S, replies dropped
now and then (drop=), drives tripping now and then (drivetrip=, reset by the operator 60 s later),
and every 6 h (repeat=21600): station 5 unplugged from 600 s to 900 s, a second master (address 1)
in the token ring from 3000 s to 3400 s, the listener's adapter pulled from 5000 s to 5030 s.

By hand: windows at 600 + k * 21600 < 604800 s, k = 0..27: 28 unplugs, 28 pulls (56 adapter events,
adapter_losses 28). Each unplug is 600 s of silence, at least 4 rounds of CYCLE_S (120 s) -- one
lost(5) and one back(5) each; a drop is one reply, never 4 rounds in a row.

What must hold: exit 0 after --duration; every event on the stream keeps docs/json.md; the history
and its captures together within 2 MiB, the oldest removed (said: `removed` events); the report lists
the newest events with captures on disk; the peak RSS of the week no more than RSS_SLACK_MB above that
of one day of the same plant (memory flat in the length of the run); a restart on the same history
resumes it (a second run, capture numbers going on).

CYCLE_S is 120 s (the virtual line's longest) so that the week costs about a minute of CPU (the
line's master and stations are simulated telegram by telegram: about 3 ms a cycle); PDRIVE_SOAK_CYCLE=10
runs the same soak at a 10 s cycle (about 6 minutes).
"""

from __future__ import annotations

import json
import os
import re
import subprocess

from conftest import pdrive_cmd
from test_json_contract import assert_contract, assert_stream

DAY_S = 86_400
WEEK_S = 7 * DAY_S
REPEAT_S = 21_600
MAX_DISK = 2 * 1024 * 1024
CYCLE_S = float(os.environ.get("PDRIVE_SOAK_CYCLE", "120"))
#: the week may hold more than one day in the pages of SQLite's cache, the captures' ring (30 s of a
#: slow line: a few dozen telegrams) and Python's allocator: 16 MiB is generous; a leak per
#: telegram or per sample would grow 7 times as much in the week as in the day
RSS_SLACK_MB = 16
PLANT = ("sim://?timing=virtual&cycle={cycle:g}&seed=7&drop=0.001&drivetrip=0.0002&ack=60"
         "&unplug=5@600-1200&master2=1@3000-3400&adapter=5000-5030&repeat=21600")
WINDOWS = len(range(600, WEEK_S, REPEAT_S))          # 28


def _monitor(db, seconds: float, *extra: str) -> tuple[int, list[dict], str, int]:
    """Run the monitor for `seconds` of the line; (exit code, JSON lines, stderr, peak RSS in KiB)."""
    with open(db.parent / f"{db.name}.out", "w+") as out, open(db.parent / f"{db.name}.err", "w+") as err:
        p = subprocess.Popen(pdrive_cmd() + ["monitor", "--db", str(db), "--max-disk", str(MAX_DISK),
                                             "--duration", str(seconds), "--json",
                                             "--port", PLANT.format(cycle=CYCLE_S), *extra],
                             stdout=out, stderr=err, stdin=subprocess.DEVNULL)
        try:
            _, status, usage = os.wait4(p.pid, 0)
            p.returncode = os.waitstatus_to_exitcode(status)
        finally:
            if p.returncode is None:
                p.kill()
                p.wait()
        out.seek(0)
        err.seek(0)
        lines = [json.loads(line) for line in out if line.strip()]
        return p.returncode, lines, err.read(), usage.ru_maxrss


def _disk(db) -> int:
    return sum(f.stat().st_size for f in db.rglob("*") if f.is_file())


def _report(db) -> dict:
    r = subprocess.run(pdrive_cmd() + ["monitor", "report", "--db", str(db), "--json"],
                       capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL)
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert_contract(doc, "monitor report")
    return doc


def _count(lines: list[dict], kind: str, station: int | None = None) -> int:
    """Events of a kind (and station), with the same event repeated inside its capture."""
    return sum(1 + d["repeats"] for d in lines if d["event"] == "monitor" and d["kind"] == kind
               and (station is None or d["station"] == station))


def test_a_virtual_week_of_a_faulty_line(tmp_path):
    day, week = tmp_path / "day", tmp_path / "week"
    day.mkdir()
    week.mkdir()
    rc, _, err, rss_day = _monitor(day, DAY_S)
    assert rc == 0 and "Traceback" not in err, err[-2000:]

    rc, lines, err, rss_week = _monitor(week, WEEK_S)
    assert rc == 0 and "Traceback" not in err, err[-2000:]
    kinds = assert_stream(lines, "monitor")
    end = lines[-1]
    assert kinds[-1] == "end" and end["ended"] == "duration"
    assert abs(end["seconds"] - WEEK_S) < 2 * CYCLE_S
    assert end["adapter_losses"] == WINDOWS
    assert _count(lines, "adapter") == 2 * WINDOWS           # lost and back, each pull
    assert _count(lines, "lost", 5) == WINDOWS
    assert _count(lines, "back", 5) >= WINDOWS
    assert _count(lines, "master") >= 1                       # the second master, the first time
    assert "removed" in kinds                                 # the disk bound made good, said
    # the bound holds at the end (the store and its captures together, after the run is closed)
    assert _disk(week) <= MAX_DISK
    # memory: flat in the length of the run
    assert rss_week <= rss_day + RSS_SLACK_MB * 1024, (rss_day, rss_week)

    doc = _report(week)
    assert len(doc["runs"]) == 1 and doc["runs"][0]["end_reason"] == "duration"
    assert {s["station"] for s in doc["stations"]} == {3, 4, 5, 6, 7}
    # the oldest went for the bound: fewer events kept than heard, the newest kept with captures
    heard = sum(1 for d in lines if d["event"] == "monitor")
    assert 0 < doc["events_total"] < heard
    newest = [e for e in doc["events"] if e["capture"]][0]   # (adapter, disk: no capture)
    assert newest["capture_present"]
    assert (week / "captures" / newest["capture"]).is_file()
    assert any(e["kind"] == "lost" and e["station"] == 5 and e["cause"] for e in doc["events"])


def test_a_restart_resumes_the_history(tmp_path):
    db = tmp_path / "line"
    db.mkdir()
    rc, first, err, _ = _monitor(db, 4 * 3600)               # 600-1200 s: station 5 unplugged
    assert rc == 0, err[-2000:]
    rc, second, err, _ = _monitor(db, 4 * 3600)
    assert rc == 0, err[-2000:]
    doc = _report(db)
    assert [r["end_reason"] for r in doc["runs"]] == ["duration", "duration"]
    # a virtual plant's clock runs ahead of the wall's: the second run follows the first
    assert doc["runs"][1]["started"] >= doc["runs"][0]["ended"]

    def numbers(lines: list[dict]) -> set[int]:
        return {int(re.match(r"\d+", d["capture"]).group()) for d in lines
                if d["event"] == "monitor" and d["capture"]}
    one, two = numbers(first), numbers(second)
    assert one and two and min(two) > max(one)               # capture numbers go on
    assert _count(first, "lost", 5) == 1 and _count(second, "lost", 5) == 1
    assert sum(1 for e in doc["events"] if e["kind"] == "lost" and e["station"] == 5) == 2
