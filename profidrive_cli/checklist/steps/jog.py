"""Step type `jog`: the card's own jog for a time, optionally checking the speed it reaches, then a
normal stop to standstill.

    - jog: {duration: 2, direction: forward, hz: 5, tolerance: 0.5, within: 30}
    - jog: 2                       # shorthand: jog forward for 2 s

validate() refuses a station whose card cannot jog over the bus (drives/jog.py: the same words as
`pdrive jog`) and a jog while the step list leaves the drive running; execute() runs it on the
station's Drive for the Runner. Imports only the checklist toolkits (fields.py, steps/base.py) and drives/.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from profidrive_cli.checklist.fields import RawStepFacts, StationFacts, StepArgs, fmt
from profidrive_cli.checklist.steps.base import Handle, R, SR, StepFailed, StepRun, StepType, rnd
from profidrive_cli.drives.jog import jog_refusal

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.checklist.fields import FieldChecker
    from profidrive_cli.drives.base import Drive, DriveStatus

DIRECTIONS = ("forward", "reverse")
DEFAULT_TOL_HZ = 0.5
DEFAULT_STOP_WITHIN_S = 30.0


class Jog(StepType):
    name = "jog"

    def validate(self, check: FieldChecker, st: StationFacts, rs: RawStepFacts, body: Any,
                 state: dict[str, bool]) -> tuple[StepArgs, str]:
        d = check.fields(rs, body, ("duration", "direction", "hz", "tolerance", "within"), "duration",
                         ("duration",))
        w = f"step {rs.index} (jog)"
        why = jog_refusal(st.profile, st.layout)
        if why is not None:
            check.fail(rs.line, f"{w}: {why}")
        if state.get("running"):
            check.fail(rs.line, f"{w}: the drive is left running by an earlier step; add a stop step first "
                                f"(a jog starts from standstill)")
        duration = check.num(rs, d, "duration", positive=True, required=True)
        direction = d.get("direction", "forward")
        if direction not in DIRECTIONS:
            check.fail(d.line_of("direction"), f"{w}: direction must be forward or reverse, got {direction!r}")
        hz = check.num(rs, d, "hz", positive=True) if "hz" in d else None
        tol = check.num(rs, d, "tolerance", default=DEFAULT_TOL_HZ, positive=True)
        within = check.num(rs, d, "within", default=DEFAULT_STOP_WITHIN_S, positive=True)
        state["running"] = False            # the step ends with a stop
        title = f"jog {direction} for {fmt(duration)} s" + (
            f", reaching {fmt(hz)} Hz ± {fmt(tol)} Hz" if hz is not None else "") + ", then stop"
        return {"duration": duration, "direction": direction, "hz": hz, "tolerance": tol,
                "within": within}, title

    def execute(self, run: StepRun[SR, R], sr: SR, r: R, d: Drive, h: Handle) -> str:
        a = r.step.args
        reverse = a["direction"] == "reverse"
        want = a["hz"]
        tol = float(a["tolerance"])
        if want is not None:
            want = -float(want) if reverse else float(want)
            r.expected = {"speed_hz": want, "tolerance": tol, "stopped_within_s": a["within"]}
        else:
            r.expected = {"stopped_within_s": a["within"]}
        ch = d.channel
        fmax = d.max_frequency()

        def hz_of(s: DriveStatus) -> float | None:
            if s.speed_hz is not None:
                return s.speed_hz
            return None if s.speed_percent is None else s.speed_percent * fmax / 100.0

        st = d.cycle()
        if st.fault:
            raise StepFailed(f"the drive is in fault ({st.fault_code or st.state}): reset it first")
        d.jog(True, reverse=reverse)
        end = ch.now() + float(a["duration"])
        peak = None
        reached = None
        while ch.now() < end:
            st = d.cycle()
            v = hz_of(st)
            if st.fault:
                r.measured = {"peak_hz": rnd(peak), "state": st.state, "fault_code": st.fault_code}
                raise StepFailed(f"the drive tripped while jogging ({st.fault_code or st.state})")
            if v is not None and (peak is None or abs(v) > abs(peak)):
                peak = v
            if want is not None and reached is None and v is not None and abs(v - want) <= tol:
                reached = ch.now() - (end - float(a["duration"]))
            run.progress(sr, r, f"jogging: {fmt(rnd(v))} Hz ({max(0.0, end - ch.now()):.1f} s left)")
        at_end = hz_of(st)
        d.jog(False)
        t0 = ch.now()
        st = d.stop("normal", wait=True, timeout=float(a["within"]))
        took = ch.now() - t0
        r.measured = {"peak_hz": rnd(peak), "at_end_hz": rnd(at_end),
                      "reached_after_s": None if reached is None else round(reached, 3),
                      "stopped": st.stopped, "stopped_after_s": round(took, 3), "state": st.state}
        if not st.stopped:
            raise StepFailed(f"not stopped {took:.1f} s after the jog (state {st.state})")
        if want is not None and reached is None:
            raise StepFailed(f"the jog did not reach {fmt(want)} Hz ± {fmt(tol)} in {fmt(a['duration'])} s "
                             f"(peak {fmt(rnd(peak))} Hz)")
        return (f"jogged {a['direction']} {fmt(a['duration'])} s, peak {fmt(rnd(peak))} Hz"
                + (f" (within ± {fmt(tol)} Hz of {fmt(want)} Hz after {reached:.2f} s)" if reached is not None
                   else "") + f"; stopped after {took:.2f} s")


STEP = Jog()
