"""The checklist step checks (checklist/fields.py, steps/run.py, read.py, write.py, expect_status.py):
what each field accepts and refuses (file:line), the titles, and what execution measures, passes and
fails, on the simulated Fuji FRENIC (station 3, PPO1) over DirectChannel (simulated clock).

Expected values are the profile's (profiles/fuji-opc-g1-pdp.yaml, from the Fuji manuals: F03
maximum frequency 25..500 Hz in 0.1 Hz steps, default 60 Hz; F07/F08 0..6000 s in 0.1 s steps;
W90 read-only; P04 auto-tuning dangerous) and docs/checklists.md (run: tolerance 0.5 Hz / 1 % and
within 10 s by default; read: exact to half a step without tolerance). Written for mutation testing
(tools/mutation/run.py checklist/...).
"""

import contextlib
import re

import pytest

from profidrive_cli.checklist.fields import (FieldChecker, ParamTarget, fmt, is_num, line_at,
                                             param_layouts, range_problem, tname)
from profidrive_cli.checklist.runner import FAILED, PASSED, Runner, StationHandle
from direct_session import direct_session
from profidrive_cli.checklist.spec import ChecklistError, load_checklist_text
from profidrive_cli.datafile import LineDict, LineList
from profidrive_cli.drives import make_drive
from profidrive_cli.drives.profile import load_profile
from profidrive_cli.sim.direct import DirectChannel
from profidrive_cli.sim.plant import make_model

HEAD = """\
name: t
stations:
  - {name: c1, address: 3, profile: fuji-g1}
steps:
"""
FIRST = 5          # the line of the first step after HEAD


def errors_of(steps):
    with pytest.raises(ChecklistError) as ei:
        load_checklist_text(HEAD + steps, "t.yaml")
    return [str(e) for e in ei.value.errors]


def steps_of(steps):
    return load_checklist_text(HEAD + steps, "t.yaml").stations[0].steps


def run_text(steps, disturb=None, trip=None, transform=None, observer=None, prepare=None, session=None):
    """Run on the simulated drive; `transform(status)` may rewrite every status the drive reports
    (a family that reports differently), `observer` gets the runner's progress."""
    cl = load_checklist_text(HEAD + steps, "t.yaml")

    @contextlib.contextmanager
    def open_station(spec):
        model = make_model(spec.profile)
        ch = DirectChannel(model, spec.profile.layouts[spec.layout].cfg)
        if trip:
            model.trip(trip, ch.now())
        if disturb is not None:
            disturb(model)
        d = make_drive(ch, spec.profile, spec.layout)
        if transform is not None:
            for name in ("cycle", "status"):
                real = getattr(d, name)
                setattr(d, name, lambda real=real: transform(real()))
        if prepare is not None:
            prepare(d)
        yield StationHandle(d, {"address": spec.address, "ident": model.ident,
                                "profile": spec.profile.name, "layout": spec.layout, "gsd": None},
                            session(d) if session is not None else direct_session(d, spec))
    kw = {"observer": observer, "progress_interval": 0.0} if observer is not None else {}
    return Runner(cl, open_station, **kw).run().stations[0].steps


RAMPS = "  - write: {param: F07, value: 1.0}\n  - write: {param: F08, value: 1.0}\n"   # 1 s to 60 Hz


# -- fields.py: the toolkit ------------------------------------------------------------------------

def test_tname_is_num_fmt():
    assert [tname(v) for v in (True, 3, 2.5, "x", [1], {"a": 1}, None, b"x")] == [
        "true/false", "a number", "a number", "text", "a list", "a mapping", "nothing", "bytes"]
    assert is_num(3) and is_num(-2.5) and not is_num(True) and not is_num("3")
    assert not is_num(float("nan")) and not is_num(float("inf"))
    assert fmt(2.50) == "2.5" and fmt(3) == "3" and fmt(1e-7) == "1e-07" and fmt("a") == "a"


def test_line_at():
    d = LineDict({"a": 1})
    d.line, d.key_lines = 4, {"a": 6}
    assert line_at(d, "a") == 6 and line_at(d) == 4
    lst = LineList([1, 2])
    lst.line, lst.item_lines = 9, [10, 11]
    assert line_at(lst, 1) == 11 and line_at(lst) == 9
    assert line_at(object(), default=7) == 7 and line_at(object()) == 0


def test_step_tolerance_is_half_a_wire_step():
    f08 = load_profile("fuji-opc-g1-pdp").param("F08")          # 0.1 s steps
    assert ParamTarget("F08", "F08", f08).step_tolerance == pytest.approx(0.05, abs=1e-8)
    assert ParamTarget("F08", "F08", f08).step_tolerance > 0.05
    assert ParamTarget("REG0x0100", "REG0x0100").step_tolerance == pytest.approx(1e-9)


def test_field_checker_records_each_problem_once():
    c = FieldChecker("t.yaml")
    c.err(3, "x")
    c.err(3, "x")
    c.err(4, "x")
    assert [str(e) for e in c.errors] == ["t.yaml:3: x", "t.yaml:4: x"]


def test_unknown_key_suggests_or_lists():
    c = FieldChecker("t.yaml")
    assert c.unknown_key("tolerence", ("hz", "tolerance"), "field") == \
        "unknown field 'tolerence' (did you mean tolerance?)"
    assert c.unknown_key("zz", ("hz", "tolerance"), "field") == "unknown field 'zz' (known: hz, tolerance)"


def test_range_problem_min_max_and_moeller_ranges():
    fuji = load_profile("fuji-opc-g1-pdp")
    f03 = fuji.param("F03")
    assert range_problem(f03, 25.0) is None and range_problem(f03, 500.0) is None
    assert range_problem(f03, 24.9) == "F03 (Maximum frequency 1 (100 % of MRV/MAV)): 24.9 Hz is outside 25..500 Hz"
    assert range_problem(f03, 500.1) is not None
    moeller = load_profile("moeller-de6-net-dp")
    b096 = moeller.param("b096")                   # two ranges: 330..380 V and 660..760 V
    assert range_problem(b096, 330) is None and range_problem(b096, 380) is None
    assert range_problem(b096, 700) is None
    assert range_problem(b096, 500) == "b096 (On level of BRD): 500 V is outside 330..380, 660..760 V"
    b031 = moeller.param("b031")                   # [0, 3] and the single value 10
    assert range_problem(b031, 5) == ("b031 (Selection of method of software lock): 5 is outside "
                                      "0..3, 10")


def test_param_layouts_lists_those_with_a_channel():
    fuji = load_profile("fuji-opc-g1-pdp")
    names = param_layouts(fuji).split(", ")
    assert names and all(fuji.layouts[n].pkw for n in names)
    assert set(names) == {n for n, lay in fuji.layouts.items() if lay.pkw}


# -- step fields (spec validation through each step type) ------------------------------------------

