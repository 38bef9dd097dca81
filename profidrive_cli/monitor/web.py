"""The monitor's web page, its JSON and /metrics (`pdrive monitor --web HOST:PORT`): a WSGI
application of our own (a small router over PATH_INFO) served by waitress (extra `monitor`, a
pure-Python WSGI server) in a daemon thread. It only reads: the live view through `live()` (the
engine's Monitor.live(), monitor/model.py) and the history through a HistoryReader (store.py's
Reader; None: no trends, no event search, no captures). It never reaches the bus loop: a slow or
hostile client holds at most one of waitress' threads and one of its bounded connections.

Routes (GET and HEAD only, anything else 405; unknown 404; JSON answers carry Cache-Control: no-store):

    /                the page (page/index.html; monitor.js and monitor.css beside it, no CDN)
    /api/live        the live view
    /api/trend       ?station=N|bus&hours=H(&buckets=B): reader.trend over the last H hours of the
                     monitor's own clock (live()["t"]), H at most 24*31, B at most MAX_BUCKETS
    /api/events      ?since=UNIX&until=UNIX&station=N&limit=N: reader.events, limit at most MAX_EVENTS
    /captures/NAME   a capture of the history (pcap), streamed in chunks; a name with a path in it 404
    /metrics         the Prometheus text exposition of the live view (metrics.py)

The rules of every HTTP endpoint of pdrive (profidrive_cli/httprules.py, shared with sim --control):

- loopback by default; on any other address (needs_token) a token is printed at start and every
  request carries it (`Authorization: Bearer TOKEN` or `?token=TOKEN`; the page keeps the one of its
  own URL and sends it on its fetches and links), compared in constant time, else 401;
- a request whose Host is not a name of this server (DNS rebinding), whose Origin is not the server
  itself, or that a browser marks cross-site (Sec-Fetch-Site), is refused 403 (CSRF);
- bounded: waitress' connection_limit (from the descriptor limit: clients_for_limit), a channel
  timeout for an idle connection, no request body (max_request_body_size 0);
- a bad query value: 400 with a JSON error naming the parameter; a fault of a handler: 500 JSON and
  one line through `log` (at most one a minute, with a count), never a traceback; it goes on.
"""

from __future__ import annotations

import hmac
import html
import json
import logging
import math
import pathlib
import re
import secrets
import threading
import time
from importlib import resources
from typing import Any, Callable, Iterable, Iterator, Protocol
from urllib.parse import parse_qs

from profidrive_cli import UsageError, httprules

#: the port `--web` binds when none is given
DEFAULT_PORT = 8470
#: connections at a time, at most (fewer under a low descriptor limit: clients_for_limit)
MAX_CLIENTS = 32
#: waitress' worker threads (a request is short: a live view, a trend, a chunk of a capture)
THREADS = 4
#: an idle connection is closed after this long
CHANNEL_TIMEOUT_S = 30.0
#: /api/trend: the longest window (hours) and the most buckets
MAX_HOURS = 24 * 31
MAX_BUCKETS = 1000
DEFAULT_BUCKETS = 120
#: /api/events: the most events per answer (and the default)
MAX_EVENTS = 1000
DEFAULT_EVENTS = 200
#: a capture is sent in chunks of this many octets
CHUNK = 64 * 1024
#: a capture's name: what store.py writes (no path, no leading dot)
CAPTURE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,200}")
#: the page's static files (package data beside this module)
PAGE_FILES = {"/": ("index.html", "text/html; charset=utf-8"),
              "/index.html": ("index.html", "text/html; charset=utf-8"),
              "/monitor.js": ("monitor.js", "text/javascript; charset=utf-8"),
              "/monitor.css": ("monitor.css", "text/css; charset=utf-8")}
#: in index.html, replaced by "?token=TOKEN" (or nothing) so that its script and style load with it
QUERY_MARK = "{{query}}"

LiveFn = Callable[[], dict[str, Any]]
StartResponse = Callable[..., Any]
WSGIApp = Callable[[dict[str, Any], StartResponse], Iterable[bytes]]

