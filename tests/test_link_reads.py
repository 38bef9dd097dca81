"""Reads take everything that is there on every link kind, and the poller waits once for the rest
of a telegram, not once per chunk (issue 13 b: socket:// converters were quadratic per frame)."""

import socket
import threading
import time

import pytest
import serial

from profidrive_cli.dp.poller import Master
from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.master import REPLY
from profidrive_cli.fdl.timing import BusParams
from profidrive_cli.link.base import Link
from profidrive_cli.link.serial_link import read_available


@pytest.fixture
def tcp_pair():
    srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    port = srv.getsockname()[1]
    ser = serial.serial_for_url(f"socket://127.0.0.1:{port}", timeout=0)
    conn, _ = srv.accept()
    yield ser, conn
    ser.close()
    conn.close()
    srv.close()


def _wait_until_readable(ser):
    end = time.monotonic() + 5
    while not ser.in_waiting and time.monotonic() < end:
        time.sleep(0.001)


def test_socket_read_takes_everything_that_is_there(tcp_pair):
    ser, conn = tcp_pair
    data = bytes(range(40))
    conn.sendall(data)
    _wait_until_readable(ser)
    time.sleep(0.05)                              # all 40 octets are in the socket by now
    assert read_available(ser, 1.0) == data       # one read, not one octet (in_waiting is 0/1)
    # waiting for the first octet, then the rest of what is there
    threading.Timer(0.05, lambda: conn.sendall(b"\x68\x05\x05\x68\x02")).start()
    got = read_available(ser, 2.0)
    got += read_available(ser, 0.2) if len(got) < 5 else b""
    assert got == b"\x68\x05\x05\x68\x02"
    # nothing there: b"" after the timeout, and at once with timeout 0
    assert read_available(ser, 0.05) == b""
    assert read_available(ser, 0.0) == b""


class ChunkedLink(Link):
    """A transport that delivers a reply in 3-octet chunks, each later than the wire would
    (like a TCP converter), on a virtual clock."""

    instant = False
    latency = 0.0

    def __init__(self, reply: bytes, first_after: float, every: float):
        self.t = 0.0
        self.reply = reply
        self.first_after, self.every = first_after, every
        self.chunks: list[tuple[float, bytes]] = []
        self.sleeps_after_write = 0
        self.written_at = None

    def now(self):
        return self.t

    def sleep(self, s):
        if s > 0:
            if self.written_at is not None:
                self.sleeps_after_write += 1
            self.t += s

    def write(self, data):
        self.written_at = self.t
        self.chunks = [(self.t + self.first_after + i // 3 * self.every, self.reply[i:i + 3])
                       for i in range(0, len(self.reply), 3)]

    def read(self, deadline):
        if self.chunks and self.chunks[0][0] <= deadline:
            self.t = max(self.t, self.chunks[0][0])
            out = b""
            while self.chunks and self.chunks[0][0] <= self.t:
                out += self.chunks.pop(0)[1]
            return out
        self.t = max(self.t, deadline)
        return b""

    def flush_input(self):
        self.chunks = []


def test_poller_waits_once_for_the_rest_of_a_telegram():
    reply = F.encode(F.Frame(F.SD2, 2, 3, F.response_fc(F.DL), bytes(range(24))))   # 33 octets
    link = ChunkedLink(reply, first_after=0.008, every=0.003)
    m = Master(link, BusParams.for_baud(19200, retries=0, link_latency=0.05))
    res = m.transact(3, F.SRD_HIGH, bytes(12), expect=len(reply))
    assert res.kind == REPLY and res.frame.data == bytes(range(24))
    # 11 chunks: the first tells the length (SD2 LE), one wait for the rest, then plain reads
    assert link.sleeps_after_write == 1
    # and the reply is taken when its last chunk is there, not later
    last = link.written_at + 0.008 + 10 * 0.003
    assert abs(link.now() - last) < 1e-9
