"""The monitor's engine: what a listener left on a line makes of what it hears, sans-IO.

    m = Monitor(baud=1_500_000, watched=watch_list(["3=fuji-g1"]), wall0=time.time())
    out = m.feed(octets, t)          # t: seconds on the link's clock since the monitor started
    out = m.tick(t)                  # after every read, data or not
    m.live(t)                        # the live view (monitor/model.py)

Inside, bustools' parts, each as `sniff` uses it: the capture decoder (dp/capture.py), the trigger
set with its passive live list (the DP state, counters, cycle and bus figures of every station),
the recorder (the ring and one capture per event: an event's capture closes `after_s` after it, and
only then are its events handed out, each with the likely cause ranked first for its station) and
the passive decoder of the drives (their state and fault from their Data_Exchange). The drives are
those given (--station) and those learned from the traffic: a station whose ident (Set_Prm, Slave
Diag) is a profile's (drives.profile.profile_for_ident) is decoded from then on with that profile.

The monitor's own events: a master address not heard in the first MASTERS_SETTLE_S that passes tokens
or parameterises stations (kind "master"). The adapter's and the disk's events are the service's
(monitor/service.py), which hands every event back through note() so that the live view and its
counts carry them.

Counters are sampled every `interval_s`: per station the increments of SAMPLE_COUNTERS and its mean
Data_Exchange cycle over the interval, for the bus the frames, tokens and framing errors heard, the
bus load and the token rotation in it (Output.samples / Output.bus). Memory is bounded whatever
the run's length: the live list holds at most 127 stations, the recorder its ring (MAX_RING
telegrams) and one open capture, the live view LIVE_EVENTS events, the counts one entry per kind
and per cause title.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from profidrive_cli.bustools.causes import Cause, likely_causes
from profidrive_cli.bustools.passive import PassiveDecoder, Watched
from profidrive_cli.bustools.passive_live import BITS_PER_OCTET, StationLive
from profidrive_cli.bustools.recorder import MAX_RING, Done, Recorder
from profidrive_cli.bustools.triggers import Trigger, TriggerSet
from profidrive_cli.dp.capture import Capture, merge_errors
from profidrive_cli.monitor.model import (
    LIVE_EVENTS, SAMPLE_COUNTERS, BusSample, MonEvent, Sample, StationInfo, state_colour,
)

#: every trigger the monitor records (bustools/triggers.py): a station lost or back, its RS/RR/NR/UE
#: answers, a diagnosis change, framing errors, a drive's fault, state and parameter-channel errors
MONITOR_TRIGGERS = tuple(Trigger(k) for k in ("lost", "back", "rs", "rr", "nr", "ue", "diag", "fcs",
                                              "framing", "fault", "state", "pkw"))
#: masters heard in this first part of a run are the line's own; one heard later is an event
MASTERS_SETTLE_S = 10.0
#: the cause a "master" event names (bustools/causes.py's rule of the same name gives its evidence in
#: the live view's causes)
SECOND_MASTER = "second master"
#: the defaults of `pdrive monitor` (docs/monitor.md)
DEFAULT_INTERVAL_S = 60.0
DEFAULT_RING_S = 30.0
DEFAULT_AFTER_S = 10.0
#: how often (link seconds) the engine looks for new drives, masters and stations' states: after
#: every read would cost a saturated line's CPU for nothing
LOOK_EVERY_S = 0.5
#: cause titles counted for the live view and /metrics, at most (a new title past it is "other")
MAX_CAUSE_TITLES = 64


@dataclass
class Output:
    """What one feed() or tick() produced, for the service to store and hand on."""
    captures: list[Done] = field(default_factory=list)
    events: list[MonEvent] = field(default_factory=list)       # the monitor's own (no capture)
    samples: list[Sample] = field(default_factory=list)
    bus: BusSample | None = None
    stations: list[StationInfo] = field(default_factory=list)   # new or changed since the last

    def __bool__(self) -> bool:
        return bool(self.captures or self.events or self.samples or self.bus or self.stations)


@dataclass
class _Mark:
    """A station's counters at the last sample."""
    counts: dict[str, int]
    cycle_n: int = 0
    cycle_total: float = 0.0


