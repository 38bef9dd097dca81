"""Step type `stop`: stop (normal, quick or coast) and confirm standstill within a time.

validate() checks the step's fields for one station (file:line, through the FieldChecker);
execute() runs it on the station's Drive for the Runner. Imports only the checklist toolkits
(fields.py, steps/base.py) and drives/."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from profidrive_cli.checklist.fields import RawStepFacts, StationFacts, StepArgs, fmt
from profidrive_cli.checklist.steps.base import Handle, R, SR, StepFailed, StepRun, StepType, rnd, status_dict

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.checklist.fields import FieldChecker
    from profidrive_cli.drives.base import Drive

STOP_MODES = ("normal", "quick", "coast")
#: stop mode -> the capability the card must declare (drives/capabilities.py)
STOP_CAPABILITY = {"quick": "quick_stop", "coast": "coast_stop"}
DEFAULT_STOP_WITHIN_S = 30.0


class Stop(StepType):
    name = "stop"

    def validate(self, check: FieldChecker, st: StationFacts, rs: RawStepFacts, body: Any,
                 state: dict[str, bool]) -> tuple[StepArgs, str]:
        d = check.fields(rs, body, ("mode", "within"), "mode")
        mode = d.get("mode", "normal")
        if mode not in STOP_MODES:
            check.fail(d.line_of("mode"), f"step {rs.index} (stop): mode must be normal, quick or coast, "
                       f"got {mode!r}")
        elif mode in STOP_CAPABILITY:
            check.need_capability(st, rs, STOP_CAPABILITY[mode], d.line_of("mode"))
        within = check.num(rs, d, "within", default=DEFAULT_STOP_WITHIN_S, positive=True)
        state["running"] = False
        return {"mode": mode, "within": within}, f"stop ({mode}), stopped within {fmt(within)} s"

    def execute(self, run: StepRun[SR, R], sr: SR, r: R, d: Drive, h: Handle) -> str:
        a = r.step.args
        ch = d.channel
        t0 = ch.now()
        r.expected = {"stopped": True, "within_s": a["within"]}
        st = d.stop(a["mode"], wait=True, timeout=float(a["within"]))
        took = ch.now() - t0
        r.measured = {"stopped": st.stopped, "after_s": round(took, 3), **status_dict(st)}
        if not st.stopped:
            raise StepFailed(f"not stopped after {took:.1f} s (state {st.state}, speed {fmt(rnd(st.speed_hz))} Hz)")
        return f"stopped after {took:.2f} s ({st.state})"


STEP = Stop()
