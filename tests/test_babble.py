"""A babbling line (issue 13 a): octets keep arriving after a broken telegram; each request must
still end within its hard cap and count as not answered, the noise as illegal."""

import os
import random
import subprocess
import threading
import time

import pytest
import serial

from conftest import pdrive_cmd
from profidrive_cli.dp import services as S
from profidrive_cli.dp.poller import Master
from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.master import NO_ANSWER
from profidrive_cli.fdl.timing import BusParams
from profidrive_cli.link.base import Link

# random octets, but never a lone SC (0xE5): it carries no address, so on any line it would be
# taken as a short acknowledgement, noise or not
NOISE = bytes(b for b in range(256) if b != 0xE5)


class BabblingLink(Link):
    """A line on a virtual clock where a random octet arrives every 1..4 ms, whatever is sent."""

    instant = False
    latency = 0.0

    def __init__(self, seed=1, give_up_s=20.0):
        self.rng = random.Random(seed)
        self.t = 0.0
        self.give_up_s = give_up_s
        self.next_t = self._gap()
        self.written = []

    def _gap(self):
        return self.rng.uniform(0.001, 0.004)

    def now(self):
        return self.t

    def sleep(self, seconds):
        if seconds > 0:
            self.t += seconds

    def write(self, data):
        self.written.append((self.t, bytes(data)))

    def read(self, deadline):
        if self.t > self.give_up_s:
            raise RuntimeError(f"still waiting after {self.t:.1f} s of babble: the master hangs")
        if self.next_t <= deadline:
            self.t = max(self.t, self.next_t)
            self.next_t = self.t + self._gap()
            return bytes([self.rng.choice(NOISE)])
        self.t = max(self.t, deadline)
        return b""

    def flush_input(self):
        pass


@pytest.mark.parametrize("seed", range(1, 6))
def test_one_request_on_a_babbling_line_ends_within_its_cap(seed):
    link = BabblingLink(seed)
    m = Master(link, BusParams.for_baud(19200, retries=1))
    t0 = link.now()
    res = m.transact(3, F.SRD_HIGH, b"", S.SAP_SLAVE_DIAG, S.SAP_MASTER, 250)
    elapsed = link.now() - t0
    # the cap by hand: Slave_Diag request = 11 octets (SD2 with both SAPs, no data), longest reply
    # 255 octets, slot time 100 bit, TSYN 33 bit, no latency on this link; 2 attempts, 11 bit/char
    cap = 2 * ((11 + 255) * 11 + 100 + 33) / 19200
    assert abs(m.fdl.request_cap(11, 250) - cap) < 1e-12
    assert res.kind == NO_ANSWER
    assert elapsed <= cap + 1e-9, (elapsed, cap)
    c = m.fdl.counters[3]
    assert c.no_answer == 1 and c.illegal >= 1
    assert len(link.written) <= 2                # the first attempt and at most one retry


def test_a_quiet_line_still_gets_its_retries():
    """The cap does not cut the retries of a line that is simply silent."""
    link = BabblingLink()
    link.next_t = float("inf")
    m = Master(link, BusParams.for_baud(19200, retries=2))
    res = m.transact(3, F.SRD_HIGH, b"", S.SAP_SLAVE_DIAG, S.SAP_MASTER, 250)
    assert res.kind == NO_ANSWER and res.retries == 2 and len(link.written) == 3


def _babbler(fd, stop):
    rng = random.Random(5)
    while not stop.is_set():
        try:
            os.write(fd, bytes([rng.choice(NOISE)]))
        except OSError:
            return
        time.sleep(rng.uniform(0.001, 0.004))


def test_scan_on_a_babbling_pty_finishes_and_says_the_line_is_noisy(socat_pair):
    a, b = socat_pair
    ser = serial.Serial(a, 19200)
    stop = threading.Event()
    th = threading.Thread(target=_babbler, args=(ser.fd, stop), daemon=True)
    th.start()
    try:
        t0 = time.monotonic()
        r = subprocess.run(pdrive_cmd() + ["scan", "--port", b, "--from", "0", "--to", "10"],
                           capture_output=True, text=True, timeout=90)
        took = time.monotonic() - t0
    finally:
        stop.set()
        th.join(5)
        ser.close()
    assert took < 60, took
    assert r.returncode == 1, (r.stdout, r.stderr)
    assert "no station answered" in r.stdout
    assert "noisy" in (r.stdout + r.stderr)
