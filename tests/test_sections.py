"""drives/sections.py, the one reader of a profile's family sections, and the family sections read with
it: each complaint keeps its words and its file:line (the messages are the ones the family readers gave
before the move; these tests pass on main's hand-written readers too)."""

from __future__ import annotations

import dataclasses
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
