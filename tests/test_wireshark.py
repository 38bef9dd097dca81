"""Wireshark (issue 18): pcap files Wireshark opens (DLT_USER0, wall-clock times), the shipped Lua
dissector read by tshark, `pdrive wireshark install` (dissector, station table from the profiles,
extcap launcher) and the extcap protocol and capture.

tshark tests skip when tshark is absent locally and FAIL when CI=true (.ci/run installs it).
Expected values come from the telegrams the tests send (hand-built octets with hand-computed FCS),
the reference (SAPs, Set_Prm / Slave_Diag bit positions) and the manuals (PPO word positions, N2
scaling: 0x4000 = 100 % of the max frequency).
"""

from __future__ import annotations

import json
import os
import select
import shutil
import signal
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from conftest import pdrive_cmd, pty_sim_process
from profidrive_cli.cli.main import cli
from profidrive_cli.dp.capture import read_pcap

ROOT = Path(__file__).resolve().parent.parent
LUA = ROOT / "wireshark" / "pdrive.lua"


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture
def pd(capsys):
    """pdrive's own entry point in this process: (exit code, stdout + stderr)."""
    from profidrive_cli.cli.main import main

    def call(*args):
        capsys.readouterr()
        with pytest.raises(SystemExit) as e:
            main([str(a) for a in args])
        got = capsys.readouterr()
        return e.value.code, got.out + got.err
    return call


@pytest.fixture
def tshark():
    exe = shutil.which("tshark")
    if exe is None:
        if os.environ.get("CI") == "true":
            pytest.fail("tshark is missing on CI (.ci/run installs it)")
        pytest.skip("tshark not installed")
    return exe


def _tshark(exe, pcap, *extra, lua=LUA):
    p = subprocess.run([exe, "-n", "-X", f"lua_script:{lua}", "-r", str(pcap), *extra],
                       capture_output=True, text=True, timeout=120,
                       env={**os.environ, "HOME": str(Path(pcap).parent)})
    assert p.returncode == 0, p.stderr
    assert "Lua Error" not in p.stdout + p.stderr, p.stdout + p.stderr
    return p.stdout


def _fields(exe, pcap, names, *extra, lua=LUA):
    """One row per frame: the values of `names` (tshark -T fields, '|' between a field's values)."""
    args = ["-T", "fields", "-E", "separator=\t", "-E", "aggregator=|", "-E", "occurrence=a"]
    for n in names:
        args += ["-e", n]
    out = _tshark(exe, pcap, *args, *extra, lua=lua)
    return [dict(zip(names, line.split("\t"))) for line in out.splitlines()]


def _pcap(path, frames, start=1_700_000_000.0, linktype=147):
    """A pcap file of hand-built telegrams, one per 10 ms."""
    data = struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 65535, linktype)
    for i, raw in enumerate(frames):
        t = start + i * 0.01
        data += struct.pack("<IIII", int(t), round((t - int(t)) * 1e6), len(raw), len(raw)) + raw
    Path(path).write_bytes(data)
    return path


def h(text: str) -> bytes:
    return bytes.fromhex(text)


# Hand-built telegrams (reference §2/§3), FCS = sum of DA..DU mod 256 computed by hand:
# Set_Prm 2 -> 6: DA 0x86 SA 0x82 FC 0x7D (SRD high, FCB FCV) DSAP 61 SSAP 62,
#   station status 0x88 (Lock_Req + WD_On), WD_Fact 10 x 5 (= 500 ms), min TSDR 11, ident 0xFD06, group 0
#   sum 86+82+7D+3D+3E+88+0A+05+0B+FD+06+00 = 0x3A5 -> FCS 0xA5
SET_PRM = h("68 0C 0C 68 86 82 7D 3D 3E 88 0A 05 0B FD 06 00 A5 16")
# Slave_Diag reply 6 -> 2 (SD3: 8 octets DU incl. SAPs): DSAP 62 SSAP 60,
#   st1 0x02 Station_Not_Ready, st2 0x05 Prm_Req + always-1, st3 0, master 0xFF, ident 0xFD06
#   sum 82+86+08+3E+3C+02+05+00+FF+FD+06 = 0x393 -> FCS 0x93
SLAVE_DIAG = h("A2 82 86 08 3E 3C 02 05 00 FF FD 06 93 16")
# Chk_Cfg 2 -> 6: DSAP 62 SSAP 62, identifiers F3 F1 (PPO1: PKW 4 words, PZD 2 words, each consistent)
#   sum 86+82+5D+3E+3E+F3+F1 = 0x3C5 -> FCS 0xC5
CHK_CFG = h("68 07 07 68 86 82 5D 3E 3E F3 F1 C5 16")
# Data_Exchange 2 -> 6, PPO1 outputs: PKW 0, STW 0x047F, HSW 0x2000 (50 %)
#   sum 06+02+7D+04+7F+20 = 0x128 -> FCS 0x28
DX_REQ = h("68 0F 0F 68 06 02 7D 00 00 00 00 00 00 00 00 04 7F 20 00 28 16")
# its reply 6 -> 2 (FC 0x08 DL): ZSW 0x0237 (S4 operation), HIW 0x1000 (25 %)
#   sum 02+06+08+02+37+10 = 0x59
DX_RES = h("68 0F 0F 68 02 06 08 00 00 00 00 00 00 00 00 02 37 10 00 59 16")
# Global_Control 2 -> 127: Clear_Data, all groups; DSAP 58 SSAP 62, SDN high FC 0x46
#   sum FF+82+46+3A+3E+02+00 = 0x241 -> FCS 0x41
GC = h("68 07 07 68 FF 82 46 3A 3E 02 00 41 16")
# FDL status request 2 -> 6 (SD1) and a token 2 -> 2, a short acknowledge
FDL_STATUS = h("10 06 02 49 51 16")
TOKEN = h("DC 02 02")
SC = h("E5")
# the same Data_Exchange with a wrong FCS
DX_BAD_FCS = DX_REQ[:-2] + b"\x29\x16"