BAD = [
    ("  - run: {hz: 10, percent: 20}\n", f"t.yaml:{FIRST}: step 1 (run): give the speed as either hz or percent"),
    ("  - run: {direction: forward}\n", f"t.yaml:{FIRST}: step 1 (run): give the speed as either hz or percent"),
    ("  - run: {hz: 0}\n", f"t.yaml:{FIRST}: step 1 (run): 'hz' must be above 0, got 0"),
    ("  - run: {hz: 10, direction: up}\n", f"t.yaml:{FIRST}: step 1 (run): direction must be forward or reverse, got 'up'"),
    ("  - run: {percent: 100.5}\n", f"t.yaml:{FIRST}: step 1 (run): percent 100.5 is above 100 (the max frequency)"),
    ("  - run: {hz: 500.5}\n", f"t.yaml:{FIRST}: step 1 (run): 500.5 Hz is above what fuji-opc-g1-pdp can run (F03 max 500 Hz)"),
    ("  - run: {hz: 10, duration: -1}\n", f"t.yaml:{FIRST}: step 1 (run): 'duration' must be at least 0, got -1"),
    ("  - run: {hz: 10, tolerance: 0}\n", f"t.yaml:{FIRST}: step 1 (run): 'tolerance' must be above 0, got 0"),
    ("  - run: {hz: 10, within: 0}\n", f"t.yaml:{FIRST}: step 1 (run): 'within' must be above 0, got 0"),
    ("  - run: {hz: 10, speed: 3}\n", f"t.yaml:{FIRST}: step 1 (run): unknown field 'speed' (known: hz, percent, direction, duration, tolerance, within, together)"),
    ("  - run: [10]\n", f"t.yaml:{FIRST}: step 1 (run): expected a mapping with hz, percent, direction, duration, tolerance, within, together, got a list"),
    ("  - read: {param: F07, range: [2, 1]}\n", f"t.yaml:{FIRST}: step 1 (read): 'range' must be [low, high] with low <= high, got [2, 1]"),
    ("  - read: {param: F07, range: [1, 2, 3]}\n", f"t.yaml:{FIRST}: step 1 (read): 'range' must be [low, high] with low <= high, got [1, 2, 3]"),
    ("  - read: {param: F07, range: [1, x]}\n", f"t.yaml:{FIRST}: step 1 (read): 'range' must be [low, high] with low <= high, got [1, 'x']"),
    ("  - read: {param: F07, range: 3}\n", f"t.yaml:{FIRST}: step 1 (read): 'range' must be [low, high] with low <= high, got 3"),
    ("  - read: {param: F07, range: [1, 2], min: 0}\n", f"t.yaml:{FIRST}: step 1 (read): give either range or min/max, not both"),
    ("  - read: {param: F07, range: [1, 2], max: 3}\n", f"t.yaml:{FIRST}: step 1 (read): give either range or min/max, not both"),
    ("  - read: {param: F07, expect: 1, min: 0}\n", f"t.yaml:{FIRST}: step 1 (read): give either expect (with tolerance) or a range, not both"),
    ("  - read: {param: F07, expect: 1, max: 3}\n", f"t.yaml:{FIRST}: step 1 (read): give either expect (with tolerance) or a range, not both"),
    ("  - read: {param: F07, tolerance: 1}\n", f"t.yaml:{FIRST}: step 1 (read): tolerance needs expect"),
    ("  - read: {param: F07, expect: 1, tolerance: -0.1}\n", f"t.yaml:{FIRST}: step 1 (read): 'tolerance' must be at least 0, got -0.1"),
    ("  - read: {param: F07, min: 3, max: 2}\n", f"t.yaml:{FIRST}: step 1 (read): min 3 is above max 2"),
    ("  - read: {param: F03, expect: 600}\n", f"t.yaml:{FIRST}: step 1 (read): expected value can never be read: F03 (Maximum frequency 1 (100 % of MRV/MAV)): 600 Hz is outside 25..500 Hz"),
    ("  - read: {param: true}\n", f"t.yaml:{FIRST}: step 1 (read): 'param' must be a parameter code, got true/false"),
    ("  - read: {expect: 3}\n", f"t.yaml:{FIRST}: step 1 (read): missing field 'param'"),
    ("  - write: {param: W90, value: 1}\n", f"t.yaml:{FIRST}: step 1 (write): W90 (PROFIBUS card software version (V1.23 reads 123)) is read-only"),
    ("  - write: {param: F07, value: 1, allow_dangerous: 1}\n", f"t.yaml:{FIRST}: step 1 (write): 'allow_dangerous' must be true or false, got 1"),
    ("  - write: {param: F07}\n", f"t.yaml:{FIRST}: step 1 (write): missing field 'value'"),
    ("  - write: {param: F07, value: x}\n", f"t.yaml:{FIRST}: step 1 (write): 'value' must be a number, got text 'x'"),
    ("  - run: {hz: 10}\n  - write: {param: F03, value: 50}\n", f"t.yaml:{FIRST + 1}: step 2 (write): F03 can only be changed while the motor is stopped, and an earlier run step leaves it running; put a stop step before it"),
    ("  - expect_status: {}\n", f"t.yaml:{FIRST}: step 1 (expect_status): expected a mapping of status flags to true/false, e.g. {{running: false, fault: false}}"),
    ("  - expect_status: running\n", f"t.yaml:{FIRST}: step 1 (expect_status): expected a mapping of status flags to true/false, e.g. {{running: false, fault: false}}"),
    ("  - expect_status: {state: 3}\n", f"t.yaml:{FIRST}: step 1 (expect_status): 'state' must be text (part of the state name), got a number"),
    ("  - expect_status: {running: true, within: -1}\n", f"t.yaml:{FIRST}: step 1 (expect_status): 'within' must be a number of seconds >= 0, got -1"),
    ("  - expect_status: {running: true, within: x}\n", f"t.yaml:{FIRST}: step 1 (expect_status): 'within' must be a number of seconds >= 0, got 'x'"),
    ("  - expect_status: {running: 1}\n", f"t.yaml:{FIRST}: step 1 (expect_status): flag 'running' must be true or false, got a number 1"),
    ("  - expect_status: {within: 2}\n", f"t.yaml:{FIRST}: step 1 (expect_status): nothing to check (name flags, or state)"),
    ("  - expect_status: {runing: true}\n", f"t.yaml:{FIRST}: step 1 (expect_status): fuji-opc-g1-pdp has no status flag 'runing' (did you mean 'running'?)"),
]


@pytest.mark.parametrize("steps,error", BAD, ids=[b[1][12:60] for b in BAD])
def test_step_field_errors(steps, error):
    assert error in errors_of(steps)


def test_an_unknown_flag_far_from_every_name_lists_them():
    errs = errors_of("  - expect_status: {qqqqqqqq: true}\n")
    assert len(errs) == 1
    assert errs[0].startswith(f"t.yaml:{FIRST}: step 1 (expect_status): fuji-opc-g1-pdp has no status "
                              f"flag 'qqqqqqqq' (flags: running, fault, stopped, ")


def test_every_bad_flag_is_reported_not_only_the_first():
    errs = errors_of("  - expect_status: {running: 1, fault: 2}\n")
    assert len(errs) == 2


def test_a_fault_alarm_name_is_accepted_as_a_flag():
    s = steps_of("  - expect_status: {'fault: OC1': false}\n")[0]
    assert s.args["flags"] == {"fault: OC1": False}


