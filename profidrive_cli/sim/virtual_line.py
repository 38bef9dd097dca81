"""The line for `pdrive monitor --port 'sim://?timing=virtual&...'`: a simulated plant with a cyclic
master of its own, heard through an RS-485 tap (issue 37).

open_line(url) -> a read-only Link. The plant is sim/plant.py's (stations, faults and options of the
sim:// URL); the master is dp.poller.Master at address 2 (as `sim --plc`) over an internal link onto
the SimBus. No threads: the master runs a cycle when a read needs octets it has not made yet, on
the line's own clock, and every octet on the wire (its requests, the stations' replies, its tokens)
is kept with the time it is complete until a read hands it out. Deterministic for a seed (seed=).

    read(deadline)   the next telegram heard up to `deadline` (the line's clock); the clock moves to
                     its time, or to the deadline when the line is silent until then
    now(), sleep(s)  timing=virtual: the line's clock (seconds from 0 at open), advanced by reads and
                     sleeps; timing=wire (or none): the same line on the real clock (reads wait)
    write()          refused (BusError): a tap cannot talk
    reopen()         after the adapter was pulled (adapter=): LinkLost until it is back

The master: per cycle a token (SD4, to itself), then one request per station (dp.poller.Master.poll):
bring-up (Slave_Diag, Set_Prm with a watchdog of at least 4 cycles, Chk_Cfg with the profile's
default layout, Slave_Diag), then Data_Exchange with zero outputs; a DH reply is followed by a
Slave_Diag; a station that drops out (RS, or silent for its retries) is brought up again on the
following cycles, one request per cycle, as a PLC does.

URL keys of the line (beside every sim/plant.py and sim/faults.py key):

    cycle=S          the master's cycle in seconds (default 0.01; at most MAX_CYCLE_S)
    master2=A@S-E    a second master at address A is in the token ring from S to E seconds: the
                     master passes it the token (SD4 2 -> A) and it passes it back (SD4 A -> 2)
    adapter=S-E      the listener's adapter is pulled from S to E: the first read at/after S raises
                     LinkLost; reopen() raises LinkLost (and costs REOPEN_COST_S) until E; then the
                     line is heard again (what went on meanwhile is not)
    ack=S            a tripped drive (trip=, drivetrip=) is reset by the line's operator S seconds
                     after the trip (default 60): the model's clear_fault, as sim/control.py `clear`
                     (the keypad reset); 0: never
    repeat=S         every window of unplug=, master2= and adapter= repeats every S seconds

Bounded: per cycle nothing is kept (the tap holds the octets of at most one cycle, the fault plan's
injection history is emptied each cycle).
"""

from __future__ import annotations

import math
import time
from collections import deque
from urllib.parse import parse_qs, urlencode, urlsplit

from profidrive_cli import BusError, UsageError
from profidrive_cli.fdl import frames as F
from profidrive_cli.link.base import Link, LinkLost, plain_sleep
from profidrive_cli.sim.bus import SimBus

#: the keys open_line takes beyond those of a plain sim:// URL
LINE_KEYS = ("cycle", "master2", "adapter", "ack", "repeat")
MASTER_ADDRESS = 2
DEFAULT_CYCLE_S = 0.01
#: the longest cycle: the DP watchdog (at most 255 * 255 * 10 ms) must cover WD_CYCLES of them
MAX_CYCLE_S = 120.0
WD_CYCLES = 4
MIN_WD_MS = 2000.0
DEFAULT_ACK_S = 60.0
#: what a failed (or successful) reopen costs on the line's clock
REOPEN_COST_S = 0.05
#: the bus's clock runs at least this often within a cycle (the stations' timers; sim/bus.py)
TICK_S = 0.005


class _Window:
    """A window [start, end) of seconds, repeating every `repeat` seconds (0: once)."""

    def __init__(self, start: float, end: float | None, repeat: float):
        self.start, self.end, self.repeat = start, end, repeat

    def index(self, t: float) -> int:
        """The number of the latest window started at or before t (-1: none yet)."""
        if t < self.start:
            return -1
        if not self.repeat:
            return 0
        return int(math.floor((t - self.start) / self.repeat))

    def bounds(self, k: int) -> tuple[float, float | None]:
        off = k * self.repeat
        return self.start + off, (None if self.end is None else self.end + off)

    def active(self, t: float) -> bool:
        k = self.index(t)
        if k < 0:
            return False
        _, end = self.bounds(k)
        return end is None or t < end


