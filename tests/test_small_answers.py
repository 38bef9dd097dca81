"""Issue 34, the small wrong answers: each a line a user would act on. Scopes of `param restore`, the
golden file's codes, report file extensions, the learned ET200S's start-up and diagnosis, the rate of
a sim:// bus, a forced --echo, `doctor`'s port list, empty fault-history slots, the Toyo dump.

Expected values come from the manuals (quoted where they decide), the PROFIBUS reference
(../shared/spec/profibus-dp-reference.md) or the real ET200S start-up of pyprofibus issue #26
(../shared/testdata/external/); a fresh simulator per test.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from conftest import SHARED, run_main
from profidrive_cli.datafile import DataFileError
from profidrive_cli.session.fleet import StationSettings, compare, load_golden

EXTERNAL = Path(SHARED) / "testdata" / "external"
ET200S = EXTERNAL / "pyprofibus26-et200s-startup.raw"


def _et200s_url() -> str:
    if not ET200S.exists():
        pytest.skip(f"{ET200S} not present (../shared/testdata/external/)")
    return f"sim://?learn={ET200S}"


@pytest.fixture
def run(capsys, monkeypatch):
    monkeypatch.delenv("PDRIVE_BAUD", raising=False)
    return lambda *args: run_main(capsys, monkeypatch, *args)


# -- param restore: an empty scope is no scope at all ------------------------------------------------

@pytest.mark.parametrize("option, value", [("--only", ""), ("--only", ","), ("--only", "motor,,protection"),
                                           ("--exclude", ""), ("--exclude", " , ")])
def test_restore_with_an_empty_group_name_is_bad_input(run, tmp_path, option, value):
    dump = tmp_path / "d6.yaml"
    assert run("param", "dump", "6", "-o", dump, "--port", "sim://").exit_code == 0
    before = dump.read_bytes()
    # the station holds another F002 than the file: a restore of every group would write it
    r = run("param", "restore", "6", dump, option, value, "--port", "sim://?set=6:F002=20")
    assert r.exit_code == 2, r.output
    assert "empty group name" in r.stderr and option in r.stderr
    assert "Traceback" not in r.output and r.stdout == ""
    assert dump.read_bytes() == before


# -- fleet diff: a golden code the profile does not know ----------------------------------------------

def test_a_golden_code_the_profile_does_not_know_is_bad_input_with_its_line(run, tmp_path):
    d = tmp_path / "line"
    d.mkdir()
    assert run("param", "fleet", "dump", "3,8", "-o", d, "--port",
               "sim://?stations=3:fuji-g1,8:fuji-g1").exit_code == 0
    gold = tmp_path / "golden.yaml"
    gold.write_text("parameters:\n  F07: 6.0\n  F99: 1\n")     # F99: no such code (line 3)
    r = run("param", "fleet", "diff", d, "--golden", gold)
    assert r.exit_code == 2, r.output
    assert f"{gold}:3" in r.stderr and "F99" in r.stderr
    assert "missing" not in r.output


def test_golden_codes_checked_against_the_named_profile_and_the_line(tmp_path):
    g = tmp_path / "g.yaml"
    g.write_text("profile: fuji-g1\nparameters:\n  F07: 6.0\n  F7: 6.0\n")
    with pytest.raises(DataFileError, match=r"g\.yaml:4: F7: .*closest: F07"):
        load_golden(g)
    # a read-only value is kept outside a dump's settings: held to it, every drive would be 'missing'
    g.write_text("profile: fuji-g1\nparameters:\n  M16: 0\n")
    with pytest.raises(DataFileError, match=r"g\.yaml:3: M16 .*read-only"):
        load_golden(g)
    # without profile: the profiles of the line's stations
    g.write_text("parameters:\n  F07: 6.0\n  P999: 1\n")
    with pytest.raises(DataFileError, match=r"g\.yaml:3: P999"):
        compare([StationSettings(3, "fuji-opc-g1-pdp", {"F07": 6.0})], load_golden(g))


# -- report files: the extension says the format ----------------------------------------------------

def test_fleet_html_refuses_another_extension_like_the_other_report_options(run, tmp_path):
    d = tmp_path / "line"
    d.mkdir()
    assert run("param", "fleet", "dump", "3", "-o", d, "--port", "sim://?stations=3:fuji-g1").exit_code == 0
    txt = tmp_path / "x.txt"
    r = run("param", "fleet", "diff", d, "--html", txt)
    assert r.exit_code == 2, r.output
    assert r.stderr.strip() == (f"pdrive: --html {txt}: the file name must end in .html or .htm (the "
                                f"format follows the extension)")
    assert not txt.exists()
    # the same check as checklist run --report and run --plot (one piece of code, one wording)
    from profidrive_cli.checklist.report import report_format
    from profidrive_cli.outfile import OutputPathError
    from profidrive_cli.plot import plot_format
    for check, words in ((report_format, "--report x.txt: the file name must end in .json, .md, .xml or "
                          ".html"), (plot_format, "--plot x.txt: the file name must end in .svg or .png")):
        with pytest.raises(OutputPathError, match=words):
            check("x.txt")
    html = tmp_path / "x.HTML"
    assert run("param", "fleet", "diff", d, "--html", html).exit_code == 0
    assert html.read_text().startswith("<!DOCTYPE html>")


# -- io against the learned ET200S: the Set_Prm, not the Chk_Cfg ---------------------------------------

def test_io_without_the_et200s_user_parameters_names_the_parameter_fault(run):
    url = _et200s_url()
    # no --prm: the Set_Prm carries none of the 29 octets of user parameters the ET200S was given
    # (txt line 12); it acknowledges the Set_Prm, then stays in Wait_Prm with Prm_Fault (st1 bit 6,
    # reference §3.3), where its Chk_Cfg SAP is not enabled (RS): the cause is the parameters
    r = run("io", "5", "--cfg", "00 10 20", "--port", url)
    assert r.exit_code == 1, r.output
    line = r.stderr.strip()
    assert "parameter fault" in line and "Chk_Cfg refused" not in line
    assert "0 octet(s) of user parameters" in line and "--prm" in line


def test_io_help_says_module_can_be_repeated(run):
    r = run("io", "--help")
    assert r.exit_code == 0
    assert "repeat it for each slot" in " ".join(r.stdout.split())


# -- diag decodes the extended diagnosis as sniff does ----------------------------------------------

def test_diag_decodes_the_dpv1_status_block_like_sniff(run):
    url = _et200s_url()
    # the device-related block 14 82 00 .. (txt line 8): header 0x14 = 20 octets, then 0x82: a DP-V1
    # status block (bit 7), Status_Type 2 = Module_Status; slot 0, specifier 0, all modules 00
    # (data valid). sniff's decoder (dp/du_decode.decode_du) gives the same words for these octets.
    from profidrive_cli.dp.du_decode import decode_du
    reply = bytes.fromhex("02 05 00 ff 80 6a 49" + " 00" * 8 + " 14 82" + " 00" * 18)
    sniff_text = decode_du("Slave_Diag reply", reply)["blocks"][1]["text"]
    assert "DP-V1 status block: Module_Status" in sniff_text
    r = run("diag", "5", "--port", url)
    assert r.exit_code == 0, r.output
    assert " ".join(f"ext: {sniff_text}".split()) in " ".join(r.stdout.split())
    assert "ext: device-related: 82 00" not in r.stdout
    r = run("diag", "5", "--json", "--port", url)
    d = json.loads(r.stdout)["diag"]
    assert d["ext_blocks"][1] == sniff_text
    assert d["ext_decoded"][1]["dpv1"]["type_name"] == "Module_Status"


# -- the rate of a simulated bus pdrive built itself -------------------------------------------------

def test_status_on_a_sim_bus_with_baud_uses_its_rate(run):
    r = run("status", "3", "--json", "--port", "sim://?baud=1500000&timing=virtual")
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["station"] == 3


def test_another_named_rate_says_the_rates_differ(run, monkeypatch):
    r = run("status", "3", "--baud", "19200", "--port", "sim://?baud=1500000&timing=virtual")
    assert r.exit_code == 1, r.output
    assert "runs at 1.5M" in r.stderr and "19.2k (option --baud)" in r.stderr
    assert "does not answer" not in r.stderr
    monkeypatch.setenv("PDRIVE_BAUD", "187500")
    r = run("scan", "--port", "sim://?baud=1500000")
    assert r.exit_code == 1 and "187.5k (env PDRIVE_BAUD)" in r.stderr


# -- a forced --echo on a port without echo --------------------------------------------------------

def test_forced_echo_without_echo_says_so_not_baud_auto(run):
    # sim:// has no echo (link/serial_link.py): every forced echo wait comes back empty
    r = run("scan", "--echo", "--port", "sim://?stations=3:fuji-g1")
    assert r.exit_code == 1
    assert "--echo was forced but the port does not echo" in r.output
    assert "--baud auto" not in r.output
    r = run("diag", "3", "--echo", "--port", "sim://?stations=3:fuji-g1")
    assert r.exit_code == 1 and "--no-echo" in r.stderr


# -- doctor without --port: a table with its headers -------------------------------------------------

def test_doctor_lists_the_ports_under_headers(run, monkeypatch):
    import serial.tools.list_ports

    class Port:
        device, description, hwid = "/dev/ttyUSB0", "FT232R USB UART", "USB VID:PID=0403:6001"
    monkeypatch.setattr(serial.tools.list_ports, "comports", lambda: [Port()])
    r = run("doctor")
    assert r.exit_code == 0, r.output
    head = next(ln for ln in r.stdout.splitlines() if "port" in ln and "description" in ln)
    assert "hardware id" in head
    assert "/dev/ttyUSB0" in r.stdout and "FT232R USB UART" in r.stdout


# -- faults: empty history slots are no rows --------------------------------------------------------

@pytest.mark.parametrize("address", [3, 6])
def test_faults_of_a_fresh_drive_list_no_empty_slots(run, address):
    # Fuji: PNU947 "0000" / M16-M19 "0" is "no alarm" (OPC-G1-PDP manual Table 10.1, seed 001 L2797);
    # Moeller: PNU 947 "0 No fault" (DE6-NET-DP manual Table 8, seed 003 L735): a slot holding no alarm
    r = run("faults", str(address), "--json", "--port", "sim://")
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["history"] == []
    r = run("faults", str(address), "--port", "sim://")
    assert "fault history: empty" in r.stdout and "no alarm" not in r.stdout and "no fault │" not in r.stdout


def test_faults_keep_the_slot_positions(run):
    # one alarm, in the newest slot: its position stays "latest" (the slot it was read from)
    r = run("faults", "3", "--json", "--port", "sim://?stations=3:fuji-g1&trip=3:OC1")
    hist = json.loads(r.stdout)["history"]
    assert [(h["position"], h["codes"]) for h in hist] == [("latest", ["OC1"])]


# -- the Toyo dump says why it holds no settings ----------------------------------------------------

def test_toyo_dump_says_why_it_has_no_settings(run, tmp_path):
    # PBUS66-Z manual note 1 (seed 002 L4201): "ＶＦ６６インバータの設定データ番号については別途お問い合わせください"
    # (ask Toyo for the VF66 setting-data numbers): no setting has an address, the dump holds none
    from profidrive_cli.drives.profile import load_profile
    prof = load_profile("toyo")
    settings = [c for c, p in prof.parameters.items() if p.writable and p.access != "wo"]
    assert settings and all(prof.param(c).pnu is None for c in settings)
    f = tmp_path / "d5.yaml"
    r = run("param", "dump", "5", "-o", f, "--port", "sim://")
    assert r.exit_code == 0, r.output
    assert "no VF66 setting-data numbers" in " ".join(r.stderr.split())
    text = f.read_text()
    header = [ln for ln in text.splitlines() if ln.startswith("#")]
    assert any(f"{len(settings)} setting(s) of the profile are not in this dump" in ln
               and "ask Toyo" in ln for ln in header)
    import yaml
    doc = yaml.safe_load(text)
    assert doc["count"] == 0 and doc["not_dumped"]["codes"] == settings
    r = run("param", "dump", "5", "-o", f, "--json", "--port", "sim://")
    d = json.loads(r.stdout)
    assert d["settings"] == 0 and d["not_dumped"]["count"] == len(settings)
    assert "ask Toyo" in d["not_dumped"]["why"]
    # a drive whose every setting has an address says nothing of the kind
    r = run("param", "dump", "3", "-o", tmp_path / "d3.yaml", "--json", "--port", "sim://")
    assert "not_dumped" not in json.loads(r.stdout)
