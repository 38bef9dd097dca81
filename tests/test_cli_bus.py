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
    got = {s["station"]: s["ident_hex"] for s in data["stations"]}
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
    assert [s["station"] for s in json.loads(r.output)["stations"]] == [3, 4]


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
    lines = [json.loads(x) for x in r.stdout.splitlines()]      # stdout: JSON only
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
    from profidrive_cli.dp.capture import LINKTYPE_USER0, read_pcap
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
    assert lt == LINKTYPE_USER0 and len(pkts) == 4
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


# =============================================================================================
# io ends like a PLC going to STOP (issue 12 finding 1); sim:// never asks
# =============================================================================================

# Moeller PPO1 (Chk_Cfg F3 F1): PKW 8 octets, then STW 047F (operate, bus control) and HSW 0x2000 = 50 %
MOELLER_RUN = "0000 0000 0000 0000 047F 2000"


def _moeller_ready(sim_port):
    """Station 6 in S2 (ready to switch on): a short run leaves it there, so 047F starts it."""
    # F002 = 5 s from 0 to A004 50 Hz (the profile's sim default): 5 Hz after 0.5 s, within the 1 s
    r = run("run", "6", "--hz", "5", "--duration", "1", "--port", sim_port)
    assert r.exit_code == 0, r.output


def test_io_on_sim_needs_no_yes_and_ends_with_the_drive_stopped_not_tripped(sim):
    port = "sim://?stations=6:moeller"
    _moeller_ready(port)
    r = run("io", "6", "--cfg", "F3F1", "--out", MOELLER_RUN, "--count", "200", "--port", port, "--json")
    assert r.exit_code == 0, r.output
    last = bytes.fromhex(json.loads(r.stdout.splitlines()[-1])["inputs"].replace(" ", ""))
    # ZSW 0x0237: operation enabled (bit 2) with bus control; HIW above 0: the motor was turning
    assert last[8] & 0x02 and last[9] & 0x04 and int.from_bytes(last[10:12], "big") > 0
    assert "Global_Control Clear" in r.stderr and "released" in r.stderr
    st = json.loads(run("status", "6", "--port", port, "--json").output)
    assert st["stopped"] and not st["running"] and not st["fault"] and st["actual_hz"] == 0.0, st


def test_io_stopped_by_an_exception_mid_run_still_ends_with_the_drive_stopped(sim, monkeypatch):
    from profidrive_cli.cli import bus_cmds
    port = "sim://?stations=6:moeller"
    _moeller_ready(port)
    seen = []

    def broken_stdout(obj):                      # e.g. `pdrive io ... --json | head`: the pipe closes
        seen.append(obj)
        if len(seen) == 150:
            raise BrokenPipeError("stdout closed")
    monkeypatch.setattr(bus_cmds, "emit_json", broken_stdout)
    r = run("io", "6", "--cfg", "F3F1", "--out", MOELLER_RUN, "--count", "100000", "--port", port, "--json")
    assert isinstance(r.exception, BrokenPipeError) and len(seen) == 150
    last = bytes.fromhex(seen[-1]["inputs"].replace(" ", ""))
    assert int.from_bytes(last[10:12], "big") > 0            # it was turning when the exception came
    st = json.loads(run("status", "6", "--port", port, "--json").output)
    assert st["stopped"] and not st["running"] and not st["fault"] and st["actual_hz"] == 0.0, st


def test_io_text_rows_are_plain_lines(monkeypatch):
    """Per-cycle rows of `io` go out as plain text, not through rich (issue 16: ~60 µs a row):
    one line per cycle, `cycle  in: octets`. Cfg 5F 6F: 16 input words = 32 input octets."""
    import re

    from profidrive_cli.cli import common
    through_rich = []
    real = common.out.print

    def spy(*a, **k):
        through_rich.append(a)
        return real(*a, **k)
    monkeypatch.setattr(common.out, "print", spy)
    r = run("io", "7", "--port", "sim://", "--cfg", "5F 6F", "--count", "3")
    assert r.exit_code == 0, r.output
    rows = [line for line in r.output.splitlines() if " in: " in line]
    assert len(rows) == 3
    for i, line in enumerate(rows):
        assert re.fullmatch(rf" {{4}}{i}  in: [0-9a-f]{{2}}( [0-9a-f]{{2}}){{31}}", line), line
    assert not any(" in: " in str(a) for args in through_rich for a in args)
