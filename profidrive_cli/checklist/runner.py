"""Run a validated checklist on drives, one station after another, and collect what was measured.

The runner does not open ports or sessions itself: `open_station(spec)` is a context manager that yields a
StationHandle (the station's session, its Drive and the identity the bus reported). In pdrive the session
comes from the API's front door, api.Bus.session (see session_opener), and on exit always stops the drive
safely and releases the station; tests may hand in a DirectChannel-backed opener (a session on its Drive). All waiting uses the drive's own clock (channel.now()), so a run on a
simulated clock takes no real time.

Safety: a failed step with on_fail: stop, an exception, Ctrl-C or SIGTERM end the station's steps, the
runner stops the drive (normal stop, bounded, then coast) and the session's exit stops it again if needed.
The drive's status after that is part of the report ("left stopped").

Each step is run by its step type (checklist/steps/, looked up by name in steps.STEPS): the runner gives it
itself (dry_run, yes, ask, progress, cycle_for), the results and the drive; timing, on_fail, the observer,
errors and the safe stop are done here once for every type.
"""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from datetime import datetime, timezone
from types import FrameType
from typing import TYPE_CHECKING, Any, Callable, Iterator, NoReturn

from profidrive_cli import PdriveError, __version__
from profidrive_cli.checklist import steptrace
from profidrive_cli.checklist.fields import StationFacts
from profidrive_cli.checklist.spec import Checklist, StationSpec, Step
from profidrive_cli.checklist.steps import STEPS
from profidrive_cli.checklist.steps.base import StepFailed, hex4, status_dict
from profidrive_cli.checklist.steptrace import StepTrace

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.api.bus import Bus
    from profidrive_cli.checklist.fields import ParamTarget
    from profidrive_cli.drives.base import Drive, DriveStatus
    from profidrive_cli.api.station import DriveStation

PASSED, FAILED, ERROR, SKIPPED, NOT_RUN = "passed", "failed", "error", "skipped", "not run"


class Terminated(KeyboardInterrupt):
    """SIGTERM between stations (while no DriveStation is open), turned into an interrupt."""


def _interrupts() -> tuple[type[BaseException], ...]:
    from profidrive_cli.api.station import SessionTerminated
    return (KeyboardInterrupt, SessionTerminated)


def _interrupt_name(e: BaseException) -> str:
    if isinstance(e, Terminated):
        return "SIGTERM"
    signum = getattr(e, "signum", None)
    if signum is not None:
        try:
            return signal.Signals(signum).name
        except ValueError:
            return f"signal {signum}"
    return "SIGINT"


