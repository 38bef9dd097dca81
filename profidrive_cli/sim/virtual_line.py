"""The line for `pdrive monitor --port 'sim://?timing=virtual&...'`: a simulated plant with a cyclic
master of its own, heard through an RS-485 tap (issue 37).

open_line(url) -> a read-only Link. The plant is sim/plant.py's (stations, faults and options of the
sim:// URL); the master is dp.poller.Master at address 2 (as `sim --plc`: the same bus parameters,
one retry, the stations' User_Prm_Data from their GSD) over an internal link onto the SimBus. No
threads: the master runs a cycle when a read needs octets it has not made yet, on the line's own
clock, and every telegram on the wire (its requests, the stations' replies and acknowledgements, the
tokens) is kept with the time its last octet is complete until a read hands it out. Deterministic
for a seed (seed=).

    read(deadline)   the next telegram heard up to `deadline` (the line's clock), whole and byte-exact
                     (an FDL telegram; a reply cut off by the next request, as a late one, only the
                     octets that were on the wire); the clock moves to its time, or to the deadline
                     when the line is silent until then
    now(), sleep(s)  timing=virtual: the line's clock (seconds from 0 at open), advanced by reads,
                     sleeps and reopens only; timing=wire (or none): the same line on the real clock
                     (reads wait for the telegrams' times)
    write()          refused (BusError): a tap cannot talk
    reopen()         after the adapter was pulled (adapter=): LinkLost until it is back
    close()          the line ends; a read after it is a BusError

What arrives while nobody reads (after a sleep, or a slow reader on the real clock) waits in the
adapter's receive buffer, RX_BUFFER_OCTETS at most: the telegrams beyond it are lost (counted in
VirtualLine.overrun_octets), as in a UART driver's buffer.

The master: per cycle a token (SD4, to itself), then one request per station (dp.poller.Master.poll):
bring-up (Slave_Diag, Set_Prm with a watchdog of at least WD_CYCLES cycles and MIN_WD_MS, Chk_Cfg
with the profile's default layout, Slave_Diag), then Data_Exchange with zero outputs; a DH reply is
followed by a Slave_Diag; a station that drops out (RS, or silent for its retries) is brought up
again on the following cycles, one request per cycle, as a PLC does. A cycle starts `cycle` seconds
after the previous one, or when the previous one's telegrams are done if they take longer.

URL keys of the line (beside every sim/plant.py and sim/faults.py key):

    cycle=S          the master's cycle in seconds (default 0.01; at most MAX_CYCLE_S)
    master2=A@S-E    a second master at address A is in the token ring from S to E seconds: the
                     master passes it the token (SD4 2 -> A) and it passes it back (SD4 A -> 2), in
                     place of the lone master's token to itself
    adapter=S-E      the listener's adapter is pulled from S to E: the first read at/after S raises
                     LinkLost; reopen() raises LinkLost (and costs REOPEN_COST_S of line time) until
                     E; then the line is heard again (what went on meanwhile is not)
    ack=S            a tripped drive (trip=, drivetrip=) is reset by the line's operator S seconds
                     after the trip (default 60): sim/control.py's `clear` (the keypad reset); 0: never
    repeat=S         every window of unplug=, master2= and adapter= repeats every S seconds (S longer
                     than each window)

Times of unplug= count from the first request on the bus (sim/faults.py), which is the first
cycle's, a token's time after the line opens; those of master2= and adapter= from the open.

Bounded: per cycle nothing is kept (the tap holds the telegrams of at most one cycle plus the
receive buffer, the fault plan's injection history is emptied each cycle).
"""

from __future__ import annotations

import math
import time
from collections import deque
from typing import TYPE_CHECKING
from urllib.parse import parse_qs, urlencode, urlsplit

