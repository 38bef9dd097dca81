"""Waiting and writing without burning CPU (issue 16): a link that cannot keep sub-millisecond timing
(pty, USB adapter, TCP) sleeps instead of spinning on the clock; the simulator and links that
declare µs timing keep the spin. On POSIX ports writes go straight to the fd (os.write), without
pyserial's select() after every write. No timing assertions: the spin is seen by the clock reads
it makes, the write path by which function runs."""

import os
import threading
import time

import pytest
import serial

from profidrive_cli.link import base, open_link
from profidrive_cli.link import serial_link
from profidrive_cli.link.base import Link, LinkLost, plain_sleep, precise_sleep


class FakeClock:
    """time.sleep and a monotonic clock on a fake timeline: a sleep wakes 0.1 ms late (as the OS
    does), each clock read takes 1 µs."""

    def __init__(self, monkeypatch):
        self.t = 100.0
        self.reads = 0
        self.sleeps = []
        monkeypatch.setattr(base.time, "sleep", self.sleep)

    def sleep(self, s):
        self.sleeps.append(s)
        self.t += s + 0.0001

    def __call__(self):
        self.reads += 1
        self.t += 0.000001
        return self.t


def test_precise_sleep_spins_the_last_part(monkeypatch):
    clock = FakeClock(monkeypatch)
    monkeypatch.setattr(base.time, "sleep", lambda s: setattr(clock, "t", clock.t + s))  # on time
    start = clock()
    precise_sleep(0.001, clock)
    assert clock.t - start >= 0.001
    assert clock.reads > 100                           # 0.2 ms of 1 µs clock reads


def test_plain_sleep_does_not_spin_and_never_returns_early(monkeypatch):
    clock = FakeClock(monkeypatch)
    start = clock()
    plain_sleep(0.001, clock)
    assert clock.t - start >= 0.001
    assert clock.reads <= 3
    assert clock.sleeps == [0.001]


def test_plain_sleep_sleeps_again_after_an_early_wake(monkeypatch):
    clock = FakeClock(monkeypatch)
    woke = []

    def early(s):                                      # e.g. a clock that runs differently
        woke.append(s)
        clock.t += s / 2
    monkeypatch.setattr(base.time, "sleep", early)
    start = clock()
    plain_sleep(0.004, clock)
    assert clock.t - start >= 0.004
    assert len(woke) > 1


class Quiet(Link):
    def write(self, data):
        pass

    def read(self, deadline):
        return b""

    def flush_input(self):
        pass


def spy(monkeypatch, module, *names):
    calls = []
    for name in names:
        def rec(seconds, *a, _name=name, **k):
            calls.append((_name, seconds))
        monkeypatch.setattr(module, name, rec)
    return calls


def test_link_sleeps_unless_it_keeps_us_timing(monkeypatch):
    calls = spy(monkeypatch, base, "precise_sleep", "plain_sleep")
    Quiet().sleep(0.002)

    class Timed(Quiet):
        us_timing = True
    Timed().sleep(0.003)
    assert calls == [("plain_sleep", 0.002), ("precise_sleep", 0.003)]


def test_a_pty_link_does_not_spin(socat_pair):
    a, b = socat_pair
    link = open_link(a, 19200)
    try:
        assert link.us_timing is False
    finally:
        link.close()


def test_a_pty_link_sleeps_plainly(socat_pair, monkeypatch):
    calls = spy(monkeypatch, serial_link, "precise_sleep", "plain_sleep")
    link = open_link(socat_pair[0], 19200)
    try:
        link.sleep(0.001)
    finally:
        link.close()
    assert calls == [("plain_sleep", 0.001)]


def test_the_simulator_keeps_us_timing():
    link = open_link("sim://?stations=3:fuji-g1&timing=wire")
    try:
        assert link.us_timing is True
    finally:
        link.close()


# -- writes ----------------------------------------------------------------------------------------

