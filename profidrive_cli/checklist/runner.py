"""Run a validated checklist on drives, one station after another, and collect what was measured.

The runner does not open ports or sessions itself: `open_station(spec)` is a context manager that yields a
StationHandle (a Drive plus the identity the bus reported). In pdrive that is drives.session.DriveSession
(see session_opener), which on exit always stops the drive safely and releases the station; tests may hand
in a DirectChannel-backed opener. All waiting uses the drive's own clock (channel.now()), so a run on a
simulated clock takes no real time.

Safety: a failed step with on_fail: stop, an exception, Ctrl-C or SIGTERM end the station's steps, the
runner stops the drive (normal stop, bounded, then coast) and the session's exit stops it again if needed.
The drive's status after that is part of the report ("left stopped").
"""

from __future__ import annotations

import contextlib
import math
import signal
import threading
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import Any, Callable

from profidrive_cli.drives.values import danger
from profidrive_cli import PdriveError, __version__
from profidrive_cli.checklist.spec import Checklist, StationSpec, Step, _fmt

PASSED, FAILED, ERROR, SKIPPED, NOT_RUN = "passed", "failed", "error", "skipped", "not run"


class Terminated(KeyboardInterrupt):
    """SIGTERM between stations (while no DriveSession is open), turned into an interrupt."""


