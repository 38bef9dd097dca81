"""Several drives in one run (pdrive run 3,4,5): one DriveStation per station on one master, all on one
bus cycle (group.py: the Group), each drive at its own speed; the stop of every drive on every way out.

Order: identify every station (nothing written), check --sync against every station's GSD, ask once
(confirm), bring every station to data exchange (with Sync_Req / Freeze_Req under --sync), read the
max frequencies, start the drives one after the other at speed 0 (each start is the drive's own
handshake; the others keep their cycle meanwhile), send every reference in one round (with --sync
they take effect in the same instant), then cycle them all until --duration, q, a fault or a station
dropping out. Then the stop: the stop command of every drive in one cycle (with --sync: taking effect
in the same instant), a bounded wait for all of them together, a coast stop for each drive that does
not stop in its time (or at once on a second signal), then Unsync/Unfreeze, release, close.

The stations come from the bus (api.Bus, through the Stations protocol below: session/ does not
import api/): Bus.session hands over one DriveStation per station on its master, not yet opened;
the run closes the bus (so the port) once at its end, after the close of every session.

Decided: a drive that trips, or a station that drops out of data exchange, ends the run for all: every
other drive is stopped too (a line of drives runs together or not at all) and the exit code is 1.
No click and no rich here: the cli renders through the callbacks.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Protocol, Sequence

from profidrive_cli import BusError, UsageError
from profidrive_cli.drives.base import DriveError
from profidrive_cli.link.base import LinkLost
from profidrive_cli.session.group import Group, StationOut
from profidrive_cli.session.live import NOT_REACHED, Reach, end_status, fault_name, trip_words
from profidrive_cli.session.signals import SessionTerminated, SignalGuard

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.dp.poller import Master
    from profidrive_cli.gsd.model import Gsd
    from profidrive_cli.session.cycle import Sample
    from profidrive_cli.session.station import DriveStation

DEFAULT_WATCHDOG_MS = 500


class Stations(Protocol):
    """Where the run's stations come from: api.Bus (api/bus.py; session/ does not import api/)."""

    @property
    def master(self) -> "Master": ...

    def station(self, station: int | None = None, *, watchdog_ms: float = 500,
                cycle_hz: float | None = None, handle_signals: bool = True,
                on_message: Callable[[str], None] | None = None) -> "DriveStation":
        """A DriveStation for `station` on this bus's master, not yet opened; its close leaves the
        port open."""
        ...

    def close(self, exc: BaseException | None = None) -> None:
        """Close the port (once: a second close does nothing)."""
        ...


def _gsd_in_library(ident: int) -> "tuple[Gsd | None, str | None]":
    from profidrive_cli.gsd.library import find_by_ident, find_path_by_ident
    g = find_by_ident(ident)
    path = find_path_by_ident(ident) if g is not None else None
    return g, (path.name if path is not None else None)


def sync_modes(sessions: Sequence["DriveStation"],
               gsd_for: "Callable[[int], tuple[Gsd | None, str | None]] | None" = None
               ) -> tuple[bool, bool]:
    """--sync: (Sync, Freeze) when every station's GSD claims Sync_Mode_supp (Freeze too when every
    one claims Freeze_Mode_supp); UsageError naming the first station that does not."""
    if gsd_for is None:
        gsd_for = _gsd_in_library
    freeze = True
    for s in sessions:
        assert s.ident is not None and s.profile is not None    # identified: ident and profile known
        g, name = gsd_for(s.ident)
        who = f"station {s.address} ({s.profile.name}, ident 0x{s.ident:04X})"
        if g is None:
            raise UsageError(f"--sync: {who} has no GSD file in the library or --gsd-dir / "
                             f"PDRIVE_GSD_DIR, so whether it supports Sync is unknown; nothing was written")
        if not g.sync_mode_supp:
            raise UsageError(f"--sync: {who}: its GSD {name} does not claim Sync_Mode_supp; "
                             f"nothing was written")
        freeze = freeze and bool(g.freeze_mode_supp)
    return True, freeze


