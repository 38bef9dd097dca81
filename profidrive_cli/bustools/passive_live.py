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
after data exchange). Bus-wide: frames, tokens, masters seen, and framing errors by kind; the bus
load (busy bit times / elapsed bit times, when the baud rate is known), the token rotation per
master, and the figures bustools/causes.py reads (watchdog expiries, reply delays, idents).

With `notes=True` the list also writes down what happened (a station lost or back, an RS/RR/NR/UE
answer, a diagnosis change, a framing error, a cycle over `cycle_limit_s`) as Note records in
`notes`, which the recorder's triggers (bustools/triggers.py) drain after every frame.

Sans-IO: dp.capture.Captured in (their arrival times), plain dicts out.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, NamedTuple

from profidrive_cli.dp import services as S
from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.timing import CHAR_BITS, BusParams

if TYPE_CHECKING:
    from profidrive_cli.dp.capture import Captured

PARAMETERISING = "parameterising"
CONFIGURING = "configuring"
DATA_EXCHANGE = "data exchange"
DIAGNOSIS = "diagnosis"
NO_ANSWER = "no answer"
RELEASED = "released"
SEEN = "seen"

_EXPECTS_REPLY = frozenset(F.NEEDS_REPLY)
_SRD_SDA = frozenset((F.SRD_LOW, F.SRD_HIGH, F.SDA_LOW, F.SDA_HIGH))
#: reply statuses of a station with diagnosis pending (high priority)
_HIGH = frozenset((F.DH, F.RDH))
_SAP_DIAG = S.SAP_SLAVE_DIAG
#: a station is lost when this many rounds in a row went unanswered: requests to it, a repeat of
#: the request before (a retry: the same FCB with FCV = 1, or the same telegram again right after
#: it went unanswered) not counted. One request and its retries lost is what a line that drops at
#: random does to every station now and then; bustools/causes.py blames a station after as many
#: (SILENT_AFTER), and `scan --watch` counts its passes against the same number
LOST_AFTER = 4
#: one octet on the line: start bit, 8 data bits, even parity, stop bit (11 bit times per octet)
BITS_PER_OCTET = CHAR_BITS
#: a reply this late (after its own octets' wire time) is late whatever the capture's timing
#: resolution: the arrival times of a capture through a USB adapter or a pty, on a busy machine, are
#: good to some ms only
LATE_FLOOR_S = 0.02
#: the reply statuses a trigger can name (fdl/frames.py RESPONSE_NAMES)
STATUS_KINDS = {F.RS: "rs", F.RR: "rr", F.NR: "nr", F.UE: "ue"}


class Note(NamedTuple):
    """Something that happened on the line (notes=True): kind (lost, back, rs, rr, nr, ue, diag,
    fcs, framing, cycle), the station (None: bus-wide), the time, the evidence in words and a
    figure (cycle: the interval in seconds)."""
    kind: str
    station: int | None
    t: float
    text: str
    value: float | None = None


def slot_s(baud: int | None) -> float:
    try:
        return BusParams.for_baud(baud).tsl / baud if baud else 0.0
    except (KeyError, ValueError):             # not a PROFIBUS rate: no slot time
        return 0.0


