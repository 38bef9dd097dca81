"""Real bus traffic decodes in full (issue 26): the ET200S start-up of pyprofibus issue #26 and the four
devices' Prm/Cfg of profirust's examples, read from ../shared/testdata/external/ (never copied here),
and the DP-V1 decoder (dp/dpv1.py, dp/du_decode.py) on hand-built octets.

Expected values are worked by hand from ../shared/spec/profibus-dp-reference.md ("ref N" = its line N)
and, for the bits the reference leaves out, from a public profichip VPC3+ slave header ("VPC3":
dp_sPRM_t DPV1_Status_1 bits 1, 0 = Dis_Stop_Control, Dis_Start_Control; DPV1_Status_3 bit 4 IsoM_Req;
Alarm_Type 1..6 = Diagnostic, Process, Pull, Plug, Status, Update; Status_Type 1 Status_Message,
2 Module_Status; the alarm specifier bits 1..0 / bit 2 Add_Ack / bits 7..3 Seq_Nr; E_DP_DIAG_MS
0 ok, 1 fault, 2 wrong module, 3 no module).
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

from conftest import SHARED, pdrive_cmd
from profidrive_cli.dp import services as S
from profidrive_cli.dp.capture import Capture
from profidrive_cli.dp.cfg import decode_cfg
from profidrive_cli.dp.dpv1 import dpv1_block, dpv1_status
from profidrive_cli.dp.du_decode import decode_du

EXTERNAL = Path(os.environ.get("PDRIVE_EXTERNAL_TESTDATA", Path(SHARED) / "testdata" / "external"))
ET200S = EXTERNAL / "pyprofibus26-et200s-startup.raw"
PROFIRUST = EXTERNAL / "profirust-examples-prm-cfg.tsv"


def _need(path: Path) -> Path:
    if not path.exists():
        pytest.skip(f"{path} not present (../shared/testdata/external/)")
    return path


def _frames() -> list[dict]:
    """The capture's frames as dp.capture describes them, each with its `decoded` DU."""
    out = []
    for c in Capture().feed(_need(ET200S).read_bytes(), 0.0):
        assert c.frame is not None, c.error           # every FCS good (the .txt beside it)
        d = c.describe()
        d["decoded"] = decode_du(d["service"], c.frame.data) if "du" in d else None
        out.append(d)
    return out


# =============================================================================================
# the #26 ET200S start-up
# =============================================================================================


def test_the_capture_has_its_15_telegrams():
    # pyprofibus26-et200s-startup.txt: 5 FDL status requests, reply, diag req/reply, Set_Prm, SC,
    # Chk_Cfg, SC, diag req/reply, diag req = 15
    assert [d["service"] for d in _frames()] == (
        ["FDL status"] * 5 + ["FDL status reply", "Slave_Diag", "Slave_Diag reply", "Set_Prm",
                              "short acknowledge", "Chk_Cfg", "short acknowledge", "Slave_Diag",
                              "Slave_Diag reply", "Slave_Diag"])


def test_set_prm_standard_octets_and_dpv1_status():
    (p,) = [d for d in _frames() if d["service"] == "Set_Prm"]
    dec = p["decoded"]
    # DU b8 1e 01 00 80 6a 01 | 40 01 00 | 11 21 ...
    # 0xB8 = 1011 1000: bit 7 Lock_Req, 5 Sync_Req, 4 Freeze_Req, 3 WD_On (ref 221-225)
    assert dec["station_status"] == ["Lock_Req", "Sync_Req", "Freeze_Req", "WD_On"]
    # WD 0x1E x 0x01 x 10 ms = 300 ms (ref 209; WD_Base_1ms, bit 2 of 0x40, is 0: ref 238)
    assert (dec["wd_fact_1"], dec["wd_fact_2"], dec["watchdog_ms"]) == (30, 1, 300)
    assert dec["min_tsdr"] == 0                       # ref 211: 0 = keep the slave's
    assert dec["ident"] == "0x806A" and dec["group"] == 1            # ref 212, 213
    # DPV1_Status_1 0x40: bit 6 Fail_Safe (ref 238); DPV1_Status_2 0x01: bit 0 Chk_Cfg_Mode
    # (ref 239); DPV1_Status_3 0x00: Alarm_Mode 0 = 1 alarm of each type (ref 240)
    v1 = dec["dpv1_status"]
    assert v1["octets"] == "40 01 00"
    assert v1["flags"] == ["Fail_Safe", "Chk_Cfg_Mode"]
    assert "DPV1_Enable" not in v1["flags"]           # bit 7 of 0x40 is 0
    assert (v1["alarm_mode"], v1["alarm_mode_text"]) == (0, "1 alarm of each type")
    assert dec["user_prm"].startswith("40 01 00 11 21")
    assert any("Fail_Safe, Chk_Cfg_Mode" in t for t in dec["text"])


