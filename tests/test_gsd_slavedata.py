"""Issue 27, every slave decoded: the GSD modules that give a configuration (gsd/match.py), a slave's
cyclic data by module (gsd/slavedata.py), its Set_Prm user data with the GSD's texts
(gsd/interp.py decode_user_prm), sniff's and io's by-module view (bustools/slaveview.py) and
`pdrive gsd match` (offline, on sim://, and a Cfg_Fault explained).

Real files: the vendor GSDs of ../shared/testdata/gsd/proview and the ET200S start-up of
../shared/testdata/external (read from there, never copied; $PDRIVE_GSD_TESTDATA /
$PDRIVE_EXTERNAL_TESTDATA point elsewhere). Expected values come from the files' lines (quoted) and
the identifier rules of ../shared/spec/profibus-dp-reference.md §3.2 worked by hand.
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

from profidrive_cli import BusError
from conftest import SHARED, pdrive_cmd
from profidrive_cli.dp.capture import Capture
from profidrive_cli.fdl import frames as F
from profidrive_cli.gsd.library import load_gsd
from profidrive_cli.gsd.match import MAX_FITS, explain_refusal, match_cfg
from profidrive_cli.gsd.parser import parse_gsd_text
from profidrive_cli.gsd.slavedata import layout, values

HERE = Path(__file__).resolve().parent
GSDS = Path(os.environ.get("PDRIVE_GSD_TESTDATA", Path(SHARED) / "testdata" / "gsd"))
EXTERNAL = Path(os.environ.get("PDRIVE_EXTERNAL_TESTDATA", Path(SHARED) / "testdata" / "external"))
ET200S_RAW = EXTERNAL / "pyprofibus26-et200s-startup.raw"

# pyprofibus26-et200s-startup.txt: Set_Prm `... 80 6A 01 | 40 01 00 11 21 00 ... 20 01 00 20 08 00 20 08 00`
# (the user data: the octets after the 7 standard ones) and Chk_Cfg `00 10 20`
ET200S_PRM = bytes.fromhex("40 01 00 11 21" + " 00" * 15 + " 20 01 00 20 08 00 20 08 00")
ET200S_CFG = bytes.fromhex("00 10 20")


def _real(name: str) -> Path:
    hits = list(GSDS.rglob(name))
    if not hits:
        pytest.skip(f"{name} not in {GSDS} (../shared/testdata/gsd)")
    return hits[0]


def _gsd(modules: str, modular: int = 1, extra: str = "") -> str:
    return ("#Profibus_DP\nIdent_Number = 0x1234\nVendor_Name = \"test\"\nModel_Name = \"match\"\n"
            f"Protocol_Ident = 0\nStation_Type = 0\n9.6_supp = 1\nModular_Station = {modular}\n{extra}"
            + modules)


# -- match: the shipped GSDs (the sim's stations) -------------------------------------------------

def test_the_shipped_fuji_gsd_names_ppo1_for_f3_f1():
    # gsd/FUJIFD01.GSD:61  Module = "PPO1: 4 PKW + 2 PZD" 0xF3, 0xF1
    r = match_cfg(load_gsd("0xFD01"), bytes.fromhex("F3 F1"))
    assert len(r.fits) == 1 and r.complete
    assert [s.name for s in r.fits[0].slots] == ["PPO1: 4 PKW + 2 PZD"]


def test_a_configuration_no_module_gives_says_where_it_stops():
    # FUJIFD01.GSD has F3 F1 / F3 F5 / F1 / F5 (lines 61-67): after F3, F9 matches nothing
    r = match_cfg(load_gsd("0xFD01"), bytes.fromhex("F3 F9"))
    assert r.fits == [] and r.unmatched_at == 0
    assert "match no module" in r.describe()[0]


def test_a_cfg_fault_is_explained_by_module():
    lines = explain_refusal(load_gsd("0xFD01"), bytes.fromhex("F3 F1"), bytes.fromhex("F3 F9"))
    assert lines[0] == "the slave has these modules: PPO1: 4 PKW + 2 PZD [f3 f1]"
    # F9 = 0b1111_1001: consistent, words, in+out, 9+1 = 10 words (reference §3.2)
    assert lines[1].startswith("you configured those: f3 f9") and "f9 = 10 words in+out" in lines[1]


# -- match: sequences, the bound, Max_Module, compact slaves -------------------------------------

def test_a_modular_slave_is_cut_into_a_sequence_of_modules():
    g = parse_gsd_text(_gsd('Module = "DI8" 0x10\nEndModule\nModule = "DO8" 0x20\nEndModule\n'
                            'Module = "AI2" 0x51\nEndModule\n'))
    r = match_cfg(g, bytes.fromhex("10 20 20 51"))
    assert [s.name for s in r.best.slots] == ["DI8", "DO8", "DO8", "AI2"]
    assert [s.offset for s in r.best.slots] == [0, 1, 2, 3]


def test_the_search_stops_at_its_bound_and_puts_the_fewest_modules_first():
    # "A" = 10, "B" = 10 10: twelve 0x10 octets can be cut in Fibonacci(13) = 233 ways (> MAX_FITS)
    g = parse_gsd_text(_gsd('Module = "A" 0x10\nEndModule\nModule = "B" 0x10,0x10\nEndModule\n'))
    r = match_cfg(g, bytes(12 * [0x10]))
    assert not r.complete and len(r.fits) == MAX_FITS
    assert [s.name for s in r.fits[0].slots] == ["B"] * 6          # 6 slots: the fewest possible
    assert "stops there" in r.describe()[0]


def test_max_module_drops_longer_sequences():
    g = parse_gsd_text(_gsd('Module = "A" 0x10\nEndModule\nModule = "B" 0x10,0x10\nEndModule\n',
                            extra="Max_Module = 2\n"))
    r = match_cfg(g, bytes.fromhex("10 10 10"))
    assert sorted(tuple(s.name for s in f.slots) for f in r.fits) == [("A", "B"), ("B", "A")]


def test_a_compact_slave_has_its_fixed_configuration_only():
    g = parse_gsd_text(_gsd('Module = "fixed" 0x13,0x23\nEndModule\n', modular=0))
    assert match_cfg(g, bytes.fromhex("13 23")).best.slots[0].name == "fixed"
    r = match_cfg(g, bytes.fromhex("13"))
    assert r.fits == [] and "compact slave" in r.problem


def test_octets_that_are_not_identifiers_are_a_problem_not_a_crash():
    g = parse_gsd_text(_gsd('Module = "A" 0x10\nEndModule\n'))
    assert "not identifier octets" in match_cfg(g, bytes.fromhex("C0")).problem   # length octet missing


# -- the real ET200S: its GSD, its Chk_Cfg and its Set_Prm from the wire ---------------------------

def test_the_et200s_modules_narrowed_by_its_set_prm():
    g = load_gsd(_real("si02806a.gse"))
    plain = match_cfg(g, ET200S_CFG).best
    narrowed = match_cfg(g, ET200S_CFG, ET200S_PRM).best
    assert [len(s.candidates) for s in narrowed.slots] < [len(s.candidates) for s in plain.slots]
    # si02806a.gse:7277-7298: the two 8DI (0x10) and the two 8DO (0x20) carry the module block
    # Ext_Module_Prm_Data_Len = 3, Const(0) = 0x20,0x08,0x00 -- the octets the wire shows twice
    assert [m.display_name for m in narrowed.slots[1].candidates] == [
        "6ES7 131-4BF00-0AA0 8DI", "6ES7 131-4BF50-0AA0 8DI DC24V"]
    assert [m.display_name for m in narrowed.slots[2].candidates] == [
        "6ES7 132-4BF00-0AA0 8DO", "6ES7 132-4BF50-0AA0 8DO DC24V"]
    # si02806a.gse:4535-4538: PM-E DC24V 0x00 with Const(0) = 0x20,0x01,0x00 -- the first module block
    assert "PM-E" in narrowed.slots[0].candidates[0].display_name


def test_the_et200s_data_by_module():
    lay = layout(load_gsd(_real("si02806a.gse")), ET200S_CFG, ET200S_PRM)
    # 00: no data; 10: 1 byte in; 20: 1 byte out (reference §3.2 compact format); each direction's
    # offsets run on in configuration order (slot 3's input offset is 1, after slot 2's one octet)
    got = [(m.slot, m.direction, m.in_offset, m.in_len, m.out_offset, m.out_len) for m in lay.modules]
    assert got == [(1, "none", 0, 0, 0, 0), (2, "in", 0, 1, 0, 0), (3, "out", 1, 0, 0, 1)]
    assert values(lay, "in", b"\x05") == [{"slot": 2, "name": "6ES7 131-4BF00-0AA0 8DI", "offset": 0,
                                          "octets": "05"}]
    assert [m["slot"] for m in values(lay, "out", b"\x81")] == [3]


def test_the_et200s_set_prm_read_with_the_gsds_texts():
    lay = layout(load_gsd(_real("si02806a.gse")), ET200S_CFG, ET200S_PRM)
    rows, _ = lay.prm_rows()
    # si02806a.gse:3110 Ext_User_Prm_Data_Ref(1)=39; :1420 ExtUserPrmData = 39 "Operation for
    # ref.<>actual conf." Bit(0) 0 0-1, Prm_Text_Ref = 1; :17-19 Text(1) = "enable". User data
    # octet 1 is 0x01 on the wire: bit 0 set.
    r = next(r for r in rows if r["name"] == "Operation for ref.<>actual conf.")
    assert (r["offset"], r["value"], r["text"], r["default"]) == (1, 1, "enable", 0)


def test_a_special_format_identifier_by_direction():
    # janitza_umg96s.gsd:58  Module = "STD: 62 Word In, 2 Byte Out" 0xc0,0x01,0x7d: special format,
    # C0 = in+out lengths follow; 01 = 2 octets out; 7D = words, 0x3D + 1 = 62 words = 124 octets in
    lay = layout(load_gsd(_real("janitza_umg96s.gsd")), bytes.fromhex("C0 01 7D"))
    (m,) = lay.modules
    assert (m.out_len, m.in_len, m.direction) == (2, 124, "in/out")
    assert m.name == "STD: 62 Word In, 2 Byte Out"


def test_without_a_fit_each_identifier_is_its_own_module():
    lay = layout(load_gsd("0xFD01"), bytes.fromhex("F3 F9"))
    assert [m.name for m in lay.modules] == ["identifier f3", "identifier f9"]
    assert (lay.modules[1].out_offset, lay.modules[1].out_len) == (8, 20)      # after F3's 4 words


# -- sniff: learnt from the traffic, by module ------------------------------------------------------

def _frames(raw: bytes):
    return [c.frame for c in Capture().feed(raw, 0.0) if c.frame is not None]


def _de(da: int, out: bytes, inp: bytes) -> bytes:
    return (F.encode(F.Frame(F.SD2, da, 2, F.request_fc(F.SRD_HIGH, True, True), out))
            + F.encode(F.Frame(F.SD2, 2, da, F.DL, inp)))


def test_sniff_learns_the_et200s_and_shows_its_data_by_module(monkeypatch):
    from profidrive_cli.bustools import slaveview
    monkeypatch.setenv("PDRIVE_GSD_DIR", str(_real("si02806a.gse").parent))
    calls = []
    real_layout = slaveview.layout
    monkeypatch.setattr(slaveview, "layout", lambda *a: calls.append(a) or real_layout(*a))
    raw = ET200S_RAW.read_bytes() if ET200S_RAW.exists() else pytest.skip("no ET200S capture")
    view = slaveview.SlaveView()
    decoded = [view.decode(f, None) for f in _frames(raw + _de(5, b"\x81", b"\x05") * 50)]
    chk = next(d for d in decoded if d and "layout" in d)
    assert [m["name"].split(" (")[0] for m in chk["layout"]][1:] == ["6ES7 131-4BF00-0AA0 8DI",
                                                                    "6ES7 132-4BF00-0AA0 8DO"]
    assert any("Operation for ref.<>actual conf. = 1 (enable)" in t for t in chk["text"])
    assert decoded[-2]["modules"] == [{"slot": 3, "name": "6ES7 132-4BF00-0AA0 8DO", "offset": 0,
                                      "octets": "81"}]
    assert decoded[-1]["modules"][0]["octets"] == "05"
    assert len(calls) == 1                            # the GSD work once, not per telegram


def test_sniff_by_module_for_a_sim_station_from_the_shipped_gsd():
    from profidrive_cli.bustools.slaveview import SlaveView
    fc = F.request_fc(F.SRD_HIGH, True, True)
    set_prm = bytes.fromhex("88 01 01 0b fd 01 00")            # ident 0xFD01 at octets 4..5
    raw = (F.encode(F.Frame(F.SD2, 3, 2, fc, set_prm, 61, 62))
           + F.encode(F.Frame(F.SD2, 3, 2, fc, bytes.fromhex("F3 F1"), 62, 62))
           + _de(3, bytes(8) + bytes.fromhex("04 7F 20 00"), bytes(12)))
    view = SlaveView()
    d = [view.decode(f, None) for f in _frames(raw)]
    assert d[1]["gsd"] == "FUJIFD01.GSD" and d[1]["layout"][0]["name"] == "PPO1: 4 PKW + 2 PZD"
    assert d[2]["modules"] == [{"slot": 1, "name": "PPO1: 4 PKW + 2 PZD", "offset": 0,
                                "octets": "00 00 00 00 00 00 00 00 04 7f 20 00"}]
    # a station watched as a drive (--station) is left to the drive decoder
    assert SlaveView(skip={3}).decode(_frames(raw)[1], None) is None


def test_sniff_cli_by_module_and_a_missing_gsd_dir(tmp_path):
    raw = tmp_path / "c.raw"
    fc = F.request_fc(F.SRD_HIGH, True, True)
    raw.write_bytes(F.encode(F.Frame(F.SD2, 3, 2, fc, bytes.fromhex("88 01 01 0b fd 01 00"), 61, 62))
                    + F.encode(F.Frame(F.SD2, 3, 2, fc, bytes.fromhex("F1"), 62, 62))
                    + _de(3, bytes.fromhex("04 7F 20 00"), bytes.fromhex("03 37 20 00")))
    r = subprocess.run(pdrive_cmd() + ["sniff", "--from-file", str(raw)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "inputs by module (FUJIFD01.GSD): 1 PPO3: 0 PKW + 2 PZD: 03 37 20 00" in r.stdout
    r = subprocess.run(pdrive_cmd() + ["sniff", "--from-file", str(raw), "--gsd-dir", str(tmp_path / "no")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "no such folder" in r.stderr and "Traceback" not in r.stderr


# -- gsd match on the command line, and the Cfg_Fault on sim:// ------------------------------------

def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(pdrive_cmd() + list(args), capture_output=True, text=True, timeout=120)


def test_gsd_match_offline():
    r = _run("gsd", "match", "--cfg", "F3 F5", "--ident", "0xFD06")
    # MOELFD06.GSD:64  Module = "PPO2: 4 PKW + 6 PZD" 0xF3, 0xF5
    assert r.returncode == 0 and "PPO2: 4 PKW + 6 PZD" in r.stdout
    r = _run("gsd", "match", "--cfg", "F3 F9", "--ident", "0xFD01")
    assert r.returncode == 1 and "match no module" in r.stdout


@pytest.mark.parametrize("args, words", [
    ((), "give a station ADDRESS"),
    (("--cfg", "F3 Fz", "--ident", "0xFD01"), "--cfg: not hex"),
    (("--cfg", "F1", "--ident", "0x7777"), "no GSD file with ident 0x7777"),
    (("3", "--cfg", "F1", "--port", "sim://"), "--cfg is for offline use"),
])
def test_gsd_match_bad_input_is_one_line_and_exit_2(args, words):
    r = _run("gsd", "match", *args)
    assert r.returncode == 2 and words in r.stderr and "Traceback" not in r.stderr


def test_gsd_match_reads_the_sim_station_and_explains_the_configured_one():
    r = _run("gsd", "match", "3", "--port", "sim://", "--configured", "F3 F9", "--json")
    d = json.loads(r.stdout)
    assert r.returncode == 1                               # the configured one differs
    assert d["cfg_from"] == "get_cfg" and d["cfg"] == "f3 f1" and d["cfg_fault"] is False
    assert d["fits"][0]["slots"][0]["modules"][0]["name"] == "PPO1: 4 PKW + 2 PZD"
    assert d["explain"][0] == "the slave has these modules: PPO1: 4 PKW + 2 PZD [f3 f1]"


def test_a_wrong_configuration_on_sim_gives_cfg_fault_and_gsd_match_names_the_modules():
    """The done-when of issue 27's item: a master configures station 3 (fuji-g1) with F3 F9, which it
    refuses (Cfg_Fault); gsd match's bus path then reads the Cfg_Fault and Get_Cfg and names the
    slave's modules next to the configured ones."""
    from profidrive_cli.api import make_master
    from profidrive_cli.cli.gsd_cmd import read_slave
    from profidrive_cli.dp.station import SlaveConfig
    from profidrive_cli.link import open_link
    m = make_master(open_link("sim://"), 19200, 2)
    try:
        m.add_station(3, SlaveConfig(ident=0xFD01, cfg=bytes.fromhex("F3 F9"), user_prm=b"", wd_ms=500))
        with pytest.raises(BusError, match="Cfg_Fault|configuration"):
            m.bring_up(3, timeout=2.0, fail_fast=True)
        d, cfg = read_slave(m, 3)
    finally:
        m.link.close()
    assert d.has("Cfg_Fault")
    assert cfg == bytes.fromhex("F3 F1")                  # the sim's default layout ppo1
    lines = explain_refusal(load_gsd(d.ident), cfg, bytes.fromhex("F3 F9"))
    assert "PPO1: 4 PKW + 2 PZD" in lines[0] and lines[1].startswith("you configured those: f3 f9")


