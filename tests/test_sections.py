"""drives/sections.py, the one reader of a profile's family sections, and the family sections read with
it: each complaint keeps its words and its file:line (the messages are the ones the family readers gave
before the move; these tests pass on main's hand-written readers too)."""

from __future__ import annotations

import dataclasses
import textwrap
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import pytest

from profidrive_cli.datafile import DataFileError, load_yaml
from profidrive_cli.drives.profile import load_profile_file
from profidrive_cli.drives.sections import key, read, section

ROOT = Path(__file__).resolve().parents[1]


# -- the reader on a made-up declaration -----------------------------------------------------------

@dataclass(frozen=True)
class Inner:
    n: int = key("int", 1, lo=1, hi=9)


@dataclass(frozen=True)
class Demo:
    RULES: ClassVar[Any] = ((lambda d: d.a < 100 or d.flag, "{where}: a >= 100 needs flag"),)
    a: float = key("number", 2.5, gt=0)
    flag: bool = key("bool", False)
    name: str = key("text", required=True)
    inner: Inner = key("section", section=Inner)


def _doc(tmp_path, text):
    f = tmp_path / "d.yaml"
    f.write_text(text, encoding="utf-8")
    return f, load_yaml(f)


def test_defaults_types_and_a_frozen_result(tmp_path):
    f, doc = _doc(tmp_path, "demo:\n  name: x\n  a: 3\n")
    d = section(Demo, f, doc, "demo")
    assert d == Demo(a=3.0, flag=False, name="x", inner=Inner(1)) and isinstance(d.a, float)
    with pytest.raises(dataclasses.FrozenInstanceError):
        d.a = 1.0                                       # type: ignore[misc]
    assert section(Demo, f, load_yaml(f), "other") == Demo(name=None)     # absent, not required: defaults


@pytest.mark.parametrize("text,line,message", [
    ("demo:\n  name: x\n  a: -1\n", 3, "'a' must be a number, got -1"),
    ("demo:\n  name: x\n  a: true\n", 3, "'a' must be a number, got True"),
    ("demo:\n  a: 1\n", 2, "missing field 'name'"),
    ("demo:\n  name: x\n  inner:\n    n: 10\n", 4, "'n' must be an integer, got 10"),
    ("demo:\n  name: x\n  inner: 5\n", 3, "'inner' must be a mapping, got 5"),
    ("demo:\n  name: x\n  a: 200\n", 2, "demo: a >= 100 needs flag"),
    ("demo:\n  name: x\n  colour: red\n", 3, "demo: unknown key 'colour' (known: a, flag, inner, name)"),
    ("demo: 7\n", 1, "'demo' must be a mapping"),
    ("other: 1\n", 1, "missing section 'demo'"),
])
def test_complaints_name_file_and_line(tmp_path, text, line, message):
    f, doc = _doc(tmp_path, text)
    with pytest.raises(DataFileError) as e:
        section(Demo, f, doc, "demo", required=True, unknown_msg="{where}: unknown key '{key}' (known: {known})")
    assert (e.value.line, e.value.message) == (line, message)


def test_a_plain_dict_reads_without_lines():
    assert read(Demo, "p.yaml", {"name": "y", "inner": {"n": 3}}) == Demo(name="y", inner=Inner(3))  # type: ignore[arg-type]


# -- yaskawa: the `yaskawa:` section ----------------------------------------------------------------

def _edited(tmp_path, name, old, new):
    text = (ROOT / "profiles" / name).read_text(encoding="utf-8")
    assert old in text, old
    f = tmp_path / name
    f.write_text(text.replace(old, new, 1), encoding="utf-8")
    lines = f.read_text(encoding="utf-8").splitlines()
    return f, lines


