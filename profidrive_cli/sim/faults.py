"""Fault injection on the simulated bus.

A FaultPlan decides, reply by reply, whether to corrupt, drop, delay or misaddress it, and, at each
new Data_Exchange request to a station in data exchange, whether to power-cycle the station or trip
its drive. A seeded random generator makes runs repeat. URL keys (rates are probabilities, 0..1):

    noise=R       a garbage octet before the reply      flip=R        one bit flipped (FCS error)
    drop=R        no reply                              late=R        reply after the slot time
    wrongsa=R     reply with a wrong source address     late_ms=MS    how late (default 200 ms)
    powercycle=R  the station powers off and on: back to Wait_Prm, needs Set_Prm again
    drivetrip=R   the drive trips (model.trip) and the station flags new diagnosis (DH)
    tripcode=ADDR:CODE   the alarm drivetrip uses for a station (default: a family overcurrent)
    phantom=R     a lone noise octet 0xE5 (it reads as a short acknowledgement, SC) in the reply
                  slot of a request to an address where no station is (issue 26: `scan` must not
                  list it as a station)
    only=3,5      limit injection to these stations     seed=N        random seed
    unplug=3@5[-8]       station 3 is unplugged 5 s after the bus's first telegram (and plugged
                  in again at 8 s): it answers nothing meanwhile; repeat the key or use ',' for more

Python API: FaultPlan(rates, seed, only, late_s, trip_codes); plan.inject_next(station, kind) queues
a one-shot injection for the next reply (or Data_Exchange) of that station where it applies.

Every injection is counted in FaultPlan.counts (and per station in FaultPlan.by_station), and
expected_counters() says what pdrive's master must count for them (fdl/master.py):

    drop, late       one failed attempt: one retry (or a no-answer when the retries are used up)
    flip, wrongsa    one illegal frame + one failed attempt
    noise            one illegal frame, the reply behind it is taken (no retry)
    powercycle       the next Data_Exchange is answered RS: one RS + one re-parameterisation
                     (on a station of firstcontact=, sim/plant.py, the master's FCV=1 request after
                     the power cycle is ignored first: one no_answer with its retries more, then RS)
    drivetrip        one DH reply (the master then reads the diagnosis)
    phantom          nothing: the master takes the SC as an answer (scan asks again, dp/scan.py)
"""

from __future__ import annotations

import random
from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

from profidrive_cli import UsageError
from profidrive_cli.fdl import frames as F
from profidrive_cli.sim.slave import DATA_EXCH

if TYPE_CHECKING:
    from profidrive_cli.sim.slave import SimSlave


class Segment(Protocol):
    """What a FaultPlan sees of the bus (sim/bus.py SimBus, which imports this module): its stations."""

    @property
    def slaves(self) -> dict[int, SimSlave]: ...

REPLY_KINDS = ("noise", "flip", "drop", "late", "wrongsa")
STATION_KINDS = ("powercycle", "drivetrip")
KINDS = REPLY_KINDS + STATION_KINDS
#: injected where no station is (not on a station's traffic: KINDS above are the ones a station's
#: requests and replies can get); counted in FaultPlan.counts once they happen
SILENT_KINDS = ("phantom",)
ALL_KINDS = KINDS + SILENT_KINDS
#: the lone octet a phantom injects: the short acknowledgement SC (fdl/frames.py SC)
PHANTOM_OCTETS = bytes((F.SC,))
URL_KEYS = ALL_KINDS + ("only", "late_ms", "tripcode", "unplug")

#: alarm used by drivetrip when no tripcode is given: the first of these the profile knows
DEFAULT_TRIP_CODES = ("OC1", "OC", "E01", "EF0")


def default_trip_code(model: object) -> str:
    prof = getattr(model, "profile", None)
    codes = [a.code for a in getattr(prof, "alarms", [])] if prof is not None else []
    for c in DEFAULT_TRIP_CODES:
        if c in codes:
            return c
    if codes:
        code: str = codes[0]          # (an alarm's code; `prof` is looked up duck-typed)
        return code
    raise ValueError(f"{getattr(model, 'family', 'this')} station has no alarms to trip")