class Monitor:
    def __init__(self, *, baud: int | None, watched: Mapping[int, Watched] | None = None,
                 wall0: float = 0.0, interval_s: float = DEFAULT_INTERVAL_S,
                 ring_s: float = DEFAULT_RING_S, after_s: float = DEFAULT_AFTER_S,
                 learn: bool = True, max_ring: int = MAX_RING, port: str = ""):
        if interval_s <= 0:
            raise ValueError("interval_s must be positive")
        self.baud = baud
        self.wall0 = wall0
        self.port = port
        self.interval_s = interval_s
        self.learn = learn
        self.decoder = PassiveDecoder(dict(watched or {}))
        self.tset = TriggerSet(list(MONITOR_TRIGGERS), self.decoder, baud=baud)
        self.live_list = self.tset.live
        self.recorder = Recorder(self.tset, ring_s, after_s, max_ring=max_ring)
        self.capture = Capture()
        self._tried_idents: dict[int, int | None] = {}      # station -> the ident last looked up
        self._masters_known: set[int] = set()
        self._next_sample = interval_s
        self._next_look = 0.0
        self._heard = False                          # telegrams fed since the last look
        self._last_sample_t = 0.0
        self._marks: dict[int, _Mark] = {}
        self._bus_mark = (0, 0, 0, 0, 0, 0.0)      # frames, tokens, errors, octets, rotation n, total
        self._infos: dict[int, tuple[int | None, str | None, str]] = {}
        #: the likely cause standing when an event of the open capture fired (by Event.n; None: no
        #: cause then): a lost station is blamed while it is silent, and may be back before its
        #: capture closes; a cause that comes later is not an earlier event's
        self._causes_seen: dict[int, tuple[str, tuple[str, ...]] | None] = {}
        self.recent: deque[MonEvent] = deque(maxlen=LIVE_EVENTS)
        self.events_total = 0
        self.by_kind: dict[str, int] = {}
        self.by_cause: dict[str, int] = {}
        self.adapter = "connected"
        self.store_status: dict[str, Any] | None = None
        self.t = 0.0

    # -- time --------------------------------------------------------------------------------------
    def wall(self, t: float) -> float:
        """Wall-clock seconds of link time t."""
        return self.wall0 + t

    # -- input -------------------------------------------------------------------------------------
    def feed(self, data: bytes, t: float) -> Output:
        """Octets heard at link time t."""
        self.t = max(self.t, t)
        out = Output()
        self._heard = True
        fired = self.recorder.events
        out.captures += self.recorder.feed(merge_errors(self.capture.feed(data, t)))
        if self.recorder.events != fired:
            self._see_causes()
        return out

    def tick(self, t: float) -> Output:
        """The time now (after every read): closes capture windows, learns drives and masters,
        takes the samples that are due."""
        self.t = max(self.t, t)
        out = Output()
        out.captures += self.recorder.tick(t)
        if t >= self._next_look and self._heard:      # (a silent line changes none of it)
            self._next_look = t + LOOK_EVERY_S
            self._heard = False
            if self.learn:
                self._learn_drives()
            out.events += self._masters(t)
            out.stations += self._station_infos(t)
        if t >= self._next_sample:
            self._sample(t, out)
        return out

    def close(self, t: float) -> Output:
        """The listening ended: the open capture with what it has, a last sample."""
        out = Output()
        out.captures += self.recorder.close()
        if t > self._last_sample_t:
            self._sample(t, out)
        out.stations += self._station_infos(t)
        return out

    def lost_link(self, t: float) -> Output:
        """The port went away: the open capture ends here (what comes after the reconnect is another
        stretch of the line), the telegram half-read is dropped."""
        self.adapter = "lost"
        self.capture = Capture()
        out = Output()
        out.captures += self.recorder.close()
        return out

    # -- events ------------------------------------------------------------------------------------
    def events_of(self, done: Done, capture: str | None) -> list[MonEvent]:
        """A closed capture's events as MonEvents, each with the likely cause ranked first for its
        station (or for the bus) and the capture's file name."""
        causes = likely_causes(self.live_list)
        out = []
        for e in done.events:
            f = e.fired
            seen = (self._causes_seen.pop(e.n) if e.n in self._causes_seen
                    else _best(causes, f.station))
            out.append(MonEvent(t=self.wall(f.t), kind=f.trigger.kind, station=f.station, text=f.text,
                                cause=None if seen is None else seen[0],
                                evidence=() if seen is None else seen[1],
                                repeats=e.repeats, capture=capture))
        if self.recorder.open is None:
            self._causes_seen.clear()          # (bounded: only the open capture's are kept)
        return out

    def _see_causes(self) -> None:
        """The events that just fired (in the open capture) get the cause ranked first now."""
        op = self.recorder.open
        if op is None:
            return
        todo = [e for e in op.events if e.n not in self._causes_seen]
        if todo:
            causes = likely_causes(self.live_list)
            for e in todo:
                self._causes_seen[e.n] = _best(causes, e.fired.station)

    def note(self, ev: MonEvent) -> None:
        """An event that was recorded (or could not be): the live view shows it and counts it."""
        self.recent.appendleft(ev)
        self.events_total += 1
        self.by_kind[ev.kind] = self.by_kind.get(ev.kind, 0) + 1
        if ev.cause:
            title = ev.cause if (ev.cause in self.by_cause
                                 or len(self.by_cause) < MAX_CAUSE_TITLES) else "other"
            self.by_cause[title] = self.by_cause.get(title, 0) + 1

    # -- learning ----------------------------------------------------------------------------------
    def _learn_drives(self) -> None:
        from profidrive_cli.drives.profile import profile_for_ident
        watched = self.decoder.watched
        for a, st in self.live_list.stations.items():
            if st.ident is None or a in watched or self._tried_idents.get(a) == st.ident:
                continue
            self._tried_idents[a] = st.ident
            try:
                prof = profile_for_ident(st.ident)
            except Exception:              # a broken profile file: the station stays undecoded
                prof = None
            if prof is not None:
                watched[a] = Watched(a, prof)

    def _masters(self, t: float) -> list[MonEvent]:
        new = self.live_list.masters - self._masters_known
        if not new:
            return []
        self._masters_known |= new
        if t < MASTERS_SETTLE_S or len(self._masters_known) == len(new):
            return []                      # the line's own master(s)
        known = sorted(self._masters_known - new)
        return [MonEvent(t=self.wall(t), kind="master", station=None,
                         text=f"master {m} heard on the line (besides master "
                              f"{', '.join(map(str, known))}): tokens or Set_Prm from a second master",
                         cause=SECOND_MASTER,
                         evidence=(f"masters heard: {', '.join(map(str, sorted(self._masters_known)))}",))
                for m in sorted(new)]

    # -- samples -----------------------------------------------------------------------------------
    def _sample(self, t: float, out: Output) -> None:
        live = self.live_list
        span = t - self._last_sample_t
        wall = self.wall(t)
        for a, st in sorted(live.stations.items()):
            now = _counts(st)
            mark = self._marks.get(a) or _Mark({k: 0 for k in SAMPLE_COUNTERS})
            inc = {k: max(0, now[k] - mark.counts.get(k, 0)) for k in SAMPLE_COUNTERS}
            dn = st.cycle.n - mark.cycle_n
            mean = (st.cycle.total - mark.cycle_total) / dn if dn > 0 else None
            out.samples.append(Sample(t=wall, interval_s=span, station=a, state=st.state, counts=inc,
                                      cycle_mean_s=None if mean is None else round(mean, 6)))
            self._marks[a] = _Mark(now, st.cycle.n, st.cycle.total)
        frames, tokens, errors, octets, rn, rt = self._bus_figures()
        f0, t0, e0, o0, rn0, rt0 = self._bus_mark
        load = None
        if self.baud and span > 0:
            load = round(100.0 * (octets - o0) * BITS_PER_OCTET / (self.baud * span), 3)
            load = load if load <= 100.0 else None
        rot = round((rt - rt0) / (rn - rn0), 6) if rn > rn0 else None
        out.bus = BusSample(t=wall, interval_s=span, frames=frames - f0, tokens=tokens - t0,
                            errors=errors - e0, load_percent=load, rotation_s=rot,
                            masters=tuple(sorted(live.masters)))
        self._bus_mark = (frames, tokens, errors, octets, rn, rt)
        self._last_sample_t = t
        while self._next_sample <= t:
            self._next_sample += self.interval_s

    def _bus_figures(self) -> tuple[int, int, int, int, int, float]:
        live = self.live_list
        rn, rt = 0, 0.0
        if live.rotation:
            m = max(live.rotation, key=lambda a: live.rotation[a].n)
            rn, rt = live.rotation[m].n, live.rotation[m].total
        return live.frames, live.tokens, sum(live.errors.values()), live.octets, rn, rt

    def _station_infos(self, t: float) -> list[StationInfo]:
        out = []
        for a, st in sorted(self.live_list.stations.items()):
            w = self.decoder.watched.get(a)
            key = (st.ident, None if w is None else w.name, st.state)
            if self._infos.get(a) != key:
                self._infos[a] = key
                out.append(StationInfo(t=self.wall(t), station=a, ident=st.ident, profile=key[1],
                                       state=st.state))
        return out

    # -- the live view -----------------------------------------------------------------------------
    def live(self, t: float | None = None) -> dict[str, Any]:
        """The live view (monitor/model.py documents its keys)."""
        t = self.t if t is None else t
        live = self.live_list
        stations = []
        for a, st in sorted(live.stations.items()):
            w = self.decoder.watched.get(a)
            drive_state, fault = self.tset.drive_state(a)
            stations.append({
                "station": a, "state": st.state, "colour": state_colour(st.state),
                "ident": st.ident, "ident_hex": None if st.ident is None else f"0x{st.ident:04X}",
                "profile": None if w is None else w.name, "drive_state": drive_state, "fault": fault,
                "counters": _counts(st),
                "cycle_s": None if not st.cycle.n else round(st.cycle.total / st.cycle.n, 6),
                "last_seen": None if st.last_answer_t is None else self.wall(st.last_answer_t)})
        cyc = live.bus_cycle()
        rot = live.token_rotation()
        return {
            "t": self.wall(t), "started": self.wall0, "port": self.port, "baud": self.baud,
            "adapter": self.adapter,
            "bus": {"frames": live.frames, "tokens": live.tokens, "masters": sorted(live.masters),
                    "load_percent": live.bus_load(t) if t > 0 else None,
                    "rotation_s": None if rot is None else rot["mean"],
                    "cycle_s": None if cyc is None else cyc["mean"],
                    "errors": dict(sorted(live.errors.items()))},
            "stations": stations,
            "causes": [c.as_dict() for c in likely_causes(live)],
            "events": [e.as_dict() for e in self.recent],
            "events_total": self.events_total, "events_by_kind": dict(self.by_kind),
            "events_by_cause": dict(self.by_cause),
            "store": self.store_status,
        }


def _counts(st: StationLive) -> dict[str, int]:
    c = st.counters
    return {"exchanges": st.exchanges, "retries": c.get("retries", 0),
            "no_answer": c.get("no_answer", 0), "illegal": c.get("illegal", 0),
            "reparams": c.get("reparams", 0)}


def _best(causes: list[Cause], station: int | None) -> tuple[str, tuple[str, ...]] | None:
    """The cause ranked first for a station (a cause of no station: the whole line; an event of no
    station: any cause): its title and evidence."""
    for c in causes:
        if not c.stations or station is None or station in c.stations:
            return c.title, tuple(c.evidence)
    return None
