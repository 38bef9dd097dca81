"""The checklist's step types as one registry (checklist/steps/): every type documented, in the order the
docs list them; a step type added to the table is validated (file:line) and run with no change to the file
format or the run loop; each module of the checklist stays one concern (split by concern, never by a line
count)."""

import contextlib
import re
from pathlib import Path

import pytest

from profidrive_cli.checklist.fields import fmt
from profidrive_cli.checklist.runner import PASSED, Runner, StationHandle
from direct_session import direct_session
from profidrive_cli.checklist.spec import ChecklistError, load_checklist_text
from profidrive_cli.checklist.steps import STEPS, StepFailed, StepType
from profidrive_cli.drives import make_drive
from profidrive_cli.sim.direct import DirectChannel
from profidrive_cli.sim.plant import make_model

ROOT = Path(__file__).resolve().parents[1]
HEAD = """\
name: t
stations:
  - {name: c1, address: 3, profile: fuji-g1}
steps:
"""


def documented_step_types() -> list[str]:
    text = (ROOT / "docs" / "checklists.md").read_text(encoding="utf-8")
    section = text.split("\n## Steps\n", 1)[1].split("\n## ", 1)[0]
    return [h for h in re.findall(r"^### (\w+)\s*$", section, re.M)]


def test_the_registry_holds_the_documented_step_types_in_their_order():
    documented = documented_step_types()
    assert documented == ["expect_identity", "read", "write", "save", "run", "jog", "stop", "expect_status", "wait",
                          "bus_health", "faults", "reset_fault", "prompt", "note", "comm_loss", "baseline"]
    assert list(STEPS) == documented
    with pytest.raises(ChecklistError) as ei:
        load_checklist_text(HEAD + "  - name: nothing to do\n", "t.yaml")
    assert str(ei.value.errors[0]) == f"t.yaml:5: step 1: no step type (one of {', '.join(documented)})"


class Beep(StepType):
    """A step type written the way docs/checklists.md says: one class, schema and execution together."""
    name = "beep"

    def validate(self, check, st, rs, body, state):
        d = check.fields(rs, body, ("times",), "times", ("times",))
        times = check.num(rs, d, "times", minimum=1)
        return {"times": times}, f"beep {fmt(times)} times"

    def execute(self, run, sr, r, d, h):
        r.expected = {"times": r.step.args["times"]}
        st = run.cycle_for(sr, r, d, 0.2)
        r.measured = {"running": st.running}
        if st.running:
            raise StepFailed("the drive runs")
        return f"beeped {r.step.args['times']} times"


@contextlib.contextmanager
def direct_station(spec):
    ch = DirectChannel(make_model(spec.profile), spec.profile.layouts[spec.layout].cfg)
    d = make_drive(ch, spec.profile, spec.layout)
    yield StationHandle(d, {"address": spec.address, "profile": spec.profile.name, "layout": spec.layout},
                        direct_session(d, spec))


def test_a_step_type_added_to_the_table_is_validated_and_run(monkeypatch):
    monkeypatch.setitem(STEPS, "beep", Beep())
    cl = load_checklist_text(HEAD + "  - beep: 3\n  - note: done\n", "t.yaml")
    steps = cl.stations[0].steps
    assert [(s.type, s.args, s.title, s.line) for s in steps[:1]] == [("beep", {"times": 3}, "beep 3 times", 5)]
    with pytest.raises(ChecklistError) as ei:
        load_checklist_text(HEAD + "  - note: first\n  - beep: {times: 0}\n", "t.yaml")
    assert [str(e) for e in ei.value.errors] == ["t.yaml:6: step 2 (beep): 'times' must be at least 1, got 0"]
    with pytest.raises(ChecklistError) as ei:
        load_checklist_text(HEAD + "  - beeps: 2\n", "t.yaml")
    assert "unknown step type or key 'beeps' (did you mean beep?)" in str(ei.value.errors[0])
    res = Runner(cl, direct_station).run()
    r = res.stations[0].steps[0]
    assert (r.status, r.message, r.measured) == (PASSED, "beeped 3 times", {"running": False})
    assert res.passed


