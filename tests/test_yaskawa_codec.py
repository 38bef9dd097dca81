"""Yaskawa SI-P1 codec: the spec's test vectors (../shared/spec/yaskawa-profibus-dp.md §11), the
derived word-level vectors (§11.9, not in the manual), decode_area on captured areas, and a property
test that decode_area never raises on areas of the right length."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from profidrive_cli import UsageError
from profidrive_cli.drives.profile import load_profile
from profidrive_cli.drives.yaskawa import (
    ERROR_CODES, FC_READ, FC_WRITE, FORMATS, FrequencyScale, ParamAccess, ParamArea, ParamRequest,
    decode_area, decode_command, decode_hs, decode_status, encode_command, encode_param_area,
    family_config, led_diagnosis, mfi_bit, pack_words, unpack_words)

EXT1, EXT2, BASIC = FORMATS["extended1"], FORMATS["extended2"], FORMATS["basic"]


@pytest.fixture(scope="module")
def prof():
    return load_profile("yaskawa-si-p1")


def h(text: str) -> bytes:
    return bytes.fromhex(text)


def area(fmt, pa: str, hs: int) -> bytes:
    """A parameter area from the manual's 6 printed fields + HS (spec §11 notation: the padding
    zeros - data 2-4, reserved - are our expansion)."""
    return h(pa).ljust(fmt.param_len - 1, b"\0") + bytes([hs])


STALE = "EE EE EE EE EE EE"   # "--" in the manual: response data to be ignored; junk proves it is


def run_vector(fmt, start_hs, request, steps, submit_at=1):
    """Step a ParamAccess through (master PA, master HS, drive PA, drive HS) rows; assert each master
    frame; return the result of the last feed."""
    pa = ParamAccess(fmt, timeout=1.0, hs=start_hs)
    now, result = 0.0, None
    for i, (m_pa, m_hs, d_pa, d_hs) in enumerate(steps):
        if i == submit_at:
            pa.submit(request, now)
        assert pa.outputs() == area(fmt, m_pa, m_hs), f"step {i + 1}"
        assert result is None, f"completed early, before step {i + 1}"
        now += 0.01
        result = pa.feed(area(fmt, d_pa if d_pa != "--" else STALE, d_hs), now)
    return result, pa


# --- §11.1 / §11.2 --------------------------------------------------------------------------------

def test_register_and_data_split_msb_first():
    # vectors 2 and 3: 0x1234 -> 12 34, 0x5678 -> 56 78
    a = encode_param_area(EXT2, ParamRequest.write(0x1234, [0x5678]), 0)
    assert a[1:3] == h("12 34") and a[4:6] == h("56 78")


def test_function_and_error_code_tables():
    assert (FC_READ, FC_WRITE) == (0x03, 0x10)
    assert set(ERROR_CODES) == {0x01, 0x02, 0x03, 0x21, 0x22}
    assert ERROR_CODES[0x21][0] == "data content error"
    assert ERROR_CODES[0x22][0] == "write fault"


@pytest.mark.parametrize("byte,expect", [
    (0x00, (0, 0, 0)), (0x20, (0, 1, 0)), (0x40, (0, 2, 0)), (0x60, (0, 3, 0)),
    (0x80, (1, 0, 0)), (0xA0, (1, 1, 0)), (0xC0, (1, 2, 0)), (0xE0, (1, 3, 0)),
    (0x62, (0, 3, 1)), (0x9E, (1, 0, 15)),          # derived cases with the watchdog counter
])
def test_response_handshake_byte(byte, expect):
    assert decode_hs(byte) == expect


def test_command_handshake_byte_uses_bit7_only():
    assert encode_param_area(EXT2, None, 1)[-1] == 0x80
    assert encode_param_area(EXT2, None, 0)[-1] == 0x00
    assert encode_param_area(EXT1, None, 1) == bytes(15) + b"\x80"


# --- §11.3 Appendix C.2: read ---------------------------------------------------------------------

READ_STEPS = [
    ("00 00 00 00 00 00", 0x80, "03 01 00 02 00 00", 0xE0),
    ("03 00 37 02 00 00", 0x80, "03 01 00 02 00 00", 0xE0),
    ("03 00 37 02 00 00", 0x00, "--", 0x00),
    ("03 00 37 02 00 00", 0x00, "--", 0x20),
    ("03 00 37 02 00 00", 0x00, "--", 0x40),
    ("03 00 37 02 00 00", 0x00, "03 00 37 02 00 15", 0x60),
]


@pytest.mark.parametrize("fmt", [EXT2, EXT1], ids=["6-word", "16-word"])
def test_appendix_c2_read(fmt):
    # step 1: the master has already set its HS to the response HS (1)
    result, _ = run_vector(fmt, 1, ParamRequest.read(0x0037), READ_STEPS)
    assert result is not None and result.ok and not result.timeout
    assert result.values == [0x0015]


def test_appendix_c2_full_images():
    # the 6W and 16W images of step 6 (spec §11.3)
    assert area(EXT2, "03 00 37 02 00 00", 0x00) == h("03 00 37 02 00 00 00 00")
    assert area(EXT1, "03 00 37 02 00 15", 0x60) == h("03 00 37 02 00 15 00 00 00 00 00 00 00 00 00 60")
    p = ParamArea.parse(EXT1, h("03 00 37 02 00 15 00 00 00 00 00 00 00 00 00 60"))
    assert (p.function, p.start, p.quantity, p.data[0], p.is_error) == (3, 0x37, 2, 0x15, False)


def test_power_up_clear_hs_then_realign_to_stale_response():
    # E11: a master that starts with HS cleared, facing the stale E0 of step 1, takes over HS 1 while
    # sending function code 00h, so the change starts no request
    pa = ParamAccess(EXT2, hs=0)
    assert pa.outputs() == area(EXT2, "00 00 00 00 00 00", 0x00)
    assert pa.feed(area(EXT2, "03 01 00 02 00 00", 0xE0), 0.01) is None
    assert pa.outputs() == area(EXT2, "00 00 00 00 00 00", 0x80)
    assert pa.realignments == 1


def test_request_waits_for_alignment_before_loading():
    pa = ParamAccess(EXT2, hs=0)
    pa.submit(ParamRequest.read(0x0037), 0.0)
    pa.feed(area(EXT2, "03 01 00 02 00 00", 0xE0), 0.01)        # realign to 1
    assert pa.outputs()[0] == 0x00                               # not loaded yet
    pa.feed(area(EXT2, "03 01 00 02 00 00", 0xE0), 0.02)        # aligned
    assert pa.outputs() == area(EXT2, "03 00 37 02 00 00", 0x80)  # loaded, HS unchanged
    pa.feed(area(EXT2, "03 01 00 02 00 00", 0xE0), 0.03)        # one settle cycle
    assert pa.outputs()[-1] == 0x00                              # toggled


def test_stale_complete_is_not_taken_as_the_answer():
    # a response with STATUS 11 but the old HS is stale (spec §4.7)
    pa = ParamAccess(EXT2, hs=1)
    pa.feed(area(EXT2, "03 01 00 02 00 00", 0xE0), 0.0)
    pa.submit(ParamRequest.read(0x0037), 0.0)
    pa.feed(area(EXT2, "03 01 00 02 00 00", 0xE0), 0.01)        # settle -> toggle to 0
    assert pa.feed(area(EXT2, "03 01 00 02 00 00", 0xE0), 0.02) is None   # still HS 1: stale


# --- §11.4 Appendix C.3: read error ---------------------------------------------------------------

READ_ERROR_STEPS = [
    ("00 00 00 00 00 00", 0x00, "03 01 00 02 00 00", 0x60),
    ("03 10 00 02 00 00", 0x00, "03 01 00 02 00 00", 0x60),
    ("03 10 00 02 00 00", 0x80, "--", 0x80),
    ("03 10 00 02 00 00", 0x80, "--", 0xA0),
    ("03 10 00 02 00 00", 0x80, "--", 0xC0),
    ("03 10 00 02 00 00", 0x80, "83 00 00 02 00 02", 0xE0),
]


@pytest.mark.parametrize("fmt", [EXT2, EXT1], ids=["6-word", "16-word"])
def test_appendix_c3_read_error(fmt):
    result, _ = run_vector(fmt, 0, ParamRequest.read(0x1000), READ_ERROR_STEPS)
    assert result is not None and not result.ok
    assert result.error_code == 0x02                 # address error; reply address 0000 not checked
    assert "address error" in result.message


# --- §11.5 Appendix C.4: write --------------------------------------------------------------------

# E12: step 1 master HS is printed with the label 1000 0000 but the value 00h; the value is used.
# E13: step 2 drive HS is printed 00h after 60h; the HS bit is unchanged, so it is harmless.
WRITE_STEPS = [
    ("00 00 00 00 00 00", 0x00, "03 01 00 02 00 00", 0x60),
    ("10 01 05 02 00 01", 0x00, "03 01 00 02 00 00", 0x00),
    ("10 01 05 02 00 01", 0x80, "--", 0x80),
    ("10 01 05 02 00 01", 0x80, "--", 0xA0),
    ("10 01 05 02 00 01", 0x80, "--", 0xC0),
    ("10 01 05 02 00 01", 0x80, "10 01 05 02 00 00", 0xE0),
]


@pytest.mark.parametrize("fmt", [EXT2, EXT1], ids=["6-word", "16-word"])
def test_appendix_c4_write(fmt):
    result, _ = run_vector(fmt, 0, ParamRequest.write(0x0105, [0x0001]), WRITE_STEPS)
    assert result is not None and result.ok and result.values == []


# --- §11.6 Appendix C.5: write error --------------------------------------------------------------

# E14: the printed table is inconsistent (step 1 master HS 80 against drive 60; step 2 drive frame
# changes; step 6 master HS printed 80, labelled 0000 0000). We test the spec's consistent
# reconstruction: master HS 80, 80, 00, 00, 00, 00 and drive HS E0, E0, 00, 20, 40, 60.
WRITE_ERROR_RECONSTRUCTED = [
    ("00 00 00 00 00 00", 0x80, "03 00 37 02 00 00", 0xE0),
    ("10 10 00 02 00 01", 0x80, "03 00 37 02 00 00", 0xE0),
    ("10 10 00 02 00 01", 0x00, "--", 0x00),
    ("10 10 00 02 00 01", 0x00, "--", 0x20),
    ("10 10 00 02 00 01", 0x00, "--", 0x40),
    ("10 10 00 02 00 01", 0x00, "90 00 00 02 00 22", 0x60),
]


@pytest.mark.parametrize("fmt", [EXT2, EXT1], ids=["6-word", "16-word"])
def test_appendix_c5_write_error_reconstructed(fmt):
    result, _ = run_vector(fmt, 1, ParamRequest.write(0x1000, [0x0001]), WRITE_ERROR_RECONSTRUCTED)
    assert result is not None and not result.ok
    # E15: decoded literally as printed, 0x22 write fault (not generalised to "0x1000 gives 0x22")
    assert result.error_code == 0x22


def test_appendix_c5_printed_step1_is_a_realignment():
    # printed step 1: master HS 80 against response 60 -> not synchronised; the master takes HS 0
    pa = ParamAccess(EXT2, hs=1)
    pa.feed(area(EXT2, "03 01 00 02 00 00", 0x60), 0.01)
    assert pa.outputs() == area(EXT2, "00 00 00 00 00 00", 0x00)
    assert pa.realignments == 1


def test_final_write_error_images(prof):
    # reconstructed final frames (spec §11.6) decoded through decode_area
    r = decode_area(prof, "extended2", "response", bytes(4) + h("90 00 00 02 00 22 00 60"))
    pa = r["parameter_access"]
    assert pa["error"] is True and pa["error_code"] == 0x22 and pa["error_name"] == "write fault"
    assert pa["handshake"]["complete"] and pa["handshake"]["hs"] == 0
    r = decode_area(prof, "extended1", "response",
                    bytes(16) + h("90 00 00 02 00 22 00 00 00 00 00 00 00 00 00 60"))
    assert r["parameter_access"]["error_code"] == 0x22


def test_timeout_when_status_never_reaches_11():
    pa = ParamAccess(EXT2, timeout=0.3, hs=0)
    pa.feed(area(EXT2, "00 00 00 00 00 00", 0x00), 0.0)
    pa.submit(ParamRequest.read(0x0037), 0.0)
    result, t = None, 0.0
    while result is None and t < 1.0:
        t += 0.01
        result = pa.feed(area(EXT2, "00 00 00 00 00 00", 0x00 if t < 0.02 else 0x40), t)
    assert result is not None and result.timeout and 0.3 < t < 0.32
    assert "watchdog counter is frozen" in result.message      # WD bits never moved
    assert not pa.busy


# --- §11.7 error-response field positions ---------------------------------------------------------

def test_error_field_positions(prof):
    img16 = bytearray(32)
    img16[16], img16[19], img16[21], img16[31] = 0x83, 0x02, 0x02, 0xE0
    r = decode_area(prof, "extended1", "response", bytes(img16))
    assert r["parameter_access"]["error_code"] == 0x02
    assert r["parameter_access"]["function_name"] == "read error"
    img6 = bytearray(12)
    img6[4], img6[7], img6[9], img6[11] = 0x90, 0x02, 0x21, 0x60
    r = decode_area(prof, "extended2", "response", bytes(img6))
    assert r["parameter_access"]["error_code"] == 0x21
    assert r["parameter_access"]["function_name"] == "write error"


# --- §11.8 configuration --------------------------------------------------------------------------

def test_layouts_cfg_and_sizes(prof):
    got = {n: (lay.cfg.hex(" ").upper(), lay.input_len, lay.output_len, lay.pkw)
           for n, lay in prof.layouts.items()}
    assert got == {"basic": ("72", 6, 6, False), "extended1": ("5F 6F", 32, 32, True),
                   "extended2": ("55 65", 12, 12, True)}
    assert (EXT1.max_registers, EXT2.max_registers, BASIC.has_params) == (4, 1, False)
    assert prof.ident == 0x00CA and prof.gsd == "YASK00CA.GSD" and prof.default_layout == "extended1"


def test_b1_01_b1_02_value_tables(prof):
    b101 = prof.param("b1-01").extra["values"]
    b102 = prof.param("b1-02").extra["values"]
    assert b101[3].startswith("option card") and b102[3].startswith("option card")
    assert b101[4].startswith("pulse input") and 4 not in b102


def test_led_interpreter(prof):
    assert led_diagnosis(prof, "green", "green", "off", "green-flash")["condition"] == "Normal"
    assert led_diagnosis(prof, "green", "off", "red", "red-flash")["condition"] == "Drive error"
    assert led_diagnosis(prof, "off", "off", "off", "off")["condition"] == "Power off"
    assert led_diagnosis(prof, "green", "red", "red", "red")["condition"] == "Unspecified option error"


# --- §11.9 derived vectors (not in the manual; from the bit tables) -------------------------------

@pytest.mark.parametrize("flags,word", [
    ({"forward_run": True}, 0x0001), ({"reverse_run": True}, 0x0002),
    ({"external_fault": True}, 0x0100), ({"fault_reset": True}, 0x0200),
    ({"external_base_block": True}, 0x8000), ({"forward_run": True, "mfi3": True}, 0x0005),
    ({"clear_error_log": True}, 0x4000), ({"mfi12": True}, 0x2000),
])
def test_derived_command_words(flags, word):
    assert encode_command(**flags) == word
    assert {k for k, v in decode_command(word).items() if v} == set(flags)


def test_derived_command_bytes_word_order():
    # D1: (A) big-endian default 00 01; (B) little 01 00
    assert pack_words([0x0001], "big") == h("00 01")
    assert pack_words([0x0001], "little") == h("01 00")
    assert unpack_words(h("04 21"), "big") == [0x0421]


def test_mfi_bits():
    assert [mfi_bit(n) for n in range(3, 13)] == [2, 3, 4, 5, 6, 7, 10, 11, 12, 13]
    with pytest.raises(ValueError):
        mfi_bit(2)


@pytest.mark.parametrize("word,on", [
    (0x0421, {"running", "ready", "remote"}), (0x0080, {"fault"}), (0x0100, {"ope_error"}),
    (0x4000, {"motor2_selected"}), (0x8000, {"zero_servo_complete"}),
    (0x0214, {"reverse", "frequency_agree", "fault_restart"}),
])
def test_derived_status_words(word, on):
    assert {k for k, v in decode_status(word).items() if v} == on


def test_derived_frequency_scaling():
    s = FrequencyScale(0, 60.0, 0.01, 0.1)
    assert s.hz_to_raw(60.0, "reference") == 6000 == 0x1770           # D11
    assert pack_words([s.hz_to_raw(60.0)]) == h("17 70")
    assert s.raw_to_hz(6000, "feedback") == 600.0                       # the same count read at 0.1 Hz
    assert s.raw_to_hz(600, "feedback") == 60.0
    pct = FrequencyScale(1, 50.0)
    assert pct.hz_to_raw(25.0) == 5000 and pct.raw_to_hz(10000) == 50.0  # o1-03 = 1: 0.01 %
    rpm = FrequencyScale(4, 60.0)
    assert rpm.hz_to_raw(50.0) == 1500                                  # 4 poles: 1500 r/min


def test_derived_output_current(prof):
    # D12: raw 4096 with a 10.0 A rating -> 5.0 A (rating / 8192 per count)
    p = replace(prof)                      # a copy: the family config is cached per object
    family_config(p).rated_current_a = 10.0
    r = decode_area(p, "basic", "response", h("00 00 00 00 10 00"))
    assert r["output_current"] == {"raw": 4096, "percent_of_rating": 50.0, "amps": 5.0}
    assert "amps" not in decode_area(prof, "basic", "response", h("00 00 00 00 10 00"))["output_current"]


def test_derived_multi_register_write_16w():
    # D13 / E4: write(0x0100, [1, 2]) -> data words at bytes 20-23, data 3-4 zero
    a = encode_param_area(EXT1, ParamRequest.write(0x0100, [0x0001, 0x0002]), 1)
    assert a == h("10 01 00 04 00 01 00 02 00 00 00 00 00 00 00 80")


def test_request_limits_per_layout():
    with pytest.raises(UsageError):
        ParamAccess(EXT2).submit(ParamRequest.read(0x0100, 2), 0.0)     # 6-word: one register
    ParamAccess(EXT1).submit(ParamRequest.read(0x0100, 4), 0.0)         # 16-word: up to four
    with pytest.raises(UsageError):
        ParamAccess(EXT1).submit(ParamRequest.read(0x0100, 5), 0.0)


# --- decode_area on captured areas ----------------------------------------------------------------

def test_decode_request_extended1(prof):
    data = h("00 01 17 70 00 00 00 00 00 00 00 00 00 00 00 00"
             "03 03 03 02 00 00 00 00 00 00 00 00 00 00 00 80")
    r = decode_area(prof, "extended1", "request", data)
    json.dumps(r)
    assert r["command"]["flags"]["forward_run"] and r["command"]["raw"] == 1
    assert r["frequency_reference"]["hz"] == 60.0
    pa = r["parameter_access"]
    assert (pa["function_name"], pa["start_register"], pa["handshake"]["hs"]) == ("read", 0x0303, 1)
    assert any("E1-04" in line for line in r["text"])


def test_decode_response_extended1(prof):
    data = h("04 31 02 58 00 00 00 00 02 58 02 58 10 00 00 00"
             "03 03 03 02 02 58 00 00 00 00 00 00 00 00 00 E2")
    r = decode_area(prof, "extended1", "response", data)
    json.dumps(r)
    assert r["status"]["flags"]["running"] and r["status"]["flags"]["frequency_agree"]
    assert r["speed_feedback"]["hz"] == 60.0 and r["output_frequency"]["hz"] == 60.0
    assert r["output_current"]["percent_of_rating"] == 50.0
    pa = r["parameter_access"]
    assert pa["values"] == [600] and pa["handshake"] == {
        "raw": 0xE2, "hs": 1, "status": 3, "status_name": "response received", "wd": 1, "complete": True}
    assert any("0x0303 (E1-04) = 0x0258 (600)" in line for line in r["text"])


def test_decode_basic_and_little_endian_override(prof):
    r = decode_area(prof, "basic", "request", h("01 00 70 17 00 00"))
    assert r["command"]["raw"] == 0x0100           # big: bytes 01 00 = external fault bit
    p2 = replace(prof, word_order="little")
    r = decode_area(p2, "basic", "request", h("01 00 70 17 00 00"))
    assert r["command"]["raw"] == 0x0001 and r["frequency_reference"]["raw"] == 0x1770
    assert r["command"]["flags"]["forward_run"]


def test_decode_wrong_length_and_layout(prof):
    with pytest.raises(UsageError, match="12 octets"):
        decode_area(prof, "extended2", "request", bytes(11))
    with pytest.raises(UsageError, match="no layout"):
        decode_area(prof, "ppo1", "request", bytes(12))


def test_decode_flags_invalid_quantity_and_function(prof):
    r = decode_area(prof, "extended2", "request", bytes(4) + h("03 01 80 04 00 00 00 00"))
    assert any("answers 0x03" in line for line in r["text"])
    r = decode_area(prof, "extended2", "request", bytes(4) + h("06 01 80 02 00 00 00 00"))
    assert any("invalid" in line for line in r["text"])


@settings(max_examples=300, deadline=None)
@given(layout=st.sampled_from(["basic", "extended1", "extended2"]),
       direction=st.sampled_from(["request", "response"]), data=st.data())
def test_decode_area_never_raises_on_right_length(layout, direction, data):
    prof = load_profile("yaskawa-si-p1")
    raw = data.draw(st.binary(min_size=FORMATS[layout].size, max_size=FORMATS[layout].size))
    r = decode_area(prof, layout, direction, raw)
    json.dumps(r)
    assert isinstance(r["text"], list) and all(isinstance(t, str) for t in r["text"])