def test_run_args_and_titles():
    s = steps_of("  - run: {hz: 10}\n"
                 "  - run: {percent: 20, direction: reverse, duration: 3, tolerance: 2, within: 15}\n"
                 "  - run: {percent: 100}\n"
                 "  - run: {hz: 500}\n")
    assert s[0].args == {"unit": "hz", "speed": 10, "direction": "forward", "duration": 0.0,
                         "tolerance": 0.5, "within": 10.0}
    assert s[0].title == "run forward at 10 Hz (± 0.5 Hz within 10 s)"
    assert s[1].args == {"unit": "percent", "speed": 20, "direction": "reverse", "duration": 3,
                         "tolerance": 2, "within": 15}
    assert s[1].title == "run reverse at 20 % (± 2 % within 15 s), hold 3 s"
    assert s[2].args["tolerance"] == 1.0 and s[2].title == "run forward at 100 % (± 1 % within 10 s)"
    assert s[3].args["speed"] == 500


def test_read_args_and_titles():
    s = steps_of("  - read: F07\n"
                 "  - read: {param: F07, expect: 3}\n"
                 "  - read: {param: F07, expect: 3, tolerance: 0.5}\n"
                 "  - read: {param: F07, range: [1, 2]}\n"
                 "  - read: {param: F07, min: 1}\n"
                 "  - read: {param: F07, max: 2}\n"
                 "  - read: {param: F07, min: 2, max: 2}\n"
                 "  - read: {param: PNU918}\n"
                 "  - read: {param: F03, expect: 500}\n")
    assert [x.title for x in s] == ["read F07", "read F07, expect 3 s", "read F07, expect 3 s ± 0.5",
                                    "read F07, expect 1..2 s", "read F07, expect >= 1 s",
                                    "read F07, expect <= 2 s", "read F07, expect 2..2 s",
                                    "read PNU918", "read F03, expect 500 Hz"]
    a = s[3].args
    assert (a["expect"], a["tolerance"], a["min"], a["max"]) == (None, None, 1, 2)
    a = s[2].args
    assert (a["expect"], a["tolerance"], a["min"], a["max"]) == (3, 0.5, None, None)
    assert s[0].args["param"].label == "F07" and s[0].args["param"].unit == "s"


def test_write_args_and_titles():
    s = steps_of("  - write: {param: F07, value: 2.5}\n"
                 "  - write: {param: P04, value: 2, allow_dangerous: true}\n"
                 "  - write: {param: F08, value: 1, allow_dangerous: true}\n")
    assert s[0].title == "write F07 = 2.5 s" and s[0].args["allow_dangerous"] is False
    assert s[1].title == "write P04 = 2 (dangerous, allowed)" and s[1].args["allow_dangerous"] is True
    assert s[2].title == "write F08 = 1 s"


def test_a_dangerous_write_without_permission_is_refused_with_the_reason():
    errs = errors_of("  - write: {param: P04, value: 2}\n")
    assert len(errs) == 1
    assert errs[0].startswith(f"t.yaml:{FIRST}: step 1 (write): P04 (Motor 1 auto-tuning (runs the motor "
                              f"whatever the PROFIdrive state)) is dangerous: writing it ")
    assert errs[0].endswith("; add 'allow_dangerous: true' to the step to write it")


def test_stop_only_write_before_any_run_is_fine():
    assert steps_of("  - write: {param: F03, value: 50}\n")[0].title == "write F03 = 50 Hz"


def test_expect_status_args_and_title():
    s = steps_of("  - expect_status: {running: false, FAULT: false, state: S2, within: 2}\n"
                 "  - expect_status: {state: S4}\n")
    assert s[0].args == {"flags": {"running": False, "fault": False}, "state": "S2", "within": 2.0}
    assert s[0].title == "status: state ~ 'S2', running = no, fault = no"
    assert s[1].args == {"flags": {}, "state": "S4", "within": 0.0}
    assert s[1].title == "status: state ~ 'S4'"


# -- execution: run --------------------------------------------------------------------------------

def test_run_passes_and_measures_in_hz():
    steps = run_text(RAMPS + "  - run: {hz: 12, duration: 2}\n  - stop\n")
    r = steps[2]
    assert r.status == PASSED, r.message
    assert r.expected == {"speed": 12.0, "unit": "Hz", "tolerance": 0.5, "within_s": 10.0, "hold_s": 2}
    m = r.measured
    assert set(m) == {"actual_hz", "reached_after_s", "state", "speed_hz", "speed_percent",
                      "hold_min", "hold_max"}
    assert m["actual_hz"] == pytest.approx(12, abs=0.05)
    assert m["speed_percent"] == pytest.approx(20, abs=0.1)          # 12 of 60 Hz
    assert 11.5 <= m["hold_min"] <= m["hold_max"] <= 12.5
    # 1 s to 60 Hz: 11.5 Hz (the band's edge) is reached after 11.5 / 60 s = 0.19 s
    assert 0.15 <= m["reached_after_s"] <= 0.5
    assert m["reached_after_s"] == round(m["reached_after_s"], 3)       # ms in the report
    assert re.fullmatch(r"within ± 0\.5 Hz of 12 Hz after \d\.\d\d s, held 2 s at 1[12](\.\d+)?\.\.1[12](\.\d+)? Hz; "
                        r"1[12](\.\d+)? Hz at the end", r.message), r.message


def test_run_in_percent_reverse():
    steps = run_text(RAMPS + "  - run: {percent: 25, direction: reverse}\n  - stop\n")
    r = steps[2]
    assert r.status == PASSED, r.message
    assert r.expected == {"speed": -25.0, "unit": "%", "tolerance": 1.0, "within_s": 10.0, "hold_s": 0.0}
    assert set(r.measured) == {"actual_percent", "reached_after_s", "state", "speed_hz", "speed_percent",
                               "hold_min", "hold_max"}
    assert r.measured["hold_min"] == r.measured["hold_max"] == r.measured["actual_percent"]   # no hold
    assert r.measured["actual_percent"] == pytest.approx(-25, abs=1.0)
    assert r.measured["speed_hz"] == pytest.approx(-15, abs=0.6)     # 25 % of 60 Hz, reverse
    assert re.fullmatch(r"within ± 1 % of -25 % after \d\.\d\d s; -2[456](\.\d+)? % at the end", r.message), r.message


def test_run_not_reached_in_time_fails_with_the_actual():
    # default F07 6 s to 60 Hz: after 0.5 s the drive is near 5 Hz, far from 30 Hz
    steps = run_text("  - run: {hz: 30, within: 0.5}\n")
    r = steps[0]
    assert r.status == FAILED
    assert re.fullmatch(r"actual \d(\.\d+)? Hz after 0\.5 s, expected 30 Hz ± 0\.5", r.message), r.message
    assert r.measured["reached_after_s"] is None and r.measured["actual_hz"] < 10
    assert "hold_min" not in r.measured


def test_run_on_a_tripped_drive_fails_with_the_fault():
    steps = run_text("  - run: {hz: 10}\n", trip="OC1")
    r = steps[0]
    assert r.status in (FAILED, "error")
    assert "OC1" in r.message or "fault" in r.message.lower()


def trips_after(seconds, alarm="OC2"):
    def disturb(model):
        real_tick = model.tick
        t0 = {}

        def tick(now):
            real_tick(now)
            t0.setdefault("t", now)
            if now - t0["t"] >= seconds and not getattr(model, "_tripped_here", False):
                model._tripped_here = True
                model.trip(alarm, now)
        model.tick = tick
    return disturb


def test_run_tripping_while_holding_fails_and_records_the_code():
    steps = run_text(RAMPS + "  - run: {hz: 10, duration: 30}\n", disturb=trips_after(5.0))
    r = steps[2]
    assert r.status == FAILED
    assert r.message.startswith("the drive tripped while running (")
    assert "fault_code" in r.measured and "hold_min" in r.measured
    assert r.measured["reached_after_s"] is not None


