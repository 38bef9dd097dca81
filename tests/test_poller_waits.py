"""How the poller waits on a link without µs timing (pty, USB adapter, TCP converter), on a simulated
clock: the fast path learns how late the link's replies come and then reads each reply whole with one
read (one wake-up), and a paced channel sleeps once per cycle for its period and the line's idle
time. The replies come from the wire-timed simulated bus (request, TSDR 11 bits, reply at 11 bits
an octet), delivered LAG seconds late as a USB adapter's latency timer would. No real time involved."""

from __future__ import annotations

from profidrive_cli.dp.poller import Master, StationChannel
from profidrive_cli.dp.station import SlaveConfig
from profidrive_cli.fdl.timing import BusParams
from profidrive_cli.link.base import Link
from profidrive_cli.sim.plant import build_bus

LAG = 0.001
BAUD = 19200


class LaggingLink(Link):
    """A port whose replies arrive `lag` s after they end on the wire. read() blocks (advancing the
    clock) until something arrives or the deadline, like a select() on the port."""

    instant = False
    us_timing = False

    def __init__(self, lag: float):
        self.bus = build_bus(f"sim://?stations=3:fuji-g1&timing=virtual&baud={BAUD}")
        self.t = 10.0
        self.lag = lag
        self.reads = 0
        self.sleeps: list[float] = []
        self.writes: list[float] = []

    def now(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            self.sleeps.append(self.t)
            self.t += seconds

    def write(self, data: bytes) -> None:
        self.writes.append(self.t)
        self.bus.receive(bytes(data), self.t)

    def read(self, deadline: float) -> bytes:
        self.reads += 1
        got = self.bus.take(self.t - self.lag)
        if not got and self.t < deadline:
            nxt = self.bus.next_time()
            self.t = deadline if nxt is None else min(deadline, max(self.t, nxt + self.lag))
            got = self.bus.take(self.t - self.lag)
        return got

    def flush_input(self) -> None:
        self.bus.flush()


def _master(lag: float) -> tuple[Master, LaggingLink]:
    link = LaggingLink(lag)
    m = Master(link, BusParams.for_baud(BAUD, retries=1, link_latency=0.02))
    m.add_station(3, SlaveConfig(ident=0xFD01, cfg=bytes.fromhex("F3F1"), wd_ms=5000))
    m.bring_up(3)
    return m, link


def test_replies_that_come_late_are_read_whole_once_the_lag_is_learned():
    m, link = _master(LAG)
    for _ in range(100):                          # learning: about 40 µs more per late reply
        m.exchange(3, bytes(12))
    reads = link.reads
    for _ in range(200):
        m.exchange(3, bytes(12))
    c = m.fdl.counters[3]
    assert (c.retries, c.no_answer, c.illegal) == (0, 0, 0)
    # one read per exchange, but for about one in twenty (the 95th percentile of the lag): before,
    # every reply 1 ms late took two (the first read came at the reply's end on the wire)
    assert link.reads - reads <= 200 + 200 // 10
    # and the wait is not longer than the lag needs (steps of 2 µs down, 38 µs up)
    assert LAG - 0.00005 <= m.reply_lag <= LAG + 0.00005


def test_the_learned_lag_costs_no_exchange_rate():
    """Each exchange after learning takes its wire time (request 21 octets, TSDR 11 bits, reply 21
    octets at 11 bits an octet), the lag and TID1 (37 bits), and at most 40 µs more."""
    m, link = _master(LAG)
    for _ in range(100):
        m.exchange(3, bytes(12))
    t0 = link.t
    for _ in range(100):
        m.exchange(3, bytes(12))
    per = (link.t - t0) / 100
    wire = (21 * 11 + 11 + 21 * 11 + 37) / BAUD          # 25.6 ms
    assert wire + LAG - 1e-9 <= per <= wire + LAG + 0.00004


def test_without_lag_nothing_is_learned():
    m, link = _master(0.0)
    reads = link.reads
    for _ in range(50):
        m.exchange(3, bytes(12))
    assert m.reply_lag == 0.0 and link.reads - reads == 50


def test_a_paced_channel_sleeps_once_per_cycle_before_the_request():
    """The period ends between the reply and the end of the line's idle time (TID1): one sleep
    until both have passed, not the period's and then the idle time's (plus the reply's)."""
    m, link = _master(LAG)
    for _ in range(100):
        m.exchange(3, bytes(12))
    wire = (21 * 11 + 11 + 21 * 11) / BAUD
    period = wire + LAG + 0.5 * 37 / BAUD         # half way into TID1 after the reply
    ch = StationChannel(m, 3, period)
    for _ in range(50):
        ch.exchange(bytes(12))
    w = link.writes[-40:]
    between = [sum(1 for s in link.sleeps if a <= s < b) for a, b in zip(w, w[1:])]
    # each cycle: the wait for the reply, then one sleep for period and TID1 together
    assert max(between) == 2, between
    gaps = [b - a for a, b in zip(w, w[1:])]
    assert min(gaps) >= period
