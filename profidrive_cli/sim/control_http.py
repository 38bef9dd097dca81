"""The plant's control over HTTP (`pdrive sim --control HOST:PORT`): sim/control.py's commands as JSON,
served by the standard library's ThreadingHTTPServer in a thread of its own, with a bound on
everything a client can hold, so that no client (slow, idle, hostile, or a web page in the user's
browser) can take the simulated plant down or steer it:

- at most `max_clients` connections at a time (derived from the descriptor limit); one more is
  answered 503 at once, without a thread;
- a read timeout per connection (READ_TIMEOUT_S) and a whole-connection bound (MAX_CONNECTION_S),
  after which its socket is shut down;
- out of descriptors on accept: one refused client, a short back-off, one report (sim/server.py
  AcceptGuard), never a spin, never an exit;
- a body of at most MAX_BODY octets, JSON nested at most MAX_DEPTH deep: else 400 with a JSON error;
- a client gone before its answer is forgotten silently; any other fault in a request is one line
  through `log` (at most one a minute, with a count: sim/server.py Reports), never a traceback;
- a request whose Host is not a name of this server, or whose Origin is not the server itself (or
  that a browser marks cross-site: Sec-Fetch-Site), is refused 403 (CSRF, DNS rebinding);
- on a non-loopback address (needs_token) every request carries the token printed at start
  (`Authorization: Bearer TOKEN`), else 401. There is no TLS: a plant is a test fixture, not a drive.

GET serves `/state` only (a GET must not steer the plant); every command is a POST.
"""

from __future__ import annotations

import hmac
import json
import secrets
import socket
import sys
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any, Callable

from profidrive_cli import httprules
from profidrive_cli.sim.control import ControlBusy, ControlError, Controller
from profidrive_cli.sim.server import AcceptGuard, Reports, refuse_now, stderr_line

#: the largest request body read
MAX_BODY = 64 * 1024
#: the deepest JSON nesting read (the arguments are one flat object)
MAX_DEPTH = 16
#: a connection that sends nothing for this long is closed
READ_TIMEOUT_S = 10.0
#: a connection open this long is shut down, whatever it does (a command waits for the bus at most
#: control.TAKE_TIMEOUT_S twice)
MAX_CONNECTION_S = 30.0
#: connections at a time, at most (fewer under a low descriptor limit: clients_for_limit)
MAX_CLIENTS = 32


def clients_for_limit(nofile: int | None) -> int:
    """How many control connections the process can afford under a descriptor limit `nofile`
    (httprules.py): 12 at a limit of 64, MAX_CLIENTS at 1,024."""
    return httprules.clients_for_limit(nofile, MAX_CLIENTS)


_nofile = httprules.nofile
is_loopback = httprules.is_loopback


def needs_token(host: str) -> bool:
    """A control bound to `host` asks every request for its token: any address but loopback (an empty
    host, 0.0.0.0 and ::, binds every interface). (A name of its own: tests replace it.)"""
    return httprules.needs_token(host)


def json_too_deep(raw: bytes, limit: int = MAX_DEPTH) -> bool:
    """True when `raw` nests arrays/objects deeper than `limit` (brackets inside strings not
    counted): checked before json.loads, which would recurse (RecursionError) on a deep one."""
    if raw.count(b"[") + raw.count(b"{") <= limit:
        return False
    depth, in_str, esc = 0, False, False
    for b in raw:
        if in_str:
            if esc:
                esc = False
            elif b == 0x5C:               # backslash
                esc = True
            elif b == 0x22:
                in_str = False
        elif b == 0x22:                   # "
            in_str = True
        elif b in (0x5B, 0x7B):           # [ {
            depth += 1
            if depth > limit:
                return True
        elif b in (0x5D, 0x7D):
            depth -= 1
    return False


_host_name = httprules.host_name


def _busy_answer(why: str) -> bytes:
    body = json.dumps({"error": why}).encode()
    return (b"HTTP/1.0 503 Service Unavailable\r\nContent-Type: application/json\r\n"
            b"Connection: close\r\nContent-Length: " + str(len(body)).encode() + b"\r\n\r\n" + body)


