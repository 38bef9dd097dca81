"""A watched live list: the stations on the bus, polled over and over, with their DP state, their
counters and how fast those rise, and the time one pass over the bus takes.

BusWatch(master, first, last) scans once (dp/scan.py), then each `step()` is one pass: a Slave_Diag
to every station found, and an FDL status to a few of the empty addresses (round robin, so a station
plugged in later appears without stalling the refresh). Between passes `wait_until()` sleeps on the
link's clock. Nothing here prints; cli/scan_watch.py renders a `WatchView`.

The state of a station is put into one of a few categories a live list colours:
    data exchange        parameterised by a master, ready (no Prm_Req, no fault bits)
    waiting              no master has parameterised it yet (Prm_Req), nothing wrong
    diagnosis pending    Stat_Diag or Ext_Diag set: the station has something to say
    configuration fault  Cfg_Fault or Prm_Fault: the master's Set_Prm/Chk_Cfg does not fit
    not supported        Not_Supported: the master asked for a function the station lacks
    no answer            no valid reply in this pass (after the configured retries)
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from profidrive_cli import BusError
from profidrive_cli.dp.scan import probe, scan

if TYPE_CHECKING:
    from profidrive_cli.dp.poller import Master
    from profidrive_cli.dp.services import SlaveDiag

#: counters shown and rated, in this order (keys of fdl.master.StationCounters)
COUNTER_KEYS = ("requests", "retries", "no_answer", "illegal", "reparams")

#: counter rates are shown once the window holds this much time
MIN_RATE_S = 0.5

CATEGORIES = ("data exchange", "waiting", "diagnosis pending", "configuration fault", "not supported",
              "no answer")


def categorize(diag: SlaveDiag | None) -> str:
    """The category of a Slave_Diag (None: no answer)."""
    if diag is None or diag.has("Station_Non_Existent"):
        return "no answer"
    if diag.has("Cfg_Fault") or diag.has("Prm_Fault"):
        return "configuration fault"
    if diag.has("Not_Supported"):
        return "not supported"
    if diag.has("Stat_Diag") or diag.has("Ext_Diag"):
        return "diagnosis pending"
    if diag.has("Prm_Req") or diag.has("Station_Not_Ready") or diag.master == 0xFF:
        return "waiting"
    return "data exchange"


@dataclass
class WatchedStation:
    address: int
    station_type: str
    ident: int | None = None
    state: str = ""                    # Slave_Diag state in words (dp.services.SlaveDiag.state_words)
    category: str = "no answer"
    master: int | None = None          # the master that parameterised it (None: none)
    counters: dict[str, int] = field(default_factory=dict)
    #: counter key -> rise per second over the window ({} at first)
    rates: dict[str, float] = field(default_factory=dict)
    seen_passes: int = 0
    #: FDL status requests it left unanswered before its first answer in the first scan (dp/scan.py
    #: ScanEntry.unanswered: the warm-up pass woke it, Baud_Search); 0 for a station found later by
    #: the round-robin probe, where an empty address cannot be told from a slave still waking
    unanswered_before: int = 0
    #: its answering record (bustools/causes.py Record): passes in a row without an answer up to
    #: now, when the first of them asked it (seconds of watching; None: it answers), and its last
    #: answer (None: none while watched)
    silent_passes: int = 0
    silent_since_s: float | None = None
    last_answer_s: float | None = None


@dataclass
class WatchView:
    """What one refresh shows."""
    t_s: float
    passes: int
    cycle_min_s: float | None
    cycle_mean_s: float | None
    cycle_max_s: float | None
    stations: list[WatchedStation]


class BusWatch:
    """A live list polled pass after pass. `window_s`: counter rates are taken over this much time;
    `probe_per_pass`: empty addresses probed per pass."""

    def __init__(self, master: Master, first: int = 0, last: int = 126, *, window_s: float = 5.0,
                 probe_per_pass: int = 4):
        self.master = master
        self.first, self.last = first, last
        self.window_s = window_s
        self.probe_per_pass = probe_per_pass
        self.stations: dict[int, WatchedStation] = {}
        self.passes = 0
        self._cycles: list[float] = []
        #: address -> (t, counters) snapshots
        self._history: dict[int, deque[tuple[float, dict[str, int]]]] = {}
        self._empty: list[int] = []
        self._probe_at = 0
        self.t0 = master.link.now()

    # -- the passes ------------------------------------------------------------------------------

    def start(self) -> None:
        """The first full scan of first..last."""
        found = scan(self.master, self.first, self.last)
        for e in found:
            self.stations[e.address] = WatchedStation(e.address, e.station_type,
                                                      unanswered_before=e.unanswered)
            if e.diag is not None:
                self._update_diag(self.stations[e.address], e.diag)
        self._empty = [a for a in range(self.first, self.last + 1)
                       if a not in self.stations and a != self.master.address]
        self.t0 = self.master.link.now()       # watching starts now: times count from here
        for ws in self.stations.values():
            ws.last_answer_s = 0.0     # the scan found it: it answered (at the latest) just before
        self._snapshot()

    def step(self) -> None:
        """One pass: Slave_Diag to every slave found, FDL status to a few empty addresses."""
        link = self.master.link
        t_start = link.now()
        for ws in self.stations.values():
            if ws.station_type != "slave":
                continue
            t_ask = self.now()
            try:
                diag = self.master.slave_diag(ws.address)
            except BusError:
                diag = None
            self._update_diag(ws, diag)
            self._answering(ws, t_ask)
        self._probe_some()
        self.passes += 1
        self._cycles.append(link.now() - t_start)
        del self._cycles[:-1000]
        self._snapshot()

    def wait_until(self, t: float) -> None:
        link = self.master.link
        left = t - link.now()
        if left > 0:
            link.sleep(left)

    def now(self) -> float:
        return self.master.link.now() - self.t0

    # -- what a refresh shows ----------------------------------------------------------------------

    def view(self) -> WatchView:
        cyc = self._cycles
        return WatchView(
            t_s=self.now(), passes=self.passes,
            cycle_min_s=min(cyc) if cyc else None,
            cycle_mean_s=sum(cyc) / len(cyc) if cyc else None,
            cycle_max_s=max(cyc) if cyc else None,
            stations=[self.stations[a] for a in sorted(self.stations)])

    # -- internals ---------------------------------------------------------------------------------

    def _update_diag(self, ws: WatchedStation, diag: SlaveDiag | None) -> None:
        ws.category = categorize(diag)
        if diag is None:
            ws.state = "no answer"
            return
        ws.seen_passes += 1
        ws.ident = diag.ident
        ws.state = diag.state_words(self.master.address)
        ws.master = None if diag.master == 0xFF else diag.master

    def _answering(self, ws: WatchedStation, t_ask: float) -> None:
        """The pass's entry in its answering record (t_ask: when this pass asked it)."""
        if ws.category == "no answer":
            if not ws.silent_passes:
                ws.silent_since_s = t_ask
            ws.silent_passes += 1
        else:
            ws.silent_passes, ws.silent_since_s = 0, None
            ws.last_answer_s = self.now()

    def _probe_some(self) -> None:
        if not self._empty:
            return
        n = min(self.probe_per_pass, len(self._empty))
        for _ in range(n):
            self._probe_at %= len(self._empty)
            addr = self._empty[self._probe_at]
            reply = probe(self.master, addr)
            if reply is None:
                self._probe_at += 1
                continue
            from profidrive_cli.fdl import frames as F
            st = F.STATION_TYPES[reply.station_type] if reply.sd != F.SC else "slave"
            self._empty.remove(addr)
            ws = self.stations[addr] = WatchedStation(addr, st)
            if st == "slave":
                t_ask = self.now()
                try:
                    self._update_diag(ws, self.master.slave_diag(addr))
                except BusError:
                    self._update_diag(ws, None)
                self._answering(ws, t_ask)
            if not self._empty:
                return

    def _snapshot(self) -> None:
        t = self.master.link.now()
        for a, ws in self.stations.items():
            c = self.master.fdl.counters_for(a).as_dict()
            ws.counters = {k: c.get(k, 0) for k in COUNTER_KEYS}
            hist = self._history.setdefault(a, deque())
            hist.append((t, ws.counters))
            while len(hist) > 2 and t - hist[1][0] >= self.window_s:
                hist.popleft()
            t_old, c_old = hist[0]
            dt = t - t_old
            # a rate over a few milliseconds says nothing: none until the window holds MIN_RATE_S
            ws.rates = ({k: (ws.counters[k] - c_old[k]) / dt for k in COUNTER_KEYS}
                        if dt >= min(MIN_RATE_S, self.window_s) else {})


def health_figures(before: dict[str, int], after: dict[str, int]) -> dict[str, float]:
    """Counter rises between two snapshots of one station (fdl StationCounters.as_dict()), and the
    retries per 1,000 requests: what a bus_health check compares with its thresholds."""
    d: dict[str, float] = {k: after.get(k, 0) - before.get(k, 0)
                           for k in ("requests", "retries", "no_answer", "illegal", "reparams",
                                     "data_exchanges")}
    d["retries_per_1000"] = 1000.0 * d["retries"] / d["requests"] if d["requests"] else 0.0
    return d


__all__ = ["BusWatch", "WatchView", "WatchedStation", "categorize", "health_figures", "CATEGORIES",
           "COUNTER_KEYS"]