def _interrupts() -> tuple:
    from profidrive_cli.session import SessionTerminated
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
def signals_as_interrupts():
    """SIGTERM raises Terminated in the main thread while the block runs (SIGINT already raises
    KeyboardInterrupt). Outside the main thread this does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def on_term(signum, frame):
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
    measured: dict = field(default_factory=dict)
    expected: dict = field(default_factory=dict)
    started: str | None = None
    finished: str | None = None
    duration_s: float = 0.0

    @property
    def ok(self) -> bool:
        return self.status in (PASSED, SKIPPED)

    def to_dict(self) -> dict:
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
    identity: dict = field(default_factory=dict)        # what the bus reported
    error: str | None = None                            # the session could not open, or an interrupt
    snapshot_before: dict = field(default_factory=dict)
    snapshot_after: dict = field(default_factory=dict)
    snapshot_note: str = ""
    final_status: dict = field(default_factory=dict)    # the drive's status at the end (left stopped?)
    started: str | None = None
    finished: str | None = None
    duration_s: float = 0.0

    def counts(self) -> dict:
        c = {PASSED: 0, FAILED: 0, ERROR: 0, SKIPPED: 0, NOT_RUN: 0}
        for r in self.steps:
            c[r.status] += 1
        return c

    def to_dict(self) -> dict:
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
    options: dict = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        return not self.interrupted and all(s.status == PASSED for s in self.stations)

    @property
    def status(self) -> str:
        if self.interrupted:
            return "interrupted"
        return PASSED if self.passed else FAILED

    def counts(self) -> dict:
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

    def to_dict(self) -> dict:
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
    """What open_station yields: the Drive, and the identity the bus reported for the station.

    session: the drives.session.DriveSession behind it (None in tests on a bare Drive); when present its
    checked write_param, save and safe stop are used. closed(): after the station is left, what the
    safe stop on the way out did (dict for the report)."""
    drive: Any
    identity: dict            # address, ident (int), profile (name), gsd (file name or None), layout, ...
    session: Any = None
    closed: Callable[[], dict] | None = None


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


class StepFailed(Exception):
    """An expectation was not met: the step fails with this message (measured values already recorded)."""


# =============================================================================================
# the runner
# =============================================================================================


class Runner:
    """Runs every station of a checklist in turn through `open_station`.

    yes: prompts count as confirmed. ask(text) -> bool asks the operator (None: nobody to ask, a prompt
    fails unless yes). dry_run: identities are checked against what the simulator presents and prompts
    are confirmed (the report says so).
    """

    def __init__(self, checklist: Checklist, open_station, *, port: str = "", yes: bool = False,
                 ask: Callable[[str], bool] | None = None, dry_run: bool = False,
                 observer: Observer | None = None, progress_interval: float = 0.25, options: dict | None = None):
        self.cl = checklist
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
            fn = getattr(self, f"do_{r.step.type}")
            msg = fn(sr, r, handle.drive, handle)
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

    # -- helpers -------------------------------------------------------------------------------
    def _progress(self, sr, r, text: str, force: bool = False) -> None:
        t = time.monotonic()
        if force or t - self._progress_at >= self.progress_interval:
            self._progress_at = t
            self.obs.step_progress(sr, r, text)

    def _snapshot(self, sr: StationResult, drive, which: str) -> None:
        target = sr.snapshot_before if which == "before" else sr.snapshot_after
        codes = _snapshot_targets(sr.spec)
        if not codes:
            return
        if not getattr(drive, "has_param_channel", True):
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
                if handle.session is not None:
                    rep = handle.session.stop()
                    how = f"{rep.how} stop: {rep.message}"
                    st = rep.status or d.status()
                else:
                    try:
                        st = d.stop("normal", wait=True, timeout=DEFAULT_SAFE_STOP_S)
                        how = "normal stop"
                    except PdriveError:
                        st = d.stop("coast", wait=True, timeout=DEFAULT_SAFE_STOP_S)
                        how = "coast stop"
            sr.final_status = {**_status_dict(st), "stop": how}
        except _interrupts():
            raise
        except Exception as e:        # noqa: BLE001 - the session's exit still stops it
            sr.final_status = {"error": f"could not confirm the drive stopped: {e}"}

    def _cycle_for(self, sr, r, drive, seconds: float, text: str = "") -> Any:
        """Keep exchanging cyclic data for `seconds` on the drive's clock; returns the last status."""
        ch = drive.channel
        end = ch.now() + seconds
        st = drive.cycle()
        while ch.now() < end:
            st = drive.cycle()
            if text:
                self._progress(sr, r, f"{text} ({max(0.0, end - ch.now()):.1f} s left)")
        return st

    # =========================================================================================
    # one method per step type: return a message on success, raise StepFailed / PdriveError
    # =========================================================================================

    def do_note(self, sr, r, d, h):
        r.measured = {"text": r.step.args["text"]}
        return r.step.args["text"]

    def do_prompt(self, sr, r, d, h):
        text = r.step.args["text"]
        r.expected = {"answer": "yes"}
        if self.dry_run:
            r.measured = {"answer": "yes", "by": "dry run"}
            return "dry run: taken as confirmed"
        if self.yes:
            r.measured = {"answer": "yes", "by": "--yes"}
            return "confirmed by --yes"
        if self.ask is None:
            r.measured = {"answer": None, "by": "nobody"}
            raise StepFailed("no operator to confirm (not a terminal): run with --yes to confirm prompts")
        # ask in a thread and keep the drive's cyclic data (and the watchdog) going meanwhile
        box: dict = {}

        def asker():
            try:
                box["answer"] = bool(self.ask(text))
            except BaseException as e:    # noqa: BLE001 - EOF / interrupt at the prompt
                box["error"] = e
        t = threading.Thread(target=asker, name="checklist-prompt", daemon=True)
        t.start()
        while t.is_alive():
            d.cycle()
            t.join(0.02)
        if "error" in box:
            e = box["error"]
            if isinstance(e, KeyboardInterrupt):
                raise e
            if isinstance(e, EOFError):
                raise StepFailed("no answer (end of input)")
            raise StepFailed(f"prompt failed: {e}")
        r.measured = {"answer": "yes" if box["answer"] else "no", "by": "operator"}
        if not box["answer"]:
            raise StepFailed("the operator answered no")
        return "confirmed by the operator"

    def do_wait(self, sr, r, d, h):
        s = float(r.step.args["seconds"])
        st = self._cycle_for(sr, r, d, s, "waiting")
        r.measured = {"seconds": s, "status": _status_dict(st)}
        return ""

    def do_expect_identity(self, sr, r, d, h):
        a = r.step.args
        idt = h.identity or {}
        got_ident = idt.get("ident")
        expect_ident = a["ident"]
        note = ""
        if self.dry_run and expect_ident != sr.spec.profile.ident and got_ident == sr.spec.profile.ident:
            note = (f"dry run: the simulator answers with the profile's ident 0x{got_ident:04X}; "
                    f"0x{expect_ident:04X} is checked on the plant")
            expect_ident = got_ident
        r.expected = {"ident": _hex(a["ident"]), "profile": a["profile"], "gsd": a["gsd"]}
        r.measured = {"ident": _hex(got_ident), "profile": idt.get("profile"), "gsd": idt.get("gsd"),
                      "address": idt.get("address"), "layout": idt.get("layout")}
        for k in ("dp_state", "warnings", "device", "name", "vendor", "card"):
            if idt.get(k):
                r.measured[k] = idt[k]
        problems = []
        if got_ident != expect_ident:
            problems.append(f"ident {_hex(got_ident)}, expected {_hex(expect_ident)}")
        if idt.get("profile") is not None and idt.get("profile") != a["profile"]:
            problems.append(f"profile {idt.get('profile')}, expected {a['profile']}")
        if a["gsd"] and not self.dry_run:
            g = idt.get("gsd")
            if g is None or _gsd_name(g) != _gsd_name(a["gsd"]):
                problems.append(f"GSD {g or 'none found for the ident'}, expected {a['gsd']}")
        if problems:
            raise StepFailed("; ".join(problems))
        return note or f"ident {_hex(got_ident)}, profile {idt.get('profile')}"

    def do_read(self, sr, r, d, h):
        a = r.step.args
        t = a["param"]
        pv = d.read_param(t.code)
        u = f" {pv.unit}" if pv.unit else ""
        r.measured = {"param": pv.code, "value": pv.value, "unit": pv.unit, "raw": pv.raw}
        v = pv.value
        if a["expect"] is not None:
            tol = a["tolerance"] if a["tolerance"] is not None else t.step_tolerance
            r.expected = {"value": a["expect"], "tolerance": a["tolerance"] or 0, "unit": t.unit}
            if not _close(v, a["expect"], tol):
                raise StepFailed(f"{pv.code} = {_fmt(v)}{u}, expected {_fmt(a['expect'])}{u}"
                                 + (f" ± {_fmt(a['tolerance'])}" if a["tolerance"] else ""))
        elif a["min"] is not None or a["max"] is not None:
            r.expected = {"min": a["min"], "max": a["max"], "unit": t.unit}
            if (a["min"] is not None and v < a["min"] - 1e-9) or (a["max"] is not None and v > a["max"] + 1e-9):
                lo = _fmt(a["min"]) if a["min"] is not None else "-inf"
                hi = _fmt(a["max"]) if a["max"] is not None else "inf"
                raise StepFailed(f"{pv.code} = {_fmt(v)}{u}, expected {lo}..{hi}{u}")
        return f"{pv.code} = {_fmt(v)}{u}"

    def do_write(self, sr, r, d, h):
        a = r.step.args
        t = a["param"]
        value = a["value"]
        r.expected = {"value": value, "unit": t.unit}
        before = None
        try:
            before = d.read_param(t.code).value
        except PdriveError:
            pass                          # write-only, or unreadable before: the read-back decides
        allow = bool(a.get("allow_dangerous"))
        if h.session is not None:
            # writable, not dangerous unless the step allows it, exact value, stop-only while running
            h.session.write_param(t.code, value, allow_dangerous=allow)
        else:
            if danger(t.param) and not allow:
                raise StepFailed(f"{t.label} is dangerous ({danger(t.param)}); the step needs "
                                 f"allow_dangerous: true")
            d.write_param(t.code, value)              # the codec's own exact-value check
        rb = d.read_param(t.code)
        u = f" {rb.unit}" if rb.unit else ""
        r.measured = {"param": rb.code, "before": before, "written": value, "read_back": rb.value,
                      "unit": rb.unit, "raw": rb.raw}
        if not _close(rb.value, value, t.step_tolerance):
            raise StepFailed(f"{rb.code}: wrote {_fmt(value)}{u}, read back {_fmt(rb.value)}{u}")
        notes = getattr(d, "notes", None)
        extra = ""
        if notes:
            extra = "; " + "; ".join(dict.fromkeys(notes))
            notes.clear()
        changed = "unchanged" if before is not None and _close(before, value, t.step_tolerance) else \
            (f"was {_fmt(before)}{u}" if before is not None else "")
        return f"{rb.code} = {_fmt(rb.value)}{u} (read back" + (f"; {changed}" if changed else "") + ")" + extra

    def do_save(self, sr, r, d, h):
        if h.session is not None:
            how = h.session.save_support()
            msg = h.session.save()        # 'automatic' cards: every write is already stored
            r.measured = {"saved": True, "how": how}
            return msg
        d.save()
        r.measured = {"saved": True, "how": "command"}
        return "saved to non-volatile memory"

    def do_run(self, sr, r, d, h):
        a = r.step.args
        sign = -1.0 if a["direction"] == "reverse" else 1.0
        target = sign * float(a["speed"])
        tol = float(a["tolerance"])
        unit = a["unit"]
        u = " Hz" if unit == "hz" else " %"
        r.expected = {"speed": target, "unit": "Hz" if unit == "hz" else "%", "tolerance": tol,
                      "within_s": a["within"], "hold_s": a["duration"]}
        ch = d.channel

        def actual(s):
            if unit == "hz":
                if s.speed_hz is not None:
                    return s.speed_hz
                if s.speed_percent is not None:
                    return s.speed_percent * d.max_frequency() / 100.0
                return None
            return s.speed_percent

        st0 = d.status()
        v0 = actual(st0)
        # reversing a turning motor: the actual has to pass through standstill before it can count (a
        # drive that reports the commanded direction with an unsigned speed would otherwise look
        # "reached" at the first cycle)
        through_zero = bool(st0.running and v0 is not None and v0 * target < 0 and abs(v0) > tol)
        t_start = ch.now()
        if unit == "hz":
            d.set_speed_hz(target)
        else:
            d.set_speed(target)
        st = d.status()
        if not st.running:
            st = d.start(timeout=float(a["within"]))
        deadline = t_start + float(a["within"])
        reached_at = None
        while True:
            v = actual(st)
            if st.fault:
                r.measured = _run_measured(st, v, None, None, None, unit)
                raise StepFailed(f"the drive tripped while accelerating ({st.fault_code or st.state})")
            if through_zero and v is not None and abs(v) <= tol:
                through_zero = False
            if v is not None and abs(v - target) <= tol and not through_zero:
                reached_at = ch.now()
                break
            if ch.now() > deadline:
                r.measured = _run_measured(st, v, None, None, None, unit)
                raise StepFailed(f"actual {_fmt(_r(v))}{u} after {_fmt(a['within'])} s, expected "
                                 f"{_fmt(target)}{u} ± {_fmt(tol)}")
            self._progress(sr, r, f"accelerating: {_fmt(_r(v))}{u} -> {_fmt(target)}{u}")
            st = d.cycle()
        reach_s = reached_at - t_start
        lo = hi = actual(st)
        hold_end = ch.now() + float(a["duration"])
        while ch.now() < hold_end:
            st = d.cycle()
            v = actual(st)
            if st.fault:
                r.measured = _run_measured(st, v, reach_s, lo, hi, unit)
                raise StepFailed(f"the drive tripped while running ({st.fault_code or st.state})")
            if v is not None:
                lo, hi = min(lo, v), max(hi, v)
                if abs(v - target) > tol:
                    r.measured = _run_measured(st, v, reach_s, lo, hi, unit)
                    raise StepFailed(f"actual left the band: {_fmt(_r(v))}{u} while holding "
                                     f"{_fmt(target)}{u} ± {_fmt(tol)}")
            self._progress(sr, r, f"holding {_fmt(_r(v))}{u} ({max(0.0, hold_end - ch.now()):.1f} s left)")
        v = actual(st)
        r.measured = _run_measured(st, v, reach_s, lo, hi, unit)
        return f"within ± {_fmt(tol)}{u} of {_fmt(target)}{u} after {reach_s:.2f} s" + (
            f", held {_fmt(a['duration'])} s at {_fmt(_r(lo))}..{_fmt(_r(hi))}{u}" if a["duration"] else "") + \
            f"; {_fmt(_r(v))}{u} at the end"

    def do_stop(self, sr, r, d, h):
        a = r.step.args
        ch = d.channel
        t0 = ch.now()
        r.expected = {"stopped": True, "within_s": a["within"]}
        st = d.stop(a["mode"], wait=True, timeout=float(a["within"]))
        took = ch.now() - t0
        r.measured = {"stopped": st.stopped, "after_s": round(took, 3), **_status_dict(st)}
        if not st.stopped:
            raise StepFailed(f"not stopped after {took:.1f} s (state {st.state}, speed {_fmt(_r(st.speed_hz))} Hz)")
        return f"stopped after {took:.2f} s ({st.state})"

    def do_expect_status(self, sr, r, d, h):
        a = r.step.args
        flags, state_text = a["flags"], a["state"]
        r.expected = {**{k: v for k, v in flags.items()}, **({"state": state_text} if state_text else {})}
        ch = d.channel
        end = ch.now() + float(a["within"])
        while True:
            st = d.status()
            got = {k: _flag(st, k) for k in flags}
            bad = [k for k, v in flags.items() if got[k] != v]
            state_ok = state_text is None or state_text.lower() in (st.state or "").lower()
            if (not bad and state_ok) or ch.now() >= end:
                break
            self._progress(sr, r, "waiting for " + ", ".join(bad or ["state"]))
        r.measured = {**got, "state": st.state, "speed_hz": _r(st.speed_hz), "speed_percent": _r(st.speed_percent),
                      "fault_code": st.fault_code}
        problems = [f"{k} is {'yes' if got[k] else 'no'}, expected {'yes' if flags[k] else 'no'}" for k in bad]
        if not state_ok:
            problems.insert(0, f"state {st.state!r}, expected {state_text!r}")
        if problems:
            raise StepFailed("; ".join(problems))
        return f"state {st.state}"

    def do_faults(self, sr, r, d, h):
        a = r.step.args
        st = d.status()
        need_history = a["history"] or a["expect"] != "none"
        hist = d.fault_history() if need_history else []
        entries = [{"position": f.position, "raw": f.raw, "codes": f.codes, "meanings": f.meanings}
                   for f in hist]
        recorded = [e for e in entries if e["raw"] and e["codes"]]
        r.measured = {"fault": st.fault, "current": st.fault_code, "state": st.state}
        if need_history:
            r.measured["history"] = entries
        if a["expect"] == "none":
            r.expected = {"fault": False, **({"history": []} if a["history"] else {})}
            if st.fault:
                raise StepFailed(f"the drive is in fault ({st.fault_code or st.state})")
            if a["history"] and recorded:
                raise StepFailed("fault history not empty: " + ", ".join(
                    f"{e['position']}: {'/'.join(e['codes'])}" for e in recorded))
            return "no fault" + (", history empty" if a["history"] else "")
        code = a["expect"]
        r.expected = {"code": code, "where": "history" if a["history"] else "current"}
        if a["history"]:
            if any(code.upper() in (c.upper() for c in e["codes"]) for e in recorded):
                return f"{code} is in the fault history"
            raise StepFailed(f"{code} is not in the fault history (" +
                             (", ".join("/".join(e["codes"]) for e in recorded) or "empty") + ")")
        current = {c.upper() for c in ([st.fault_code] if st.fault_code else [])}
        if st.fault and recorded:
            current |= {c.upper() for c in recorded[0]["codes"]}
        if st.fault and code.upper() in current:
            return f"current fault {code}"
        raise StepFailed(f"current fault is {st.fault_code or ('/'.join(sorted(current)) if st.fault else 'none')}, "
                         f"expected {code}")

    def do_reset_fault(self, sr, r, d, h):
        before = d.status()
        st = d.reset_fault()
        r.measured = {"fault_before": before.fault, "code_before": before.fault_code, **_status_dict(st)}
        r.expected = {"fault": False}
        if st.fault:
            raise StepFailed(f"still in fault after the reset ({st.fault_code or st.state})")
        return "fault acknowledged" if before.fault else "no fault to acknowledge"


