"""Step type `faults`: no active fault (and an empty history), or an alarm code as current fault or in the history.

validate() checks the step's fields for one station (file:line, through the FieldChecker);
execute() runs it on the station's Drive for the Runner. Imports only the checklist toolkits
(fields.py, steps/base.py) and drives/."""

from __future__ import annotations

import difflib
from typing import TYPE_CHECKING, Any

from profidrive_cli.checklist.fields import RawStepFacts, StationFacts, StepArgs, layout_has_params, tname
from profidrive_cli.checklist.steps.base import Handle, R, SR, StepFailed, StepRun, StepType

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.checklist.fields import FieldChecker
    from profidrive_cli.drives.base import Drive


class Faults(StepType):
    name = "faults"

    def validate(self, check: FieldChecker, st: StationFacts, rs: RawStepFacts, body: Any,
                 state: dict[str, bool]) -> tuple[StepArgs, str]:
        d = check.fields(rs, body, ("expect", "history"), "expect")
        w = f"step {rs.index} (faults)"
        expect = d.get("expect", "none")
        if expect is None:
            expect = "none"
        if not isinstance(expect, (str, int)) or isinstance(expect, bool):
            check.fail(d.line_of("expect"), f"{w}: 'expect' must be none or an alarm code, got {tname(expect)}")
        expect = str(expect)
        history = d.get("history", False)
        if not isinstance(history, bool):
            check.fail(d.line_of("history"), f"{w}: 'history' must be true or false, got {history!r}")
        if expect.lower() != "none":
            a = st.profile.alarm_by_code(expect)
            if a is None:
                codes = [x.code for x in st.profile.alarms]
                close = difflib.get_close_matches(expect, codes, 3, 0.5)
                check.fail(d.line_of("expect"), f"{w}: {st.profile.name} has no alarm {expect!r}"
                           + (f" (did you mean {', '.join(close)}?)" if close else ""))
            expect = a.code
        if (history or expect != "none") and not layout_has_params(st.profile, st.layout):
            check.fail(rs.line, f"{w}: reading the fault history needs a parameter channel; layout "
                       f"{st.layout} has none")
        if expect == "none":
            title = "no active fault" + (" and an empty fault history" if history else "")
        else:
            title = f"fault {expect} " + ("in the fault history" if history else "is the current fault")
        return {"expect": expect, "history": history}, title

    def execute(self, run: StepRun[SR, R], sr: SR, r: R, d: Drive, h: Handle) -> str:
        a = r.step.args
        st = d.status()
        need_history = a["history"] or a["expect"] != "none"
        hist = d.fault_history() if need_history else []
        entries: list[dict[str, Any]] = [
            {"position": f.position, "raw": f.raw, "codes": f.codes, "meanings": f.meanings} for f in hist]
        recorded = [e for e in entries if e["raw"] and e["codes"]]
        r.measured = {"fault": st.fault, "current": st.fault_code, "state": st.state}
        if need_history:
            r.measured["history"] = entries
        if a["expect"] == "none":
            r.expected = {"fault": False, **({"history": []} if a["history"] else {})}
            if st.fault:
                raise StepFailed(f"the drive is in fault ({st.fault_code or st.state})")
            if a["history"] and recorded:
                raise StepFailed("fault history not empty: " + ", ".join(
                    f"{e['position']}: {'/'.join(e['codes'])}" for e in recorded))
            return "no fault" + (", history empty" if a["history"] else "")
        code = a["expect"]
        r.expected = {"code": code, "where": "history" if a["history"] else "current"}
        if a["history"]:
            if any(code.upper() in (c.upper() for c in e["codes"]) for e in recorded):
                return f"{code} is in the fault history"
            raise StepFailed(f"{code} is not in the fault history (" +
                             (", ".join("/".join(e["codes"]) for e in recorded) or "empty") + ")")
        current = {c.upper() for c in ([st.fault_code] if st.fault_code else [])}
        if st.fault and recorded:
            current |= {c.upper() for c in recorded[0]["codes"]}
        if st.fault and code.upper() in current:
            return f"current fault {code}"
        raise StepFailed(f"current fault is {st.fault_code or ('/'.join(sorted(current)) if st.fault else 'none')}, "
                         f"expected {code}")


STEP = Faults()