YASKAWA = [
    ("  reference_unit_hz: 0.01", "  reference_unit_hz: x", "'reference_unit_hz' must be a number, got 'x'"),
    ("  reference_unit_hz: 0.01", "  reference_unit_hz: 0", "'reference_unit_hz' must be > 0"),
    ("  feedback_unit_hz: 0.1", "  feedback_unit_hz: -0.1", "'feedback_unit_hz' must be > 0"),
    ("  o1_03: 0", "  o1_03: 1.5", "'o1_03' must be a number, got 1.5"),
    ("  o1_03: 0", "  o1_03: 40000", "'o1_03' must be 0..39999"),
    ("  rated_current_a: null", "  rated_current_a: 0", "'rated_current_a' must be > 0 or null"),
    ("  rated_current_a: null", "  rated_current_a: yes", "'rated_current_a' must be a number, got True"),
    ("  fast_stop_input: null", "  fast_stop_input: 2", "'fast_stop_input' must be a multi-function input 3..12 or null"),
    ("  fast_stop_input: null", "  fast_stop_input: 3.0", "'fast_stop_input' must be a number, got 3.0"),
    ("    timeout_s: 1.0 ", "    timeout_s: soon ", "'timeout_s' must be a number, got 'soon'"),
    ("    settle_cycles: 1 ", "    settle_cycles: 1.5 ", "'settle_cycles' must be a number, got 1.5"),
    ("  handshake:\n", "  handshake: 3\n  x_handshake:\n", "'handshake' must be a mapping"),
    ("  enter_register:", "  enter_register: 7\n  x_enter_register:", "'enter_register' must be a mapping with an integer 'register'"),
    ("decisions:\n", "decisions: [1, 2]\nx_decisions:\n", "'decisions' must be a list of strings"),
    ("led_diagnostics:\n", "led_diagnostics: {}\nx_led_diagnostics:\n", "'led_diagnostics' must be a list"),
    ('  - {pwr: "off", com: "off"', '  - {pwr: "blue", com: "off"', "LED row: 'pwr' must be one of off, green, red, green-flash, red-flash"),
]


@pytest.mark.parametrize("old,new,message", YASKAWA, ids=[m for _, _, m in YASKAWA])
def test_yaskawa_section_complaints_keep_words_and_line(tmp_path, old, new, message):
    from profidrive_cli.drives.yaskawa import family_config
    f, lines = _edited(tmp_path, "yaskawa-si-p1.yaml", old, new)
    with pytest.raises(DataFileError) as e:
        family_config(load_profile_file(f))
    assert e.value.message == message
    # the line of the edited key
    assert lines[e.value.line - 1].startswith(new.split("\n")[0]), (e.value.line, lines[e.value.line - 1])
    assert str(e.value).startswith(f"{f}:{e.value.line}: ")


def test_yaskawa_handshake_rule_is_reported_on_the_handshake_mapping(tmp_path):
    from profidrive_cli.drives.yaskawa import family_config
    f, lines = _edited(tmp_path, "yaskawa-si-p1.yaml", "    timeout_s: 1.0 ", "    timeout_s: 0 ")
    with pytest.raises(DataFileError) as e:
        family_config(load_profile_file(f))
    assert e.value.message == "handshake: timeout_s must be > 0 and settle_cycles >= 1"
    # the mapping under `handshake:` starts at its first key
    assert lines[e.value.line - 1].startswith("    timeout_s: 0")


def test_yaskawa_section_values_reach_the_config(tmp_path):
    from profidrive_cli.drives.yaskawa import family_config
    f, _ = _edited(tmp_path, "yaskawa-si-p1.yaml", "  rated_current_a: null", "  rated_current_a: 12")
    c = family_config(load_profile_file(f))
    # profiles/yaskawa-si-p1.yaml: reference 0.01 Hz, feedback 0.1 Hz, o1_03 0, handshake 1.0 s / 1 cycle
    assert (c.reference_unit_hz, c.feedback_unit_hz, c.o1_03, c.rated_current_a, c.fast_stop_input,
            c.timeout_s, c.settle_cycles) == (0.01, 0.1, 0, 12.0, None, 1.0, 1)
    assert isinstance(c.rated_current_a, float)


# -- the PROFIdrive core: the `profidrive:` section --------------------------------------------------

GENERIC = """\
profile: generic-test
family: profidrive
title: Generic PROFIdrive test drive
identity: {ident: 0x1234}
layouts:
  ppo1: {cfg: "F3 F1", pkw: true}
default_layout: ppo1
max_frequency: {param: FMAX, default_hz: 50.0}
profidrive:
%s
parameters:
  - {code: FMAX, name: Max frequency, pnu: 10, unit: Hz, scale: 0.01, min: 25, max: 400, default: 50}
  - {code: ACC, name: Acceleration time, pnu: 11, unit: s, scale: 0.1, min: 0.1, max: 3600, default: 2.0}
"""

_KNOWN = ("array_pnus, baud_codes, ctw_bits, device_ids, dpv1, fault_memory, held_ctw_bits, jog_reference, "
          "labels, pkw, pzd_map, ramps, save, stw_bits")
