"""Step type `reset_fault`: acknowledge the fault and confirm the drive left it.

validate() checks the step's fields for one station (file:line, through the FieldChecker);
execute() runs it on the station's Drive for the Runner. Imports only the checklist toolkits
(fields.py, steps/base.py) and drives/."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from profidrive_cli.checklist.steps.base import Handle, R, SR, StepFailed, StepRun, StepType, status_dict

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.checklist.fields import FieldChecker, RawStepFacts, StationFacts, StepArgs
    from profidrive_cli.drives.base import Drive


class ResetFault(StepType):
    name = "reset_fault"

    def validate(self, check: FieldChecker, st: StationFacts, rs: RawStepFacts, body: Any,
                 state: dict[str, bool]) -> tuple[StepArgs, str]:
        check.fields(rs, body, ("within",))
        return {}, "reset (acknowledge) the fault"

    def execute(self, run: StepRun[SR, R], sr: SR, r: R, d: Drive, h: Handle) -> str:
        before = d.status()
        st = d.reset_fault()
        r.measured = {"fault_before": before.fault, "code_before": before.fault_code, **status_dict(st)}
        r.expected = {"fault": False}
        if st.fault:
            raise StepFailed(f"still in fault after the reset ({st.fault_code or st.state})")
        return "fault acknowledged" if before.fault else "no fault to acknowledge"


STEP = ResetFault()
