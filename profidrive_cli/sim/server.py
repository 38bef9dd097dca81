"""Serve a simulated bus to another master through a real byte path: a pty, a TCP port or an
existing serial device (e.g. one end of a socat pty pair).

The loop reads what the master sends, lets the SimBus answer, and writes reply octets when the bus
says they are complete (at once with timing=instant; octet by octet after wire time with
timing=wire). Watchdogs run on the real clock, so a master that stops talking (or whose link is
lost) sees its stations fall back to Wait_Prm and its drives react as to a communication loss.

The byte path can go away and come back: a TCP client may disconnect and another connect; a serial
device that disappears (USB pulled, the socat of a pty pair ended) is reopened when it returns.
"""

from __future__ import annotations

import errno
import os
import select
import socket
import sys
import threading
import time
from typing import Any, Callable, Protocol

from profidrive_cli.sim.bus import SimBus


class Endpoint(Protocol):
    """What serve() needs of where the master is: octets in (waiting at most `timeout` s), out."""

    def read(self, timeout: float) -> bytes: ...

    def write(self, data: bytes) -> None: ...


class PtyEndpoint:
    def __init__(self) -> None:
        import tty                      # POSIX only: `sim --pty` (imported here, so that the module
                                        # loads on Windows, where --listen and --serial work)
        self.master_fd, self.slave_fd = os.openpty()
        tty.setraw(self.slave_fd)
        self.path = os.ttyname(self.slave_fd)

    def read(self, timeout: float) -> bytes:
        r, _, _ = select.select([self.master_fd], [], [], timeout)
        if not r:
            return b""
        try:
            return os.read(self.master_fd, 4096)
        except OSError:
            return b""      # the client closed its side; we keep ours open for the next one

    def write(self, data: bytes) -> None:
        os.write(self.master_fd, data)

    def close(self) -> None:
        for fd in (self.master_fd, self.slave_fd):
            try:
                os.close(fd)
            except OSError:
                pass


#: what a second client hears before its connection is closed (one client at a time, like a
#: converter; a silent bus would send its user looking for a wiring fault)
BUSY_LINE = b"pdrive sim: busy - another client is connected; try again when it has gone\r\n"
#: what a client hears when the process has no descriptor left to serve it with
NO_FDS_LINE = b"pdrive sim: out of file descriptors - try again later\r\n"

#: accept() errors that mean "no descriptor (or kernel memory) for the connection": the connection
#: stays queued, so the listening socket stays readable -- answered by AcceptGuard, not retried
FD_ERRNOS = frozenset({errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM})


def stderr_line(line: str) -> None:
    """The default report of a server running in the foreground: one line on stderr (written
    straight to the stream: a report out of descriptors cannot import or open anything)."""
    try:
        print(f"pdrive sim: {line}", file=sys.stderr, flush=True)
    except (OSError, ValueError):
        pass                         # stderr gone (a closed terminal): nothing to tell it


