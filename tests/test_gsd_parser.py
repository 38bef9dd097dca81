"""GSD parser and interpreter: real vendor files (read from ../shared/testdata/gsd, skipped when absent),
syntax cases written inline, and the hand-written broken files in tests/data/gsd_broken.

Expected octets below were worked out by hand from the file text (comments show the working), not by
running the code.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from profidrive_cli import UsageError
from profidrive_cli.datafile import DataFileError
from profidrive_cli.gsd import build_prm, chk_cfg, decode_unit_diag, parse_gsd, parse_gsd_bytes, parse_gsd_text
from profidrive_cli.gsd.interp import device_user_prm
from profidrive_cli.gsd.model import select_module

HERE = Path(__file__).resolve().parent
BROKEN = HERE / "data" / "gsd_broken"
TESTDATA = Path(os.environ.get("PDRIVE_GSD_TESTDATA", HERE.parents[1] / "shared" / "testdata" / "gsd"))
SUFFIXES = (".gsd", ".gse", ".gsg", ".gsf", ".gsi", ".gsp", ".gss")

needs_testdata = pytest.mark.skipif(not TESTDATA.is_dir(), reason=f"{TESTDATA} not present")


def real(name: str) -> Path:
    if not TESTDATA.is_dir():
        pytest.skip(f"{TESTDATA} not present")
    hits = sorted(TESTDATA.rglob(name))
    if not hits:
        pytest.fail(f"{name} not in {TESTDATA}")          # ../shared is there: the file must be
    return hits[0]


def real_files() -> list[Path]:
    if not TESTDATA.is_dir():
        return []
    return sorted(p for p in TESTDATA.rglob("*") if p.is_file() and p.suffix.lower() in SUFFIXES)


# ------------------------------------------------------------------ every real file parses
@needs_testdata
def test_testdata_folder_has_the_ten_files():
    assert len(real_files()) >= 10


@pytest.mark.parametrize("path", real_files(), ids=lambda p: p.name)
def test_real_file_parses(path: Path):
    g = parse_gsd(path)
    assert g.ident_number is not None and 0 < g.ident_number <= 0xFFFF
    assert g.vendor_name and g.model_name
    assert g.modules, "every test file defines modules"
    for m in g.modules:
        assert m.cfg and m.cfg_modules      # decoded with dp.cfg.decode_cfg
    for w in g.warnings:                    # warnings always carry file:line
        assert w.startswith(f"{path}:")


@needs_testdata
@pytest.mark.parametrize("name,ident", [
    ("abb_acs880_pb_slave.gsd", 0x0959), ("abb_acs_pb_slave.gsd", 0x0812),
    ("sew_movidrive_pb_slave.gsd", 0x6003), ("SI028158.gsd", 0x8158), ("janitza_umg96s.gsd", 0x0781),
    ("eurotherm_tc3001_pbslave.gsd", 0x0536), ("si0380a7.gsd", 0x80A7), ("siemens_et200s_im151.gsd", 0x806A),
    ("si02806a.gse", 0x806A), ("siemens_et200m_im153.gsd", 0x801D),
])
def test_real_idents(name, ident):
    assert parse_gsd(real(name)).ident_number == ident


# ------------------------------------------------------------------ hand-checked values
@needs_testdata
def test_abb_fpba01_ppo_modules():
    g = parse_gsd(real("abb_acs880_pb_slave.gsd"))
    assert len(g.modules) == 22
    want = {1: "F3 F1", 2: "F3 F5", 3: "F1", 4: "F5", 5: "F3 F9", 6: "F9", 7: "F3 FB", 8: "FB"}
    for n, cfg in want.items():
        m = select_module(g, f"PPO{n}")
        assert m.index == n and m.name.startswith(f"PPO-0{n}")
        assert m.cfg == bytes.fromhex(cfg)
    m = g.modules[14]                                  # "PPO-01, 4 PKW +NoCons. 2 PZD" 0xF3, 0x71
    assert m.display_name == "PPO-01, 4 PKW +NoCons. 2 PZD" and m.cfg == b"\xf3\x71" and m.reference == 15
    assert (m.inputs, m.outputs) == (12, 12)
    assert g.max_tsdr(1_500_000) == 100 and g.max_tsdr("12M") == 400      # file: 100 / 400
    assert g.slave_family == 1 and g.slave_family_text == "1@ABB"
    assert g.unit_diag_bits == {0: "Host communication lost"}             # bit 1 is commented out


@needs_testdata
def test_abb_fpba01_user_prm_defaults():
    # Const(0..6) = 80 00 08 18 81 00 00; Const(7) = 00 00 00 04 7E 00*18 -> 30 octets. Then the refs:
    #  (0) Bit(7) default 0 clears the 0x80 -> 00;   (1) Bit(6)/Bit(5)/Bit(2) all 0 -> 00
    #  (2) BitArea(0-2) 0, Bit(3) 1 -> 08;           (3) Unsigned8 26 -> 1A;  (4) Unsigned8 129 -> 81
    #  (5), (6) 0;  (7) BitArea(0-1) 0 + BitArea(2-3) 0 -> 00;  (8) Unsigned16 30 -> 00 1E
    #  (10) Unsigned16 1150 -> 04 7E;  (12)..(28) Unsigned16 0
    g = parse_gsd(real("abb_acs880_pb_slave.gsd"))
    r = build_prm(g, ["PPO1"])
    assert r.user_prm == bytes.fromhex("00 00 08 1A 81 00 00 00 00 1E 04 7E") + bytes(18)
    assert r.cfg == b"\xf3\xf1"


@needs_testdata
def test_abb_rpba01_user_prm_defaults_and_overrides():
    # Const(0) = 24 zeros; (1) BitArea(0-1)/(4-5)/(2-3) all 0; (2) Unsigned16 default 1 -> 00 01; rest 0
    g = parse_gsd(real("abb_acs_pb_slave.gsd"))
    r = build_prm(g, ["PPO Type 2"])
    assert r.user_prm == bytes.fromhex("00 00 00 01") + bytes(20)
    assert r.cfg == b"\xf3\xf5"
    # "Fail Safe mode" BitArea(0-1) = 2 (by text), "Operation mode" BitArea(4-5) = 1 -> octet 1 = 0x12;
    # "Cut-Off time ..." Unsigned16 0x1234 big endian at 2..3
    r = build_prm(g, ["PPO3"], ["Fail Safe mode=Use fail-safe values", "operation MODE=1",
                                "Cut-Off time (0 = no cut-off)=0x1234"])
    assert r.user_prm[:4] == bytes.fromhex("00 12 12 34")
    assert r.cfg == b"\xf1"
    with pytest.raises(UsageError, match=r"not allowed.*0-2"):
        build_prm(g, ["PPO3"], {"Fail Safe mode": 3})
    with pytest.raises(UsageError, match="neither a number nor one of its texts"):
        build_prm(g, ["PPO3"], {"Fail Safe mode": "Explode"})
    with pytest.raises(UsageError, match="no user parameter"):
        build_prm(g, ["PPO3"], {"Nonexistent": 1})


@needs_testdata
def test_diagnostic_repeater_bit_defaults():
    # Const(0) = 80 00 08 08 81 00 00 54 00 00 00; (7) BitArea(0-7) default 0x54 -> 54;
    # (9) Bit(0) 0, Bit(1) 0 -> 00; (10) Bit(0) 1, Bit(1) 1 -> 03
    g = parse_gsd(real("si0380a7.gsd"))
    r = build_prm(g, ["DR-CfgData"])
    assert r.user_prm == bytes.fromhex("80 00 08 08 81 00 00 54 00 00 03")
    assert r.cfg == b"\x20"
    assert select_module(g, 2).cfg == bytes.fromhex("C0 00 82")
    # BitArea(0-7) allows only the listed values 0x5b,0x54,0x41,0x2e,0x1b
    r = build_prm(g, [1], {"Diagnose frame for": "Segment DP2,DP3"})
    assert r.user_prm[7] == 0x2E
    with pytest.raises(UsageError, match="not allowed"):
        build_prm(g, [1], {"Diagnose frame for": 0x55})
    assert len(g.slots) == 1 and g.slots[0].allowed == (1, 2) and g.slots[0].default == 1


@needs_testdata
def test_et200m_module_prm_block_and_slot_number():
    # device: User_Prm_Data_Len 3, 40 60 00; refs keep 40 60 00 (Bit5=1, Bit6=1 already set, others 0)
    # module 4 "6ES7 321-7RD00-0AB0 4DI": Ext_Module_Prm_Data_Len 21, Const(0) = 15 5F 04 00 10 00*16;
    #   (2) "[SlotNumber]" -> slot 4 (Modul_Offset 1 + position 3); all Bit defaults 0
    g = parse_gsd(real("siemens_et200m_im153.gsd"))
    r = build_prm(g, [1, 2, 3, 4])
    assert r.user_prm == bytes.fromhex("40 60 00") + bytes.fromhex("15 5F 04 00 10") + bytes(16)
    assert r.cfg == bytes.fromhex("04 00 00 AD C4 04 00 00 8B 41 04 00 00 8F C0 43 00 00 1F C1")
    # and a module-level Bit override: "Process interrupt enable" Bit(7) at module octet 15
    r = build_prm(g, [1, 2, 3, 4], ["4:Process interrupt enable=1"])
    assert r.user_prm[3 + 15] == 0x80


@needs_testdata
def test_profisafe_f_parameters_follow_the_module():
    # Standard telegram 1 (no prm) + PROFIsafe module: F block of 14 octets after the 3 DPV1 octets:
    # 0E 05 [SlotNumber]=2 00 | F-Param1: Bit0 0, BitArea(2-3) 1, BitArea(4-5) 1 -> 14 | BitArea(6-7) 0 -> 00
    # | F_Source_Add 1 -> 00 01 | F_Dest_Add 1 -> 00 01 | F_WD_Time 100 -> 00 64 | F_Par_CRC 0x783E
    g = parse_gsd(real("SI028158.gsd"))
    r = build_prm(g, ["Standard telegram 1", "PROFIsafe v1.x Module"])
    assert r.user_prm == bytes.fromhex("00 00 00 0E 05 02 00 14 00 00 01 00 01 00 64 78 3E")
    assert r.cfg == bytes.fromhex("E1 D1 C6 85 85 05 05 0A 05 05 0A")
    assert r.cfg[2:][:1] == b"\xc6"


@needs_testdata
def test_sew_and_janitza_special_cases():
    g = parse_gsd(real("sew_movidrive_pb_slave.gsd"))
    assert select_module(g, "4 PD   (4 words)").cfg == b"\x00\xf3"          # empty-slot 0x00 kept
    assert select_module(g, "4 pd (4 words)".replace(" (", "   (")).index == 4
    assert chk_cfg(g, ["Param + 10 PD   (4+10 words)"]) == b"\xf3\xf9"
    assert build_prm(g, [1]).user_prm == bytes.fromhex("00 00 00 06 81 00 00 01 01")
    j = parse_gsd(real("janitza_umg96s.gsd"))
    (m,) = j.modules
    assert m.cfg == bytes.fromhex("C0 01 7D") and (m.outputs, m.inputs) == (2, 124)
    assert build_prm(j, []).user_prm == b""                                  # User_Prm_Data_Len=0


@needs_testdata
def test_latin1_and_mixed_line_ends():
    p = real("siemens_et200m_im153.gsd")
    g = parse_gsd(p)
    assert g.encoding == "latin-1"                    # Text(160)="thermocouple comp.  0\xbaC Type B" (0xBA)
    assert any(t == "thermocouple comp.  0\u00baC Type B" for pt in g.prm_texts.values() for t in pt.texts.values())
    # the same file with every line end style, cycling CRLF / CR / LF line by line
    lines = p.read_bytes().split(b"\r\n")
    seps = [b"\r\n", b"\r", b"\n"]
    mixed = b"".join(ln + seps[i % 3] for i, ln in enumerate(lines))
    m = parse_gsd_bytes(mixed, p)
    assert [x.cfg for x in m.modules] == [x.cfg for x in g.modules]
    assert [x.line for x in m.modules] == [x.line for x in g.modules]
    assert len(m.ext_user_prm_data) == len(g.ext_user_prm_data) > 500
    assert build_prm(m, [1, 2, 3, 4]).user_prm == build_prm(g, [1, 2, 3, 4]).user_prm


@needs_testdata
def test_unit_diag_texts_of_the_diagnostic_repeater():
    g = parse_gsd(real("si0380a7.gsd"))
    # device block: header 0x12 (18 octets incl. header), body 17 octets:
    # status type 0x81, slot 0, specifier 0, then octet 3 = 0x40 (bit 30 "Segment DP1"),
    # octet 4 = 0x02 (bit 33), octet 5 = 0x05 (bits 40-47 = 5 -> "Reflection error rate: 5%")
    body = bytes([0x81, 0, 0, 0x40, 0x02, 0x05]) + bytes(11)
    texts = decode_unit_diag(g, bytes([0x12]) + body)
    assert "====== Segment DP1 ====== (unit diag bit 30)" in texts
    assert "Segment deactivated (unit diag bit 33)" in texts
    assert "Reflection error rate: 5% (unit diag bits 40-47 = 5)" in texts
    # bits 48-55 = 0 has a text too ("Station x: 0!"), area 56-63 has no values and is 0 -> silent
    assert any(t.startswith("Station x: 0!") for t in texts)
    # an identifier-related block before it is skipped; a channel block too
    texts2 = decode_unit_diag(g, bytes([0x42, 0x01, 0x80, 0x41, 0x21]) + bytes([0x12]) + body)
    assert texts2 == texts


# ------------------------------------------------------------------ syntax, inline
BASE = "#Profibus_DP\nIdent_Number = 0x1234\nModule = \"M\" 0x11\nEndModule\n"


def test_text_before_profibus_dp_is_ignored_and_keywords_are_case_insensitive():
    text = ("this is not GSD = at all\n\"unbalanced\n=====\n"
            "#PROFIBUS_DP\nVENDOR_NAME = \"V\"\nident_number=4660\nMODULE = \"A\" 0x11 ENDMODULE\n")
    with pytest.raises(DataFileError):                   # 'ENDMODULE' on the same line is not a number
        parse_gsd_text(text)
    g = parse_gsd_text(text.replace(" ENDMODULE", "\nendmodule"))
    assert g.vendor_name == "V" and g.ident_number == 0x1234 and g.modules[0].cfg == b"\x11"
    assert g.start_line == 4


def test_comments_continuations_and_line_ends():
    text = ('#Profibus_DP\r\n'
            'Vendor_Name = "A;B" ; the ; inside the string is kept\r'
            'Info_Text = "first part \\\r\n'
            'second part"\n'
            'Ident_Number = 0x0ABC;comment right after the value\n'
            'User_Prm_Data_Len = 4\n'
            'User_Prm_Data = 0x01, 2, \\   ; comment after the continuation\n'
            '                0x03,\\\n'
            '4\n'
            'Module = "M" 0xF3, \\\n 0xF1;\n'
            'EndModule;\n')
    g = parse_gsd_text(text, "t.gsd")
    assert g.vendor_name == "A;B"
    assert g.get("Info_Text") == "first part second part"
    assert g.ident_number == 0x0ABC
    assert g.user_prm_data == b"\x01\x02\x03\x04"
    assert g.modules[0].cfg == b"\xf3\xf1"
    assert g.modules[0].line == 10 and g.value_lines["ident_number"] == 5
    assert device_user_prm(g) == b"\x01\x02\x03\x04"
    # a string continued over three lines keeps its text exactly; no blank is added inside it
    g = parse_gsd_text('#Profibus_DP\nInfo_Text = "a \\\n  b\\\nc" ; x\nIdent_Number = 1\n')
    assert g.get("info_text") == "a   bc" and g.ident_number == 1


def test_yaskawa_maxtsd_alias_and_defaults():
    g = parse_gsd_text("#Profibus_DP\nMaxTsd_45.45 = 250\nMAXTSDR_12M = 700\n12M_supp = 1\n" + BASE[13:])
    assert g.max_tsdr(45_450) == 250 and g.max_tsdr("45.45") == 250
    assert g.max_tsdr(12_000_000) == 700
    # absent -> reference §5 defaults
    assert [g.max_tsdr(b) for b in (9600, "19.2", "93.75k", 187_500, 500_000, "1.5M", "3M", 6_000_000)] \
        == [60, 60, 60, 60, 100, 150, 250, 450]
    assert g.baud_supported("12M") and not g.baud_supported(9600)
    with pytest.raises(UsageError):
        g.max_tsdr(115_200)


def test_ext_user_prm_data_types_and_signed_values():
    text = """#Profibus_DP