def test_run_tripping_while_accelerating_fails():
    steps = run_text("  - run: {hz: 50, within: 20}\n", disturb=trips_after(1.0))
    r = steps[0]
    assert r.status == FAILED
    assert r.message.startswith("the drive tripped while accelerating (")
    assert "fault_code" in r.measured and r.measured["reached_after_s"] is None
    assert "hold_min" not in r.measured


def test_a_reversal_counts_only_after_standstill():
    steps = run_text(RAMPS + "  - run: {hz: 30}\n  - run: {hz: 30, direction: reverse}\n  - stop\n")
    fwd, rev = steps[2], steps[3]
    assert fwd.status == PASSED and rev.status == PASSED, rev.message
    # 1 s ramps over 60 Hz: from +30 through 0 to -29.5 Hz takes (30 + 29.5) / 60 = 0.99 s
    assert rev.measured["reached_after_s"] >= 0.9
    assert rev.measured["actual_hz"] == pytest.approx(-30, abs=0.5)


def test_a_reversal_within_the_band_of_zero_is_no_reversal():
    # from +0.3 Hz to -0.3 Hz with a 0.5 Hz band: already within the band, no crossing needed
    steps = run_text(RAMPS + "  - run: {hz: 0.3, tolerance: 0.5}\n"
                     "  - run: {hz: 0.3, direction: reverse, tolerance: 0.5}\n  - stop\n")
    assert steps[2].status == PASSED and steps[3].status == PASSED
    assert steps[3].measured["reached_after_s"] < 0.1


# -- execution: read -------------------------------------------------------------------------------

def read_after_write(value, read):
    return run_text(f"  - write: {{param: F07, value: {value}}}\n  - read: {read}\n")[1]


def test_read_records_the_value_and_raw():
    r = read_after_write(3.0, "F07")
    assert r.status == PASSED and r.message == "F07 = 3 s"
    assert r.measured == {"param": "F07", "value": 3.0, "unit": "s", "raw": 30}   # 0.1 s steps
    assert r.expected == {}


def test_read_expect_without_tolerance_is_half_a_step():
    r = read_after_write(3.0, "{param: F07, expect: 3.04}")
    assert r.status == PASSED
    assert r.expected == {"value": 3.04, "tolerance": 0, "unit": "s"}
    r = read_after_write(3.0, "{param: F07, expect: 3.06}")
    assert r.status == FAILED and r.message == "F07 = 3 s, expected 3.06 s"
    r = read_after_write(3.0, "{param: F07, expect: 2.94}")
    assert r.status == FAILED


def test_read_expect_with_tolerance():
    r = read_after_write(3.0, "{param: F07, expect: 3.5, tolerance: 0.4}")
    assert r.status == FAILED and r.message == "F07 = 3 s, expected 3.5 s ± 0.4"
    assert r.expected == {"value": 3.5, "tolerance": 0.4, "unit": "s"}
    r = read_after_write(3.0, "{param: F07, expect: 2.6, tolerance: 0.4}")
    assert r.status == PASSED


def test_read_tolerance_zero_means_half_a_step_too():
    # tolerance: 0 is allowed (at least 0) and is not "no tolerance": the check is then exact
    r = read_after_write(3.0, "{param: F07, expect: 3.04, tolerance: 0}")
    assert r.status == FAILED and r.message == "F07 = 3 s, expected 3.04 s"


@pytest.mark.parametrize("read,status,message", [
    ("{param: F07, range: [3, 4]}", PASSED, "F07 = 3 s"),             # the low edge is inside
    ("{param: F07, range: [2, 3]}", PASSED, "F07 = 3 s"),             # the high edge is inside
    ("{param: F07, range: [3.1, 4]}", FAILED, "F07 = 3 s, expected 3.1..4 s"),
    ("{param: F07, range: [1, 2.9]}", FAILED, "F07 = 3 s, expected 1..2.9 s"),
    ("{param: F07, min: 3.1}", FAILED, "F07 = 3 s, expected 3.1..inf s"),
    ("{param: F07, max: 2.9}", FAILED, "F07 = 3 s, expected -inf..2.9 s"),
    ("{param: F07, min: 3}", PASSED, "F07 = 3 s"),
    ("{param: F07, max: 3}", PASSED, "F07 = 3 s"),
])
def test_read_range(read, status, message):
    r = read_after_write(3.0, read)
    assert (r.status, r.message) == (status, message)
    lo = re.search(r"min: ([\d.]+)", read)
    if "range" in read or lo or "max" in read:
        assert r.expected["unit"] == "s" and set(r.expected) == {"min", "max", "unit"}


# -- execution: write ------------------------------------------------------------------------------

def test_write_measures_before_written_and_read_back():
    steps = run_text("  - write: {param: F07, value: 2.5}\n  - write: {param: F07, value: 2.5}\n")
    r = steps[0]
    assert r.status == PASSED
    assert r.expected == {"value": 2.5, "unit": "s"}
    assert r.measured == {"param": "F07", "before": 6.0, "written": 2.5, "read_back": 2.5, "unit": "s",
                          "raw": 25}                                  # the default 6 s; 0.1 s steps
    assert r.message == "F07 = 2.5 s (read back; was 6 s)"
    assert steps[1].message == "F07 = 2.5 s (read back; unchanged)"


# -- execution: expect_status ----------------------------------------------------------------------

def test_expect_status_stopped_drive():
    r = run_text("  - expect_status: {stopped: true, running: false, fault: false}\n")[0]
    assert r.status == PASSED
    assert r.expected == {"stopped": True, "running": False, "fault": False}
    assert r.measured["stopped"] is True and r.measured["running"] is False
    assert r.measured["fault"] is False and r.measured["fault_code"] is None
    assert r.message == f"state {r.measured['state']}"


def test_expect_status_mismatch_says_each_flag():
    r = run_text("  - expect_status: {running: true, fault: true, stopped: true}\n")[0]
    assert r.status == FAILED
    assert r.message == "running is no, expected yes; fault is no, expected yes"


def test_expect_status_state_mismatch():
    r = run_text("  - expect_status: {state: S4, running: true}\n")[0]
    assert r.status == FAILED
    st = r.measured["state"]
    assert r.message == f"state {st!r}, expected 'S4'; running is no, expected yes"
    assert r.expected == {"running": True, "state": "S4"}


def test_expect_status_state_is_matched_case_blind():
    r = run_text("  - expect_status: {state: s1 SWITCHING}\n")[0]      # "S1 switching on inhibited"
    assert r.status == PASSED, r.message


def test_expect_status_within_waits_for_the_flags():
    # 1 s ramp to 60 Hz: running at 30 Hz is reached after about 0.5 s; without `within` the
    # first read after the start command can still show the ramp, with 5 s it must pass
    steps = run_text(RAMPS + "  - run: {hz: 30}\n  - expect_status: {running: true, stopped: false, within: 5}\n"
                     "  - stop\n  - expect_status: {running: false, stopped: true, within: 5}\n")
    assert [s.status for s in steps] == [PASSED] * 6, [s.message for s in steps]


def test_expect_status_family_flag_and_fault():
    steps = run_text("  - expect_status: {fault: true, running: false}\n", trip="OC1")
    assert steps[0].status == PASSED, steps[0].message
    assert steps[0].measured["fault_code"] == "OC1"