TOO_MANY = _busy_answer("the simulator's control has too many clients; try again")
NO_FDS = _busy_answer("the simulator is out of file descriptors; try again")


class _Httpd(ThreadingHTTPServer):
    daemon_threads = True
    block_on_close = False              # a hung handler must not hang the simulator's exit
    request_queue_size = 16

    def __init__(self, owner: "ControlServer", address: tuple[str, int],
                 handler: type[BaseHTTPRequestHandler]) -> None:
        self.owner = owner
        if ":" in address[0]:
            self.address_family = socket.AF_INET6
        super().__init__(address, handler)
        self.socket.setblocking(False)  # accept only after the selector; nobody there is no wait
        self.lock = threading.Lock()
        self.conns: dict[socket.socket, float] = {}     # open connection -> when accepted

    def get_request(self) -> tuple[socket.socket, Any]:
        got = self.owner.guard.accept(self.socket, NO_FDS)
        if got is None:
            raise OSError("no client")  # (socketserver's "nothing to handle")
        conn, addr = got
        conn.setblocking(True)
        return conn, addr

    def process_request(self, request: Any, client_address: Any) -> None:
        with self.lock:
            full = len(self.conns) >= self.owner.max_clients
            if not full:
                self.conns[request] = time.monotonic()
        if full:
            self.owner.refused_busy += 1
            refuse_now(request, TOO_MANY)
            self.owner.report_busy(f"control: {self.owner.max_clients} clients at once; refusing "
                                   f"more (503) until one leaves")
            return
        try:
            super().process_request(request, client_address)
        except RuntimeError:                 # (no thread to be had: refused as one too many)
            self.shutdown_request(request)

    def close_request(self, request: Any) -> None:
        with self.lock:
            self.conns.pop(request, None)
        super().close_request(request)

    def service_actions(self) -> None:
        """Between two looks at the listening socket (every poll interval): connections open too
        long are shut down; out of descriptors, wait out the back-off here (never spin)."""
        now = time.monotonic()
        with self.lock:
            old = [c for c, t in self.conns.items() if now - t > MAX_CONNECTION_S]
            for c in old:
                self.conns[c] = float("inf")     # shut down once; closed by its handler
        for c in old:
            self.owner.cut += 1
            try:
                c.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        wait = self.owner.guard.backoff_left()
        if wait:
            time.sleep(wait)

    def handle_error(self, request: Any, client_address: Any) -> None:
        """The last resort: a client gone is nothing; anything else one line, never a traceback."""
        e = sys.exc_info()[1]
        if isinstance(e, (ConnectionError, TimeoutError)):
            return
        self.owner.errors += 1
        self.owner.report_error(f"control: a request failed: {type(e).__name__}: {str(e)[:200]}")