Ident_Number = 1
PrmText = 1
Text(-1) = "minus one"
Text(0) = "zero"
EndPrmText
ExtUserPrmData = 1 "s16"
Signed16 -2 -100-100
Prm_Text_Ref = 1
EndExtUserPrmData
ExtUserPrmData = 2 "u32"
Unsigned32 0x01020304 0-0xFFFFFFFF
EndExtUserPrmData
ExtUserPrmData = 3 "list"
BitArea(4-6) 3 1,3,5
Changeable = 0
Visible = 0
EndExtUserPrmData
Ext_User_Prm_Data_Const(0) = 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF
Ext_User_Prm_Data_Ref(0) = 1
Ext_User_Prm_Data_Ref(2) = 2
Ext_User_Prm_Data_Ref(6) = 3
Module = "M" 0x10
EndModule
"""
    g = parse_gsd_text(text)
    d = g.ext_user_prm_data[3]
    assert (d.data_type, d.bit_lo, d.bit_hi, d.allowed, d.changeable, d.visible) == \
        ("BitArea", 4, 6, (1, 3, 5), False, False)
    r = build_prm(g, [])
    # -2 -> FF FE; 0x01020304 big endian; BitArea(4-6)=3 into 0xFF keeps bits 7 and 0..3 -> 0xBF
    assert r.user_prm == bytes.fromhex("FF FE 01 02 03 04 BF")
    r = build_prm(g, [], {"s16": "minus one"})
    assert r.user_prm[:2] == b"\xff\xff"
    with pytest.raises(UsageError, match="not changeable"):
        build_prm(g, [], {"list": 5})
    with pytest.raises(UsageError, match="not allowed"):
        build_prm(g, [], {"s16": 101})


def test_module_parameters_appended_in_module_order_and_qualified_names():
    text = """#Profibus_DP
