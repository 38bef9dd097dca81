"""The passive live list (`pdrive sniff --live`): what a listener can tell about every station from
the traffic alone, without sending a single octet.

Per station: its DP state as the master's requests and the station's replies show it
(parameterising: Set_Prm; configuring: Chk_Cfg; data exchange: Data_Exchange answered;
diagnosis: the station answered Data_Exchange with high priority (diagnosis pending) or the master
reads its Slave_Diag while in data exchange; no answer: a request that expects a reply was followed
by the next request or a token instead; released: Set_Prm with Unlock_Req), its ident from Set_Prm,
the master's Data_Exchange cycle time (min / mean / max between two Data_Exchange requests to it)
and counters in the dp layer's names: retries (a request repeated with the same FCB, FCV = 1),
no_answer, illegal (a reply that was corrupt: FCS, length, delimiter), reparams (Set_Prm again
after data exchange). Bus-wide: frames, tokens, masters seen, and framing errors by kind.

Sans-IO: dp.capture.Captured in (their arrival times), plain dicts out.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from profidrive_cli.dp import services as S
from profidrive_cli.fdl import frames as F

PARAMETERISING = "parameterising"
CONFIGURING = "configuring"
DATA_EXCHANGE = "data exchange"
DIAGNOSIS = "diagnosis"
NO_ANSWER = "no answer"
RELEASED = "released"
SEEN = "seen"

_EXPECTS_REPLY = frozenset(F.NEEDS_REPLY)
_SRD_SDA = frozenset((F.SRD_LOW, F.SRD_HIGH, F.SDA_LOW, F.SDA_HIGH))


@dataclass
class _Cycle:
    n: int = 0
    total: float = 0.0
    lo: float = float("inf")
    hi: float = 0.0

    def add(self, dt: float) -> None:
        self.n += 1
        self.total += dt
        self.lo = min(self.lo, dt)
        self.hi = max(self.hi, dt)

    def as_dict(self) -> dict | None:
        if not self.n:
            return None
        return {"min": round(self.lo, 6), "mean": round(self.total / self.n, 6),
                "max": round(self.hi, 6), "n": self.n}


@dataclass
class StationLive:
    address: int
    state: str = SEEN
    ident: int | None = None
    master: int | None = None
    exchanges: int = 0
    counters: dict = field(default_factory=lambda: {"retries": 0, "no_answer": 0, "illegal": 0,
                                                    "reparams": 0})
    cycle: _Cycle = field(default_factory=_Cycle)
    last_fcb: bool | None = None
    last_dx_t: float | None = None
    was_dx: bool = False
    drive: dict = field(default_factory=dict)     # the last decoded request / response (--station)

    def as_dict(self) -> dict:
        d = {"station": self.address, "state": self.state,
             "ident": self.ident, "ident_hex": None if self.ident is None else f"0x{self.ident:04X}",
             "master": self.master, "exchanges": self.exchanges,
             "cycle_s": self.cycle.as_dict(), "counters": dict(self.counters)}
        if self.drive:
            d["drive"] = dict(self.drive)
        return d


@dataclass
class _Pending:
    station: StationLive
    dx: bool
    t: float


class LiveList:
    """feed() every captured frame; snapshot() the list as a dict."""

    def __init__(self):
        self.stations: dict[int, StationLive] = {}
        self.masters: set[int] = set()
        self.frames = 0
        self.tokens = 0
        self.errors: dict[str, int] = {}
        self._pending: _Pending | None = None

    def station(self, address: int) -> StationLive:
        st = self.stations.get(address)
        if st is None:
            st = self.stations[address] = StationLive(address)
        return st

    # -- feeding ---------------------------------------------------------------------------------
    def feed(self, c) -> None:
        self.frames += 1
        f = c.frame
        if f is None:
            kind = c.error.split(":", 1)[0].strip() or "error"
            self.errors[kind] = self.errors.get(kind, 0) + 1
            if self._pending is not None and kind != F.FrameError.GARBAGE:
                self._pending.station.counters["illegal"] += 1     # its reply came corrupt
                self._pending = None
            return
        if f.sd == F.SD4:
            self.tokens += 1
            self.masters.add(f.sa)
            self._no_answer()
            return
        if f.sd == F.SC:
            self._answered(c, high=False)
            return
        if f.is_request:
            self._request(c, f)
        elif self._pending is not None and self._pending.station.address == f.sa:
            self._answered(c, high=f.fc & 0x0F in (F.DH, F.RDH))
        else:
            self._pending = None           # a reply nobody is waiting for (another master's?)

    def _no_answer(self) -> None:
        p = self._pending
        if p is not None:
            p.station.counters["no_answer"] += 1
            p.station.state = NO_ANSWER
            self._pending = None

    def _answered(self, c, high: bool) -> None:
        p = self._pending
        self._pending = None
        if p is None:
            return
        st = p.station
        if p.dx:
            st.exchanges += 1
            st.was_dx = True
            st.state = DIAGNOSIS if high else DATA_EXCHANGE
        elif st.state == NO_ANSWER:
            st.state = SEEN

    def _request(self, c, f: F.Frame) -> None:
        self._no_answer()
        self.masters.add(f.sa)
        if f.da == F.BROADCAST:
            return
        st = self.station(f.da)
        st.master = f.sa
        fn = f.function
        if fn in _SRD_SDA:
            if f.fcv and st.last_fcb is not None and f.fcb == st.last_fcb:
                st.counters["retries"] += 1
                retry = True
            else:
                retry = False
            st.last_fcb = f.fcb
        else:
            retry = False
        dx = f.dsap is None and f.ssap is None and fn in (F.SRD_LOW, F.SRD_HIGH)
        if dx:
            if not retry:
                if st.last_dx_t is not None:
                    st.cycle.add(c.t - st.last_dx_t)
                st.last_dx_t = c.t
        elif f.dsap == S.SAP_SET_PRM:
            st.last_dx_t = None
            status = f.data[0] if f.data else 0
            if len(f.data) >= 6:
                st.ident = f.data[4] << 8 | f.data[5]
            if status & 0x40 and not status & 0x80:
                st.state = RELEASED
                st.was_dx = False
            else:
                if st.was_dx and not retry:
                    st.counters["reparams"] += 1
                st.was_dx = False
                st.state = PARAMETERISING
        elif f.dsap == S.SAP_CHK_CFG:
            st.state = CONFIGURING
        elif f.dsap == S.SAP_SLAVE_DIAG and st.state == DATA_EXCHANGE:
            st.state = DIAGNOSIS
        if fn in _EXPECTS_REPLY:
            self._pending = _Pending(st, dx, c.t)

    # -- reading ---------------------------------------------------------------------------------
    def bus_cycle(self) -> dict | None:
        """The master's Data_Exchange cycle over every station: min of the minima, mean of all
        intervals, max of the maxima."""
        cs = [s.cycle for s in self.stations.values() if s.cycle.n]
        if not cs:
            return None
        n = sum(x.n for x in cs)
        return {"min": round(min(x.lo for x in cs), 6), "mean": round(sum(x.total for x in cs) / n, 6),
                "max": round(max(x.hi for x in cs), 6)}

    def snapshot(self, t: float) -> dict:
        return {"t_s": round(t, 3), "frames": self.frames, "tokens": self.tokens,
                "masters": sorted(self.masters), "cycle_s": self.bus_cycle(),
                "errors": dict(sorted(self.errors.items())),
                "stations": [s.as_dict() for _, s in sorted(self.stations.items())]}