@dataclass
class StationRun:
    """One drive of the run: its session, reference and what happened to it."""
    session: "DriveStation"
    address: int
    ref: tuple[str, float]               # ("hz" | "percent", value)
    percent: float = 0.0
    started: bool = False
    t_start: float = 0.0                 # when its reference went (the run's clock)
    reached_after: float | None = None
    reach: Reach | None = None           # the one "reached" rule, from the reference's round
    last: "Sample | None" = None         # the last Sample
    problem: str = ""                    # why this drive failed (trip, dropped out, not reached ...)
    tripped: bool = False

    def to_dict(self) -> dict[str, Any]:
        s = self.session
        rep = s.motion.stop_report
        fs = end_status(s)                  # with a fault's code where the stop read it
        return {"station": self.address, "profile": s.profile.name if s.profile else None,
                "started": self.started, "reached_after_s": self.reached_after,
                "stop": rep.to_dict() if rep is not None else None,
                "stopped": bool(rep.stopped) if rep is not None else not self.started,
                "state": fs.state if fs is not None else None,
                "fault": fs.fault if fs is not None else None,
                "fault_code": fs.fault_code if fs is not None else None,
                "fault_name": fault_name(s.profile, fs.fault_code) if fs is not None else None,
                "problem": self.problem or None, "counters": s.counters}