Ident_Number = 1
Modular_Station = 1
Max_Module = 3
User_Prm_Data_Len = 2
User_Prm_Data = 0xAA
ExtUserPrmData = 7 "Mode"
BitArea(0-1) 1 0-3
EndExtUserPrmData
Module = "A" 0x21
Ext_Module_Prm_Data_Len = 2
Ext_User_Prm_Data_Const(0) = 0x10
Ext_User_Prm_Data_Ref(1) = 7
EndModule
Module = "B" 0x00
EndModule
"""
    g = parse_gsd_text(text)
    r = build_prm(g, ["A", "B", "A"])
    # device: User_Prm_Data padded to 2 -> AA 00; A: 10 01; B: nothing; A: 10 01
    assert r.user_prm == bytes.fromhex("AA 00 10 01 10 01")
    assert r.cfg == bytes.fromhex("21 00 21")              # 0x00 empty slot sent verbatim
    with pytest.raises(UsageError, match="several blocks"):
        build_prm(g, ["A", "B", "A"], {"Mode": 2})
    r = build_prm(g, ["A", "B", "A"], {"3:Mode": 2})
    assert r.user_prm == bytes.fromhex("AA 00 10 01 10 02")
    lines = r.explain()
    assert any("Mode = 2" in ln and "[set]" in ln and "User_Prm[5]" in ln for ln in lines)
    assert any(ln.startswith("User_Prm[0]") and "0xAA" in ln for ln in lines)
    rows = r.rows()
    assert [(x["offset"], x["constant"]) for x in rows] == [(0, True), (1, True), (2, True), (3, False),
                                                             (4, True), (5, False)]
    with pytest.raises(UsageError, match="at most 3"):
        build_prm(g, ["A"] * 4)


def test_ppo_selection_forms():
    text = "#Profibus_DP\nIdent_Number = 1\n" + "".join(
        f'Module = "{n}" 0x{c:02X}\nEndModule\n'
        for n, c in [("PPO Type 1", 0xF1), ("PPO-02, x", 0xF5), ("ppo_3", 0x71), ("PPO12", 0x11)])
    g = parse_gsd_text(text)
    assert select_module(g, "PPO1").index == 1
    assert select_module(g, "ppo2").index == 2
    assert select_module(g, "PPO3").index == 3
    assert select_module(g, "PPO12").index == 4
    assert select_module(g, "3").index == 3 and select_module(g, 4).index == 4
    with pytest.raises(UsageError, match="no module 'PPO5'"):
        select_module(g, "PPO5")
    with pytest.raises(UsageError, match="out of range"):
        select_module(g, 9)
    with pytest.raises(UsageError, match="choose the module"):
        build_prm(g, [])


def test_unknown_keywords_are_kept_with_their_line():
    g = parse_gsd_text("#Profibus_DP\nIdent_Number = 1\nVendor_Special(3) = 1, 2\nModule = \"M\" 0x10\n"
                       "Odd_Module_Key = \"x\"\nEndModule\n", "u.gsd")
    assert g.get("vendor_special") == "(3) 1, 2"
    assert g.modules[0].extra["odd_module_key"] == '"x"'
    assert g.unknown == [("Vendor_Special", 3), ("Odd_Module_Key", 5)]
    assert g.warnings == ["u.gsd:3: unknown keyword 'Vendor_Special' (kept, not interpreted)",
                          "u.gsd:5: unknown keyword 'Odd_Module_Key' in Module 'M' (kept, not interpreted)"]


def test_undefined_reference_warns_at_parse_and_fails_at_build():
    g = parse_gsd_text("#Profibus_DP\nIdent_Number = 1\nExt_User_Prm_Data_Ref(0) = 9\n"
                       "Module = \"M\" 0x10\nEndModule\n", "r.gsd")
    assert any(w.startswith("r.gsd:3:") and "no ExtUserPrmData" in w for w in g.warnings)
    with pytest.raises(UsageError, match=r"r\.gsd:3:"):
        build_prm(g, [1])


def test_utf8_file():
    g = parse_gsd_bytes('#Profibus_DP\nVendor_Name = "Größe µs"\nIdent_Number = 1\n'.encode("utf-8"))
    assert g.vendor_name == "Größe µs" and g.encoding == "utf-8"
    g = parse_gsd_bytes('#Profibus_DP\nVendor_Name = "Größe µs"\nIdent_Number = 1\n'.encode("latin-1"))
    assert g.vendor_name == "Größe µs" and g.encoding == "latin-1"


def test_unit_diag_not_bits_and_diag_types():
    text = """#Profibus_DP