# -- run: more of what the reports and the checks rest on ---------------------------------------------

def block(step_lines):
    return "".join(f"  {x}\n" for x in step_lines)


@pytest.mark.parametrize("lines,bad_line,words", [
    (["- run:", "    hz: 10", "    direction: up"], FIRST + 2, "direction must be forward or reverse"),
    (["- run:", "    tolerance: 1", "    percent: 101"], FIRST + 2, "percent 101 is above 100"),
    (["- run:", "    within: 5", "    hz: 600"], FIRST + 2, "600 Hz is above what fuji-opc-g1-pdp can run"),
])
def test_run_errors_point_at_the_key_in_block_style(lines, bad_line, words):
    errs = errors_of(block(lines))
    assert any(e.startswith(f"t.yaml:{bad_line}: ") and words in e for e in errs), errs


def unsigned(st):
    """A drive that reports the commanded direction with the speed's magnitude."""
    if st.reference_percent and st.speed_hz is not None:
        sign = 1.0 if st.reference_percent > 0 else -1.0
        st.speed_hz = sign * abs(st.speed_hz)
        st.speed_percent = sign * abs(st.speed_percent)
    return st


def test_a_reversal_on_a_drive_reporting_the_commanded_sign_waits_for_standstill():
    # with a wide band (± 6 Hz) the first samples of the reversal (-29.x Hz .. -24 Hz: the
    # magnitude, signed like the command) are already "in the band"; the speed must first pass
    # standstill: 1 s ramps from +30 through 0 to -24 Hz take (30 + 24) / 60 = 0.9 s
    steps = run_text(RAMPS + "  - run: {hz: 30}\n  - run: {hz: 30, direction: reverse, tolerance: 6}\n"
                     "  - stop\n", transform=unsigned)
    rev = steps[3]
    assert rev.status == PASSED, rev.message
    assert rev.measured["reached_after_s"] >= 0.8


@pytest.mark.parametrize("first,second", [(10, 20), (20, 10), (0.8, 1.2)])
def test_a_speed_change_in_the_same_direction_needs_no_standstill(first, second):
    steps = run_text(RAMPS + f"  - run: {{hz: {first}}}\n  - run: {{hz: {second}, within: 3}}\n  - stop\n")
    assert steps[3].status == PASSED, steps[3].message
    # 1 s to 60 Hz: the change takes |second - first| / 60 s (well under 1 s), no stop on the way
    assert steps[3].measured["reached_after_s"] < 0.5


def no_hz(st):
    """A drive that reports only % of the max frequency."""
    st.speed_hz = None
    return st


def test_run_in_hz_on_a_drive_that_reports_percent_only():
    steps = run_text(RAMPS + "  - run: {hz: 12}\n  - stop\n", transform=no_hz)
    r = steps[2]
    assert r.status == PASSED, r.message
    assert r.measured["actual_hz"] == pytest.approx(12, abs=0.01)      # 20 % of F03 = 60 Hz: 12 Hz


def clamp_at(hz):
    """The motor cannot go faster than `hz` (a load that holds it)."""
    def disturb(model):
        real_tick = model.tick

        def tick(now):
            real_tick(now)
            model.freq = min(model.freq, hz)
        model.tick = tick
    return disturb


def test_the_band_edge_counts_as_reached():
    # 15 Hz is 4096 counts of 16384 = 60 Hz exactly; 0.9375 Hz is 256 counts: a speed held at exactly
    # 14.0625 Hz is on the edge of 15 ± 0.9375, inside
    steps = run_text(RAMPS + "  - run: {hz: 15, tolerance: 0.9375, within: 3}\n  - stop\n",
                     disturb=clamp_at(14.0625))
    assert steps[2].status == PASSED, steps[2].message
    assert steps[2].measured["actual_hz"] == 14.062                   # reported to 3 decimals


def drift_to(target, offset, after_s=0.5, for_s=2.0):
    def disturb(model):
        real_tick = model.tick
        seen = {}

        def tick(now):
            real_tick(now)
            if "at" not in seen and abs(model.freq - target) < 0.05:
                seen["at"] = now
            if "at" in seen and after_s <= now - seen["at"] < after_s + for_s:
                model.freq = target + offset
        model.tick = tick
    return disturb


def test_the_band_edge_while_holding_is_inside():
    steps = run_text(RAMPS + "  - run: {hz: 15, tolerance: 0.9375, duration: 3}\n  - stop\n",
                     disturb=drift_to(15, -0.9375))
    r = steps[2]
    assert r.status == PASSED, r.message
    assert r.measured["hold_min"] == 14.062


def test_leaving_the_band_while_holding_reports_what_and_where():
    steps = run_text(RAMPS + "  - run: {hz: 20, tolerance: 0.5, duration: 3}\n  - stop\n",
                     disturb=drift_to(20, -1.0))
    r = steps[2]
    assert r.status == FAILED
    # 19 Hz on the wire: round(19 / 60 * 16384) = 5188 counts = 18.999 Hz
    assert r.message == "actual left the band: 18.999 Hz while holding 20 Hz ± 0.5"
    m = r.measured
    assert m["actual_hz"] == pytest.approx(19, abs=0.01) and m["hold_min"] == pytest.approx(19, abs=0.01)
    assert m["hold_max"] == pytest.approx(20, abs=0.05) and m["reached_after_s"] is not None


def named_fault(st):
    """A family whose cyclic status names the fault."""
    if st.fault:
        st.fault_code = "OC2"
    return st


def test_a_trip_while_holding_names_the_fault_and_keeps_the_measurements():
    steps = run_text(RAMPS + "  - run: {hz: 10, duration: 30}\n", disturb=trips_after(5.0),
                     transform=named_fault)
    r = steps[2]
    assert r.status == FAILED and r.message == "the drive tripped while running (OC2)"
    m = r.measured
    assert m["fault_code"] == "OC2" and m["actual_hz"] is not None
    assert m["hold_min"] is not None and m["hold_max"] is not None and m["reached_after_s"] is not None


def test_a_trip_without_a_code_names_the_state():
    steps = run_text(RAMPS + "  - run: {hz: 10, duration: 30}\n", disturb=trips_after(5.0))
    r = steps[2]
    assert r.message == f"the drive tripped while running ({r.measured['state']})"
    steps = run_text("  - run: {hz: 50, within: 20}\n", disturb=trips_after(1.0))
    r = steps[0]
    assert r.message == f"the drive tripped while accelerating ({r.measured['state']})"
    assert "actual_hz" in r.measured and r.measured["actual_hz"] is not None


class Progress:
    def __init__(self):
        self.seen = []

    def __getattr__(self, name):
        return lambda *a: None

    def step_progress(self, station, result, text):
        self.seen.append((station, result, text))


def test_run_progress_says_accelerating_then_holding():
    obs = Progress()
    steps = run_text(RAMPS + "  - run: {hz: 12, duration: 2}\n  - stop\n", observer=obs)
    texts = [t for _, r, t in obs.seen if r is steps[2]]
    assert all(sr is not None and r is not None for sr, r, _ in obs.seen)
    acc = [t for t in texts if t.startswith("accelerating")]
    hold = [t for t in texts if t.startswith("holding")]
    assert acc and all(re.fullmatch(r"accelerating: -?\d+(\.\d+)? Hz -> 12 Hz", t) for t in acc), acc
    assert acc[0] == "accelerating: 0 Hz -> 12 Hz"
    assert hold and all(re.fullmatch(r"holding 1[12](\.\d+)? Hz \(\d\.\d s left\)", t) for t in hold), hold
    assert hold[-1].endswith("(0.0 s left)") and hold[0].endswith("(2.0 s left)") or \
        hold[0].endswith("(1.9 s left)")


