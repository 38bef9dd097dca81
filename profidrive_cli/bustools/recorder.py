"""The black-box recorder (`pdrive sniff --ring 30 --trigger 'lost(*)'`): a ring of the telegrams
heard in the last `ring_s` seconds; when a trigger fires (bustools/triggers.py), one capture holding
the ring (the time before the event) and the `after_s` seconds after it.

Bounded for days: the ring keeps at most `ring_s` seconds AND at most `max_ring` telegrams (the
seconds alone do not bound memory: a saturated 12 Mbit/s line carries about 38,000 telegrams a
second, a noisy line a framing error per octet); a capture's "after" part at most `max_ring`
telegrams too. One capture is open at a time: an event inside an open capture's window joins it
(the window is not extended), the same trigger and station again only counts a repeat; so memory
holds at most the ring plus one capture (2 x max_ring telegrams before, max_ring after).

Sans-IO: feed(captured frames) and tick(t) return the captures whose window has closed (Done:
the telegrams with their times and the events in them); the caller writes them (pcap through
outfile.OutputFile) and prints the events.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from profidrive_cli.bustools.triggers import Fired, TriggerSet

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.dp.capture import Captured

#: the most telegrams the ring holds (and a capture's "after" part): about 150 bytes each, so
#: 250,000 x 150 B = 37.5 MB for the ring, 3 x that at most with an open capture (a Raspberry Pi
#: 3 has 1 GB); at 19.2 kbit/s that is hours of traffic, at a saturated 12 Mbit/s line ~6.6 s
MAX_RING = 250_000


@dataclass
class Event:
    """One trigger fired (the first of its kind and station in a capture) and how often the same
    fired again inside the capture's window."""
    n: int
    fired: Fired
    repeats: int = 0


@dataclass
class Done:
    """A capture whose window closed (or which the end of the listening closed early)."""
    n: int                                   # capture number, from 1
    t_event: float                           # the first event's time
    packets: list[tuple[float, bytes]]       # (time, octets) in order
    events: list[Event]
    complete: bool                           # the "after" window was heard to its end
    dropped: int = 0                         # "after" telegrams over max_ring, not kept

    @property
    def before_s(self) -> float:
        return max(0.0, self.t_event - self.packets[0][0]) if self.packets else 0.0

    @property
    def after_s(self) -> float:
        return max(0.0, self.packets[-1][0] - self.t_event) if self.packets else 0.0


@dataclass
class _Open:
    n: int
    t_event: float
    t_end: float
    packets: list[tuple[float, bytes]]
    events: list[Event] = field(default_factory=list)
    after: int = 0
    dropped: int = 0


class Recorder:
    def __init__(self, triggers: TriggerSet, ring_s: float, after_s: float,
                 max_ring: int = MAX_RING, first_n: int = 1):
        if ring_s <= 0 or after_s < 0 or max_ring < 1:
            raise ValueError("ring_s > 0, after_s >= 0 and max_ring >= 1")
        self.triggers = triggers
        self.ring_s = ring_s
        self.after_s = after_s
        self.max_ring = max_ring
        self.ring: deque[tuple[float, bytes]] = deque(maxlen=max_ring)
        self.open: _Open | None = None
        self.captures = first_n - 1         # the number of the newest capture (from first_n on)
        self.events = 0
        self.telegrams = 0

    def feed(self, items: list[Captured]) -> list[Done]:
        """Captured frames (and framing errors) in arrival order -> captures completed."""
        done: list[Done] = []
        ring = self.ring
        for c in items:
            self.telegrams += 1
            if self.open is not None and c.t > self.open.t_end:
                done.append(self._close(True))
            pkt = (c.t, c.raw)
            ring.append(pkt)
            op = self.open
            if op is not None:
                if op.after < self.max_ring:
                    op.packets.append(pkt)
                    op.after += 1
                else:
                    op.dropped += 1
            for f in self.triggers.feed(c):
                self._event(f)
        if items:
            self._trim(items[-1].t)
        return done

    def tick(self, t: float) -> list[Done]:
        """The time now (seconds, the frames' clock): closes a window that ended on a silent line."""
        self._trim(t)
        if self.open is not None and t > self.open.t_end:
            return [self._close(True)]
        return []

    def close(self) -> list[Done]:
        """The listening ended: an open capture is handed over with what it has."""
        return [self._close(False)] if self.open is not None else []

    # -- inside ------------------------------------------------------------------------------------
    def _trim(self, t: float) -> None:
        ring, oldest = self.ring, t - self.ring_s
        while ring and ring[0][0] < oldest:
            ring.popleft()

    def _event(self, f: Fired) -> None:
        op = self.open
        if op is None:
            self.captures += 1
            self._trim(f.t)
            op = self.open = _Open(self.captures, f.t, f.t + self.after_s, list(self.ring))
        for e in op.events:
            if e.fired.key == f.key:
                e.repeats += 1
                return
        self.events += 1
        op.events.append(Event(self.events, f))

    def _close(self, complete: bool) -> Done:
        op = self.open
        assert op is not None
        self.open = None
        return Done(op.n, op.t_event, op.packets, op.events, complete, op.dropped)