DEFAULT_SAFE_STOP_S = 30.0


# =============================================================================================
# small helpers
# =============================================================================================


def _hex(v) -> str | None:
    return f"0x{v:04X}" if isinstance(v, int) else v


def _gsd_name(text: str) -> str:
    from pathlib import PurePath
    return PurePath(str(text).replace("\\", "/")).name.lower()


def _close(a, b, tol) -> bool:
    try:
        return abs(float(a) - float(b)) <= float(tol) + 1e-9
    except (TypeError, ValueError):
        return a == b


def _r(v):
    if v is None or not isinstance(v, float):
        return v
    return round(v, 3) if math.isfinite(v) else v


def _flag(st, name: str) -> bool:
    if name == "running":
        return bool(st.running)
    if name == "fault":
        return bool(st.fault)
    if name == "stopped":
        return bool(st.stopped)
    if name in st.flags:
        return bool(st.flags[name])
    low = name.lower()
    for k, v in st.flags.items():
        if k.lower() == low:
            return bool(v)
    return False


def _status_dict(st) -> dict:
    if st is None:
        return {}
    return {"state": st.state, "running": st.running, "stopped": st.stopped, "fault": st.fault,
            "fault_code": st.fault_code, "speed_hz": _r(st.speed_hz), "speed_percent": _r(st.speed_percent),
            "flags": {k: v for k, v in st.flags.items() if v}}