from profidrive_cli import BusError, UsageError
from profidrive_cli.fdl import frames as F
from profidrive_cli.link.base import Link, LinkLost, plain_sleep
from profidrive_cli.sim.bus import Reply, SimBus

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.dp.station import SlaveConfig
    from profidrive_cli.sim.slave import SimSlave

#: the keys open_line takes beyond those of a plain sim:// URL
LINE_KEYS = ("cycle", "master2", "adapter", "ack", "repeat")
MASTER_ADDRESS = F.DEFAULT_MASTER
DEFAULT_CYCLE_S = 0.01
#: the longest cycle: the DP watchdog (at most 255 * 255 * 10 ms = 650 s) must cover WD_CYCLES of them
MAX_CYCLE_S = 120.0
WD_CYCLES = 4
#: the shortest watchdog armed (ms): as `sim --plc` (sim/plc.py WATCHDOG_MS)
MIN_WD_MS = 2000.0
DEFAULT_ACK_S = 60.0
#: the longest ack=, repeat= and window time taken (seconds: a year)
MAX_SECONDS = 366 * 86400.0
#: what a reopen costs on the line's clock (virtual timing)
REOPEN_COST_S = 0.05
#: the adapter's receive buffer: octets heard while nobody reads that wait for the next read
RX_BUFFER_OCTETS = 4096

#: a telegram heard: (time its last octet is complete, its octets)
Heard = tuple[float, bytes]


class _Window:
    """A window [start, end) of seconds, repeating every `repeat` seconds (0: once)."""

    def __init__(self, start: float, end: float, repeat: float):
        self.start, self.end, self.repeat = start, end, repeat

    def index(self, t: float) -> int:
        """The number of the latest window started at or before t (-1: none yet)."""
        if t < self.start:
            return -1
        if not self.repeat:
            return 0
        return int(math.floor((t - self.start) / self.repeat))

    def bounds(self, k: int) -> tuple[float, float]:
        off = k * self.repeat
        return self.start + off, self.end + off

    def active(self, t: float) -> bool:
        k = self.index(t)
        return k >= 0 and t < self.bounds(k)[1]