Ident_Number = 1
Unit_Diag_Bit(0) = "zero set"
Unit_Diag_Not_Bit(1) = "one clear"
Unit_Diag_Area = 8-11
Value(3) = "three"
Unit_Diag_Area_End
UnitDiagType = 129
X_Unit_Diag_Bit(15) = "typed"
EndUnitDiagType
"""
    g = parse_gsd_text(text)
    assert decode_unit_diag(g, bytes([0x03, 0x01, 0x03])) == [
        "zero set (unit diag bit 0)", "one clear (unit diag bit 1 = 0)", "three (unit diag bits 8-11 = 3)"]
    assert decode_unit_diag(g, bytes([0x03, 0x81, 0x8C])) == [
        "zero set (unit diag bit 0)", "one clear (unit diag bit 1 = 0)",
        "unit diag bits 8-11 = 12 (no text in the GSD)", "typed (unit diag bit 15)"]
    assert decode_unit_diag(g, b"") == [] and decode_unit_diag(g, b"\x00\xff") == []


# ------------------------------------------------------------------ broken files
@pytest.mark.parametrize("name,line,message", [
    ("unterminated_module.gsd", 7, "Module 'PPO3' not terminated: EndModule missing"),
    ("module_in_module.gsd", 3, "Module 'PPO1' not terminated: EndModule missing before Module at line 4"),
    ("bad_number.gsd", 3, "bad number 0x12G4"),
    ("missing_profibus_dp.gsd", 1, "no '#Profibus_DP' line"),
    ("unterminated_string.gsd", 2, "unterminated string"),
    ("bad_bit.gsd", 4, "Bit(8): bits must be 0..7"),
    ("endmodule_without_module.gsd", 5, "EndModule without a matching Module"),
    ("bad_cfg.gsd", 3, "input length octet missing"),
])
def test_broken_files_give_file_and_line(name, line, message):
    path = BROKEN / name
    with pytest.raises(DataFileError) as ei:
        parse_gsd(path)
    e = ei.value
    assert isinstance(e, UsageError)
    assert (e.path, e.line) == (str(path), line)
    assert message in e.message
    assert str(e).startswith(f"{path}:{line}: ")


def test_unknown_keyword_file_parses_with_a_warning():
    path = BROKEN / "unknown_keyword.gsd"
    g = parse_gsd(path)
    assert g.ident_number == 0x1234 and g.modules[0].cfg == b"\xf1"
    assert g.warnings == [f"{path}:4: unknown keyword 'Frobnicate_Level' (kept, not interpreted)"]
    assert g.get("frobnicate_level") == "3"


def test_missing_file_and_folder():
    with pytest.raises(DataFileError, match="file not found"):
        parse_gsd(BROKEN / "nope.gsd")
    with pytest.raises(DataFileError, match="folder"):
        parse_gsd(BROKEN)


def test_truncated_library_file_is_an_error_naming_what_is_missing(tmp_path):
    """YASK00CA.GSD cut at 600 bytes ends inside `Protocol_Ident` (line 24): no Protocol_Ident,
    Station_Type, baud rate or Module is left. Before, it parsed as a device with 0 modules."""
    p = tmp_path / "YASKCUT.GSD"
    p.write_bytes((HERE.parent / "gsd" / "YASK00CA.GSD").read_bytes()[:600])
    with pytest.raises(DataFileError) as ei:
        parse_gsd(p)
    assert str(ei.value) == (f"{p}:24: incomplete GSD file (truncated?): missing Protocol_Ident, Station_Type, "
                             "a supported baud rate (<baud>_supp = 1), a Module")


def test_required_keywords_each_missing_is_named(tmp_path):
    full = ['Vendor_Name = "V"', 'Model_Name = "M"', "Ident_Number = 0x1234", "Protocol_Ident = 0",
            "Station_Type = 0", "12M_supp = 1", 'Module = "m" 0x11', "EndModule"]
    names = ["Vendor_Name", "Model_Name", "Ident_Number", "Protocol_Ident", "Station_Type",
             "a supported baud rate (<baud>_supp = 1)", "a Module"]
    p = tmp_path / "x.gsd"
    p.write_text("#Profibus_DP\n" + "\n".join(full) + "\n")
    g = parse_gsd(p)                                  # complete; no GSD_Revision: accepted, with a warning
    assert g.warnings == [f"{p}:1: no GSD_Revision line (a revision-0 file: accepted)"]
    for i, name in enumerate(names):
        lines = full[:i] + full[i + 1:] if i < 6 else full[:6]
        p.write_text("#Profibus_DP\n" + "\n".join(lines) + "\n")
        with pytest.raises(DataFileError, match="missing " + name.replace("(", r"\(").replace(")", r"\)") + r"\Z"):
            parse_gsd(p)


@needs_testdata
def test_every_real_file_has_the_required_keywords():
    """All ten real files and the library files pass the completeness check; the Eurotherm file has no
    GSD_Revision (a revision-0 file) and is accepted with a warning."""
    for f in real_files() + sorted((HERE.parent / "gsd").glob("*.GSD")):
        g = parse_gsd(f)
        rev_warn = [w for w in g.warnings if "GSD_Revision" in w]
        assert bool(rev_warn) == (f.name == "eurotherm_tc3001_pbslave.gsd"), f
