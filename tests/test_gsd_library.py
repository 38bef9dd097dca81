"""The device library in gsd/ and the lookup in profidrive_cli.gsd.library.

The idents and configuration octets below are the table in docs/architecture.md (the simulator and the
drive profiles use the same values). YASK00CA.GSD must be the listing printed in the Yaskawa manual:
it is compared with the spec's copy of the listing (../shared/spec, skipped when absent).

Decisions recorded here (YASK00CA.GSD cannot carry comments without changing its printed content):
- the file is the two code blocks of the manual listing (header comment block, then the body) in the order
  printed, with DOS line ends; the `=====` separator lines of the listing are kept: they stand before
  `#PROFIBUS_DP`, where a GSD reader ignores everything (spec §3.3);
- errata E20: the file is named YASK00CA.GSD (manual text) although the header comment says
  YASK00CA_Rev1YEA.GSD; the identity key is Ident_Number 0x00CA;
- errata E21: the `MaxTsd_<baud>` spelling is kept as printed; the parser reads it as `MaxTsdr_<baud>`.
"""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path

import pytest

from profidrive_cli import UsageError
from profidrive_cli.data import gsd_dir
from profidrive_cli.datafile import DataFileError
from profidrive_cli.gsd import build_prm, decode_unit_diag, parse_gsd
from profidrive_cli.gsd import library
from profidrive_cli.gsd.model import select_module

HERE = Path(__file__).resolve().parent
SPEC = Path(os.environ.get("PDRIVE_SPEC_DIR", HERE.parents[1] / "shared" / "spec"))

ARCH_TABLE = {
    "FUJIFD01.GSD": (0xFD01, {"PPO1": "F3 F1", "PPO2": "F3 F5", "PPO3": "F1", "PPO4": "F5"}),
    "FUJIFD02.GSD": (0xFD02, {"PPO1": "F3 F1", "PPO2": "F3 F5", "PPO3": "F1", "PPO4": "F5"}),
    "TOYO0BE7.GSD": (0x0BE7, {"PPO1": "F3 F1", "PPO2": "F3 F5", "PPO3": "F1", "PPO4": "F5", "PPO5": "F3 F9",
                              "Toyo mode PLCH off": "E9 DF D1", "Toyo mode PLCH on": "EF DF D6"}),
    "MOELFD06.GSD": (0xFD06, {"PPO1": "F3 F1", "PPO2": "F3 F5", "PPO3": "F1", "PPO4": "F5", "PPO5": "F3 F9"}),
    "YASK00CA.GSD": (0x00CA, {"Basic data": "72", "Extended Data 1": "5F 6F", "Extended Data 2": "55 65"}),
}


@pytest.fixture(autouse=True)
def _no_env(monkeypatch):
    monkeypatch.delenv("PDRIVE_GSD_DIR", raising=False)
    library.clear_cache()


def test_library_holds_exactly_the_five_files():
    names = sorted(p.name for p in library.gsd_files(gsd_dir()))
    assert names == sorted(ARCH_TABLE)


@pytest.mark.parametrize("name", sorted(ARCH_TABLE))
def test_library_file_matches_architecture_table(name):
    ident, modules = ARCH_TABLE[name]
    g = parse_gsd(gsd_dir() / name)
    assert g.ident_number == ident
    assert g.warnings == []
    assert len(g.modules) == len(modules)
    for sel, cfg in modules.items():
        m = select_module(g, sel)
        assert m.cfg == bytes.fromhex(cfg), (name, sel)
        assert build_prm(g, [sel]).cfg == bytes.fromhex(cfg)
    assert g.station_type == 0 and g.protocol_ident == 0 and g.slave_family == 1
    assert g.supported_bauds() == ["9.6", "19.2", "45.45", "93.75", "187.5", "500", "1.5M", "3M", "6M", "12M"]
    assert g.auto_baud_supp and not g.set_slave_add_supp
    assert g.modular_station and g.max_module == 1
    for m in g.modules:                                # the GSD's own size limits hold for every module
        assert m.inputs <= g.max_input_len and m.outputs <= g.max_output_len
        assert m.inputs + m.outputs <= g.max_data_len
        assert build_prm(g, [m]).user_prm == b""       # no user parameters in any of the five


