"""Step type `run`: run at a speed (Hz or %), reach it within a time, optionally hold it in the band.

validate() checks the step's fields for one station (file:line, through the FieldChecker);
execute() runs it on the station's Drive for the Runner. Imports only the checklist toolkits
(fields.py, steps/base.py) and drives/."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from profidrive_cli.checklist.fields import RawStepFacts, StationFacts, StepArgs, fmt
from profidrive_cli.checklist.steps.base import Handle, R, SR, StepFailed, StepRun, StepType, rnd
from profidrive_cli.api.station import Reach

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.checklist.fields import FieldChecker
    from profidrive_cli.drives.base import Drive, DriveStatus

DIRECTIONS = ("forward", "reverse")
DEFAULT_RUN_WITHIN_S = 10.0
DEFAULT_TOL_HZ = 0.5
DEFAULT_TOL_PERCENT = 1.0


class Run(StepType):
    name = "run"

    def validate(self, check: FieldChecker, st: StationFacts, rs: RawStepFacts, body: Any,
                 state: dict[str, bool]) -> tuple[StepArgs, str]:
        d = check.fields(rs, body, ("hz", "percent", "direction", "duration", "tolerance", "within",
                                    "together"))
        w = f"step {rs.index} (run)"
        if ("hz" in d) == ("percent" in d):
            check.fail(rs.body_line, f"{w}: give the speed as either hz or percent")
        unit = "hz" if "hz" in d else "percent"
        speed = check.num(rs, d, unit, positive=True, required=True)    # there: checked above
        direction = d.get("direction", "forward")
        if direction not in DIRECTIONS:
            check.fail(d.line_of("direction"), f"{w}: direction must be forward or reverse, got {direction!r}")
        if unit == "percent" and speed > 100:
            check.fail(d.line_of("percent"), f"{w}: percent {fmt(speed)} is above 100 (the max frequency)")
        if unit == "hz":
            fp = st.profile.param(st.profile.max_frequency_param or "")
            top = fp.max if fp is not None and fp.max is not None else None
            if top is not None and fp is not None and speed > top:
                check.fail(d.line_of("hz"), f"{w}: {fmt(speed)} Hz is above what {st.profile.name} can run "
                           f"({fp.code} max {fmt(top)} Hz)")
        duration = check.num(rs, d, "duration", default=0.0, minimum=0)
        tol = check.num(rs, d, "tolerance", default=DEFAULT_TOL_HZ if unit == "hz" else DEFAULT_TOL_PERCENT,
                        positive=True)
        within = check.num(rs, d, "within", default=DEFAULT_RUN_WITHIN_S, positive=True)
        together = d.get("together", False)
        if not isinstance(together, bool):
            check.fail(d.line_of("together"), f"{w}: together must be true or false, got {together!r}")
        # together: every station of the step at once, all stopped at its end (together.py)
        state["running"] = not together
        u = " Hz" if unit == "hz" else " %"
        names = [n for n, _ in rs.stations] if rs.stations else None
        title = (f"run {direction} at {fmt(speed)}{u} (± {fmt(tol)}{u} within {fmt(within)} s)"
                 + (f", hold {fmt(duration)} s" if duration else "")
                 + ((", together with " + (", ".join(names) if names else "every station") + ", then stop")
                    if together else ""))
        args = {"unit": unit, "speed": speed, "direction": direction, "duration": duration, "tolerance": tol,
                "within": within}
        if together:
            args.update(together=True, together_stations=names)
        return args, title

    def execute(self, run: StepRun[SR, R], sr: SR, r: R, d: Drive, h: Handle) -> str:
        a = r.step.args
        if a.get("together"):
            from profidrive_cli.checklist.steps import together
            return together.execute(run, sr, r, d, h, a, run_measured)
        sign = -1.0 if a["direction"] == "reverse" else 1.0
        target = sign * float(a["speed"])
        tol = float(a["tolerance"])
        unit = a["unit"]
        u = " Hz" if unit == "hz" else " %"
        r.expected = {"speed": target, "unit": "Hz" if unit == "hz" else "%", "tolerance": tol,
                      "within_s": a["within"], "hold_s": a["duration"]}
        ch = d.channel

        def actual(s: DriveStatus) -> float | None:
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
        min_abs = abs(v0) if v0 is not None else 0.0
        t_start = ch.now()
        if unit == "hz":
            d.set_speed_hz(target)
        else:
            d.set_speed(target)
        st = d.status()
        if not st.running:
            st = d.start(timeout=float(a["within"]))
        deadline = t_start + float(a["within"])
        # the one "reached" rule of run (session/live.py Reach): settled in the band, not passed
        # through; beyond it on the far side fails the step
        reach = Reach(target, tol, start=v0 if st0.running else None, t0=t_start, unit=u.strip())
        while True:
            v = actual(st)
            if st.fault:
                r.measured = run_measured(st, v, None, None, None, unit)
                raise StepFailed(f"the drive tripped while accelerating ({st.fault_code or st.state})")
            if through_zero and v is not None and v0 is not None:     # (through_zero: v0 known)
                # standstill seen: a sample within ± tol of zero, or the magnitude fell and is
                # rising again (at a low cycle rate no sample need land near zero). Not the sign
                # alone: a drive that reports the commanded direction with the speed's magnitude
                # shows the target's sign while it still decelerates.
                min_abs = min(min_abs, abs(v))
                if abs(v) <= tol or (min_abs < abs(v0) - tol and abs(v) > min_abs + tol):
                    through_zero = False
            if not through_zero:
                reach.feed(ch.now(), v)
            if reach.overshoot:
                r.measured = run_measured(st, v, None, None, None, unit)
                raise StepFailed(reach.overshoot_words())
            if reach.reached_after is not None:
                break
            if reach.missed(ch.now(), deadline):
                r.measured = run_measured(st, v, None, None, None, unit)
                raise StepFailed(f"actual {fmt(rnd(v))}{u} after {fmt(a['within'])} s, expected "
                                 f"{fmt(target)}{u} ± {fmt(tol)}")
            run.progress(sr, r, f"accelerating: {fmt(rnd(v))}{u} -> {fmt(target)}{u}")
            st = d.cycle()
        reach_s = reach.reached_after
        lo = hi = actual(st)
        assert lo is not None and hi is not None    # Reach counts known speeds only: the one that reached
        hold_end = ch.now() + float(a["duration"])
        while ch.now() < hold_end:
            st = d.cycle()
            v = actual(st)
            if st.fault:
                r.measured = run_measured(st, v, reach_s, lo, hi, unit)
                raise StepFailed(f"the drive tripped while running ({st.fault_code or st.state})")
            if v is not None:
                lo, hi = min(lo, v), max(hi, v)
                if abs(v - target) > tol:
                    r.measured = run_measured(st, v, reach_s, lo, hi, unit)
                    raise StepFailed(f"actual left the band: {fmt(rnd(v))}{u} while holding "
                                     f"{fmt(target)}{u} ± {fmt(tol)}")
            run.progress(sr, r, f"holding {fmt(rnd(v))}{u} ({max(0.0, hold_end - ch.now()):.1f} s left)")
        v = actual(st)
        r.measured = run_measured(st, v, reach_s, lo, hi, unit)
        return f"within ± {fmt(tol)}{u} of {fmt(target)}{u} after {reach_s:.2f} s" + (
            f", held {fmt(a['duration'])} s at {fmt(rnd(lo))}..{fmt(rnd(hi))}{u}" if a["duration"] else "") + \
            f"; {fmt(rnd(v))}{u} at the end"


def run_measured(st: DriveStatus, v: float | None, reach_s: float | None, lo: float | None, hi: float | None,
                 unit: str) -> dict[str, Any]:
    key = "actual_hz" if unit == "hz" else "actual_percent"
    out = {key: rnd(v), "reached_after_s": round(reach_s, 3) if reach_s is not None else None,
           "state": st.state, "speed_hz": rnd(st.speed_hz), "speed_percent": rnd(st.speed_percent)}
    if lo is not None:
        out["hold_min"] = rnd(lo)
        out["hold_max"] = rnd(hi)
    if st.fault:
        out["fault_code"] = st.fault_code
    return out


STEP = Run()
