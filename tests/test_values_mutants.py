"""drives/values.py: the one exact-value check, cases mutation testing found untested (issue 20).

Expected values are hand calculations from each parameter's step, range and wire width."""

import math
from decimal import Decimal
from fractions import Fraction

import pytest

from profidrive_cli.drives.profile import ParamDef
from profidrive_cli.drives import values as V


def P(**kw):
    kw.setdefault("scale", 1.0)
    return ParamDef(code="X1", name="Test", **kw)


# -- not a number ---------------------------------------------------------------------------------

@pytest.mark.parametrize("value, text", [
    ("3", "X1 (Test): '3' is not a number"),
    (True, "X1 (Test): True is not a number"),
    (None, "X1 (Test): None is not a number"),
    (math.nan, "X1 (Test): nan is not a value a parameter can hold"),
    (-math.inf, "X1 (Test): -inf is not a value a parameter can hold"),
    (Decimal("NaN"), "X1 (Test): Decimal('NaN') is not a number"),
    (Decimal("Infinity"), "X1 (Test): Decimal('Infinity') is not a number"),
])
def test_not_a_number_messages(value, text):
    assert V.value_problem(P(), value) == text


def test_label_replaces_the_code():
    assert V.value_problem(P(), "x", label="X1[2]") == "X1[2] (Test): 'x' is not a number"


# -- resolution -----------------------------------------------------------------------------------

def test_between_two_steps_names_step_and_neighbours():
    p = P(scale=0.1, unit="s", min=0, max=6000)
    assert V.value_problem(p, 0.05) == \
        "X1 = 0.05 s cannot be held exactly: resolution 0.1 s; nearest 0 s or 0.1 s"
    assert V.value_problem(p, 2.55) == \
        "X1 = 2.55 s cannot be held exactly: resolution 0.1 s; nearest 2.5 s or 2.6 s"


def test_whole_numbers_only_for_step_1():
    assert V.value_problem(P(min=0, max=15), 10.7) == \
        "X1 = 10.7 cannot be held exactly: X1 takes whole numbers only; nearest 10 or 11"


def test_negative_scale_is_a_step_of_its_size():
    # a scale of -0.1 (reversed sign on the wire) still has 0.1 steps
    assert V.value_problem(P(scale=-0.1, signed=True), 0.3) is None
    assert "resolution 0.1" in V.value_problem(P(scale=-0.1, signed=True), 0.35)


def test_float_noise_is_1e_9_of_a_step():
    p = P(scale=1.0)
    assert V.value_problem(p, Fraction(1) + Fraction(1, 10**9)) is None      # exactly the noise
    assert V.value_problem(p, Fraction(1) + Fraction(2, 10**9)) is not None
    assert V.value_problem(P(scale=0.1), 0.30000000000000004) is None


def test_no_scale_means_no_step_check():
    p = P(scale=0, min=0, max=10)
    assert V.value_problem(p, 2.5) is None
    assert V.exact_raw(p, 7) == 7


# -- ranges ---------------------------------------------------------------------------------------

def test_outside_min_max():
    p = P(scale=1.0, unit="s", min=0, max=6)
    assert V.value_problem(p, 7) == "X1 (Test): 7 s is outside 0..6 s; nearest 6 s"
    assert V.value_problem(p, -1) == "X1 (Test): -1 s is outside 0..6 s; nearest 0 s"
    assert V.value_problem(p, 6) is None and V.value_problem(p, 0) is None


def test_open_ended_ranges():
    assert V.value_problem(P(min=3), 2) == "X1 (Test): 2 is outside 3..inf; nearest 3"
    assert V.value_problem(P(max=-3, signed=True), -2) == \
        "X1 (Test): -2 is outside -inf..-3; nearest -3"


def test_listed_ranges():
    p = P(extra={"ranges": [[0, 3], [10, 10]]})
    assert V.value_problem(p, 5) == "X1 (Test): 5 is outside 0..3, 10; nearest 3 or 10"
    assert V.value_problem(p, 10) is None


def test_code_values_parsing():
    p = P(signed=True, extra={"values": {0: "a", "2-39": "b", "-5": "c", " 7 ": "d", "x": "e",
                                         True: "f", "-8 - -6": "g"}})
    assert V.code_values(p) == [(-8, -6), (-5, -5), (0, 0), (2, 39), (7, 7)]
    assert V.code_values(P(extra={"values": {}})) is None
    assert V.code_values(P(extra={"values": [1, 2]})) is None
    assert V.code_values(P(extra={"values": {"x": 1}})) is None
    assert V.code_values(P()) is None


