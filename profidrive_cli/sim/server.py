"""Serve a simulated bus to another master through a real byte path: a pty, a TCP port or an
existing serial device (e.g. one end of a socat pty pair).

The loop reads what the master sends, lets the SimBus answer, and writes each reply when the bus
says it is complete (at once with timing=instant; after wire time with timing=wire). Watchdogs run on
the real clock, so a master that stops talking sees its stations fall back to Wait_Prm.
"""

from __future__ import annotations

import os
import select
import socket
import time
import tty

from profidrive_cli.sim.bus import SimBus


class PtyEndpoint:
    def __init__(self):
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


class TcpEndpoint:
    """One client at a time (like an RS-485-over-TCP converter)."""

    def __init__(self, host: str, port: int):
        self.srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.srv.bind((host, port))
        self.srv.listen(1)
        self.address = self.srv.getsockname()
        self.conn: socket.socket | None = None

    def read(self, timeout: float) -> bytes:
        socks = [self.conn] if self.conn else [self.srv]
        r, _, _ = select.select(socks, [], [], timeout)
        if not r:
            return b""
        if self.conn is None:
            self.conn, _ = self.srv.accept()
            self.conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            return b""
        try:
            data = self.conn.recv(4096)
        except OSError:
            data = b""
        if not data:
            self.conn.close()
            self.conn = None
        return data

    def write(self, data: bytes) -> None:
        if self.conn is not None:
            try:
                self.conn.sendall(data)
            except OSError:
                self.conn.close()
                self.conn = None

    def close(self) -> None:
        if self.conn:
            self.conn.close()
        self.srv.close()


class SerialEndpoint:
    """An existing serial device through pyserial (8E1)."""

    def __init__(self, port: str, baud: int):
        from profidrive_cli.link.serial_link import open_serial
        self.ser = open_serial(port, baud)
        self.path = port

    def read(self, timeout: float) -> bytes:
        from profidrive_cli.link.serial_link import read_available
        try:
            return read_available(self.ser, timeout)
        except Exception:
            time.sleep(timeout)     # the master side closed: keep serving for the next one
            return b""

    def write(self, data: bytes) -> None:
        self.ser.write(data)

    def close(self) -> None:
        self.ser.close()


def serve(bus: SimBus, endpoint, stop=lambda: False, poll: float = 0.005, clock=time.monotonic) -> None:
    """Run until stop() is true. Replies go out in the order and at the times the bus gives."""
    pending: list[tuple[float, bytes]] = []
    while not stop():
        timeout = poll
        if pending:
            timeout = max(0.0, min(poll, pending[0][0] - clock()))
        data = endpoint.read(timeout)
        now = clock()
        bus.tick(now)
        if data:
            pending.extend(bus.receive(data, now))
            pending.sort(key=lambda p: p[0])
        now = clock()
        while pending and pending[0][0] <= now:
            endpoint.write(pending.pop(0)[1])