_SECURITY_HEADERS = [
    ("X-Content-Type-Options", "nosniff"),
    ("Referrer-Policy", "no-referrer"),
    ("X-Frame-Options", "DENY"),
    ("Content-Security-Policy", "default-src 'none'; script-src 'self'; style-src 'self'; "
                                "connect-src 'self'; img-src 'self' data:; frame-ancestors 'none'; "
                                "base-uri 'none'; form-action 'none'"),
]


class HistoryReader(Protocol):
    """What the page reads of the history (store.py's Reader)."""

    def events(self, since: float | None = None, until: float | None = None,
               station: int | None = None, limit: int = 1000) -> list[dict[str, Any]]:
        """MonEvent.as_dict() keys + "id" + "capture_present", newest first."""
        ...

    def stations(self) -> list[dict[str, Any]]:
        ...

    def trend(self, station: int | None, since: float, until: float,
              buckets: int = 120) -> dict[str, Any]:
        """{"station", "since", "until", "t": [bucket starts], "series": {name: [number | None]}};
        station None: the bus (frames, tokens, errors, load_percent, rotation_s), a station:
        exchanges, retries, no_answer, illegal, reparams."""
        ...

    def capture_path(self, name: str) -> pathlib.Path | None:
        """An own capture file that exists, else None."""
        ...


# -- the rules of an HTTP endpoint (httprules.py) ---------------------------------------------

def clients_for_limit(nofile: int | None) -> int:
    """How many connections the page can afford under a descriptor limit `nofile` (httprules.py):
    12 at a limit of 64, MAX_CLIENTS at 1,024."""
    return httprules.clients_for_limit(nofile, MAX_CLIENTS)


_nofile = httprules.nofile
is_loopback, needs_token = httprules.is_loopback, httprules.needs_token
host_name, names_for, own_host = httprules.host_name, httprules.names_for, httprules.own_host


def foreign(environ: dict[str, Any], names: set[str]) -> str | None:
    """Why a request comes from somewhere else (403), or None."""
    return httprules.foreign(environ.get("HTTP_HOST"), environ.get("HTTP_SEC_FETCH_SITE"),
                             environ.get("HTTP_ORIGIN"), names, "monitor")


def token_ok(token: str | None, environ: dict[str, Any], query: dict[str, list[str]]) -> bool:
    """No token asked, or the request carries it (Authorization: Bearer, or ?token=)."""
    if token is None:
        return True
    want = token.encode()
    auth = str(environ.get("HTTP_AUTHORIZATION", ""))
    if auth.startswith("Bearer ") and hmac.compare_digest(
            auth[7:].strip().encode("latin-1", "replace"), want):
        return True
    given = query.get("token", [])
    return len(given) == 1 and hmac.compare_digest(given[0].encode("utf-8", "replace"), want)


class Reports:
    """One line through `log` at most every `every_s` seconds; the lines held back in between are
    counted and said with the next one."""

    def __init__(self, log: Callable[[str], None], every_s: float = 60.0) -> None:
        self.log, self.every_s = log, every_s
        self._last: float | None = None
        self._held = 0
        self._lock = threading.Lock()

    def __call__(self, line: str) -> None:
        now = time.monotonic()
        with self._lock:
            if self._last is not None and now - self._last < self.every_s:
                self._held += 1
                return
            held, self._held, self._last = self._held, 0, now
        try:
            self.log(line + (f" (and {held} more since the last report)" if held else ""))
        except Exception:                       # noqa: BLE001  (a log that fails is no reason to stop)
            pass


# -- the application ------------------------------------------------------------------------------

class BadQuery(ValueError):
    """A query value that is not what the route takes (400)."""


def _one(query: dict[str, list[str]], name: str) -> str | None:
    values = query.get(name)
    if not values:
        return None
    if len(values) > 1:
        raise BadQuery(f"{name}: given {len(values)} times")
    return values[0]


def _number(query: dict[str, list[str]], name: str, lo: float, hi: float) -> float | None:
    raw = _one(query, name)
    if raw is None:
        return None
    try:
        v = float(raw)
    except ValueError:
        raise BadQuery(f"{name}: {raw[:40]!r} is not a number") from None
    if not math.isfinite(v) or not lo <= v <= hi:
        raise BadQuery(f"{name}: {raw[:40]!r} is not between {lo:g} and {hi:g}")
    return v