class FaultPlan:
    def __init__(self, rates: dict[str, float] | None = None, seed: int = 1,
                 only: set[int] | None = None, late_s: float = 0.2,
                 trip_codes: dict[int, str] | None = None):
        self.rates = {k: float(v) for k, v in (rates or {}).items()}
        for k, v in self.rates.items():
            if k not in ALL_KINDS:
                raise ValueError(f"unknown fault kind {k} (known: {', '.join(ALL_KINDS)})")
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"{k} rate {v} outside 0..1")
        if late_s <= 0:
            raise ValueError(f"late delay {late_s} s must be > 0")
        self.rng = random.Random(seed)
        self.only = only
        self.late_s = late_s
        self.trip_codes = dict(trip_codes or {})
        self.counts = {k: 0 for k in KINDS}
        self.by_station: dict[int, dict[str, int]] = {}
        #: one-shot injections queued by tests: list of (station, kind)
        self.queue: list[tuple[int, str]] = []
        #: (time, station, kind) of every injection, for a test that wants to look closer
        self.history: list[tuple[float, int, str]] = []
        #: timed unplugs: station -> (from, until or None), seconds after the first telegram
        self.unplugs: dict[int, tuple[float, float | None]] = {}
        self.t0: float | None = None

    # -- API ------------------------------------------------------------------------------------
    def inject_next(self, station: int, kind: str) -> None:
        if kind not in ALL_KINDS:
            raise ValueError(f"unknown fault kind {kind} (known: {', '.join(ALL_KINDS)})")
        self.queue.append((station, kind))

    def expected_counters(self, station: int | None = None) -> dict[str, int]:
        """What the master's counters must show for the injections so far (all stations, or one):
        illegal, failed_attempts (= retries + no_answer), rs, reparams, dh."""
        c = self.counts if station is None else self.by_station.get(station, {})

        def g(k: str) -> int:
            return c.get(k, 0)

        return {"illegal": g("flip") + g("wrongsa") + g("noise"),
                "failed_attempts": g("drop") + g("flip") + g("late") + g("wrongsa"),
                "rs": g("powercycle"), "reparams": g("powercycle"), "dh": g("drivetrip")}

    # -- decisions ------------------------------------------------------------------------------
    def _count(self, station: int, kind: str, t: float) -> None:
        self.counts[kind] = self.counts.get(kind, 0) + 1
        per = self.by_station.setdefault(station, {k: 0 for k in KINDS})
        per[kind] = per.get(kind, 0) + 1
        self.history.append((t, station, kind))

    def _choose(self, station: int, kinds: tuple[str, ...],
                applicable: Callable[[str], bool]) -> str | None:
        for i, (st, kind) in enumerate(self.queue):
            if st == station and kind in kinds and applicable(kind):
                del self.queue[i]
                return kind
        if self.only is not None and station not in self.only:
            return None
        for kind in kinds:
            r = self.rates.get(kind, 0.0)
            if r and self.rng.random() < r and applicable(kind):
                return kind
        return None

    def on_telegram(self, bus: Segment, t: float) -> None:
        """Every request on the bus: unplug (power off, silent) or plug in the stations of
        `unplugs` whose time has come (counted as kind "unplug" / "replug")."""
        if self.t0 is None:
            self.t0 = t
        rel = t - self.t0
        for a, (start, end) in self.unplugs.items():
            s = bus.slaves.get(a)
            if s is None or rel < start:
                continue
            off = end is None or rel < end
            if off and s.powered:
                if s.state == DATA_EXCH:
                    s.model.on_leave_data_exchange(t, "unplugged")
                s.powered = False
                self._count(a, "unplug", t)
            elif not off and not s.powered:
                s.power_on(t)
                s.powered = True
                self._count(a, "replug", t)

    def on_request(self, bus: Segment, slave: SimSlave, req: F.Frame, t: float) -> None:
        """A new Data_Exchange request to `slave` in data exchange, before the slave handles it."""
        kind = self._choose(slave.address, STATION_KINDS, lambda k: True)
        if kind is None:
            return
        self._count(slave.address, kind, t)
        if kind == "powercycle":
            slave.power_cycle(t)
        else:
            code = self.trip_codes.get(slave.address) or default_trip_code(slave.model)
            slave.inject_trip(code, t)

    def on_silence(self, bus: Segment, req: F.Frame, t: float) -> bytes | None:
        """A request that needs a reply, to an address where no station is: the octets of a
        phantom (a lone 0xE5 in the reply slot), or None (silence)."""
        kind = self._choose(req.da, SILENT_KINDS, lambda k: True)
        if kind is None:
            return None
        self._count(req.da, kind, t)
        return PHANTOM_OCTETS

    def on_reply(self, bus: Segment, req: F.Frame, reply: bytes, t: float) -> tuple[bytes, float] | None:
        """-> None (dropped) or (octets, extra delay in seconds)."""
        sc = reply[:1] == b"\xE5"
        kind = self._choose(req.da, REPLY_KINDS, lambda k: not (k == "wrongsa" and sc))
        if kind is None:
            return reply, 0.0
        self._count(req.da, kind, t)
        if kind == "drop":
            return None
        if kind == "noise":
            return bytes((0x55,)) + reply, 0.0
        if kind == "flip":
            b = bytearray(reply)
            i = self.rng.randrange(1, len(b)) if len(b) > 1 else 0
            b[i] ^= 1 << self.rng.randrange(8)
            return bytes(b), 0.0
        if kind == "late":
            return reply, self.late_s
        # wrongsa (never on an SC: it carries no address)
        parsed = F.parse(reply)
        assert isinstance(parsed, tuple), parsed      # a station's own reply: one whole telegram
        f, _ = parsed
        wrong = F.Frame(f.sd, f.da, (f.sa + 1) % 126, f.fc, f.data, f.dsap, f.ssap)
        return F.encode(wrong, force_sd2=f.sd == F.SD2), 0.0