_PKW = ("error_numbers, errors, max_zero_cycles, requests, responses, timeout_s, unsupported_text, "
        "zero_after_error, zero_between_identical")
_ROLES = "unknown_pnu, read_only, out_of_range, bad_subindex, not_array, wrong_type, stop_only, no_rights, bad_request"

#: (the section's text under `profidrive:`, line of the complaint (profidrive: is line 9), message)
PROFIDRIVE = [
    ("  bogus: 1", 10, f"profidrive: unknown key 'bogus' (known: {_KNOWN})"),
    ("  labels: {foo: x}", 10, "profidrive.labels: 'foo' must be one of control, status, reference, actual with a text value"),
    ("  labels: {control: 5}", 10, "profidrive.labels: 'control' must be one of control, status, reference, actual with a text value"),
    ("  labels: 5", 10, "'labels' must be a mapping"),
    ("  ctw_bits: {16: x}", 10, "ctw_bits: keys are bit numbers 0..15, values names (null = unused)"),
    ("  stw_bits: [1]", 10, "'stw_bits' must be a mapping"),
    ("  held_ctw_bits: [16]", 10, "'held_ctw_bits' must be a list of integers 0..15"),
    ("  held_ctw_bits: [0]", 10, "held_ctw_bits cannot include bits 0-3, 7 or 10 (the state machine sets them)"),
    ("  array_pnus: [0]", 10, "'array_pnus' must be a list of integers 1..2047"),
    ("  pzd_map: {foo: 1}", 10, "profidrive.pzd_map: unknown key 'foo' (known: actual, setpoint)"),
    ("  pzd_map: {setpoint: x}", 10, "'setpoint' must be an integer, got 'x'"),
    ("  pzd_map: 1", 10, "'pzd_map' must be a mapping"),
    ("  pkw: 3", 10, "'pkw' must be a mapping"),
    ("  pkw: {timeout_s: -1}", 10, "pkw.timeout_s must be a number > 0"),
    ("  pkw: {timeout_s: true}", 10, "pkw.timeout_s must be a number > 0"),
    ("  pkw:\n    max_zero_cycles: 3\n    timeout_s: 0", 12, "pkw.timeout_s must be a number > 0"),
    ("  pkw: {zero_after_error: 1}", 10, "pkw.zero_after_error must be true or false"),
    ("  pkw: {max_zero_cycles: 1.5}", 10, "'max_zero_cycles' must be an integer, got 1.5"),
    ("  pkw: {requests: [16]}", 10, "'requests' must be a list of integers 0..15"),
    ("  pkw: {responses: x}", 10, "'responses' must be a list of integers 0..15"),
    ("  pkw: {unsupported_text: ' '}", 10, "pkw.unsupported_text must be a text"),
    ("  pkw: {errors: {x: y}}", 10, "pkw.errors: keys are error numbers, values texts"),
    ("  pkw:\n    error_numbers: {nonsense: 3}", 11, f"pkw.error_numbers: 'nonsense' must be one of {_ROLES} with a number"),
    ("  pkw: {colour: 1}", 10, f"profidrive.pkw: unknown key 'colour' (known: {_PKW})"),
    ("  fault_memory: {subindexes: [1, 9], positions: [a]}", 10, "fault_memory.positions must be one text per subindex"),
    ("  fault_memory: {positions: [a, 1, c, d]}", 10, "fault_memory.positions must be one text per subindex"),
    ("  fault_memory: {subindexes: [256]}", 10, "'subindexes' must be a list of integers 0..255"),
    ("  fault_memory: {pnu: x}", 10, "'pnu' must be an integer, got 'x'"),
    ("  fault_memory: {x: 1}", 10, "profidrive.fault_memory: unknown key 'x' (known: pnu, positions, subindexes)"),
    ("  save: {pnu: x}", 10, "'pnu' must be an integer, got 'x'"),
    ("  save: {at: 1}", 10, "profidrive.save: unknown key 'at' (known: pnu)"),
    ("  dpv1: {slott: 0}", 10, "profidrive.dpv1: unknown key 'slott' (known: axis, c1_timeout_ms, slot, timeout_s)"),
    ("  dpv1: {slot: 255}", 10, "dpv1.slot must be 0..254"),
    ("  dpv1: {c1_timeout_ms: 0}", 10, "dpv1.c1_timeout_ms must be a number > 0"),
    ("  baud_codes: {x: y}", 10, "baud_codes: keys are numbers, values texts"),
    ("  device_ids: {1: 2}", 10, "device_ids: keys are numbers, values texts"),
    ("  ramps: {up: ACC}", 10, "ramps: keys accel, decel, quick_decel; values parameter codes"),
    ("  ramps:\n    decel: ACC\n    accel: NOPE", 12, "ramps.accel: parameter NOPE is not in parameters"),
    ("  jog_reference: NOPE", 10, "jog_reference 'NOPE' is not in parameters"),
    ("  jog_reference: 5", 10, "jog_reference 5 is not in parameters"),
]


