"""The monitor's web page, JSON and /metrics (profidrive_cli/monitor/web.py, metrics.py; issue 37),
over real HTTP to the app served by waitress on a port the OS picks.

The page's stable ids and classes (monitor/page/index.html, filled by monitor.js):
    #stations tbody tr[data-station="N"]   one row per station, class "state-COLOUR" (the live view's
                                           colour) and "selected" for the station whose trends show
    #causes li.cause                       a likely cause (strong: title; ul.evidence)
    #events tbody tr                       an event (class "kind-KIND"), td.cause, a.capture (the
                                           capture's link, ?token= when one is asked)
    #bus (dl), #status, #adapter, #error, #trends, #range, #trend-bus, #trend-station (SVG plots)
"""

from __future__ import annotations

import http.client
import json
import os
import pathlib
import subprocess
import sys
from typing import Any

import pytest

from conftest import CHROMIUM, chromium
from profidrive_cli.monitor import web
from profidrive_cli.monitor.model import SAMPLE_COUNTERS, MonEvent, state_colour

T0 = 1_764_900_000.0           # the monitor's clock (live()["t"]), not time.time()
CAPTURE = "20251205-020000-lost-st5.pcap"
# a pcap header (link type 147, USER0) and one record: 24 + 16 + 3 octets
PCAP = (bytes.fromhex("d4c3b2a1020004000000000000000000ffff000093000000")
        + bytes.fromhex("00000000000000000300000003000000") + b"\x10\x05\x02")


def _station(n: int, state: str, ident: int, profile: str, drive_state: str | None,
             fault: bool | None, exchanges: int, no_answer: int = 0) -> dict[str, Any]:
    counters = dict.fromkeys(SAMPLE_COUNTERS, 0)
    counters.update(exchanges=exchanges, no_answer=no_answer, retries=no_answer * 2)
    return {"station": n, "state": state, "colour": state_colour(state), "ident": ident,
            "ident_hex": f"0x{ident:04X}", "profile": profile, "drive_state": drive_state,
            "fault": fault, "counters": counters, "cycle_s": 0.004 if state == "data exchange" else None,
            "last_seen": T0 - (30.0 if state == "no answer" else 0.01)}


def live_view() -> dict[str, Any]:
    """The default simulated plant's five drives (stations 3..7), station 5 lost."""
    lost = MonEvent(T0 - 30.0, "lost", 5, "station 5 left data exchange (no answer)",
                    cause="station 5's cable or power", evidence=("3 no-answers in a row",
                                                                  "the others go on"),
                    capture=CAPTURE)
    return {
        "t": T0, "started": T0 - 3600.0, "port": "sim://?timing=virtual", "baud": 1_500_000,
        "adapter": "connected",
        "bus": {"frames": 912_345, "tokens": 450_000, "masters": [2], "load_percent": 41.5,
                "rotation_s": 0.0031, "cycle_s": 0.004, "errors": {"framing": 2, "fcs": 1}},
        "stations": [
            _station(3, "data exchange", 0x0A51, "fuji-g1", "running", False, 90_000),
            _station(4, "data exchange", 0x0C8F, "fuji-pdp3", "ready", False, 90_000),
            _station(5, "no answer", 0x09C6, "toyo", None, None, 60_000, no_answer=3),
            _station(6, "data exchange", 0x0B2D, "moeller", "running", False, 90_000),
            _station(7, "diagnosis", 0x0E13, "yaskawa", "fault", True, 89_000),
        ],
        "causes": [{"title": "station 5's cable or power", "score": 0.8, "stations": [5],
                    "evidence": ["3 no-answers in a row", "the others go on"]}],
        "events": [lost.as_dict()],
        "events_total": 1, "events_by_kind": {"lost": 1},
        "events_by_cause": {"station 5's cable or power": 1},
        "store": {"path": "/var/lib/pdrive", "bytes": 5_000_000, "max_bytes": 1_000_000_000,
                  "full": False, "removed": 0},
    }


