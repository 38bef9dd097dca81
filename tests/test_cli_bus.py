"""pdrive scan / diag / io / sniff through click, on the in-process simulated bus."""

import json

import pytest
from click.testing import CliRunner

from profidrive_cli.cli.main import cli

DEFAULT_IDENTS = {3: "0xFD01", 4: "0xFD02", 5: "0x0BE7", 6: "0xFD06", 7: "0x00CA"}


def run(*args, env=None):
    r = CliRunner().invoke(cli, list(args), env=env or {})
    return r


def test_scan_lists_the_default_plant_as_json():
    r = run("scan", "--port", "sim://", "--json")
    assert r.exit_code == 0, r.output
    data = json.loads(r.output)
    got = {s["address"]: s["ident"] for s in data["stations"]}
    assert got == DEFAULT_IDENTS
    assert all(s["state"] == "waiting for parameters" for s in data["stations"])
    assert all(s["device"] for s in data["stations"])        # named from the library


def test_scan_table_names_stations():
    r = run("scan", "--port", "sim://")
    assert r.exit_code == 0, r.output
    for ident in DEFAULT_IDENTS.values():
        assert ident in r.output
    assert "5 station(s)" in r.output


def test_scan_range_and_empty_result():
    r = run("scan", "--port", "sim://", "--from", "10", "--to", "20")
    assert r.exit_code == 1 and "no station answered" in r.output


def test_port_from_environment():
    r = run("scan", "--json", "--to", "4", env={"PDRIVE_PORT": "sim://"})
    assert r.exit_code == 0
    assert [s["address"] for s in json.loads(r.output)["stations"]] == [3, 4]


def test_no_port_says_how():
    r = CliRunner().invoke(cli, ["scan"], env={"PDRIVE_PORT": ""})
    from profidrive_cli import UsageError
    assert isinstance(r.exception, UsageError)                   # exit 2 (tests/test_exit_codes.py)
    assert "sim://" in str(r.exception or r.output)


def test_diag_decodes_bits_and_cfg():
    r = run("diag", "7", "--port", "sim://")
    assert r.exit_code == 0, r.output
    assert "Prm_Req: needs parameters" in r.output
    assert "ident: 0x00CA" in r.output
    assert "Get_Cfg:" in r.output and "16 words" in r.output


def test_diag_json():
    r = run("diag", "7", "--port", "sim://", "--json")
    d = json.loads(r.output)
    assert d["diag"]["flags"] == ["Station_Not_Ready", "Prm_Req"] and d["diag"]["master"] is None


def test_io_wrong_cfg_reports_cfg_fault_in_words():
    r = run("io", "7", "--port", "sim://", "--cfg", "F1")
    from profidrive_cli import BusError
    assert isinstance(r.exception, BusError)                     # exit 1 (tests/test_exit_codes.py)
    assert "configuration fault" in str(r.exception)


def test_io_right_cfg_exchanges_data():
    r = run("io", "7", "--port", "sim://", "--cfg", "5F 6F", "--count", "3", "--json")
    assert r.exit_code == 0, r.output
    lines = [json.loads(x) for x in r.output.splitlines()]
    assert len(lines) == 3 and all(len(bytes.fromhex(x["inputs"].replace(" ", ""))) == 32 for x in lines)


@pytest.mark.parametrize("args,msg", [
    (["diag", "200", "--port", "sim://"], "outside 0..125"),
    (["diag", "9", "--port", "sim://"], "does not answer"),
    (["io", "7", "--port", "sim://", "--cfg", "ZZ"], "--cfg"),
    (["scan", "--port", "sim://", "--baud", "1234"], "not a PROFIBUS-DP baud rate"),
    (["scan", "--port", "sim://?stations=3:nosuch"], "unknown profile"),
    (["scan", "--port", "/dev/does-not-exist"], "no such port"),
])
def test_bad_input_one_line(args, msg):
    r = run(*args)
    from profidrive_cli import PdriveError
    assert isinstance(r.exception, PdriveError), r.exception    # one line, no traceback; codes: test_exit_codes.py
    assert msg in str(r.exception) + r.output


def test_sniff_from_file_and_pcap(tmp_path):
    from profidrive_cli.fdl.capture import LINKTYPE_PROFIBUS_DL, read_pcap
    raw = bytes.fromhex("10 22 02 49 6D 16 10 02 22 00 24 16 55 "
                        "68 05 05 68 8A 82 6D 3C 3E F3 16 E5")
    f = tmp_path / "cap.raw"
    f.write_bytes(raw)
    pcap = tmp_path / "cap.pcap"
    r = run("sniff", "--from-file", str(f), "--pcap", str(pcap))
    assert r.exit_code == 0, r.output
    assert "FDL status" in r.output and "Slave_Diag" in r.output and "garbage" in r.output
    assert "SC" in r.output
    lt, pkts = read_pcap(pcap.read_bytes())
    assert lt == LINKTYPE_PROFIBUS_DL and len(pkts) == 4
    assert pkts[0][1] == bytes.fromhex("10 22 02 49 6D 16")
    r = run("sniff", "--from-file", str(f), "--json")
    services = [json.loads(x).get("service") for x in r.output.splitlines()]
    assert services[:2] == ["FDL status", "FDL status reply"]


def test_diag_names_unit_diagnosis_from_the_gsd():
    # Toyo protection 18 (communication timeout) shows in its device-related diagnosis block,
    # and TOYO0BE7.GSD's Unit_Diag_Bit texts name it
    r = run("diag", "5", "--port", "sim://?trip=5:18", "--json")
    assert r.exit_code == 0, r.output
    d = json.loads(r.output)
    assert "Ext_Diag" in d["diag"]["flags"]
    assert any("timeout" in t.lower() for t in d["unit_diag"])