# -- pcap files pdrive writes ------------------------------------------------------------------

def test_sniff_pcap_is_dlt_user0_with_wall_clock_times(tmp_path):
    """Wireshark 4.0 refuses link type 257; pdrive writes 147 (DLT_USER0) by default and times from
    the capture (here: the raw file's time), not from 1970."""
    raw = tmp_path / "c.raw"
    raw.write_bytes(FDL_STATUS + SC)
    os.utime(raw, (1_700_000_000, 1_700_000_000))
    pcap = tmp_path / "c.pcap"
    r = run("sniff", "--from-file", raw, "--pcap", pcap)
    assert r.exit_code == 0, r.output
    lt, pkts = read_pcap(pcap.read_bytes())
    assert lt == 147
    assert [p for _, p in pkts] == [FDL_STATUS, SC]
    assert all(abs(t - 1_700_000_000) < 1 for t, _ in pkts)


def test_sniff_linktype_257_stays_available(tmp_path):
    raw = tmp_path / "c.raw"
    raw.write_bytes(FDL_STATUS)
    pcap = tmp_path / "c.pcap"
    r = run("sniff", "--from-file", raw, "--pcap", pcap, "--linktype", "257")
    assert r.exit_code == 0, r.output
    assert read_pcap(pcap.read_bytes())[0] == 257
    r = run("sniff", "--from-file", raw, "--pcap", pcap, "--linktype", "1")
    assert r.exit_code == 2


# -- the dissector, on hand-built telegrams -----------------------------------------------------

def test_tshark_names_every_service_like_pdrive(tshark, tmp_path):
    pcap = _pcap(tmp_path / "a.pcap", [SET_PRM, SLAVE_DIAG, CHK_CFG, DX_REQ, DX_RES, GC, FDL_STATUS,
                                       TOKEN, SC])
    rows = _fields(tshark, pcap, ["profibus.service", "profibus.sa", "profibus.da", "profibus.fcs.status"])
    assert [r["profibus.service"] for r in rows] == [
        "Set_Prm", "Slave_Diag reply", "Chk_Cfg", "Data_Exchange", "Data_Exchange reply",
        "Global_Control", "FDL status", "token", "short acknowledge"]
    assert [(r["profibus.sa"], r["profibus.da"]) for r in rows[:4]] == [("2", "6"), ("6", "2"), ("2", "6"),
                                                                       ("2", "6")]
    assert all(r["profibus.fcs.status"] == "good" for r in rows[:7])
    # the same names as pdrive sniff prints for these telegrams
    raw = tmp_path / "a.raw"
    raw.write_bytes(SET_PRM + SLAVE_DIAG + CHK_CFG + DX_REQ + DX_RES + GC + FDL_STATUS + TOKEN + SC)
    r = run("sniff", "--from-file", raw, "--json")
    assert [json.loads(x)["service"] for x in r.output.splitlines()] == \
        [r["profibus.service"] for r in rows]


def test_tshark_decodes_set_prm_chk_cfg_and_slave_diag(tshark, tmp_path):
    pcap = _pcap(tmp_path / "a.pcap", [SET_PRM, SLAVE_DIAG, CHK_CFG])
    rows = _fields(tshark, pcap, ["profibus.prm.watchdog_ms", "profibus.prm.wd_on", "profibus.prm.lock_req",
                                  "profibus.prm.min_tsdr", "profibus.prm.ident", "profibus.diag.flags",
                                  "profibus.diag.prm_req", "profibus.diag.station_not_ready",
                                  "profibus.diag.cfg_fault", "profibus.diag.master", "profibus.cfg.text"])
    prm, diag, cfg = rows
    assert prm["profibus.prm.watchdog_ms"] == "500"          # 10 x 5 x 10 ms
    assert prm["profibus.prm.wd_on"] == "1" and prm["profibus.prm.lock_req"] == "1"
    assert prm["profibus.prm.min_tsdr"] == "11"
    assert prm["profibus.prm.ident"] == "0xfd06"
    assert diag["profibus.diag.flags"] == "Station_Not_Ready, Prm_Req"
    assert diag["profibus.diag.prm_req"] == "1" and diag["profibus.diag.station_not_ready"] == "1"
    assert diag["profibus.diag.cfg_fault"] == "0"
    assert diag["profibus.diag.master"] == "255"
    # F3 = 1111 0011: consistent, words, in+out, 3+1 words; F1 = 1111 0001: the same with 1+1 words
    assert cfg["profibus.cfg.text"] == "4 words in+out, consistent|2 words in+out, consistent"


def test_tshark_decodes_global_control_set_slave_add_and_extended_diagnosis(tshark, tmp_path):
    # Set_Slave_Add 2 -> 126: DSAP 55, new address 5, ident 0xFD06, No_Add_Chg 0
    #   sum FE+82+5D+37+3E+05+FD+06+00 = 0x35A -> FCS 0x5A
    ssa = h("68 09 09 68 FE 82 5D 37 3E 05 FD 06 00 5A 16")
    # Slave_Diag reply with st1 Ext_Diag, an identifier-related block (0x42: type 1, 2 octets; module
    # 0 set) and a channel-related one (0x80 module 0, 0x41 input channel 1, 0xA5 word, error 5)
    #   sum 82+86+08+3E+3C+08+0C+00+02+FD+06+42+01+80+41+A5 = 0x44C -> FCS 0x4C
    diag = h("68 10 10 68 82 86 08 3E 3C 08 0C 00 02 FD 06 42 01 80 41 A5 4C 16")
    # Rd_Inp reply 6 -> 2: DSAP 62 SSAP 56, the station's PPO1 inputs (ZSW 0x0237, HIW 0x1000)
    #   sum 82+86+08+3E+38+02+37+10 = 0x1CF -> FCS 0xCF
    rd_inp = h("68 11 11 68 82 86 08 3E 38 00 00 00 00 00 00 00 00 02 37 10 00 CF 16")
    pcap = _pcap(tmp_path / "a.pcap", [GC, ssa, diag, rd_inp])
    rows = _fields(tshark, pcap, ["profibus.service", "profibus.gc.text", "profibus.gc.group",
                                  "profibus.ssa.new_address", "profibus.ssa.ident", "profibus.diag.flags",
                                  "profibus.diag.block", "profidrive.state"])
    gc, ssa_row, diag_row, rd = rows
    assert rd["profibus.service"] == "Rd_Inp reply" and rd["profidrive.state"] == "S4 operation"
    assert gc["profibus.gc.text"] == "Clear_Data" and gc["profibus.gc.group"] == "0x00"
    assert ssa_row["profibus.service"] == "Set_Slave_Add"
    assert ssa_row["profibus.ssa.new_address"] == "5" and ssa_row["profibus.ssa.ident"] == "0xfd06"
    assert diag_row["profibus.diag.flags"] == "Ext_Diag, WD_On"
    assert diag_row["profibus.diag.block"] == ("identifier-related: modules with diagnosis: 0|"
                                               "channel-related: module 0, channel 1 input, word: overtemperature")