def test_codes_message_and_min_max_bound_them():
    p = P(signed=True, extra={"values": {0: "a", "2-39": "b", -5: "c"}})
    assert V.value_problem(p, 1) == \
        "X1 (Test): 1 is not one of its codes -5, 0, 2..39; nearest 0 or 2"
    q = P(min=3, max=30, extra={"values": {0: "a", "2-39": "b"}})
    assert V.value_problem(q, 2) == "X1 (Test): 2 is not one of its codes 3..30; nearest 3"
    assert V.value_problem(q, 31) == "X1 (Test): 31 is not one of its codes 3..30; nearest 30"
    assert V.value_problem(q, 30) is None
    r = P(min=3, extra={"values": {0: "a", "2-39": "b"}})
    assert V.value_problem(r, 40).startswith("X1 (Test): 40 is not one of its codes 3..39")
    s = P(max=5, extra={"values": {0: "a", "2-39": "b"}})
    assert V.value_problem(s, 1).startswith("X1 (Test): 1 is not one of its codes 0, 2..5")


# -- wire width -----------------------------------------------------------------------------------

@pytest.mark.parametrize("kw, ok, bad, words", [
    ({}, 65535, 65536, "wire word (0..65535)"),
    ({"signed": True}, -32768, -32769, "signed wire word (-32768..32767)"),
    ({"signed": True}, 32767, 32768, "signed wire word (-32768..32767)"),
    ({"size": 32}, 4294967295, 4294967296, "wire word (0..4294967295)"),
    ({"extra": {"bytes": 1}}, 255, 256, "wire word (0..255)"),
    ({"scale": 0.1, "signed": True}, -3276.8, -3276.9, "signed wire word (-3276.8..3276.7)"),
])
def test_wire_word_bounds(kw, ok, bad, words):
    p = P(**kw)
    assert V.value_problem(p, ok) is None
    msg = V.value_problem(p, bad)
    assert msg is not None and f"does not fit the parameter's {words}" in msg


def test_wire_word_message_and_nearest():
    assert V.value_problem(P(unit="Hz"), 70000) == (
        "X1 (Test): 70000 Hz does not fit the parameter's wire word (0..65535 Hz); nearest 65535 Hz")


# -- nearest --------------------------------------------------------------------------------------

def test_nearest_valid():
    p = P(scale=0.1, min=0, max=6000)
    assert V.nearest_valid(p, Fraction(1, 20)) == [0, Fraction(1, 10)]
    assert V.nearest_valid(p, Fraction(7000)) == [6000]
    assert V.nearest_valid(p, Fraction(-1)) == [0]
    assert V.nearest_valid(p, Fraction(5, 2)) == [Fraction(5, 2)]
    # the override scale: steps of 0.5
    assert V.nearest_valid(p, Fraction(3, 10), scale=0.5) == [0, Fraction(1, 2)]


def test_a_range_holding_no_step_has_no_nearest():
    p = P(scale=0.1, min=0.05, max=0.08)
    assert V.nearest_valid(p, Fraction(6, 100)) == []
    assert V.value_problem(p, 0.06) == "X1 = 0.06 cannot be held exactly: resolution 0.1"


def test_nearest_respects_the_wire_word_inside_an_open_range():
    assert V.nearest_valid(P(min=10), Fraction(70000)) == [65535]
    assert V.nearest_valid(P(max=10, signed=True), Fraction(-40000)) == [-32768]


# -- raw access -----------------------------------------------------------------------------------

@pytest.mark.parametrize("value, text", [
    (True, "P5: True is not a value a parameter can hold"),
    ("1", "P5: '1' is not a value a parameter can hold"),
    (math.inf, "P5: inf is not a value a parameter can hold"),
    (2.5, "P5 = 2.5 cannot be held exactly: raw values are whole numbers; nearest 2 or 3"),
    (-2.5, "P5 = -2.5 cannot be held exactly: raw values are whole numbers; nearest -3 or -2"),
    (-32769, "P5: -32769 does not fit 16 bits"),
    (65536, "P5: 65536 does not fit 16 bits"),
    (-32768, None), (65535, None), (3.0, None),
])
def test_raw_value_problem(value, text):
    assert V.raw_value_problem("P5", value) == text


def test_raw_value_problem_32_bits():
    assert V.raw_value_problem("P5", 4294967295, bits=32) is None
    assert V.raw_value_problem("P5", 4294967296, bits=32) == "P5: 4294967296 does not fit 32 bits"
    assert V.raw_value_problem("P5", -2147483649, bits=32) == "P5: -2147483649 does not fit 32 bits"


# -- exact_raw ------------------------------------------------------------------------------------

def test_exact_raw():
    assert V.exact_raw(P(scale=0.1), 2.5) == 25
    assert V.exact_raw(P(scale=0.1), 0.30000000000000004) == 3
    assert V.exact_raw(P(scale=0.01), 1.55) == 155
    assert V.exact_raw(P(scale=0.1), 2.5, scale=0.5) == 5


