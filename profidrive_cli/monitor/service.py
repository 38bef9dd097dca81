"""The monitor's loop: the port listened to for as long as it is asked (never written to), the engine
fed, its output stored and handed on; every recoverable fault an event, and on it goes.

    summary = run(link, opener, engine, history, say=..., duration=None)

- Listening is bustools/listen.py on the link's own clock (a virtual plant's clock runs as fast as
  the reads go: seven virtual days in minutes).
- A closed capture is written to the history first (its file name goes into its events), then its
  events are stored, counted in the live view, said (one line or one JSON object) and handed to
  the sinks (MQTT). A sample, a station's new state and the monitor's own events go the same way.
- The port lost (LinkLost: USB adapter pulled, pty or socket closed) is an event "adapter" and the
  port is opened again every `retry_s` (link.reopen(); where a link cannot, `opener()` anew) until
  it answers: a second event "adapter" says it is back. While it is away the live view says
  "lost" and the web page and exporters go on serving.
- The history's own faults (a full disk, a write that failed) come back as StoreNotes: "full" and
  "room" are events "disk", "failed" an event "store", removals for the disk bound a line each
  (counted in the store's status). None of them ends the loop.
- Only `duration` (link seconds), KeyboardInterrupt or Stopped (the cli's SIGTERM) end it; the open
  capture is written and a last sample taken on the way out, and the run is closed in the history.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

from profidrive_cli import BusError
from profidrive_cli.bustools.listen import POLL_S, listen
from profidrive_cli.link.base import LinkLost
from profidrive_cli.monitor.engine import Monitor, Output
from profidrive_cli.monitor.model import MonEvent, StoreNote

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.link.base import Link
    from profidrive_cli.monitor.store import History

#: how often a lost port is tried again (seconds on the link's clock)
RETRY_S = 2.0
#: how often the live view is rebuilt for the page and the exporters (real seconds: the likely causes
#: are ranked there, which a virtual week at every tick would pay for nothing)
LIVE_EVERY_S = 1.0


class Stopped(Exception):
    """Asked to end (SIGTERM, systemd's stop): the loop ends as on Ctrl-C, writing what is open."""


class Sink(Protocol):
    """An exporter that is told of events and of stations' states (monitor/mqtt.py MqttAlarms)."""

    def event(self, ev: MonEvent) -> None: ...

    def station_state(self, station: int, state: str, drive_state: str | None,
                      fault: bool | None) -> None: ...

    def close(self, timeout: float = 2.0) -> None: ...


class LiveBox:
    """The newest live view, shared with the web page's threads."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._view: dict[str, Any] = {}

    def put(self, view: dict[str, Any]) -> None:
        with self._lock:
            self._view = view

    def get(self) -> dict[str, Any]:
        with self._lock:
            return self._view


@dataclass
class Summary:
    events: int = 0
    captures: int = 0
    telegrams: int = 0
    seconds: float = 0.0
    adapter_losses: int = 0
    ended: str = "duration"


Say = Callable[[dict[str, Any], str], None]


class _Run:
    def __init__(self, engine: Monitor, history: History | None, say: Say, sinks: Sequence[Sink],
                 box: LiveBox | None, clock: Callable[[], float]):
        self.engine, self.history, self.say, self.sinks, self.box = engine, history, say, sinks, box
        self.clock = clock
        self.summary = Summary()
        self._live_at = float("-inf")
        self._states: dict[int, tuple[str, str | None, bool | None]] = {}

    # -- output of the engine --------------------------------------------------------------------
    def handle(self, out: Output) -> None:
        if not out:
            return
        eng, hist = self.engine, self.history
        events: list[MonEvent] = []
        for done in out.captures:
            name: str | None = None
            if hist is not None and done.packets:
                first = done.events[0].fired if done.events else None
                hint = "bus" if first is None else (
                    f"{first.trigger.kind}-{'bus' if first.station is None else first.station}")
                name, notes = hist.save_capture(eng.wall(done.t_event), hint, done.packets, eng.wall0)
                self.notes(notes)
                if name is not None:
                    self.summary.captures += 1
            events += eng.events_of(done, name)
        events += out.events
        if hist is not None and (events or out.samples or out.bus or out.stations):
            self.notes(hist.write(samples=out.samples, bus=out.bus, stations=out.stations,
                                  events=events))
        for ev in events:
            self.announce(ev)

    def announce(self, ev: MonEvent) -> None:
        """An event stored (or queued by a full store): counted, said, handed to the sinks."""
        self.engine.note(ev)
        self.summary.events += 1
        self.say({"event": "monitor", **ev.as_dict(), "time": _iso(ev.t)}, _line(ev))
        for s in self.sinks:
            s.event(ev)

    def own_event(self, ev: MonEvent) -> None:
        if self.history is not None:
            self.notes(self.history.write(events=[ev]))
        self.announce(ev)

    def notes(self, notes: list[StoreNote]) -> None:
        """The history's notes: a full disk and room again are events (kind disk), a failed write
        an event (kind store), removals for the bound one line each."""
        for n in notes:
            if n.kind == "removed":
                self.say({"event": "removed", "text": n.text, "count": n.count, **n.extra},
                         f"{_stamp(time.time())}  {n.text}")
                continue
            kind = "disk" if n.kind in ("full", "room") else "store"
            ev = MonEvent(t=self.engine.wall(self.engine.t), kind=kind, station=None, text=n.text)
            if self.history is not None:
                # a full store queues it (bounded) and writes it when there is room again
                self.history.write(events=[ev])
            self.announce(ev)

    # -- the live view -----------------------------------------------------------------------------
    def refresh(self, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self._live_at < LIVE_EVERY_S:
            return
        self._live_at = now
        eng = self.engine
        if self.history is not None:
            eng.store_status = self.history.status()
        view = eng.live()
        if self.box is not None:
            self.box.put(view)
        if self.sinks:
            for st in view["stations"]:
                key = (st["state"], st["drive_state"], st["fault"])
                if self._states.get(st["station"]) != key:
                    self._states[st["station"]] = key
                    for s in self.sinks:
                        s.station_state(st["station"], *key)


def run(link: Link, engine: Monitor, history: History | None, *, say: Say,
        opener: Callable[[], Link] | None = None, duration: float | None = None,
        sinks: Sequence[Sink] = (), box: LiveBox | None = None, retry_s: float = RETRY_S,
        port: str = "", poll_s: float = POLL_S) -> Summary:
    """Listen until `duration` link seconds have passed (None: until KeyboardInterrupt or
    Stopped). The link is closed on the way out; the history is not (the caller owns it). A read
    returns at least every `poll_s` link seconds (a virtual plant's idle reads cost CPU only)."""
    clock = link.now
    t0 = clock()
    r = _Run(engine, history, say, sinks, box, clock)
    if history is not None:
        r.notes(history.begin_run(engine.wall(0.0), port or engine.port, engine.baud))
    r.refresh(force=True)
    ended = "duration"

    def on_data(data: bytes, _t: float) -> None:
        r.summary.telegrams += 1
        r.handle(engine.feed(data, clock() - t0))

    def on_tick(_t: float) -> None:
        r.handle(engine.tick(clock() - t0))
        r.refresh()

    try:
        try:
            link.flush_input()
        except BusError:
            pass
        while True:
            left = None if duration is None else duration - (clock() - t0)
            if left is not None and left <= 0:
                break
            try:
                listen(link, left, on_data, clock=clock, on_tick=on_tick, poll_s=poll_s)
                break                                   # the duration is over
            except LinkLost as e:
                try:
                    link = _reconnect(link, opener, e, r, engine, t0, duration, retry_s)
                except _DurationOver:
                    break
                clock = link.now
                r.clock = clock
    except KeyboardInterrupt:
        ended = "interrupted"
    except Stopped:
        ended = "stopped"
    finally:
        t_end = clock() - t0
        try:
            link.close()
        except Exception:                               # a port already gone
            pass
        r.handle(engine.close(t_end))
        r.refresh(force=True)
        if history is not None:
            r.notes(history.end_run(engine.wall(t_end), ended))
        r.summary.seconds = t_end
        r.summary.ended = ended
    return r.summary


def _reconnect(link: Link, opener: Callable[[], Link] | None, e: LinkLost, r: _Run, engine: Monitor,
               t0: float, duration: float | None, retry_s: float) -> Link:
    """The port was lost: an event, then a try every retry_s until it is back (another event).
    Returns the link to go on with. Ends (Stopped) only when the duration runs out meanwhile."""
    clock = link.now
    t = clock() - t0
    r.handle(engine.lost_link(t))
    r.summary.adapter_losses += 1
    r.own_event(MonEvent(t=engine.wall(t), kind="adapter", station=None,
                         text=f"adapter lost: {e}; trying again every {retry_s:g} s"))
    r.refresh(force=True)
    tries = 0
    while True:
        if duration is not None and clock() - t0 >= duration:
            raise _DurationOver()
        try:
            link.sleep(retry_s)
        except BusError:
            time.sleep(retry_s)
        tries += 1
        try:
            try:
                link.reopen()
            except NotImplementedError:
                if opener is None:
                    raise
                link = opener()
        except BusError:
            r.refresh()
            continue
        except OSError:
            r.refresh()
            continue
        break
    clock = link.now
    t = clock() - t0
    engine.adapter = "connected"
    r.own_event(MonEvent(t=engine.wall(t), kind="adapter", station=None,
                         text=f"adapter back after {tries} tr{'y' if tries == 1 else 'ies'}"))
    r.refresh(force=True)
    return link


class _DurationOver(Exception):
    """The duration ran out while the port was away (ends the run as the duration does)."""


def _stamp(t: float) -> str:
    from datetime import datetime
    return datetime.fromtimestamp(t).strftime("%Y-%m-%d %H:%M:%S")


def _iso(t: float) -> str:
    from datetime import datetime
    return datetime.fromtimestamp(t).isoformat(timespec="milliseconds")


def _line(ev: MonEvent) -> str:
    where = "bus" if ev.station is None else f"station {ev.station}"
    why = f"; likely: {ev.cause}" if ev.cause else ""
    cap = f"; capture {ev.capture}" if ev.capture else ""
    rep = f" (x{ev.repeats + 1})" if ev.repeats else ""
    return f"{_stamp(ev.t)}  {ev.kind}{rep}  {where}: {ev.text}{why}{cap}"