@pytest.mark.parametrize("text,line,message", PROFIDRIVE, ids=[t.strip() for t, _, _ in PROFIDRIVE])
def test_profidrive_section_complaints_keep_words_and_line(tmp_path, text, line, message):
    from profidrive_cli.drives.profidrive.config import ProfidriveConfig
    f = tmp_path / "generic-test.yaml"
    f.write_text(GENERIC % text, encoding="utf-8")
    with pytest.raises(DataFileError) as e:
        ProfidriveConfig.from_profile(load_profile_file(f))
    assert (e.value.line, e.value.message) == (line, message)
    assert str(e.value).startswith(f"{f}:{line}: ")


def test_profidrive_section_values(tmp_path):
    from profidrive_cli.drives.profidrive.config import ProfidriveConfig
    f = tmp_path / "generic-test.yaml"
    f.write_text(GENERIC % textwrap.indent(textwrap.dedent("""\
        labels: {reference: HSW}
        ctw_bits: {11: reverse, 9: null}
        stw_bits: {8: at speed}
        held_ctw_bits: [4, 5]
        array_pnus: [947]
        pzd_map: {setpoint: 915}
        pkw: {timeout_s: 1, zero_between_identical: true, max_zero_cycles: 5, requests: [1, 2],
              responses: [1], unsupported_text: not here, errors: {104: busy}, error_numbers: {stop_only: 11}}
        fault_memory: {pnu: 947, subindexes: [1, 9], positions: [now, before]}
        save: {pnu: 971}
        baud_codes: {1: 12 Mbit/s}
        device_ids: {0x812C: DF6}
        ramps: {accel: ACC}
        jog_reference: FMAX"""), "  "), encoding="utf-8")
    c = ProfidriveConfig.from_profile(load_profile_file(f))
    assert c.labels == {"control": "CTW", "status": "STW", "reference": "HSW", "actual": "MAV"}
    assert c.ctw_names[11] == "reverse" and 9 not in c.ctw_names and c.unused_ctw_bits == frozenset({9})
    assert c.stw_names[8] == "at speed"
    assert c.held_ctw_bits == 0x30 and c.array_pnus == frozenset({947}) and c.pzd_map[0] == 915
    assert (c.pkw_timeout, c.zero_after_error, c.zero_between_identical, c.max_zero_cycles) == (1.0, False, True, 5)
    assert isinstance(c.pkw_timeout, float)
    assert (c.supported_requests, c.supported_responses, c.unsupported_text) == (
        frozenset({1, 2}), frozenset({1}), "not here")
    assert c.error_texts[104] == "busy" and c.error_numbers["stop_only"] == 11
    assert (c.fault_memory_pnu, c.fault_subindexes, c.fault_positions) == (947, [1, 9], ["now", "before"])
    assert c.save_pnu == 971 and c.baud_codes == {1: "12 Mbit/s"} and c.device_ids == {0x812C: "DF6"}
    assert c.ramps == {"accel": "ACC"} and c.jog_reference == "FMAX"
    f.write_text(GENERIC % "  save: {}", encoding="utf-8")
    c = ProfidriveConfig.from_profile(load_profile_file(f))
    assert c.save_pnu is None and c.fault_positions == ["current", "last", "2nd last", "3rd last"]


# -- toyo: the top-level Toyo keys and sections ------------------------------------------------------