EXTERNAL = ROOT.parent / "shared" / "testdata" / "external"


def test_tshark_names_the_dpv1_octets_and_every_block_like_sniff(tshark, tmp_path):
    """Issue 26: the dissector names the DP-V1 Set_Prm status octets and every extended-diagnosis
    block kind with the same words as `pdrive sniff` (the real ET200S start-up of pyprofibus #26 from
    ../shared, and hand-built blocks: alarm, Module_Status with bad modules, vendor data, channel)."""
    from profidrive_cli.fdl import frames as F
    diag = bytes.fromhex("08 0c 00 02 12 34 44 00 01 00 88 41 21 04 10 20 30 06 04 05 0d aa bb"
                         " 06 82 00 01 e4 00")
    # Set_Prm with WD_Base_1ms (DPV1_Status_1 bit 2, reference line 209/238): 30 x 1 x 1 ms
    prm = bytes.fromhex("88 1e 01 0b 12 34 00 84 00 00")
    raw = (F.encode(F.make(2, 5, F.response_fc(0x08), diag, 62, 60))
           + F.encode(F.make(5, 2, F.request_fc(F.SRD_HIGH, fcv=True), prm, 61, 62)))
    real = EXTERNAL / "pyprofibus26-et200s-startup.raw"
    if real.exists():
        raw += real.read_bytes()
    f = tmp_path / "a.raw"
    f.write_bytes(raw)
    pcap = tmp_path / "a.pcap"
    assert run("sniff", "--from-file", f, "--pcap", pcap).exit_code == 0
    sniffed = [json.loads(x) for x in run("sniff", "--from-file", f, "--json").output.splitlines()]
    rows = _fields(tshark, pcap, ["profibus.service", "profibus.prm.dpv1_flags", "profibus.prm.alarm_mode",
                                  "profibus.prm.watchdog_ms", "profibus.diag.block"])
    assert len(rows) == len(sniffed) == (17 if real.exists() else 2)
    for r, d in zip(rows, sniffed):
        dec = d.get("decoded") or {}
        assert r["profibus.diag.block"] == "|".join(b["text"] for b in dec.get("blocks", [])), r
        v1 = dec.get("dpv1_status")
        assert r["profibus.prm.dpv1_flags"] == (", ".join(v1["flags"]) if v1 else ""), r
        if v1:
            assert r["profibus.prm.alarm_mode"] == f"{v1['alarm_mode']} ({v1['alarm_mode_text']})"
            assert r["profibus.prm.watchdog_ms"] == str(dec["watchdog_ms"])
    assert rows[1]["profibus.prm.watchdog_ms"] == "30"
    assert "Plug_Alarm (0x04), slot 5" in rows[0]["profibus.diag.block"]
    assert "module 3: data invalid (no module)" in rows[0]["profibus.diag.block"]
    if real.exists():
        (p,) = [r for r in rows[2:] if r["profibus.service"] == "Set_Prm"]
        assert p["profibus.prm.dpv1_flags"] == "Fail_Safe, Chk_Cfg_Mode"        # 40 01 00


def test_tshark_flags_a_bad_fcs(tshark, tmp_path):
    pcap = _pcap(tmp_path / "a.pcap", [DX_BAD_FCS])
    rows = _fields(tshark, pcap, ["profibus.fcs.status", "profibus.fcs", "_ws.expert.message"])
    assert rows[0]["profibus.fcs.status"] == "bad"
    assert "the octets sum to 0x28" in rows[0]["_ws.expert.message"]


def test_tshark_decodes_ppo_by_length_without_a_station_table(tshark, tmp_path):
    pcap = _pcap(tmp_path / "a.pcap", [DX_REQ, DX_RES])
    rows = _fields(tshark, pcap, ["profidrive.control.set", "profidrive.reference_percent",
                                  "profidrive.state", "profidrive.actual_percent", "profidrive.pkw.ak"])
    req, res = rows
    # 0x047F: bits 0-6 and 10 (PROFIdrive control word)
    assert req["profidrive.control.set"] == ("ON, no OFF2, no OFF3, enable operation, enable ramp generator, "
                                             "unfreeze ramp generator, enable setpoint, control by PLC")
    assert float(req["profidrive.reference_percent"]) == 50.0       # 0x2000 / 0x4000
    assert res["profidrive.state"] == "S4 operation"                # 0x0237: bits 0, 1, 2 set
    assert float(res["profidrive.actual_percent"]) == 25.0          # 0x1000 / 0x4000
    assert req["profidrive.pkw.ak"] == "0"


# -- pdrive wireshark install: dissector + station table ----------------------------------------