@pytest.mark.parametrize("name,ppo_count,max_in,max_diag", [
    ("FUJIFD01.GSD", 4, 20, 6), ("FUJIFD02.GSD", 4, 20, 6), ("MOELFD06.GSD", 5, 28, 6),
    ("TOYO0BE7.GSD", 5, 46, 15), ("YASK00CA.GSD", 0, 32, 6),
])
def test_library_sizes_from_the_manuals(name, ppo_count, max_in, max_diag):
    g = parse_gsd(gsd_dir() / name)
    assert sum(1 for m in g.modules if m.name.startswith("PPO")) == ppo_count
    assert g.max_input_len == max_in
    assert g.max_diag_data_len == max_diag
    assert max(m.inputs for m in g.modules) == max_in          # the limit is reached by some module


@pytest.mark.parametrize("name", ["FUJIFD01.GSD", "FUJIFD02.GSD", "MOELFD06.GSD"])
def test_placeholder_idents_say_so(name):
    text = (gsd_dir() / name).read_text(encoding="ascii")
    head = text.split("#Profibus_DP")[0]
    assert "PLACEHOLDER" in head and "vendor's GSD" in head
    ident_line = next(ln for ln in text.splitlines() if ln.startswith("Ident_Number"))
    assert "PLACEHOLDER" in ident_line


def test_toyo_ident_is_marked_as_inferred_and_its_diag_texts_decode():
    text = (gsd_dir() / "TOYO0BE7.GSD").read_text(encoding="ascii")
    assert "INFERRED from the file name" in text
    g = parse_gsd(gsd_dir() / "TOYO0BE7.GSD")
    # manual example (spec D19): 09 | status 0080 | fault flag 1 0001 (overcurrent) | fault flag 2 | MFO
    assert decode_unit_diag(g, bytes.fromhex("09 00 80 00 01 00 00 00 00")) == ["Overcurrent (unit diag bit 24)"]
    # fault flag 1 bit 15 (option error, octet +9 bit 7) and fault flag 2 bit 1 (comm timeout, +12 bit 1)
    assert decode_unit_diag(g, bytes.fromhex("09 00 00 80 00 00 02 00 00")) == [
        "Option error (unit diag bit 23)", "Communication timeout error (unit diag bit 41)"]
    assert decode_unit_diag(g, bytes.fromhex("00")) == []      # +6 = 0: no external data


def test_yaskawa_file_is_the_printed_listing():
    spec = SPEC / "yaskawa-profibus-dp.md"
    if not SPEC.is_dir():
        pytest.skip(f"{SPEC} not present")
    assert spec.is_file(), f"{spec} missing from {SPEC}"
    lines = spec.read_text(encoding="utf-8").splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("### 3.1 Exact content as printed"))
    blocks, cur = [], None
    for ln in lines[start:]:
        if ln.strip() == "```":
            if cur is None:
                cur = []
            else:
                blocks.append(cur)
                cur = None
                if len(blocks) == 2:
                    break
        elif cur is not None:
            cur.append(ln)
    want = "\r\n".join(blocks[0] + blocks[1]) + "\r\n"
    assert (gsd_dir() / "YASK00CA.GSD").read_bytes() == want.encode("ascii")


def test_yaskawa_golden_values():
    # spec §11.8 vector 14
    g = parse_gsd(gsd_dir() / "YASK00CA.GSD")
    assert (g.vendor_name, g.model_name, g.ident_number, g.gsd_revision) == \
        ("YASKAWA ELECTRIC", "PROFIBUS-DP INTERFACE CARD SI-P1", 0x00CA, 1)
    assert {r["baud"]: r["max_tsdr"] for r in g.max_tsdr_table() if r["supported"]} == {
        "9.6": 60, "19.2": 60, "45.45": 250, "93.75": 60, "187.5": 60, "500": 100, "1.5M": 150, "3M": 250,
        "6M": 450, "12M": 800}
    assert all(not r["default"] for r in g.max_tsdr_table() if r["supported"])   # all given, via MaxTsd_
    assert g.freeze_mode_supp and g.sync_mode_supp and g.auto_baud_supp and not g.set_slave_add_supp
    assert (g.min_slave_intervall, g.max_input_len, g.max_output_len, g.max_data_len) == (1, 32, 32, 64)
    assert (g.get("modul_offset"), g.fail_safe, g.max_diag_data_len, g.get("implementation_type")) == \
        (1, False, 6, "SPC3")
    assert (g.get("redundancy"), g.get("repeater_ctrl_sig"), g.get("24v_pins")) == (0, 2, 0)
    assert g.user_prm_data_len is None and g.prm.empty
    assert [(m.inputs, m.outputs) for m in g.modules] == [(6, 6), (32, 32), (12, 12)]