def _integer(query: dict[str, list[str]], name: str, lo: int, hi: int) -> int | None:
    raw = _one(query, name)
    if raw is None:
        return None
    try:
        v = int(raw, 10)
    except ValueError:
        raise BadQuery(f"{name}: {raw[:40]!r} is not a whole number") from None
    if not lo <= v <= hi:
        raise BadQuery(f"{name}: {raw[:40]!r} is not between {lo} and {hi}")
    return v


def _page_file(name: str) -> bytes:
    return resources.files("profidrive_cli.monitor").joinpath("page").joinpath(name).read_bytes()


class _Capture:
    """A capture file sent in chunks of CHUNK octets, closed when the server is done with it."""

    def __init__(self, f: Any) -> None:
        self.f = f

    def __iter__(self) -> Iterator[bytes]:
        while True:
            chunk = self.f.read(CHUNK)
            if not chunk:
                return
            yield chunk

    def close(self) -> None:
        self.f.close()


class App:
    """The WSGI application: make_app's answer (callable as environ, start_response)."""

    def __init__(self, live: LiveFn, reader: HistoryReader | None, token: str | None,
                 names: set[str], log: Callable[[str], None]) -> None:
        self.live, self.reader, self.token = live, reader, token
        self.names = {n.lower().strip("[]") for n in names}
        self.report = Reports(log)
        #: requests answered 500 (a fault of a handler)
        self.errors = 0

    # each answer: status, headers, body
    def __call__(self, environ: dict[str, Any], start_response: StartResponse) -> Iterable[bytes]:
        head = environ.get("REQUEST_METHOD", "GET") == "HEAD"
        try:
            status, headers, body = self.route(environ)
        except Exception as e:                  # noqa: BLE001  (one line, never a traceback)
            self.errors += 1
            path = str(environ.get("PATH_INFO", ""))[:80]
            self.report(f"web: {path!r} failed: {type(e).__name__}: {str(e)[:200]}")
            status, headers, body = self._json(500, {"error": f"{path} failed in the monitor: "
                                                              f"{type(e).__name__}"})
        start_response(status, headers + _SECURITY_HEADERS)
        if head:
            if isinstance(body, _Capture):
                body.close()
            return [b""]
        return body

    @staticmethod
    def _json(code: int, obj: Any) -> tuple[str, list[tuple[str, str]], Iterable[bytes]]:
        data = json.dumps(obj, default=str).encode()
        headers = [("Content-Type", "application/json"), ("Cache-Control", "no-store"),
                   ("Content-Length", str(len(data)))]
        if code == 401:
            headers.append(("WWW-Authenticate", "Bearer"))
        reason = {200: "OK", 400: "Bad Request", 401: "Unauthorized", 403: "Forbidden",
                  404: "Not Found", 405: "Method Not Allowed", 413: "Payload Too Large",
                  500: "Internal Server Error"}[code]
        if code == 405:
            headers.append(("Allow", "GET, HEAD"))
        return f"{code} {reason}", headers, [data]

    def route(self, environ: dict[str, Any]) -> tuple[str, list[tuple[str, str]], Iterable[bytes]]:
        why = foreign(environ, self.names)
        if why is not None:
            return self._json(403, {"error": f"refused: {why}"})
        try:
            query = parse_qs(str(environ.get("QUERY_STRING", "")), keep_blank_values=True,
                             max_num_fields=32)
        except ValueError:
            return self._json(400, {"error": "query: more than 32 fields"})
        if not token_ok(self.token, environ, query):
            return self._json(401, {"error": "this monitor needs its token (Authorization: Bearer "
                                             "TOKEN, or ?token=TOKEN in the page's address)"})
        method = environ.get("REQUEST_METHOD", "GET")
        if method not in ("GET", "HEAD"):
            return self._json(405, {"error": f"{str(method)[:20]}: the monitor only answers GET"})
        if str(environ.get("CONTENT_LENGTH") or "0") not in ("", "0"):
            return self._json(413, {"error": "the monitor takes no request body"})
        path = str(environ.get("PATH_INFO", "/")) or "/"
        try:
            if path in PAGE_FILES:
                return self._page(path)
            if path == "/api/live":
                return self._json(200, self.live())
            if path == "/api/trend":
                return self._trend(query)
            if path == "/api/events":
                return self._events(query)
            if path == "/metrics":
                from profidrive_cli.monitor import metrics
                data = metrics.render(self.live())
                return "200 OK", [("Content-Type", metrics.CONTENT_TYPE),
                                  ("Cache-Control", "no-store"),
                                  ("Content-Length", str(len(data)))], [data]
            if path.startswith("/captures/"):
                return self._capture(path[len("/captures/"):])
        except BadQuery as e:
            return self._json(400, {"error": str(e)})
        return self._json(404, {"error": f"no such page: {path[:80]}"})

    def _page(self, path: str) -> tuple[str, list[tuple[str, str]], Iterable[bytes]]:
        name, ctype = PAGE_FILES[path]
        data = _page_file(name)
        if name == "index.html":
            q = f"?token={html.escape(self.token)}" if self.token else ""
            data = data.replace(QUERY_MARK.encode(), q.encode())
        return "200 OK", [("Content-Type", ctype), ("Cache-Control", "no-cache"),
                          ("Content-Length", str(len(data)))], [data]

    def _no_history(self) -> tuple[str, list[tuple[str, str]], Iterable[bytes]]:
        return self._json(404, {"error": "this monitor keeps no history (no --db)"})

    def _trend(self, query: dict[str, list[str]]) -> tuple[str, list[tuple[str, str]], Iterable[bytes]]:
        raw = _one(query, "station")
        station: int | None = None
        if raw is not None and raw != "bus":
            station = _integer(query, "station", 0, 126)
        hours = _number(query, "hours", 1 / 60, MAX_HOURS)
        buckets = _integer(query, "buckets", 1, MAX_BUCKETS)
        if self.reader is None:
            return self._no_history()
        until = float(self.live().get("t") or time.time())
        since = until - (24.0 if hours is None else hours) * 3600.0
        return self._json(200, self.reader.trend(station, since, until,
                                                 DEFAULT_BUCKETS if buckets is None else buckets))

    def _events(self, query: dict[str, list[str]]) -> tuple[str, list[tuple[str, str]], Iterable[bytes]]:
        since = _number(query, "since", 0, 1e12)
        until = _number(query, "until", 0, 1e12)
        station = _integer(query, "station", 0, 126)
        limit = _integer(query, "limit", 1, MAX_EVENTS)
        if self.reader is None:
            return self._no_history()
        return self._json(200, {"events": self.reader.events(
            since=since, until=until, station=station,
            limit=DEFAULT_EVENTS if limit is None else limit)})

    def _capture(self, name: str) -> tuple[str, list[tuple[str, str]], Iterable[bytes]]:
        if self.reader is None:
            return self._no_history()
        if CAPTURE_NAME.fullmatch(name) is None or ".." in name:
            return self._json(404, {"error": f"no such capture: {name[:80]!r}"})
        p = self.reader.capture_path(name)
        if p is None or p.name != name or not p.is_file():
            return self._json(404, {"error": f"no such capture: {name!r}"})
        f = open(p, "rb")
        try:
            size = pathlib.Path(p).stat().st_size
        except OSError:
            f.close()
            raise
        return "200 OK", [("Content-Type", "application/vnd.tcpdump.pcap"),
                          ("Content-Disposition", f'attachment; filename="{name}"'),
                          ("Cache-Control", "no-store"),
                          ("Content-Length", str(size))], _Capture(f)


