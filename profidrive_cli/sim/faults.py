"""Fault injection on the simulated bus (reference: issue "bus realism").

A FaultPlan decides, reply by reply, whether to corrupt, drop, delay or misaddress it, with a seeded
random generator so runs repeat. URL keys (rates are probabilities per reply, 0..1):

    noise=R      a garbage octet before the reply        flip=R     one bit flipped (FCS error)
    drop=R       no reply                               late=R     reply after the slot time
    wrongsa=R    reply with a wrong source address      only=3,5   limit injection to these stations

Every injection is counted in FaultPlan.counts so tests can check that the master accounted for each.
"""

from __future__ import annotations

import random

from profidrive_cli import UsageError

URL_KEYS = ("noise", "flip", "drop", "late", "wrongsa", "only")
KINDS = ("noise", "flip", "drop", "late", "wrongsa")


class FaultPlan:
    def __init__(self, rates: dict[str, float] | None = None, seed: int = 1,
                 only: set[int] | None = None, late_s: float = 0.2):
        self.rates = {k: float(v) for k, v in (rates or {}).items()}
        for k, v in self.rates.items():
            if k not in KINDS:
                raise ValueError(f"unknown fault kind {k}")
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"{k} rate {v} outside 0..1")
        self.rng = random.Random(seed)
        self.only = only
        self.late_s = late_s
        self.counts = {k: 0 for k in KINDS}
        #: one-shot injections queued by tests: list of (station, kind)
        self.queue: list[tuple[int, str]] = []

    def inject_next(self, station: int, kind: str) -> None:
        if kind not in KINDS:
            raise ValueError(f"unknown fault kind {kind}")
        self.queue.append((station, kind))

    def _choose(self, station: int) -> str | None:
        for i, (st, kind) in enumerate(self.queue):
            if st == station:
                del self.queue[i]
                return kind
        if self.only is not None and station not in self.only:
            return None
        for kind in KINDS:
            r = self.rates.get(kind, 0.0)
            if r and self.rng.random() < r:
                return kind
        return None

    def on_reply(self, bus, req, reply: bytes, t: float):
        """-> None (dropped) or (octets, extra delay in seconds)."""
        kind = self._choose(req.da)
        if kind is None:
            return reply, 0.0
        self.counts[kind] += 1
        if kind == "drop":
            return None
        if kind == "noise":
            return bytes((0x55,)) + reply, 0.0
        if kind == "flip":
            b = bytearray(reply)
            i = self.rng.randrange(1, len(b)) if len(b) > 1 else 0
            b[i] ^= 1 << self.rng.randrange(8)
            if bytes(b) == reply:
                b[0] ^= 0x01
            return bytes(b), 0.0
        if kind == "late":
            return reply, self.late_s
        if kind == "wrongsa":
            from profidrive_cli.fdl import frames as F
            r = F.parse(reply)
            if r is None or isinstance(r, F.FrameError):
                return reply, 0.0
            f, _ = r
            if f.sd in (F.SC, F.SD4):
                return reply, 0.0
            wrong = F.Frame(f.sd, f.da, (f.sa + 1) % 126, f.fc, f.data, f.dsap, f.ssap)
            return F.encode(wrong, force_sd2=f.sd == F.SD2), 0.0
        return reply, 0.0


def plan_from_query(q: dict[str, list[str]], seed: int = 1) -> FaultPlan:
    rates = {}
    for k in KINDS:
        if k in q:
            try:
                rates[k] = float(q[k][-1])
            except ValueError:
                raise UsageError(f"sim URL: {k}={q[k][-1]} is not a number") from None
    only = None
    if "only" in q:
        try:
            only = {int(x) for x in q["only"][-1].split(",") if x}
        except ValueError:
            raise UsageError(f"sim URL: only={q['only'][-1]} must be addresses") from None
    try:
        return FaultPlan(rates, seed=seed, only=only)
    except ValueError as e:
        raise UsageError(f"sim URL: {e}") from None
