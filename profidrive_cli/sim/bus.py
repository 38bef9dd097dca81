"""A simulated PROFIBUS segment: master octets in, slave reply octets out, at byte level.

The bus parses what the master sends with the same fdl receiver the master uses, hands each request
to the addressed SimSlave, and returns the reply octets together with the time they are complete on
the wire. With timing="wire" that time includes the request's own wire time, TSDR and the reply's
wire time at the bus baud rate (11 bits per character); the bus also flags a master that sends before
TSYN of idle line or while a reply is still due. With timing="instant" replies are available at once.

Fault injection (a FaultPlan, sim/faults.py) can corrupt, drop, delay or misaddress replies.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.timing import BusParams, TSYN_BITS
from profidrive_cli.sim.slave import SimSlave


@dataclass
class BusStats:
    requests: int = 0
    replies: int = 0
    framing_errors: int = 0
    no_station: int = 0
    tsyn_violations: int = 0
    collisions: int = 0            # master sent while a reply was due
    injected: dict = field(default_factory=dict)


class SimBus:
    def __init__(self, slaves: list[SimSlave], baud: int = 19200, timing: str = "instant",
                 tsdr_bits: int = 11, faults=None):
        self.slaves = {s.address: s for s in slaves}
        self.params = BusParams.for_baud(baud)
        self.timing = timing
        self.tsdr_bits = tsdr_bits
        self.faults = faults
        self.rx = F.Receiver()
        self.stats = BusStats()
        self.busy_until = 0.0        # end of the last octet on the wire (request or reply)
        self.log: list[tuple[float, str, bytes]] | None = None   # (time, "M"/"S", octets) if enabled

    @property
    def wire(self) -> bool:
        return self.timing == "wire"

    def slave(self, address: int) -> SimSlave:
        return self.slaves[address]

    def tick(self, now: float) -> None:
        for s in self.slaves.values():
            s.tick(now)

    def receive(self, data: bytes, now: float) -> list[tuple[float, bytes]]:
        """Octets from the master written at `now` -> [(time complete, reply octets), ...]."""
        out: list[tuple[float, bytes]] = []
        if self.wire:
            if now < self.busy_until - 1e-9:
                self.stats.collisions += 1
            elif now - self.busy_until < TSYN_BITS / self.params.baud - 1e-9 and self.busy_until:
                self.stats.tsyn_violations += 1
        t_req_end = now + (self.params.chars(len(data)) if self.wire else 0.0)
        self.rx.feed(data)
        while True:
            r = self.rx.next()
            if r is None:
                break
            if isinstance(r, F.FrameError):
                self.stats.framing_errors += 1
                continue
            reply = self._dispatch(r, t_req_end)
            if reply is not None:
                out.append(reply)
        self.busy_until = out[-1][0] if out else t_req_end
        return out

    def _dispatch(self, req: F.Frame, t: float):
        if req.sd in (F.SC, F.SD4) or not req.is_request:
            return None          # tokens, replies of other stations: nothing for a slave to do
        self.stats.requests += 1
        if self.log is not None:
            self.log.append((t, "M", F.encode(req)))
        targets = (list(self.slaves.values()) if req.da == F.BROADCAST
                   else [self.slaves[req.da]] if req.da in self.slaves else [])
        if not targets:
            self.stats.no_station += 1
        reply = None
        for s in targets:
            r = s.handle(req, t)
            if req.da != F.BROADCAST:
                reply = r
        if reply is None:
            return None
        delay = (self.tsdr_bits / self.params.baud + self.params.chars(len(reply))) if self.wire else 0.0
        if self.faults is not None:
            res = self.faults.on_reply(self, req, reply, t)
            if res is None:
                return None
            reply, extra = res
            delay += extra
        self.stats.replies += 1
        if self.log is not None:
            self.log.append((t + delay, "S", reply))
        return t + delay, reply