class FakeReader:
    def __init__(self, root: pathlib.Path) -> None:
        self.root = root
        (root / "captures").mkdir()
        (root / "captures" / CAPTURE).write_bytes(PCAP)
        (root / "secret.txt").write_text("not a capture")
        self.calls: list[tuple[str, Any]] = []

    def events(self, since: float | None = None, until: float | None = None,
               station: int | None = None, limit: int = 1000) -> list[dict[str, Any]]:
        self.calls.append(("events", (since, until, station, limit)))
        ev = dict(live_view()["events"][0], id=1, capture_present=True)
        return [ev][:limit]

    def stations(self) -> list[dict[str, Any]]:
        return []

    def trend(self, station: int | None, since: float, until: float,
              buckets: int = 120) -> dict[str, Any]:
        self.calls.append(("trend", (station, since, until, buckets)))
        names = (["frames", "tokens", "errors", "load_percent", "rotation_s"] if station is None
                 else list(SAMPLE_COUNTERS))
        step = (until - since) / buckets
        return {"station": station, "since": since, "until": until,
                "t": [since + i * step for i in range(buckets)],
                "series": {n: [None if i % 17 == 5 else float(i % 7) for i in range(buckets)]
                           for n in names}}

    def capture_path(self, name: str) -> pathlib.Path | None:
        p = self.root / "captures" / name
        return p if p.parent == self.root / "captures" and p.is_file() else None


@pytest.fixture
def reader(tmp_path: pathlib.Path) -> FakeReader:
    return FakeReader(tmp_path)


@pytest.fixture
def server(reader: FakeReader):
    logged: list[str] = []
    s = web.serve(live_view, reader, "127.0.0.1", 0, log=logged.append)
    s.logged = logged  # type: ignore[attr-defined]
    try:
        yield s
    finally:
        s.close()


def get(port: int, path: str, headers: dict[str, str] | None = None, method: str = "GET",
        host: str = "127.0.0.1", body: bytes | None = None) -> tuple[int, dict[str, str], bytes]:
    c = http.client.HTTPConnection(host, port, timeout=60)
    try:
        c.request(method, path, body=body, headers=headers or {})
        r = c.getresponse()
        return r.status, {k.lower(): v for k, v in r.getheaders()}, r.read()
    finally:
        c.close()


def test_routes_and_status_codes(server, reader) -> None:
    st, h, body = get(server.port, "/")
    assert st == 200 and h["content-type"].startswith("text/html")
    assert b'id="stations"' in body and b"{{query}}" not in body and b'src="monitor.js"' in body
    for path, ctype in (("/monitor.js", "text/javascript"), ("/monitor.css", "text/css")):
        st, h, body = get(server.port, path)
        assert st == 200 and h["content-type"].startswith(ctype) and body
    st, h, body = get(server.port, "/api/live")
    assert st == 200 and h["cache-control"] == "no-store" and h["content-type"] == "application/json"
    assert [s["station"] for s in json.loads(body)["stations"]] == [3, 4, 5, 6, 7]
    # HEAD: the headers, no body
    st, h, body = get(server.port, "/api/live", method="HEAD")
    assert st == 200 and body == b""
    # trends: the monitor's clock, 24 h by default, the bus or a station
    st, _, body = get(server.port, "/api/trend?station=bus")
    tr = json.loads(body)
    assert st == 200 and tr["station"] is None and tr["until"] == T0 and tr["since"] == T0 - 86400
    assert len(tr["t"]) == 120 and set(tr["series"]) == {"frames", "tokens", "errors",
                                                         "load_percent", "rotation_s"}
    st, _, body = get(server.port, "/api/trend?station=5&hours=168&buckets=50")
    tr = json.loads(body)
    assert st == 200 and tr["station"] == 5 and tr["since"] == T0 - 168 * 3600 and len(tr["t"]) == 50
    # events, the limit capped
    st, _, body = get(server.port, "/api/events?since=1764800000&station=5&limit=10")
    assert st == 200 and json.loads(body)["events"][0]["capture"] == CAPTURE
    assert reader.calls[-1] == ("events", (1764800000.0, None, 5, 10))
    st, _, _ = get(server.port, "/api/events")
    assert st == 200 and reader.calls[-1] == ("events", (None, None, None, web.DEFAULT_EVENTS))
    # bad values name their parameter
    for path, name in (("/api/trend?hours=x", "hours"), ("/api/trend?hours=745", "hours"),
                       ("/api/trend?station=200", "station"), ("/api/trend?buckets=100000", "buckets"),
                       ("/api/events?limit=5000", "limit"), ("/api/events?station=five", "station"),
                       ("/api/events?since=nan", "since"), ("/api/events?limit=1&limit=2", "limit")):
        st, h, body = get(server.port, path)
        assert st == 400 and json.loads(body)["error"].startswith(name + ":"), path
    st, _, body = get(server.port, "/nowhere")
    assert st == 404 and "error" in json.loads(body)
    for method in ("POST", "PUT", "DELETE"):
        st, h, _ = get(server.port, "/api/live", method=method)
        assert st == 405 and h["allow"] == "GET, HEAD"
    # a body is never taken (waitress' max_request_body_size 0 or the app's own check)
    st, _, _ = get(server.port, "/api/live", method="GET", body=b"x" * 10)
    assert st in (400, 413)


