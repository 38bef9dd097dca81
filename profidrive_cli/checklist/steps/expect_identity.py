"""Step type `expect_identity`: the station answers with the ident, profile and GSD file the checklist expects.

validate() checks the step's fields for one station (file:line, through the FieldChecker);
execute() runs it on the station's Drive for the Runner. Imports only the checklist toolkits
(fields.py, steps/base.py) and drives/."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from profidrive_cli import PdriveError
from profidrive_cli.checklist.steps.base import Handle, R, SR, StepFailed, StepRun, StepType, hex4

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.checklist.fields import FieldChecker, RawStepFacts, StationFacts, StepArgs
    from profidrive_cli.drives.base import Drive


class ExpectIdentity(StepType):
    name = "expect_identity"

    def validate(self, check: FieldChecker, st: StationFacts, rs: RawStepFacts, body: Any,
                 state: dict[str, bool]) -> tuple[StepArgs, str]:
        d = check.fields(rs, body, ("ident", "profile", "gsd"))
        ident = st.ident
        if "ident" in d:
            ident = d["ident"]
            if not isinstance(ident, int) or isinstance(ident, bool) or not 0 <= ident <= 0xFFFF:
                check.fail(d.line_of("ident"), f"step {rs.index} (expect_identity): 'ident' must be 0..0xFFFF")
        profile = st.profile.name
        if "profile" in d:
            from profidrive_cli.drives.profile import load_profile
            try:
                profile = load_profile(str(d["profile"])).name
            except PdriveError as e:
                check.fail(d.line_of("profile"), f"step {rs.index} (expect_identity): {e}")
        gsd = d.get("gsd", st.gsd)
        args = {"ident": ident, "profile": profile, "gsd": gsd}
        return args, f"identity: ident 0x{ident:04X}, profile {profile}" + (f", GSD {gsd}" if gsd else "")

    def execute(self, run: StepRun[SR, R], sr: SR, r: R, d: Drive, h: Handle) -> str:
        a = r.step.args
        idt = h.identity or {}
        got_ident = idt.get("ident")
        expect_ident = a["ident"]
        note = ""
        if run.dry_run and expect_ident != sr.spec.profile.ident and got_ident == sr.spec.profile.ident:
            note = (f"dry run: the simulator answers with the profile's ident 0x{got_ident:04X}; "
                    f"0x{expect_ident:04X} is checked on the plant")
            expect_ident = got_ident
        r.expected = {"ident": hex4(a["ident"]), "profile": a["profile"], "gsd": a["gsd"]}
        r.measured = {"ident": hex4(got_ident), "profile": idt.get("profile"), "gsd": idt.get("gsd"),
                      "address": idt.get("address"), "layout": idt.get("layout")}
        for k in ("dp_state", "warnings", "device", "name", "vendor", "card"):
            if idt.get(k):
                r.measured[k] = idt[k]
        problems = []
        if got_ident != expect_ident:
            problems.append(f"ident {hex4(got_ident)}, expected {hex4(expect_ident)}")
        if idt.get("profile") is not None and idt.get("profile") != a["profile"]:
            problems.append(f"profile {idt.get('profile')}, expected {a['profile']}")
        if a["gsd"] and not run.dry_run:
            g = idt.get("gsd")
            if g is None or gsd_name(g) != gsd_name(a["gsd"]):
                problems.append(f"GSD {g or 'none found for the ident'}, expected {a['gsd']}")
        if problems:
            raise StepFailed("; ".join(problems))
        return note or f"ident {hex4(got_ident)}, profile {idt.get('profile')}"


def gsd_name(text: str) -> str:
    from pathlib import PurePath
    return PurePath(str(text).replace("\\", "/")).name.lower()


STEP = ExpectIdentity()
