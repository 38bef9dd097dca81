"""Step type `write`: write a parameter (writable, exact, in range, stop-only, dangerous: checked) and read it back.

validate() checks the step's fields for one station (file:line, through the FieldChecker);
execute() runs it on the station's Drive for the Runner. Imports only the checklist toolkits
(fields.py, steps/base.py) and drives/."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from profidrive_cli import PdriveError
from profidrive_cli.checklist.fields import RawStepFacts, StationFacts, StepArgs, fmt
from profidrive_cli.checklist.steps.base import Handle, R, SR, StepFailed, StepRun, StepType, close_to
from profidrive_cli.drives.values import danger, profile_value_problem

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.checklist.fields import FieldChecker
    from profidrive_cli.drives.base import Drive


class Write(StepType):
    name = "write"

    def validate(self, check: FieldChecker, st: StationFacts, rs: RawStepFacts, body: Any,
                 state: dict[str, bool]) -> tuple[StepArgs, str]:
        d = check.fields(rs, body, ("param", "value", "allow_dangerous"), None, ("param", "value"))
        w = f"step {rs.index} (write)"
        check.need_param_channel(st, rs)
        t = check.code_field(st, rs, d)
        value = check.num(rs, d, "value", required=True)
        allow = d.get("allow_dangerous", False)
        if not isinstance(allow, bool):
            check.fail(d.line_of("allow_dangerous"), f"{w}: 'allow_dangerous' must be true or false, got {allow!r}")
        p = t.param
        if p is not None:
            if not p.writable:
                check.fail(d.line_of("param"), f"{w}: {t.label} ({p.name}) is read-only")
            msg = profile_value_problem(st.profile, p, value)
            if msg:
                check.fail(d.line_of("value"), f"{w}: {msg} (station {st.name!r})")
            if p.access == "stop" and state["running"]:
                check.fail(rs.line, f"{w}: {t.label} can only be changed while the motor is stopped, and an "
                           f"earlier run step leaves it running; put a stop step before it")
            what = danger(p)
            if what and not allow:
                check.err(d.line_of("param"), f"{w}: {t.label} ({p.name}) is dangerous: writing it {what}; "
                          f"add 'allow_dangerous: true' to the step to write it")
        u = f" {t.unit}" if t.unit else ""
        return ({"param": t, "value": value, "allow_dangerous": allow},
                f"write {t.label} = {fmt(value)}{u}" + (" (dangerous, allowed)" if allow and p is not None
                                                         and danger(p) else ""))

    def execute(self, run: StepRun[SR, R], sr: SR, r: R, d: Drive, h: Handle) -> str:
        a = r.step.args
        t = a["param"]
        value = a["value"]
        r.expected = {"value": value, "unit": t.unit}
        before = None
        try:
            before = d.read_param(t.code).value
        except PdriveError:
            pass                          # write-only, or unreadable before: the read-back decides
        allow = bool(a.get("allow_dangerous"))
        # writable, not dangerous unless the step allows it, exact value: the code resolved and
        # checked once (Parameters.plan); stop-only while running, write, read back (execute)
        params = h.session.params
        params.execute(params.plan(t.code, value, allow_dangerous=allow))
        rb = d.read_param(t.code)
        u = f" {rb.unit}" if rb.unit else ""
        r.measured = {"param": rb.code, "before": before, "written": value, "read_back": rb.value,
                      "unit": rb.unit, "raw": rb.raw}
        if not close_to(rb.value, value, t.step_tolerance):
            raise StepFailed(f"{rb.code}: wrote {fmt(value)}{u}, read back {fmt(rb.value)}{u}")
        notes = d.take_notes()                        # the codec's remarks since the last call
        extra = "; " + "; ".join(dict.fromkeys(notes)) if notes else ""
        changed = "unchanged" if before is not None and close_to(before, value, t.step_tolerance) else \
            (f"was {fmt(before)}{u}" if before is not None else "")
        return f"{rb.code} = {fmt(rb.value)}{u} (read back" + (f"; {changed}" if changed else "") + ")" + extra


STEP = Write()