def test_without_a_history(reader) -> None:
    s = web.serve(live_view, None, "127.0.0.1", 0, log=lambda line: None)
    try:
        assert get(s.port, "/api/live")[0] == 200
        for path in ("/api/trend", "/api/events", f"/captures/{CAPTURE}"):
            st, _, body = get(s.port, path)
            assert st == 404 and "history" in json.loads(body)["error"]
    finally:
        s.close()


def test_capture_download_and_traversal(server) -> None:
    st, h, body = get(server.port, f"/captures/{CAPTURE}")
    assert st == 200 and body == PCAP
    assert h["content-type"] == "application/vnd.tcpdump.pcap"
    assert h["content-disposition"] == f'attachment; filename="{CAPTURE}"'
    assert h["content-length"] == str(len(PCAP))
    for path in ("/captures/../secret.txt", "/captures/..%2Fsecret.txt", "/captures/%2e%2e%2fsecret.txt",
                 "/captures/.hidden", "/captures/", "/captures/nope.pcap",
                 "/captures/captures%2F" + CAPTURE, "/captures/..", "/captures/%00x"):
        st, _, body = get(server.port, path)
        assert st == 404 and b"not a capture" not in body, path


def test_host_and_origin_refused(server) -> None:
    port = server.port
    assert get(port, "/api/live", {"Host": "evil.example"})[0] == 403          # DNS rebinding
    assert get(port, "/api/live", {"Host": f"evil.example:{port}"})[0] == 403
    for host in (f"localhost:{port}", f"127.0.0.1:{port}", f"[::1]:{port}"):
        assert get(port, "/api/live", {"Host": host})[0] == 200, host
    h = {"Host": f"127.0.0.1:{port}"}
    assert get(port, "/api/live", dict(h, Origin="http://evil.example"))[0] == 403
    assert get(port, "/api/live", dict(h, Origin=f"http://127.0.0.1:{port + 1}"))[0] == 403
    assert get(port, "/api/live", dict(h, Origin=f"http://127.0.0.1:{port}"))[0] == 200
    assert get(port, "/api/live", dict(h, **{"Sec-Fetch-Site": "cross-site"}))[0] == 403
    assert get(port, "/api/live", dict(h, **{"Sec-Fetch-Site": "same-site"}))[0] == 403
    assert get(port, "/api/live", dict(h, **{"Sec-Fetch-Site": "same-origin"}))[0] == 200
    assert get(port, "/", dict(h, **{"Sec-Fetch-Site": "none"}))[0] == 200


def test_token_on_every_address_but_loopback(reader) -> None:
    assert web.needs_token("0.0.0.0") and web.needs_token("::") and web.needs_token("192.168.1.5")
    assert not web.needs_token("127.0.0.1") and not web.needs_token("::1")
    assert not web.needs_token("localhost")
    s = web.serve(live_view, reader, "0.0.0.0", 0, log=lambda line: None)
    try:
        assert s.token and len(s.token) >= 20
        port, tok = s.port, s.token
        for path in ("/", "/api/live", "/monitor.js", "/metrics", f"/captures/{CAPTURE}"):
            assert get(port, path)[0] == 401, path
            assert get(port, path, {"Authorization": "Bearer wrong"})[0] == 401
            assert get(port, path + "?token=wrong")[0] == 401
            assert get(port, path, {"Authorization": f"Bearer {tok}"})[0] == 200, path
            assert get(port, path + f"?token={tok}")[0] == 200, path
        # the page loads its script and style with the token, and the script sends it on
        # its fetches and its capture links
        st, _, page = get(port, f"/?token={tok}")
        assert st == 200
        assert f'src="monitor.js?token={tok}"'.encode() in page
        assert f'href="monitor.css?token={tok}"'.encode() in page
        _, _, js = get(port, f"/monitor.js?token={tok}")
        assert b'"Authorization": "Bearer " + token' in js and b"withToken(" in js
    finally:
        s.close()


