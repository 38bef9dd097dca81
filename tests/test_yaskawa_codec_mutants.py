"""drives/yaskawa/codec.py: the cases mutation testing found untested (issue 20).

Expected values: the layouts and bit tables of ../shared/spec/yaskawa-profibus-dp.md (§2.2, §2.3,
§2.7, E6) and hand calculations of the o1-03 units the codec documents (0.01 % of max frequency;
r/min = Hz x 120 / poles; user units: the last four digits of o1-03 = counts at max frequency).
"""

import pytest

from profidrive_cli.drives.yaskawa.codec import (FORMATS, FrequencyScale, encode_command, mfi_bit,
                                                 pack_words, unpack_words)

EXT1, EXT2, BASIC = FORMATS["extended1"], FORMATS["extended2"], FORMATS["basic"]


def test_layout_sizes_and_parameter_areas():
    assert (BASIC.param_len, EXT1.param_len, EXT2.param_len) == (0, 16, 8)
    assert (EXT1.has_params, EXT2.has_params) == (True, True)
    # E6: one register (2 octets) is valid; the 16-word layout takes up to four
    assert EXT1.data_quantities == (2, 4, 6, 8)
    assert EXT2.data_quantities == (2,)
    assert BASIC.data_quantities == ()


def test_little_endian_words_and_odd_tail():
    assert pack_words([0x1770, 0x0001], "little") == bytes.fromhex("7017 0100")
    assert unpack_words(bytes.fromhex("7017 0100"), "little") == [0x1770, 0x0001]
    assert unpack_words(bytes.fromhex("0102 03"), "big") == [0x0102]       # half a word is no word
    assert pack_words([-1]) == b"\xff\xff"


def test_unknown_command_bit_and_mfi_range_say_what():
    with pytest.raises(ValueError) as e:
        encode_command(forward=True)
    assert str(e.value) == "unknown command bit 'forward'"
    assert encode_command(forward_run=False, reverse_run=True) == 0x0002
    with pytest.raises(ValueError) as e:
        mfi_bit(13)
    assert str(e.value) == "multi-function input 13: the command word carries inputs 3..12"
    assert mfi_bit(12) == 13 and mfi_bit(3) == 2


def test_hz_units_per_direction():
    s = FrequencyScale(0, 60.0, 0.01, 0.1)
    assert s.unit_text("reference") == "0.01 Hz" and s.unit_text("feedback") == "0.1 Hz"
    assert s.hz_to_raw(-30.0) == 3000                     # the sign travels in the command bits
    assert s.raw_to_hz(1, "reference") == 0.01
    assert s.hz_to_raw(1.0, "feedback") == 10
    assert FrequencyScale().raw_to_hz(600) == 60.0        # defaults: 0.1 Hz feedback, 0.01 Hz out
    assert FrequencyScale().hz_to_raw(60.0) == 6000


def test_percent_of_max_frequency():
    s = FrequencyScale(1, 60.0)
    assert s.unit_text("reference") == "0.01 % of max frequency"
    assert s.hz_to_raw(30.0) == 5000 and s.raw_to_hz(5000) == 30.0
    assert s.raw_to_hz(1) == 0.006                        # 60 Hz / 10000


@pytest.mark.parametrize("poles, rpm, hz", [(2, 3000, 50.0), (4, 1800, 60.0), (39, 120, 39.0)])
def test_rpm_with_o1_03_poles(poles, rpm, hz):
    s = FrequencyScale(poles, 60.0)
    assert s.unit_text("feedback") == f"1 r/min ({poles}-pole motor)"
    assert s.hz_to_raw(hz) == rpm and s.raw_to_hz(rpm) == hz


@pytest.mark.parametrize("o1_03, counts", [(40, 40), (12000, 2000), (39999, 9999)])
def test_user_units(o1_03, counts):
    s = FrequencyScale(o1_03, 60.0)
    assert s.unit_text("reference") == f"user units ({counts} counts = max frequency)"
    assert s.hz_to_raw(60.0) == counts and s.raw_to_hz(counts) == 60.0
    if counts % 2 == 0:
        assert s.hz_to_raw(30.0) == counts // 2


def test_user_units_with_zero_counts_fall_back_to_hz():
    # o1-03 = 10000: 0 counts at max frequency is no unit; the manual's Hz units apply
    s = FrequencyScale(10000, 60.0)
    assert s.unit_text("reference") == "0.01 Hz"
    assert s.hz_to_raw(60.0) == 6000


def test_default_word_order_is_big_endian_unsigned():
    # spec D1: big-endian by default; words are 0..0xFFFF (signedness is per field, §2.7)
    assert unpack_words(bytes.fromhex("0102 FFFF")) == [0x0102, 0xFFFF]


@pytest.mark.parametrize("word, signed", [(0xFFFF, -1), (0x8000, -32768), (0x7FFF, 32767), (1, 1),
                                          (0, 0)])
def test_signed_fields_are_twos_complement(word, signed):
    # §2.7 [DERIVED]: torque and analog words are two's complement
    from profidrive_cli.drives.yaskawa.codec import _s16
    assert _s16(word) == signed