def test_diagnosis_blocks_before_and_after_start_up():
    first, second = [d["decoded"] for d in _frames() if d["service"] == "Slave_Diag reply"]
    # st1 0x02 = bit 1 Station_Not_Ready; st2 0x05 = bit 0 Prm_Req + bit 2 (always 1) (ref 286-288)
    assert first["flags"] == ["Station_Not_Ready", "Prm_Req"]
    assert first["master"] is None and first["ident"] == "0x806A"          # 0xFF (ref 280)
    # after start-up st2 0x0C = bit 3 WD_On + bit 2; master 2 (ref 289, 280)
    assert second["flags"] == ["Station_Not_Ready", "WD_On"] and second["master"] == 2
    for dec in (first, second):
        ident, dev = dec["blocks"]
        # 0x49 = 01 001001: identifier-related, 9 octets incl. header, 8 octets of zero bits (ref 306)
        assert ident["kind"] == "identifier" and ident["modules"] == []
        assert ident["raw"] == "49" + " 00" * 8
        # 0x14 = 00 010100: device-related, 20 octets (ref 305); octet 1 0x82: bit 7 = 1 status,
        # type 2 Module_Status (ref 305, VPC3); slot 0; specifier 0 (bits 1..0 = 0: no further
        # differentiation); 16 octets of module status = 64 modules x 2 bits, all 00 = data valid
        assert dev["kind"] == "device" and len(dev["raw"].split()) == 20
        v1 = dev["dpv1"]
        assert (v1["block"], v1["type"], v1["type_name"]) == ("status", 2, "Module_Status")
        assert (v1["slot"], v1["specifier"], v1["specifier_text"]) == (0, 0, "no further differentiation")
        assert v1["module_status"] == [] and v1["data"] == " ".join(["00"] * 16)
        assert "64 modules: all data valid" in dev["text"]


def test_chk_cfg_of_the_capture():
    (c,) = [d["decoded"] for d in _frames() if d["service"] == "Chk_Cfg"]
    # 00 = empty slot (ref 262); 0x10 = bits 5..4 01 input, length 0+1 = 1 byte; 0x20 = 1 byte out
    # (ref 250-251)
    assert c["cfg"] == ["empty slot", "1 byte in", "1 byte out"]