def test_metrics(server) -> None:
    from prometheus_client.parser import text_string_to_metric_families
    st, h, body = get(server.port, "/metrics")
    assert st == 200 and h["content-type"].startswith("text/plain; version=0.0.4")
    samples: dict[str, list[tuple[dict[str, str], float]]] = {}
    for fam in text_string_to_metric_families(body.decode()):
        for smp in fam.samples:
            samples.setdefault(smp.name, []).append((smp.labels, smp.value))

    def one(name: str, **labels: str) -> float:
        got = [v for lab, v in samples[name] if all(lab.get(k) == x for k, x in labels.items())]
        assert len(got) == 1, (name, labels, samples.get(name))
        return got[0]

    for n, up in ((3, 1), (4, 1), (5, 0), (6, 1), (7, 0)):
        assert one("pdrive_station_up", station=str(n)) == up
        for c in SAMPLE_COUNTERS:
            one(f"pdrive_station_{c}_total", station=str(n))
    assert one("pdrive_station_up", station="3", ident="0x0A51", profile="fuji-g1") == 1
    assert one("pdrive_station_state", station="5", state="no answer") == 1
    assert one("pdrive_station_state", station="5", state="data exchange") == 0
    assert one("pdrive_station_state", station="7", state="diagnosis") == 1
    assert one("pdrive_station_exchanges_total", station="3") == 90_000
    assert one("pdrive_station_no_answer_total", station="5") == 3
    assert one("pdrive_station_retries_total", station="5") == 6
    assert one("pdrive_station_cycle_seconds", station="3") == 0.004
    assert not [lab for lab, _ in samples["pdrive_station_cycle_seconds"] if lab["station"] == "5"]
    assert one("pdrive_drive_fault", station="7", profile="yaskawa") == 1
    assert one("pdrive_drive_fault", station="3") == 0
    assert not [lab for lab, _ in samples["pdrive_drive_fault"] if lab["station"] == "5"]
    assert one("pdrive_bus_frames_total") == 912_345
    assert one("pdrive_bus_tokens_total") == 450_000
    assert one("pdrive_bus_errors_total", kind="framing") == 2
    assert one("pdrive_bus_errors_total", kind="fcs") == 1
    assert one("pdrive_bus_load_percent") == 41.5
    assert one("pdrive_token_rotation_seconds") == 0.0031
    assert one("pdrive_masters") == 1
    assert one("pdrive_events_total", kind="lost") == 1
    assert one("pdrive_events_by_cause_total", cause="station 5's cable or power") == 1
    assert one("pdrive_adapter_up") == 1
    assert one("pdrive_store_bytes") == 5_000_000
    assert one("pdrive_store_full") == 0


def test_metrics_of_a_sparse_view() -> None:
    """No store, no cause counts, no measurements yet: those series are absent, nothing fails."""
    from prometheus_client.parser import text_string_to_metric_families

    from profidrive_cli.monitor import metrics
    v = live_view()
    del v["events_by_cause"]
    v.update(store=None, adapter="lost", bus={"frames": 0, "tokens": 0, "masters": [],
                                             "load_percent": None, "rotation_s": None,
                                             "cycle_s": None, "errors": {}})
    names = {s.name for f in text_string_to_metric_families(metrics.render(v).decode())
             for s in f.samples}
    assert "pdrive_events_by_cause_total" not in names and "pdrive_store_bytes" not in names
    assert "pdrive_bus_load_percent" not in names and "pdrive_token_rotation_seconds" not in names
    assert {"pdrive_adapter_up", "pdrive_masters", "pdrive_station_up"} <= names


def test_a_failing_handler_is_one_line_and_it_goes_on(reader) -> None:
    logged: list[str] = []
    calls = {"n": 0}

    def live() -> dict[str, Any]:
        calls["n"] += 1
        if calls["n"] <= 3:
            raise RuntimeError("the engine is confused")
        return live_view()

    s = web.serve(live, reader, "127.0.0.1", 0, log=logged.append)
    try:
        for _ in range(3):
            st, _, body = get(s.port, "/api/live")
            assert st == 500 and "RuntimeError" in json.loads(body)["error"]
            assert b"Traceback" not in body
        # rate-limited: one line for the three (waitress may add its own "Task queue depth"
        # warning when a loaded machine leaves a request waiting: not this handler's)
        mine = [m for m in logged if "Task queue depth" not in m]
        assert len(mine) == 1 and "the engine is confused" in mine[0]
        assert get(s.port, "/api/live")[0] == 200
    finally:
        s.close()


