"""Step type `read`: read a parameter, compare it with an expected value (± tolerance) or a range.

validate() checks the step's fields for one station (file:line, through the FieldChecker);
execute() runs it on the station's Drive for the Runner. Imports only the checklist toolkits
(fields.py, steps/base.py) and drives/."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from profidrive_cli.checklist.fields import RawStepFacts, StationFacts, StepArgs, fmt, is_num, range_problem
from profidrive_cli.checklist.steps.base import Handle, R, SR, StepFailed, StepRun, StepType, close_to

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.checklist.fields import FieldChecker
    from profidrive_cli.drives.base import Drive


class Read(StepType):
    name = "read"

    def validate(self, check: FieldChecker, st: StationFacts, rs: RawStepFacts, body: Any,
                 state: dict[str, bool]) -> tuple[StepArgs, str]:
        d = check.fields(rs, body, ("param", "expect", "tolerance", "min", "max", "range"), "param", ("param",))
        w = f"step {rs.index} (read)"
        check.need_param_channel(st, rs)
        t = check.code_field(st, rs, d)
        expect = check.num(rs, d, "expect")
        tol = check.num(rs, d, "tolerance", minimum=0)
        lo, hi = check.num(rs, d, "min"), check.num(rs, d, "max")
        if "range" in d:
            r = d["range"]
            if not (isinstance(r, list) and len(r) == 2 and all(is_num(x) for x in r) and r[0] <= r[1]):
                check.fail(d.line_of("range"), f"{w}: 'range' must be [low, high] with low <= high, got {r!r}")
            if lo is not None or hi is not None:
                check.fail(d.line_of("range"), f"{w}: give either range or min/max, not both")
            lo, hi = r
        if expect is not None and (lo is not None or hi is not None):
            check.fail(d.line_of("expect"), f"{w}: give either expect (with tolerance) or a range, not both")
        if tol is not None and expect is None:
            check.fail(d.line_of("tolerance"), f"{w}: tolerance needs expect")
        if lo is not None and hi is not None and lo > hi:
            check.fail(d.line_of("min"), f"{w}: min {fmt(lo)} is above max {fmt(hi)}")
        u = f" {t.unit}" if t.unit else ""
        if expect is not None:
            if t.param is not None:
                msg = range_problem(t.param, expect)
                if msg:
                    check.err(d.line_of("expect"), f"{w}: expected value can never be read: {msg}")
            title = f"read {t.label}, expect {fmt(expect)}{u}" + (f" ± {fmt(tol)}" if tol else "")
        elif lo is not None or hi is not None:
            title = f"read {t.label}, expect " + (
                f"{fmt(lo)}..{fmt(hi)}{u}" if lo is not None and hi is not None else
                f">= {fmt(lo)}{u}" if lo is not None else f"<= {fmt(hi)}{u}")
        else:
            title = f"read {t.label}"
        return {"param": t, "expect": expect, "tolerance": tol, "min": lo, "max": hi}, title

    def execute(self, run: StepRun[SR, R], sr: SR, r: R, d: Drive, h: Handle) -> str:
        a = r.step.args
        t = a["param"]
        pv = d.read_param(t.code)
        u = f" {pv.unit}" if pv.unit else ""
        r.measured = {"param": pv.code, "value": pv.value, "unit": pv.unit, "raw": pv.raw}
        v = pv.value
        if a["expect"] is not None:
            tol = a["tolerance"] if a["tolerance"] is not None else t.step_tolerance
            r.expected = {"value": a["expect"], "tolerance": a["tolerance"] or 0, "unit": t.unit}
            if not close_to(v, a["expect"], tol):
                raise StepFailed(f"{pv.code} = {fmt(v)}{u}, expected {fmt(a['expect'])}{u}"
                                 + (f" ± {fmt(a['tolerance'])}" if a["tolerance"] else ""))
        elif a["min"] is not None or a["max"] is not None:
            r.expected = {"min": a["min"], "max": a["max"], "unit": t.unit}
            if (a["min"] is not None and v < a["min"] - 1e-9) or (a["max"] is not None and v > a["max"] + 1e-9):
                lo = fmt(a["min"]) if a["min"] is not None else "-inf"
                hi = fmt(a["max"]) if a["max"] is not None else "inf"
                raise StepFailed(f"{pv.code} = {fmt(v)}{u}, expected {lo}..{hi}{u}")
        return f"{pv.code} = {fmt(v)}{u}"


STEP = Read()