def bus_load_percent(octets: int, seconds: float, baud: int | None) -> float | None:
    """Busy bit times / elapsed bit times, in percent: octets x 11 bit / (baud x seconds). None when
    it cannot be told: no baud rate, no time, or a figure over 100 % (more octets than the line
    carries in that time at `baud`: the capture's line ran faster than the rate assumed)."""
    if not baud or seconds <= 0:
        return None
    load = 100.0 * octets * BITS_PER_OCTET / (baud * seconds)
    return round(load, 2) if load <= 100.0 else None


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

    def as_dict(self) -> dict[str, float] | None:
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
    counters: dict[str, int] = field(default_factory=lambda: {"retries": 0, "no_answer": 0, "illegal": 0,
                                                    "reparams": 0})
    cycle: _Cycle = field(default_factory=_Cycle)
    last_fcb: bool | None = None
    last_dx_t: float | None = None
    was_dx: bool = False
    drive: dict[str, object] = field(default_factory=dict)   # the last decoded request / response (--station)
    silent: int = 0                  # rounds unanswered in a row (LOST_AFTER)
    silent_since: float | None = None    # when they began: the first unanswered request's time
    lost: bool = False               # lost (LOST_AFTER unanswered, or left data exchange), not back
    lost_in_dx: bool = False         # ... and it was in data exchange then
    last_answer_t: float | None = None   # None: it never answered
    prev_req_t: float | None = None  # the request to it before the last one
    last_req_t: float | None = None
    wd_s: float | None = None        # the watchdog from its last Set_Prm (None: off / not seen)
    #: (t, silence s, watchdog s), the last few
    wd_expiries: list[tuple[float, float, float]] = field(default_factory=list)
    diag: bytes | None = None        # its last Slave_Diag answer
    diag_idents: set[int] = field(default_factory=set)
    sets_prm_from: set[int] = field(default_factory=set)   # masters that sent it Set_Prm
    statuses: dict[str, int] = field(default_factory=dict)      # rs/rr/nr/ue answers counted
    late: int = 0                    # replies later than LiveList.late_s (request -> reply)
    late_max: float = 0.0            # the latest of them (s)

    def as_dict(self) -> dict[str, object]:
        d: dict[str, object] = {"station": self.address, "state": self.state,
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
    repeat: bool = False             # a retry of the request before it (one round with it)
    raw: bytes = b""


class LiveList:
    """feed() every captured frame; snapshot() the list as a dict."""

    def __init__(self, baud: int | None = None, notes: bool = False,
                 cycle_limit_s: float = float("inf"),
                 explain: Callable[[LiveList], list[dict[str, Any]]] | None = None):
        self.stations: dict[int, StationLive] = {}
        self.masters: set[int] = set()
        self.frames = 0
        self.tokens = 0
        self.octets = 0
        self._bad = 0                                 # framing errors, all kinds
        self.baud = baud
        self.errors: dict[str, int] = {}
        self.token_from: dict[int, int] = {}          # tokens passed by each master
        self.rotation: dict[int, _Cycle] = {}         # token rotation per master
        self._token_t: dict[int, float] = {}
        self.notes: list[Note] | None = [] if notes else None
        self.cycle_limit_s = cycle_limit_s
        #: the likely causes in a snapshot (bustools/causes.py causes_json; None: not asked for)
        self.explain = explain
        #: a reply later than this is counted late (the slot time, at least LATE_FLOOR_S)
        self.late_s = max(LATE_FLOOR_S, slot_s(baud))
        self._pending: _Pending | None = None
        #: the last request that went unanswered, while nothing else came after it (a repeat of it
        #: is the same round)
        self._unanswered: _Pending | None = None

    def _note(self, kind: str, station: int | None, t: float, text: str,
              value: float | None = None) -> None:
        if self.notes is not None:
            self.notes.append(Note(kind, station, t, text, value))

    def station(self, address: int) -> StationLive:
        st = self.stations.get(address)
        if st is None:
            st = self.stations[address] = StationLive(address)
        return st

    # -- feeding ---------------------------------------------------------------------------------
    def feed(self, c: Captured) -> None:
        self.frames += 1
        self.octets += len(c.raw)
        f = c.frame
        if f is None:
            kind = c.error.split(":", 1)[0].strip() or "error"
            self.errors[kind] = self.errors.get(kind, 0) + 1
            self._bad += 1
            if self.notes is not None and self.frames > self._bad:      # a whole frame before it
                # (octets before the first whole frame are the tail of one the capture joined)
                self._note("fcs" if kind == F.FrameError.FCS else "framing", None, c.t,
                           f"{c.error} ({len(c.raw)} octets: {c.raw[:12].hex(' ')})")
            if self._pending is not None and kind != F.FrameError.GARBAGE:
                self._pending.station.counters["illegal"] += 1     # its reply came corrupt
                self._pending = None
            return
        if f.sd == F.SD4:
            self.tokens += 1
            self.masters.add(f.sa)
            self.token_from[f.sa] = self.token_from.get(f.sa, 0) + 1
            last = self._token_t.get(f.sa)
            if last is not None:
                self.rotation.setdefault(f.sa, _Cycle()).add(c.t - last)
            self._token_t[f.sa] = c.t
            self._no_answer(c.t)
            return
        if f.sd == F.SC:
            self._answered(c, high=False)
            return
        if f.fc & F.FC_REQ:                                  # (f.is_request: not SC, not SD4)
            self._request(c, f)
        elif self._pending is not None and self._pending.station.address == f.sa:
            status = f.fc & 0x0F
            if status in STATUS_KINDS:
                self._status(c, self._pending.station, status)
            if f.ssap == _SAP_DIAG and len(f.data) >= 6:
                self._diag(c, self._pending.station, bytes(f.data))
            self._answered(c, high=status in _HIGH)
        else:
            self._pending = None           # a reply nobody is waiting for (another master's?)

    def _status(self, c: Captured, st: StationLive, status: int) -> None:
        kind = STATUS_KINDS[status]
        st.statuses[kind] = st.statuses.get(kind, 0) + 1
        if status == F.RS and st.wd_s is not None and _gap(st) > st.wd_s:
            self._wd_expired(c.t, st)
        self._note(kind, st.address, c.t, f"station {st.address} answered "
                   f"{F.RESPONSE_NAMES.get(status, status)}")

    def _wd_expired(self, t: float, st: StationLive) -> None:
        assert st.wd_s is not None
        st.wd_expiries = (st.wd_expiries + [(round(t, 6), round(_gap(st), 6), st.wd_s)])[-5:]

    def _diag(self, c: Captured, st: StationLive, data: bytes) -> None:
        st.diag_idents.add(data[4] << 8 | data[5])
        old, st.diag = st.diag, data
        if old is None or self.notes is None:
            return
        # octet 3 is the master's address, octets 4..5 the ident: the rest is the station's state
        key_old, key_new = old[:3] + old[6:], data[:3] + data[6:]
        if key_old != key_new:
            self._note("diag", st.address, c.t, f"station {st.address} diagnosis changed: "
                       f"{diag_change(old, data)}")

    def _no_answer(self, t: float) -> None:
        p = self._pending
        if p is not None:
            st = p.station
            st.counters["no_answer"] += 1
            st.state = NO_ANSWER
            if not p.repeat:
                if not st.silent:
                    st.silent_since = p.t
                st.silent += 1
            self._pending = None
            self._unanswered = p
            if st.silent == LOST_AFTER and st.last_answer_t is not None and not st.lost:
                st.lost, st.lost_in_dx = True, st.was_dx
                since = "" if st.last_answer_t is None else f"; last answer at {st.last_answer_t:.3f} s"
                self._note("lost", st.address, t, f"station {st.address} stopped answering: "
                           f"{LOST_AFTER} rounds in a row unanswered{since}")

    def _answered(self, c: Captured, high: bool) -> None:
        p = self._pending
        self._pending = None
        if p is None:
            return
        st = p.station
        st.silent, st.silent_since = 0, None
        st.last_answer_t = c.t
        d = c.t - p.t
        if d > self.late_s:
            # request -> reply: from the request's arrival to the reply's first octet on the line
            d -= len(c.raw) * BITS_PER_OCTET / self.baud if self.baud else 0.0
            if d > self.late_s:
                st.late += 1
                st.late_max = max(st.late_max, d)
        if st.lost and (p.dx or not st.lost_in_dx):
            st.lost = False
            self._note("back", st.address, c.t, f"station {st.address} is back"
                       + (" in data exchange" if p.dx else " (answers again)"))
        if p.dx:
            st.exchanges += 1
            st.was_dx = True
            st.state = DIAGNOSIS if high else DATA_EXCHANGE
        elif st.state == NO_ANSWER:
            st.state = SEEN

    def _request(self, c: Captured, f: F.Frame) -> None:
        self._unanswered = None
        self._no_answer(c.t)
        before, self._unanswered = self._unanswered, None
        self.masters.add(f.sa)
        if f.da == F.BROADCAST:
            return
        st = self.station(f.da)
        st.master = f.sa
        st.prev_req_t, st.last_req_t = st.last_req_t, c.t
        fc = f.fc
        fn = fc & 0x0F                                      # (f.function, f.fcv, f.fcb)
        if fn in _SRD_SDA:
            fcb = bool(fc & F.FC_FCB)
            if fc & F.FC_FCV and st.last_fcb is not None and fcb == st.last_fcb:
                st.counters["retries"] += 1
                retry = True
            else:
                retry = False
            st.last_fcb = fcb
        else:
            retry = False
        dx = f.dsap is None and f.ssap is None and fn in (F.SRD_LOW, F.SRD_HIGH)
        if dx:
            if not retry:
                if st.last_dx_t is not None:
                    dt = c.t - st.last_dx_t
                    st.cycle.add(dt)
                    if dt > self.cycle_limit_s:
                        self._note("cycle", st.address, c.t, f"station {st.address}: "
                                   f"{dt * 1000:.1f} ms between two Data_Exchange", dt)
                st.last_dx_t = c.t
        elif f.dsap == S.SAP_SET_PRM:
            st.last_dx_t = None
            st.sets_prm_from.add(f.sa)
            status = f.data[0] if f.data else 0
            if len(f.data) >= 6:
                st.ident = f.data[4] << 8 | f.data[5]
            if len(f.data) >= 3:
                st.wd_s = (f.data[1] * f.data[2] * 0.01) if status & 0x08 else None
            if status & 0x40 and not status & 0x80:
                st.state = RELEASED
                st.was_dx = False
            else:
                if st.was_dx and not retry:
                    st.counters["reparams"] += 1
                    if st.wd_s is not None and _gap(st) > st.wd_s:
                        self._wd_expired(c.t, st)
                    if not st.lost:
                        st.lost, st.lost_in_dx = True, True
                        self._note("lost", st.address, c.t, f"station {st.address} left data "
                                   f"exchange: master {f.sa} parameterises it again")
                st.was_dx = False
                st.state = PARAMETERISING
        elif f.dsap == S.SAP_CHK_CFG:
            st.state = CONFIGURING
        elif f.dsap == S.SAP_SLAVE_DIAG and st.state == DATA_EXCHANGE:
            st.state = DIAGNOSIS
        if fn in _EXPECTS_REPLY:
            same = before is not None and before.station is st and before.raw == c.raw
            self._pending = _Pending(st, dx, c.t, retry or same, c.raw)

    # -- reading ---------------------------------------------------------------------------------
    def bus_cycle(self) -> dict[str, float] | None:
        """The master's Data_Exchange cycle over every station: min of the minima, mean of all
        intervals, max of the maxima."""
        cs = [s.cycle for s in self.stations.values() if s.cycle.n]
        if not cs:
            return None
        n = sum(x.n for x in cs)
        return {"min": round(min(x.lo for x in cs), 6), "mean": round(sum(x.total for x in cs) / n, 6),
                "max": round(max(x.hi for x in cs), 6)}

    def bus_load(self, t: float) -> float | None:
        """The bus load in percent from the capture's start to `t` (seconds since the start);
        None: baud rate unknown."""
        return bus_load_percent(self.octets, t, self.baud)

    def token_rotation(self) -> dict[str, float] | None:
        """The token rotation of the master that passed the most tokens: {min, mean, max, n}."""
        if not self.rotation:
            return None
        m = max(self.rotation, key=lambda a: self.rotation[a].n)
        return self.rotation[m].as_dict()

    def snapshot(self, t: float) -> dict[str, object]:
        snap: dict[str, object] = {"t_s": round(t, 3), "frames": self.frames, "tokens": self.tokens,
                "masters": sorted(self.masters), "cycle_s": self.bus_cycle(),
                "bus_load_percent": self.bus_load(t), "token_rotation_s": self.token_rotation(),
                "errors": dict(sorted(self.errors.items())),
                "stations": [s.as_dict() for _, s in sorted(self.stations.items())]}
        if self.explain is not None:
            snap["causes"] = self.explain(self)
        return snap


def _gap(st: StationLive) -> float:
    """The master's silence towards a station before its last request (0: no earlier request)."""
    return 0.0 if st.prev_req_t is None or st.last_req_t is None else st.last_req_t - st.prev_req_t


def diag_change(old: bytes, new: bytes) -> str:
    """What changed between two Slave_Diag answers, in the standard's bit names."""
    parts = []
    for i, names in enumerate((S.ST1_BITS, S.ST2_BITS, S.ST3_BITS)):
        for bit, name in enumerate(names):
            was, now = old[i] >> bit & 1, new[i] >> bit & 1
            if was != now and name not in ("always 1", "reserved"):
                parts.append(("+" if now else "-") + name)
    if old[6:] != new[6:]:
        parts.append(f"extended diagnosis {old[6:].hex(' ') or '-'} -> {new[6:].hex(' ') or '-'}")
    return ", ".join(parts) or "no change"
