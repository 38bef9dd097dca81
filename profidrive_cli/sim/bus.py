"""A simulated PROFIBUS segment: master octets in, slave reply octets out, at byte level.

The bus parses what the master sends with the same fdl receiver the master uses, hands each request
to the addressed SimSlave, and queues the reply in its outbox with the time each octet is complete
on the wire.

timing="instant"   replies are there at once (no wire time at all)
timing="wire"      real wire time at the bus baud rate: the request's own octets (11 bits each), the
                   station's TSDR (its own response time, at least the min TSDR the master sent in
                   Set_Prm octet 3), then the reply octet by octet
timing="virtual"   the same wire time on a simulated clock: the sim:// port handler advances the
                   clock instead of sleeping, so a test or benchmark runs as fast as the CPU allows
                   and times are exact

With wire timing the bus also checks the master: a request that starts less than TSYN (33 bit) after
the end of the last telegram counts in stats.tsyn_violations, one that starts while a reply is still
due (before its last octet) in stats.collisions.

Every station on the line hears every valid telegram on it (Baud_Search, sim/slave.py
SimSlave.baud_search: a station still searching the rate takes it from any telegram, not only one
addressed to it): the bus counts them in one Line (requests, broadcasts, the stations' replies;
SD1/SD2/SD3 only) and a searching station reads the count when a telegram addresses it.

Fault injection (a FaultPlan, sim/faults.py) corrupts, drops, delays or misaddresses replies,
power-cycles or trips stations, and puts a lone noise octet 0xE5 (phantom) where no station answers;
every injection is counted in the plan.

A station's clock (its watchdog, its drive model's ramps and timers) runs when a request addresses it
and when it is due, not at every tick: the bus keeps the stations in a queue by the time each is next
due (SimSlave.next_due: the watchdog's expiry, the model's own SlaveModel.next_due), so a tick costs
what the due stations cost, whatever the number of stations. A station that was not run at some
ticks makes up for them when it next runs (SimSlave.tick, from the bus's TickLog), so it ends where a
station run at every tick would be. The queue is built again when the stations change (bus.slaves =
..., a command of sim/control.py, a different number of stations) and every RESYNC_S of bus time.
"""

from __future__ import annotations

import heapq
import math
from collections import deque
from dataclasses import dataclass, field
from itertools import count
from typing import TYPE_CHECKING, Any, Callable, ContextManager, Iterator

from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.timing import TSYN_BITS, BusParams
from profidrive_cli.sim.slave import DATA_EXCH, Line, SimSlave, TickLog

if TYPE_CHECKING:
    from profidrive_cli.sim.control import Controller
    from profidrive_cli.sim.faults import FaultPlan

TIMINGS = ("instant", "wire", "virtual")
_SC = F.SC
#: seconds of bus time after which every station's next due time is asked again (a safety net for a
#: station changed from outside the bus, e.g. a watchdog armed by hand)
RESYNC_S = 1.0


@dataclass
class BusStats:
    requests: int = 0
    replies: int = 0
    framing_errors: int = 0
    no_station: int = 0
    tsyn_violations: int = 0
    collisions: int = 0            # master sent while a reply was due
    cancelled: int = 0             # replies not yet delivered when the master sent again
    injected: dict[str, int] = field(default_factory=dict)


@dataclass(eq=False)
class Reply:
    """One slave transmission: octet i is complete at start + (i + 1) * char_s."""
    start: float
    octets: bytes
    char_s: float = 0.0
    late: bool = False             # injected: beyond the slot time
    sent: int = 0                  # octets already handed to the master side

    @property
    def end(self) -> float:
        return self.start + len(self.octets) * self.char_s

    def due(self, now: float) -> int:
        """How many octets are complete at `now`."""
        if self.char_s <= 0.0:
            return len(self.octets) if now >= self.start - 1e-12 else 0
        # `now` as the reply's own end (start + k * char_s) must count octet k complete also days into
        # a virtual clock, where the subtraction loses more than 1e-9 of an octet: a few ulps of `now`
        # in time, far below an octet at 12 Mbit/s (0.9 us)
        n = int((now - self.start + 4.0 * math.ulp(now)) / self.char_s + 1e-9)
        return max(0, min(len(self.octets), n))

    def __iter__(self) -> Iterator[float | bytes]:            # old form: (time complete, octets)
        return iter((self.end, self.octets))


