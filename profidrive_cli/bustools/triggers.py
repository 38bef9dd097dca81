"""The trigger language of the black-box recorder (`pdrive sniff --ring 30 --trigger EXPR`): what
makes an event, parsed with the text's position in errors, and evaluated on captured telegrams.

    EXPR     := TRIGGER ("," TRIGGER)*           several triggers; --trigger may also repeat
    TRIGGER  := NAME ["(" STATION ")"] [">" NUMBER UNIT]
    STATION  := 0..126 | "*"                     "*" (or no parentheses): every station

    lost(3)       station 3 stops answering (LOST_AFTER rounds in a row unanswered) or leaves
                  data exchange (its master sends it Set_Prm again)
    back(3)       a lost station answers again (is back in data exchange, when it was in it)
    rs(3) rr(3) nr(3) ue(3)   the station answered RS (SAP not enabled), RR (no resources),
                  NR (no response data), UE (user error)
    diag(3)       the station's Slave_Diag answer changed (status bits or extended diagnosis)
    fcs           a telegram with a wrong checksum
    framing       any other framing error (length, end delimiter, garbage octets)
    fault(7)      the drive's fault bit came or went (needs --station 7=PROFILE: its status word)
    state(7)      the drive's state changed (needs --station)
    pkw(7)        the drive answered a parameter request with an error (needs --station)
    cycle>20ms    a station's Data_Exchange cycle longer than 20 ms (units: us, ms, s);
                  cycle(3)>20ms for one station

Sans-IO: Captured frames in (dp/capture.py), Fired records out. The bus facts come from
bustools/passive_live.py (its notes), the drives' words from bustools/passive.py.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from profidrive_cli import UsageError
from profidrive_cli.bustools.passive_live import LiveList, Note

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.bustools.passive import PassiveDecoder
    from profidrive_cli.dp.capture import Captured

#: name -> (takes a station, needs the station's profile (--station), needs "> limit")
KINDS: dict[str, tuple[bool, bool, bool]] = {
    "lost": (True, False, False), "back": (True, False, False),
    "rs": (True, False, False), "rr": (True, False, False), "nr": (True, False, False),
    "ue": (True, False, False), "diag": (True, False, False),
    "fcs": (False, False, False), "framing": (False, False, False),
    "fault": (True, True, False), "state": (True, True, False), "pkw": (True, True, False),
    "cycle": (True, False, True),
}
UNITS = {"us": 1e-6, "ms": 1e-3, "s": 1.0}
MAX_STATION = 126


class TriggerError(UsageError):
    """A --trigger expression that does not parse: names the position (1-based column)."""

    def __init__(self, expr: str, pos: int, what: str):
        self.expr, self.position, self.what = expr, pos + 1, what
        super().__init__(f"--trigger {expr!r}: at position {pos + 1}: {what}")


@dataclass(frozen=True)
class Trigger:
    kind: str
    station: int | None = None       # None: every station (or a bus-wide kind)
    limit_s: float | None = None     # cycle: the longest cycle that does not fire

    @property
    def label(self) -> str:
        s = "" if not KINDS[self.kind][0] else f"({'*' if self.station is None else self.station})"
        lim = "" if self.limit_s is None else f">{self.limit_s * 1000:g}ms"
        return f"{self.kind}{s}{lim}"

    def matches(self, kind: str, station: int | None, value: float | None = None) -> bool:
        if kind != self.kind or (self.station is not None and station != self.station):
            return False
        return self.limit_s is None or (value is not None and value > self.limit_s)


@dataclass(frozen=True)
class Fired:
    """One trigger fired: which, by whom (station), when, and what happened in words."""
    trigger: Trigger
    station: int | None
    t: float
    text: str

    @property
    def key(self) -> tuple[str, int | None]:
        return self.trigger.label, self.station


# -- parsing ---------------------------------------------------------------------------------------

class _Parser:
    def __init__(self, expr: str):
        self.s, self.i = expr, 0

    def fail(self, what: str, at: int | None = None) -> TriggerError:
        return TriggerError(self.s, self.i if at is None else at, what)

    def ws(self) -> None:
        while self.i < len(self.s) and self.s[self.i].isspace():
            self.i += 1

    def peek(self) -> str:
        self.ws()
        return self.s[self.i] if self.i < len(self.s) else ""

    def word(self, chars: str) -> str:
        self.ws()
        j = self.i
        while self.i < len(self.s) and (self.s[self.i].isalnum() or self.s[self.i] in chars):
            self.i += 1
        return self.s[j:self.i]

    def parse(self) -> list[Trigger]:
        out = [self.trigger()]
        while self.peek() == ",":
            self.i += 1
            out.append(self.trigger())
        if self.peek():
            raise self.fail(f"unexpected {self.peek()!r} (triggers are separated by ',')")
        return out

    def trigger(self) -> Trigger:
        self.ws()
        at = self.i
        name = self.word("_").lower()
        if not name:
            raise self.fail("expected a trigger name (" + ", ".join(KINDS) + ")"
                            if self.peek() else "expected a trigger after ','" if at else
                            "empty trigger expression")
        if name not in KINDS:
            raise self.fail(f"unknown trigger {name!r} (known: {', '.join(KINDS)})", at)
        takes, _, needs_limit = KINDS[name]
        station = None
        if self.peek() == "(":
            if not takes:
                raise self.fail(f"{name} takes no station (it is bus-wide)")
            self.i += 1
            station = self.station()
            if self.peek() != ")":
                raise self.fail("expected ')' after the station")
            self.i += 1
        limit = None
        if self.peek() == ">":
            if not needs_limit:
                raise self.fail(f"{name} takes no limit (only cycle>TIME does)")
            self.i += 1
            limit = self.duration()
        elif needs_limit:
            raise self.fail(f"{name} needs a limit, e.g. {name}>20ms")
        return Trigger(name, station, limit)

    def station(self) -> int | None:
        if self.peek() == "*":
            self.i += 1
            return None
        at = self.i
        w = self.word("")
        if not (w.isascii() and w.isdigit()) or int(w) > MAX_STATION:
            raise self.fail(f"expected a station address 0..{MAX_STATION} or '*'"
                            + (f", got {w!r}" if w else ""), at)
        return int(w)

    def duration(self) -> float:
        self.ws()
        at = j = self.i
        while j < len(self.s) and (self.s[j].isdigit() or self.s[j] == "."):
            j += 1
        num = self.s[self.i:j]
        self.i = j
        unit = self.word("").lower()
        try:
            value = float(num)
        except ValueError:
            raise self.fail("expected a time such as 20ms", at) from None
        if unit not in UNITS:
            raise self.fail(f"expected a unit ({', '.join(UNITS)}) after {num}", j)
        if value <= 0:
            raise self.fail("the limit must be above 0", at)
        return value * UNITS[unit]


def parse(expr: str) -> list[Trigger]:
    """One --trigger expression -> its triggers; TriggerError (exit 2) names the position."""
    return _Parser(expr).parse()


def parse_all(exprs: list[str] | tuple[str, ...], watched: set[int] | None = None) -> list[Trigger]:
    """Every --trigger value; the drive triggers (fault, state, pkw) checked against the stations
    given with --station (`watched`): without its profile a drive's words cannot be read."""
    out: list[Trigger] = []
    for e in exprs:
        for t in parse(e):
            if t not in out:
                out.append(t)
    if not out:
        raise UsageError("--trigger: give at least one trigger, e.g. --trigger 'lost(*)'")
    watched = watched or set()
    for t in out:
        if not KINDS[t.kind][1]:
            continue
        if t.station is None and not watched:
            raise UsageError(f"--trigger {t.label}: needs --station ADDRESS=PROFILE for the drives "
                             f"to watch (their profiles decode the status word)")
        if t.station is not None and t.station not in watched:
            raise UsageError(f"--trigger {t.label}: needs --station {t.station}=PROFILE "
                             f"(its profile decodes the status word)")
    return out


