"""Issue 37's "done when", end to end over real processes: `pdrive sim --plc` runs a five-station
plant on one end of a socat pty pair, `pdrive monitor` listens on the other end with the page on a
port the OS picks; station 5 is unplugged 4 s after the PLC's first telegram for 5 s
(sim://?unplug=5@4-9). Then:

- /metrics has the per-station series of all five stations (the default plant: stations 3..7,
  sim/plant.py), each learned drive with its profile;
- headless Chromium renders the page with five station rows and the lost(5) event;
- SIGTERM (systemd's stop) ends the monitor with exit 0, its JSON stream keeps docs/json.md;
- `pdrive monitor report --json` lists the lost(5) event with its likely cause (the silent-station
  rule: the others answered while it was silent) and a capture that is on disk and holds station 5's
  telegrams; the report keeps docs/json.md.

Bounds are generous (a loaded machine): each wait is up to 90 s, the unplug needs 4 + 5 s of line.
"""

from __future__ import annotations

import json
import os
import queue
import signal
import subprocess
import threading
import time
import urllib.request
from html.parser import HTMLParser

import pytest

from conftest import CHROMIUM, chromium, pdrive_cmd, stop_pty_sim
from test_json_contract import assert_contract, assert_stream
from profidrive_cli.dp.capture import read_pcap
from profidrive_cli.fdl import frames as F

STATIONS = {3, 4, 5, 6, 7}           # sim/plant.py's default plant
WAIT_S = 90.0


def _lines(stream, into: queue.Queue) -> None:
    for line in iter(stream.readline, ""):
        into.put(line)
    into.put(None)


def _next_json(q: queue.Queue, until, what: str, seen: list[dict]) -> dict:
    end = time.monotonic() + WAIT_S
    while time.monotonic() < end:
        try:
            line = q.get(timeout=0.5)
        except queue.Empty:
            continue
        if line is None:
            break
        d = json.loads(line)
        seen.append(d)
        if until(d):
            return d
    pytest.fail(f"no {what} within {WAIT_S:.0f} s; heard: {[d.get('kind', d['event']) for d in seen]}")


def _metrics(port: int) -> str:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=30) as r:
        return r.read().decode()


def _up_stations(text: str) -> set[int]:
    """The stations with a pdrive_station_up series (labels in any order)."""
    found = set()
    for line in text.splitlines():
        if line.startswith("pdrive_station_up{"):
            labels = line[line.index("{") + 1:line.index("}")]
            for part in labels.split(","):
                k, _, v = part.partition("=")
                if k == "station":
                    found.add(int(v.strip('"')))
    return found


class _Page(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.stations: set[str] = set()
        self.kinds: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if tag == "tr" and "data-station" in a:
            self.stations.add(a["data-station"] or "")
        if tag == "tr" and (a.get("class") or "").startswith("kind-"):
            self.kinds.append((a.get("class") or "")[5:].split()[0])


def test_a_monitor_on_a_plc_line_sees_an_unplugged_station(socat_pair, tmp_path):
    a, b = socat_pair
    db = tmp_path / "line"
    db.mkdir()
    mon = subprocess.Popen(pdrive_cmd() + ["monitor", "--port", b, "--db", str(db),
                                           "--web", "127.0.0.1:0", "--ring", "10", "--after", "3",
                                           "--json"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    q: queue.Queue = queue.Queue()
    threading.Thread(target=_lines, args=(mon.stdout, q), daemon=True).start()
    seen: list[dict] = []
    sim = None
    try:
        web = _next_json(q, lambda d: d["event"] == "web", "web line", seen)
        port = web["port"]
        assert web["token"] is None and web["url"] == f"http://127.0.0.1:{port}/"
        sim = subprocess.Popen(pdrive_cmd() + ["sim", "--plc", "--port", a, "--plant",
                                               "sim://?unplug=5@4-9", "--json"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        # the five stations with their series on /metrics, once each has been heard
        end = time.monotonic() + WAIT_S
        text = ""
        while time.monotonic() < end and _up_stations(text) != STATIONS:
            time.sleep(0.5)
            text = _metrics(port)
        assert _up_stations(text) == STATIONS, text[:2000]
        for n in STATIONS:
            assert f'pdrive_station_exchanges_total{{station="{n}"}}' in text
        lost = _next_json(q, lambda d: d.get("kind") == "lost" and d.get("station") == 5,
                          "lost(5) event", seen)
        assert lost["cause"] and "station 5" in lost["cause"], lost
        assert lost["capture"] and (db / "captures" / lost["capture"]).is_file()
        if CHROMIUM is not None:
            page = _Page()
            page.feed(chromium(f"http://127.0.0.1:{port}/", "--dump-dom"))
            assert page.stations == {str(n) for n in STATIONS}
            assert "lost" in page.kinds
        elif os.environ.get("CI") == "true":
            pytest.fail("CI needs Debian's chromium for the page's browser test")
        mon.send_signal(signal.SIGTERM)
        mon.wait(timeout=60)
        _next_json(q, lambda d: d["event"] == "end", "end line", seen)
    finally:
        if mon.poll() is None:
            mon.kill()
            mon.wait()
        if sim is not None:
            stop_pty_sim(sim)
    err = mon.stderr.read()
    assert mon.returncode == 0, err
    assert "Traceback" not in err
    assert assert_stream(seen, "monitor")[0] == "web"
    end = seen[-1]
    assert end["event"] == "end" and end["ended"] == "stopped" and end["adapter_losses"] == 0

    rep = subprocess.run(pdrive_cmd() + ["monitor", "report", "--db", str(db), "--json"],
                         capture_output=True, text=True, timeout=120)
    assert rep.returncode == 0, rep.stderr
    doc = json.loads(rep.stdout)
    assert_contract(doc, "monitor report")
    assert {s["station"] for s in doc["stations"]} == STATIONS
    assert doc["runs"][0]["end_reason"] == "stopped"
    lost5 = [e for e in doc["events"] if e["kind"] == "lost" and e["station"] == 5]
    assert len(lost5) == 1, doc["events"]
    ev = lost5[0]
    assert ev["cause"] == lost["cause"] and ev["capture"] == lost["capture"] and ev["capture_present"]
    linktype, pkts = read_pcap((db / "captures" / ev["capture"]).read_bytes())
    assert linktype == 147
    frames = [F.parse(raw) for _, raw in pkts]
    frames = [r[0] for r in frames if r is not None and not isinstance(r, F.FrameError)]
    # the capture holds station 5's answers from before and the master's unanswered requests to it
    assert any(f.sd not in (F.SC, F.SD4) and not f.is_request and f.sa == 5 for f in frames)
    assert any(f.sd not in (F.SC, F.SD4) and f.is_request and f.da == 5 for f in frames)