# -- read: block-style lines, a one-value range, unitless parameters -----------------------------------

@pytest.mark.parametrize("lines,bad_line,words", [
    (["- read:", "    param: F07", "    range: [2, 1]"], FIRST + 2, "'range' must be [low, high]"),
    (["- read:", "    param: F07", "    min: 0", "    range: [1, 2]"], FIRST + 3, "give either range or min/max"),
    (["- read:", "    param: F07", "    range: [1, 2]", "    expect: 1"], FIRST + 3, "give either expect"),
    (["- read:", "    param: F07", "    expect: 1", "    tolerance: 0.5", "    min: 0"], FIRST + 2, "give either expect"),
    (["- read:", "    param: F07", "    tolerance: 1"], FIRST + 2, "tolerance needs expect"),
    (["- read:", "    param: F07", "    max: 2", "    min: 3"], FIRST + 3, "min 3 is above max 2"),
    (["- read:", "    param: F03", "    expect: 600"], FIRST + 2, "expected value can never be read"),
])
def test_read_errors_point_at_the_key_in_block_style(lines, bad_line, words):
    errs = errors_of(block(lines))
    assert any(e.startswith(f"t.yaml:{bad_line}: ") and words in e for e in errs), errs


def test_read_a_one_value_range():
    s = steps_of("  - read: {param: F07, range: [3, 3]}\n")[0]
    assert s.title == "read F07, expect 3..3 s"
    r = read_after_write(3.0, "{param: F07, range: [3, 3]}")
    assert r.status == PASSED


def test_read_a_parameter_without_a_unit():
    s = steps_of("  - read: {param: PNU918, expect: 3}\n")[0]
    assert s.title == "read PNU918, expect 3"                 # the station address in use
    # the model behind DirectChannel is on no bus: its address in use reads 0
    r = run_text("  - read: {param: PNU918, expect: 0}\n")[0]
    assert r.status == PASSED and r.message == "PNU918 = 0"
    r = run_text("  - read: {param: PNU918, expect: 4}\n")[0]
    assert r.status == FAILED and r.message == "PNU918 = 0, expected 4"


# -- expect_status: true flags, family flags, waiting, words ------------------------------------------

RL = "R/L (PROFIBUS commands active)"


def test_expect_status_true_flags_and_their_words():
    s = steps_of(f"  - expect_status: {{running: true, fault: false, '{RL}': true}}\n")[0]
    assert s.title == f"status: running = yes, fault = no, {RL} = yes"
    r = run_text(f"  - expect_status: {{'{RL}': false, stopped: false}}\n")[0]   # R/L on, stopped
    assert r.status == FAILED
    assert r.message == f"{RL} is yes, expected no; stopped is yes, expected no"
    assert r.measured[RL] is True and r.measured["stopped"] is True
    assert r.measured["speed_hz"] == 0.0 and r.measured["speed_percent"] == 0.0


def test_expect_status_family_flag_true_passes():
    r = run_text(f"  - expect_status: {{'{RL}': true}}\n")[0]
    assert r.status == PASSED, r.message


def test_expect_status_running_measures_the_speed():
    steps = run_text(RAMPS + "  - run: {hz: 12}\n  - expect_status: {running: true}\n  - stop\n")
    m = steps[3].measured
    assert steps[3].status == PASSED
    assert m["speed_hz"] == pytest.approx(12, abs=0.5) and m["speed_percent"] == pytest.approx(20, abs=1)


def test_a_flag_named_in_another_case_by_the_drive():
    def lower_flags(st):
        st.flags = {k.lower(): v for k, v in st.flags.items()}
        return st
    r = run_text(f"  - expect_status: {{'{RL}': true}}\n", transform=lower_flags)[0]
    assert r.status == PASSED, r.message
    r = run_text(f"  - expect_status: {{'{RL}': false}}\n", transform=lower_flags)[0]
    assert r.status == FAILED


def test_running_is_the_status_itself_not_a_flag_of_that_name():
    def no_flags(st):
        st.flags = {}
        return st
    steps = run_text(RAMPS + "  - run: {hz: 12}\n  - expect_status: {running: true, stopped: false}\n  - stop\n",
                     transform=no_flags)
    assert steps[3].status == PASSED, steps[3].message


def test_a_fault_alarm_flag_the_drive_does_not_report_is_false():
    r = run_text("  - expect_status: {'fault: OC1': false}\n")[0]
    assert r.status == PASSED, r.message


def test_expect_status_waits_within_and_says_what_for():
    obs = Progress()
    # the drive trips 1 s after the start; the step waits up to 3 s for the fault
    steps = run_text("  - expect_status: {fault: true, within: 3}\n", disturb=trips_after(1.0), observer=obs)
    assert steps[0].status == PASSED, steps[0].message
    texts = [t for sr, r, t in obs.seen if r is steps[0] and sr is not None]
    assert texts and set(texts) == {"waiting for fault"}
    obs = Progress()
    steps = run_text("  - expect_status: {state: fault, within: 3}\n", disturb=trips_after(1.0), observer=obs)
    assert steps[0].status == PASSED, steps[0].message
    assert {t for _, _, t in obs.seen} == {"waiting for state"}
    steps = run_text("  - expect_status: {fault: true}\n", disturb=trips_after(1.0))
    assert steps[0].status == FAILED                      # one read: not tripped yet
    assert steps[0].message == "fault is no, expected yes"


@pytest.mark.parametrize("within", [0, 0.5])
def test_expect_status_within_zero_and_below_one_are_allowed(within):
    assert steps_of(f"  - expect_status: {{running: false, within: {within}}}\n")[0].args["within"] == within


def test_expect_status_keys_after_state_and_after_a_bad_flag_are_checked():
    s = steps_of("  - expect_status: {state: S4, running: true}\n")[0]
    assert s.args["flags"] == {"running": True}
    errs = errors_of("  - expect_status: {runing: true, fualt: true}\n")
    assert len(errs) == 2


def test_expect_status_suggestions():
    errs = errors_of("  - expect_status: {ready: true}\n")
    assert errs == [f"t.yaml:{FIRST}: step 1 (expect_status): fuji-opc-g1-pdp has no status flag 'ready' "
                    f"(did you mean 'ready to run'?)"]
    errs = errors_of("  - expect_status: {'ready (frequency run)': true}\n")
    assert errs == [f"t.yaml:{FIRST}: step 1 (expect_status): fuji-opc-g1-pdp has no status flag "
                    f"'ready (frequency run)' (did you mean 'ready for run-ON', 'FAR (frequency arrival)', "
                    f"'ready to run'?)"]


def test_expect_status_error_points_at_the_key_in_block_style():
    errs = errors_of(block(["- expect_status:", "    running: false", "    fualt: true"]))
    assert errs[0].startswith(f"t.yaml:{FIRST + 2}: step 1 (expect_status): fuji-opc-g1-pdp has no status flag")



# -- write: what it reports and how it writes --------------------------------------------------------