def test_pty_writes_go_to_the_fd_not_through_pyserial(socat_pair, monkeypatch):
    def no(*a, **k):
        raise AssertionError("pyserial's Serial.write called")
    monkeypatch.setattr(serial.Serial, "write", no)
    a, b = socat_pair
    link = open_link(a, 19200)
    peer = serial.Serial(b, timeout=2)
    try:
        link.write(bytes.fromhex("10 03 02 49 4E 16"))
        assert peer.read(6) == bytes.fromhex("10 03 02 49 4E 16")
    finally:
        link.close()
        peer.close()


def test_a_big_write_arrives_whole(socat_pair):
    a, b = socat_pair
    data = bytes(range(256)) * 512                      # 128 KiB: more than the pty buffer holds
    # echo off: with echo="auto" the first write also waits for a possible echo as long as the wire
    # takes for it (128 KiB * 11 bits / 19200 = 75 s), which is not what this test is about
    link = open_link(a, 19200, echo=False)
    peer = serial.Serial(b, timeout=0.5)
    got = bytearray()

    def drain():
        while len(got) < len(data):
            chunk = peer.read(4096)
            if not chunk:
                break
            got.extend(chunk)
    t = threading.Thread(target=drain)
    t.start()
    try:
        link.write(data)
        t.join(10)
        assert bytes(got) == data
    finally:
        link.close()
        peer.close()


def test_a_write_nobody_takes_times_out_as_link_lost(socat_pair):
    a, b = socat_pair
    link = open_link(a, 19200)
    link.ser._write_timeout = 0.2                    # (the setter would reconfigure the pty)
    try:
        t0 = time.monotonic()
        with pytest.raises(LinkLost, match="write timed out"):
            for _ in range(200):                      # nobody reads b: the buffers fill up
                link.write(bytes(64 * 1024))
        assert time.monotonic() - t0 < 30             # (a hang bound, not a timing test)
    finally:
        link.close()


def test_write_on_a_closed_port_is_link_lost(socat_pair):
    link = open_link(socat_pair[0], 19200)
    link.ser.close()
    with pytest.raises(LinkLost):
        link.write(b"\x10")


def test_write_fd_takes_partial_writes(monkeypatch):
    r, w = os.pipe()
    os.set_blocking(w, False)
    written = []
    real = os.write

    def two_at_a_time(fd, data):
        n = real(fd, bytes(data[:2]))
        written.append(n)
        return n
    monkeypatch.setattr(serial_link.os, "write", two_at_a_time)
    try:
        serial_link.write_fd(w, b"abcdefg", 1.0)
        assert os.read(r, 100) == b"abcdefg"
        assert written == [2, 2, 2, 1]
    finally:
        os.close(r)
        os.close(w)


# -- reads -----------------------------------------------------------------------------------------

def test_pty_reads_go_to_the_fd_not_through_pyserial(socat_pair, monkeypatch):
    """os.read on the fd: pyserial's in_waiting (an ioctl) and read (a select of its own) are not
    used; what has arrived comes back whole, nothing in time is b''."""
    a, b = socat_pair
    link = open_link(a, 19200)
    peer = serial.Serial(b, timeout=2)

    def no(*args, **kw):
        raise AssertionError("pyserial read path used")
    monkeypatch.setattr(serial.Serial, "read", no)
    monkeypatch.setattr(serial.Serial, "in_waiting", property(no))
    try:
        assert link.read(link.now() + 0.05) == b""
        peer.write(bytes.fromhex("68 05 05 68 02 03 08 01 02 10 16"))
        peer.flush()
        got = b""
        deadline = link.now() + 2.0
        while len(got) < 11 and link.now() < deadline:
            got += link.read(deadline)
        assert got == bytes.fromhex("68 05 05 68 02 03 08 01 02 10 16")
    finally:
        link.close()
        peer.close()


def test_pty_read_after_the_other_end_closed_is_link_lost():
    import pty
    mfd, sfd = pty.openpty()
    link = open_link(os.ttyname(sfd), 19200)
    os.close(sfd)
    try:
        os.close(mfd)                                  # the other end goes away
        with pytest.raises(LinkLost):
            link.read(link.now() + 1.0)
    finally:
        link.close()
