"""Step type `expect_status`: status flags (running, fault, stopped, the family's own) and the state name.

validate() checks the step's fields for one station (file:line, through the FieldChecker);
execute() runs it on the station's Drive for the Runner. Imports only the checklist toolkits
(fields.py, steps/base.py) and drives/."""

from __future__ import annotations

import difflib
from typing import TYPE_CHECKING, Any

from profidrive_cli.checklist.fields import RawStepFacts, Skip, StationFacts, StepArgs, is_num, tname
from profidrive_cli.checklist.steps.base import Handle, R, SR, StepFailed, StepRun, StepType, rnd
from profidrive_cli.datafile import LineDict

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.checklist.fields import FieldChecker
    from profidrive_cli.drives.base import Drive, DriveStatus

# generic status names every family answers (DriveStatus fields), besides the family's own flags
GENERIC_FLAGS = ("running", "fault", "stopped")


class ExpectStatus(StepType):
    name = "expect_status"

    def validate(self, check: FieldChecker, st: StationFacts, rs: RawStepFacts, body: Any,
                 state: dict[str, bool]) -> tuple[StepArgs, str]:
        w = f"step {rs.index} (expect_status)"
        if not isinstance(body, LineDict) or not body:
            check.fail(rs.body_line, f"{w}: expected a mapping of status flags to true/false, e.g. "
                       f"{{running: false, fault: false}}")
        flags = {}
        state_text = None
        within = 0.0
        known = list(dict.fromkeys(list(GENERIC_FLAGS) + st.flag_names))
        n_errors = len(check.errors)
        lower = {k.lower(): k for k in known}
        for k, v in body.items():
            ln = body.line_of(k)
            if k == "state":
                if not isinstance(v, str):
                    check.err(ln, f"{w}: 'state' must be text (part of the state name), got {tname(v)}")
                state_text = str(v)
                continue
            if k == "within":
                if not is_num(v) or v < 0:
                    check.err(ln, f"{w}: 'within' must be a number of seconds >= 0, got {v!r}")
                else:
                    within = float(v)
                continue
            if not isinstance(v, bool):
                check.err(ln, f"{w}: flag {k!r} must be true or false, got {tname(v)} {v!r}")
                continue
            name = lower.get(str(k).lower())
            if name is None and not str(k).lower().startswith("fault: "):
                close = difflib.get_close_matches(str(k), known, 3, 0.5)
                check.err(ln, f"{w}: {st.profile.name} has no status flag {k!r}"
                          + (f" (did you mean {', '.join(repr(c) for c in close)}?)" if close else
                             f" (flags: {', '.join(known)})"))
                continue
            flags[name or str(k)] = v
        if len(check.errors) > n_errors:
            raise Skip()
        if not flags and state_text is None:
            check.fail(rs.body_line, f"{w}: nothing to check (name flags, or state)")
        parts = [f"{k} = {'yes' if v else 'no'}" for k, v in flags.items()]
        if state_text:
            parts.insert(0, f"state ~ {state_text!r}")
        return {"flags": flags, "state": state_text, "within": within}, "status: " + ", ".join(parts)

    def execute(self, run: StepRun[SR, R], sr: SR, r: R, d: Drive, h: Handle) -> str:
        a = r.step.args
        flags, state_text = a["flags"], a["state"]
        r.expected = {**{k: v for k, v in flags.items()}, **({"state": state_text} if state_text else {})}
        ch = d.channel
        end = ch.now() + float(a["within"])
        while True:
            st = d.status()
            got = {k: flag_of(st, k) for k in flags}
            bad = [k for k, v in flags.items() if got[k] != v]
            state_ok = state_text is None or state_text.lower() in (st.state or "").lower()
            if (not bad and state_ok) or ch.now() >= end:
                break
            run.progress(sr, r, "waiting for " + ", ".join(bad or ["state"]))
        r.measured = {**got, "state": st.state, "speed_hz": rnd(st.speed_hz), "speed_percent": rnd(st.speed_percent),
                      "fault_code": st.fault_code}
        problems = [f"{k} is {'yes' if got[k] else 'no'}, expected {'yes' if flags[k] else 'no'}" for k in bad]
        if not state_ok:
            problems.insert(0, f"state {st.state!r}, expected {state_text!r}")
        if problems:
            raise StepFailed("; ".join(problems))
        return f"state {st.state}"


def flag_of(st: DriveStatus, name: str) -> bool:
    if name == "running":
        return bool(st.running)
    if name == "fault":
        return bool(st.fault)
    if name == "stopped":
        return bool(st.stopped)
    if name in st.flags:
        return bool(st.flags[name])
    low = name.lower()
    for k, v in st.flags.items():
        if k.lower() == low:
            return bool(v)
    return False


STEP = ExpectStatus()
