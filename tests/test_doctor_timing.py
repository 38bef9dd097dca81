"""doctor's turnaround and request-to-request gap (dp/doctor_timing.py) against a fake port on a fake
clock: the adapter's latency and drain time are set here, so every expected figure is a hand
calculation (no timing assertion on the machine's own speed)."""

import pytest

from profidrive_cli.dp.doctor_timing import GAP_REQUESTS, TURNAROUNDS, timing_rows

BAUD = 19200
# FDL status request to 126 from 2 (the echo check's, tests/test_doctor.py)
REQ = bytes.fromhex("10 7e 02 49 c9 16")
# 6 octets x 11 bit at 19.2k (reference §1: 8E1 = 11 bit a character)
WIRE = 66 / BAUD


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


class TimedPort:
    """A pyserial-like port on a fake clock. A write goes on the line when it is free and takes its
    wire time; with echo its octets are readable `latency` s after the last one left; flush() (tcdrain)
    returns `drain` s after the last octet left. A read waits (moves the clock) up to its timeout."""

    def __init__(self, clock, echo, latency=0.0, drain=0.0, echo_on_wire=True):
        self.clock, self.echo, self.latency, self.drain = clock, echo, latency, drain
        self.echo_on_wire = echo_on_wire
        self.q = []                      # (readable at, octets)
        self.line_free = 0.0
        self.timeout = 0.0
        self.written = []

    def write(self, data):
        self.written.append(bytes(data))
        start = max(self.clock.t, self.line_free)
        self.line_free = start + len(data) * 11 / BAUD
        if self.echo:
            at = (self.line_free if self.echo_on_wire else start) + self.latency
            self.q.append((at, bytes(data)))
        return len(data)

    def flush(self):
        self.clock.t = max(self.clock.t, self.line_free + self.drain)

    @property
    def in_waiting(self):
        return sum(len(d) for at, d in self.q if at <= self.clock.t)

    def read(self, n=1):
        if not self.in_waiting and self.timeout > 0:
            nxt = min((at for at, _ in self.q), default=None)
            end = self.clock.t + self.timeout
            self.clock.t = end if nxt is None or nxt > end else nxt
        out = b""
        while self.q and self.q[0][0] <= self.clock.t and len(out) < n:
            at, d = self.q.pop(0)
            take = d[:n - len(out)]
            out += take
            if len(take) < len(d):
                self.q.insert(0, (at, d[len(take):]))
        return out

    def reset_input_buffer(self):
        self.q = [(at, d) for at, d in self.q if at > self.clock.t]


def rows(port, clock, echo, round_trip=None, probe_silent=True, busy=False):
    got = timing_rows(port, BAUD, 2, 126, echo=echo, busy=busy, probe_silent=probe_silent,
                      round_trip=round_trip, clock=clock)
    return {name: (status, detail, data) for name, status, detail, data in got}


def test_echo_turnaround_is_the_echo_latency_after_the_wire_time():
    clock = Clock()
    port = TimedPort(clock, echo=True, latency=0.002)
    r = rows(port, clock, echo=True)
    status, detail, data = r["turnaround"]
    assert data["method"] == "echo"
    assert data["turnaround_ms"] == [2.0] * TURNAROUNDS              # the latency set above
    assert data["turnaround_bits"] == 38                              # 0.002 s x 19200 = 38.4
    assert (data["min_tsdr_bits"], data["max_tsdr_bits"], data["tsl_bits"], data["tid1_bits"]) \
        == (11, 60, 100, 37)                                          # reference §4.1, 9.6k..187.5k
    assert status == "ok" and "within the slot time" in detail
    assert all(w == REQ for w in port.written)


def test_echo_turnaround_beyond_the_slot_time_is_said_not_judged():
    clock = Clock()
    port = TimedPort(clock, echo=True, latency=0.010)
    status, detail, data = rows(port, clock, echo=True)["turnaround"]
    assert data["turnaround_bits"] == 192                             # 0.010 x 19200
    assert status == "info" and "92 bit beyond the slot time" in detail   # 192 - TSL 100


