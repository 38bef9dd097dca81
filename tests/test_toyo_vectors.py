"""Toyo VF66 + PBUS66-Z: every "Test vectors" entry of the spec through the codec.

M1-M20 are the manual's own (configuration octets, control-word patterns, value encoding, error codes,
PNU numbers, diagnosis and date layouts); D1-D20 are derived by applying the manual's layouts and are
tested as such. Byte strings are in the documented (little-endian) word order. Each frame goes through
drives/toyo.decode_area and through profidrive_cli.drives.decode_area.
"""

import json
from pathlib import Path

import pytest

from profidrive_cli.dp.cfg import decode_cfg, io_sizes
from profidrive_cli.drives import decode_area as dispatch_decode
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives import toyo
from profidrive_cli.drives.profile import load_profile, load_profile_file

ROOT = Path(__file__).resolve().parent.parent
PROFILE_PATH = ROOT / "profiles" / "toyo-pbus66z.yaml"
P = load_profile_file(PROFILE_PATH)
PZD_IDLE = "76 04 00 00"            # control word 0x0476 + speed 0, to complete PPO1 frames


def h(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", ""))


def dec(layout, direction, hexstr, prof=P):
    a = toyo.decode_area(prof, layout, direction, h(hexstr))
    b = dispatch_decode(prof, layout, direction, h(hexstr))
    assert a == b
    json.dumps(a)
    assert a["text"] and all(isinstance(t, str) for t in a["text"])
    return a


def variant(tmp_path, **changes) -> object:
    """The profile with some top-level keys or parameter lines changed (a user's override)."""
    text = PROFILE_PATH.read_text(encoding="utf-8")
    for old, new in changes.items():
        assert old in text
        text = text.replace(old, new)
    f = tmp_path / "toyo-variant.yaml"
    f.write_text(text, encoding="utf-8")
    return load_profile_file(f)


# ---------------------------------------------------------------------------------------------
# profile
# ---------------------------------------------------------------------------------------------

def test_profile_identity_and_word_order():
    assert (P.name, P.aliases, P.family, P.ident, P.gsd) == ("toyo-pbus66z", ["toyo"], "toyo", 0x0BE7,
                                                             "TOYO0BE7.GSD")
    assert P.word_order == "little" and P.raw["diag_word_order"] == "big"
    assert "TOYO0BE7" in P.ident_placeholder
    assert load_profile("toyo").name == P.name
    assert P.raw["decisions"]
    assert len(P.alarms) == 32 and [a.number for a in P.alarms] == list(range(1, 33))


def test_parameter_table():
    assert [P.param(c).pnu for c in ("status-flag", "fault-flag-1", "dc-voltage", "motor-flux")] == \
        [680, 681, 688, 693]
    assert all(P.param(c).access == "stop" and P.param(c).pnu is None
               for c in ("J-00", "J-03", "J-08", "i-01", "b-10", "b-11", "C-00", "A-00"))
    assert (P.param("J-03").max, P.param("J-03").default, P.param("J-08").max) == (126, 2, 2)
    assert P.param("FH").pnu == 720 and P.param("TB15").pnu == 715


# M1-M7: configuration octets
@pytest.mark.parametrize("layout,cfg,out_words,in_words,pkw", [
    ("ppo1", "F3 F1", 6, 6, True), ("ppo2", "F3 F5", 10, 10, True), ("ppo3", "F1", 2, 2, False),
    ("ppo4", "F5", 6, 6, False), ("ppo5", "F3 F9", 14, 14, True),
    ("toyo", "E9 DF D1", 10, 18, True), ("toyo_plch", "EF DF D6", 16, 23, True)])
def test_m1_m7_chk_cfg(layout, cfg, out_words, in_words, pkw):
    lay = P.layouts[layout]
    assert lay.cfg == h(cfg) and lay.pkw == pkw
    inp, out = io_sizes(h(cfg))
    assert (out, inp) == (2 * out_words, 2 * in_words)
    assert (lay.output_len, lay.input_len) == (2 * out_words, 2 * in_words)
    assert all(m.consistent and m.words for m in decode_cfg(h(cfg)))
    assert toyo.toyo_config(P).layouts[layout].mode == (1 if layout.startswith("toyo") else 0)


# ---------------------------------------------------------------------------------------------
# control word patterns (M8-M12, D8-D11)
# ---------------------------------------------------------------------------------------------

def ctw(word: int) -> dict:
    return dec("ppo3", "request", f"{word & 0xFF:02X} {word >> 8:02X} 00 00")["control_word"]


def test_m8_off1_pattern():
    for w in (0x0406, 0x0476, 0x0436, 0x7C06 & ~0x0008 | 0x0406):     # XXXX X1XX XXXX X110, bit 3 = 0
        assert ctw(w)["command"].startswith("OFF1 normal stop (ready to switch on)")
    c = ctw(0x0406)
    assert c["word"] == 0x0406 and "master control valid" in " ".join(c["set"])


def test_m9_on_pattern():
    assert ctw(0x0407)["command"] == "ON (ready, run inhibited)"
    assert ctw(0x047F)["command"] == "RUN"


def test_m10_hazard_pattern():
    assert "runs as soon as bit 0 goes to 1" in ctw(0x040E)["command"]
    assert "runs as soon as" not in ctw(0x0406)["command"]


def test_m11_jog_priority():
    assert "forward jog (jog 1)" in ctw(0x0307 | 0x0400)["command"]          # bits 8 and 9: bit 8 wins
    assert "reverse jog (jog 2)" in ctw(0x0607)["command"]
    assert "jog bit ignored" in ctw(0x057F)["command"]                       # bits 4-6 = 1


def test_m12_d10_fault_acknowledge():
    assert dec("ppo3", "request", "76 04 00 00")["control_word"]["word"] == 0x0476
    c = dec("ppo3", "request", "F6 04 00 00")["control_word"]
    assert c["word"] == 0x04F6 and "fault acknowledge" in c["command"]
    z = dec("ppo3", "response", "78 02 00 00")["status_word"]
    assert z["state"] == "fault" and "fault" in z["set"]


def test_d8_start_sequence():
    assert [ctw(w)["command"] for w in (0x0476, 0x0477, 0x047F)] == [
        "OFF1 normal stop (ready to switch on)", "ON (ready, run inhibited)", "RUN"]
    assert dec("ppo3", "request", "76 04 00 00")["octets"] == "76 04 00 00"


@pytest.mark.parametrize("word,text", [
    (0x047E, "OFF1 normal stop"), (0x047D, "OFF2 coast stop"), (0x047B, "OFF3 quick stop"),
    (0x046F, "RUN with ramp inhibit (ARC = 0)"), (0x045F, "RUN with ramp stop (ARC held)"),
    (0x043F, "RUN with setpoint inhibit"), (0x007F, "master control invalid"),
    (0x0478, "OFF2 coast stop")])                    # OFF2 > OFF3 > OFF1
def test_d9_stops(word, text):
    assert ctw(word)["command"].startswith(text)


def test_d11_jog_words():
    assert "forward jog" in ctw(0x0507)["command"]
    assert "reverse jog" in ctw(0x0607)["command"]
    assert "forward jog" in ctw(0x0707)["command"]


def test_d12_status_words():
    z = dec("ppo3", "response", "37 06 00 00")["status_word"]
    assert z["word"] == 0x0637 and z["state"].startswith("S4")
    assert z["set"] == ["ready to switch on", "ready to run", "running", "no OFF2", "no OFF3",
                        "control requested (master commands valid)", "speed setpoint reached"]
    z = dec("ppo3", "response", "78 02 00 00")["status_word"]
    assert z["set"] == ["fault", "no OFF2", "no OFF3", "switch-on inhibited",
                        "control requested (master commands valid)"]


# ---------------------------------------------------------------------------------------------
# values and scaling (M13, M20, D13-D16)
# ---------------------------------------------------------------------------------------------

def test_m13_value_without_decimal_point(tmp_path):
    a00 = P.param("A-00")
    assert toyo.wire_from_value(P, a00, 15.0) == 150 == 0x0096
    assert pd.words_to_bytes([150], "little") == h("96 00")
    assert toyo.value_from_wire(P, a00, 0x0096) == 15.0


def test_d13_speed_words():
    assert pd.words_to_bytes([toyo.speed_word(P, 100)], "little") == h("20 4E")
    assert pd.words_to_bytes([toyo.speed_word(P, 50)], "little") == h("10 27")
    assert pd.words_to_bytes([toyo.speed_word(P, -50)], "little") == h("F0 D8")
    r = dec("ppo3", "request", "7F 04 F0 D8")
    assert r["reference"]["percent"] == -50.0 and r["reference"]["hz"] == -30.0


def test_d14_torque_and_m20_d15_date_words():
    r = dec("ppo2", "request", "00 00 00 00 00 00 00 00 7F 04 20 4E 88 13 19 0C 2D 0D 00 00")
    f = {x["field"]: x for x in r["fields"]}
    assert f["torque_ref"]["value"] == 100.0 and f["torque_ref"]["unit"] == "%"
    assert (f["month_day"]["month"], f["month_day"]["day"]) == (12, 25)
    assert (f["hour_minute"]["hour"], f["hour_minute"]["minute"]) == (13, 45)
    assert r["reference"]["percent"] == 100.0


def test_d16_output_voltage_by_class(tmp_path):
    r = dec("ppo1", "response", "B1 12 00 00 00 00 A0 0F 37 06 00 00")
    assert r["pkw"]["code"] == "output-voltage" and r["pkw"]["value"] == 200.0
    p400 = variant(tmp_path, **{"voltage_class: 200": "voltage_class: 400"})
    r = dec("ppo1", "response", "B1 12 00 00 00 00 A0 0F 37 06 00 00", prof=p400)
    assert r["pkw"]["value"] == 400.0


# ---------------------------------------------------------------------------------------------
# PKW: monitors, fault history, traceback, setting data, errors (M14-M18, D1-D7)
# ---------------------------------------------------------------------------------------------

def test_d1_monitor_read_dc_voltage(tmp_path):
    rq = dec("ppo1", "request", "B0 12 00 00 00 00 00 00 " + PZD_IDLE)["pkw"]
    assert (rq["ak"], rq["pnu"], rq["pnu_hex"], rq["code"]) == (1, 688, "0x2B0", "dc-voltage")
    busy = dec("ppo1", "response", "B0 02 00 00 00 00 00 00 37 06 00 00")["pkw"]
    assert busy["ak"] == 0 and "processing" in busy["ak_text"]
    ok = dec("ppo1", "response", "B0 12 00 00 00 00 0E 0B 37 06 00 00")["pkw"]
    assert (ok["ak"], ok["pwe"], ok["value"], ok["unit"]) == (1, 2830, 283.0, "V")
    p400 = variant(tmp_path, **{"voltage_class: 200": "voltage_class: 400"})
    assert dec("ppo1", "response", "B0 12 00 00 00 00 0E 0B 37 06 00 00", prof=p400)["pkw"]["value"] == 566.0


def test_d2_fault_history_newest():
    rq = dec("ppo1", "request", "D0 62 01 00 00 00 00 00 " + PZD_IDLE)["pkw"]
    assert (rq["ak"], rq["pnu"], rq["history_index"]) == (6, 720, 1)
    r = dec("ppo1", "response", "D0 42 01 00 00 00 12 01 78 02 00 00")
    hist = r["pkw"]["history"]
    assert (hist["code"], hist["name"], hist["mode"], hist["block"]) == (18, "COMM", 1, 1)
    assert hist["mode_text"] == "induction-motor vector"
    assert "COMM" in r["summary"]


def test_d3_history_word():
    hw = toyo.decode_history_word(P, 0x1207)
    assert (hw["code"], hw["name"], hw["mode"], hw["mode_text"], hw["block"]) == (7, "OL", 2, "ED-motor vector", 2)
    assert toyo.history_word(7, 2, 1) == 0x1207
    assert toyo.decode_history_word(P, 0xEC07)["code"] == 7          # undefined bits masked off
    assert toyo.protection(P, 40)[0] == "GAC40"


def test_d4_m14_empty_history_slot():
    rq = dec("ppo1", "request", "D0 62 06 00 00 00 00 00 " + PZD_IDLE)["pkw"]
    assert rq["history_index"] == 6
    pk = dec("ppo1", "response", "D0 72 06 00 00 00 65 00 78 02 00 00")["pkw"]
    assert (pk["ak"], pk["error"]) == (7, 101) and "no data" in pk["error_text"]


def test_m15_m16_error_codes():
    texts = {}
    for n in (0, 1, 2, 3, 101, 102):
        pk = dec("ppo1", "response", f"A8 72 00 00 00 00 {n:02X} 00 37 06 00 00")["pkw"]
        texts[n] = pk["error_text"]
    assert texts == {0: "PNU out of range", 1: "parameter is write-protected",
                     2: "value to write is out of range", 3: "IND (subindex) out of range",
                     101: "no data for this read (e.g. empty fault-history slot)", 102: "task ID not supported"}


def test_d5_traceback_read():
    rq = dec("ppo1", "request", "BC 62 0A 01 00 00 00 00 " + PZD_IDLE)["pkw"]
    assert (rq["ak"], rq["pnu"], rq["recording"], rq["point"]) == (6, 700, 1, 10)
    assert toyo.traceback_ind(1, 10) == 0x010A
    pk = dec("ppo1", "response", "BC 42 0A 01 00 00 35 09 37 06 00 00")["pkw"]
    assert (pk["ak"], pk["pwe"], pk["code"]) == (4, 2357, "TB00")
    assert pk["value"] == pytest.approx(100.0, abs=0.01)


def test_d6_m17_traceback_oldest_last_point():
    rq = dec("ppo1", "request", "CB 62 63 03 00 00 00 00 " + PZD_IDLE)["pkw"]
    assert (rq["pnu"], rq["recording"], rq["point"], rq["code"]) == (715, 3, 99, "TB15")
    assert toyo.traceback_ind(3, 99) == 0x0363 and toyo.decode_traceback_ind(0x0363) == (3, 99)


def test_d7_setting_write_second_block():
    r = dec("ppo1", "request", "05 24 00 00 00 00 96 00 " + PZD_IDLE)
    pk = r["pkw"]
    assert (pk["pke"], pk["ak"], pk["pnu"], pk["block"], pk["pwe"]) == (0x2405, 2, 5, 2, 150)
    assert "2nd setting block" in pk["text"] and "150" in pk["value_text"]
    ok = dec("ppo1", "response", "05 14 00 00 00 00 96 00 37 06 00 00")["pkw"]
    assert (ok["ak"], ok["pwe"]) == (1, 150)


def test_m18_pnu_numbers():
    mons = {p.pnu: p for p in P.parameters.values() if p.pnu and 677 <= p.pnu <= 698}
    assert sorted(mons) == list(range(677, 699))
    assert hex(677) == "0x2a5" and hex(698) == "0x2ba"
    tbs = {p.pnu for p in P.parameters.values() if p.extra.get("traceback")}
    assert tbs == set(range(700, 716)) and hex(700) == "0x2bc" and hex(715) == "0x2cb"
    assert P.param("FH").pnu == 720 == 0x2D0
    assert dec("ppo1", "request", "D0 62 01 00 00 00 00 00 " + PZD_IDLE)["pkw"]["pnu_hex"] == "0x2D0"


# ---------------------------------------------------------------------------------------------
# diagnosis, flag words, mode 1 (M19, D17-D20)
# ---------------------------------------------------------------------------------------------

def test_m19_d19_diagnosis_block():
    assert toyo.decode_diag(P, b"")["length"] == 0
    assert toyo.decode_diag(P, b"\x00")["length"] == 0
    d = toyo.decode_diag(P, h("09 00 80 00 01 00 00 00 00"))
    assert d["length"] == 9
    assert d["status_flag"]["raw"] == 0x0080 and d["status_flag"]["set"] == ["power stage on"]
    assert d["fault_flag1"]["set"] == ["overcurrent"] and d["fault_flag2"]["raw"] == 0


def test_d17_fault_flags():
    frame = ("00 00 00 00 00 00 00 00 78 02 00 00 00 00 00 00 00 00 00 00 "
             "00 00 41 08 02 00 00 00")
    r = dec("ppo5", "response", frame)
    f = {x["field"]: x for x in r["fields"]}
    assert f["fault_flag1"]["set"] == ["overcurrent", "overload", "undervoltage (power failure)"]
    assert f["fault_flag2"]["set"] == ["communication timeout"]
    assert "communication timeout" in r["summary"]


@pytest.mark.parametrize("word,command,extra", [
    ("01 00", "run forward", {}), ("05 00", "run reverse", {"reverse": True}),
    ("20 00", "stop", {"reset": True}), ("C1 02", "run forward", {"preset_speed": 3, "accel_set": 2})])
def test_d18_mode1_run_command(word, command, extra):
    frame = "00 " * 8 + word + " 00 00" + " 00 00" * 4
    r = dec("toyo", "request", frame)
    rc = r["run_command"]
    assert rc["command"] == command
    for k, v in extra.items():
        assert rc[k] == v
    assert r["mode"] == 1


def test_run_command_ignored_bits_in_ppo5():
    frame = "00 " * 8 + "7F 04 10 27" + " 00 00" * 6 + " 05 00 00 00"
    r = dec("ppo5", "request", frame)
    assert r["run_command"]["note"].startswith("bits 0-2")
    assert r["control_word"]["command"] == "RUN"


def test_d20_mode0_ppo1_frame():
    r = dec("ppo1", "request", "00 00 00 00 00 00 00 00 7F 04 10 27")
    assert r["pkw"]["ak"] == 0
    assert r["control_word"]["word"] == 0x047F and r["reference"]["percent"] == 50.0


def test_mode1_response_frame():
    words = [0, 0, 0, 0, 0x0083, 0x0040, 0x0000, 0x0080, 10000, 10000, 150, 2500, 2830, 2000, 10000, 500,
             400, 1024]
    r = dec("toyo", "response", pd.words_to_bytes(words, "little").hex())
    f = {x["field"]: x for x in r["fields"]}
    assert f["status_flag"]["set"] == ["normal run command", "running", "power stage on"]
    assert f["fault_flag1"]["set"] == ["overload"]
    assert f["mf_output"]["set"] == ["setpoint reached"]
    assert f["motor_speed"]["percent"] == 50.0 and f["output_frequency"]["hz"] == 30.0
    assert f["current"]["value"] == 15.0 and f["dc_voltage"]["value"] == 283.0
    assert f["output_voltage"]["value"] == 100.0 and f["ol_counter"]["value"] == 5.0
    assert f["motor_temp"]["value"] == 40.0 and f["motor_flux"]["value"] == 100.0


def test_plch_frames(tmp_path):
    r = dec("toyo_plch", "request", ("00 " * 8) + "01 00 00 00" + " 34 12" * 10)
    names = [x["field"] for x in r["fields"]]
    assert names[:3] == ["run_cmd", "mf_input2", "i00010"] and names[-1] == "i00019"
    assert r["plch"] is True
    pl = variant(tmp_path, **{"\nplch: false": "\nplch: true"})
    r = dec("ppo2", "request", "00 " * 8 + "7F 04 34 12" + " 00 00" * 4, prof=pl)
    assert [x["field"] for x in r["fields"]][:2] == ["ctw", "i00010"]


def test_word_order_override(tmp_path):
    big = variant(tmp_path, **{"word_order: little": "word_order: big"})
    r = dec("ppo1", "request", "12 B0 00 00 00 00 00 00 04 7F 27 10", prof=big)
    assert r["pkw"]["pnu"] == 688 and r["control_word"]["word"] == 0x047F
    assert r["reference"]["percent"] == 50.0
