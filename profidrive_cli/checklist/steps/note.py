"""Step type `note`: a line of text in the report; touches nothing.

validate() checks the step's fields for one station (file:line, through the FieldChecker);
execute() runs it on the station's Drive for the Runner. Imports only the checklist toolkits
(fields.py, steps/base.py) and drives/."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from profidrive_cli.checklist.steps.base import Handle, R, SR, StepRun, StepType

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.checklist.fields import FieldChecker, RawStepFacts, StationFacts, StepArgs
    from profidrive_cli.drives.base import Drive


class Note(StepType):
    name = "note"

    def validate(self, check: FieldChecker, st: StationFacts, rs: RawStepFacts, body: Any,
                 state: dict[str, bool]) -> tuple[StepArgs, str]:
        d = check.fields(rs, body, ("text",), "text", ("text",))
        if not isinstance(d["text"], (str, int, float)):
            check.fail(d.line_of("text"), f"step {rs.index} (note): 'text' must be text")
        return {"text": str(d["text"]).strip()}, f"note: {str(d['text']).strip()}"

    def execute(self, run: StepRun[SR, R], sr: SR, r: R, d: Drive, h: Handle) -> str:
        r.measured = {"text": r.step.args["text"]}
        text: str = r.step.args["text"]
        return text


STEP = Note()
