"""The records the monitor's parts share (issue 37): what the engine produces, the history stores,
the report, the web page and the exporters read. Plain frozen dataclasses and JSON-ready dicts; no
behaviour beyond turning them into dicts.

Times: `t` is wall-clock seconds since the epoch (float) -- on a real port time.time() of the moment
the telegram was heard; on the virtual plant the virtual clock anchored at the monitor's start.
Every part takes its "now" from the records it is given, never from time.time() itself, so that seven
virtual days are seven days to the history's retention and trends.

The live view (`Monitor.live()`, served as /api/live, read by metrics.py and the page) is a dict:

    {"t": float, "started": float, "port": str, "baud": int | None,
     "adapter": "connected" | "lost",              # the port: heard, or gone and being reopened
     "bus": {"frames": int, "tokens": int, "masters": [int], "load_percent": float | None,
             "rotation_s": float | None, "cycle_s": float | None, "errors": {kind: int}},
     "stations": [{"station": int, "state": str (passive_live's DP state words),
                   "colour": str (STATE_COLOURS), "ident": int | None, "ident_hex": str | None,
                   "profile": str | None, "drive_state": str | None, "fault": bool | None,
                   "counters": {name: int for name in SAMPLE_COUNTERS} (since the monitor started),
                   "cycle_s": float | None, "last_seen": float | None}],
     "causes": [{"title": str, "score": float, "stations": [int], "evidence": [str]}],
     "events": [MonEvent.as_dict(), newest first, at most LIVE_EVENTS],
     "events_total": int, "events_by_kind": {kind: int},
     "store": {"path": str, "bytes": int, "max_bytes": int, "full": bool, "removed": int} | None}
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

#: a station's counters the history samples (increments per interval) and the live view shows
#: (totals): passive_live's StationLive.exchanges and its counters
SAMPLE_COUNTERS = ("exchanges", "retries", "no_answer", "illegal", "reparams")

#: the events the live view carries (newest first); the history keeps them all
LIVE_EVENTS = 50

#: the kinds of MonEvent: the recorder's triggers (bustools/triggers.py) and the monitor's own
TRIGGER_KINDS = ("lost", "back", "rs", "rr", "nr", "ue", "diag", "fcs", "framing", "fault", "state",
                 "pkw", "cycle")
#: master: a master address not heard before began passing tokens or parameterising;
#: adapter: the port was lost ("lost") or heard again ("back"); disk: the store's disk full or
#: with room again; store: a fault of the history that is not a full disk (it goes on in memory)
OWN_KINDS = ("master", "adapter", "disk", "store")
EVENT_KINDS = TRIGGER_KINDS + OWN_KINDS

#: the page's colour per DP state (passive_live state words), as `scan --watch` colours its list
STATE_COLOURS = {
    "data exchange": "green",
    "parameterising": "cyan",
    "configuring": "cyan",
    "seen": "cyan",
    "diagnosis": "yellow",
    "released": "grey",
    "no answer": "red",
}


def state_colour(state: str) -> str:
    return STATE_COLOURS.get(state, "grey")


@dataclass(frozen=True)
class Sample:
    """One station over one sampling interval ending at `t`: its DP state at t, the increments of
    its counters (SAMPLE_COUNTERS, each >= 0) in the interval, its mean Data_Exchange cycle."""
    t: float
    interval_s: float
    station: int
    state: str
    counts: dict[str, int]
    cycle_mean_s: float | None = None

    def as_dict(self) -> dict[str, Any]:
        return {"t": self.t, "interval_s": self.interval_s, "station": self.station,
                "state": self.state, "counts": dict(self.counts), "cycle_mean_s": self.cycle_mean_s}


@dataclass(frozen=True)
class BusSample:
    """The bus over one sampling interval ending at `t`: frames, tokens and framing errors heard in
    it (increments), the bus load and the token rotation in it, the masters heard so far."""
    t: float
    interval_s: float
    frames: int
    tokens: int
    errors: int
    load_percent: float | None = None
    rotation_s: float | None = None
    masters: tuple[int, ...] = ()

    def as_dict(self) -> dict[str, Any]:
        return {"t": self.t, "interval_s": self.interval_s, "frames": self.frames,
                "tokens": self.tokens, "errors": self.errors, "load_percent": self.load_percent,
                "rotation_s": self.rotation_s, "masters": list(self.masters)}


@dataclass(frozen=True)
class StationInfo:
    """What is known of a station at `t`: its ident (Set_Prm, Slave_Diag), the drive profile it was
    watched with (--station, or learned from the ident) and its DP state."""
    t: float
    station: int
    ident: int | None
    profile: str | None
    state: str


@dataclass(frozen=True)
class MonEvent:
    """One event: a trigger that fired (the recorder's kinds) or one of the monitor's own
    (OWN_KINDS). `cause` and `evidence`: the likely cause ranked first for it, when any;
    `capture`: the capture's file name in the history's captures directory (None: none, or not
    written -- a full disk); `repeats`: the same trigger and station again inside its capture."""
    t: float
    kind: str
    station: int | None
    text: str
    cause: str | None = None
    evidence: tuple[str, ...] = ()
    repeats: int = 0
    capture: str | None = None

    def as_dict(self) -> dict[str, Any]:
        return {"t": self.t, "kind": self.kind, "station": self.station, "text": self.text,
                "cause": self.cause, "evidence": list(self.evidence), "repeats": self.repeats,
                "capture": self.capture}


@dataclass(frozen=True)
class StoreNote:
    """Something the history did or could not do, for the service to print and count: kind
    "removed" (rows or captures dropped for the disk bound or the retention, `count` of them),
    "full" / "room" (the disk), "failed" (a write that did not happen; `text` says what and why)."""
    kind: str
    text: str
    count: int = 0
    extra: dict[str, Any] = field(default_factory=dict)
