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

import os
import select
import socket
import threading
import time

from profidrive_cli.sim.bus import SimBus


class PtyEndpoint:
    def __init__(self):
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


def _send_and_close(sock: socket.socket, line: bytes, linger_s: float = 1.0) -> None:
    """Tell a refused client why, then close gracefully. The line goes out after the client's
    first request (or after `linger_s` of silence): a port that empties its input right after
    connecting (pyserial's socket:// does) would otherwise throw it away. Closing with unread input
    would reset the connection and could discard the line too, so the input is drained first."""
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
    while one is served is told so (BUSY_LINE) and closed at once."""

    def __init__(self, host: str, port: int):
        self.srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.srv.bind((host, port))
        self.srv.listen(1)
        self.address = self.srv.getsockname()
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
        socks = [self.conn, self.srv] if self.conn else [self.srv]
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
            self.conn, _ = self.srv.accept()
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
        try:
            extra, _ = self.srv.accept()
        except OSError:
            return
        self.refused += 1
        self._waited = False
        # say why, then close gracefully: a socket closed with unread input (the client's first
        # request) is reset, and a reset can discard the line before the client reads it
        threading.Thread(target=_send_and_close, args=(extra, BUSY_LINE), daemon=True).start()

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


class SerialEndpoint:
    """An existing serial device through pyserial (8E1). When it goes away, it is reopened as soon
    as the same path opens again."""

    RETRY_S = 0.2

    def __init__(self, port: str, baud: int):
        from profidrive_cli.link.serial_link import open_serial
        self._open = lambda: open_serial(port, baud)
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


def serve(bus: SimBus, endpoint, stop=lambda: False, poll: float = 0.005, clock=time.monotonic,
          tick_s: float = TICK_S) -> None:
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
