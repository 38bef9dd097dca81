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

Fault injection (a FaultPlan, sim/faults.py) corrupts, drops, delays or misaddresses replies,
power-cycles or trips stations, and puts a lone noise octet 0xE5 (phantom) where no station answers;
every injection is counted in the plan.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Callable

from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.timing import TSYN_BITS, BusParams
from profidrive_cli.sim.slave import DATA_EXCH, SimSlave

TIMINGS = ("instant", "wire", "virtual")


@dataclass
class BusStats:
    requests: int = 0
    replies: int = 0
    framing_errors: int = 0
    no_station: int = 0
    tsyn_violations: int = 0
    collisions: int = 0            # master sent while a reply was due
    cancelled: int = 0             # replies not yet delivered when the master sent again
    injected: dict = field(default_factory=dict)


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
        n = int((now - self.start) / self.char_s + 1e-9)
        return max(0, min(len(self.octets), n))

    def __iter__(self):            # old form: (time complete, octets)
        return iter((self.end, self.octets))


class SimBus:
    def __init__(self, slaves: list[SimSlave], baud: int = 19200, timing: str = "instant",
                 tsdr_bits: int = 11, faults=None):
        if timing not in TIMINGS:
            raise ValueError(f"timing must be one of {', '.join(TIMINGS)}, got {timing!r}")
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

    def slave(self, address: int) -> SimSlave:
        return self.slaves[address]

    def tick(self, now: float) -> None:
        if self.pending:
            self.run_pending(now)
        for s in self.slaves.values():
            s.tick(now)

    def run_pending(self, now: float) -> None:
        """The control's queued commands, in order, on this (the bus's) thread."""
        while self.pending:
            self.pending.popleft()(now)

    def control(self, lock=None, clock=None):
        """A sim/control.py Controller of this bus (the Python API's Bus.simulator): its commands
        run at once, under `lock` (the master's), at the time `clock()` gives."""
        from profidrive_cli.sim.control import Controller
        return Controller(self, clock=clock, lock=lock)

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
        self.slaves[address].power_cycle(now)

    # -- what the master sends ------------------------------------------------------------------
    def receive(self, data: bytes, now: float) -> list[Reply]:
        """Octets from the master written at `now` -> the replies they cause (also queued in the
        outbox for take())."""
        if self.pending:
            self.run_pending(now)
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

    def _take_requests(self, t_req_end: float, out: list) -> None:
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
        if req.sd in (F.SC, F.SD4) or not req.is_request:
            return None          # tokens, replies of other stations: nothing for a slave to do
        self.stats.requests += 1
        if self.faults is not None and self.faults.unplugs:
            self.faults.on_telegram(self, t)
        if self.log is not None:
            self.log.append((t - (self.params.chars(len(F.encode(req))) if self.wire else 0.0),
                             "M", F.encode(req)))
        targets = (list(self.slaves.values()) if req.da == F.BROADCAST
                   else [self.slaves[req.da]] if req.da in self.slaves else [])
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
            if req.da != F.BROADCAST:
                reply, answering = r, s
        if reply is None:
            return None
        assert answering is not None        # the station that gave the reply
        start = t + (answering.reply_delay_bits / self.params.baud if self.wire else 0.0)
        late = False
        if self.faults is not None:
            res = self.faults.on_reply(self, req, reply, t)
            if res is None:
                return None
            reply, extra = res
            if extra:
                start += extra
                late = True
        self.stats.replies += 1
        if self.log is not None:
            self.log.append((start, "S", reply))
        return Reply(start, reply, self.char_s, late)


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
