"""`run` with `together: true`: the stations of the step (its `stations:` list, else every station of
the checklist) run at once, with the same checks per drive as `run` (reach the band within `within`,
hold it for `duration`), and all of them are stopped together at the end of the step.

Stations run one after the other in a checklist, so the step runs on the turn of the first station of
its list: it opens the others' sessions beside that one (run.open_station, the same master), puts every
session on one bus cycle (session/group.py: the Group, its rounds and its stop of all in one round) and,
on the later stations' turns, reports what it measured for them. A trip or a station dropping out ends
the run for all (every drive stopped). Not a step type of its own: checklist/steps/run.py hands over
to it. The watchdog every station of such a step holds (the Group's three rounds) is decided before
any of them is parameterised: group_watchdog, asked by runner.session_opener.
"""

from __future__ import annotations

import contextlib
import weakref
from typing import TYPE_CHECKING, Any, Callable

from profidrive_cli.checklist.fields import StationFacts, StepArgs, fmt
from profidrive_cli.checklist.steps.base import ChecklistFacts, Handle, R, SR, StepFailed, StepRun, rnd
from profidrive_cli.api.station import Group
from profidrive_cli.api.station import Reach

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.dp.poller import Master
    from profidrive_cli.drives.base import Drive, DriveStatus
    from profidrive_cli.api.station import DriveStation

#: run.py's run_measured(st, v, reach_s, lo, hi, unit) -> the step's measured dict
RunMeasured = Callable[["DriveStatus", "float | None", "float | None", "float | None", "float | None", str],
                       dict[str, Any]]
#: one station's outcome: (passed, message, expected, measured)
Outcome = tuple[bool, str, dict[str, Any], dict[str, Any]]

#: Runner -> {step index: {station name: Outcome}}
_DONE: weakref.WeakKeyDictionary[object, dict[int, dict[str, Outcome]]] = weakref.WeakKeyDictionary()


