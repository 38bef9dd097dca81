"""Moeller DE6-NET-DP codec and profile: the spec's test vectors (section 12) through the codec.

TV-* are the manual's own examples (exact); D-* are the spec's derived vectors (lower confidence,
marked `derived` in the test names).
"""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import pytest

from profidrive_cli.datafile import DataFileError
from profidrive_cli.drives import decode_area
from profidrive_cli.drives import moeller as mo
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.profile import load_profile, load_profile_file

ROOT = Path(__file__).resolve().parent.parent
CSV = ROOT.parent / "shared" / "spec" / "moeller-de6-parameters.csv"


@pytest.fixture(scope="module")
def prof():
    return load_profile("moeller")


def h(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", ""))


# -- profile ------------------------------------------------------------------------------------

def test_identity_and_layouts(prof):
    assert prof.name == "moeller-de6-net-dp" and prof.family == "moeller"
    assert prof.aliases == ["moeller"] and prof.ident == 0xFD06 and prof.ident_placeholder
    assert prof.gsd == "MOELFD06.GSD" and prof.word_order == "big"
    cfgs = {n: l.cfg.hex(" ").upper() for n, l in prof.layouts.items()}
    assert cfgs == {"ppo1": "F3 F1", "ppo2": "F3 F5", "ppo3": "F1", "ppo4": "F5", "ppo5": "F3 F9"}
    assert [prof.layouts[f"ppo{n}"].pkw for n in range(1, 6)] == [True, True, False, False, True]
    assert prof.max_frequency_param == "A004"
    assert prof.decisions if hasattr(prof, "decisions") else prof.raw["decisions"]


def test_cross_reference_complete(prof):
    rows = [p for p in prof.parameters.values() if p.pnu <= 418]
    assert len(rows) == 378
    assert len({p.pnu for p in rows}) == 378
    nines = sorted(p.pnu for p in prof.parameters.values() if p.pnu > 418)
    assert nines == [915, 916, 918, 927, 928, 947, 963, 964, 965, 967, 968, 971]


@pytest.mark.skipif(not CSV.parent.is_dir(), reason=f"{CSV.parent} not present")
def test_profile_matches_csv(prof):
    assert CSV.is_file(), f"{CSV} missing"
    with open(CSV, encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    by_pnu = {p.pnu: p for p in prof.parameters.values()}
    access = {"R/W": "rw", "R/WOS": "stop", "RO": "ro"}
    for r in rows:
        p = by_pnu[int(r["PROFIBUS PNU"])]
        assert p.access == access[r["Access"]], p.code
        assert p.extra["bytes"] == int(r["Size [bytes]"]), p.code
        assert p.size == (32 if r["Size [bytes]"] == "4" else 16)
        code = r["DF6/DV6 code"].replace("\u2192", "").strip()
        if code[:1] in "AbCdFHP" and code not in ("d016", "d017", "d081") and p.pnu < 355:
            assert p.code == code
    generator = ROOT / "tools" / "gen_moeller_profile.py"
    rc = subprocess.run([sys.executable, str(generator), str(CSV), "--check"]).returncode
    assert rc == 0, "profile is out of date with the CSV: run tools/gen_moeller_profile.py"


def test_key_parameters(prof):
    a001, a002 = prof.param("A001"), prof.param("A002")
    assert (a001.pnu, a001.access, a001.extra["bytes"], a001.min, a001.max) == (189, "stop", 1, 0, 5)
    assert (a002.pnu, a002.min, a002.max) == (190, 1, 5)
    assert (prof.param("P001").pnu, prof.param("P002").pnu) == (332, 333)
    f002 = prof.param("F002")
    assert (f002.pnu, f002.scale, f002.size, f002.unit, f002.min, f002.max) == \
        (23, 0.01, 32, "s", 0.01, 3600.0)
    a004 = prof.param("A004")
    assert (a004.pnu, a004.scale, a004.access, a004.min, a004.max) == (62, 1, "stop", 30, 400)
    assert prof.param("A038").pnu == 61 and prof.param("F203").pnu == 27
    assert prof.param("A113").signed and prof.param("d012").signed
    assert prof.param("C001").extra["df6_max"] == 39
    assert prof.param("C001").extra["ranges"] == [[1, 48], [255, 255]]
    assert prof.param("H020").extra["df6"] is False
    assert prof.param("d081").pnu == 355 and prof.param("PNU354").pnu == 354
    assert prof.param("d016").pnu == 401 and prof.param("PNU340").pnu == 340
    assert prof.param("PNU971").access == "wo"


def test_profidrive_section(prof):
    c = pd.config(prof)
    assert c.fault_subindexes == [1, 9, 17, 25, 33, 41, 49]
    assert c.fault_positions[:3] == ["current", "last", "2nd last"]
    assert c.save_pnu == 971 and c.zero_between_identical
    assert c.error_numbers["stop_only"] == 17 and c.error_text(106) == "request ID not allowed"
    assert c.labels == {"control": "STW", "status": "ZSW", "reference": "HSW", "actual": "HIW"}
    assert c.ctw_names[11] == "reverse" and 9 not in c.ctw_names
    assert c.supported_requests == frozenset({0, 1, 2, 3, 6, 7, 9})
    mc = mo.moeller_config(prof)
    assert (mc.frequency_param, mc.frequency_bus_value, mc.commands_param, mc.commands_bus_value) \
        == ("A001", 2, "A002", 1)
    assert (mc.comm_loss_param, mc.comm_loss_other_param, mc.comm_loss_alarm) == \
        ("P002", "P001", "E70")


# -- TV-1 .. TV-3: the manual's worked examples ---------------------------------------------------

TV1A = ("30 17 00 00 00 00 01 90 04 06 20 00", "20 17 00 00 00 00 01 90 03 31 20 00")
TV1B = ("30 17 00 00 00 00 01 90 04 7F 20 00", "20 17 00 00 00 00 01 90 03 37 20 00")
TV2A = ("73 94 01 00 00 00 00 3D 04 06 20 00 00 00 00 00 00 00 00 00",
        "43 94 01 00 00 00 00 3D 03 31 20 00 01 F4 00 00 00 00 00 00")
TV2B = ("73 94 01 00 00 00 00 3D 04 7F 20 00 00 00 00 00 00 00 00 00",
        "43 94 01 00 00 00 00 3D 03 37 20 00 01 F4 00 00 00 00 00 00")
TV3 = ("73 93 01 00 00 00 00 3E 04 7F 20 00 00 4B 00 00 00 00 00 00",
       "43 93 01 00 00 00 00 3E 03 37 20 00 01 F4 00 00 00 00 00 00")


def test_tv1a_request(prof):
    d = decode_area(prof, "ppo1", "request", h(TV1A[0]))
    pk = d["pkw"]
    assert (pk["ak"], pk["spm"], pk["pnu"], pk["code"], pk["subindex"]) == (3, 0, 23, "F002", 0)
    assert pk["ak_text"] == "change parameter value (long word)"
    assert (pk["pwe"], pk["value"], pk["unit"], pk["value_text"]) == (400, 4.0, "s", "4.00 s")
    cw = d["control_word"]
    assert cw["word"] == 0x0406 and cw["set"] == ["no OFF2", "no OFF3", "control by PLC"]
    assert cw["bus_controls"] == "frequency and commands" and cw["direction"] == "forward"
    assert d["reference"]["percent"] == 50.0


def test_tv1a_response(prof):
    d = decode_area(prof, "ppo1", "response", h(TV1A[1]))
    pk = d["pkw"]
    assert (pk["ak"], pk["pnu"], pk["value"]) == (2, 23, 4.0)
    sw = d["status_word"]
    assert sw["word"] == 0x0331 and sw["state"] == "S2 ready for switching on"
    assert sw["set"] == ["ready to switch on", "no OFF2", "no OFF3", "at setpoint",
                         "control requested"]
    assert not any(b["set"] for b in sw["bits"] if b["bit"] in (1, 2, 3, 6, 12, 13))


def test_tv1b(prof):
    q = decode_area(prof, "ppo1", "request", h(TV1B[0]))
    assert q["control_word"]["word"] == 0x047F and q["control_word"]["command"] == "operate"
    assert q["control_word"]["set"] == ["ON", "no OFF2", "no OFF3", "enable operation",
                                        "enable ramp generator", "unfreeze ramp generator",
                                        "enable setpoint", "control by PLC"]
    # the Done-when sentence
    assert q["summary"] == ("change parameter value (long word), PNU 23 = F002 1st Acceleration "
                            "time 1 = 4.00 s; operate; reference 50 %")
    r = decode_area(prof, "ppo1", "response", h(TV1B[1]))
    assert r["status_word"]["word"] == 0x0337 and r["status_word"]["state"] == "S4 operation"
    assert r["actual"]["percent"] == 50.0 and r["actual"]["hz"] == 25.0
    assert r["summary"] == ("transfer parameter value (long word), PNU 23 = F002 1st Acceleration "
                            "time 1 = 4.00 s; S4 operation; actual 50 %")


@pytest.mark.parametrize("vec,stw,zsw", [(TV2A, 0x0406, 0x0331), (TV2B, 0x047F, 0x0337)])
def test_tv2(prof, vec, stw, zsw):
    q = decode_area(prof, "ppo2", "request", h(vec[0]))
    pk = q["pkw"]
    assert (pk["ak"], pk["pnu"], pk["subindex"], pk["ind"], pk["pwe"]) == (7, 916, 1, 0x0100, 61)
    assert pk["maps"] == {"pnu": 61, "code": "A038"}
    assert q["control_word"]["word"] == stw and q["reference"]["raw"] == 0x2000
    assert [e["raw"] for e in q["pzd"]] == [0, 0, 0, 0]
    r = decode_area(prof, "ppo2", "response", h(vec[1]))
    assert (r["pkw"]["ak"], r["pkw"]["pnu"], r["pkw"]["subindex"], r["pkw"]["pwe"]) == (4, 916, 1, 61)
    assert r["status_word"]["word"] == zsw and r["actual"]["raw"] == 0x2000
    assert [e["raw"] for e in r["pzd"]] == [0x01F4, 0, 0, 0]
    # PZD3 = A038 raw 500 = 5.00 Hz (x100)
    assert mo.value_from_wire(prof.param("A038"), r["pzd"][0]["raw"]) == 5.0


def test_tv3(prof):
    q = decode_area(prof, "ppo2", "request", h(TV3[0]))
    assert (q["pkw"]["ak"], q["pkw"]["pnu"], q["pkw"]["subindex"], q["pkw"]["pwe"]) == (7, 915, 1, 62)
    assert q["pkw"]["maps"]["code"] == "A004"
    assert q["control_word"]["word"] == 0x047F and q["reference"]["percent"] == 50.0
    assert q["pzd"][0]["raw"] == 0x004B
    assert mo.value_from_wire(prof.param("A004"), q["pzd"][0]["raw"]) == 75
    r = decode_area(prof, "ppo2", "response", h(TV3[1]))
    assert (r["pkw"]["ak"], r["pkw"]["pnu"], r["pkw"]["pwe"]) == (4, 915, 62)
    assert r["status_word"]["word"] == 0x0337 and r["pzd"][0]["raw"] == 0x01F4


def test_tv_encode_back(prof):
    """Building the same telegrams with the codec gives the manual's octets."""
    ppo1, ppo2 = pd.ppo_layout(prof, "ppo1"), pd.ppo_layout(prof, "ppo2")
    req = pd.write_request(prof.param("F002").pnu,
                           mo.wire_from_value(prof.param("F002"), 4.00), long=True)
    out = pd.encode_area(ppo1, pd.PpoArea(req.words(), [0x047F, pd.n2_from_percent(50)]))
    assert out == h(TV1B[0])
    req = pd.pzd_map_write("actual", 1, prof.param("A038").pnu)
    assert pd.encode_area(ppo2, pd.PpoArea(req.words(), [0x0406, 0x2000])) == h(TV2A[0])
    req = pd.pzd_map_write("setpoint", 1, prof.param("A004").pnu)
    area = pd.PpoArea(req.words(), [0x047F, 0x2000, mo.wire_from_value(prof.param("A004"), 75)])
    assert pd.encode_area(ppo2, area) == h(TV3[0])


# -- TV-4 .. TV-14: field-level vectors -----------------------------------------------------------

@pytest.mark.parametrize("pke,ak,pnu", [(0x3017, 3, 23), (0x2017, 2, 23), (0x7394, 7, 916),
                                        (0x4394, 4, 916), (0x7393, 7, 915), (0x4393, 4, 915)])
def test_tv4_pke(pke, ak, pnu):
    assert pd.decode_pke(pke) == (ak, 0, pnu)
    assert pd.encode_pke(ak, pnu) == pke


@pytest.mark.parametrize("raw,pct", [(0x0000, 0), (0x2000, 50), (0x4000, 100), (0xC000, -100),
                                     (0x8000, -200), (0x7FFF, 199.9939)])
def test_tv5_n2(raw, pct):
    assert round(pd.n2_to_percent(raw), 4) == pct
    assert pd.n2_to_percent(1) == 0.006103515625
    assert pd.n2_to_hz(0x2000, 50) == 25.0 and pd.n2_to_hz(0x2000, 75) == 37.5


def test_tv6_stw_encode():
    C = pd.Ctw
    assert int(C.NO_OFF2 | C.NO_OFF3 | C.CONTROL_BY_PLC) == 0x0406
    assert int(C.ON | C.NO_OFF2 | C.NO_OFF3 | C.ENABLE_OPERATION | C.ENABLE_RFG | C.UNFREEZE_RFG
               | C.ENABLE_SETPOINT | C.CONTROL_BY_PLC) == 0x047F
    # and the state machine walks the manual's start sequence
    assert pd.next_control_word(0x0240, "operate") == 0x0406
    assert pd.next_control_word(0x0331, "operate") == 0x047F


def test_tv7_zsw_decode(prof):
    names = pd.stw_names(prof)
    assert [b for b in range(16) if 0x0331 >> b & 1] == [0, 4, 5, 8, 9]
    assert pd.bit_list(0x0337, names) == ["ready to switch on", "ready to operate",
                                          "operation enabled", "no OFF2", "no OFF3", "at setpoint",
                                          "control requested"]
    assert pd.state_from_status(0x0331) is pd.State.S2
    assert pd.state_from_status(0x0337) is pd.State.S4


@pytest.mark.parametrize("code,raw,value", [("F002", 0x0190, 4.0), ("A038", 0x01F4, 5.0),
                                            ("A004", 0x004B, 75)])
def test_tv8_parameter_scaling(prof, code, raw, value):
    p = prof.param(code)
    assert mo.value_from_wire(p, raw) == value
    assert mo.wire_from_value(p, value) == raw


def test_tv9_device_id(prof):
    assert mo.device_name(0x012C) == "DV6" and mo.device_name(0x812C) == "DF6"
    c = pd.config(prof)
    assert pd.decode_device_id(0x812C, c) == "DF6" and pd.decode_device_id(0x012C, c) == "DV6"


def test_tv10_baud_codes(prof):
    want = ["12 Mbit/s", "6 Mbit/s", "3 Mbit/s", "1.5 Mbit/s", "500 kbit/s", "187.5 kbit/s",
            "93.75 kbit/s", "45.45 kbit/s", "19.2 kbit/s", "9.6 kbit/s"]
    assert [mo.baud_text(i, prof) for i in range(10)] == want
    assert "invalid" in mo.baud_text(10, prof)


def test_tv11_address_switches():
    assert mo.address_from_switches(right=2, left=7) == 27
    with pytest.raises(ValueError):
        mo.address_from_switches(10, 0)


def test_tv12_fault_slots(prof):
    c = pd.config(prof)
    slots = dict(zip(c.fault_subindexes, c.fault_positions))
    assert slots == {1: "current", 9: "last", 17: "2nd last", 25: "3rd last", 33: "4th last",
                     41: "5th last", 49: "6th last"}
    reqs = pd.fault_memory_requests(c)
    assert [f.words()[:2] for _, f in reqs][:2] == [(0x63B3, 0x0100), (0x63B3, 0x0900)]


def test_tv13_fault_codes(prof):
    assert mo.fault_text(prof, 0) == "no fault"
    assert mo.fault_text(prof, 1).startswith("E01 ")
    assert "USP" in mo.fault_text(prof, 13)
    assert "Gate array" in mo.fault_text(prof, 23)
    assert "Brake" in mo.fault_text(prof, 36)
    assert mo.fault_text(prof, 60) == "E60 Option 1 fault 0"
    assert mo.fault_text(prof, 69) == "E69 Option 1 fault 9"
    assert mo.fault_text(prof, 70) == "E70 Option 2 fault 0"
    assert mo.fault_text(prof, 79) == "E79 Option 2 fault 9"
    assert mo.fault_text(prof, 17) == "unknown (17)"
    assert len(prof.alarms) == 42


@pytest.mark.parametrize("bits,meaning", [((1, 0, 0), "frequency and commands"),
                                          ((1, 1, 0), "frequency only"),
                                          ((1, 0, 1), "commands only"), ((1, 1, 1), "nothing"),
                                          ((0, 0, 0), "nothing (data invalid)"),
                                          ((0, 1, 1), "nothing (data invalid)")])
def test_tv14_source_selection(bits, meaning):
    b10, b12, b13 = bits
    ctw = 0x007F | b10 << 10 | b12 << 12 | b13 << 13
    assert mo.source_selection(ctw) == meaning


def test_direction_sign_xor_bit11():
    assert mo.direction_text(0x047F, 0x2000) == "forward"
    assert mo.direction_text(0x0C7F, 0x2000) == "reverse"
    assert mo.direction_text(0x047F, 0xE000) == "reverse"
    assert mo.direction_text(0x0C7F, 0xE000) == "forward"


# -- derived vectors D-1 .. D-8 (not in the manual) -----------------------------------------------

def test_derived_d1_read_fault_memory(prof):
    assert pd.words_to_bytes(pd.read_request(947, 9, array=True).words()) == h("63 B3 09 00 00 00 00 00")
    d = pd.describe_pkw(prof, pd.PkwFrame(4, 947, 9, 5), "response")
    assert d["alarms"] == ["E05"] and "E05" in d["value_text"]


def test_derived_d2_device_id(prof):
    assert pd.words_to_bytes(pd.read_request(964).words()) == h("13 C4 00 00 00 00 00 00")
    for resp, dev in (("13 C4 00 00 00 00 01 2C", "DV6"), ("13 C4 00 00 00 00 81 2C", "DF6")):
        f = pd.PkwFrame.from_words(pd.bytes_to_words(h(resp)))
        assert dev in pd.describe_pkw(prof, f, "response")["value_text"]


def test_derived_d3_save():
    assert [pd.words_to_bytes(f.words()) for f in pd.save_requests()] == \
        [h("23 CB 00 00 00 00 00 00"), h("23 CB 00 00 00 00 00 01")]


def test_derived_d4_edit_rights():
    assert pd.words_to_bytes(pd.write_request(927, 1).words()) == h("23 9F 00 00 00 00 00 01")


def test_derived_d5_a001_and_refusal(prof):
    p = prof.param("A001")
    req = pd.write_request(p.pnu, mo.wire_from_value(p, 2))
    assert pd.words_to_bytes(req.words()) == h("20 BD 00 00 00 00 00 02")
    f = pd.PkwFrame.from_words(pd.bytes_to_words(h("70 BD 00 00 00 00 00 11")))
    d = pd.describe_pkw(prof, f, "response")
    assert d["error"] == 17 and "operating state" in d["error_text"]


def test_derived_d6_read_f003():
    assert pd.words_to_bytes(pd.read_request(26).words()) == h("10 1A 00 00 00 00 00 00")


def test_derived_d7_rejection(prof):
    f = pd.PkwFrame(7, 23, 0, 2)
    d = pd.describe_pkw(prof, f, "response")
    assert d["error"] == 2 and "limits" in d["error_text"]


def test_derived_d8_ack_sequence():
    seq, prev = [], 0x0406
    for stw in (0x0238, 0x0238):           # fault shown twice
        prev = pd.next_control_word(stw, "ack", previous=prev)
        seq.append(prev)
    seq.append(pd.next_control_word(0x0250, "ack", previous=prev))      # S1 after the edge
    seq.append(pd.next_control_word(0x0331, "operate", previous=seq[-1]))
    assert seq == [0x0486, 0x0406, 0x0406, 0x047F]


# -- values on the wire ---------------------------------------------------------------------------

def test_signed_and_sized_values(prof):
    a113 = prof.param("A113")                 # 1 octet, signed
    assert mo.wire_from_value(a113, -1) == 0xFF
    assert mo.value_from_wire(a113, 0xFF) == -1
    assert mo.value_from_wire(a113, 0xFFFFFFFF) == -1     # card that sign-extends
    a111 = prof.param("A111")                 # 4 octets, signed, x100
    assert mo.wire_from_value(a111, -400.0) == (-40000) & 0xFFFFFFFF
    assert mo.value_from_wire(a111, (-40000) & 0xFFFFFFFF) == -400.0
    assert mo.value_from_wire(prof.param("b034"), 3) == 30     # one count = 10 h


def test_ranges(prof):
    assert mo.in_ranges(prof.param("C001"), 255) and not mo.in_ranges(prof.param("C001"), 100)
    assert mo.in_ranges(prof.param("b096"), 700) and not mo.in_ranges(prof.param("b096"), 500)
    assert not mo.in_ranges(prof.param("F002"), 0)


# -- validation of Moeller keys -------------------------------------------------------------------

def _copy_profile(tmp_path, edit):
    src = ROOT / "profiles" / "moeller-de6-net-dp.yaml"
    text = src.read_text(encoding="utf-8")
    dst = tmp_path / "moeller-test.yaml"
    dst.write_text(edit(text), encoding="utf-8")
    return dst, load_profile_file(dst, check_sections=False)


@pytest.mark.parametrize("old,new,msg", [
    ("commands: {param: A002, bus_value: 1}", "commands: {param: A999, bus_value: 1}",
     "A999 is not a parameter"),
    ("comm_loss: {param: P002, other_param: P001, alarm: E70}",
     "comm_loss: {param: P002, other_param: P001, alarm: E99}", "E99"),
    ("  df6_device_id: 0x812C", "  df6_device_id: 0x812C\n  colour: blue", "unknown key 'colour'"),
    ('pnu: 23, unit: "s", scale: 0.01, min: 0.01, max: 3600.0, access: "rw", bytes: 4',
     'pnu: 23, unit: "s", scale: 0.01, min: 0.01, max: 3600.0, access: "rw", bytes: 3',
     "bytes must be 1, 2 or 4"),
    ('"A001", name: "Selection of frequency command destination", pnu: 189',
     '"A001", name: "Selection of frequency command destination", flavour: x, pnu: 189',
     "unknown key(s) flavour"),
])
def test_moeller_key_errors_name_line(tmp_path, old, new, msg):
    path, prof = _copy_profile(tmp_path, lambda t: t.replace(old, new, 1))
    with pytest.raises(DataFileError) as ei:
        mo.moeller_config(prof)
    assert msg in ei.value.message
    lines = path.read_text(encoding="utf-8").splitlines()
    assert ei.value.line and new.split("\n")[-1].strip()[:20] in lines[ei.value.line - 1]
    assert str(ei.value).startswith(f"{path}:{ei.value.line}:")


def test_make_drive_validates(tmp_path):
    from profidrive_cli.drives import make_drive
    _, prof = _copy_profile(tmp_path, lambda t: t.replace("moeller:\n", "moeller_x:\n", 1))
    with pytest.raises(DataFileError, match="missing section 'moeller'"):
        make_drive(object(), prof, "ppo1")