def _run_measured(st, v, reach_s, lo, hi, unit) -> dict:
    key = "actual_hz" if unit == "hz" else "actual_percent"
    out = {key: _r(v), "reached_after_s": round(reach_s, 3) if reach_s is not None else None,
           "state": st.state, "speed_hz": _r(st.speed_hz), "speed_percent": _r(st.speed_percent)}
    if lo is not None:
        out["hold_min"] = _r(lo)
        out["hold_max"] = _r(hi)
    if st.fault:
        out["fault_code"] = st.fault_code
    return out


def _identity_dict(identity) -> dict:
    out = {}
    for k, v in dict(identity or {}).items():
        out[k] = _hex(v) if k == "ident" else v
    return out


def _snapshot_targets(spec: StationSpec) -> list:
    """The header/station snapshot list plus every parameter the station's steps read or write."""
    out = list(spec.snapshot)
    for s in spec.steps:
        t = s.args.get("param") if s.type in ("read", "write") else None
        if t is not None and all(t.label != o.label for o in out):
            out.append(t)
    return out


# =============================================================================================
# opening stations through drives.session.DriveSession
# =============================================================================================


def dry_run_port(checklist: Checklist) -> str:
    """sim:// with one simulated station of each checklist station's profile at its address."""
    return "sim://?stations=" + ",".join(f"{s.address}:{s.profile.name}" for s in checklist.stations)


