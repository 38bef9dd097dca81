"""Fuji OPC-G1-PDP and OPC-PDP3: every "Test vectors" entry of both specs through the codec.

The chapter-7 PPO3 frames and the chapter-8 PKW examples are the manual's own (bytes for the PPO3 frames,
field values for the PKW ones, serialised big-endian as the specs state); the PNU947 index bytes, C05,
the PNU963 codes and the scaling rows are derived from the stated rules. Each vector goes through
drives/fuji.decode_area and through profidrive_cli.drives.decode_area (the family dispatch).
"""

from pathlib import Path

import pytest

from profidrive_cli.drives import decode_area as dispatch_decode
from profidrive_cli.drives import fuji
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.profile import load_profile, load_profile_file

ROOT = Path(__file__).resolve().parent.parent
G1 = load_profile_file(ROOT / "profiles" / "fuji-opc-g1-pdp.yaml")
PDP3 = load_profile_file(ROOT / "profiles" / "fuji-opc-pdp3.yaml")
BOTH = pytest.mark.parametrize("prof", [G1, PDP3], ids=["g1", "pdp3"])

IDLE_PZD = "04 7E 40 00"       # a CTW/MRV pair to complete PPO1 frames around the PKW vectors


def h(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", ""))


def both(prof, layout, direction, hexstr):
    """Decode with the family module and with the dispatcher; both must agree."""
    a = fuji.decode_area(prof, layout, direction, h(hexstr))
    b = dispatch_decode(prof, layout, direction, h(hexstr))
    assert a == b
    assert a["text"] and all(isinstance(t, str) for t in a["text"])
    import json
    json.dumps(a)          # JSON-serialisable
    return a


# ---------------------------------------------------------------------------------------------
# profiles
# ---------------------------------------------------------------------------------------------

@BOTH
def test_profile_loads_with_identity_and_layouts(prof):
    assert prof.family == "fuji"
    assert prof.word_order == "big"
    assert prof.ident_placeholder and "GSD" in prof.ident_placeholder
    assert {n: l.cfg.hex(" ").upper() for n, l in prof.layouts.items()} == {
        "ppo1": "F3 F1", "ppo2": "F3 F5", "ppo3": "F1", "ppo4": "F5"}
    assert (prof.layouts["ppo1"].input_len, prof.layouts["ppo2"].input_len,
            prof.layouts["ppo3"].input_len, prof.layouts["ppo4"].input_len) == (12, 20, 4, 12)
    assert prof.max_frequency_param == "F03"
    assert prof.raw["decisions"]


def test_identity_table():
    assert (G1.name, G1.aliases, G1.ident, G1.gsd) == \
        ("fuji-opc-g1-pdp", ["fuji-g1"], 0xFD01, "FUJIFD01.GSD")
    assert (PDP3.name, PDP3.aliases, PDP3.ident, PDP3.gsd) == ("fuji-opc-pdp3", ["fuji-pdp3"], 0xFD02,
                                                               "FUJIFD02.GSD")
    assert load_profile("fuji-g1").name == G1.name and load_profile("fuji-pdp3").name == PDP3.name


@BOTH
def test_parameter_table(prof):
    p = prof.param
    assert (p("F03").pnu, p("F03").index, p("F03").unit, p("F03").access) == (0x104, 3, "Hz", "stop")
    assert (p("F26").pnu, p("F26").index) == (0x104, 0x1A)
    assert (p("E31").pnu, p("E31").index) == (0x105, 0x1F)
    assert (p("H56").pnu, p("H56").index) == (0x108, 0x38)
    assert (p("y98").pnu, p("y98").index, p("y98").max) == (0x10F, 0x62, 3)
    assert (p("o27").pnu, p("o27").index, p("o27").max) == (0x10A, 0x1B, 15)
    assert (p("o28").pnu, p("o28").index, p("o28").max, p("o28").unit) == (0x10A, 0x1C, 60.0, "s")
    assert (p("o30").pnu, p("o30").index, p("o30").extra["power_cycle"]) == (0x10A, 0x1E, True)
    assert [p(f"o{n}").index for n in range(40, 44)] == [0x28, 0x29, 0x2A, 0x2B]
    assert [p(f"o{n}").index for n in range(48, 52)] == [0x30, 0x31, 0x32, 0x33]
    assert (p("W90").pnu, p("W90").index, p("W90").access) == (0x110, 0x5A, "ro")
    assert [(p(f"M{n}").pnu, p(f"M{n}").index) for n in range(16, 20)] == \
        [(0x103, 0x10), (0x103, 0x11), (0x103, 0x12), (0x103, 0x13)]
    assert (p("S06").pnu, p("S06").index, p("S19").index) == (0x102, 6, 0x13)
    assert p("PNU947").extra["array"] == 32 and p("PNU947").access == "ro"
    assert p("PNU918").access == "ro" and p("PNU927").access == "rw"
    assert (p("y97") is not None) == (prof is PDP3)
    assert (p("o32") is not None) == (prof is PDP3)


@BOTH
def test_alarm_table_and_shared_codes(prof):
    assert len([a for a in prof.alarms if a.code != "OH6"]) == 42
    by = {a.code: a for a in prof.alarms}
    assert by["OC1"].number == 0x2301 and fuji.mcode_of(prof, "OC1") == 1
    assert by["Er5"].number == 0x7511 and fuji.mcode_of(prof, "Er5") == 35
    assert by["Err"].number == 0xFF00 and fuji.mcode_of(prof, "Err") == 254
    shared = {0x4310: ["OH1", "OH4"], 0x2212: ["OL2", "OL3", "OL4"], 0x7520: ["Er2", "ErP"],
              0x5220: ["Er3", "ErH"], 0x7200: ["Er7", "CoF"]}
    for num, codes in shared.items():
        assert [a.code for a in fuji.alarm_candidates(prof, num)] == codes
    assert fuji.alarm_by_mcode(prof, 44).code == "OL3"


@BOTH
def test_function_code_group_table(prof):
    fc = fuji.fuji_config(prof)
    groups = {"S": 2, "M": 3, "F": 4, "E": 5, "C": 6, "P": 7, "H": 8, "A": 9, "o": 10, "r": 12, "J": 14,
              "y": 15, "W": 16, "X": 17, "Z": 18, "b": 19, "d": 20}
    for g, c in groups.items():
        assert fc.groups[g] == c
        assert fuji.parse_function_code(prof, f"{g}01")[2] == 0x100 + c
    extra = {"L": 11, "U": 13, "W1": 23, "K": 29, "T": 30, "H1": 32, "J1": 36, "J6": 41, "d1": 42}
    for g, c in extra.items():
        assert (fc.groups.get(g) == c) == (prof is PDP3)


# ---------------------------------------------------------------------------------------------
# chapter 7 process data (PPO3), G1 TV1-TV8 / PDP3 vectors 1-8
# ---------------------------------------------------------------------------------------------

@BOTH
def test_tv1_power_on_idle(prof):
    rq = both(prof, "ppo3", "request", "00 00 00 00")
    assert rq["control_word"]["word"] == 0 and rq["reference"]["hz"] == 0.0
    assert "bit 10 = 0" in rq["control_word"]["command"]
    r = both(prof, "ppo3", "response", "02 40 00 00")
    sw = r["status_word"]
    assert sw["word"] == 0x0240 and sw["state"].startswith("S1")
    assert set(sw["set"]) == {"R/L (PROFIBUS commands active)", "not ready for run-ON (switch-on inhibited)"}
    assert r["actual"]["hz"] == 0.0


@BOTH
def test_tv2_ready_request_60hz(prof):
    rq = both(prof, "ppo3", "request", "04 7E 40 00")
    cw = rq["control_word"]
    assert cw["word"] == 0x047E
    assert [b["bit"] for b in cw["bits"] if b["set"]] == [1, 2, 3, 4, 5, 6, 10]
    assert cw["command"].startswith("OFF1")
    assert rq["reference"]["hz"] == 60.0 and rq["reference"]["percent"] == 100.0
    r = both(prof, "ppo3", "response", "02 31 00 00")
    assert r["status_word"]["state"].startswith("S2")
    assert [b["bit"] for b in r["status_word"]["bits"] if b["set"]] == [0, 4, 5, 9]


@BOTH
def test_tv3_run_forward(prof):
    rq = both(prof, "ppo3", "request", "04 7F 40 00")
    assert rq["control_word"]["word"] == 0x047F and rq["control_word"]["command"] == "operate"
    assert rq["control_word"]["direction"] == "forward"
    for mav in ("00 00", "12 34"):          # "** **" in the manual: accelerating, any value
        r = both(prof, "ppo3", "response", "02 37 " + mav)
        assert r["status_word"]["state"].startswith("S4")
        assert [b["bit"] for b in r["status_word"]["bits"] if b["set"]] == [0, 1, 2, 4, 5, 9]


@BOTH
def test_tv4_ramp_stop(prof):
    rq = both(prof, "ppo3", "request", "04 7E 40 00")
    assert rq["control_word"]["word"] & 1 == 0
    dec = both(prof, "ppo3", "response", "02 33 20 00")      # decelerating: MAV not 0
    assert dec["status_word"]["state"].startswith("S5")
    assert "S3 and S5" in dec["status_word"]["note"]
    assert both(prof, "ppo3", "response", "02 33 00 00")["status_word"]["state"].startswith("S3")
    assert both(prof, "ppo3", "response", "02 31 00 00")["status_word"]["state"].startswith("S2")


@BOTH
def test_tv5_reverse_by_direction_bit(prof):
    rq = both(prof, "ppo3", "request", "0C 7F 20 00")
    assert rq["control_word"]["word"] == 0x0C7F
    assert any(b["bit"] == 11 and b["set"] and b["name"] == "reverse" for b in rq["control_word"]["bits"])
    assert rq["control_word"]["direction"] == "reverse"
    assert rq["reference"]["hz"] == 30.0
    r = both(prof, "ppo3", "response", "03 37 E0 00")
    sw = r["status_word"]
    assert sw["state"].startswith("S4") and "FAR (frequency arrival)" in sw["set"]
    assert "FDT (frequency >= E31)" not in sw["set"]
    assert r["actual"]["hz"] == -30.0 and r["actual"]["raw"] == 0xE000


@BOTH
def test_tv6_reverse_by_negative_reference(prof):
    rq = both(prof, "ppo3", "request", "04 7F E0 00")
    assert rq["control_word"]["word"] == 0x047F
    assert rq["reference"]["hz"] == -30.0 and rq["control_word"]["direction"] == "reverse"
    r = both(prof, "ppo3", "response", "03 37 E0 00")
    assert r["status_word"]["state"].startswith("S4") and r["actual"]["hz"] == -30.0


@BOTH
def test_tv7_fault_reset(prof):
    rq = both(prof, "ppo3", "request", "04 80 10 00")
    cw = rq["control_word"]
    assert cw["word"] == 0x0480
    assert [b["bit"] for b in cw["bits"] if b["set"]] == [7, 10]
    assert "fault acknowledge" in cw["command"]
    assert rq["reference"]["hz"] == 15.0
    r = both(prof, "ppo3", "response", "02 40 00 00")
    assert r["status_word"]["state"].startswith("S1")      # not "37 = running" (erratum)


@BOTH
def test_tv8_after_reset(prof):
    rq = both(prof, "ppo3", "request", "04 00 00 00")
    assert rq["control_word"]["word"] == 0x0400
    assert [b["bit"] for b in rq["control_word"]["bits"] if b["set"]] == [10]


# ---------------------------------------------------------------------------------------------
# chapter 8 PKW examples, G1 TV9-TV16 / PDP3 vectors 9-17 (PPO1 frames)
# ---------------------------------------------------------------------------------------------

@BOTH
def test_tv9_write_f26_request(prof):
    r = both(prof, "ppo1", "request", "21 04 1A 00 00 00 00 0F " + IDLE_PZD)
    pk = r["pkw"]
    assert (pk["ak"], pk["spm"], pk["pnu"], pk["subindex"], pk["pwe"]) == (2, 0, 0x104, 0x1A, 15)
    assert pk["function_code"] == "F26" and pk["code"] == "F26"
    assert pk["value"] == 15 and pk["unit"] == "kHz"
    assert "F26" in r["summary"] and "PNU 0x104, subindex 0x1A" in "\n".join(r["text"])
    assert r["control_word"]["word"] == 0x047E
    # the same octets come out of the core encoder for RC 2 / PNU 0x104 / subindex 26 / 15
    assert pd.words_to_bytes(pd.write_request(0x104, 15, 26).words()) == h("21 04 1A 00 00 00 00 0F")


@BOTH
def test_tv10_write_f26_ok_response(prof):
    pk = both(prof, "ppo1", "response", "11 04 1A 00 00 00 00 0F 02 31 00 00")["pkw"]
    assert (pk["ak"], pk["pnu"], pk["subindex"], pk["value"]) == (1, 0x104, 26, 15)
    assert pk["function_code"] == "F26"


@BOTH
def test_tv11_write_f26_out_of_range(prof):
    pk = both(prof, "ppo1", "response", "71 04 1A 00 00 00 00 02 02 31 00 00")["pkw"]
    assert (pk["ak"], pk["error"]) == (7, 2)
    assert pk["error_text"] == "value outside the setting range"


@BOTH
def test_tv12_tv13_read_y98(prof):
    rq = both(prof, "ppo1", "request", "11 0F 62 00 00 00 00 00 " + IDLE_PZD)["pkw"]
    assert (rq["ak"], rq["pnu"], rq["subindex"], rq["function_code"]) == (1, 0x10F, 0x62, "y98")
    rs = both(prof, "ppo1", "response", "11 0F 62 00 00 00 00 03 02 31 00 00")["pkw"]
    assert (rs["ak"], rs["function_code"], rs["value"]) == (1, "y98", 3)
    assert pd.words_to_bytes(pd.read_request(0x10F, 0x62).words()) == h("11 0F 62 00 00 00 00 00")


@BOTH
def test_tv14_y100_does_not_exist(prof):
    rq = both(prof, "ppo1", "request", "11 0F 64 00 00 00 00 00 " + IDLE_PZD)["pkw"]
    assert rq["function_code"] == "y100"
    r = both(prof, "ppo1", "response", "71 0F 64 00 00 00 00 00 02 31 00 00")
    pk = r["pkw"]
    assert (pk["ak"], pk["pnu"], pk["subindex"], pk["error"]) == (7, 0x10F, 100, 0)
    assert pk["function_code"] == "y100" and "does not exist" in pk["error_text"]
    assert "y100" in r["summary"]


@BOTH
def test_tv15_tv16_read_fault_memory_latest(prof):
    rq = both(prof, "ppo1", "request", "63 B3 01 00 00 00 00 00 " + IDLE_PZD)["pkw"]
    assert (rq["ak"], rq["pnu"], rq["subindex"]) == (6, 947, 1)
    r = both(prof, "ppo1", "response", "43 B3 01 00 00 00 75 11 02 40 00 00")
    pk = r["pkw"]
    assert (pk["ak"], pk["pnu"], pk["pwe"]) == (4, 947, 0x7511)
    (cand,) = pk["alarm_candidates"]
    assert (cand["code"], cand["mcode"]) == ("Er5", 35)
    assert "PROFIBUS communication" in cand["meaning"]      # spec §6: Er5 = PROFIBUS communication error
    assert "0x7511" in r["summary"] and "Er5" in r["summary"]


@BOTH
@pytest.mark.parametrize("ind", ["01", "1A"])        # text says subindex 01, the figure 0x1A
def test_tv16b_fault_memory_not_read_as_array(prof, ind):
    rq = both(prof, "ppo1", "request", f"13 B3 {ind} 00 00 00 00 00 " + IDLE_PZD)["pkw"]
    assert (rq["ak"], rq["pnu"]) == (1, 947)
    pk = both(prof, "ppo1", "response", f"73 B3 {ind} 00 00 00 00 03 02 40 00 00")["pkw"]
    assert (pk["ak"], pk["pnu"], pk["error"]) == (7, 947, 3)
    assert pk["error_text"] == "invalid subindex"


# Table 8.10 (G1 spec §5.3, PDP3 spec §5.3): error number -> words of the manual's meaning
FUJI_ERRORS = {0: "does not exist", 1: "cannot be written", 2: "outside the setting range",
               3: "invalid subindex", 4: "not an array", 11: "inverter runs", 17: "read cannot",
               104: "busy"}


@BOTH
@pytest.mark.parametrize("number,words", sorted(FUJI_ERRORS.items()))
def test_error_number_table(prof, number, words):
    pk = both(prof, "ppo1", "response", f"71 04 1A 00 00 00 00 {number:02X} 02 31 00 00")["pkw"]
    assert pk["error"] == number and words in pk["error_text"].lower()


# ---------------------------------------------------------------------------------------------
# encoding rules: TV17-TV20 (G1) / vectors 18-24 (PDP3)
# ---------------------------------------------------------------------------------------------

@BOTH
def test_tv17_pcd_assignment_word(prof):
    assert fuji.pcd_assignment(prof, "F26") == 0x041A
    assert fuji.pcd_assignment_code(prof, 0x041A) == "F26"
    assert fuji.pcd_assignment(prof, "C05") == 0x0605          # derived (PDP3 vector 18)
    assert fuji.pcd_assignment_code(prof, 0) is None
    # o40 = 0x041A written through the PKW channel, and PNU916[1] = 0x041A as an array write
    rq = both(prof, "ppo1", "request", "21 0A 28 00 00 00 04 1A " + IDLE_PZD)["pkw"]
    assert (rq["function_code"], rq["pwe"]) == ("o40", 0x041A)
    rq = both(prof, "ppo1", "request", "73 94 01 00 00 00 04 1A " + IDLE_PZD)
    assert rq["pkw"]["assigned_code"] == "F26" and "0x041A (F26)" in rq["summary"]


@BOTH
def test_tv18_function_code_addressing(prof):
    assert fuji.parse_function_code(prof, "F01") == ("F01", 4, 0x104, 1)
    assert pd.words_to_bytes(pd.read_request(0x104, 1).words()) == h("11 04 01 00 00 00 00 00")
    assert both(prof, "ppo1", "request", "11 04 01 00 00 00 00 00 " + IDLE_PZD)["pkw"]["function_code"] == "F01"
    # case-insensitive letters, canonical spelling
    assert fuji.parse_function_code(prof, "Y98")[0] == "y98"
    assert fuji.parse_function_code(prof, "o30")[2:] == (0x10A, 30)
    assert fuji.parse_function_code(prof, "y100")[2:] == (0x10F, 100)
    assert fuji.parse_function_code(prof, "Q01") is None


def test_two_character_groups_pdp3_only():
    assert fuji.parse_function_code(PDP3, "J101")[:3] == ("J101", 0x24, 0x124)
    assert fuji.parse_function_code(PDP3, "W190")[2:] == (0x117, 90)
    assert fuji.parse_function_code(G1, "J101")[2:] == (0x10E, 101)     # G1: no J1 group


@BOTH
@pytest.mark.parametrize("word,hz", [("40 00", 60.0), ("20 00", 30.0), ("10 00", 15.0), ("E0 00", -30.0),
                                     ("00 00", 0.0)])
def test_tv19_scaling(prof, word, hz):
    assert both(prof, "ppo3", "request", "04 7F " + word)["reference"]["hz"] == hz
    assert both(prof, "ppo3", "response", "02 37 " + word)["actual"]["hz"] == hz


@BOTH
@pytest.mark.parametrize("stw,mav,state,extra", [
    ("02 40", "00 00", "S1", {"R/L (PROFIBUS commands active)"}),
    ("02 31", "00 00", "S2", {"ON2 (CTW bit 1)", "ON3 (CTW bit 2)", "R/L (PROFIBUS commands active)"}),
    ("02 33", "10 00", "S5", set()),
    ("02 33", "00 00", "S3", set()),
    ("02 37", "40 00", "S4", set()),
    ("03 37", "40 00", "S4", {"FAR (frequency arrival)"}),
    ("02 08", "00 00", "fault", {"alarm (tripped)"}),
])
def test_tv20_status_word_table(prof, stw, mav, state, extra):
    sw = both(prof, "ppo3", "response", f"{stw} {mav}")["status_word"]
    assert sw["state"].startswith(state)
    assert extra <= set(sw["set"])


def test_pdp3_v21_fault_memory_indexes():
    for idx, ind in ((1, "01 00"), (9, "09 00"), (17, "11 00"), (25, "19 00")):
        frame = pd.read_request(947, idx, array=True)
        assert pd.words_to_bytes(frame.words())[2:4] == h(ind)
    cfg = pd.config(PDP3)
    assert cfg.fault_subindexes == [1, 9, 17, 25]
    assert [i for _, i, _ in fuji.fuji_config(PDP3).history] == [1, 9, 17, 25]


@BOTH
@pytest.mark.parametrize("code,text", [(10, "12M"), (7, "1.5M"), (0, "undetermined")])
def test_pdp3_v22_baud_codes(prof, code, text):
    pk = both(prof, "ppo1", "response", f"13 C3 00 00 00 00 00 {code:02X} 02 40 00 00")["pkw"]
    assert pk["pnu"] == 963 and text in pk["value_text"]


def test_pdp3_v24_ambiguous_and_special_fault_codes():
    assert fuji.alarm_text(PDP3, 0x2212).startswith("one of OL2")
    assert [a.code for a in fuji.alarm_candidates(PDP3, 0xFFFF)] == ["OH6"]
    assert fuji.alarm_candidates(G1, 0xFFFF) == []           # OH6 is listed only for OPC-PDP3
    assert [a.code for a in fuji.alarm_candidates(PDP3, 0xFF00)] == ["Err"]
    assert fuji.alarm_text(PDP3, 0) == "no alarm"
    for num, codes in ((0x4310, "OH1 OH4"), (0x7520, "Er2 ErP"), (0x5220, "Er3 ErH"), (0x7200, "Er7 CoF")):
        r = both(PDP3, "ppo1", "response", f"43 B3 09 00 00 00 {num >> 8:02X} {num & 0xFF:02X} 02 40 00 00")
        assert [c["code"] for c in r["pkw"]["alarm_candidates"]] == codes.split()


# ---------------------------------------------------------------------------------------------
# other rules: o30, o27/o28, PCD words
# ---------------------------------------------------------------------------------------------

@BOTH
@pytest.mark.parametrize("o30,layout", [(0, "ppo1"), (1, "ppo1"), (6, "ppo1"), (255, "ppo1"), (2, "ppo2"),
                                        (5, "ppo2"), (3, "ppo3"), (4, "ppo4")])
def test_o30_ppo_selection(prof, o30, layout):
    assert fuji.ppo_for_o30(prof, o30) == layout


@BOTH
def test_o27_actions(prof):
    a = fuji.comm_loss_action
    assert (a(prof, 0).stop, a(prof, 0).delayed, a(prof, 0).trip) == ("coast", False, True)
    assert a(prof, 7).stop == "coast"
    assert (a(prof, 1).delayed, a(prof, 1).recover) == (True, False)
    assert (a(prof, 2).delayed, a(prof, 2).recover) == (True, True)
    assert (a(prof, 3).stop, a(prof, 3).trip) == ("none", False) and a(prof, 14).stop == "none"
    assert (a(prof, 10).stop, a(prof, 10).delayed) == ("ramp", False)
    assert (a(prof, 12).stop, a(prof, 12).recover) == ("ramp", True)
    assert "F08" in fuji.comm_loss_text(prof, 11, 2.5) and "2.5 s" in fuji.comm_loss_text(prof, 11, 2.5)


def test_ppo2_pcd_words_named():
    r = both(G1, "ppo2", "response", "11 0F 62 00 00 00 00 03 02 37 20 00 00 64 00 00 00 00 12 34")
    assert [e["pcd"] for e in r["pzd"]] == [1, 2, 3, 4] and r["pzd"][3]["raw"] == 0x1234
    assert any(t.startswith("PCD1-4:") and "o48-o51" in t for t in r["text"])
    r = both(G1, "ppo4", "request", "04 7F 20 00 00 00 00 00 00 00 00 00")
    assert any("o40-o43" in t for t in r["text"])
