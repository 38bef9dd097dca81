"""Checklists without a bus: the format's validation (file:line for every kind of bad input) and the runner
on a Drive over DirectChannel (simulated clock, no real time)."""

import contextlib
from pathlib import Path

import pytest

from profidrive_cli.checklist.runner import FAILED, NOT_RUN, PASSED, Runner, StationHandle
from direct_session import direct_session
from profidrive_cli.checklist.spec import ChecklistError, load_checklist, load_checklist_text, parse_var_assignments
from profidrive_cli.drives import make_drive
from profidrive_cli.sim.direct import DirectChannel
from profidrive_cli.sim.plant import make_model

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples" / "checklists").glob("*.yaml"))

HEAD = """\
name: t
stations:
  - {name: c1, address: 3, profile: fuji-g1}
steps:
"""


def errors_of(text, overrides=None):
    with pytest.raises(ChecklistError) as ei:
        load_checklist_text(text, "t.yaml", overrides)
    return ei.value.errors


def test_there_is_one_example_per_family():
    fams = {load_checklist(p).stations[0].profile.name for p in EXAMPLES}
    assert fams == {"fuji-opc-g1-pdp", "fuji-opc-pdp3", "toyo-pbus66z", "moeller-de6-net-dp", "yaskawa-si-p1"}


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
def test_examples_validate_and_cover_the_commissioning_steps(path):
    cl = load_checklist(path)
    types = [s.type for s in cl.stations[0].steps]
    for t in ("expect_identity", "run", "stop", "expect_status", "faults"):
        assert t in types, t
    runs = [s.args for s in cl.stations[0].steps if s.type == "run"]
    assert [(r["direction"], r["speed"], r["unit"]) for r in runs] == [("forward", 10, "hz"), ("reverse", 10, "hz")]


# (step lines after HEAD, line of the error, words in the message)
BAD_STEPS = [
    ("  - jump: 3\n", 5, "unknown step type or key 'jump'"),
    ("  - write: {param: F07}\n", 5, "missing field 'value'"),
    ("  - run: {hz: ten}\n", 5, "'hz' must be a number, got text 'ten'"),
    ("  - read: {param: C1-01}\n", 5, "unknown parameter 'C1-01' for fuji-opc-g1-pdp (C1-01 is a yaskawa code"),
    ("  - write: {param: F07, value: 99999}\n", 5, "99999 s is outside 0..6000 s"),
    ("  - write: {param: PNU918, value: 3}\n", 5, "read-only"),
    ("  - note: a\n  - write: {param: F07, value: \"${accel}\"}\n", 6, "variable ${accel} is not defined"),
    ("  - expect_status: {runing: true}\n", 5, "no status flag 'runing' (did you mean 'running'"),
    ("  - faults: {expect: OC9}\n", 5, "no alarm 'OC9'"),
    ("  - run: {hz: 10}\n  - write: {param: F03, value: 50}\n", 6, "only be changed while the motor is stopped"),
    ("  - stop: sideways\n", 5, "mode must be normal, quick or coast"),
    ("  - wait: {seconds: 1, foo: 2}\n", 5, "unknown field 'foo'"),
    ("  - read: F03\n    on_fail: maybe\n", 6, "on_fail must be stop or continue"),
    ("  - write: {param: H03, value: 1}\n", 5, "dangerous"),
    ("  - write: {param: P04, value: 2}\n", 5, "add 'allow_dangerous: true' to the step"),
    ("  - write: {param: o27, value: 10.7}\n", 5, "o27 = 10.7 cannot be held exactly"),
    ("  - write: {param: F07, value: 0.05}\n", 5, "resolution 0.1 s; nearest 0 s or 0.1 s"),
    ("  - write: {param: F07, value: 2.55}\n", 5, "nearest 2.5 s or 2.6 s"),
    ("  - write: {param: F07, value: 2, allow_dangerous: yes please}\n", 5, "'allow_dangerous' must be true"),
    ("  - read: F03\n    write: {param: F07, value: 1}\n", 6, "one step type per step"),
    ("  - run: {hz: 10, percent: 20}\n", 5, "either hz or percent"),
    ("  - read: {param: F03, expect: 60, range: [1, 2]}\n", 5, "not both"),
    ("  - save: {now: true}\n", 5, "takes no fields, got 'now'"),
    ("  - read: F03\n    stations: [c9]\n", 6, "no station named 'c9'"),
]


@pytest.mark.parametrize("steps,line,words", BAD_STEPS, ids=[w[2][:30] for w in BAD_STEPS])
def test_bad_steps_are_rejected_with_file_and_line(steps, line, words):
    errs = errors_of(HEAD + steps)
    assert any(e.line == line and words in e.message for e in errs), [str(e) for e in errs]
    assert all(str(e).startswith("t.yaml:") for e in errs)


