"""drives/toyo/codec.py: the cases mutation testing found untested (issue 20).

Expected values from ../shared/spec/toyo-vf66-pbus66z.md: speed words 20000 = A-00 (§4, formulas
raw = round(value / A00 * 20000)), the mode-0 control word (§3.1 Table 3.5, priority OFF2 > OFF3 >
OFF1, jog only with bits 4-6 = 0 and bit 8 winning over bit 9, §3.3), the run-command word
(§3.4 Table 3.7) and the fault-history word (bits 0-7 code, 8-9 mode, 12 setting block).
"""

import pytest

from profidrive_cli.drives.profile import load_profile
from profidrive_cli.drives.toyo import codec as C

P = load_profile("toyo-pbus66z")


def test_speed_words_and_clamp():
    assert C.speed_word(P, 100) == 20000
    assert C.speed_word(P, 0.005) == 1
    assert C.speed_word(P, -0.005) == 0xFFFF
    assert C.speed_word(P, 200) == 0x7FFF                 # 40000 does not fit: clamped
    assert C.speed_word(P, -200) == 0x8000
    assert C.speed_percent(P, 20000) == 100.0
    assert C.speed_percent(P, 0xD8F0) == -50.0            # -10000
    assert C.speed_percent(P, 1) == 0.005


def test_protection_names():
    assert C.protection(P, 7)[0] == P.alarms_for(7)[0].code
    assert C.protection(P, 33) == ("GAC33", "GAC protection 33 (GAC-equipped models; see the model's manual)")
    assert C.protection(P, 0) == ("?0", "unknown protection code 0")


def test_history_word_fields():
    assert C.history_word(0x1FF, 4, 2) == 0x00FF           # each field masked to its width
    assert C.history_word(7, 3, 1) == 0x1307
    d = C.decode_history_word(P, 0x1307)
    assert (d["code"], d["mode"], d["mode_text"], d["block"]) == (7, 3, "unused", 2)
    assert d["word"] == 0x1307
    name, meaning = C.protection(P, 7)
    assert d["name"] == name and d["meaning"] == meaning
    assert d["text"] == f"protection 7 {name} ({meaning}); inverter mode unused; setting block 2"
    d0 = C.decode_history_word(P, 0x0001)
    assert (d0["mode"], d0["mode_text"], d0["block"]) == (0, "V/f", 1)


def test_traceback_ind_limits():
    assert C.traceback_ind(3, 255) == 0x03FF and C.traceback_ind(0, 0) == 0
    for rec, point in ((4, 0), (-1, 0), (0, 256), (0, -1)):
        with pytest.raises(ValueError) as e:
            C.traceback_ind(rec, point)
        assert str(e.value) == "recording must be 0..3 and point 0..255"
    assert C.decode_traceback_ind(0xFF63) == (3, 0x63)


def test_bit_names():
    assert C.bit_names(P, "ctw", 0x0003) == ["ON (0 = OFF1: normal stop)", "no OFF2 (0 = coast stop)"]
    assert C.bit_names(P, "no-such-table", 0x8001) == ["bit 0", "bit 15"]
    assert C.bit_names(P, "no-such-table", 0x10000) == []


@pytest.mark.parametrize("word, on", [
    (0x0001, {"run"}), (0x0002, {"jog"}), (0x0004, {"reverse"}), (0x0008, {"initial_excitation"}),
    (0x0010, {"dc_brake"}), (0x0020, {"reset"}), (0x0800, {"speed_up"}), (0x1000, {"speed_down"}),
    (0x2000, {"speed_hold"}), (0x4000, {"s_curve_inhibit"}), (0x8000, {"max_speed_reduction"}),
])
def test_run_cmd_flags(word, on):
    f = C.run_cmd_fields(word)
    assert {k for k, v in f.items() if v is True} == on
    assert f["preset_speed"] == 0 and f["accel_set"] == 1


@pytest.mark.parametrize("word, preset, accel", [
    (0x0040, 1, 1), (0x01C0, 7, 1), (0x0200, 0, 2), (0x0600, 0, 4), (0x0180, 6, 1),
])
def test_run_cmd_fields(word, preset, accel):
    f = C.run_cmd_fields(word)
    assert (f["preset_speed"], f["accel_set"]) == (preset, accel)
    assert not any(v is True for v in f.values())


@pytest.mark.parametrize("word, text", [
    (0x0076, "master control invalid (bit 10 = 0: the previous command is kept)"),
    (0x047D, "OFF2 coast stop"),
    (0x0479, "OFF2 coast stop"),                                       # OFF2 and OFF3: OFF2 wins
    (0x047B, "OFF3 quick stop"),
    (0x047A, "OFF3 quick stop"),                                       # OFF3 and OFF1: OFF3 wins
    (0x040E, "OFF1 normal stop (bit 3 = 1: runs as soon as bit 0 goes to 1)"),
    (0x0406, "OFF1 normal stop (ready to switch on)"),
    (0x0477, "ON (ready, run inhibited)"),
    (0x047F, "RUN"),
    (0x046F, "RUN with ramp inhibit (ARC = 0)"),
    (0x045F, "RUN with ramp stop (ARC held)"),
    (0x043F, "RUN with setpoint inhibit"),
    (0x040F, "RUN with ramp inhibit (ARC = 0), ramp stop (ARC held), setpoint inhibit"),
    (0x050F, "RUN with ramp inhibit (ARC = 0), ramp stop (ARC held), setpoint inhibit; "
             "forward jog (jog 1)"),
    (0x0707, "ON (ready, run inhibited); forward jog (jog 1)"),         # bit 8 wins over bit 9
    (0x0607, "ON (ready, run inhibited); reverse jog (jog 2)"),
    (0x057F, "RUN; jog bit ignored (needs bits 4-6 = 0)"),
    (0x054F, "RUN with ramp inhibit (ARC = 0), ramp stop (ARC held); jog bit ignored (needs bits 4-6 = 0)"),
    (0x052F, "RUN with ramp inhibit (ARC = 0), setpoint inhibit; jog bit ignored (needs bits 4-6 = 0)"),
    (0x051F, "RUN with ramp stop (ARC held), setpoint inhibit; jog bit ignored (needs bits 4-6 = 0)"),
    (0x04F6, "OFF1 normal stop (ready to switch on); fault acknowledge"),
])
def test_ctw_command(word, text):
    assert C.ctw_command(word) == text


@pytest.mark.parametrize("word", [0x0506, 0x050D, 0x050B])
def test_no_jog_without_on_or_with_off2_off3(word):
    # jog runs from the run-command state (§3.3): not in OFF1 (bit 0 = 0), OFF2 or OFF3
    assert "jog (jog" not in C.ctw_command(word)


def test_history_word_defaults_and_unnamed_modes():
    assert C.history_word(7) == 0x0007                     # mode 0 (V/f), 1st setting block
    from dataclasses import replace

    from profidrive_cli.drives.toyo.config import toyo_config
    p = replace(P)
    toyo_config(p).history_modes = {0: "V/f"}              # a profile naming only mode 0
    d = C.decode_history_word(p, 0x0207)
    assert d["mode_text"] == "2" and "; inverter mode 2; setting block 1" in d["text"]
