"""A listen-only endpoint: the octets of a running bus go out as an RS-485 tap would hear them.

Wraps one of sim/server.py's endpoints (pty, TCP, serial device) for `pdrive sim --plc`: writes
never block the bus (a listener that does not keep up, or no listener at all, loses octets, as on a
real tap: they are counted in `dropped`), and whatever a client writes is read and thrown away (a
tap cannot talk on the line).
"""

from __future__ import annotations

import os
import socket
import time
from collections.abc import Callable
from typing import Any


class Tap:
    DRAIN_S = 0.05          # how often what clients write is read away (and TCP clients accepted)

    # endpoint: a sim/server.py endpoint (pty, TCP or serial), told apart by what it has (duck typed)
    def __init__(self, endpoint: Any, clock: Callable[[], float] = time.monotonic):
        self.ep = endpoint
        self.clock = clock
        self.dropped = 0
        self.written = 0
        self.ignored = 0     # octets a client wrote (thrown away)
        self._drained = float("-inf")
        fd = getattr(endpoint, "master_fd", None)
        self._fd = fd
        self._serial_fd: int | None = None
        if fd is not None:
            os.set_blocking(fd, False)

    def drain(self) -> None:
        """Read away what clients wrote (and let a TCP endpoint accept a client)."""
        self._drained = self.clock()
        for _ in range(64):
            try:
                data = self.ep.read(0.0)
            except OSError:
                return
            if not data:
                return
            self.ignored += len(data)

    def write(self, data: bytes) -> None:
        if self.clock() - self._drained >= self.DRAIN_S:
            self.drain()
        if self._fd is not None:
            self._write_fd(self._fd, data)
        elif getattr(self.ep, "srv", None) is not None:
            self._write_tcp(data)
        elif hasattr(self.ep, "ser"):
            self._write_serial(data)
        else:
            self.ep.write(data)
            self.written += len(data)

    def _write_serial(self, data: bytes) -> None:
        """A serial device (a pty of a socat pair): its fd non-blocking too (the pair stops taking
        octets when nobody reads the other end); the device may be reopened, with a new fd."""
        from profidrive_cli.link.serial_link import posix_fd
        ser = self.ep.ser
        fd = posix_fd(ser) if ser is not None else None
        if fd is None:
            if ser is None:
                self.dropped += len(data)          # gone for now; SerialEndpoint reopens it
            else:
                self.ep.write(data)
                self.written += len(data)
            return
        if fd != self._serial_fd:
            os.set_blocking(fd, False)
            self._serial_fd = fd
        self._write_fd(fd, data)

    def _write_fd(self, fd: int, data: bytes) -> None:
        try:
            n = os.write(fd, data)
        except BlockingIOError:
            n = 0
        except OSError:
            n = 0
        self.written += n
        self.dropped += len(data) - n

    def _write_tcp(self, data: bytes) -> None:
        conn = self.ep.conn
        if conn is None:
            self.dropped += len(data)
            return
        try:
            n = conn.send(data, socket.MSG_DONTWAIT)
        except BlockingIOError:
            n = 0
        except OSError:
            self.ep.drop()
            n = 0
        self.written += n
        self.dropped += len(data) - n

    def close(self) -> None:
        self.ep.close()