def plan_from_query(q: dict[str, list[str]], seed: int = 1) -> FaultPlan:
    rates = {}
    for k in ALL_KINDS:
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
    late_s = 0.2
    if "late_ms" in q:
        try:
            late_s = float(q["late_ms"][-1]) / 1000.0
        except ValueError:
            raise UsageError(f"sim URL: late_ms={q['late_ms'][-1]} is not a number") from None
    codes: dict[int, str] = {}
    for v in q.get("tripcode", []):
        addr, _, code = v.partition(":")
        try:
            codes[int(addr)] = code.strip()
        except ValueError:
            raise UsageError(f"sim URL: tripcode={v} must be ADDRESS:CODE") from None
        if not code.strip():
            raise UsageError(f"sim URL: tripcode={v} must be ADDRESS:CODE")
    try:
        plan = FaultPlan(rates, seed=seed, only=only, late_s=late_s, trip_codes=codes)
    except ValueError as e:
        raise UsageError(f"sim URL: {e}") from None
    for v in q.get("unplug", []):
        plan.unplugs.update(_unplugs(v))
    return plan


def _unplugs(v: str) -> dict[int, tuple[float, float | None]]:
    """unplug=3@5 or 3@5-8 (seconds after the first telegram; an 's' may follow), ',' between."""
    out: dict[int, tuple[float, float | None]] = {}
    for item in filter(None, (x.strip() for x in v.split(","))):
        addr, at, when = item.partition("@")
        start, dash, end = when.replace("s", "").partition("-")
        try:
            a, t0, t1 = int(addr), float(start), (float(end) if dash else None)
        except ValueError:
            a, t0, t1 = -1, -1.0, None
        if not at or not 0 <= a <= 125 or t0 < 0 or (t1 is not None and t1 <= t0):
            raise UsageError(f"sim URL: unplug={v} must be ADDRESS@SECONDS[-SECONDS], e.g. "
                             f"unplug=3@5 or unplug=3@5-8")
        out[a] = (t0, t1)
    return out