def test_header_and_station_problems():
    errs = errors_of("name: t\nstatoins: []\nsteps: [save]\n")
    assert any(e.line == 2 and "unknown header key 'statoins' (did you mean stations?)" in e.message for e in errs)
    assert any("missing field 'stations'" in e.message for e in errs)
    errs = errors_of("name: t\nstations:\n  - {address: 3, profile: fuji-g1, layout: ppo9}\nsteps: [save]\n")
    assert errs[0].line == 3 and "no layout 'ppo9'" in errs[0].message
    errs = errors_of("name: t\nstations:\n  - {address: 3, profile: nosuch}\nsteps: [save]\n")
    assert errs[0].line == 3 and "unknown profile 'nosuch'" in errs[0].message
    errs = errors_of("name: t\nstations:\n  - {address: 3, profile: fuji-g1, gsd: YASK00CA.GSD}\nsteps: [save]\n")
    assert errs[0].line == 3 and "ident 0x00CA (from YASK00CA.GSD) is yaskawa-si-p1" in errs[0].message


def test_yaml_syntax_error_names_the_line():
    errs = errors_of(HEAD + "  - write: {param: F07, value: ${x}}\n")
    assert errs[0].line == 5 and "YAML error" in errs[0].message


def test_step_needing_a_parameter_channel_on_a_layout_without_one():
    text = "name: t\nstations:\n  - {address: 6, profile: moeller, layout: ppo3}\nsteps:\n  - read: F002\n"
    errs = errors_of(text)
    assert errs[0].line == 5 and "no parameter channel" in errs[0].message


def test_every_problem_is_listed_not_only_the_first():
    errs = errors_of(HEAD + "  - jump: 1\n  - run: {hz: ten}\n  - write: {param: F07, value: -1}\n")
    assert [e.line for e in errs] == [5, 6, 7]


def test_variables_per_station_overrides_and_var_option():
    text = """\
name: t
variables: {accel: 2.0, code: F07}
stations:
  - {name: a, address: 3, profile: fuji-g1}
  - {name: b, address: 4, profile: fuji-pdp3, variables: {accel: 4.5}}
steps:
  - write: {param: "${code}", value: "${accel}"}
  - note: "accel ${accel} s"
"""
    cl = load_checklist_text(text, "t.yaml")
    a, b = cl.stations
    assert a.steps[0].args["value"] == 2.0 and b.steps[0].args["value"] == 4.5
    assert a.steps[0].args["param"].label == "F07"
    assert b.steps[1].args["text"] == "accel 4.5 s"
    cl = load_checklist_text(text, "t.yaml", parse_var_assignments(["accel=1.5"]))
    assert [s.steps[0].args["value"] for s in cl.stations] == [1.5, 1.5]
    errs = errors_of(text, parse_var_assignments(["acel=1"]))
    assert "acel: the checklist declares no variable of that name (did you mean accel?)" in errs[0].message


def test_a_value_out_of_range_for_one_station_only_names_that_station():
    text = """\
name: t
variables: {fmax: 60}
stations:
  - {name: a, address: 3, profile: fuji-g1}
  - {name: b, address: 4, profile: fuji-pdp3, variables: {fmax: 900}}
steps:
  - write: {param: F03, value: "${fmax}"}
"""
    errs = errors_of(text)
    assert len(errs) == 1 and errs[0].line == 7 and "station 'b'" in errs[0].message


def test_var_assignments_are_typed():
    assert parse_var_assignments(["a=0.5", "b=10", "c=fast", "d="]) == {"a": 0.5, "b": 10, "c": "fast", "d": ""}
    from profidrive_cli import UsageError
    with pytest.raises(UsageError, match="--var 'no-equals': expected NAME=VALUE"):
        parse_var_assignments(["no-equals"])


# =============================================================================================
# the runner on DirectChannel (simulated clock)
# =============================================================================================


def direct_opener(models: dict, trip: dict | None = None):
    """open_station over DirectChannel; the models stay in `models` (by address) for checks afterwards."""
    @contextlib.contextmanager
    def open_station(spec):
        model = models.setdefault(spec.address, make_model(spec.profile))
        ch = DirectChannel(model, spec.profile.layouts[spec.layout].cfg)
        if trip and spec.address in trip:
            model.trip(trip[spec.address], ch.now())
        d = make_drive(ch, spec.profile, spec.layout)
        # no stop on the way out here: what the tests see stopped, the runner stopped
        yield StationHandle(d, {"address": spec.address, "ident": model.ident,
                                "profile": spec.profile.name, "layout": spec.layout, "gsd": None},
                            direct_session(d, spec))
    return open_station


def run_text(text, models=None, **kw):
    cl = load_checklist_text(text, "t.yaml")
    models = {} if models is None else models
    trip = kw.pop("trip", None)
    return Runner(cl, direct_opener(models, trip), **kw).run(), models


