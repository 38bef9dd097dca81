"""Step type `prompt`: ask the operator a yes/no question while the cyclic exchange keeps going.

validate() checks the step's fields for one station (file:line, through the FieldChecker);
execute() runs it on the station's Drive for the Runner. Imports only the checklist toolkits
(fields.py, steps/base.py) and drives/."""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, Any

from profidrive_cli.checklist.steps.base import Handle, R, SR, StepFailed, StepRun, StepType

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.checklist.fields import FieldChecker, RawStepFacts, StationFacts, StepArgs
    from profidrive_cli.drives.base import Drive


class Prompt(StepType):
    name = "prompt"

    def validate(self, check: FieldChecker, st: StationFacts, rs: RawStepFacts, body: Any,
                 state: dict[str, bool]) -> tuple[StepArgs, str]:
        d = check.fields(rs, body, ("text",), "text", ("text",))
        if not isinstance(d["text"], str) or not d["text"].strip():
            check.fail(d.line_of("text"), f"step {rs.index} (prompt): 'text' must be the question for the operator")
        return {"text": d["text"].strip()}, f"operator: {d['text'].strip()}"

    def execute(self, run: StepRun[SR, R], sr: SR, r: R, d: Drive, h: Handle) -> str:
        text = r.step.args["text"]
        r.expected = {"answer": "yes"}
        if run.dry_run:
            r.measured = {"answer": "yes", "by": "dry run"}
            return "dry run: taken as confirmed"
        if run.yes:
            r.measured = {"answer": "yes", "by": "--yes"}
            return "confirmed by --yes"
        if run.ask is None:
            r.measured = {"answer": None, "by": "nobody"}
            raise StepFailed("no operator to confirm (not a terminal): run with --yes to confirm prompts")
        # ask in a thread and keep the drive's cyclic data (and the watchdog) going meanwhile
        ask = run.ask
        box: dict[str, bool | BaseException] = {}

        def asker() -> None:
            try:
                box["answer"] = bool(ask(text))
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


STEP = Prompt()