# ------------------------------------------------------------------ lookup
def test_find_by_ident_and_load_gsd_forms():
    g = library.find_by_ident(0x00CA)
    assert g is not None and g.model_name == "PROFIBUS-DP INTERFACE CARD SI-P1"
    assert library.find_by_ident(0x4242) is None
    assert library.load_gsd(0x0BE7).vendor_name == "Toyo Denki"
    assert library.load_gsd("0x0be7") is library.load_gsd(3047)             # cached: same object
    assert library.load_gsd("moelfd06").ident_number == 0xFD06               # library name, any case
    assert library.load_gsd("FUJIFD02.GSD").ident_number == 0xFD02
    assert library.load_gsd(str(gsd_dir() / "FUJIFD01.GSD")).ident_number == 0xFD01
    with pytest.raises(UsageError, match="no GSD file with ident 0x4242"):
        library.load_gsd(0x4242)
    with pytest.raises(UsageError, match="no such GSD file"):
        library.load_gsd("NOPE.GSD")
    assert library.station_name(0xFD06) == "Moeller DE6-NET-DP (DF6/DV6)"
    assert library.station_name(0x4242) is None


def test_user_folder_wins_over_library(tmp_path, monkeypatch):
    user = tmp_path / "vendor"
    user.mkdir()
    (user / "fuji_real.gsd").write_bytes(
        b'#Profibus_DP\r\nVendor_Name = "Fuji Electric"\r\nModel_Name = "vendor file"\r\n'
        b'Ident_Number = 0xFD01\r\nProtocol_Ident = 0\r\nStation_Type = 0\r\n12M_supp = 1\r\n'
        b'Module = "PPO1" 0xF3, 0xF1\r\nEndModule\r\n')
    assert library.find_by_ident(0xFD01).model_name == "OPC-G1-PDP (FRENIC-MEGA)"
    assert library.find_by_ident(0xFD01, user).model_name == "vendor file"
    entries = library.list_library(user)
    assert entries[0].source == "user" and entries[0].path.name == "fuji_real.gsd"
    lib_fuji = next(e for e in entries if e.path.name == "FUJIFD01.GSD")
    assert lib_fuji.source == "library" and lib_fuji.shadowed_by == user / "fuji_real.gsd"
    # the environment variable works the same way
    monkeypatch.setenv("PDRIVE_GSD_DIR", str(user))
    assert library.find_by_ident(0xFD01).model_name == "vendor file"
    with pytest.raises(UsageError, match="no such folder"):
        library.find_by_ident(0xFD01, tmp_path / "missing")


def test_broken_user_file_is_listed_with_its_error(tmp_path):
    shutil.copy(HERE / "data" / "gsd_broken" / "bad_number.gsd", tmp_path / "bad_number.gsd")
    entries = library.list_library(tmp_path)
    bad = entries[0]
    assert bad.path.name == "bad_number.gsd" and bad.error and ":3:" in bad.error
    assert len(entries) == 6                                   # the five library files still listed


# what every complete GSD file has besides Ident_Number and a Module (gsd.required)
HEAD = (b'#Profibus_DP\nVendor_Name = "V"\nModel_Name = "M"\nProtocol_Ident = 0\nStation_Type = 0\n'
        b'9.6_supp = 1\n')