def test_install_writes_the_dissector_and_a_station_table(tmp_path):
    r = run("wireshark", "install", "--dir", tmp_path, "--station", "3=fuji-g1", "--station",
            "6=moeller:ppo1", "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.output)
    assert doc["stations"] == [{"station": 3, "profile": "fuji-opc-g1-pdp", "layout": "ppo1"},
                               {"station": 6, "profile": "moeller-de6-net-dp", "layout": "ppo1"}]
    assert doc["extcap"] == []              # with --dir only when --extcap-dir is given
    assert sorted(os.listdir(tmp_path)) == ["pdrive.lua", "pdrive_stations.lua"]
    assert (tmp_path / "pdrive.lua").read_text() == LUA.read_text()
    table = (tmp_path / "pdrive_stations.lua").read_text()
    assert '[3] = "fuji-opc-g1-pdp:ppo1"' in table and '[6] = "moeller-de6-net-dp:ppo1"' in table


@pytest.mark.parametrize("spec, msg", [
    ("3", "expected ADDRESS=PROFILE[:LAYOUT]"),
    ("x=fuji-g1", "is not a station address"),
    ("200=fuji-g1", "outside 0..126"),
    ("3=nosuch", "unknown profile 'nosuch'"),
    ("3=fuji-g1:ppo5", "has no layout 'ppo5'"),
])
def test_install_refuses_a_bad_station_and_writes_nothing(pd, tmp_path, spec, msg):
    code, out = pd("wireshark", "install", "--dir", tmp_path, "--station", spec)
    assert code == 2
    assert msg in out and "Traceback" not in out and len(out.strip().splitlines()) == 1
    assert os.listdir(tmp_path) == []


def test_install_into_a_missing_dir_is_refused(pd, tmp_path):
    code, out = pd("wireshark", "install", "--dir", tmp_path / "nope")
    assert code == 2 and "does not exist" in out


def _home(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.delenv("XDG_CONFIG_HOME", raising=False)
    monkeypatch.setattr(Path, "home", classmethod(lambda cls: tmp_path))


def test_install_default_is_the_personal_plugins_and_extcap_folders(tmp_path, monkeypatch):
    """Plugins: ~/.local/lib/wireshark/plugins; extcap: ~/.local/lib/wireshark/extcap (Wireshark 4.2+)
    and ~/.config/wireshark/extcap (Wireshark up to 4.0, e.g. Debian 12's)."""
    _home(tmp_path, monkeypatch)
    r = run("wireshark", "install")
    assert r.exit_code == 0, r.output
    plugins = tmp_path / ".local/lib/wireshark/plugins"
    assert (plugins / "pdrive.lua").is_file() and (plugins / "pdrive_stations.lua").is_file()
    assert str(plugins / "pdrive.lua") in r.output
    for extcap in (tmp_path / ".local/lib/wireshark/extcap/pdrive-extcap",
                   tmp_path / ".config/wireshark/extcap/pdrive-extcap"):
        assert extcap.is_file() and os.access(extcap, os.X_OK)
        assert str(extcap) in r.output
        p = subprocess.run([str(extcap), "--extcap-interfaces"], capture_output=True, text=True,
                           timeout=60, cwd="/")
        assert p.returncode == 0, p.stderr
        assert "interface {value=pdrive}" in p.stdout


@pytest.mark.skipif(not shutil.which("socat"), reason="socat not installed")
def test_tshark_captures_live_through_the_installed_extcap(tshark, tmp_path, monkeypatch, socat_pair):
    """The real thing: tshark finds the interface 'pdrive' in the personal folders pdrive wrote, runs
    the launcher with the port as its option, and decodes what arrives on the line with the plugin."""
    _home(tmp_path, monkeypatch)
    r = run("wireshark", "install", "--station", "6=moeller")
    assert r.exit_code == 0, r.output
    a, b = socat_pair
    env = {**os.environ, "HOME": str(tmp_path)}
    env.pop("XDG_CONFIG_HOME", None)
    p = subprocess.run([tshark, "-D"], capture_output=True, text=True, timeout=120, env=env)
    assert "pdrive (PROFIBUS (pdrive sniff, listen only))" in p.stdout, p.stdout + p.stderr
    cap = subprocess.Popen([tshark, "-n", "-i", "pdrive", "-o", f"extcap.pdrive.port:{a}", "-a", "duration:6",
                            "-T", "fields", "-e", "profibus.service", "-e", "profidrive.reference_hz"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        # the line repeats its three telegrams until tshark ends (it may start listening late)
        fd = os.open(b, os.O_WRONLY | os.O_NOCTTY)
        while cap.poll() is None:
            os.write(fd, FDL_STATUS + DX_REQ + SC)
            time.sleep(0.5)
        os.close(fd)
        out, err = cap.communicate(timeout=60)
    finally:
        if cap.poll() is None:
            cap.kill()
    rows = [tuple(ln.split("\t")) for ln in out.splitlines()]
    expected = {("FDL status", ""), ("Data_Exchange", "25"), ("short acknowledge", "")}
    assert rows and set(rows) <= expected, out + err
    assert ("Data_Exchange", "25") in rows, out + err      # HSW 0x2000 of A004 = 50 Hz


def test_windows_personal_folders_are_under_appdata():
    from profidrive_cli.bustools.wireshark import personal_dirs
    plugins, extcap = personal_dirs("win32", {"APPDATA": r"C:\Users\u\AppData\Roaming"})
    assert str(plugins).endswith("Wireshark/plugins") or str(plugins).endswith(r"Wireshark\plugins")
    assert [(e.name, e.parent.name) for e in extcap] == [("extcap", "Wireshark")]


def test_extcap_launchers_run_pdrive_with_this_python():
    from profidrive_cli.bustools.wireshark import launcher_text
    name, text = launcher_text("win32", r"C:\Python\python.exe")
    assert name == "pdrive-extcap.bat"
    assert '"C:\\Python\\python.exe" -m profidrive_cli wireshark extcap %*' in text
    name, text = launcher_text("linux", "/opt/py/bin/python3")
    assert name == "pdrive-extcap" and text.startswith("#!/bin/sh\n")
    assert 'exec /opt/py/bin/python3 -m profidrive_cli wireshark extcap "$@"' in text


def test_station_fields_follow_the_manuals_ppo_and_vendor_layouts():
    """PPO1 (PROFIdrive): PKW octets 0-7, PZD1 at 8 (Moeller STW / ZSW), PZD2 at 10 (HSW / HIW, N2 of
    A004 = 50 Hz by default); Yaskawa extended1 (spec §2): parameter access in octets 16-31."""
    from profidrive_cli.drives.profile import load_profile
    from profidrive_cli.drives.wirefields import area_fields
    req = area_fields(load_profile("moeller"), "ppo1", "request")
    assert req["length"] == 12
    assert [(f["name"], f["offset"], f["size"], f["kind"]) for f in req["fields"]] == [
        ("PKW", 0, 8, "pkw"), ("STW", 8, 2, "bits"), ("HSW", 10, 2, "n2")]
    assert req["fields"][2]["max_hz"] == 50.0
    assert req["fields"][1]["bits"][8] == "inching 1"        # moeller-de6-net-dp.md L279
    res = area_fields(load_profile("yaskawa"), "extended1", "response")
    pa = [f for f in res["fields"] if f["name"] == "parameter access"][0]
    assert (pa["offset"], pa["size"]) == (16, 16)
    fb = [f for f in res["fields"] if f["name"] == "speed_feedback"][0]
    assert (fb["offset"], fb["scale"], fb["unit"]) == (2, 0.1, "Hz")   # feedback 0.1 Hz per count


def test_tshark_decodes_a_station_with_its_vendor_layout(tshark, tmp_path):
    """Station 6 = Moeller: its own word names (STW/HSW, ZSW/HIW), its bit names (bit 8 'inching 1'
    where the generic PROFIdrive word says 'jog 1') and Hz from A004 = 50 Hz."""
    r = run("wireshark", "install", "--dir", tmp_path, "--station", "6=moeller:ppo1")
    assert r.exit_code == 0, r.output
    pcap = _pcap(tmp_path / "a.pcap", [DX_REQ, DX_RES])
    text = _tshark(tshark, pcap, "-V", lua=tmp_path / "pdrive.lua")
    assert "PROFIdrive moeller-de6-net-dp ppo1, station 6" in text
    assert "bit  8 inching 1: 0" in text
    assert "HSW (reference) 0x2000: 50 % = 25.00 Hz" in text
    assert "HIW (actual value) 0x1000: 25 % = 12.50 Hz" in text
    rows = _fields(tshark, pcap, ["profidrive.reference_hz", "profidrive.actual_hz"],
                   lua=tmp_path / "pdrive.lua")
    assert float(rows[0]["profidrive.reference_hz"]) == 25.0
    assert float(rows[1]["profidrive.actual_hz"]) == 12.5


def test_tshark_names_the_parameter_of_a_pkw_request_by_its_native_code(tshark, tmp_path):
    """Station 3 = Fuji OPC-G1-PDP: a PKW read of F03 (the profile's PNU/subindex for F03) shows as F03
    in the request and in the answer (PWE 6000 raw)."""
    from profidrive_cli.drives.profile import load_profile
    f03 = load_profile("fuji-g1").param("F03")
    r = run("wireshark", "install", "--dir", tmp_path, "--station", "3=fuji-g1")
    assert r.exit_code == 0, r.output
    pke, ind = 0x1000 | f03.pnu, f03.index << 8                # AK 1 request parameter value
    body = bytes([3, 2, 0x7D]) + struct.pack(">HHHH", pke, ind, 0, 0) + h("04 7F 20 00")
    req = bytes([0x68, len(body), len(body), 0x68]) + body + bytes([sum(body) & 0xFF, 0x16])
    body = bytes([2, 3, 0x08]) + struct.pack(">HHHH", pke, ind, 0, 6000) + h("02 37 20 00")
    res = bytes([0x68, len(body), len(body), 0x68]) + body + bytes([sum(body) & 0xFF, 0x16])
    rows = _fields(tshark, _pcap(tmp_path / "a.pcap", [req, res]),
                   ["profidrive.pkw.param", "profidrive.pkw.ak_text", "profidrive.pkw.pwe"],
                   lua=tmp_path / "pdrive.lua")
    assert [r["profidrive.pkw.param"].split(" ", 1)[0] for r in rows] == ["F03", "F03"]
    assert rows[0]["profidrive.pkw.ak_text"] == "request parameter value"
    assert rows[1]["profidrive.pkw.ak_text"] == "transfer parameter value (word)"
    assert int(rows[1]["profidrive.pkw.pwe"], 0) == 6000


def test_tshark_station_preference_picks_a_vendor_layout(tshark, tmp_path):
    """The preference profidrive.stations (here 7=yaskawa:basic) with the generated table: the SI-P1
    basic layout, run command bit 0 forward run, reference in 0.01 Hz (spec §2.2, §2.7)."""
    r = run("wireshark", "install", "--dir", tmp_path)
    assert r.exit_code == 0, r.output
    # Data_Exchange 2 -> 7, 6 octets: command 0x0001, reference 3000 (0x0BB8), torque 0
    # sum 07+02+7D+00+01+0B+B8 = 0x14A -> FCS 0x4A
    dx = h("68 09 09 68 07 02 7D 00 01 0B B8 00 00 4A 16")
    pcap = _pcap(tmp_path / "a.pcap", [dx])
    rows = _fields(tshark, pcap, ["profidrive.layout", "profidrive.control.set", "profidrive.reference_hz"],
                   "-o", "profidrive.stations:7=yaskawa:basic", lua=tmp_path / "pdrive.lua")
    assert rows[0]["profidrive.layout"] == "yaskawa-si-p1 basic"
    assert rows[0]["profidrive.control.set"] == "forward run"
    assert float(rows[0]["profidrive.reference_hz"]) == 30.0


# -- end to end: a master talking to `pdrive sim --pty`, heard on an RS-485 tap --------------------

def _pty_pair(tmp_path, name):
    a, b = str(tmp_path / f"{name}A"), str(tmp_path / f"{name}B")
    p = subprocess.Popen(["socat", f"pty,raw,echo=0,ignoreeof,link={a}", f"pty,raw,echo=0,ignoreeof,link={b}"],
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    for _ in range(500):
        if os.path.exists(a) and os.path.exists(b):
            return p, a, b
        time.sleep(0.01)
    p.kill()
    pytest.fail("socat did not create its ptys")


class Tap(threading.Thread):
    """The bus between a master's pty and the simulator's pty, with every octet either way also
    copied to listener ptys (what an RS-485 receiver on the same pair hears)."""

    def __init__(self, master_end, sim_port, taps):
        super().__init__(daemon=True)
        flags = os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK
        self.m = os.open(master_end, flags)
        self.s = os.open(sim_port, flags)
        self.taps = [os.open(t, os.O_WRONLY | os.O_NOCTTY) for t in taps]
        self.stop = threading.Event()

    def run(self):
        while not self.stop.is_set():
            r, _, _ = select.select([self.m, self.s], [], [], 0.05)
            for fd in r:
                try:
                    data = os.read(fd, 4096)
                except OSError:
                    continue
                if data:
                    os.write(self.s if fd == self.m else self.m, data)
                    for t in self.taps:
                        os.write(t, data)

    def close(self):
        self.stop.set()
        self.join(5)
        for fd in [self.m, self.s, *self.taps]:
            os.close(fd)


@pytest.mark.skipif(not shutil.which("socat"), reason="socat not installed")
def test_sniff_and_extcap_capture_a_running_bus_and_tshark_decodes_it(tshark, tmp_path):
    """`pdrive run 6` against `pdrive sim --pty`; `pdrive sniff --pcap` and the extcap capture (into
    a fifo, as Wireshark runs it) listen on a tap. tshark with the dissector and the station table
    shows the start-up and the drive running: Set_Prm watchdog 500 ms (run's default), Slave_Diag
    Prm_Req before parameters, STW with 'enable operation', HSW 25 Hz = 0x2000 of A004 50 Hz."""
    from profidrive_cli.drives.profile import load_profile
    ident = load_profile("moeller").ident
    r = run("wireshark", "install", "--dir", tmp_path, "--station", "6=moeller")
    assert r.exit_code == 0, r.output
    procs = []
    mp, master, master_end = _pty_pair(tmp_path, "m")
    tp1, tap1, tap1_end = _pty_pair(tmp_path, "t1")
    tp2, tap2, tap2_end = _pty_pair(tmp_path, "t2")
    procs += [mp, tp1, tp2]
    fifo = tmp_path / "wireshark.fifo"
    os.mkfifo(fifo)
    sniff_pcap = tmp_path / "sniff.pcap"
    chunks = []
    try:
        with pty_sim_process("--plant", "sim://?stations=6:moeller") as sim_port:
            tap = Tap(master_end, sim_port, [tap1_end, tap2_end])
            tap.start()
            sniff = subprocess.Popen(pdrive_cmd() + ["sniff", "--port", tap1, "--duration", "60",
                                                     "--pcap", str(sniff_pcap)],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
            extcap = subprocess.Popen(pdrive_cmd() + ["wireshark", "extcap", "--capture",
                                                      "--extcap-interface", "pdrive", "--fifo", str(fifo),
                                                      "--port", tap2, "--baud", "19200"],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
            procs += [sniff, extcap]
            reader_done = threading.Event()

            def read_fifo():
                with open(fifo, "rb") as fh:            # like Wireshark: read until the writer ends
                    while True:
                        b = fh.read(4096)
                        if not b:
                            break
                        chunks.append(b)
                reader_done.set()
            threading.Thread(target=read_fifo, daemon=True).start()
            time.sleep(1.5)                            # both listeners up
            # 25 Hz: reached after 2.5 s (F002 5 s for A004 50 Hz), within the 3.5 s: a good run
            master_run = subprocess.run(pdrive_cmd() + ["run", "6", "--hz", "25", "--duration", "3.5",
                                                        "--port", master, "--yes", "--json"],
                                        capture_output=True, text=True, timeout=120)
            assert master_run.returncode == 0, master_run.stderr
            time.sleep(0.5)
            sniff.send_signal(signal.SIGINT)           # Ctrl-C ends a capture and keeps it
            extcap.send_signal(signal.SIGTERM)         # Wireshark stops an extcap with SIGTERM
            assert sniff.wait(30) == 0, sniff.stderr.read()
            assert extcap.wait(30) == 0, extcap.stderr.read()
            assert reader_done.wait(10)
            tap.close()
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
    lt, pkts = read_pcap(sniff_pcap.read_bytes())
    assert lt == 147 and len(pkts) > 20
    now = time.time()
    assert all(now - 300 < t <= now + 1 for t, _ in pkts)          # wall clock, not 1970
    lt2, pkts2 = read_pcap(b"".join(chunks))
    assert lt2 == 147
    # both listeners heard the same telegrams (the extcap one may lack none of sniff's frames)
    assert [p for _, p in pkts2] == [p for _, p in pkts]

    names = ["profibus.service", "profibus.prm.watchdog_ms", "profibus.prm.ident", "profibus.diag.flags",
             "profidrive.control.set", "profidrive.reference_hz", "profidrive.layout"]
    for pcap in (sniff_pcap, _write(tmp_path / "extcap.pcap", b"".join(chunks))):
        rows = _fields(tshark, pcap, names, lua=tmp_path / "pdrive.lua")
        services = [r["profibus.service"] for r in rows]
        for s in ("Set_Prm", "Chk_Cfg", "Slave_Diag", "Slave_Diag reply", "Data_Exchange",
                  "Data_Exchange reply"):
            assert s in services, (s, services)
        prm = [r for r in rows if r["profibus.service"] == "Set_Prm"][0]
        assert prm["profibus.prm.watchdog_ms"] == "500"
        assert int(prm["profibus.prm.ident"], 16) == ident
        diags = [r["profibus.diag.flags"] for r in rows if r["profibus.service"] == "Slave_Diag reply"]
        assert "Prm_Req" in diags[0]
        dx = [r for r in rows if r["profibus.service"] == "Data_Exchange"]
        assert all(r["profidrive.layout"] == "moeller-de6-net-dp ppo1" for r in dx)
        running = [r for r in dx if "enable operation" in r["profidrive.control.set"]]
        assert running, [r["profidrive.control.set"] for r in dx]
        assert any(r["profidrive.reference_hz"] and float(r["profidrive.reference_hz"]) == 25.0
                   for r in running)


def _write(path, data):
    Path(path).write_bytes(data)
    return path


# -- extcap protocol -------------------------------------------------------------------------------

def _extcap(*args):
    return subprocess.run(pdrive_cmd() + ["wireshark", "extcap", *args], capture_output=True, text=True,
                          timeout=60, stdin=subprocess.DEVNULL)


def test_extcap_interfaces_dlts_and_config_answer_in_the_extcap_format():
    p = _extcap("--extcap-interfaces", "--extcap-version=4.0")
    assert p.returncode == 0, p.stderr
    lines = p.stdout.splitlines()
    assert lines[0].startswith("extcap {version=")
    assert lines[1].startswith("interface {value=pdrive}{display=")
    p = _extcap("--extcap-interface", "pdrive", "--extcap-dlts")
    assert p.stdout.splitlines() == ["dlt {number=147}{name=USER0}{display=PROFIBUS FDL (pdrive.lua)}"]
    p = _extcap("--extcap-interface", "pdrive", "--extcap-config")
    lines = p.stdout.splitlines()
    assert lines[0].startswith("arg {number=0}{call=--port}") and "{required=true}" in lines[0]
    assert lines[1].startswith("arg {number=1}{call=--baud}{display=Baud rate}{type=selector}")
    values = [ln for ln in lines if ln.startswith("value {arg=1}")]
    assert len(values) == 10                               # the ten DP baud rates, 9.6k .. 12M
    assert [ln for ln in values if "{default=true}" in ln] == \
        ["value {arg=1}{value=19200}{display=19.2kbit/s}{default=true}"]


def test_extcap_refuses_another_interface_and_a_capture_without_fifo():
    p = _extcap("--extcap-interface", "eth0", "--extcap-dlts")
    assert p.returncode == 2 and "unknown interface 'eth0'" in p.stderr
    p = _extcap("--capture", "--extcap-interface", "pdrive", "--port", "sim://")
    assert p.returncode == 2 and "--fifo" in p.stderr
    assert "Traceback" not in p.stderr


def test_tshark_names_the_dpv1_telegrams_and_decodes_ds47_like_sniff(tshark, tmp_path):
    """Issue 39: the dissector names the DP-V1 acyclic telegrams as `pdrive sniff` does (a DS47 read
    as a master runs it: request, SC, poll, SC, answer; a negative answer; the Toshiba change
    request; an Alarm_Ack; a class-2 Initiate; a negative parameter response), its Info column ends
    in sniff's decoded lines, and the PDU and DS47 fields carry the values of the octets
    (tests/test_sniff_dpv1.py: the telegrams and their hand-written words)."""
    from test_sniff_dpv1 import CAPTURE, READ_RES_NEGATIVE, WRITE_964
    frames = CAPTURE + [WRITE_964, READ_RES_NEGATIVE]
    pcap = _pcap(tmp_path / "dpv1.pcap", frames)
    names = ["profibus.service", "_ws.col.Info", "profibus.msac.kind", "profibus.msac.function",
             "profibus.msac.negative", "profibus.msac.slot", "profibus.msac.index", "profibus.msac.length",
             "profibus.msac.error_decode", "profibus.msac.error_class", "profibus.msac.error_code",
             "profibus.msac.error_text", "profibus.msac.request", "profibus.msac.note",
             "profibus.msac.alarm_type", "profidrive.ds47.kind", "profidrive.ds47.reference",
             "profidrive.ds47.request_id", "profidrive.ds47.response_id", "profidrive.ds47.axis",
             "profidrive.ds47.count", "profidrive.ds47.attribute", "profidrive.ds47.elements",
             "profidrive.ds47.pnu", "profidrive.ds47.subindex", "profidrive.ds47.format",
             "profidrive.ds47.value", "profidrive.ds47.error", "profidrive.ds47.error_text"]
    rows = _fields(tshark, pcap, names)
    raw = tmp_path / "dpv1.raw"
    raw.write_bytes(b"".join(frames))
    sniffed = [json.loads(x) for x in run("sniff", "--from-file", raw, "--json").output.splitlines()]
    assert len(rows) == len(sniffed) == len(frames)
    for r, d in zip(rows, sniffed):
        assert r["profibus.service"] == d["service"]
        assert r["_ws.col.Info"].endswith("  " + "; ".join(d["decoded"]["text"])), r["_ws.col.Info"]
    # by hand from the octets
    write, ack, poll, ack2, wres, read, _, _, rres, _, _, _, err, change, _, alarm, init, _, neg = rows
    assert [r["profibus.msac.kind"] for r in (write, ack, poll, ack2, wres, rres, alarm, init)] == \
        ["request", "ack", "poll", "ack", "response", "response", "request", "request"]
    assert (write["profibus.msac.function"], write["profibus.msac.slot"], write["profibus.msac.index"],
            write["profibus.msac.length"]) == ("0x5f", "0", "47", "10")
    assert (read["profibus.msac.function"], read["profibus.msac.length"]) == ("0x5e", "240")
    assert poll["profibus.msac.request"] == "Write slot 0 index 47 length 10"
    assert ack["profibus.msac.note"] == ("MSAC_C1: station 5 took the request (Write slot 0 index 47 "
                                         "length 10); the master polls for the answer")
    assert ack2["profibus.msac.note"].startswith("MSAC_C1: station 5 has no answer yet")
    # DE 80 B5 00: Read (0x5E) with the error bit, Error_Decode 0x80 DPV1, class 0xB access, code 5
    assert (err["profibus.msac.function"], err["profibus.msac.negative"], err["profibus.msac.error_decode"],
            err["profibus.msac.error_class"], err["profibus.msac.error_code"]) == ("0x5e", "1", "0x80",
                                                                                  "0x0b", "5")
    assert err["profibus.msac.error_text"] == "DPV1 access: state conflict (80 B5 00)"
    assert err["profibus.msac.request"] == "Read slot 0 index 47 length 240"
    assert alarm["profibus.service"] == "MSAC_C1 Alarm_Ack request" and alarm["profibus.msac.alarm_type"] == "1"
    assert init["profibus.service"] == "MSAC_C2 Initiate request"
    # DS47: 01 01 01 01 10 01 03 C4 00 00 / 01 01 01 01 42 01 00 2A / the change of PNU 927 to 0
    assert [write[f"profidrive.ds47.{k}"] for k in ("kind", "reference", "request_id", "axis", "count",
                                                    "attribute", "elements", "pnu", "subindex")] == \
        ["request", "1", "0x01", "1", "1", "0x10", "1", "964", "0"]
    assert [rres[f"profidrive.ds47.{k}"] for k in ("kind", "reference", "response_id", "axis", "count",
                                                   "format", "value")] == \
        ["response", "1", "0x01", "1", "1", "0x42", "42"]
    assert [change[f"profidrive.ds47.{k}"] for k in ("request_id", "pnu", "subindex", "format", "value")] == \
        ["0x02", "927", "0", "0x06", "0"]
    assert (neg["profidrive.ds47.response_id"], neg["profidrive.ds47.format"], neg["profidrive.ds47.error"],
            neg["profidrive.ds47.error_text"]) == ("0x81", "0x44", "0x0014", "0x14 value impermissible")
    assert ack["profidrive.ds47.kind"] == "" and wres["profidrive.ds47.kind"] == ""


def test_tshark_dpv1_tree_and_a_capture_without_dpv1_keeps_its_sc_plain(tshark, tmp_path):
    """The DS47 subtree's items in words (-V); an SC in a capture without DP-V1 telegrams is the plain
    short acknowledge, and an SC that follows anything but a request or poll too."""
    from test_sniff_dpv1 import READ_RES, WRITE_927
    out = _tshark(tshark, _pcap(tmp_path / "a.pcap", [WRITE_927, SC, READ_RES, SC]), "-V")
    assert "PROFIdrive parameter request (DS47): ref 1 change axis 1: PNU927[0] (1 element) = Unsigned16 0" in out
    assert "Parameter 1: PNU927[0] (1 element) = Unsigned16 0" in out
    assert "PROFIdrive parameter response (DS47): ref 1 read ok axis 1: Word 0x002A" in out
    rows = _fields(tshark, _pcap(tmp_path / "b.pcap", [WRITE_927, SC, READ_RES, SC, DX_REQ, SC]),
                   ["_ws.col.Info", "profibus.msac.kind"])
    assert rows[1]["profibus.msac.kind"] == "ack"
    assert [r["_ws.col.Info"] for r in rows[3::2]] == ["SC  short acknowledge"] * 2


def _lua_table(name: str) -> str:
    """The text of `local NAME = { ... }` in the dissector (braces counted)."""
    text = LUA.read_text(encoding="utf-8")
    start = text.index(f"local {name} = {{") + len(f"local {name} = ")
    depth = 0
    for i in range(start, len(text)):
        depth += {"{": 1, "}": -1}.get(text[i], 0)
        if depth == 0:
            return text[start:i + 1]
    raise AssertionError(f"{name}: no end")


def _lua_names(table_text: str) -> dict[int, str]:
    import re
    return {int(k, 0): v for k, v in re.findall(r'\[(0x[0-9A-Fa-f]+|\d+)\]\s*=\s*"([^"]*)"', table_text)}


def test_the_dissectors_dpv1_tables_are_the_codecs():
    """The dissector repeats dp/msac1.py's and drives/profidrive/ds47.py's tables (Lua cannot ask
    Python): the same functions, error classes and codes, DS47 names, formats, value sizes and error
    numbers, so Wireshark and sniff say the same words."""
    import re

    from profidrive_cli.dp import msac1 as M
    from profidrive_cli.drives.profidrive import ds47 as D
    assert _lua_names(_lua_table("MSAC_FUNCTIONS")) == M.FUNCTIONS
    assert _lua_names(_lua_table("MSAC_ERROR_DECODE")) == M.ERROR_DECODE
    assert _lua_names(_lua_table("MSAC_ERROR_CLASSES")) == M.ERROR_CLASSES
    codes = _lua_table("MSAC_ERROR_CODES")
    blocks = dict(re.findall(r"\[(0x[0-9A-F]+)\]\s*=\s*(\{[^}]*\})", codes))
    assert {int(k, 16): _lua_names(v) for k, v in blocks.items()} == M.ERROR_CODES
    assert _lua_names(_lua_table("DS47_REQUEST")) == D.REQUEST_NAMES
    assert _lua_names(_lua_table("DS47_RESPONSE")) == D.RESPONSE_NAMES
    assert _lua_names(_lua_table("DS47_ATTRIBUTES")) == D.ATTRIBUTES
    assert _lua_names(_lua_table("DS47_FORMATS")) == D.FORMATS
    assert _lua_names(_lua_table("DS47_ERRORS")) == D.ERRORS
    coding = {int(k, 16): (int(n), kind) for k, n, kind in
              re.findall(r'\[(0x[0-9A-F]+)\]\s*=\s*\{\s*(\d+),\s*"(\w)"\s*\}', _lua_table("DS47_CODING"))}
    assert coding == D._CODING
    assert {int(k, 16) for k in re.findall(r"\[(0x[0-9A-F]+)\]", _lua_table("DS47_HEX"))} == D._HEX_FORMATS