class _Wire(Link):
    """The master's side: a Link onto the SimBus on the plant's virtual clock. Every telegram on the
    wire goes to the tap with the time its last octet is complete: a request when it is written, a
    reply when the master has read it all, or, cut off by the next request, the octets on the wire
    by then (the bus cancels the rest)."""

    is_simulator = True
    instant = False
    latency = 0.0
    us_timing = False
    name = "line"

    def __init__(self, bus: SimBus, tap: deque[Heard]):
        self.bus = bus
        self.t = 0.0
        self.tap = tap
        self._pending: list[Reply] = []

    def now(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            self.t += seconds

    def write(self, data: bytes) -> None:
        t = self.t
        self.cut(t)
        octets = bytes(data)
        self.tap.append((t + self.bus.params.chars(len(octets)), octets))
        self._pending += self.bus.receive(octets, t)

    def tick(self) -> None:
        """The bus's clock (its stations' watchdogs and timers; a station addressed runs its own)."""
        self.bus.tick(self.t)

    def cut(self, t: float) -> None:
        """Replies still coming at `t`, when the master sends again: what was on the wire by then."""
        for r in self._pending:
            n = r.due(t)
            if n:
                self.tap.append((r.start + n * r.char_s, r.octets[:n]))
        self._pending.clear()

    def done(self, before: float) -> None:
        """The end of a cycle: replies complete before `before` (no request comes sooner) are heard."""
        rest = []
        for r in self._pending:
            if r.end <= before:
                self.tap.append((r.end, r.octets))
            else:
                rest.append(r)
        self._pending = rest

    def read(self, deadline: float) -> bytes:
        bus = self.bus
        nxt = bus.next_time()
        if nxt is None or nxt > deadline:
            if deadline > self.t:
                self.t = deadline
            return b""
        # a reply is coming: handed over whole when it ends by the deadline (as a port that delivers
        # a telegram at once: one read of it, not one per octet), else what is there by then
        # (a thousandth of an octet later: the bus counts the octets due by dividing times, which
        # after days of line time rounds the last one away at its exact end)
        r0 = bus.outbox[0]
        end = min(r0.end + r0.char_s * 0.001, deadline)
        if end > self.t:
            self.t = end
        data = bus.take(self.t)
        if not data:                    # never a read that returns nothing before its deadline
            self.t = max(self.t, deadline)
            return b""
        p = self._pending
        if p and p[0].sent >= len(p[0].octets):
            r = p.pop(0)
            self.tap.append((r.end, r.octets))
        return data

    def flush_input(self) -> None:
        # the master drops what it has not read; what is on the wire stays there (cut() at the
        # next request says how much of it)
        self.bus.flush()


class VirtualLine(Link):
    """The read-only Link of open_line (see the module doc). `bus` is the plant (sim/bus.py),
    `master` its master (dp/poller.py), `cycles` the cycles run, `overrun_octets` the octets lost
    from the receive buffer."""

    is_simulator = True
    instant = False
    latency = 0.0
    us_timing = False

    def __init__(self, url: str, bus: SimBus, cycle_s: float, virtual: bool,
                 master2: tuple[int, _Window] | None, adapter: _Window | None, ack_s: float,
                 repeat_s: float, tripped: set[int]):
        from profidrive_cli.dp.poller import Master
        from profidrive_cli.fdl.timing import BusParams
        self.name = url
        self.bus = bus
        self.cycle_s = cycle_s
        self.virtual = virtual
        self.master2 = master2
        self.adapter = adapter
        self.ack_s = ack_s
        self.repeat_s = repeat_s
        self._tap: deque[Heard] = deque()
        self.wire = _Wire(bus, self._tap)
        # as `sim --plc` builds its master (sim/plc.py Plc): one retry, no link latency
        #: the line's baud rate (the monitor's bus load)
        self.baud = int(bus.params.baud)
        self.master = Master(self.wire, BusParams.for_baud(bus.params.baud, retries=1,
                                                           link_latency=0.0),
                             address=MASTER_ADDRESS)
        wd_ms = max(MIN_WD_MS, WD_CYCLES * cycle_s * 1000.0)
        for a, s in sorted(bus.slaves.items()):
            config, out_len = _station_config(s, wd_ms)
            self.master.add_station(a, config).set_outputs(bytes(out_len))
        self._control = bus.control(clock=lambda: self.wire.t)
        plan = bus.faults
        #: the unplug= windows as given (repeat= moves the plan's to the current repetition)
        self._unplug_base = ({a: (s0, e) for a, (s0, e) in plan.unplugs.items() if e is not None}
                             if plan is not None else {})
        #: station -> when its drive tripped (the operator resets it ack_s later)
        self._tripped_at: dict[int, float] = {a: 0.0 for a in tripped}
        self._trips_seen: dict[int, int] = {a: s.stats.get("trips", 0) for a, s in bus.slaves.items()}
        self._next_cycle = 0.0
        self.cycles = 0
        self.overrun_octets = 0
        self._backlog = 0               # octets handed out from the receive buffer since caught up
        self.t = 0.0                    # the listener's clock (virtual timing)
        self._t_open = time.monotonic()
        self._lost = False
        self._adapter_next = 0          # the number of the next adapter window to raise at
        self._closed = False

    # -- the plant and its master -------------------------------------------------------------
    def _cycle(self) -> None:
        """One cycle of the master at its time: token(s), one request per station (octets to the tap)."""
        w = self.wire
        p = self.master.params
        # the token keeps the idle time after the last telegram on the wire (TID1 >= TSYN)
        start = max(self._next_cycle, w.t, self.bus.busy_until + p.tid1_seconds)
        w.t = start
        w.tick()
        self._episodes(start)
        if self.master2 is not None and self.master2[1].active(start):
            a2 = self.master2[0]
            self._token(a2, MASTER_ADDRESS)
            self._token(MASTER_ADDRESS, a2)
        else:
            self._token(MASTER_ADDRESS, MASTER_ADDRESS)
        self.master.poll()
        plan = self.bus.faults
        if plan is not None and plan.history:
            plan.history.clear()
        self.cycles += 1
        self._next_cycle = max(start + self.cycle_s, w.t)
        w.done(self._next_cycle)

    def _token(self, da: int, sa: int) -> None:
        """A token frame on the wire; the next telegram (its receiver's) TSYN after its end. The
        master's own idle time (after its last reply) lies before it: its next request goes at once."""
        w = self.wire
        frame = F.encode(F.token(da, sa))
        w.write(frame)
        p = self.master.params
        w.t += p.chars(len(frame)) + p.tsyn

    def _episodes(self, t: float) -> None:
        """Unplug windows of this repetition; the operator's resets of tripped drives."""
        bus = self.bus
        plan = bus.faults
        if plan is not None and self.repeat_s and self._unplug_base:
            rel = t - (plan.t0 if plan.t0 is not None else 0.0)
            for a, (s0, e) in self._unplug_base.items():
                if rel >= s0:
                    k = int((rel - s0) // self.repeat_s)
                    plan.unplugs[a] = (s0 + k * self.repeat_s, e + k * self.repeat_s)
        for a, slave in bus.slaves.items():
            n = slave.stats.get("trips", 0)
            if n != self._trips_seen.get(a, 0):
                self._trips_seen[a] = n
                self._tripped_at[a] = t
        if self.ack_s and self._tripped_at:
            from profidrive_cli.sim.control import ControlError
            for a, at in list(self._tripped_at.items()):
                if t - at < self.ack_s:
                    continue
                del self._tripped_at[a]
                if a in bus.slaves:
                    try:
                        self._control.clear(a)
                    except ControlError:        # (a drive without a fault to clear: nothing to do)
                        pass

    def _catch_up(self, t: float) -> None:
        """The plant runs on up to `t`, unheard (the adapter was out)."""
        tap = self._tap
        while True:
            while tap and tap[0][0] <= t:
                tap.popleft()
            if tap or self._next_cycle > t:
                return
            self._cycle()

    # -- what the tap hears ---------------------------------------------------------------------
    def _adapter_start(self) -> float | None:
        a = self.adapter
        if a is None or (not a.repeat and self._adapter_next > 0):
            return None
        return a.bounds(self._adapter_next)[0]

    def _pull(self, at: float) -> LinkLost:
        self._lost = True
        self.t = max(self.t, at)
        return LinkLost(f"{self.name}: adapter unplugged (simulated, at {at:g} s)", self.name)

    def _heard(self, now: float, deadline: float) -> bytes:
        """The next telegram heard up to `deadline` (b"": none), `now` the listener's clock at the
        read (older telegrams came while nobody read: the receive buffer's)."""
        if self._closed:
            raise BusError(f"{self.name}: the line is closed")
        if self._lost:
            raise LinkLost(f"{self.name}: adapter unplugged (simulated)", self.name)
        pull = self._adapter_start()
        if pull is not None and pull <= now:
            raise self._pull(pull)
        tap = self._tap
        while True:
            if tap:
                t0, data = tap[0]
                if pull is not None and pull <= min(t0, deadline):
                    raise self._pull(pull)
                if t0 > deadline:
                    break
                tap.popleft()
                if t0 < now:
                    if self._backlog + len(data) > RX_BUFFER_OCTETS:
                        self.overrun_octets += len(data)
                        continue
                    self._backlog += len(data)
                else:
                    self._backlog = 0
                if t0 > self.t:
                    self.t = t0
                return data
            if self._next_cycle > deadline:
                break
            self._cycle()
        if pull is not None and pull <= deadline:
            raise self._pull(pull)
        self._backlog = 0
        if deadline > self.t:
            self.t = deadline
        return b""

    def read(self, deadline: float) -> bytes:
        """The next telegram heard up to `deadline` (b"" when the line is silent until then);
        LinkLost while the adapter is out, BusError after close()."""
        if self.virtual:
            return self._heard(self.t, deadline)
        while True:                             # the real clock: wait for the telegrams' times
            now = self.now()
            data = self._heard(now, min(now, deadline))
            if data or now >= deadline:
                return data
            nxt = self._tap[0][0] if self._tap else self._next_cycle
            pull = self._adapter_start()
            if pull is not None:
                nxt = min(nxt, pull)
            plain_sleep(max(0.0, min(nxt, deadline) - now))

    def now(self) -> float:
        if self.virtual:
            return self.t
        return time.monotonic() - self._t_open

    def sleep(self, seconds: float) -> None:
        if seconds <= 0:
            return
        if self.virtual:
            self.t += seconds
        else:
            plain_sleep(seconds)

    def write(self, data: bytes) -> None:
        raise BusError(f"{self.name}: a listening tap cannot transmit ({len(data)} octets refused)")

    def flush_input(self) -> None:
        pass

    def reopen(self) -> None:
        """LinkLost while the adapter is out (each try costs REOPEN_COST_S of line time); then the
        line is heard again from now on."""
        if self._closed:
            raise LinkLost(f"{self.name}: the line is closed", self.name)
        if not self._lost:
            return
        if self.virtual:
            self.t += REOPEN_COST_S
        assert self.adapter is not None         # (only adapter= loses the line)
        t = self.now()
        _, end = self.adapter.bounds(self._adapter_next)
        if t < end:
            raise LinkLost(f"{self.name}: adapter still unplugged (simulated, back at {end:g} s)",
                           self.name)
        self._lost = False
        self.t = max(self.t, t)
        self._adapter_next = max(self._adapter_next + 1, self.adapter.index(t) + 1)
        self._catch_up(t)
        self._backlog = 0

    def close(self) -> None:
        self._closed = True
        self._tap.clear()


def _station_config(s: SimSlave, wd_ms: float) -> tuple[SlaveConfig, int]:
    """What the master parameterises a station with, and its output length: a drive's profile
    (its default layout, the GSD's User_Prm_Data, as sim/plc.py), else the station's own default
    configuration."""
    from profidrive_cli.dp.cfg import io_sizes
    from profidrive_cli.dp.station import SlaveConfig
    from profidrive_cli.sim.plc import _user_prm
    model = s.model
    prof = getattr(model, "profile", None)      # (a LazyModel is built here: Set_Prm would build it)
    if prof is not None:
        layout = prof.layouts[model.default_layout or prof.default_layout]
        return (SlaveConfig(ident=prof.ident, cfg=layout.cfg, user_prm=_user_prm(prof.ident),
                            wd_ms=wd_ms), int(layout.output_len))
    cfg = model.real_cfg()
    try:
        out_len = io_sizes(cfg)[1]
    except ValueError:                          # a configuration the decoder does not know
        out_len = 0
    return SlaveConfig(ident=model.ident, cfg=cfg, wd_ms=wd_ms), out_len


def _seconds(q: dict[str, list[str]], key: str, default: float, lo: float, hi: float) -> float:
    if key not in q:
        return default
    v = q[key][-1]
    try:
        x = float(v)
    except ValueError:
        x = float("nan")
    if not lo <= x <= hi:
        raise UsageError(f"sim URL: {key}={v} must be a number of seconds in {lo:g}..{hi:g}")
    return x


def _span(key: str, v: str) -> tuple[float, float]:
    a, dash, b = v.replace("s", "").partition("-")
    try:
        t0, t1 = float(a), float(b)
    except ValueError:
        t0, t1 = -1.0, -1.0
    if not dash or not 0 <= t0 < t1 <= MAX_SECONDS:
        raise UsageError(f"sim URL: {key}={v} must be SECONDS-SECONDS with the end after the start, "
                         f"e.g. {key}={'1@' if key == 'master2' else ''}100-200")
    return t0, t1


def open_line(url: str) -> VirtualLine:
    """The line of a sim:// URL as a listening tap hears it (see the module doc). UsageError (one
    line, naming the key) for a URL that is no sim:// one, an unknown key or a bad value."""
    from profidrive_cli.sim import faults as faults_mod
    from profidrive_cli.sim.plant import KNOWN_KEYS, build_bus
    parts = urlsplit(url)
    if parts.scheme != "sim":
        raise UsageError(f"not a sim:// URL: {url!r} (the monitor's virtual plant is "
                         f"sim://?timing=virtual&...)")
    q = parse_qs(parts.query, keep_blank_values=True)
    known = set(KNOWN_KEYS) | set(faults_mod.URL_KEYS) | set(LINE_KEYS)
    unknown = set(q) - known
    if unknown:
        raise UsageError(f"sim URL: unknown option(s) {', '.join(sorted(unknown))} "
                         f"(known: {', '.join(sorted(known))})")
    timing = q.get("timing", ["wire"])[-1]
    if timing not in ("wire", "virtual"):
        raise UsageError(f"sim URL: timing={timing}: the monitored line runs with timing=virtual "
                         f"or timing=wire")
    cycle = _seconds(q, "cycle", DEFAULT_CYCLE_S, 0.001, MAX_CYCLE_S)
    ack = _seconds(q, "ack", DEFAULT_ACK_S, 0.0, MAX_SECONDS)
    repeat = _seconds(q, "repeat", 0.0, 0.0, MAX_SECONDS)
    spans: list[tuple[str, float, float]] = []
    master2 = None
    if "master2" in q:
        v = q["master2"][-1]
        addr, at, when = v.partition("@")
        try:
            a2 = int(addr)
        except ValueError:
            a2 = -1
        if not at or not 0 <= a2 <= 126 or a2 == MASTER_ADDRESS:
            raise UsageError(f"sim URL: master2={v} must be ADDRESS@SECONDS-SECONDS with an address "
                             f"0..126 other than the line's master ({MASTER_ADDRESS}), e.g. "
                             f"master2=1@100-200")
        s0, s1 = _span("master2", when)
        spans.append(("master2", s0, s1))
        master2 = (a2, _Window(s0, s1, repeat))
    adapter = None
    if "adapter" in q:
        s0, s1 = _span("adapter", q["adapter"][-1])
        spans.append(("adapter", s0, s1))
        adapter = _Window(s0, s1, repeat)
    plain = {k: v for k, v in q.items() if k not in LINE_KEYS}
    plain["timing"] = ["virtual"]
    bus = build_bus(f"sim://{parts.netloc}?{urlencode(plain, doseq=True)}", now=0.0)
    if master2 is not None and master2[0] in bus.slaves:
        raise UsageError(f"sim URL: master2={q['master2'][-1]}: station {master2[0]} is a slave "
                         f"on the line")
    if bus.faults is not None:
        for s0, end in bus.faults.unplugs.values():
            if end is not None:
                spans.append(("unplug", s0, end))
    if repeat:
        for key, s0, s1 in spans:
            if s1 - s0 >= repeat:
                raise UsageError(f"sim URL: repeat={q['repeat'][-1]} must be longer than the "
                                 f"{key}= window of {s1 - s0:g} s")
    tripped = _trip_addresses(q.get("trip", []))
    return VirtualLine(url, bus, cycle, timing == "virtual", master2, adapter, ack, repeat, tripped)


def _trip_addresses(values: list[str]) -> set[int]:
    out = set()
    for v in values:
        try:
            out.add(int(v.partition(":")[0]))
        except ValueError:
            pass                  # (build_bus has refused it already)
    return out