def session_opener(master, *, cycle_hz: float | None = None, watchdog_ms: float | None = None,
                   on_message: Callable[[str], None] | None = None):
    """open_station for Runner: one DriveSession per station on a shared master (the caller closes its
    link after the run). The session identifies the station, refuses a station of another family,
    parameterises it with the watchdog armed, and on exit stops the drive safely and releases it."""
    from profidrive_cli.session import DEFAULT_WATCHDOG_MS, DriveSession

    @contextlib.contextmanager
    def open_station(spec: StationSpec):
        s = DriveSession(master, spec.address, profile=spec.profile.name, layout=spec.layout,
                         cycle_hz=cycle_hz, watchdog_ms=watchdog_ms or DEFAULT_WATCHDOG_MS,
                         close_link=False, on_message=on_message)

        def closed() -> dict:
            rep = s.stop_report
            if rep is None:
                return {}
            out = {"exit_stop": rep.how, "exit_stop_message": rep.message}
            if rep.how not in ("not needed",):
                out["stopped"] = rep.stopped
                if rep.status is not None:
                    out["state"] = rep.status.state
            return out

        handle = StationHandle(None, {}, session=s, closed=closed)
        with s:
            handle.drive = s.drive
            handle.identity = session_identity(s)
            yield handle

    return open_station


def session_identity(s) -> dict:
    """The identity a DriveSession found: address, ident, profile, layout, GSD file of the ident, DP state."""
    gsd = None
    try:
        from profidrive_cli.gsd.library import find_path_by_ident
        p = find_path_by_ident(s.ident) if s.ident is not None else None
        gsd = p.name if p is not None else None
    except PdriveError:
        gsd = None
    out = {"address": s.address, "ident": s.ident, "profile": s.profile.name if s.profile else None,
           "layout": s.layout, "gsd": gsd}
    st = getattr(s, "station", None)
    if st is not None and getattr(st, "state", ""):
        out["dp_state"] = st.state
    if s.warnings:
        out["warnings"] = list(s.warnings)
    return out