@contextlib.contextmanager
def signals_as_interrupts() -> Iterator[None]:
    """SIGTERM raises Terminated in the main thread while the block runs (SIGINT already raises
    KeyboardInterrupt). Outside the main thread this does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def on_term(signum: int, frame: FrameType | None) -> NoReturn:
        raise Terminated()
    old = signal.signal(signal.SIGTERM, on_term)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


def now_iso() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


# =============================================================================================
# results
# =============================================================================================


@dataclass
class StepResult:
    step: Step
    status: str = NOT_RUN
    message: str = ""
    measured: dict[str, Any] = field(default_factory=dict)
    expected: dict[str, Any] = field(default_factory=dict)
    started: str | None = None
    finished: str | None = None
    duration_s: float = 0.0
    #: the drive cycle by cycle during a step that moves it (steptrace.StepTrace; not in the JSON)
    trace: StepTrace | None = None

    @property
    def ok(self) -> bool:
        return self.status in (PASSED, SKIPPED)

    def to_dict(self) -> dict[str, Any]:
        d = self.step.to_dict()
        d.update({"status": self.status, "message": self.message, "expected": self.expected,
                  "measured": self.measured, "started": self.started, "finished": self.finished,
                  "duration_s": round(self.duration_s, 3)})
        return d


@dataclass
class StationResult:
    spec: StationSpec
    steps: list[StepResult]
    status: str = NOT_RUN
    identity: dict[str, Any] = field(default_factory=dict)        # what the bus reported
    error: str | None = None                            # the session could not open, or an interrupt
    #: parameter label -> {"value", "unit", "raw", "name"} or {"error"}
    snapshot_before: dict[str, dict[str, Any]] = field(default_factory=dict)
    snapshot_after: dict[str, dict[str, Any]] = field(default_factory=dict)
    snapshot_note: str = ""
    final_status: dict[str, Any] = field(default_factory=dict)    # the drive's status at the end (left stopped?)
    started: str | None = None
    finished: str | None = None
    duration_s: float = 0.0

    def counts(self) -> dict[str, int]:
        c = {PASSED: 0, FAILED: 0, ERROR: 0, SKIPPED: 0, NOT_RUN: 0}
        for r in self.steps:
            c[r.status] += 1
        return c

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.spec.name, "address": self.spec.address, "status": self.status,
                "error": self.error, "expected_identity": self.spec.identity(), "identity": self.identity,
                "started": self.started, "finished": self.finished, "duration_s": round(self.duration_s, 3),
                "counts": self.counts(), "snapshot_before": self.snapshot_before,
                "snapshot_after": self.snapshot_after, "snapshot_note": self.snapshot_note,
                "final_status": self.final_status, "steps": [r.to_dict() for r in self.steps]}


@dataclass
class RunResult:
    checklist: Checklist
    port: str
    dry_run: bool
    stations: list[StationResult]
    started: str = ""
    finished: str = ""
    duration_s: float = 0.0
    interrupted: str | None = None      # "SIGINT" / "SIGTERM"
    options: dict[str, Any] = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        return not self.interrupted and all(s.status == PASSED for s in self.stations)

    @property
    def status(self) -> str:
        if self.interrupted:
            return "interrupted"
        return PASSED if self.passed else FAILED

    def counts(self) -> dict[str, int]:
        c = {PASSED: 0, FAILED: 0, ERROR: 0, SKIPPED: 0, NOT_RUN: 0}
        for s in self.stations:
            for k, v in s.counts().items():
                c[k] += v
        return c

    def first_failure(self) -> tuple[StationResult, StepResult | None] | None:
        for s in self.stations:
            for r in s.steps:
                if r.status in (FAILED, ERROR):
                    return s, r
            if s.status in (FAILED, ERROR):
                return s, None
        return None

    def to_dict(self) -> dict[str, Any]:
        cl = self.checklist
        return {"pdrive": __version__, "checklist": {"name": cl.name, "description": cl.description,
                                                      "file": str(cl.path), "sha256": cl.sha256},
                "status": self.status, "passed": self.passed, "interrupted": self.interrupted,
                "dry_run": self.dry_run, "port": self.port, "options": self.options,
                "variables": cl.variables, "started": self.started, "finished": self.finished,
                "duration_s": round(self.duration_s, 3), "counts": self.counts(),
                "stations": [s.to_dict() for s in self.stations]}


# =============================================================================================
# the station handle
# =============================================================================================


@dataclass
class StationHandle:
    """What open_station yields: the Drive, the identity the bus reported for the station, and the
    station behind them (api.Bus.station: a DriveStation), whose .params (the one write path, save),
    .motion (the safe stop), counters and master the steps use. closed(): after the station is left, what the safe
    stop on the way out did (dict for the report)."""
    drive: Drive
    identity: dict[str, Any]  # address, ident (int), profile (name), gsd (file name or None), layout, ...
    session: DriveStation
    closed: Callable[[], dict[str, Any]] | None = None


#: Runner's open_station: a station's spec -> a context manager yielding its StationHandle
OpenStation = Callable[[StationFacts], AbstractContextManager[StationHandle]]


class Observer:
    """Live progress hooks (the CLI renders them); every method is optional."""

    def run_started(self, run: RunResult) -> None: ...
    def station_started(self, station: StationResult) -> None: ...
    def station_opened(self, station: StationResult) -> None: ...
    def step_started(self, station: StationResult, result: StepResult) -> None: ...
    def step_progress(self, station: StationResult, result: StepResult, text: str) -> None: ...
    def step_finished(self, station: StationResult, result: StepResult) -> None: ...
    def station_finished(self, station: StationResult) -> None: ...
    def run_finished(self, run: RunResult) -> None: ...


# =============================================================================================
# the runner
# =============================================================================================


class Runner:
    """Runs every station of a checklist in turn through `open_station`.

    yes: prompts count as confirmed. ask(text) -> bool asks the operator (None: nobody to ask, a prompt
    fails unless yes). dry_run: identities are checked against what the simulator presents and prompts
    are confirmed (the report says so).
    """

    def __init__(self, checklist: Checklist, open_station: OpenStation, *, port: str = "", yes: bool = False,
                 ask: Callable[[str], bool] | None = None, dry_run: bool = False,
                 observer: Observer | None = None, progress_interval: float = 0.25,
                 options: dict[str, Any] | None = None, trace_steps: bool = False) -> None:
        self.cl = checklist
        #: record the drive cycle by cycle during the steps that move it (an HTML report plots them)
        self.trace_steps = trace_steps
        self.open_station = open_station
        self.yes = yes
        self.ask = ask
        self.dry_run = dry_run
        self.obs = observer or Observer()
        self.progress_interval = progress_interval
        self.result = RunResult(checklist, port, dry_run,
                                [StationResult(s, [StepResult(step) for step in s.steps]) for s in checklist.stations],
                                options=options or {})
        self._abort = False

    # -- run -----------------------------------------------------------------------------------
    def run(self) -> RunResult:
        res = self.result
        res.started = now_iso()
        t0 = time.monotonic()
        self.obs.run_started(res)
        try:
            for sr in res.stations:
                if self._abort:
                    sr.status = NOT_RUN
                    sr.error = sr.error or "not run: an earlier station stopped the checklist"
                    continue
                self._station(sr)
        finally:
            res.finished = now_iso()
            res.duration_s = time.monotonic() - t0
            self.obs.run_finished(res)
        return res

    def _station(self, sr: StationResult) -> None:
        sr.started = now_iso()
        t0 = time.monotonic()
        self.obs.station_started(sr)
        interrupts = _interrupts()
        interrupted: BaseException | None = None
        handle: StationHandle | None = None
        try:
            with self.open_station(sr.spec) as handle:
                sr.identity = _identity_dict(handle.identity)
                self.obs.station_opened(sr)
                self._snapshot(sr, handle.drive, "before")
                self._steps(sr, handle)
                # failed or passed: leave the drive stopped (a failed step stops it here, at once)
                self._leave_stopped(sr, handle)
                self._snapshot(sr, handle.drive, "after")
            # an interrupt skips the block's tail: the session's exit does the safe stop
        except interrupts as e:
            interrupted = e
        except PdriveError as e:
            sr.error = str(e)
            for r in sr.steps:
                if r.status == NOT_RUN and not r.message:
                    r.message = "not run: the station could not be opened" if handle is None else \
                        f"not run: {e}"
            if self._stops_on_error(sr):
                self._abort = True
        finally:
            if handle is not None and handle.closed is not None:
                try:
                    sr.final_status = {**sr.final_status, **handle.closed()}
                except Exception:     # noqa: BLE001 - the report must still be written
                    pass
            sr.finished = now_iso()
            sr.duration_s = time.monotonic() - t0
        if interrupted is not None:
            which = _interrupt_name(interrupted)
            self.result.interrupted = which
            stopped = sr.final_status.get("stopped")
            sr.error = f"interrupted by {which}" + (
                "; the drive was stopped" if stopped else
                "; the stop could not be confirmed" if stopped is False else "")
            sr.snapshot_note = "snapshot after: not taken (interrupted)"
            for r in sr.steps:
                if r.status == NOT_RUN:
                    r.message = r.message or f"not run: interrupted by {which}"
            self._abort = True
        c = sr.counts()
        if interrupted is not None:
            sr.status = "interrupted"
        elif sr.error is not None:
            sr.status = ERROR
        elif c[FAILED] or c[ERROR]:
            sr.status = FAILED
        else:
            sr.status = PASSED
        self.obs.station_finished(sr)

    def _stops_on_error(self, sr: StationResult) -> bool:
        return self.cl.on_fail == "stop"

    def _steps(self, sr: StationResult, handle: StationHandle) -> None:
        stop_here = False
        for r in sr.steps:
            if stop_here:
                r.status = NOT_RUN
                r.message = "not run: an earlier step failed (on_fail: stop)"
                continue
            self._one(sr, r, handle)
            if r.status in (FAILED, ERROR) and r.step.on_fail == "stop":
                stop_here = True
                self._abort = True

    def _one(self, sr: StationResult, r: StepResult, handle: StationHandle) -> None:
        r.started = now_iso()
        t0 = time.monotonic()
        self._progress_at = 0.0
        self.obs.step_started(sr, r)
        try:
            with self._traced(r, handle.drive):
                msg = STEPS[r.step.type].execute(self, sr, r, handle.drive, handle)
            r.status = PASSED
            r.message = msg or ""
        except StepFailed as e:
            r.status = FAILED
            r.message = str(e)
        except _interrupts() as e:
            r.status = ERROR
            r.message = f"interrupted by {_interrupt_name(e)}"
            raise
        except PdriveError as e:
            r.status = ERROR
            r.message = str(e)
        except Exception as e:        # noqa: BLE001 - a codec bug must not leave the motor running
            r.status = ERROR
            r.message = f"internal error: {type(e).__name__}: {e}"
        finally:
            r.finished = now_iso()
            r.duration_s = time.monotonic() - t0
            self.obs.step_finished(sr, r)

    # -- what step types use ------------------------------------------------------------------
    def progress(self, sr: StationResult, r: StepResult, text: str, force: bool = False) -> None:
        """Tell the observer how a step is getting on (at most every progress_interval s unless force)."""
        t = time.monotonic()
        if force or t - self._progress_at >= self.progress_interval:
            self._progress_at = t
            self.obs.step_progress(sr, r, text)

    def _snapshot(self, sr: StationResult, drive: Drive, which: str) -> None:
        target = sr.snapshot_before if which == "before" else sr.snapshot_after
        codes = _snapshot_targets(sr.spec)
        if not codes:
            return
        if not drive.has_param_channel:
            sr.snapshot_note = f"no parameter snapshot: layout {sr.spec.layout} has no parameter channel"
            return
        for t in codes:
            try:
                pv = drive.read_param(t.code)
                target[t.label] = {"value": pv.value, "unit": pv.unit, "raw": pv.raw, "name": pv.name}
            except PdriveError as e:
                target[t.label] = {"error": str(e)}

    def _leave_stopped(self, sr: StationResult, handle: StationHandle) -> None:
        """Stop the drive if it is not stopped (the session's safe stop: normal, bounded, then coast)
        and record its status."""
        d = handle.drive
        try:
            st = d.status()
            how = "already stopped"
            if st.running or not st.stopped:
                rep = handle.session.motion.stop()
                how = f"{rep.how} stop: {rep.message}"
                st = rep.status or d.status()
            sr.final_status = {**status_dict(st), "stop": how}
        except _interrupts():
            raise
        except Exception as e:        # noqa: BLE001 - the session's exit still stops it
            sr.final_status = {"error": f"could not confirm the drive stopped: {e}"}

    @contextlib.contextmanager
    def _traced(self, r: StepResult, drive: Drive) -> Iterator[None]:
        """Record the drive's cycles during a step that moves it (for the HTML report's plots)."""
        if not self.trace_steps or r.step.type not in steptrace.PLOTTED:
            yield
            return
        with steptrace.record(drive) as tr:
            r.trace = tr
            yield

    def cycle_for(self, sr: StationResult, r: StepResult, drive: Drive, seconds: float,
                  text: str = "") -> DriveStatus:
        """Keep exchanging cyclic data for `seconds` on the drive's clock; returns the last status."""
        ch = drive.channel
        end = ch.now() + seconds
        st = drive.cycle()
        while ch.now() < end:
            st = drive.cycle()
            if text:
                self.progress(sr, r, f"{text} ({max(0.0, end - ch.now()):.1f} s left)")
        return st