class _Drive:
    """One drive of the run and its checks (the rules of `run`)."""

    def __init__(self, name: str, drive: Drive, session: DriveStation, a: StepArgs) -> None:
        self.name, self.d, self.session = name, drive, session
        assert session.address is not None          # an open session found its station (as api/bus.py)
        self.address: int = session.address
        sign = -1.0 if a["direction"] == "reverse" else 1.0
        self.target = sign * float(a["speed"])
        self.tol, self.unit = float(a["tolerance"]), a["unit"]
        self.u = " Hz" if self.unit == "hz" else " %"
        self.reached: float | None = None              # seconds to the band
        self.lo: float | None = None
        self.hi: float | None = None
        self.failed = ""
        self.st: DriveStatus | None = None

    def actual(self, s: DriveStatus) -> float | None:
        if self.unit == "hz":
            if s.speed_hz is not None:
                return s.speed_hz
            if s.speed_percent is not None:
                return s.speed_percent * self.d.max_frequency() / 100.0
            return None
        return s.speed_percent

    def begin(self, within: float) -> None:
        ch = self.d.channel
        st0 = self.d.status()
        self.v0 = self.actual(st0)
        self.through_zero = bool(st0.running and self.v0 is not None and self.v0 * self.target < 0
                                 and abs(self.v0) > self.tol)
        self.min_abs = abs(self.v0) if self.v0 is not None else 0.0
        self.t_start = ch.now()
        if self.unit == "hz":
            self.d.set_speed_hz(self.target)
        else:
            self.d.set_speed(self.target)
        st = self.d.status()
        if not st.running:
            st = self.d.start(timeout=within)
        self.deadline = self.t_start + within
        self.st = st
        # the one "reached" rule of run (session/live.py Reach)
        self.reach = Reach(self.target, self.tol, start=self.v0 if st0.running else None,
                           t0=self.t_start, unit=self.u.strip())

    def feed_reach(self, st: DriveStatus, now: float) -> bool:
        """True once this drive is done with the reach phase (in the band, failed or tripped)."""
        self.st = st
        v = self.actual(st)
        if st.fault:
            self.failed = f"the drive tripped while accelerating ({st.fault_code or st.state})"
            return True
        if self.through_zero and v is not None and self.v0 is not None:     # (through_zero: v0 known)
            self.min_abs = min(self.min_abs, abs(v))
            fell = self.min_abs < abs(self.v0) - self.tol
            if abs(v) <= self.tol or (fell and abs(v) > self.min_abs + self.tol):
                self.through_zero = False
        reach = self.reach
        if not self.through_zero:
            reach.feed(now, v)
        if reach.overshoot:
            self.failed = reach.overshoot_words()
            return True
        if reach.reached_after is not None:
            self.reached = reach.reached_after
            self.lo = self.hi = v
            return True
        if reach.missed(now, self.deadline):
            self.failed = (f"actual {fmt(rnd(v))}{self.u} after {fmt(now - self.t_start)} s, expected "
                           f"{fmt(self.target)}{self.u} ± {fmt(self.tol)}")
            return True
        return False

    def feed_hold(self, st: DriveStatus) -> None:
        self.st = st
        v = self.actual(st)
        if self.failed:
            return
        if st.fault:
            self.failed = f"the drive tripped while running ({st.fault_code or st.state})"
        elif v is not None:
            assert self.lo is not None and self.hi is not None     # reached: set to the speed that reached
            self.lo, self.hi = min(self.lo, v), max(self.hi, v)
            if abs(v - self.target) > self.tol:
                self.failed = (f"actual left the band: {fmt(rnd(v))}{self.u} while holding "
                               f"{fmt(self.target)}{self.u} ± {fmt(self.tol)}")

    def result(self, a: StepArgs, others: str, run_measured: RunMeasured) -> Outcome:
        st = self.st
        v = self.actual(st) if st is not None else None
        expected = {"speed": self.target, "unit": "Hz" if self.unit == "hz" else "%",
                    "tolerance": self.tol, "within_s": a["within"], "hold_s": a["duration"],
                    "together_with": others}
        measured = run_measured(st, v, self.reached, self.lo, self.hi, self.unit) if st is not None else {}
        if self.session.motion.stop_report is not None:
            measured["stop"] = self.session.motion.stop_report.how
            measured["stopped"] = self.session.motion.stop_report.stopped
        if self.failed:
            return False, self.failed, expected, measured
        msg = (f"within ± {fmt(self.tol)}{self.u} of {fmt(self.target)}{self.u} after {self.reached:.2f} s"
               + (f", held {fmt(a['duration'])} s at {fmt(rnd(self.lo))}..{fmt(rnd(self.hi))}{self.u}"
                  if a["duration"] else "") + f"; run together with {others}, all stopped after")
        rep = self.session.motion.stop_report
        if rep is None or not rep.stopped:
            return False, msg.replace("all stopped after", "NOT confirmed stopped after"), expected, measured
        return True, msg, expected, measured


def execute(run: StepRun[SR, R], sr: SR, r: R, d: Drive, h: Handle, a: StepArgs,
            run_measured: RunMeasured) -> str:
    """run_measured: run.py's measured dict (passed in: run.py imports this module)."""
    names = a.get("together_stations") or [s.name for s in run.cl.stations]
    specs = [s for s in run.cl.stations if s.name in names]
    done = _DONE.setdefault(run, {})
    index = r.step.index
    if index not in done:
        if specs[0].name != sr.spec.name:
            raise StepFailed(f"not run: it runs on the turn of {specs[0].name}, which did not run it")
        done[index] = _run_all(run, sr, r, d, h, a, specs, run_measured)
    res = done[index].get(sr.spec.name)
    if res is None:
        raise StepFailed("not run: this station was not part of the run together")
    ok, msg, r.expected, r.measured = res
    if not ok:
        raise StepFailed(msg)
    return msg