def test_wrong_expectation_fails_there_records_the_value_and_leaves_the_drive_stopped():
    res, models = run_text(HEAD + """\
  - write: {param: F07, value: 1.0}
  - run: {hz: 10, duration: 1}
  - read: {param: F07, expect: 5.0}
  - stop
  - note: never
""")
    sr = res.stations[0]
    assert [r.status for r in sr.steps] == [PASSED, PASSED, FAILED, NOT_RUN, NOT_RUN]
    failed = sr.steps[2]
    assert failed.measured["value"] == 1.0 and "expected 5" in failed.message
    assert not res.passed and res.status == "failed"
    assert sr.final_status["stopped"] is True and sr.final_status["running"] is False
    # and the simulated drive agrees, independently of the runner
    m = models[3]
    d = make_drive(DirectChannel(m, b"\xf3\xf1", start=1000.0), sr.spec.profile, "ppo1")
    st = d.status()
    assert not st.running and st.speed_hz == 0.0


def test_a_dangerous_write_runs_only_when_the_step_allows_it():
    cl = load_checklist_text(HEAD + "  - write: {param: P04, value: 2, allow_dangerous: true}\n", "t.yaml")
    step = cl.stations[0].steps[0]
    assert step.args["allow_dangerous"] is True and "dangerous, allowed" in step.title
    res, models = run_text(HEAD + "  - write: {param: P04, value: 2, allow_dangerous: true}\n"
                                  "  - read: {param: P04, expect: 2}\n")
    assert [r.status for r in res.stations[0].steps] == [PASSED, PASSED]


def test_on_fail_continue_goes_on_and_still_fails_the_run():
    res, _ = run_text(HEAD + """\
  - read: {param: F07, expect: 1.0}
    on_fail: continue
  - read: {param: F07, range: [5, 7]}
""")
    assert [r.status for r in res.stations[0].steps] == [FAILED, PASSED]
    assert not res.passed


def test_run_reaches_the_band_in_both_directions_and_measures():
    res, _ = run_text(HEAD + """\
  - write: {param: F07, value: 3.0}
  - write: {param: F08, value: 3.0}
  - run: {hz: 12, duration: 2}
  - run: {hz: 12, direction: reverse, duration: 1}
  - stop: {within: 5}
  - expect_status: {stopped: true, running: false, fault: false}
""")
    steps = res.stations[0].steps
    assert res.passed, [(r.step.index, r.message) for r in steps]
    fwd, rev = steps[2].measured, steps[3].measured
    assert abs(fwd["actual_hz"] - 12) <= 0.5 and abs(rev["actual_hz"] + 12) <= 0.5
    # 3 s to 60 Hz: 12 Hz takes about 0.6 s; reversing passes through standstill first
    assert 0.3 < fwd["reached_after_s"] < 2 and rev["reached_after_s"] > fwd["reached_after_s"]
    assert rev["hold_min"] >= -12.5 and rev["hold_max"] <= -11.5


def test_run_that_cannot_reach_the_speed_in_time_fails_with_the_actual():
    res, _ = run_text(HEAD + "  - run: {hz: 30, within: 0.5}\n")     # default F07 6 s: 30 Hz needs 3 s
    r = res.stations[0].steps[0]
    assert r.status == FAILED and "after 0.5 s" in r.message and r.measured["actual_hz"] < 29
    assert res.stations[0].final_status["stopped"] is True


def test_faults_expect_a_code_and_reset():
    res, _ = run_text(HEAD + """\
  - faults: {expect: OC1}
  - faults: none
    on_fail: continue
  - reset_fault
  - faults: none
  - faults: {expect: OC1, history: true}
""", trip={3: "OC1"})
    st = [r.status for r in res.stations[0].steps]
    assert st == [PASSED, FAILED, PASSED, PASSED, PASSED], [r.message for r in res.stations[0].steps]
    assert "OC1" in res.stations[0].steps[1].message


def test_prompt_needs_an_answer():
    text = HEAD + "  - prompt: Guards closed?\n  - note: after\n"
    res, _ = run_text(text)
    assert res.stations[0].steps[0].status == FAILED and "--yes" in res.stations[0].steps[0].message
    res, _ = run_text(text, yes=True)
    assert res.passed and res.stations[0].steps[0].measured["by"] == "--yes"
    asked = []
    res, _ = run_text(text, ask=lambda q: asked.append(q) or False)
    assert asked == ["Guards closed?"] and res.stations[0].steps[0].message == "the operator answered no"
    res, _ = run_text(text, ask=lambda q: True)
    assert res.passed


def test_station_that_cannot_be_opened_is_an_error_and_stops_the_checklist():
    text = """\
name: t
stations:
  - {name: a, address: 3, profile: fuji-g1}
  - {name: b, address: 4, profile: fuji-pdp3}
steps:
  - note: hello
"""
    from profidrive_cli import BusError
    cl = load_checklist_text(text, "t.yaml")

    @contextlib.contextmanager
    def absent(spec):
        raise BusError(f"station {spec.address} does not answer")
        yield

    res = Runner(cl, absent).run()
    a, b = res.stations
    assert a.status == "error" and "does not answer" in a.error
    assert b.status == NOT_RUN and not res.passed
    # on_fail: continue in the header: the next station is tried all the same
    res = Runner(load_checklist_text("on_fail: continue\n" + text, "t.yaml"), absent).run()
    assert [s.status for s in res.stations] == ["error", "error"] and not res.passed