class _Wire(Link):
    """The master's side: a Link onto the SimBus on the line's virtual clock; every octet on the
    wire goes to the tap with the time it is complete."""

    is_simulator = True
    instant = False
    latency = 0.0
    us_timing = False
    name = "line"

    def __init__(self, bus: SimBus, tap: deque[list[object]]):
        self.bus = bus
        self.t = 0.0
        self.tap = tap
        self._ticked = float("-inf")
        self._char = bus.params.chars(1)

    def now(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            self.t += seconds

    def _record(self, t: float, data: bytes, sent: bool) -> None:
        tap = self.tap
        if not sent and tap:
            last = tap[-1]
            # the rest of a reply: one piece with its start (a tap's read hands a telegram out)
            if not last[2] and t - float(last[0]) <= 1.5 * self._char:      # type: ignore[arg-type]
                last[0] = t
                last[1] = bytes(last[1]) + data           # type: ignore[arg-type]
                return
        tap.append([t, data, sent])

    def write(self, data: bytes) -> None:
        t = self.t
        if t - self._ticked >= TICK_S:
            self.bus.tick(t)
            self._ticked = t
        self._record(t + self.bus.params.chars(len(data)), bytes(data), True)
        self.bus.receive(bytes(data), t)

    def read(self, deadline: float) -> bytes:
        bus = self.bus
        while True:
            data = bus.take(self.t)
            if data:
                self._record(self.t, data, False)
                return data
            nxt = bus.next_time()
            if nxt is None or nxt > deadline:
                if deadline > self.t:
                    self.t = deadline
                return b""
            if nxt > self.t:
                self.t = nxt

    def flush_input(self) -> None:
        self.bus.flush()


class VirtualLine(Link):
    """The read-only Link of open_line (see the module doc)."""

    is_simulator = True
    instant = False
    latency = 0.0
    us_timing = False

    def __init__(self, url: str, bus: SimBus, cycle_s: float, virtual: bool,
                 master2: tuple[int, _Window] | None, adapter: _Window | None, ack_s: float,
                 repeat_s: float, tripped: set[int]):
        from profidrive_cli.dp.poller import Master
        from profidrive_cli.dp.station import SlaveConfig
        from profidrive_cli.fdl.timing import BusParams
        from profidrive_cli.sim.plc import _user_prm
        self.name = url
        self.bus = bus
        self.cycle_s = cycle_s
        self.virtual = virtual
        self.master2 = master2
        self.adapter = adapter
        self.ack_s = ack_s
        self.repeat_s = repeat_s
        self._tap: deque[list[object]] = deque()
        self.wire = _Wire(bus, self._tap)
        self.master = Master(self.wire, BusParams.for_baud(bus.params.baud, retries=1, link_latency=0.0),
                             address=MASTER_ADDRESS)
        wd_ms = max(MIN_WD_MS, WD_CYCLES * cycle_s * 1000.0)
        self._outputs: dict[int, bytes] = {}
        for a, s in sorted(bus.slaves.items()):
            prof = getattr(s.model, "profile", None)
            if prof is not None:
                layout = prof.layouts[s.model.default_layout or prof.default_layout]
                cfg, out_len, ident = layout.cfg, layout.output_len, prof.ident
                user_prm = _user_prm(ident)
            else:                              # a plain DP-V0 slave: its first configuration
                ident = s.model.ident
                cfg = next(iter(s.model.layouts.values()), b"")
                out_len, user_prm = _cfg_output_len(cfg), b""
            st = self.master.add_station(a, SlaveConfig(ident=ident, cfg=cfg, user_prm=user_prm,
                                                        wd_ms=wd_ms))
            self._outputs[a] = bytes(out_len)
            st.set_outputs(self._outputs[a])
        plan = bus.faults
        self._unplug_base = dict(plan.unplugs) if plan is not None else {}
        #: station -> when its drive tripped (the operator resets it ack_s later)
        self._tripped_at: dict[int, float] = {a: 0.0 for a in tripped}
        self._trips_seen: dict[int, int] = {a: s.stats.get("trips", 0) for a, s in bus.slaves.items()}
        self._next_cycle = 0.0
        self.cycles = 0
        self.t = 0.0                    # the listener's clock (virtual timing)
        self._t_open = time.monotonic()
        self._lost = False
        self._adapter_next = 0          # the number of the next adapter window to raise at
        self._closed = False

    # -- the plant and its master -------------------------------------------------------------
    def _cycle(self) -> None:
        """One cycle of the master, at its next time (octets to the tap)."""
        w = self.wire
        if w.t < self._next_cycle:
            w.t = self._next_cycle
        start = w.t
        self._episodes(start)
        self._token(MASTER_ADDRESS, MASTER_ADDRESS)
        if self.master2 is not None and self.master2[1].active(start):
            a2 = self.master2[0]
            self._token(a2, MASTER_ADDRESS)
            self._token(MASTER_ADDRESS, a2)
        self.master.poll()
        plan = self.bus.faults
        if plan is not None and plan.history:
            plan.history.clear()
        self.cycles += 1
        self._next_cycle = max(start + self.cycle_s, w.t)

    def _token(self, da: int, sa: int) -> None:
        """A token frame on the wire, then the idle time TSYN before the next telegram."""
        w = self.wire
        m = self.master
        m._wait_idle()
        frame = F.encode(F.token(da, sa))
        w.write(frame)
        p = m.params
        w.t += p.chars(len(frame)) + p.tsyn
        m._line_free_at = w.t

    def _episodes(self, t: float) -> None:
        """Unplug windows of this repetition; the operator's resets of tripped drives."""
        plan = self.bus.faults
        if plan is not None and self.repeat_s and self._unplug_base:
            rel = t - (plan.t0 if plan.t0 is not None else 0.0)
            for a, (s, e) in self._unplug_base.items():
                if e is None or rel < s:
                    continue
                k = int((rel - s) // self.repeat_s)
                plan.unplugs[a] = (s + k * self.repeat_s, e + k * self.repeat_s)
        for a, s in self.bus.slaves.items():
            n = s.stats.get("trips", 0)
            if n != self._trips_seen.get(a, 0):
                self._trips_seen[a] = n
                self._tripped_at[a] = t
        if self.ack_s and self._tripped_at:
            for a, at in list(self._tripped_at.items()):
                if t - at < self.ack_s:
                    continue
                del self._tripped_at[a]
                s = self.bus.slaves.get(a)
                if s is None:
                    continue
                s.settle(self.bus.ticks.last)
                try:
                    s.model.clear_fault(t)
                except ValueError:
                    pass
                self.bus.schedule(s)

    def _catch_up(self, t: float) -> None:
        """The plant runs on up to `t`, unheard (the adapter was out)."""
        while self._next_cycle <= t:
            self._cycle()
        while self._tap and float(self._tap[0][0]) <= t:      # type: ignore[arg-type]
            self._tap.popleft()

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

    def _heard(self, deadline: float) -> bytes:
        """Virtual: the next telegram up to `deadline` and the clock moved to it."""
        if self._closed:
            raise BusError(f"{self.name}: the line is closed")
        if self._lost:
            raise LinkLost(f"{self.name}: adapter unplugged (simulated)", self.name)
        pull = self._adapter_start()
        while True:
            tap = self._tap
            if tap:
                t0 = float(tap[0][0])                  # type: ignore[arg-type]
                if pull is not None and pull <= min(t0, deadline):
                    raise self._pull(pull)
                if t0 <= deadline:
                    item = tap.popleft()
                    if t0 > self.t:
                        self.t = t0
                    return item[1]                     # type: ignore[return-value]
                break
            if self._next_cycle > deadline:
                break
            self._cycle()
        if pull is not None and pull <= deadline:
            raise self._pull(pull)
        if deadline > self.t:
            self.t = deadline
        return b""

    def read(self, deadline: float) -> bytes:
        if self.virtual:
            return self._heard(deadline)
        while True:                             # the real clock: wait for the octets' time
            now = self.now()
            self.t = max(self.t, min(now, deadline) if now < deadline else deadline)
            data = self._heard(min(now, deadline))
            if data or now >= deadline:
                return data
            nxt = float(self._tap[0][0]) if self._tap else self._next_cycle   # type: ignore[arg-type]
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
        if self._closed:
            raise LinkLost(f"{self.name}: the line is closed", self.name)
        if not self._lost:
            return
        if self.virtual:
            self.t += REOPEN_COST_S
        assert self.adapter is not None         # (only adapter= loses the line)
        t = self.now()
        _, end = self.adapter.bounds(self._adapter_next)
        if end is None or t < end:
            raise LinkLost(f"{self.name}: adapter still unplugged (simulated"
                           + (f", back at {end:g} s)" if end is not None else ")"), self.name)
        self._lost = False
        self.t = max(self.t, t)
        self._adapter_next = max(self._adapter_next + 1, self.adapter.index(t) + 1)
        self._catch_up(t)

    def close(self) -> None:
        self._closed = True
        self._tap.clear()


def _cfg_output_len(cfg: bytes) -> int:
    try:
        from profidrive_cli.dp.cfg import io_lengths
        return int(io_lengths(cfg)[1])
    except Exception:       # a configuration the decoder does not know: no outputs
        return 0


def _float(q: dict[str, list[str]], key: str, default: float, lo: float, hi: float) -> float:
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
    if not dash or t0 < 0 or t1 <= t0:
        raise UsageError(f"sim URL: {key}={v} must be SECONDS-SECONDS with the end after the start")
    return t0, t1


def open_line(url: str) -> VirtualLine:
    """The line of a sim:// URL as a listening tap hears it (see the module doc). UsageError (one
    line, naming the key) for an unknown key or a bad value."""
    from profidrive_cli.sim import faults as faults_mod
    from profidrive_cli.sim.plant import KNOWN_KEYS, build_bus
    parts = urlsplit(url)
    if parts.scheme != "sim":
        raise UsageError(f"not a sim URL: {url}")
    q = parse_qs(parts.query, keep_blank_values=True)
    known = set(KNOWN_KEYS) | set(faults_mod.URL_KEYS) | set(LINE_KEYS)
    unknown = set(q) - known
    if unknown:
        raise UsageError(f"sim URL: unknown option(s) {', '.join(sorted(unknown))} "
                         f"(known: {', '.join(sorted(known))})")
    timing = q.get("timing", ["wire"])[-1]
    if timing not in ("wire", "virtual"):
        raise UsageError(f"sim URL: timing={timing}: the monitored line runs with timing=virtual or wire")
    cycle = _float(q, "cycle", DEFAULT_CYCLE_S, 0.001, MAX_CYCLE_S)
    ack = _float(q, "ack", DEFAULT_ACK_S, 0.0, 1e9)
    repeat = _float(q, "repeat", 0.0, 0.0, 1e9)
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
                             f"0..126 other than the line's master ({MASTER_ADDRESS}), e.g. master2=1@100-200")
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
    bus = build_bus(urlunsplit_query(parts, plain), now=0.0)
    if master2 is not None and master2[0] in bus.slaves:
        raise UsageError(f"sim URL: master2={q['master2'][-1]}: station {master2[0]} is a slave on the line")
    if bus.faults is not None:
        for a, (s0, end) in bus.faults.unplugs.items():
            if end is not None:
                spans.append(("unplug", s0, end))
    if repeat:
        for key, s0, s1 in spans:
            if s1 - s0 >= repeat:
                raise UsageError(f"sim URL: repeat={q['repeat'][-1]} must be longer than the "
                                 f"{key}= window of {s1 - s0:g} s")
    tripped = {a for a in _trip_addresses(q.get("trip", []))}
    return VirtualLine(url, bus, cycle, timing == "virtual", master2, adapter, ack, repeat, tripped)


def urlunsplit_query(parts: object, q: dict[str, list[str]]) -> str:
    """sim://HOST?query (the plant's keys only)."""
    netloc = getattr(parts, "netloc", "")
    return f"sim://{netloc}?{urlencode(q, doseq=True)}"


def _trip_addresses(values: list[str]) -> set[int]:
    out = set()
    for v in values:
        try:
            out.add(int(v.partition(":")[0]))
        except ValueError:
            pass                  # (build_bus has refused it already)
    return out