class SimBus:
    def __init__(self, slaves: list[SimSlave], baud: int = 19200, timing: str = "instant",
                 tsdr_bits: int = 11, faults: FaultPlan | None = None):
        if timing not in TIMINGS:
            raise ValueError(f"timing must be one of {', '.join(TIMINGS)}, got {timing!r}")
        #: the bus's clock ticks (what a station not run at some of them makes up for)
        self.ticks = TickLog()
        #: the valid telegrams that went by on this line (what a station in Baud_Search hears)
        self.line = Line()
        self._queue: list[tuple[float, int, SimSlave]] = []     # (due, order, station)
        self._order = count()
        self._members: list[SimSlave] = []
        self._synced = -1               # len(slaves) the queue was built for (-1: at the first tick)
        self._resync_at = float("-inf")
        self.slaves = {s.address: s for s in slaves}
        self.params = BusParams.for_baud(baud)
        self.timing = timing
        self.tsdr_bits = tsdr_bits
        for s in slaves:
            if s.response_bits is None:
                s.response_bits = tsdr_bits
        self.faults = faults
        self.rx = F.Receiver()
        self.stats = BusStats()
        self.busy_until = 0.0        # end of the last octet on the wire (request or reply)
        self.reply_due_until = 0.0   # end of the last reply that the master must wait for
        self.outbox: list[Reply] = []
        self.log: list[tuple[float, str, bytes]] | None = None   # (time, "M"/"S", octets) if enabled
        #: stations taken off the line by the control (sim/control.py): address -> the station
        self.unplugged: dict[int, SimSlave] = {}
        #: commands of the control waiting for the bus's own thread: run at the next tick/receive,
        #: between telegrams (fn(now); sim/control.py puts them here from its HTTP thread)
        self.pending: deque[Callable[[float], None]] = deque()

    @property
    def wire(self) -> bool:
        return self.timing != "instant"

    @property
    def char_s(self) -> float:
        return self.params.chars(1) if self.wire else 0.0

    @property
    def slaves(self) -> dict[int, SimSlave]:
        """The stations on the line: address -> station."""
        return self._slaves

    @slaves.setter
    def slaves(self, stations: dict[int, SimSlave]) -> None:
        self._slaves = stations
        self._synced = -1

    def slave(self, address: int) -> SimSlave:
        return self._slaves[address]

    # -- the stations' clocks -------------------------------------------------------------------
    def tick(self, now: float) -> None:
        """The bus's clock: runs the stations that are due; the others make up for this tick when
        they next run."""
        if self.pending:
            self.run_pending(now)
        if len(self._slaves) != self._synced or now >= self._resync_at:
            self.resync(now)
        self.ticks.add(now)
        q = self._queue
        if not q or q[0][0] > now:
            return
        woken = []
        while q and q[0][0] <= now:
            t, _, s = heapq.heappop(q)
            if s.queued != t:
                continue                      # superseded by an earlier entry
            s.queued = None
            if not s.plugged:
                continue                      # off the line
            due = s.next_due()
            if due is None:
                continue
            if due > now:
                self._enqueue(s, due)         # its entry was early (a watchdog fed since)
                continue
            s.tick(now)
            woken.append(s)
        for s in woken:
            self.schedule(s)

    def schedule(self, s: SimSlave) -> None:
        """Queue station `s` for the time it is next due (after it ran or something acted on it)."""
        due = s.next_due()
        if due is not None and (s.queued is None or due < s.queued):
            self._enqueue(s, due)

    def _enqueue(self, s: SimSlave, due: float) -> None:
        s.queued = due
        heapq.heappush(self._queue, (due, next(self._order), s))

    def resync(self, now: float | None = None) -> None:
        """Queue every station on the line anew: stations that joined start from the bus's last
        tick (a station plugged back in did not run while it was off the line), stations that left
        are dropped."""
        current = list(self._slaves.values())
        here = {id(s) for s in current}
        for s in self._members:
            if id(s) not in here:
                s.plugged = False
        last = self.ticks.last
        for s in current:
            if not s.plugged:
                s.plugged = True
                s.ticks = self.ticks
                s.join(self.line)
                s.ticked_at = max(s.ticked_at, last)
                s.queued = None               # (an entry from before it left is not its own now)
            self.schedule(s)
        self._members = current
        self._synced = len(current)
        self._resync_at = (last if now is None else now) + RESYNC_S

    def settle(self) -> None:
        """Every station made up to the bus's last tick (before a command acts on the plant)."""
        last = self.ticks.last
        for s in self._slaves.values():
            s.settle(last)

    def run_pending(self, now: float) -> None:
        """The control's queued commands, in order, on this (the bus's) thread."""
        self.settle()
        while self.pending:
            self.pending.popleft()(now)
        self.resync(now)

    def control(self, lock: ContextManager[Any] | None = None,
                clock: Callable[[], float] | None = None) -> Controller:
        """A sim/control.py Controller of this bus (the Python API's Bus.simulator): its commands
        run at once, under `lock` (the master's), at the time `clock()` gives."""
        from profidrive_cli.sim.control import Controller
        return Controller(self, clock=clock, lock=_Settled(self, lock))

    # -- what the master side reads -------------------------------------------------------------
    def take(self, now: float) -> bytes:
        """Reply octets complete on the wire at `now` (each octet once)."""
        ob = self.outbox
        if not ob:
            return b""
        r = ob[0]
        if len(ob) == 1 and r.char_s <= 0.0 and not r.sent and now >= r.start:
            ob.clear()                       # (hot path of the instant bus: the whole reply)
            return r.octets
        out = bytearray()
        while self.outbox:
            r = self.outbox[0]
            n = r.due(now)
            if n > r.sent:
                out += r.octets[r.sent:n]
                r.sent = n
            if r.sent < len(r.octets):
                break
            self.outbox.pop(0)
        return bytes(out)

    def next_time(self) -> float | None:
        """When the next reply octet is complete (None: nothing is coming)."""
        if not self.outbox:
            return None
        r = self.outbox[0]
        return r.start + (r.sent + 1) * r.char_s

    def flush(self) -> None:
        """The master dropped its input: undelivered reply octets are gone."""
        self.outbox.clear()

    def power_cycle(self, address: int, now: float) -> None:
        self._slaves[address].power_cycle(now)
        self.schedule(self._slaves[address])

    # -- what the master sends ------------------------------------------------------------------
    def receive(self, data: bytes, now: float) -> list[Reply]:
        """Octets from the master written at `now` -> the replies they cause (also queued in the
        outbox for take())."""
        if self.pending:
            self.run_pending(now)
        if len(self._slaves) != self._synced:
            self.resync(now)
        out: list[Reply] = []
        if self.wire and not len(self.rx) and data:
            # a new telegram starts: check the master's idle time
            if now < self.reply_due_until - 1e-9:
                self.stats.collisions += 1
            elif self.busy_until and now - self.busy_until < TSYN_BITS / self.params.baud - 1e-9:
                self.stats.tsyn_violations += 1
        if self.outbox and data:
            # whatever was still to come is overtaken (a late reply, or a collision)
            self.stats.cancelled += len(self.outbox)
            self.outbox.clear()
        t_req_end = now + (self.params.chars(len(data)) if self.wire else 0.0)
        # octets flagged with a parity/framing error by a marking port (link/parity.py, `pdrive sim
        # --port` on a real device): like a real station, drop the telegram they belong to
        errors = getattr(data, "errors", ()) or ()
        start = 0
        for pos in list(errors) + [len(data)]:
            self.rx.feed(bytes(data[start:pos]))
            self._take_requests(t_req_end, out)
            if pos < len(data):
                self.stats.framing_errors += 1
                self.rx.reset()
            start = pos + 1
        self.busy_until = max(self.busy_until, t_req_end)
        for r in out:
            self.outbox.append(r)
            if not r.late:
                self.reply_due_until = max(self.reply_due_until, r.end)
            self.busy_until = max(self.busy_until, r.end)
        return out

    def _take_requests(self, t_req_end: float, out: list[Reply]) -> None:
        while True:
            r = self.rx.next()
            if r is None:
                return
            if isinstance(r, F.FrameError):
                self.stats.framing_errors += 1
                continue
            reply = self._dispatch(r, t_req_end)
            if reply is not None:
                out.append(reply)

    def _dispatch(self, req: F.Frame, t: float) -> Reply | None:
        line = self.line
        if req.sd in (F.SC, F.SD4) or not req.is_request:
            # tokens, replies of other stations: nothing for a slave to do; a reply is still a
            # valid telegram on the line (Baud_Search: sim/slave.py Line)
            if req.sd != F.SC and req.sd != F.SD4:
                line.telegrams += 1
            return None
        self.stats.requests += 1
        if self.faults is not None and self.faults.unplugs:
            touched = [s for a in self.faults.unplugs if (s := self._slaves.get(a)) is not None]
            for s in touched:
                s.settle(t)
            self.faults.on_telegram(self, t)
            for s in touched:
                self.schedule(s)
        if self.log is not None:
            self.log.append((t - (self.params.chars(len(F.encode(req))) if self.wire else 0.0),
                             "M", F.encode(req)))
        targets = (list(self._slaves.values()) if req.da == F.BROADCAST
                   else [self._slaves[req.da]] if req.da in self._slaves else [])
        if not targets:
            self.stats.no_station += 1
            if self.faults is not None and req.da != F.BROADCAST and req.function in F.NEEDS_REPLY:
                noise = self.faults.on_silence(self, req, t)
                if noise is not None:     # a phantom: a lone noise octet where nobody answers
                    start = t + (self.tsdr_bits / self.params.baud if self.wire else 0.0)
                    if self.log is not None:
                        self.log.append((start, "S", noise))
                    return Reply(start, noise, self.char_s)
        reply = None
        answering = None
        for s in targets:
            if self.faults is not None and req.da != F.BROADCAST and _is_new_data_exchange(s, req):
                self.faults.on_request(self, s, req, t)
            r = s.handle(req, t)
            self.schedule(s)
            if req.da != F.BROADCAST:
                reply, answering = r, s
        # every station on the line heard it (counted after they handled it: a station in
        # Baud_Search compares the telegrams before this one)
        line.telegrams += 1
        if reply is None:
            return None
        assert answering is not None        # the station that gave the reply
        start = t + (answering.reply_delay_bits / self.params.baud if self.wire else 0.0)
        late = False
        heard = reply[0] != _SC
        if self.faults is not None:
            res = self.faults.on_reply(self, req, reply, t)
            if res is None:
                return None
            heard = heard and res[0] == reply          # (a corrupted reply is no valid telegram)
            reply, extra = res
            if extra:
                start += extra
                late = True
        if heard:
            line.telegrams += 1           # the reply, an SD1 or SD2 telegram on the line
        self.stats.replies += 1
        if self.log is not None:
            self.log.append((start, "S", reply))
        return Reply(start, reply, self.char_s, late)