def every_label() -> list[str]:
    """A label of every form a trigger can take -- each kind, for one station, for every station
    (`*`) and at the address limits, with a limit where the kind needs one: the recorder's file
    pattern ({trigger}) is checked against each before it records."""
    out: list[str] = []
    for kind, (takes, _, needs_limit) in KINDS.items():
        for station in ((None, 0, MAX_STATION) if takes else (None,)):
            label = Trigger(kind, station, 0.02 if needs_limit else None).label
            if label not in out:
                out.append(label)
    return out


# -- evaluation ------------------------------------------------------------------------------------

def is_fault(d: dict[str, Any]) -> bool:
    """A decoded response (bustools/passive.py) says the drive is in fault: its state begins with
    "fault" (PROFIdrive S-state fault, Yaskawa fault, Toyo "fault: ...") or its status flags
    include the fault bit."""
    state = str(d.get("state") or "").lower()
    return state.startswith("fault") or "fault" in (d.get("status") or [])


class TriggerSet:
    """feed(captured frame) -> the triggers it fired. Owns the LiveList it reads the bus facts
    from (exposed as `live`, for the causes and the figures) and, with drive triggers, the
    PassiveDecoder of the --station stations."""

    def __init__(self, triggers: list[Trigger], decoder: PassiveDecoder | None = None,
                 baud: int | None = None):
        self.triggers = triggers
        limits = [t.limit_s for t in triggers if t.limit_s is not None]
        self.live = LiveList(baud=baud, notes=True, cycle_limit_s=min(limits, default=float("inf")))
        self.decoder = decoder if any(KINDS[t.kind][1] for t in triggers) else None
        self._fault: dict[int, bool] = {}
        self._state: dict[int, str] = {}

    def feed(self, c: Captured) -> list[Fired]:
        live = self.live
        live.feed(c)
        notes = live.notes
        assert notes is not None
        happened = list(notes)
        notes.clear()
        if self.decoder is not None:
            happened += self._drive(c)
        out: list[Fired] = []
        for n in happened:
            for t in self.triggers:
                if t.matches(n.kind, n.station, n.value):
                    out.append(Fired(t, n.station, n.t, n.text))
                    break
        return out

    def drive_state(self, station: int) -> tuple[str | None, bool | None]:
        """A decoded drive's last state in words and whether it is in fault (None, None: not decoded
        yet, or not a drive this set decodes)."""
        if station not in self._fault:
            return None, None
        return self._state.get(station) or None, self._fault[station]

    def _drive(self, c: Captured) -> list[Note]:
        assert self.decoder is not None
        f = c.frame
        if f is not None and f.fc & 0x40 and f.dsap is None:
            return []               # a Data_Exchange request: the triggers read the drives' answers
        # (a Chk_Cfg still goes to the decoder: it names the layout); state, flags and parameter
        # channel only, not the Hz (speed=False)
        d = self.decoder.decode(c, speed=False)
        if d is None or "error" in d or d.get("direction") != "response":
            return []
        a = d["station"]
        out: list[Note] = []
        fault, state = is_fault(d), str(d.get("state") or "")
        was = self._fault.get(a)
        if was is not None and was != fault:
            out.append(Note("fault", a, c.t, f"drive {a} ({d['profile']}): fault "
                            + (f"on ({state or ', '.join(d.get('status') or [])})" if fault
                               else "cleared")))
        self._fault[a] = fault
        old = self._state.get(a)
        if old is not None and old != state:
            out.append(Note("state", a, c.t, f"drive {a} ({d['profile']}): {old or '-'} -> "
                            f"{state or '-'}"))
        self._state[a] = state
        p = d.get("param")
        if p and p.get("error") is not None:
            out.append(Note("pkw", a, c.t, f"drive {a} ({d['profile']}): parameter channel error: "
                            f"{p.get('text', '')}"))
        return out
