"""Step type `wait`: keep the cyclic exchange going for some seconds.

validate() checks the step's fields for one station (file:line, through the FieldChecker);
execute() runs it on the station's Drive for the Runner. Imports only the checklist toolkits
(fields.py, steps/base.py) and drives/."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from profidrive_cli.checklist.fields import RawStepFacts, StationFacts, StepArgs, fmt
from profidrive_cli.checklist.steps.base import Handle, R, SR, StepRun, StepType, status_dict

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.checklist.fields import FieldChecker
    from profidrive_cli.drives.base import Drive


class Wait(StepType):
    name = "wait"

    def validate(self, check: FieldChecker, st: StationFacts, rs: RawStepFacts, body: Any,
                 state: dict[str, bool]) -> tuple[StepArgs, str]:
        d = check.fields(rs, body, ("seconds",), "seconds", ("seconds",))
        s = check.num(rs, d, "seconds", minimum=0)
        return {"seconds": s}, f"wait {fmt(s)} s"

    def execute(self, run: StepRun[SR, R], sr: SR, r: R, d: Drive, h: Handle) -> str:
        s = float(r.step.args["seconds"])
        st = run.cycle_for(sr, r, d, s, "waiting")
        r.measured = {"seconds": s, "status": status_dict(st)}
        return ""


STEP = Wait()