def test_an_echo_faster_than_the_wire_measures_nothing():
    # a pty echoes at once: no line behind it, no verdict
    clock = Clock()
    port = TimedPort(clock, echo=True, echo_on_wire=False)
    status, detail, data = rows(port, clock, echo=True)["turnaround"]
    assert status == "info" and "no real line" in detail and "turnaround_ms" not in data


def test_without_echo_a_station_answer_bounds_the_turnaround():
    clock = Clock()
    port = TimedPort(clock, echo=False)
    status, detail, data = rows(port, clock, echo=False,
                                round_trip={"station": 5, "round_trips_ms": [12.0, 10.0]})["turnaround"]
    # fastest round trip 10 ms - request 66 bit - min TSDR 11 bit - reply 66 bit, at 19.2k:
    # 0.010 - 143 / 19200 = 0.0025521 s = 49.0 bit
    assert data["method"] == "round trip" and data["station"] == 5
    assert data["turnaround_ms"] == [2.552] and data["turnaround_bits"] == 49
    assert status == "ok" and "within the slave's min TSDR (11 bit)" in detail
    assert len(port.written) == GAP_REQUESTS            # only the request gap's: none for this


def test_an_answer_faster_than_the_wire_proves_nothing():
    clock = Clock()
    port = TimedPort(clock, echo=False)
    # 143 bit at 19.2k = 7.45 ms on the wire: 5 ms is no real line
    status, detail, data = rows(port, clock, echo=False,
                                round_trip={"station": 5, "round_trips_ms": [5.0]})["turnaround"]
    assert status == "info" and "no real line" in detail and "turnaround_ms" not in data


def test_without_echo_or_answer_nothing_is_claimed():
    clock = Clock()
    port = TimedPort(clock, echo=False)
    status, detail, data = rows(port, clock, echo=False)["turnaround"]
    assert status == "info" and "not measurable" in detail and data["method"] is None


@pytest.mark.parametrize("drain,status,gap_bits", [
    (0.001, "ok", 85),        # 66 bit + 1 ms (19.2 bit) = 85.2 bit <= 2 x (66 + 33)
    (0.020, "info", 450),     # 66 bit + 20 ms (384 bit) = 450 bit > 198
])
def test_request_gap_without_echo_is_wire_time_plus_drain(drain, status, gap_bits):
    clock = Clock()
    port = TimedPort(clock, echo=False, drain=drain)
    st, detail, data = rows(port, clock, echo=False)["request gap"]
    # each request timed from its start to the next one's (the last: to when it was drained)
    assert len(port.written) == GAP_REQUESTS and len(data["gap_ms"]) == GAP_REQUESTS
    assert data["gap_ms"] == pytest.approx([(WIRE + drain) * 1000] * GAP_REQUESTS, abs=0.001)
    assert data["gap_bits"] == gap_bits and (data["wire_bits"], data["tsyn_bits"]) == (66, 33)
    assert data["requests_per_s"] == pytest.approx(1 / (WIRE + drain), abs=0.1)
    assert st == status
    if status == "info":
        assert "the port, not the line, limits the request rate" in detail


def test_request_gap_with_echo_waits_for_each_echo():
    clock = Clock()
    port = TimedPort(clock, echo=True, latency=0.002)
    _, _, data = rows(port, clock, echo=True)["request gap"]
    # each request: its wire time, then its echo 2 ms later, then the next
    assert data["gap_ms"] == pytest.approx([(WIRE + 0.002) * 1000] * GAP_REQUESTS, abs=0.001)


def test_a_buffering_port_gives_no_line_figure():
    clock = Clock()

    class Pty(TimedPort):
        def flush(self):                 # a pty drains at once: no wire behind it
            pass
    port = Pty(clock, echo=False)
    st, detail, _ = rows(port, clock, echo=False)["request gap"]
    assert st == "info" and "faster than the wire" in detail


def test_nothing_is_sent_on_a_busy_line_or_back_to_back_to_an_address_that_answers():
    clock = Clock()
    port = TimedPort(clock, echo=True, latency=0.002)
    r = rows(port, clock, echo=True, busy=True)
    assert r["turnaround"][0] == r["request gap"][0] == "skip" and port.written == []
    r = rows(port, clock, echo=False, probe_silent=False)
    assert r["request gap"][0] == "skip" and "answered the echo check" in r["request gap"][1]
    assert port.written == []