class _Settled:
    """The lock around a command of the in-process control (sim/control.py): the stations are made
    up to the bus's last tick before the command and queued anew after it (it may have started,
    stopped, tripped, unplugged or replugged one)."""

    def __init__(self, bus: SimBus, lock: Any = None):
        self.bus = bus
        self.lock = lock

    def __enter__(self) -> _Settled:
        if self.lock is not None:
            self.lock.__enter__()
        try:
            self.bus.settle()
        except BaseException:
            if self.lock is not None:
                self.lock.__exit__(None, None, None)
            raise
        return self

    def __exit__(self, *exc: Any) -> None:
        try:
            self.bus.resync()
        finally:
            if self.lock is not None:
                self.lock.__exit__(*exc)


def _is_new_data_exchange(s: SimSlave, req: F.Frame) -> bool:
    """A Data_Exchange request (no SAPs, SRD) that the station will execute in Data_Exch: the point
    where station faults (power cycle, drive trip) are injected. FCB repetitions are not."""
    return (req.dsap is None and req.function in (F.SRD_LOW, F.SRD_HIGH) and s.powered
            and s.state == DATA_EXCH and s.master == req.sa
            and not s.fcb.would_repeat(req.sa, req.fc))


def wire_limit(log: list[tuple[float, str, bytes]], params: BusParams) -> float:
    """The least time the logged traffic needs on the wire with these timing parameters: each
    request, then either its reply after the station's TSDR and TID1 of idle line, or the slot time
    (TSL >= TSYN, so the next request may follow at once). From SimBus.log (wire or virtual timing)."""
    total = 0.0
    i = 0
    while i < len(log):
        t, who, octets = log[i]
        if who != "M":
            i += 1
            continue
        req_end = t + params.chars(len(octets))
        total += params.chars(len(octets))
        if i + 1 < len(log) and log[i + 1][1] == "S":
            ts, _, rep = log[i + 1]
            tsdr = max(0.0, ts - req_end)
            total += tsdr + params.chars(len(rep)) + params.tid1_seconds
            i += 2
        else:
            total += params.slot_seconds
            i += 1
    return total