@pytest.mark.parametrize("lines,bad_line,words", [
    (["- write:", "    value: 1", "    param: W90"], FIRST + 2, "is read-only"),
    (["- write:", "    param: F07", "    value: 99999"], FIRST + 2, "99999 s is outside 0..6000 s"),
    (["- write:", "    param: F07", "    value: 1", "    allow_dangerous: 1"], FIRST + 3, "'allow_dangerous' must be true"),
    (["- write:", "    value: 2", "    param: P04"], FIRST + 2, "is dangerous: writing it"),
])
def test_write_errors_point_at_the_key_in_block_style(lines, bad_line, words):
    errs = errors_of(block(lines))
    assert any(e.startswith(f"t.yaml:{bad_line}: ") and words in e for e in errs), errs


def test_write_needs_a_mapping_and_a_parameter_channel():
    assert errors_of("  - write: F07\n") == [
        f"t.yaml:{FIRST}: step 1 (write): expected a mapping with param, value, allow_dangerous, got text"]
    text = ("name: t\nstations:\n  - {name: c1, address: 3, profile: fuji-g1, layout: ppo3}\nsteps:\n"
            "  - write: {param: F07, value: 1}\n")
    with pytest.raises(ChecklistError) as e:
        load_checklist_text(text, "t.yaml")
    msgs = [str(x) for x in e.value.errors]
    assert len(msgs) == 1 and msgs[0].startswith(f"t.yaml:{FIRST}: step 1 (write): station 'c1' uses layout "
                                                 f"ppo3, which has no parameter channel")


def test_write_a_parameter_without_a_unit_and_its_notes():
    r = run_text("  - write: {param: o27, value: 2}\n")[0]
    assert r.status == PASSED and r.message == "o27 = 2 (read back; was 0)"
    r = run_text("  - write: {param: o30, value: 3}\n")[0]
    assert r.status == PASSED
    assert r.message == "o30 = 3 (read back; was 0); o30 takes effect after the inverter is switched off and on"


def keeps(value_of):
    """Every read of a parameter answers value_of(code, value) instead of the value."""
    def prepare(d):
        real = d.read_param

        def read(code):
            pv = real(code)
            pv.value = value_of(code, pv.value)
            return pv
        d.read_param = read
    return prepare


def test_write_read_back_within_half_a_step_is_the_value():
    # F07 in 0.1 s steps: 2.54 s read back is the 2.5 s written
    r = run_text("  - write: {param: F07, value: 2.5}\n", prepare=keeps(lambda c, v: v + 0.04))[0]
    assert r.status == PASSED and r.message == "F07 = 2.54 s (read back; was 6.04 s)"
    assert r.measured["read_back"] == pytest.approx(2.54)


def test_write_unchanged_within_half_a_step():
    # the drive holds 2.54 s; writing 2.5 s changes nothing (within half a 0.1 s step)
    def prepare(d):
        d.write_param("F07", 2.5)
        keeps(lambda c, v: 2.54 if c == "F07" else v)(d)
    r = run_text("  - write: {param: F07, value: 2.5}\n", prepare=prepare)[0]
    assert r.status == PASSED and r.message == "F07 = 2.54 s (read back; unchanged)"


def test_write_read_back_that_differs_fails():
    r = run_text("  - write: {param: F07, value: 2.5}\n",
                 prepare=keeps(lambda c, v: 3.0 if v == 2.5 else v))[0]
    assert r.status == FAILED and r.message == "F07: wrote 2.5 s, read back 3 s"


def test_write_when_the_value_before_cannot_be_read():
    def prepare(d):
        real = d.read_param
        calls = []

        def read(code):
            calls.append(code)
            if calls.count("F07") == 2 and code == "F07":     # (the first: the runner's snapshot)
                from profidrive_cli import PdriveError
                raise PdriveError("write-only")
            return real(code)
        d.read_param = read
    r = run_text("  - write: {param: F07, value: 2.5}\n", prepare=prepare)[0]
    assert r.status == PASSED and r.message == "F07 = 2.5 s (read back)"
    assert r.measured["before"] is None


class Session:
    """The session's checked write (its Parameters: plan, then execute), recorded
    (runner.StationHandle.session)."""

    def __init__(self, d):
        self.d = d
        self.calls = []
        self.params = self

    def plan(self, code, value, allow_dangerous=False):
        self.calls.append((code, value, allow_dangerous))
        return code, value

    def execute(self, plan, check_running=True):
        return self.d.write_param(*plan)


def test_write_goes_through_the_session_when_there_is_one():
    made = []

    def session(d):
        made.append(Session(d))
        return made[-1]
    steps = run_text("  - write: {param: F07, value: 2.5}\n"
                     "  - write: {param: P04, value: 0, allow_dangerous: true}\n", session=session)
    assert [s.status for s in steps] == [PASSED, PASSED], [s.message for s in steps]
    assert made[0].calls == [("F07", 2.5, False), ("P04", 0, True)]


# -- fields.py: resolve_param for a family without its own resolver (Yaskawa), lines, odd profiles ----

from types import SimpleNamespace  # noqa: E402

from profidrive_cli import UsageError  # noqa: E402
from profidrive_cli.checklist.fields import resolve_param  # noqa: E402

YASK = load_profile("yaskawa-si-p1")
FUJI = load_profile("fuji-opc-g1-pdp")


def test_resolve_param_profile_codes_and_registers():
    label, p = resolve_param(YASK, "C1-01")
    assert label == "C1-01" and p is YASK.param("C1-01")
    assert resolve_param(YASK, "REG0x0180") == ("REG0x0180", None)
    assert resolve_param(YASK, "REG384") == ("REG0x0180", None)          # 384 = 0x0180
    assert resolve_param(YASK, "REG0") == ("REG0x0000", None)
    assert resolve_param(YASK, "REG0xFFFF") == ("REG0xFFFF", None)
    assert resolve_param(YASK, " C1-01 ")[0] == "C1-01"


def test_resolve_param_a_function_code_the_fuji_profile_does_not_list():
    assert resolve_param(FUJI, "F99") == ("F99", None)                    # PNU 0x104, subindex 99


def test_resolve_param_unknown_words():
    with pytest.raises(UsageError) as e:
        resolve_param(YASK, "REG0x10000")
    assert str(e.value).startswith("unknown parameter 'REG0x10000' for yaskawa-si-p1")
    with pytest.raises(UsageError) as e:
        resolve_param(YASK, "C1-0")
    assert str(e.value) == "unknown parameter 'C1-0' for yaskawa-si-p1; closest yaskawa codes: C1-10, C1-09, C1-02"
    with pytest.raises(UsageError) as e:
        resolve_param(YASK, "PNU918")
    # PNU918 is a code of every family with a PNU channel: Fuji and Moeller (PKW) and the DP-V1
    # PROFIdrive axis (DS47, profiles/profidrive-dpv1.yaml)
    assert str(e.value).startswith("unknown parameter 'PNU918' for yaskawa-si-p1 (PNU918 is a "
                                   "fuji/moeller/profidrive code; this station is family yaskawa)")


def test_read_of_a_raw_register_has_no_unit():
    text = ("name: t\nstations:\n  - {name: y1, address: 7, profile: yaskawa-si-p1}\nsteps:\n"
            "  - read: REG0x0180\n")
    s = load_checklist_text(text, "t.yaml").stations[0].steps[0]
    assert s.title == "read REG0x0180" and s.args["param"].unit == ""