def test_cache_reparses_only_when_the_file_changes(tmp_path):
    p = tmp_path / "x.gsd"
    p.write_bytes(HEAD + b'Ident_Number = 0x1111\nModule = "M" 0x10\nEndModule\n')
    g1 = library.parse_cached(p)
    assert library.parse_cached(p) is g1
    assert library.find_by_ident(0x1111, tmp_path) is g1
    time.sleep(0.01)
    p.write_bytes(HEAD + b'Ident_Number = 0x2222\nModule = "M" 0x10\nEndModule\n')
    os.utime(p, ns=(time.time_ns(), time.time_ns() + 10_000_000))
    assert library.parse_cached(p).ident_number == 0x2222
    assert library.find_by_ident(0x1111, tmp_path) is None
    with pytest.raises(DataFileError, match="file not found"):
        library.parse_cached(tmp_path / "gone.gsd")


def test_broken_user_file_is_skipped_with_a_warning_not_used(tmp_path, monkeypatch):
    """A user file that claims an ident but does not parse never shadows the library's file."""
    seen = []
    monkeypatch.setattr(library, "warn_hook", seen.append)
    library.clear_cache()
    (tmp_path / "YASKCUT.GSD").write_bytes((gsd_dir() / "YASK00CA.GSD").read_bytes()[:600])
    g = library.find_by_ident(0x00CA, tmp_path)
    assert g is not None and Path(g.path).name == "YASK00CA.GSD"
    assert library.find_path_by_ident(0x00CA, tmp_path).name == "YASK00CA.GSD"
    assert len(seen) == 1 and "YASKCUT.GSD:24: incomplete GSD file" in seen[0]     # once per process
    assert library.station_name(0x00CA, tmp_path) == g.title


def test_env_folder_missing_is_an_error_like_gsd_dir(tmp_path, monkeypatch):
    seen = []
    monkeypatch.setattr(library, "warn_hook", seen.append)
    library.clear_cache()
    monkeypatch.setenv("PDRIVE_GSD_DIR", str(tmp_path / "nope"))
    with pytest.raises(UsageError, match=f"PDRIVE_GSD_DIR {tmp_path / 'nope'}: no such folder"):
        library.list_library()
    with pytest.raises(UsageError, match="no such folder"):
        library.load_gsd("0x00CA")
    assert library.station_name(0xFD06) == "Moeller DE6-NET-DP (DF6/DV6)"      # naming only warns
    assert seen == [f"PDRIVE_GSD_DIR {tmp_path / 'nope'}: no such folder (ignored)"]


def test_library_names_from_the_header_lines_are_the_parsed_titles():
    """station_name reads only Vendor_Name / Model_Name of pdrive's own files: for every library file
    that is the title the full parse gives (and every library file parses)."""
    library.clear_cache()
    files = library.gsd_files(gsd_dir())
    assert len(files) == 5
    for p in files:
        g = library.parse_cached(p)
        assert library._head(p) == (g.ident_number, g.title), p.name
        assert library.station_name(g.ident_number) == g.title
    library.clear_cache()


def test_a_user_file_names_its_station_over_the_library_header(tmp_path, monkeypatch):
    monkeypatch.delenv("PDRIVE_GSD_DIR", raising=False)
    library.clear_cache()
    (tmp_path / "fuji_real.gsd").write_bytes(
        b'#Profibus_DP\r\nVendor_Name = "Fuji Electric"\r\nModel_Name = "vendor file"\r\n'
        b'Ident_Number = 0xFD01\r\nProtocol_Ident = 0\r\nStation_Type = 0\r\n12M_supp = 1\r\n'
        b'Module = "PPO1" 0xF3, 0xF1\r\nEndModule\r\n')
    assert library.station_name(0xFD01, tmp_path) == "Fuji Electric vendor file"
    assert library.station_name(0xFD01) == "Fuji Electric OPC-G1-PDP (FRENIC-MEGA)"
    library.clear_cache()


def test_a_name_line_the_header_reader_cannot_take_is_left_to_the_parser(tmp_path):
    p = tmp_path / "x.gsd"
    p.write_bytes(b'#Profibus_DP\r\nVendor_Name = Fuji\r\nModel_Name = "a" "b"\r\nIdent_Number = 0x1234\r\n')
    library.clear_cache()
    assert library._head(p) == (0x1234, None)
    p.write_bytes(b'#Profibus_DP\r\nvendor_name="ACME" ; the maker\r\nIdent_Number = 4660\r\n')
    assert library._head(p) == (0x1234, "ACME")
    library.clear_cache()