def test_close_frees_the_port(reader) -> None:
    s = web.serve(live_view, reader, "127.0.0.1", 0, log=lambda line: None)
    port = s.port
    assert get(port, "/api/live")[0] == 200
    s.close()
    s2 = web.serve(live_view, reader, "127.0.0.1", port, log=lambda line: None)
    s2.close()


def test_no_waitress_at_import() -> None:
    code = ("import sys, profidrive_cli.monitor.web, profidrive_cli.monitor.metrics;"
            "bad = [m for m in sys.modules if m.split('.')[0] in ('waitress', 'prometheus_client')];"
            "print(bad); sys.exit(1 if bad else 0)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr


def test_without_the_extra_a_usage_error(monkeypatch) -> None:
    import profidrive_cli
    monkeypatch.setitem(sys.modules, "waitress", None)        # import waitress -> ImportError
    with pytest.raises(profidrive_cli.UsageError, match=r"pip install 'profidrive-cli\[monitor\]'"):
        web.serve(live_view, None, "127.0.0.1", 0)


def test_clients_for_limit() -> None:
    assert web.clients_for_limit(64) == 12 and web.clients_for_limit(1024) == 32
    assert web.clients_for_limit(10) == 2 and web.clients_for_limit(None) == web.MAX_CLIENTS


def test_the_page_in_a_browser(reader) -> None:
    if CHROMIUM is None:
        if os.environ.get("CI") == "true":
            pytest.fail("CI needs Debian's chromium for the page's browser test")
        pytest.skip("no chromium on this machine")
    from html.parser import HTMLParser
    s = web.serve(live_view, reader, "0.0.0.0", 0, log=lambda line: None)
    try:
        dom = chromium(f"http://127.0.0.1:{s.port}/?token={s.token}", "--dump-dom")
    finally:
        s.close()

    class Rows(HTMLParser):
        def __init__(self) -> None:
            super().__init__()
            self.rows: dict[str, str] = {}
            self.links: list[str] = []
            self.section: list[str] = []
            self.events = 0
            self.causes = 0
            self.plots = 0

        def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
            a = dict(attrs)
            if tag == "table":
                self.section.append(a.get("id") or "")
            if tag == "tr" and "data-station" in a:
                self.rows[a["data-station"] or ""] = a.get("class") or ""
            if tag == "tr" and self.section and self.section[-1] == "events" \
                    and (a.get("class") or "").startswith("kind-"):
                self.events += 1
            if tag == "a" and a.get("class") == "capture":
                self.links.append(a.get("href") or "")
            if tag == "li" and a.get("class") == "cause":
                self.causes += 1
            if tag == "polyline":
                self.plots += 1

        def handle_endtag(self, tag: str) -> None:
            if tag == "table" and self.section:
                self.section.pop()

    r = Rows()
    r.feed(dom)
    assert {k: set(v.split()) - {"selected"} for k, v in r.rows.items()} == {
        "3": {"state-green"}, "4": {"state-green"}, "5": {"state-red"}, "6": {"state-green"},
        "7": {"state-yellow"}}, dom[:3000]
    assert r.events == 1 and r.causes == 1
    assert "station 5&#39;s cable or power" in dom or "station 5's cable or power" in dom
    assert r.links == [f"captures/{CAPTURE}?token={s.token}"]
    assert r.plots > 0                      # the trends drawn from /api/trend


def test_idle_and_slow_clients_hold_no_worker(server) -> None:
    """Clients that connect and send half a request (or nothing) hold no worker thread: a request
    beside them is answered (waitress reads requests asynchronously; web.THREADS workers)."""
    import socket
    held = []
    try:
        for i in range(web.THREADS * 2):
            c = socket.create_connection(("127.0.0.1", server.port), timeout=60)
            if i % 2:
                c.sendall(b"GET /api/live HTTP/1.1\r\nHost: 127.0.0.1\r\n")    # never finished
            held.append(c)
        assert get(server.port, "/api/live")[0] == 200
    finally:
        for c in held:
            c.close()


def test_too_many_query_fields() -> None:
    app = web.make_app(live_view, None, None, {"127.0.0.1"}, log=lambda line: None)
    got: list[str] = []
    body = b"".join(app({"REQUEST_METHOD": "GET", "PATH_INFO": "/api/live",
                         "QUERY_STRING": "&".join(f"a{i}=1" for i in range(40)),
                         "HTTP_HOST": "127.0.0.1"}, lambda status, headers: got.append(status)))
    assert got == ["400 Bad Request"] and json.loads(body)["error"].startswith("query:")