@dataclass
class MultiRun:
    """The run on `bus` (an api.Bus: its sessions, its master; the run closes it at the end);
    callbacks (all optional): on_start(header), on_phase(phase, address or None),
    on_sample(address, t_s, sample, phase), on_end(end), confirm(sessions), should_quit() -> bool,
    on_message(text)."""
    bus: Stations
    addresses: list[int]
    refs: list[tuple[str, float]]        # one per station
    reverse: bool = False
    fmax: float | None = None
    duration: float | None = None
    watchdog_ms: float = DEFAULT_WATCHDOG_MS
    cycle_hz: float | None = None
    sync: bool = False
    confirm: Callable[[list["DriveStation"]], None] | None = None
    should_quit: Callable[[], bool] | None = None
    on_start: Callable[[dict[str, Any]], None] | None = None
    on_phase: Callable[[str, int | None], None] | None = None
    on_sample: Callable[[int, float, "Sample", str], None] | None = None
    on_end: Callable[[dict[str, Any]], None] | None = None
    on_message: Callable[[str], None] | None = None
    runs: list[StationRun] = field(default_factory=list)
    reason: str = ""
    failed: bool = False

    def __post_init__(self) -> None:
        if len(self.refs) != len(self.addresses):
            raise UsageError("one speed for all stations or one per station")
        self.group: Group | None = None
        self.freeze = False
        self.t0 = 0.0
        self.cycle_rate = 0.0
        self.wire_hz = 0.0
        self.warnings: list[str] = []
        self.guard = SignalGuard(True)
        self.link_lost = False

    @property
    def master(self) -> "Master":
        return self.bus.master

    # -- helpers -------------------------------------------------------------------------------
    def _say(self, text: str) -> None:
        if self.on_message:
            self.on_message(text)

    def _phase(self, phase: str, address: int | None = None) -> None:
        if self.on_phase:
            self.on_phase(phase, address)

    def now(self) -> float:
        return self.master.link.now() - self.t0

    def _sample(self, r: StationRun, sample: "Sample", phase: str) -> None:
        r.last = sample
        if self.on_sample:
            self.on_sample(r.address, self.now(), sample, phase)

    # -- the run -------------------------------------------------------------------------------
    def run(self) -> int:
        """Run to the end; 0 when every drive reached its speed and stopped, else 1. Raises what ended
        it early (SessionTerminated, KeyboardInterrupt, BusError, DriveError, UsageError) after the
        stop of every drive."""
        self.guard.install()
        exc: BaseException | None = None
        try:
            self._open()
            self._start_all()
            self._cycle()
        except SessionTerminated as e:
            self.reason, exc = "SIGTERM", e
            raise
        except KeyboardInterrupt as e:
            self.reason, exc = "Ctrl-C", e
            raise
        except LinkLost as e:
            self.reason, exc, self.link_lost = f"error: {e}", e, True
            raise
        except BaseException as e:
            self.reason, exc = self.reason or f"error: {e}", e
            raise
        finally:
            self.guard.guard()             # from here a signal hurries the stop (coast)
            try:
                self._stop_all(exc)
            finally:
                self._close_all(exc)
                self.guard.restore()
                if self.on_end:
                    self.on_end(self.end_dict())
        return 1 if self.failed else 0

    def _open(self) -> None:
        for a, ref in zip(self.addresses, self.refs):
            s = self.bus.station(a, watchdog_ms=self.watchdog_ms, handle_signals=False,
                                 on_message=self.on_message, cycle_hz=self.cycle_hz)
            self.runs.append(StationRun(s, a, ref))
            s.identify()                    # Slave_Diag only: nothing written yet
        sessions = [r.session for r in self.runs]
        for s in sessions:
            self.warnings.extend(s.warnings)
        if self.sync:
            _, self.freeze = sync_modes(sessions)
        # one round = one Data_Exchange per station: the wire limit of the round is the sum
        self.cycle_rate, self.wire_hz = Group.rate(self.master, [s.wire_hz for s in sessions])
        if self.cycle_hz is not None:
            self.cycle_rate = float(self.cycle_hz)
            if self.cycle_rate > self.wire_hz * 1.0001:
                self.warnings.append(f"--cycle-hz {self.cycle_rate:g} is more than the bus allows for "
                                     f"{len(sessions)} stations ({self.wire_hz:.1f} rounds/s); on a "
                                     f"real bus the wire sets the pace")
        round_s = 1.0 / min(self.cycle_rate or self.wire_hz, self.wire_hz)
        need, raised = Group.watchdog_for(self.watchdog_ms, round_s, len(sessions))
        if raised is not None:
            # the Set_Prm of every station carries the raised one
            self.warnings.append(raised)
            self.watchdog_ms = need
            for s in sessions:
                s.settle(watchdog_ms=need)
        if self.confirm:
            self.confirm(sessions)
        self.group = Group(self.master, 1.0 / self.cycle_rate if self.cycle_rate else 0.0,
                           sync=self.sync, freeze=self.sync and self.freeze)
        for r in self.runs:
            s = r.session
            s.settle(cycle_hz=self.cycle_rate, sync=self.sync, freeze=self.sync and self.freeze)
            s.open()                        # Set_Prm (+ Sync_Req / Freeze_Req), Chk_Cfg, the Drive
            self.group.join(s)
        self.t0 = self.master.link.now()
        stations = []
        for r in self.runs:
            s = r.session
            top, src = s.motion.fmax(self.fmax)
            kind, value = r.ref
            pct = value if kind == "percent" else s.motion.percent_for_hz(value, self.fmax)
            if not -100.0 <= pct <= 100.0:
                raise UsageError(f"station {r.address}: {pct:g} % is outside -100..100")
            r.percent = -abs(pct) if self.reverse else pct
            assert s.profile is not None    # open() chose it
            stations.append({"station": r.address, "ident": s.ident, "ident_hex": f"0x{s.ident:04X}",
                             "profile": s.profile.name, "family": s.profile.family,
                             "title": s.profile.title, "layout": s.layout, "fmax_hz": top,
                             "fmax_source": src, "reference_percent": round(r.percent, 4),
                             "reference_hz": round(r.percent * top / 100.0, 3)})
        if self.on_start:
            self.on_start({"stations": stations, "cycle_hz_target": round(self.cycle_rate, 3),
                           "wire_hz": round(self.wire_hz, 3), "watchdog_ms": self.watchdog_ms,
                           "duration_s": self.duration, "sync": self.sync,
                           "freeze": self.sync and self.freeze, "warnings": self.warnings})

    def _start_all(self) -> None:
        """Each drive started at 0 (its own handshake, one after the other: nothing turns yet), then the
        references of all in one round: with --sync they take effect in the same instant."""
        group = self.group
        assert group is not None            # _open() made it
        for r in self.runs:
            self._phase("starting", r.address)
            try:
                sample = r.session.motion.start(0.0)
            except StationOut:
                raise
            except DriveError as e:
                r.problem = f"did not start: {e}"
                self.failed = True
                raise DriveError(f"station {r.address}: {e}") from None
            r.started = True
            self._sample(r, sample, "starting")
        group.end_round()
        t = self.now()
        for r in self.runs:
            r.session.motion.set_reference(r.percent)
            r.t_start = t
            r.reach = Reach.of_run(r.percent, r.last)
            r.reach.t0 = t
        for r in self.runs:                 # a codec that sets its words without an exchange
            if not group.exchanged(r.address):
                self._sample(r, r.session.motion.poll(), "running")
        group.end_round()              # (Sync: every new reference takes effect now)
        self._phase("running")

    def _cycle(self) -> None:
        group = self.group
        assert group is not None            # _open() made it
        t_start = self.now()
        while True:
            for r in self.runs:
                try:
                    sample = r.session.motion.poll()
                except StationOut as e:
                    r.problem = f"dropped out of data exchange ({e.why})"
                    self._end(f"station {r.address} dropped out of data exchange ({e.why})")
                    return
                self._sample(r, sample, "running")
                st = sample.status
                reach = r.reach
                if reach is not None and not st.fault:
                    reach.feed(self.now(), sample.actual_percent)
                    r.reached_after = reach.reached_after
                if st.fault:
                    r.tripped = True
                    r.problem = trip_words(r.session.profile, st.fault_code)
                    self._end(f"station {r.address} {r.problem}")
                    return
                if reach is not None and reach.overshoot:
                    # beyond its reference on the far side: the run ends for all, as on a trip
                    r.problem = reach.overshoot_words()
                    self._end(f"station {r.address}: {r.problem}")
                    return
            group.end_round()
            if group.dropped:
                a, why = next(iter(group.dropped.items()))
                for r in self.runs:
                    if r.address == a:
                        r.problem = f"dropped out of data exchange ({why})"
                self._end(f"station {a} dropped out of data exchange ({why})")
                return
            if self.duration is not None and self.now() - t_start >= self.duration:
                self.reason = f"duration {self.duration:g} s reached"
                break
            if self.should_quit is not None and self.should_quit():
                self.reason = "q pressed"
                return                      # the user ended it: no drive is judged on its speed
        for r in self.runs:
            if r.reached_after is None:
                r.problem = NOT_REACHED
                self.failed = True

    def _end(self, reason: str) -> None:
        self.reason = reason
        self.failed = True

    # -- the stop of every drive ---------------------------------------------------------------
    def _stop_all(self, exc: BaseException | None) -> None:
        if self.group is None or self.link_lost:
            return                          # nothing connected, or nothing can be sent: _close_all
        runs = [r for r in self.runs if r.session.drive is not None and r.session.motion.may_run]
        if not runs:
            return
        self._phase("stopping")
        try:
            self._stop_together(runs)
        except LinkLost:
            self.link_lost = True          # each session's close says what the watchdog will do
        except BusError as e:
            self._say(f"stop: {e}; each drive not yet stopped gets its own stop")
        if all(r.session.motion.stop_report is not None and r.session.motion.stop_report.stopped for r in runs):
            self._phase("stopped")

    def _stop_together(self, runs: list[StationRun]) -> None:
        def on_sample(address: int, sample: "Sample") -> None:
            r = next(x for x in runs if x.address == address)
            self._sample(r, sample, "stopping")

        def hurry() -> bool:
            h, self.guard.hurry = self.guard.hurry, False
            return h
        assert self.group is not None       # _stop_all() checked it
        self.group.stop_all([(r.address, r.session, r.percent) for r in runs], hurry, on_sample)
        for r in runs:
            rep = r.session.motion.stop_report
            st = end_status(r.session)
            code = st.fault_code if st is not None else None
            if r.tripped and code and f"({code})" not in r.problem:
                # the cycle's words had no code: the stop read it
                r.problem = trip_words(r.session.profile, code)
                self.reason = f"station {r.address} {r.problem}"
            if rep is None or not rep.stopped:
                self.failed = True
                r.problem = r.problem or "not confirmed stopped"
            elif rep.how == "coast":
                self._say(f"station {r.address}: stopped by a coast stop after {rep.seconds:.1f} s "
                          f"({rep.message})")

    def _close_all(self, exc: BaseException | None) -> None:
        if self.group is not None and not self.link_lost:
            try:
                self.group.finish()          # Unsync / Unfreeze before the release
            except (BusError, LinkLost):
                pass
        first: BaseException | None = None
        for r in reversed(self.runs):
            try:
                # a drive still marked as possibly running gets the session's own safe stop here
                r.session.close(exc)
            except BaseException as e:      # noqa: BLE001  (the others still need their close)
                first = first or e
            rep = r.session.motion.stop_report
            if r.started and (rep is None or not rep.stopped):
                self.failed = True
        try:
            self.bus.close(exc)              # the port: closed here, once
        except Exception:                   # noqa: BLE001
            pass
        if first is not None and exc is None:
            raise first

    def end_dict(self) -> dict[str, Any]:
        return {"reason": self.reason, "failed": self.failed,
                "stopped": all((r.session.motion.stop_report.stopped if r.session.motion.stop_report is not None
                                else not r.started) for r in self.runs),
                "stations": [r.to_dict() for r in self.runs],
                "rounds": self.group.rounds if self.group is not None else 0,
                "global_controls": self.group.global_controls if self.group is not None else 0,
                "warnings": self.warnings + [w for r in self.runs for w in r.session.warnings
                                             if w not in self.warnings]}