class ControlServer:
    """`pdrive sim --control HOST:PORT`: the controller over HTTP, in a thread of its own.

    require_token: None decides by the address (needs_token); True asks for a token on any address
    (the same check as off loopback). log: one line per event (default: stderr)."""

    def __init__(self, controller: Controller, host: str = "127.0.0.1", port: int = 0, *,
                 require_token: bool | None = None, log: Callable[[str], None] = stderr_line,
                 max_clients: int | None = None) -> None:
        self.controller = controller
        self.log = log
        if require_token is None:
            require_token = needs_token(host)
        #: None on loopback; else the token every request must carry
        self.token: str | None = secrets.token_urlsafe(18) if require_token else None
        self.max_clients = max_clients or clients_for_limit(_nofile())
        self.guard = AcceptGuard("control", log)
        #: counters: refused for too many clients, shut down for taking too long, failed requests
        self.refused_busy = self.cut = self.errors = 0
        self.report_busy, self.report_error = Reports(log), Reports(log)
        self.httpd = _Httpd(self, (host, port), _handler(self))
        self.host, self.port = host, int(self.httpd.server_address[1])
        self._names = httprules.names_for(host)
        self._thread = threading.Thread(target=self._serve, name="pdrive-sim-control", daemon=True)

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}"

    def start(self) -> "ControlServer":
        self._thread.start()
        return self

    def _serve(self) -> None:
        try:
            self.httpd.serve_forever(poll_interval=0.25)
        except Exception as e:                  # noqa: BLE001  (the bus goes on without it)
            self.log(f"control: stopped: {type(e).__name__}: {e}")

    def close(self) -> None:
        if self._thread.is_alive():
            self.httpd.shutdown()
        self.httpd.server_close()
        self.guard.close()

    def own_host(self, host: str) -> bool:
        """A Host (or an Origin's host) that names this server (httprules.own_host)."""
        return httprules.own_host(host, self._names)

    def foreign(self, headers: Any) -> str | None:
        """Why a request comes from somewhere else (403), or None (httprules.foreign)."""
        return httprules.foreign(headers.get("Host"), headers.get("Sec-Fetch-Site"),
                                 headers.get("Origin"), self._names, "simulator",
                                 (self.host, self.port))

    def token_ok(self, authorization: str) -> bool:
        if self.token is None:
            return True
        got = authorization.encode("latin-1", "replace")     # (headers are latin-1 text)
        return hmac.compare_digest(got, f"Bearer {self.token}".encode())


def _handler(server: ControlServer) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        server_version = "pdrive-sim-control"
        timeout = READ_TIMEOUT_S

        def log_message(self, format: str, *args: Any) -> None:     # noqa: A002  (quiet)
            pass

        def _answer(self, status: int, body: dict[str, Any]) -> None:
            data = json.dumps(body).encode()
            self.send_response(status)
            self.send_header("Content-Type", "application/json")
            self.send_header("Content-Length", str(len(data)))
            if status == 401:
                self.send_header("WWW-Authenticate", "Bearer")
            self.end_headers()
            self.wfile.write(data)

        def _allowed(self) -> bool:
            why = server.foreign(self.headers)
            if why is not None:
                self._answer(403, {"error": f"refused: {why}"})
                return False
            if server.token_ok(self.headers.get("Authorization", "")):
                return True
            self._answer(401, {"error": "this plant needs its token (Authorization: Bearer TOKEN)"})
            return False

        def _run(self, command: str, args: dict[str, Any]) -> None:
            status = 200
            try:
                body = server.controller.call(command, args)
            except ControlBusy as e:
                status, body = 503, {"error": str(e)}
            except ControlError as e:
                status, body = 404 if str(e).startswith("unknown command") else 400, {"error": str(e)}
            except Exception as e:                   # noqa: BLE001  (a fault of the plant: one line)
                server.errors += 1
                server.report_error(f"control: {command[:40]!r} failed: {type(e).__name__}: {str(e)[:200]}")
                status, body = 500, {"error": f"{command[:40]} failed in the simulator: {type(e).__name__}"}
            self._answer(status, body)

        def do_GET(self) -> None:                                    # noqa: N802
            if not self._allowed():
                return
            command = self.path.strip("/") or "state"
            if command != "state":
                self._answer(405, {"error": f"GET serves /state only; {command[:40]!r} is a POST"})
                return
            self._run(command, {})

        def do_POST(self) -> None:                                   # noqa: N802
            if not self._allowed():
                return
            try:
                n = int(self.headers.get("Content-Length") or 0)
            except ValueError:
                n = -1
            if not 0 <= n <= MAX_BODY:
                self._answer(400, {"error": f"the request body must be 0..{MAX_BODY} octets"})
                return
            raw = self.rfile.read(n) if n else b"{}"
            if json_too_deep(raw):
                self._answer(400, {"error": f"the body nests deeper than {MAX_DEPTH} levels"})
                return
            try:
                args = json.loads(raw or b"{}")
            except (ValueError, RecursionError) as e:
                self._answer(400, {"error": f"the body is not JSON: {str(e)[:120]}"})
                return
            if not isinstance(args, dict):
                self._answer(400, {"error": "the body must be a JSON object of arguments"})
                return
            self._run(self.path.strip("/"), args)
    return Handler