# =============================================================================================
# small helpers
# =============================================================================================


def _identity_dict(identity: dict[str, Any] | None) -> dict[str, Any]:
    out = {}
    for k, v in dict(identity or {}).items():
        out[k] = hex4(v) if k == "ident" else v
    return out


def _snapshot_targets(spec: StationSpec) -> list[ParamTarget]:
    """The header/station snapshot list plus every parameter the station's steps read or write."""
    out = list(spec.snapshot)
    for s in spec.steps:
        t = s.args.get("param") if s.type in ("read", "write") else None
        if t is not None and all(t.label != o.label for o in out):
            out.append(t)
    return out


# =============================================================================================
# opening stations through session.DriveStation
# =============================================================================================


def dry_run_port(checklist: Checklist) -> str:
    """sim:// with one simulated station of each checklist station's profile at its address."""
    return "sim://?stations=" + ",".join(f"{s.address}:{s.profile.name}" for s in checklist.stations)


def session_opener(bus: Bus, *, cycle_hz: float | None = None, watchdog_ms: float | None = None,
                   on_message: Callable[[str], None] | None = None,
                   checklist: Checklist | None = None) -> OpenStation:
    """open_station for Runner: one session per station on one bus, the front door the CLI's drive
    commands use (api.Bus.session; the caller closes the bus after the run). The session identifies
    the station, refuses a station of another family, parameterises it with the watchdog armed, and
    on exit stops the drive safely and releases it.
    checklist: a station of its `together` steps gets the watchdog of their group (three rounds)."""
    from profidrive_cli.checklist.steps.together import group_watchdog
    from profidrive_cli.api.station import DEFAULT_WATCHDOG_MS

    @contextlib.contextmanager
    def open_station(spec: StationFacts) -> Iterator[StationHandle]:
        wd, raised = watchdog_ms or DEFAULT_WATCHDOG_MS, None
        if checklist is not None:
            wd, raised = group_watchdog(checklist, spec, bus.master, wd)
        s = bus.station(spec.address, profile=spec.profile.name, layout=spec.layout,
                        cycle_hz=cycle_hz, watchdog_ms=wd, on_message=on_message)
        if raised is not None:
            s.warn(f"{spec.name}: {raised}")

        def closed() -> dict[str, Any]:
            rep = s.motion.stop_report
            if rep is None:
                return {}
            out: dict[str, Any] = {"exit_stop": rep.how, "exit_stop_message": rep.message}
            if rep.how not in ("not needed",):
                out["stopped"] = rep.stopped
                if rep.status is not None:
                    out["state"] = rep.status.state
            return out

        with s:
            drive = s.need_drive()                  # connected: the session's Drive
            yield StationHandle(drive, session_identity(s), s, closed=closed)

    return open_station


def session_identity(s: DriveStation) -> dict[str, Any]:
    """The identity a DriveStation found: address, ident, profile, layout, GSD file of the ident, DP state."""
    gsd = None
    try:
        from profidrive_cli.gsd.library import find_path_by_ident
        p = find_path_by_ident(s.ident) if s.ident is not None else None
        gsd = p.name if p is not None else None
    except PdriveError:
        gsd = None
    out: dict[str, Any] = {"address": s.address, "ident": s.ident,
                           "profile": s.profile.name if s.profile else None,
                           "layout": s.layout, "gsd": gsd}
    st = s.station
    if st is not None and st.state:
        out["dp_state"] = st.state
    if s.warnings:
        out["warnings"] = list(s.warnings)
    return out