def _run(*args: str) -> str:
    r = subprocess.run([*pdrive_cmd(), *args], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return r.stdout


def test_sniff_text_names_the_dpv1_octets_and_the_blocks():
    out = _run("sniff", "--from-file", str(_need(ET200S)))
    assert "DP-V1 status 40 01 00: Fail_Safe, Chk_Cfg_Mode; Alarm_Mode 0 (1 alarm of each type)" in out
    assert out.count("ext diag: identifier-related: modules with diagnosis: none") == 2
    assert out.count("ext diag: device-related: DP-V1 status block: Module_Status (0x82), "
                     "slot 0, specifier 0 (no further differentiation); 64 modules: all data valid") == 2
    assert "watchdog 300 ms (30 x 1 x 10 ms)" in out


def test_sniff_json_carries_the_decoded_object():
    lines = [json.loads(x) for x in _run("sniff", "--from-file", str(_need(ET200S)), "--json").splitlines()]
    assert len(lines) == 15
    (prm,) = [d for d in lines if d.get("service") == "Set_Prm"]
    assert prm["decoded"]["dpv1_status"]["flags"] == ["Fail_Safe", "Chk_Cfg_Mode"]
    diags = [d for d in lines if d.get("service") == "Slave_Diag reply"]
    assert [[b["kind"] for b in d["decoded"]["blocks"]] for d in diags] == [["identifier", "device"]] * 2
    assert all("decoded" not in d for d in lines if d["service"] in ("FDL status", "short acknowledge"))


# =============================================================================================
# profirust's four devices: Prm (the standard octets around their user prm) and Cfg
# =============================================================================================


def _profirust_rows() -> dict[str, tuple[int, bytes, bytes]]:
    rows = {}
    for line in _need(PROFIRUST).read_text(encoding="utf-8").splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        cells = line.split("\t")
        rows[cells[0].split()[1]] = (int(cells[2], 16), bytes.fromhex(cells[3]), bytes.fromhex(cells[4]))
    return rows


# by hand, ref 250-262 (and 255: 0xF1 = 2 words in+out consistent, PPO3's PZD; 269: MM4 "00 F1")
CFG_BY_HAND = {
    "MICROMASTER": ["empty slot", "2 words in+out, consistent"],
    "ET200B": ["1 byte out", "1 byte in"],
    "750-343": ["empty slot"] + ["1 byte in"] * 10 + ["1 byte out"] * 7,
    "absolute": ["2 words in+out, consistent"],
}


@pytest.mark.parametrize("key", list(CFG_BY_HAND))
def test_profirust_devices_prm_and_cfg(key):
    rows = _profirust_rows()
    ident, user, cfg = rows[key]
    du = S.SetPrm(ident=ident, wd_ms=100.0, sync=False, freeze=False, group=0, user_prm=user).encode()
    dec = decode_du("Set_Prm", du)
    assert dec is not None
    # 0x88 = Lock_Req + WD_On (ref 221, 225); 100 ms = 10 x 1 x 10 ms (ref 209); ident (ref 212)
    assert dec["station_status"] == ["Lock_Req", "WD_On"] and dec["watchdog_ms"] == 100
    assert dec["ident"] == f"0x{ident:04X}" and bytes.fromhex(dec["user_prm"]) == user
    if key == "absolute":
        # FRABA 00 0A 00: 0x0A has bit 1 set, reserved in DPV1_Status_2 (ref 239, VPC3): a DP-V0
        # encoder's own parameters (0x0A = class 2 + scaling, the .tsv's note), not DP-V1 status
        assert "dpv1_status" not in dec
    else:
        assert dec["dpv1_status"]["flags"] == []         # 00 00 00: no DP-V1 bit set
    assert [m.describe() for m in decode_cfg(cfg)] == CFG_BY_HAND[key]
    assert decode_du("Chk_Cfg", cfg)["cfg"] == CFG_BY_HAND[key]


def test_profirust_rows_are_the_four_devices():
    assert [(n.split()[0], hex(i)) for n, (i, _, _) in _profirust_rows().items()] == [
        ("MICROMASTER", "0x80b5"), ("ET200B", "0xb"), ("750-343", "0xb757"), ("absolute", "0x4711")]


# =============================================================================================
# the decoder on hand-built octets
# =============================================================================================


def test_dpv1_status_every_bit():
    # 0xE7 = bits 7,6,5 (DPV1_Enable, Fail_Safe, Publisher_Enable) + 2,1,0 (WD_Base_1ms,
    # Dis_Stop_Control, Dis_Start_Control); 0xFD = every alarm enable + Chk_Cfg_Mode;
    # 0x9F = Prm_Cmd, IsoM_Req, Prm_Structure, Alarm_Mode 7 = 32 alarms (ref 238-240, VPC3)
    s = dpv1_status(bytes.fromhex("e7 fd 9f"))
    assert s is not None and s.flags == [
        "DPV1_Enable", "Fail_Safe", "Publisher_Enable", "WD_Base_1ms", "Dis_Stop_Control",
        "Dis_Start_Control", "Enable_Pull_Plug_Alarm", "Enable_Process_Alarm",
        "Enable_Diagnostic_Alarm", "Enable_Manufacturer_Specific_Alarm", "Enable_Status_Alarm",
        "Enable_Update_Alarm", "Chk_Cfg_Mode", "Prm_Cmd", "IsoM_Req", "Prm_Structure"]
    assert s.to_dict()["alarm_mode_text"] == "32 alarms in total"


@pytest.mark.parametrize("octets", ["08 00 00", "10 00 00", "00 02 00", "00 00 20", "00 00 40", "00 00"])
def test_reserved_bits_or_too_few_octets_are_not_dpv1_status(octets):
    assert dpv1_status(bytes.fromhex(octets)) is None


def test_wd_base_1ms_changes_the_watchdog():
    # WD_Base_1ms (DPV1_Status_1 bit 2, ref 209 / 238): 30 x 1 x 1 ms = 30 ms
    du = bytes.fromhex("88 1e 01 0b 12 34 00 84 00 00")
    assert decode_du("Set_Prm", du)["watchdog_ms"] == 30


def test_alarm_block():
    # 08: device-related, 8 octets; 01: bit 7 = 0 alarm, type 1 Diagnostic_Alarm; slot 3;
    # specifier 0x0D = 00001 1 01: Seq_Nr 1, Add_Ack, bits 1..0 = 01 error appears (VPC3)
    b = dpv1_block(bytes.fromhex("08 01 03 0d aa bb cc dd"))
    assert b is not None and b.to_dict() == {
        "block": "alarm", "type": 1, "type_name": "Diagnostic_Alarm", "slot": 3, "specifier": 13,
        "specifier_text": "error appears (slot disturbed)", "data": "aa bb cc dd", "seq_nr": 1,
        "add_ack": True}


@pytest.mark.parametrize("code,name", [(2, "Process_Alarm"), (3, "Pull_Alarm"), (4, "Plug_Alarm"),
                                       (5, "Status_Alarm"), (6, "Update_Alarm"),
                                       (0x20, "manufacturer-specific 32")])
def test_alarm_types(code, name):
    b = dpv1_block(bytes((0x04, code, 0, 0x12)))      # specifier 0x12: Seq_Nr 2, bits 1..0 = 10
    assert b is not None and (b.type_name, b.seq_nr, b.add_ack) == (name, 2, False)
    assert b.specifier_text == "error disappears (slot okay)"


def test_status_message_and_module_status_with_bad_modules():
    b = dpv1_block(bytes.fromhex("06 81 02 01 55 66"))      # Status_Message, slot 2, appears
    assert b is not None and (b.block, b.type_name, b.slot, b.specifier_text) == (
        "status", "Status_Message", 2, "status appears")
    # 0xE4 = 11 10 01 00: module 0 valid, 1 fault, 2 wrong module, 3 no module (VPC3 E_DP_DIAG_MS)
    m = dpv1_block(bytes.fromhex("06 82 00 02 e4 00"))
    assert m is not None and m.module_status == [(1, "data invalid (module fault)"),
                                                 (2, "data invalid (wrong module)"),
                                                 (3, "data invalid (no module)")]
    assert m.specifier_text == "status disappears"
    assert "8 modules: module 1: data invalid (module fault)" in m.describe()


@pytest.mark.parametrize("octets", ["04 10 20 30",     # ref 312's device block: type 16 reserved
                                    "03 82 00",        # shorter than the 4-octet DP-V1 header
                                    "04 80 00 00",     # Status_Type 0 reserved
                                    "04 00 00 00",     # Alarm_Type 0 reserved
                                    "04 ff 00 00"])    # 127 reserved
def test_device_blocks_that_are_vendor_data(octets):
    assert dpv1_block(bytes.fromhex(octets)) is None


def test_every_block_kind_in_one_diagnosis():
    # ref 312's vector behind a diag header: identifier (module 8), channel (module 8, channel 1,
    # input, bit, short circuit), device 10 20 30 (vendor data), then a DP-V1 alarm and a reserved 0xC0
    du = bytes.fromhex("08 0c 00 02 12 34" "44 00 01 00" "88 41 21" "04 10 20 30" "04 04 05 09" "c0")
    dec = decode_du("Slave_Diag reply", du)
    assert dec is not None
    assert [b["kind"] for b in dec["blocks"]] == ["identifier", "channel", "device", "device", "reserved"]
    ident, chan, vendor, plug, _ = dec["blocks"]
    assert ident["modules"] == [8]
    assert (chan["module"], chan["channel"], chan["direction"], chan["width"], chan["error"]) == (
        8, 1, "input", "bit", "short circuit")
    assert "dpv1" not in vendor and vendor["text"] == "device-related: 10 20 30"
    # 04 04 05 09: Plug_Alarm, slot 5, specifier 0x09 = Seq_Nr 1, bits 1..0 = 01
    assert (plug["dpv1"]["type_name"], plug["dpv1"]["slot"], plug["dpv1"]["seq_nr"]) == ("Plug_Alarm", 5, 1)
    assert dec["flags"] == ["Ext_Diag", "WD_On"]             # st1 0x08, st2 0x0C (ref 289)


def test_services_without_a_decoder_and_short_dus():
    assert decode_du("Data_Exchange", b"\x01\x02") is None
    assert decode_du("Set_Prm", b"\x88\x01") is None           # shorter than the 7 octets
    assert decode_du("Slave_Diag reply", b"\x00") is None
    assert decode_du("Global_Control", bytes((0x02, 0x00)))["text"] == ["Global_Control: Clear_Data, all groups"]
