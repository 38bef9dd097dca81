"""Step type `save`: store the parameters in the drive's non-volatile memory.

validate() checks the step's fields for one station (file:line, through the FieldChecker);
execute() runs it on the station's Drive for the Runner. Imports only the checklist toolkits
(fields.py, steps/base.py) and drives/."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from profidrive_cli.checklist.steps.base import Handle, R, SR, StepRun, StepType

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.checklist.fields import FieldChecker, RawStepFacts, StationFacts, StepArgs
    from profidrive_cli.drives.base import Drive


class Save(StepType):
    name = "save"

    def validate(self, check: FieldChecker, st: StationFacts, rs: RawStepFacts, body: Any,
                 state: dict[str, bool]) -> tuple[StepArgs, str]:
        check.fields(rs, body, ())
        check.need_param_channel(st, rs)
        return {}, "save parameters to non-volatile memory"

    def execute(self, run: StepRun[SR, R], sr: SR, r: R, d: Drive, h: Handle) -> str:
        how = h.session.params.save_support()
        msg = h.session.params.save()        # 'automatic' cards: every write is already stored
        r.measured = {"saved": True, "how": how}
        return msg


STEP = Save()