TOYO = [
    ("diag_word_order: big", "diag_word_order: middle", "diag_word_order must be big or little"),
    ("diag_word_order: big", "diag_word_order: 5", "diag_word_order must be big or little"),
    ("plch: false", "plch: 0", "plch must be true or false"),
    ("speed_full_scale: 20000", "speed_full_scale: 0", "speed_full_scale must be a positive integer"),
    ("speed_full_scale: 20000", "speed_full_scale: 2e4", "speed_full_scale must be a positive integer"),
    ("voltage_class: 200", "voltage_class: 300", "voltage_class must be 200 or 400"),
    ("bits:\n", "bits: 5\nx_bits:\n", "'bits' must be a mapping"),
    ("fields:\n", "fields: []\nx_fields:\n", "'fields' must be a mapping"),
    ("parameter_channel:\n", "parameter_channel: 1\nx_parameter_channel:\n", "'parameter_channel' must be a mapping"),
    ("traceback:\n", "traceback: null\nx_traceback:\n", "'traceback' must be a mapping"),
    ("fault_history:\n", "fault_history: [1]\nx_fault_history:\n", "'fault_history' must be a mapping"),
    ("  ctw: {name: Control word, kind: ctw}", "  ctw: {name: Control word, kind: word}",
     "fields.ctw: kind must be one of ctw, zsw, run_cmd, bits, speed, scaled, date, raw, param"),
    ("    mode: 0\n    description: \"Mode 0 PPO1", "    mode: 2\n    description: \"Mode 0 PPO1",
     "layout ppo1: mode must be 0 or 1"),
    ("    out: [ctw, speed_ref]", "    out: [ctw, nosuch]", "layout ppo1: unknown field 'nosuch'"),
]


@pytest.mark.parametrize("old,new,message", TOYO, ids=[m for _, _, m in TOYO])
def test_toyo_complaints_keep_words_and_line(tmp_path, old, new, message):
    from profidrive_cli.drives.toyo import toyo_config
    f, lines = _edited(tmp_path, "toyo-pbus66z.yaml", old, new)
    with pytest.raises(DataFileError) as e:
        toyo_config(load_profile_file(f))
    assert e.value.message == message
    assert lines[e.value.line - 1].strip().startswith(new.split("\n")[0].strip()), (e.value.line, lines[e.value.line - 1])


@pytest.mark.parametrize("name", ["bits", "fields", "parameter_channel", "traceback", "fault_history"])
def test_toyo_sections_are_required(tmp_path, name):
    from profidrive_cli.drives.toyo import toyo_config
    f, lines = _edited(tmp_path, "toyo-pbus66z.yaml", f"\n{name}:\n", f"\nx_{name}:\n")
    with pytest.raises(DataFileError) as e:
        toyo_config(load_profile_file(f))
    assert e.value.message == f"missing section '{name}'"
    assert lines[e.value.line - 1].startswith("profile:")         # the document's mapping starts there


def test_toyo_speed_full_scale_true_is_not_the_integer_1(tmp_path):
    """YAML `true` is a Python bool, an int subclass: the hand-written reader took it as 1 (100 % speed
    = 1 count); the declared int kind refuses a bool, as every other integer key does."""
    from profidrive_cli.drives.toyo import toyo_config
    f, lines = _edited(tmp_path, "toyo-pbus66z.yaml", "speed_full_scale: 20000", "speed_full_scale: true")
    with pytest.raises(DataFileError) as e:
        toyo_config(load_profile_file(f))
    assert e.value.message == "speed_full_scale must be a positive integer"
    assert lines[e.value.line - 1].startswith("speed_full_scale: true")


# -- fuji: the Fuji keys ----------------------------------------------------------------------------