def group_watchdog(checklist: ChecklistFacts, spec: StationFacts, master: Master,
                   asked_ms: float) -> tuple[float, str | None]:
    """The DP watchdog (ms) for `spec`'s station: the one asked for, raised to three rounds of the
    largest group of a `together` step it runs in (Group.watchdog_for, as run 3,4,5), with the
    warning's words when raised. The rounds as the step paces them (Group.rate of the stations'
    wire limits at the bus's baud rate); decided before the station is parameterised, because the
    Set_Prm carries it (on its own turn too: the step runs on the first station's)."""
    from profidrive_cli.api.station import wire_limit_hz
    best: tuple[float, str | None] = (asked_ms, None)
    by_name = {s.name: s for s in checklist.stations}
    steps = {id(st): st for s in checklist.stations for st in s.steps
             if st.type == "run" and st.args.get("together")}
    for st in steps.values():
        names = st.args.get("together_stations") or list(by_name)
        if spec.name not in names or len(names) < 2:
            continue
        members = [by_name[n] for n in names if n in by_name]
        wire = [wire_limit_hz(master.params.baud, lay.output_len, lay.input_len)
                for lay in (m.profile.layouts[m.layout] for m in members)]
        rate, _ = Group.rate(master, wire)
        got = Group.watchdog_for(asked_ms, 1.0 / rate, len(members))
        if got[0] > best[0]:
            best = got
    return best


def _run_all(run: StepRun[SR, R], sr: SR, r: R, d: Drive, h: Handle, a: StepArgs,
             specs: list[StationFacts], run_measured: RunMeasured) -> dict[str, Outcome]:
    drives = [_Drive(sr.spec.name, d, h.session, a)]
    results: dict[str, Outcome] = {}
    with contextlib.ExitStack() as stack:
        group = Group(h.session.master)
        stack.callback(group.join(h.session))
        for spec in specs[1:]:
            hh = stack.enter_context(run.open_station(spec))
            group.join(hh.session)           # stays on the group until its session is closed
            drives.append(_Drive(spec.name, hh.drive, hh.session, a))
        rate, _ = Group.rate(group.master, [x.session.wire_hz for x in drives])
        group.period = 1.0 / rate if rate else 0.0
        try:
            _reach_and_hold(run, sr, r, a, drives, group)
        finally:
            _stop_all(drives, group)
        for x in drives:
            others = ", ".join(y.name for y in drives if y is not x)
            results[x.name] = x.result(a, others, run_measured)
    return results


def _reach_and_hold(run: StepRun[SR, R], sr: SR, r: R, a: StepArgs, drives: list[_Drive],
                    group: Group) -> None:
    def end_round() -> None:
        group.end_round()
    for x in drives:
        x.begin(float(a["within"]))
    ch = drives[0].d.channel
    pending = list(drives)
    while pending:
        for x in list(pending):
            if x.feed_reach(x.d.cycle(), ch.now()):
                pending.remove(x)
        end_round()
        tripped = [x.name for x in drives if x.st is not None and x.st.fault]
        if tripped:                         # a trip ends the run for all
            for x in pending:               # (still on the way: not reached, not failed yet)
                x.failed = f"not in the band when the run ended: {', '.join(tripped)} tripped (a trip ends " \
                           f"the run for all)"
            return
        run.progress(sr, r, "accelerating: " + ", ".join(
            f"{x.name} {fmt(rnd(x.actual(x.st)))}{x.u}" for x in drives if x.st is not None))
    if any(x.failed for x in drives):
        return
    hold_end = ch.now() + float(a["duration"])
    while ch.now() < hold_end:
        for x in drives:
            x.feed_hold(x.d.cycle())
        end_round()
        if any(x.st is not None and x.st.fault for x in drives):
            return
        run.progress(sr, r, f"holding ({max(0.0, hold_end - ch.now()):.1f} s left)")


def _stop_all(drives: list[_Drive], group: Group) -> None:
    """Every drive stopped together (the Group's stop of all)."""
    group.stop_all([(x.address, x.session, None) for x in drives])