# -- danger ---------------------------------------------------------------------------------------

def test_danger_texts():
    assert V.danger(P(extra={"dangerous": True})) == V.DEFAULT_DANGER
    assert V.DEFAULT_DANGER == \
        "initialises data or runs the motor on its own (marked dangerous in the profile)"
    assert V.danger(P(extra={"dangerous": True, "danger": "starts auto-tuning"})) == \
        "starts auto-tuning"
    assert V.danger(P(extra={"danger": "text only"})) is None
    assert not V.is_dangerous(None) and V.danger(None) is None


# -- the family's scale hook ----------------------------------------------------------------------

def test_profile_value_problem_uses_the_toyo_400v_scale():
    from dataclasses import replace

    from profidrive_cli.drives.profile import load_profile
    from profidrive_cli.drives.toyo.config import toyo_config
    prof = load_profile("toyo-pbus66z")
    p = prof.param("dc-voltage")                      # scale 0.1 V, 0.2 V on 400 V models
    assert V.profile_value_problem(prof, p, 0.3) is None
    p400 = replace(prof)
    toyo_config(p400).voltage_class = 400
    msg = V.profile_value_problem(p400, p, 0.3)
    assert msg is not None and "resolution 0.2 V; nearest 0.2 V or 0.4 V" in msg
    # a family without the hook: the parameter's own scale
    fuji = load_profile("fuji-g1")
    assert V.profile_value_problem(fuji, fuji.param("F07"), 0.05).endswith("nearest 0 s or 0.1 s")


# -- second run: the scale override in every message, scale 0, odd inputs ------------------------

def test_override_scale_in_the_whole_number_message():
    # a 0.1 profile entry read with an override step of 1: 2.5 lies between 2 and 3
    assert V.value_problem(P(scale=0.1, min=0, max=100), 2.5, scale=1) == \
        "X1 = 2.5 cannot be held exactly: X1 takes whole numbers only; nearest 2 or 3"


def test_override_scale_in_the_range_message():
    # step 0.2: 1.4 = 7 steps, outside 0..1.1; the highest 0.2 step inside is 1.0
    assert V.value_problem(P(scale=0.1, min=0, max=1.1), 1.4, scale=0.2) == \
        "X1 (Test): 1.4 is outside 0..1.1; nearest 1"


def test_override_scale_in_the_wire_word_message():
    # 16-bit unsigned word of 0.2 steps: 0..13107 (65535 x 0.2); 13107.2 = 65536 steps
    assert V.value_problem(P(scale=0.1), 13107.2, scale=0.2) == (
        "X1 (Test): 13107.2 does not fit the parameter's wire word (0..13107); nearest 13107")
    assert V.nearest_valid(P(scale=0.1), Fraction(40000), scale=0.5) == [Fraction(65535, 2)]


def test_scale_0_nearest_uses_whole_numbers_and_open_ends():
    assert V.nearest_valid(P(scale=0), Fraction(5, 2)) == [2, 3]
    assert V.value_problem(P(scale=0, min=0), -1) == "X1 (Test): -1 is outside 0..inf; nearest 0"
    assert V.value_problem(P(scale=0, max=10), 12) == "X1 (Test): 12 is outside -inf..10; nearest 10"
    assert V.nearest_valid(P(scale=0, max=10), Fraction(12)) == [10]


def test_a_range_without_steps_is_skipped_not_the_end():
    p = P(scale=0.1, extra={"ranges": [[0.05, 0.08], [1, 2]]})
    assert V.nearest_valid(p, Fraction(1, 2)) == [1]
    assert V.value_problem(p, 0.5) == "X1 (Test): 0.5 is outside 0.05..0.08, 1..2; nearest 1"


def test_ranges_that_are_not_a_list_are_ignored():
    assert V.value_problem(P(min=0, max=5, extra={"ranges": "0..3"}), 4) is None


def test_no_size_means_a_16_bit_word():
    assert V.value_problem(P(size=0), 65535) is None
    assert "wire word (0..65535)" in V.value_problem(P(size=0), 65536)


def test_code_keys_that_are_no_numbers_are_skipped():
    assert V.code_values(P(extra={"values": {"X5": "a", 1: "b", "-x": "c"}})) == [(1, 1)]


def test_a_value_too_big_for_a_float_is_shown_exactly():
    v = Fraction(10**400 + 1, 2)
    msg = V.value_problem(P(scale=1.0), v)
    assert msg.startswith(f"X1 = {10**400 + 1}/2 cannot be held exactly: X1 takes whole numbers only")