def test_unknown_parameter_message_names_the_step():
    errs = errors_of("  - read: {param: Q9}\n")
    assert errs[0].startswith(f"t.yaml:{FIRST}: step 1 (read): unknown parameter 'Q9' for fuji-opc-g1-pdp")


@pytest.mark.parametrize("lines,bad_line,words", [
    (["- read:", "    expect: 1", "    param: true"], FIRST + 2, "'param' must be a parameter code"),
    (["- read:", "    expect: 1", "    param: Q9"], FIRST + 2, "unknown parameter 'Q9'"),
    (["- run:", "    hz: 10", "    speed: 3"], FIRST + 2, "unknown field 'speed'"),
    (["- run:", "    within: 5", "    hz: ten"], FIRST + 2, "'hz' must be a number"),
    (["- run:", "    hz: 10", "    duration: -1"], FIRST + 2, "'duration' must be at least 0"),
    (["- run:", "    hz: 10", "    within: 0"], FIRST + 2, "'within' must be above 0"),
])
def test_field_errors_point_at_the_key_in_block_style(lines, bad_line, words):
    errs = errors_of(block(lines))
    assert any(e.startswith(f"t.yaml:{bad_line}: ") and words in e for e in errs), errs


def test_an_unknown_field_stops_the_other_checks_of_that_step():
    assert len(errors_of("  - run: {hz: ten, speed: 3}\n")) == 1


def test_a_step_without_fields_given_a_list():
    assert errors_of("  - save: [1]\n") == [f"t.yaml:{FIRST}: step 1 (save): expected a mapping with no "
                                            f"fields, got a list"]


def test_a_required_number_missing_in_block_style():
    text = ("name: t\nstations:\n  - {name: m1, address: 6, profile: moeller-de6-net-dp}\nsteps:\n"
            "  - jog:\n      direction: reverse\n")
    with pytest.raises(ChecklistError) as e:
        load_checklist_text(text, "t.yaml")
    assert [str(x) for x in e.value.errors] == [f"t.yaml:{FIRST}: step 1 (jog): missing field 'duration'"]


def test_line_at_other_nodes():
    lst = LineList([1])
    lst.line, lst.item_lines = 9, [10]
    assert line_at(lst, "a") == 9                      # a text key on a list: the list's own line
    assert line_at(SimpleNamespace(line=4), "k") == 4
    assert line_at(SimpleNamespace(line=4), 3) == 4
    assert line_at(object(), 3, 7) == 7


def test_param_layouts_none():
    prof = SimpleNamespace(layouts={"a": SimpleNamespace(pkw=False)})
    assert param_layouts(prof) == "none"


def test_range_problem_slack_is_tiny_and_open_ends():
    moeller = load_profile("moeller-de6-net-dp")
    b096 = moeller.param("b096")
    assert range_problem(b096, 329.5) is not None and range_problem(b096, 380.5) is not None
    p = SimpleNamespace(code="X1", name="test", unit="Hz", min=None, max=3.0, extra={})
    assert range_problem(p, -1e9) is None
    assert range_problem(p, 4) == "X1 (test): 4 Hz is outside -inf..3 Hz"
    p = SimpleNamespace(code="X1", name="test", unit="", min=1.0, max=None, extra={})
    assert range_problem(p, 1e9) is None
    assert range_problem(p, 0.5) == "X1 (test): 0.5 is outside 1..inf"


def test_write_on_a_drive_without_notes_and_with_earlier_notes():
    def no_notes(d):
        d.take_notes = lambda: []                     # a family that keeps no remarks (Drive's default)
    r = run_text("  - write: {param: F07, value: 2.5}\n", prepare=no_notes)[0]
    assert r.status == PASSED and r.message == "F07 = 2.5 s (read back; was 6 s)"

    def earlier(d):
        d.notes.append("an earlier remark")
    r = run_text("  - write: {param: o30, value: 3}\n", prepare=earlier)[0]
    assert r.message == ("o30 = 3 (read back; was 0); an earlier remark; o30 takes effect after the "
                         "inverter is switched off and on")


def test_expect_status_without_within_reads_once():
    obs = Progress()
    steps = run_text("  - expect_status: {running: true}\n", observer=obs)
    assert steps[0].status == FAILED and obs.seen == []


def test_expect_status_waits_for_several_flags():
    obs = Progress()
    steps = run_text("  - expect_status: {fault: true, 'alarm (tripped)': true, within: 3}\n",
                     disturb=trips_after(1.0), observer=obs)
    assert steps[0].status == PASSED, steps[0].message
    assert {t for _, _, t in obs.seen} == {"waiting for fault, alarm (tripped)"}


def test_expect_status_within_first_then_flags():
    s = steps_of("  - expect_status: {within: 2, running: false}\n")[0]
    assert s.args == {"flags": {"running": False}, "state": None, "within": 2.0}


def test_resolve_param_register_bounds_in_decimal():
    assert resolve_param(YASK, "REG65535") == ("REG0xFFFF", None)
    with pytest.raises(UsageError):
        resolve_param(YASK, "REG65536")                       # 16-bit register numbers only


def test_validation_talks_to_no_drive(monkeypatch):
    # validation once built each family's Drive on a channel that refused traffic ("internal:
    # validation tried to talk to a drive"); now it asks the Drive class (param_label_for) and
    # builds no Drive at all: any construction fails this test
    import profidrive_cli.drives as drives
    import profidrive_cli.drives.registry as registry

    def no_drive(*a, **k):
        raise AssertionError("validation built a Drive")
    monkeypatch.setattr(drives, "make_drive", no_drive)
    monkeypatch.setattr(registry, "make_drive", no_drive)
    assert resolve_param(YASK, "REG0x0180")[0] == "REG0x0180"
    for name, code in (("fuji-g1", "F07"), ("moeller", "A038"), ("toyo", "PNU918")):
        assert resolve_param(load_profile(name), code)[0]


def test_a_stop_mode_the_card_cannot_make_is_refused_at_the_mode():
    text = ("name: t\nstations:\n  - {name: y1, address: 7, profile: yaskawa-si-p1}\nsteps:\n"
            "  - stop:\n      within: 5\n      mode: quick\n")
    with pytest.raises(ChecklistError) as e:
        load_checklist_text(text, "t.yaml")
    msgs = [str(x) for x in e.value.errors]
    assert len(msgs) == 1 and msgs[0].startswith(f"t.yaml:{FIRST + 2}: step 1 (stop): station 'y1': ")
    s = steps_of("  - stop: {mode: quick}\n")[0]                 # the Fuji card can (CTW bit 2)
    assert s.type == "stop"


def test_a_stop_mode_refused_on_one_layout_only():
    # docs/checklists.md "stop": a coast stop in Toyo mode 1 (layout toyo) is refused; PPO1 can
    head = "name: t\nstations:\n  - {name: t1, address: 5, profile: toyo-pbus66z%s}\nsteps:\n  - stop: {mode: coast}\n"
    with pytest.raises(ChecklistError) as e:
        load_checklist_text(head % ", layout: toyo", "t.yaml")
    assert [str(x) for x in e.value.errors][0].startswith(f"t.yaml:{FIRST}: step 1 (stop): station 't1': ")
    assert load_checklist_text(head % ", layout: ppo1", "t.yaml").stations[0].steps[0].type == "stop"