def make_app(live: LiveFn, reader: HistoryReader | None, token: str | None, names: set[str],
             log: Callable[[str], None] | None = None) -> WSGIApp:
    """The page's WSGI application: `live()` the live view, `reader` the history (None: none),
    `token` asked of every request (None: none), `names` the Host names it answers (names_for)."""
    return App(live, reader, token, names, log or _stderr_line)


def _stderr_line(line: str) -> None:
    import sys
    try:
        print(line, file=sys.stderr, flush=True)
    except (OSError, ValueError):
        pass


# -- the server ----------------------------------------------------------------------------------

class _ToLog(logging.Handler):
    """waitress' own log lines (a socket error, a queue too deep) as one rate-limited line each,
    never a traceback on stderr."""

    def __init__(self, report: Reports) -> None:
        super().__init__(logging.WARNING)
        self.report = report

    def emit(self, record: logging.LogRecord) -> None:
        try:
            msg = record.getMessage()
        except Exception:                       # noqa: BLE001
            msg = str(record.msg)
        exc = record.exc_info[1] if record.exc_info else None
        tail = f": {type(exc).__name__}: {str(exc)[:200]}" if exc is not None else ""
        self.report(f"web: {msg[:200]}{tail}")


class WebServer:
    """A running page: `url` (with the actual port), `token` (None on loopback), `close()`."""

    def __init__(self, server: Any, app: App, host: str, token: str | None,
                 handler: logging.Handler) -> None:
        self._server, self.app, self.host, self.token = server, app, host, token
        self.port = int(server.effective_port)
        self._handler = handler
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="pdrive-monitor-web", daemon=True)

    @property
    def url(self) -> str:
        host = self.host or "0.0.0.0"
        host = f"[{host}]" if ":" in host else host
        return f"http://{host}:{self.port}/"

    @property
    def page_url(self) -> str:
        """The page's address as a user opens it (with ?token= when one is asked)."""
        return self.url + (f"?token={self.token}" if self.token else "")

    def start(self) -> "WebServer":
        self._thread.start()
        return self

    def _run(self) -> None:
        from waitress import wasyncore
        s = self._server
        try:
            while not self._stop.is_set():
                wasyncore.loop(timeout=0.25, map=s._map, use_poll=True, count=1)
        except Exception as e:                   # noqa: BLE001  (the monitor goes on without it)
            self.app.report(f"web: stopped: {type(e).__name__}: {str(e)[:200]}")
        finally:
            try:
                s.task_dispatcher.shutdown(cancel_pending=True, timeout=5)
            finally:
                wasyncore.close_all(s._map)

    def close(self) -> None:
        """Stop the thread, close every connection, free the port."""
        self._stop.set()
        if self._thread.is_alive():
            try:
                self._server.pull_trigger()
            except OSError:
                pass
            self._thread.join(10.0)
        else:
            from waitress import wasyncore
            self._server.task_dispatcher.shutdown(cancel_pending=True, timeout=5)
            wasyncore.close_all(self._server._map)
        logging.getLogger("waitress").removeHandler(self._handler)