FUJI = [
    ("  pnu_base: 0x100", "  pnu_base: 0x800", "function_codes.pnu_base must be an integer"),
    ("  pnu_base: 0x100", "  pnu_base: x", "function_codes.pnu_base must be an integer"),
    ("  groups:\n", "  groups: {}\n  x_groups:\n", "function_codes.groups must map group letters to {code, name}"),
    ("    S: {code: 0x02,", "    S: {code: 0x100,", "group S: needs code 0..255"),
    ("    S: {code: 0x02,", "    S1x: {code: 0x02,", "group 'S1x': one letter, optionally followed by one character"),
    ("ppo_select: {param: o30, power_cycle: true}", "ppo_select: 3", "'ppo_select' must be a mapping"),
    ('o30: [0, 1, "6-255"]', 'o30: [0, 1, "6-x"]', "layout ppo1: o30 value '6-x' is neither a number nor a range 'a-b'"),
    ("  errors:\n    0:", "  errors: 5\n  x_errors:\n    0:", "parameter_channel.errors must map numbers to texts"),
    ("    0: parameter (PNU", "    x: parameter (PNU", "parameter_channel.errors: keys are numbers, values texts"),
    ("storage: {param: y97,", "storage: {param: y97x,", "storage.param y97x is not a parameter"),
    ("storage: {param: y97, eeprom: 0,", "storage: {param: y97,", "storage: missing 'eeprom'"),
    ("storage: {param: y97, eeprom: 0, ram: 1, save: 2, saved_reads: 1, save_time_s: 5.0}", "storage: [y97]",
     "'storage' must be a mapping"),
    ("  action_param: o27", "  action_param: o99", "comm_loss.action_param: o99 is not a parameter"),
    ("  alarm: Er5", "  alarm: Er9", "comm_loss.alarm Er9 is not in alarms"),
    ("    - {o27: [0, \"4-9\"], stop: coast,", "    - {o27: [0, \"4-9\"], stop: brake,",
     "comm_loss.actions[0]: needs o27: [values], stop: coast | ramp | none"),
    ("    - {o27: [0, \"4-9\"], stop: coast,", "    - {o27: [0, \"9-4\"], stop: coast,",
     "comm_loss.actions[0]: o27 value '9-4' is neither a number nor a range 'a-b'"),
    ("zero_data: {param: o32, actions: {0: ignore, 1: coast, 2: coast_if_last_ctw_bit10}}", "zero_data: 0",
     "'zero_data' must be a mapping"),
    ("    - {position: latest, index: 1, mcode_param: M16}", "    - {position: latest, index: x, mcode_param: M16}",
     "fault_history entry needs position and index"),
    ("    - {position: latest, index: 1, mcode_param: M16}", "    - {position: latest, index: 1, mcode_param: M99}",
     "fault_history: M99 is not a parameter"),
    ("fault_history:\n  pnu: 947\n  elements: 32\n  entries:\n", "fault_history:\n  pnu: 947\n  elements: 32\n  entries: []\n  x_entries:\n",
     "fault_history.entries must be a list"),
]


@pytest.mark.parametrize("old,new,message", FUJI, ids=[m for _, _, m in FUJI])
def test_fuji_complaints_keep_words_and_line(tmp_path, old, new, message):
    from profidrive_cli.drives.fuji import fuji_config
    f, lines = _edited(tmp_path, "fuji-opc-pdp3.yaml", old, new)
    with pytest.raises(DataFileError) as e:
        fuji_config(load_profile_file(f))
    assert e.value.message == message
    first = new.split("\n")[0] if not new.startswith("fault_history") else "  entries: []"
    assert first.strip()[:12] in lines[e.value.line - 1], (e.value.line, lines[e.value.line - 1])


@pytest.mark.parametrize("name", ["function_codes", "ppo_select", "parameter_channel", "comm_loss", "fault_history"])
def test_fuji_sections_are_required(tmp_path, name):
    from profidrive_cli.drives.fuji import fuji_config
    f, lines = _edited(tmp_path, "fuji-opc-pdp3.yaml", f"\n{name}:", f"\nx_{name}:")
    with pytest.raises(DataFileError) as e:
        fuji_config(load_profile_file(f))
    assert e.value.message == f"missing section '{name}'"
    assert lines[e.value.line - 1].startswith("profile:")


def test_fuji_null_section_is_missing(tmp_path):
    from profidrive_cli.drives.fuji import fuji_config
    f, lines = _edited(tmp_path, "fuji-opc-pdp3.yaml", "ppo_select: {param: o30, power_cycle: true}", "ppo_select: null")
    with pytest.raises(DataFileError) as e:
        fuji_config(load_profile_file(f))
    assert e.value.message == "missing section 'ppo_select'"


def test_fuji_pnu_base_true_is_not_the_integer_1(tmp_path):
    """YAML `true` is a bool (an int subclass): the hand-written reader took it as PNU base 1; the declared
    int kind refuses it."""
    from profidrive_cli.drives.fuji import fuji_config
    f, lines = _edited(tmp_path, "fuji-opc-pdp3.yaml", "  pnu_base: 0x100", "  pnu_base: true")
    with pytest.raises(DataFileError) as e:
        fuji_config(load_profile_file(f))
    assert e.value.message == "function_codes.pnu_base must be an integer"
    assert lines[e.value.line - 1] == "  pnu_base: true"