def test_io_shows_the_inputs_by_module_from_get_cfg():
    r = _run("io", "7", "--cfg", "72", "--count", "1", "--port", "sim://", "--json")
    ev = json.loads(r.stdout.splitlines()[0])
    # YASK00CA.GSD:67 Module = "Basic data" 0x72: in+out (bits 5-4 = 11), words, 2 + 1 = 3 words
    assert r.returncode == 0 and ev["modules"][0]["name"] == "Basic data" and ev["modules"][0]["offset"] == 0
    assert ev["modules"][0]["octets"] == ev["inputs"]


def test_the_profirust_devices_configurations_by_identifier_without_their_gsd():
    """profirust-examples-prm-cfg.tsv: four real devices' Chk_Cfg; their GSDs are not in the test data,
    so each identifier is its own module. Sizes by reference §3.2 (compact format: bits 5-4 direction,
    bit 6 words, bits 3-0 length - 1): 00 nothing; 10 1 byte in; 20 1 byte out; F1 2 words in+out."""
    tsv = EXTERNAL / "profirust-examples-prm-cfg.tsv"
    if not tsv.exists():
        pytest.skip(f"{tsv} not present")
    rows = [ln.split("\t") for ln in tsv.read_text(encoding="utf-8").splitlines()
            if ln and not ln.startswith("#")]
    by_ident = {r[2]: bytes.fromhex(r[4]) for r in rows}
    wago = layout(None, by_ident["0xB757"])                # 00, ten 10, seven 20
    assert len(wago.modules) == 18 and (wago.input_len, wago.output_len) == (10, 7)
    assert [m.in_offset for m in wago.modules if m.in_len] == list(range(10))
    assert [m.out_offset for m in wago.modules if m.out_len] == list(range(7))
    mm4 = layout(None, by_ident["0x80B5"])                 # 00 F1: PPO3
    assert (mm4.input_len, mm4.output_len) == (4, 4) and mm4.modules[1].unit == "word"
    assert (layout(None, by_ident["0x000B"]).input_len, layout(None, by_ident["0x000B"]).output_len) == (1, 1)


def test_sniff_goes_on_when_pdrive_gsd_dir_is_stale(monkeypatch, tmp_path):
    from profidrive_cli.bustools.slaveview import SlaveView
    monkeypatch.setenv("PDRIVE_GSD_DIR", str(tmp_path / "gone"))
    fc = F.request_fc(F.SRD_HIGH, True, True)
    raw = (F.encode(F.Frame(F.SD2, 3, 2, fc, bytes.fromhex("88 01 01 0b fd 01 00"), 61, 62))
           + F.encode(F.Frame(F.SD2, 3, 2, fc, bytes.fromhex("F1"), 62, 62)))
    view = SlaveView()
    assert [view.decode(f, None) for f in _frames(raw)] == [None, None]
