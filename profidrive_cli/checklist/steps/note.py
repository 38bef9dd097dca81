"""Step type `note`: a line of text in the report; touches nothing.

validate() checks the step's fields for one station (file:line, through the FieldChecker);
execute() runs it on the station's Drive for the Runner. Imports only the checklist toolkits
(fields.py, steps/base.py) and drives/."""

from __future__ import annotations

from profidrive_cli.checklist.steps.base import StepType


class Note(StepType):
    name = "note"

    def validate(self, check, st, rs, body, state):
        d = check.fields(rs, body, ("text",), "text", ("text",))
        if not isinstance(d["text"], (str, int, float)):
            check.fail(d.line_of("text"), f"step {rs.index} (note): 'text' must be text")
        return {"text": str(d["text"]).strip()}, f"note: {str(d['text']).strip()}"

    def execute(self, run, sr, r, d, h):
        r.measured = {"text": r.step.args["text"]}
        return r.step.args["text"]


STEP = Note()