class Reports:
    """A recurring event's report: the first at once, then at most one each `every_s` (with how many
    were held back), so that a client churning at a limit for days cannot fill the log."""

    def __init__(self, log: Callable[[str], None], every_s: float = 60.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.log, self.every_s, self.clock = log, every_s, clock
        self._last = float("-inf")
        self._held = 0

    def __call__(self, line: str) -> None:
        now = self.clock()
        if now - self._last < self.every_s:
            self._held += 1
            return
        more = f" (and {self._held} more like it before)" if self._held else ""
        self._last, self._held = now, 0
        try:
            self.log(line + more)
        except Exception:               # noqa: BLE001  (out of descriptors, a report may fail too)
            pass


def refuse_now(sock: socket.socket, line: bytes) -> None:
    """Say `line` to a client without waiting for it, and close: no thread, no blocking (what it sent
    so far is read away first, so that the close does not reset the line away): _send_and_close
    without lingering."""
    _send_and_close(sock, line, linger_s=0.0)


class AcceptGuard:
    """accept() on a listening socket that survives running out of descriptors (EMFILE, ENFILE).

    The kernel keeps a connection it could not give a descriptor queued, so the socket stays
    readable: retried at once, accept would spin at 100 % CPU. Instead the guard holds one spare
    descriptor; when accept fails for want of one, the spare is closed, the waiting client accepted
    with it, told `line` and closed (one refused client), the spare taken again, and the socket left
    alone for BACKOFF_S (`ready()` is false). An episode is reported once through `log`, and its end
    (with the count) when a client is accepted again (at most one of each a minute: Reports)."""

    BACKOFF_S = 0.25

    def __init__(self, name: str, log: Callable[[str], None] = stderr_line,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.name, self.clock = name, clock
        self._report_out, self._report_back = Reports(log, clock=clock), Reports(log, clock=clock)
        #: clients refused for want of a descriptor (over the server's life)
        self.refused = 0
        self._episode = 0            # refused in the episode running now (0: none)
        self._until = float("-inf")
        self._spare = self._take_spare()

    @staticmethod
    def _take_spare() -> int | None:
        try:
            return os.open(os.devnull, os.O_RDONLY)
        except OSError:
            return None

    def ready(self) -> bool:
        """False while backing off after running out of descriptors."""
        return self.clock() >= self._until

    def backoff_left(self) -> float:
        return max(0.0, self._until - self.clock())

    def accept(self, srv: socket.socket, line: bytes) -> tuple[socket.socket, object] | None:
        """(connection, address), or None: nobody waiting, or a client refused (told `line`)."""
        try:
            got = srv.accept()
        except OSError as e:
            if e.errno in FD_ERRNOS:
                self._out_of_descriptors(srv, line, e)
            return None                 # (EAGAIN: another look found nobody; ECONNABORTED ...)
        if self._episode:
            self._report_back(f"{self.name}: descriptors free again ({self._episode} client(s) refused "
                     f"meanwhile)")
            self._episode = 0
        return got

    def _out_of_descriptors(self, srv: socket.socket, line: bytes, e: OSError) -> None:
        self.refused += 1
        self._episode += 1
        self._until = self.clock() + self.BACKOFF_S
        if self._spare is not None:
            os.close(self._spare)
            self._spare = None
            try:
                conn, _ = srv.accept()
            except OSError:
                conn = None             # (another thread took the spare: the back-off covers it)
            if conn is not None:
                refuse_now(conn, line)
            self._spare = self._take_spare()
        if self._episode == 1:
            self._report_out(f"{self.name}: out of file descriptors ({e.strerror or e}): refusing "
                             f"clients until some are free")

    def close(self) -> None:
        if self._spare is not None:
            os.close(self._spare)
            self._spare = None


def _send_and_close(sock: socket.socket, line: bytes, linger_s: float = 1.0) -> None:
    """Tell a refused client why, then close gracefully. The line goes out after the client's
    first request (or after `linger_s` of silence): a port that empties its input right after
    connecting (pyserial's socket:// does) would otherwise throw it away. Closing with unread input
    would reset the connection and could discard the line too, so the input is drained first.
    linger_s 0: nothing waited for (the socket non-blocking; what has come is read away)."""
    try:
        sock.settimeout(linger_s)
        try:
            sock.recv(4096)
        except OSError:
            pass
        sock.sendall(line)
        sock.shutdown(socket.SHUT_WR)
        end = time.monotonic() + linger_s
        while time.monotonic() < end and sock.recv(4096):
            pass                       # drain what the client sent until it closes
    except OSError:
        pass
    finally:
        sock.close()


class TcpEndpoint:
    """One client at a time (like an RS-485-over-TCP converter). A second client that connects
    while one is served is told so (BUSY_LINE) and closed at once (at most MAX_REFUSING of them
    are told at a time, the others closed at once). Out of descriptors, a client is refused
    (AcceptGuard), the loop goes on."""

    #: refused clients being told BUSY_LINE at once (each a short-lived thread)
    MAX_REFUSING = 4

    def __init__(self, host: str, port: int, log: Callable[[str], None] = stderr_line,
                 clock: Callable[[], float] = time.monotonic):
        self.srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.srv.bind((host, port))
        self.srv.listen(1)
        self.srv.setblocking(False)      # accept only after select; nobody there is no wait
        self.address = self.srv.getsockname()
        self.guard = AcceptGuard("bus port", log, clock)
        self._refusing = threading.BoundedSemaphore(self.MAX_REFUSING)
        self.conn: socket.socket | None = None
        #: clients accepted so far
        self.accepted = 0
        #: clients turned away because another was connected
        self.refused = 0
        self._drop_requested = False
        self._waited = False        # a waiting client was seen while the served one had input

    def request_drop(self) -> None:
        """Ask the serving loop (maybe another thread) to drop the client at its next read."""
        self._drop_requested = True

    def read(self, timeout: float) -> bytes:
        if self._drop_requested:
            self._drop_requested = False
            self.drop()
        socks = [self.conn] if self.conn else []
        if self.guard.ready():
            socks.append(self.srv)
        if not socks:                    # backing off, out of descriptors, and nobody served
            time.sleep(min(timeout, self.guard.backoff_left()))
            return b""
        r, _, _ = select.select(socks, [], [], timeout)
        if not r:
            return b""
        if self.conn is not None and self.srv in r:
            # a client waits while one is served. If the served one has closed (its end, maybe
            # behind its last octets, not read yet: a busy machine), the waiting one is served;
            # it is refused only when the served one is still there (idle, or talking again after
            # its pending octets were read once)
            if self.conn in r and self._client_gone():
                self.drop()
            elif self.conn in r and not self._waited:
                self._waited = True
            else:
                self._refuse()
                if self.conn not in r:
                    return b""
        if self.conn is None:
            self._waited = False
            got = self.guard.accept(self.srv, NO_FDS_LINE)
            if got is None:
                return b""
            self.conn = got[0]
            self.conn.setblocking(True)
            self.conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self.accepted += 1
            return b""
        try:
            data = self.conn.recv(4096)
        except OSError:
            data = b""
        if not data:
            self.drop()
        return data

    def _client_gone(self) -> bool:
        """The client's connection is at its end (closed or reset), its input read up to there."""
        assert self.conn is not None        # called while a client is connected
        try:
            return self.conn.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT) == b""
        except BlockingIOError:
            return False
        except OSError:
            return True

    def _refuse(self) -> None:
        got = self.guard.accept(self.srv, NO_FDS_LINE)
        if got is None:
            return
        extra = got[0]
        self.refused += 1
        self._waited = False
        if not self._refusing.acquire(blocking=False):
            refuse_now(extra, BUSY_LINE)         # enough threads telling others already
            return
        # say why, then close gracefully: a socket closed with unread input (the client's first
        # request) is reset, and a reset can discard the line before the client reads it
        extra.setblocking(True)

        def tell() -> None:
            try:
                _send_and_close(extra, BUSY_LINE)
            finally:
                self._refusing.release()
        threading.Thread(target=tell, daemon=True).start()

    def write(self, data: bytes) -> None:
        if self.conn is not None:
            try:
                self.conn.sendall(data)
            except OSError:
                self.drop()

    def drop(self) -> None:
        """Close the client connection (the converter lost it); the next client is accepted."""
        if self.conn is not None:
            try:
                self.conn.close()
            except OSError:
                pass
            self.conn = None

    def close(self) -> None:
        self.drop()
        self.srv.close()
        self.guard.close()


class SerialEndpoint:
    """An existing serial device through pyserial (8E1). When it goes away, it is reopened as soon
    as the same path opens again."""

    RETRY_S = 0.2

    def __init__(self, port: str, baud: int):
        from profidrive_cli.link.serial_link import open_serial
        self._open: Callable[[], Any] = lambda: open_serial(port, baud)    # a pyserial port (untyped)
        self.ser = self._open()
        self.path = port
        self.reopened = 0
        self._retry_at = 0.0

    def _lost(self) -> None:
        try:
            self.ser.close()
        except Exception:
            pass
        self.ser = None
        self._retry_at = time.monotonic() + self.RETRY_S

    def read(self, timeout: float) -> bytes:
        from profidrive_cli.link.serial_link import read_available
        if self.ser is None:
            if time.monotonic() >= self._retry_at:
                try:
                    self.ser = self._open()
                    self.reopened += 1
                except Exception:
                    self._retry_at = time.monotonic() + self.RETRY_S
            if self.ser is None:
                time.sleep(timeout)
                return b""
        try:
            return read_available(self.ser, timeout)
        except Exception:
            self._lost()        # the device went away: keep serving, reopen when it is back
            return b""

    def write(self, data: bytes) -> None:
        from profidrive_cli.link.serial_link import posix_fd, write_fd
        if self.ser is None:
            return
        try:
            fd = posix_fd(self.ser)
            if fd is not None:
                write_fd(fd, data, self.ser.write_timeout or 2.0)   # no select after each write
            else:
                self.ser.write(data)
        except Exception:
            self._lost()

    def close(self) -> None:
        if self.ser is not None:
            self.ser.close()


#: how often the bus's clock ticks while it is served (the stations due then run their watchdogs and
#: ramps: sim/bus.py SimBus.tick)
TICK_S = 0.005


def serve(bus: SimBus, endpoint: Endpoint, stop: Callable[[], bool] = lambda: False, poll: float = 0.005,
          clock: Callable[[], float] = time.monotonic, tick_s: float = TICK_S) -> None:
    """Run until stop() is true. Reply octets go out at the times the bus gives.

    The bus's clock ticks every `tick_s` (and a station a request addresses runs its own first,
    sim/slave.py handle), not on every pass of the loop; at a tick only the stations that are due
    run (sim/bus.py), so a tick costs what they cost, not what the whole plant does.

    Stations built on first use (sim/lazy.py) are built here, before the first request: building
    one (its profile, its model) takes milliseconds, which a master waiting for a reply must not see."""
    for s in getattr(bus, "slaves", {}).values():
        build = getattr(s.model, "materialize", None)
        if build is not None:
            build()
    next_tick = clock()
    while not stop():
        now = clock()
        if now >= next_tick:
            bus.tick(now)
            next_tick = now + tick_s
        timeout = min(poll, max(0.0, next_tick - now))
        nxt = bus.next_time()
        if nxt is not None:
            timeout = max(0.0, min(timeout, nxt - now))
        data = endpoint.read(timeout)
        if data:
            bus.receive(data, clock())
        out = bus.take(clock())
        if out:
            endpoint.write(out)