def serve(live: LiveFn, reader: HistoryReader | None, host: str = "127.0.0.1",
          port: int = DEFAULT_PORT, token: str | None | bool = None,
          log: Callable[[str], None] = _stderr_line) -> WebServer:
    """Serve the page on host:port (port 0: one the system picks) in a daemon thread.

    token: None decides by the address (needs_token: a token off loopback), True makes one, False
    asks none, a string is the token. Raises UsageError without the monitor extra or when the
    address cannot be bound."""
    try:
        import waitress
    except ImportError:
        raise UsageError("--web needs the monitor extra: pip install 'profidrive-cli[monitor]'") \
            from None
    if token is None:
        token = needs_token(host)
    tok: str | None
    if token is True:
        tok = secrets.token_urlsafe(18)
    elif token is False or token == "":
        tok = None
    else:
        tok = str(token)
    app = App(live, reader, tok, names_for(host), log)
    handler = _ToLog(app.report)
    wlog = logging.getLogger("waitress")
    wlog.addHandler(handler)
    wlog.propagate = False
    wlog.setLevel(logging.WARNING)
    try:
        server = waitress.create_server(
            app, host=host, port=port, threads=THREADS,
            connection_limit=clients_for_limit(_nofile()), channel_timeout=CHANNEL_TIMEOUT_S,
            max_request_body_size=0, max_request_header_size=16 * 1024,
            expose_tracebacks=False, clear_untrusted_proxy_headers=True, ident="pdrive")
    except (OSError, ValueError) as e:
        wlog.removeHandler(handler)
        raise UsageError(f"--web {host}:{port}: cannot serve there: {e}") from None
    return WebServer(server, app, host, tok, handler).start()
