"""`pdrive gsd show | list | prm` on the click group directly (CliRunner)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from click.testing import CliRunner

from profidrive_cli import UsageError
from profidrive_cli.cli.gsd_cmd import gsd_group
from profidrive_cli.datafile import DataFileError
from profidrive_cli.gsd import library

HERE = Path(__file__).resolve().parent
TESTDATA = Path(os.environ.get("PDRIVE_GSD_TESTDATA", HERE.parents[1] / "shared" / "testdata" / "gsd"))


@pytest.fixture(autouse=True)
def _no_env(monkeypatch):
    monkeypatch.delenv("PDRIVE_GSD_DIR", raising=False)
    library.clear_cache()


def run(*args: str, columns: int = 80):
    return CliRunner(env={"COLUMNS": str(columns)}).invoke(gsd_group, list(args), catch_exceptions=True)


def abb880() -> Path:
    return vendor_file("abb_acs880_pb_slave.gsd")


def vendor_file(name: str) -> Path:
    """A named vendor file from ../shared/testdata/gsd: skipped only when that folder is absent
    altogether; a missing file in it is a failure (CI always has ../shared)."""
    if not TESTDATA.is_dir():
        pytest.skip(f"{TESTDATA} not present")
    hits = sorted(TESTDATA.rglob(name))
    if not hits:
        pytest.fail(f"{name} not in {TESTDATA}")
    return hits[0]


def test_show_abb_fpba01_lists_ppo_modules_with_cfg():
    res = run("show", str(abb880()), columns=200)
    assert res.exit_code == 0, res.output
    out = res.output
    assert "0x0959" in out and "ABB Drives FPBA-01 DP-V0" in out
    for name, cfg in [("PPO-01, 4 PKW +", "F3 F1"), ("PPO-05, 4 PKW +", "F3 F9"), ("PPO-08, 0 PKW +", "FB")]:
        row = next(ln for ln in out.splitlines() if name in ln)
        assert cfg in row
    assert "Fail Safe" in out and "Use fail-safe" in out        # user parameters with their texts


def test_show_json_abb_fpba01():
    res = run("show", str(abb880()), "--json")
    assert res.exit_code == 0
    d = json.loads(res.output)
    assert d["identity"]["ident"] == 0x0959
    mods = {m["name"]: m for m in d["modules"]}
    assert mods["PPO-02, 4 PKW + 6 PZD"]["cfg"] == "f3 f5"
    assert mods["PPO-02, 4 PKW + 6 PZD"]["identifiers"][1]["description"] == "6 words in+out, consistent"
    assert {r["baud"]: r["max_tsdr"] for r in d["baud_rates"]}["12M"] == 400
    p = next(p for p in d["user_params"] if p["name"] == "PZD1 Failsafe value")
    assert (p["offset"], p["type"], p["default"], p["allowed"]) == (10, "Unsigned16", 1150, "0-65535")


def test_show_by_ident_and_library_name():
    for src in ("0x00CA", "YASK00CA", "202"):
        res = run("show", src)
        assert res.exit_code == 0, (src, res.output)
        assert "PROFIBUS-DP INTERFACE CARD SI-P1" in res.output
        assert "Extended Data 1" in res.output and "5F 6F" in res.output
        assert "250" in next(ln for ln in res.output.splitlines() if "45.45" in ln)


def test_list_library_and_user_dir(tmp_path):
    res = run("list", "--json")
    assert res.exit_code == 0
    d = json.loads(res.output)
    assert sorted(e["ident_hex"] for e in d) == ["0x00CA", "0x0BE7", "0xFD01", "0xFD02", "0xFD06"]
    (tmp_path / "mine.gsd").write_text('#Profibus_DP\nIdent_Number = 0x00CA\nModel_Name = "mine"\n'
                                       'Vendor_Name = "me"\nProtocol_Ident = 0\nStation_Type = 0\n'
                                       '1.5M_supp = 1\nModule = "M" 0x10\nEndModule\n')
    res = run("list", "--gsd-dir", str(tmp_path), columns=250)
    assert res.exit_code == 0
    assert "mine.gsd" in res.output and "(overridden by mine.gsd)" in res.output
    assert f"user: {tmp_path}" in res.output
    res = run("show", "0x00CA", "--gsd-dir", str(tmp_path), "--json")
    assert json.loads(res.output)["identity"]["model"] == "mine"


def test_prm_table_and_json():
    res = run("prm", str(abb880()), "--module", "PPO3", "--set", "Fail Safe mode=2",
              "--set", "PZD1 Failsafe value=0x0400")
    assert res.exit_code == 0, res.output
    assert "00 00 08 1A 81 00 00 02 00 1E 04 00" in res.output.replace("\n", " ")
    assert "Chk_Cfg (1 octet): F1" in res.output
    res = run("prm", str(abb880()), "-m", "PPO3", "--set", "Fail Safe mode=2", "--json")
    d = json.loads(res.output)
    assert d["user_prm"].startswith("00 00 08 1a 81 00 00 02 00 1e 04 7e")
    assert d["chk_cfg"] == "f1" and d["inputs"] == 4 and d["user_prm_len"] == 30
    row = next(r for r in d["user_prm_fields"] if r["name"] == "Fail Safe mode")
    assert (row["offset"], row["set_prm_octet"], row["bits"], row["value"], row["text"], row["overridden"]) == \
        (7, 14, "bits 0-1", 2, "Use fail-safe values", True)


def test_prm_library_drive_by_ppo_number():
    res = run("prm", "TOYO0BE7", "-m", "PPO5", "--json")
    d = json.loads(res.output)
    assert (d["chk_cfg"], d["user_prm"], d["inputs"], d["outputs"]) == ("f3 f9", "", 28, 28)
    res = run("prm", "0x0BE7", "-m", "Toyo mode PLCH on")
    assert res.exit_code == 0 and "EF DF D6" in res.output and "46 octets in, 32 out" in res.output


@pytest.mark.parametrize("args,match", [
    (("prm", "YASK00CA", "-m", "PPO1"), "no module 'PPO1'"),
    (("prm", "YASK00CA", "-m", "1", "-m", "2"), "at most 1"),
    (("prm", "YASK00CA"), "choose the module"),
    (("prm", "YASK00CA", "-m", "1", "--set", "x"), "expected NAME=VALUE"),
    (("prm", "YASK00CA", "-m", "1", "--set", "speed=3"), "no user parameter 'speed'"),
    (("show", "0x4242"), "no GSD file with ident 0x4242"),
    (("show", "nothing-here"), "no such GSD file"),
    (("list", "--gsd-dir", "/nonexistent/folder"), "no such folder"),
])
def test_bad_input_is_a_usage_error(args, match):
    res = run(*args)
    assert res.exit_code != 0
    assert isinstance(res.exception, UsageError), res.exception
    assert match in str(res.exception)


def test_broken_file_error_names_file_and_line():
    path = HERE / "data" / "gsd_broken" / "unterminated_module.gsd"
    res = run("show", str(path))
    assert isinstance(res.exception, DataFileError)
    assert str(res.exception).startswith(f"{path}:7: ")


def test_prm_explains_constant_and_dpv1_octets():
    hits = [vendor_file("si0380a7.gsd")]
    res = run("prm", str(hits[0]), "-m", "DR-CfgData", "--set", "Diagnose frame for=Segment DP2,DP3", columns=200)
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    assert "80 00 08 08 81 00 00 2E 00 00 03" in res.output
    row0 = next(ln for ln in lines if "DPV1_Status_1 (constant)" in ln)
    assert "0x80" in row0
    row7 = next(ln for ln in lines if "Diagnose frame for" in ln)
    assert "bits 0-7" in row7 and "46 (Segment DP2,DP3) [set]" in row7
    assert "1 byte out" in next(ln for ln in lines if "DR-CfgData" in ln and "20" in ln)


def test_bracketed_gsd_names_are_printed_literally():
    hits = [vendor_file("siemens_et200m_im153.gsd")]
    res = run("prm", str(hits[0]), "-m", "1", "-m", "2", "-m", "3", "-m", "4", columns=200)
    assert res.exit_code == 0, res.output
    row = next(ln for ln in res.output.splitlines() if "[SlotNumber]" in ln)
    assert "4 (slot number)" in row
