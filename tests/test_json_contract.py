"""docs/json.md is the JSON contract: every command's --json output is checked against its table
(no undocumented key, no missing required key, the documented type), and errors under --json are a
JSON object with the same exit code as without --json."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import pdrive_cmd, pty_sim_process

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "json.md"
TYPES = {"int", "number", "string", "bool", "null", "object", "list", "any", "open", "octets", "hex16"}
OCTETS = re.compile(r"([0-9a-f]{2}( [0-9a-f]{2})*)?")       # lower-case hex, single spaces
HEX16 = re.compile(r"0x[0-9A-F]{4}")                          # "0x%04X"


# =============================================================================================
# the contract, read from docs/json.md
# =============================================================================================


def load_contracts(text: str) -> dict[str, dict[str, tuple[set[str], bool]]]:
    """{contract name: {key path: (types, optional)}} from the `<!-- contract: NAME -->` tables."""
    contracts: dict[str, dict] = {}
    lines = text.splitlines()
    for i, line in enumerate(lines):
        m = re.fullmatch(r"<!-- contract: (.+?) -->", line.strip())
        if not m:
            continue
        name = m.group(1)
        assert name not in contracts, f"docs/json.md:{i + 1}: contract {name!r} twice"
        rows: dict[str, tuple[set[str], bool]] = {}
        j = i + 3                                   # the header and the |---| line
        while j < len(lines) and lines[j].startswith("|"):
            cells = [c.strip() for c in lines[j].strip().strip("|").split("|")]
            key = cells[0].strip("`")
            optional = key.endswith("?")
            key = key.rstrip("?")
            types = {t.strip() for t in cells[1].split(" or ")}
            assert types <= TYPES, f"docs/json.md:{j + 1}: unknown type in {cells[1]!r}"
            assert key not in rows, f"docs/json.md:{j + 1}: {key} twice"
            rows[key] = (types, optional)
            j += 1
        assert rows, f"docs/json.md:{i + 1}: contract {name!r} has no table"
        contracts[name] = rows
    return contracts


CONTRACTS = load_contracts(DOC.read_text(encoding="utf-8"))


def _type_ok(value, types: set[str]) -> bool:
    if "any" in types:
        return True
    if value is None:
        return "null" in types
    if isinstance(value, bool):
        return "bool" in types
    if isinstance(value, int):
        return bool(types & {"int", "number"})
    if isinstance(value, float):
        return "number" in types
    if isinstance(value, str):
        return ("string" in types or ("octets" in types and OCTETS.fullmatch(value) is not None)
                or ("hex16" in types and HEX16.fullmatch(value) is not None))
    if isinstance(value, list):
        return "list" in types
    if isinstance(value, dict):
        return bool(types & {"object", "open"})
    return False


def _split(path: str) -> tuple[str, str] | None:
    """(parent, key) of an object member's path; None for a list element ('a[]')."""
    if path.endswith("[]"):
        return None
    if "." in path:
        parent, _, key = path.rpartition(".")
        return parent, key
    return "", path


def problems(doc, contract: str) -> list[str]:
    """Everything in `doc` that differs from the contract's table."""
    spec = CONTRACTS[contract]
    found: list[str] = []

    def check(value, path: str, types: set[str]) -> None:
        where = path or "(the document)"
        if not _type_ok(value, types):
            found.append(f"{where}: {type(value).__name__} {value!r:.60} is not {' or '.join(sorted(types))}")
            return
        if "any" in types:
            return
        if isinstance(value, dict):
            for k, v in value.items():
                child = f"{path}.{k}" if path else k
                if child not in spec:                  # a data key: its documented form is `*`
                    star = f"{path}.*" if path else "*"
                    if star not in spec:
                        if "open" not in types:
                            found.append(f"{child}: not in docs/json.md")
                        continue
                    child = star
                check(v, child, spec[child][0])
            for p, (_, optional) in spec.items():
                pk = _split(p)
                if pk and pk[0] == path and pk[1] != "*" and not optional and pk[1] not in value:
                    found.append(f"{p}: missing")
        elif isinstance(value, list):
            entry = spec.get(f"{path}[]")
            if value and entry is None:
                found.append(f"{path}[]: the elements are not in docs/json.md")
                return
            for v in value:
                check(v, f"{path}[]", entry[0])

    check(doc, "", {"list"} if "[]" in spec else {"object"})
    return found


def assert_contract(doc, contract: str) -> None:
    bad = problems(doc, contract)
    assert not bad, f"{contract}: " + "; ".join(bad)


def assert_stream(lines: list[dict], contract: str) -> list[str]:
    """Every line of a stream against `contract event=<its event>`; returns the events in order."""
    events = []
    for d in lines:
        assert "event" in d, f"{contract}: a line without an event: {d}"
        name = f"{contract} event={d['event']}" if d["event"] != "error" else "error"
        assert name in CONTRACTS, f"{contract}: event {d['event']!r} is not in docs/json.md"
        assert_contract(d, name)
        events.append(d["event"])
    return events


# =============================================================================================
# the checker itself: it must catch each kind of difference
# =============================================================================================


def test_checker_finds_an_undocumented_key():
    assert problems({"port": "x", "stations": [], "baud": 1, "line_noise": 0, "echo": None, "extra": 1},
                    "scan") == \
        ["extra: not in docs/json.md"]


def test_checker_finds_a_missing_key():
    assert problems({"port": "x", "stations": [], "baud": 1, "echo": None}, "scan") == ["line_noise: missing"]


def test_checker_finds_a_wrong_type():
    bad = problems({"port": "x", "stations": [], "baud": "19200", "line_noise": 0, "echo": False}, "scan")
    assert len(bad) == 1 and bad[0].startswith("baud: str")


def test_checker_checks_the_octet_and_ident_formats():
    frame = {"event": "bad_frame", "t_s": 0.0, "error": "bad FCS", "raw": "68 05"}
    assert problems(frame, "sniff event=bad_frame") == []
    for bad in ("68 0A", "68  05", "6805", "68 05 "):
        assert len(problems({**frame, "raw": bad}, "sniff event=bad_frame")) == 1, bad
    assert problems({**frame, "raw": ""}, "sniff event=bad_frame") == []
    d = {"station": 3, "ident": 64769, "ident_hex": "0xFD01"}
    assert problems(d, "diag")[:0] == [] and not [b for b in problems(d, "diag") if "ident_hex" in b]
    assert [b for b in problems({**d, "ident_hex": "0xfd01"}, "diag") if b.startswith("ident_hex")]


def test_checker_finds_old_names_inside_lists():
    st = {"address": 3, "type": "slave", "ident": "0xFD01", "ident_hex": "0xFD01", "state": "",
          "device": "", "diag": None, "counters": {"retries": 0, "no_answer": 0, "illegal": 0, "reparams": 0}}
    bad = problems({"port": "x", "stations": [st], "baud": 1, "line_noise": 0}, "scan")
    assert "stations[].address: not in docs/json.md" in bad
    assert "stations[].station: missing" in bad
    assert any(b.startswith("stations[].ident: str") for b in bad)


def test_open_objects_allow_more_keys_but_check_the_listed_ones():
    run_end = {"event": "end", "reason": "r", "stop": None, "stopped": True, "cycles": 1, "warnings": [],
               "counters": {"retries": 0, "no_answer": 0, "illegal": 0, "reparams": 0, "dh": 0}}
    assert problems(run_end, "run event=end") == []
    run_end["counters"]["retries"] = "0"
    assert len(problems(run_end, "run event=end")) == 1


def test_every_documented_table_is_used():
    """Each contract in docs/json.md is checked below (or by the unit tests of the checker)."""
    used = {"error", "scan", "diag", "io event=cycle", "status", "param get", "param set", "param dump",
            "param rows", "faults", "run event=start", "run event=phase", "run event=update",
            "run event=end", "sniff event=frame", "sniff event=bad_frame", "doctor", "doctor ports",
            "decode", "gsd show", "gsd list", "gsd prm", "gsd match", "sim", "checklist validate", "checklist run",
            "scan watch event=watch", "scan watch event=end",
            "run multi event=start", "run multi event=phase", "run multi event=update", "run multi event=end",
            "commloss-test event=start", "commloss-test event=reaction", "commloss-test event=started",
            "commloss-test event=at_speed", "commloss-test event=silence", "commloss-test event=clear",
            "commloss-test event=back", "commloss-test event=result",
            "sniff drive", "sniff event=live", "sniff event=trigger", "sniff event=removed",
            "sniff event=disk", "config show", "config path",
            "wireshark install", "checklist measured bus_health", "sim-ctl state", "audit",
            "scan save", "scan compare", "checklist measured baseline", "param fleet dump",
            "param fleet diff",
            # tests/test_monitor_e2e.py (web, monitor, end, report), test_monitor_soak.py (removed)
            "monitor event=web", "monitor event=monitor", "monitor event=end", "monitor report",
            "monitor event=removed"}
    assert set(CONTRACTS) == used


# =============================================================================================
# every command on the simulator
# =============================================================================================


def pdrive(*args: str, cwd=None, timeout: float = 60) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    env.pop("PDRIVE_PORT", None)
    return subprocess.run(pdrive_cmd() + list(args), capture_output=True, text=True, timeout=timeout,
                          cwd=cwd or ROOT, env=env)


def one_doc(r: subprocess.CompletedProcess, code: int = 0):
    assert r.returncode == code, r.stderr
    assert r.stdout.strip(), r.stderr
    return json.loads(r.stdout)


def lines_of(r: subprocess.CompletedProcess, code: int = 0) -> list[dict]:
    assert r.returncode == code, r.stderr
    return [json.loads(x) for x in r.stdout.splitlines() if x.strip()]


SIM = ("--port", "sim://")


def test_scan():
    d = one_doc(pdrive("scan", *SIM, "--json"))
    assert_contract(d, "scan")
    s3 = next(s for s in d["stations"] if s["station"] == 3)
    # the OPC-G1-PDP's ident from its GSD (FUJIFD01.GSD: Ident_Number = 0xFD01)
    assert (s3["ident"], s3["ident_hex"], s3["diag"]["ident"]) == (0xFD01, "0xFD01", 0xFD01)
    assert s3["diag"]["flags"] == ["Station_Not_Ready", "Prm_Req"]     # unparameterised: st1 bit 1, st2 bit 0


def test_scan_with_nobody_is_a_document_and_exit_1():
    d = one_doc(pdrive("scan", *SIM, "--from", "100", "--to", "101", "--json"), code=1)
    assert_contract(d, "scan")
    assert d["stations"] == []


def test_audit(tmp_path):
    # every finding kind of the plant: an error with a check (P002, DE6-NET-DP manual L361-363), a
    # warning with one (y97, OPC-PDP3 L4325-4333), a note without one (Toyo ZSW bit 9), a delay
    d = one_doc(pdrive("audit", "--port", "sim://?set=6:P002=1&set=4:y97=1,o27=11,o28=2.5"
                       "&set=5:b-11=1,b-10=1", "--json", "--checklist", str(tmp_path / "c.yaml")),
                code=1)
    assert_contract(d, "audit")
    assert d["errors"] == 2 and [s["station"] for s in d["stations"]] == [3, 4, 5, 6, 7]
    d = one_doc(pdrive("audit", "3", "--port", "sim://", "--ppo", "3", "--json"))   # not checked
    assert_contract(d, "audit")
    assert d["stations"][0]["not_checked"] and d["checklist"] is None


def test_diag():
    d = one_doc(pdrive("diag", "7", *SIM, "--json"))
    assert_contract(d, "diag")
    assert (d["station"], d["ident"], d["ident_hex"]) == (7, 0x00CA, "0x00CA")   # YASK00CA.GSD


def test_io_stream():
    lines = lines_of(pdrive("io", "3", "--cfg", "F3 F1", "--count", "2", *SIM, "--json"))
    assert assert_stream(lines, "io") == ["cycle", "cycle"]
    # PPO1 in: 4 PKW words + 2 PZD words = 12 octets, lower-case hex with single spaces
    assert re.fullmatch(r"[0-9a-f]{2}( [0-9a-f]{2}){11}", lines[0]["inputs"])


@pytest.mark.parametrize("station", ["3", "4", "5", "6", "7"])
def test_status(station):
    d = one_doc(pdrive("status", station, *SIM, "--json"))
    assert_contract(d, "status")
    assert d["station"] == int(station)
    assert all(isinstance(f, str) for f in d["flags"])


def test_status_flags_are_the_names_set():
    d = one_doc(pdrive("status", "3", *SIM, "--json"))
    # Fuji STW after power-on: bit 6 (switch-on inhibited) and bit 9 (R/L) set, the card's names
    # (fuji-opc-g1-pdp.md status word table)
    assert "not ready for run-ON (switch-on inhibited)" in d["flags"]
    assert "running" not in d["flags"]
    assert d["actual_hz"] == 0.0


def test_param_get_set_dump_diff_restore(tmp_path):
    d = one_doc(pdrive("param", "get", "3", "F07", *SIM, "--json"))
    assert_contract(d, "param get")
    assert d["station"] == 3 and d["parameters"][0]["code"] == "F07"
    d = one_doc(pdrive("param", "set", "3", "F07", "5", *SIM, "--json"))
    assert_contract(d, "param set")
    assert d["new"]["value"] == 5.0                      # F07 in 0.1 s: raw 50
    dump = tmp_path / "d3.yaml"
    d = one_doc(pdrive("param", "dump", "3", "-o", str(dump), *SIM, "--json"))
    assert_contract(d, "param dump")
    d = one_doc(pdrive("param", "diff", "3", str(dump), *SIM, "--json"))
    assert_contract(d, "param rows")
    d = one_doc(pdrive("param", "restore", "3", str(dump), "--dry-run", *SIM, "--json"))
    assert_contract(d, "param rows")
    assert d["dry_run"] is True


def test_param_defaults_changed_and_fleet(tmp_path):
    # issue 28: diff --defaults and dump --changed keep their tables; the fleet's two documents
    port = ["--port", "sim://?set=3:F07=5&set=6:F002=2"]
    d = one_doc(pdrive("param", "diff", "3", "--defaults", *port, "--json"), code=1)
    assert_contract(d, "param rows")
    assert d["compared_with"] == "factory defaults" and d["counts"]["differs"] == 1
    d = one_doc(pdrive("param", "dump", "3", "-o", str(tmp_path / "c.yaml"), "--changed", *port, "--json"))
    assert_contract(d, "param dump")
    line = tmp_path / "line"
    line.mkdir()
    five = ["--port", "sim://?stations=3:fuji-g1,8:fuji-g1,9:fuji-g1&set=9:F07=5"]
    d = one_doc(pdrive("param", "fleet", "dump", "3,8,9", "-o", str(line), *five, "--json"))
    assert_contract(d, "param fleet dump")
    g = tmp_path / "golden.yaml"
    g.write_text("parameters:\n  F07: 6.0\n  F08: 7.0\nexcept:\n  8: [F08]\n")     # 8 excepted, 3 and 9 not
    d = one_doc(pdrive("param", "fleet", "diff", str(line), "--golden", str(g), "--json"), code=1)
    assert_contract(d, "param fleet diff")
    assert d["odd"] == [{"station": 9, "code": "F07"}]


def test_param_restore_refused_is_one_error_object(tmp_path):
    dump = tmp_path / "d3.yaml"
    one_doc(pdrive("param", "dump", "3", "-o", str(dump), *SIM, "--json"))
    # the dump is station 3's (Fuji); restoring it to the Moeller at 6 is refused before any write
    r = pdrive("param", "restore", "6", str(dump), *SIM, "--json")
    d = one_doc(r, code=2)
    assert_contract(d, "error")
    assert d["exit_code"] == 2 and d["written"] == 0 and d["problems"]
    assert r.stdout.count("\n") == 1                      # one document on stdout


@pytest.mark.parametrize("args", [("3",), ("4",), ("5",), ("6", "--clear"), ("7",)])
def test_faults(args):
    d = one_doc(pdrive("faults", *args, *SIM, "--json"))
    assert_contract(d, "faults")


def test_run_stream():
    # F07 0.1 s: the 20 Hz are reached within the 0.3 s (a run that does not: exit 1, below)
    lines = lines_of(pdrive("run", "3", "--hz", "20", "--duration", "0.3", "--port", "sim://?set=3:F07=0.1",
                            "--json"))
    events = assert_stream(lines, "run")
    assert events[0] == "start" and events[-1] == "end" and "update" in events
    assert lines[-1]["failed"] is False and lines[-1]["problem"] is None
    start = lines[0]
    assert (start["station"], start["ident"], start["ident_hex"]) == (3, 0xFD01, "0xFD01")
    assert start["watchdog_s"] == 0.5                   # --watchdog default 500 ms
    assert lines[-1]["stop"]["how"] == "normal"


@pytest.mark.parametrize("args", [("6", "--hz", "10", "--monitor", "default"), ("5", "--ppo", "5", "--torque", "20")])
def test_run_stream_with_monitors_and_torque(args):
    # F002 0.1 s (for A004 50 Hz): the 10 Hz are reached within the 0.3 s; a torque run is not judged
    lines = lines_of(pdrive("run", *args, "--duration", "0.3", "--port", "sim://?set=6:F002=0.1", "--json"))
    events = assert_stream(lines, "run")
    assert events[0] == "start" and events[-1] == "end"
    if "--monitor" in args:
        assert lines[-1]["monitors"] and all("t_s" in m for m in lines[-1]["monitors"].values())
    else:
        assert lines[0]["torque_ref_percent"] == 20


def test_run_not_reaching_its_reference_ends_failed_then_the_error():
    # F07 = 6 s from 0 to F03 60 Hz (the sim's ramp, profile fuji-opc-g1-pdp F07 default): 30 Hz
    # would take 3 s, so after 1 s the run has not reached it: the end says so, then the error, exit 1
    lines = lines_of(pdrive("run", "3", "--hz", "30", "--duration", "1", *SIM, "--json"), code=1)
    events = assert_stream(lines, "run")
    assert events[-2:] == ["end", "error"]
    end, error = lines[-2], lines[-1]
    assert end["failed"] is True and end["problem"] == "did not reach its reference"
    assert end["reached_after_s"] is None and end["stopped"]
    assert error["exit_code"] == 1 and "did not reach its reference (30 Hz) within 1 s" in error["error"]


def test_jog_stream():
    lines = lines_of(pdrive("jog", "6", "--duration", "0.3", *SIM, "--json"))
    events = assert_stream(lines, "run")
    assert events[0] == "start" and events[-1] == "end"
    assert lines[0]["jog_speed"]["code"] == "A038"     # the DF6's jog frequency


def test_doctor():
    assert_contract(one_doc(pdrive("doctor", *SIM, "--json")), "doctor")
    assert_contract(one_doc(pdrive("doctor", "--json")), "doctor ports")


def test_doctor_on_a_pty(socat_pair):
    a, _ = socat_pair
    r = pdrive("doctor", "--port", a, "--listen", "0.05", "--json")
    d = json.loads(r.stdout)
    assert_contract(d, "doctor")
    assert r.returncode == (1 if not d["ok"] else 0)


@pytest.mark.parametrize("args", [
    ("moeller", "--ppo", "1", "--request", "3017 0000 0000 0190 047F 2000"),
    ("fuji-g1", "--ppo", "1", "--response", "0000 0000 0000 0000 0237 1000"),
    ("toyo", "--ppo", "5", "--request", " ".join(["0000"] * 14)),
    ("toyo", "--ppo", "1", "--response", " ".join(["0000"] * 6)),
    ("yaskawa", "--format", "extended1", "--response", " ".join(["0000"] * 16)),
    ("yaskawa", "--format", "basic", "--request", "0001 0002 0003"),
])
def test_decode(args):
    d = one_doc(pdrive("decode", *args, "--json"))
    assert_contract(d, "decode")


def test_decode_every_layout_of_every_profile():
    """The decode document of each layout and direction of the five cards (in process: the same
    function the command prints through)."""
    from profidrive_cli.cli.decode_cmd import _result_json
    from profidrive_cli.drives import decode_area
    from profidrive_cli.drives.profile import load_profile
    seen = 0
    for name in ("fuji-g1", "fuji-pdp3", "toyo", "moeller", "yaskawa"):
        prof = load_profile(name)
        for layout, lay in prof.layouts.items():
            for direction, n in (("request", lay.output_len), ("response", lay.input_len)):
                d = _result_json(decode_area(prof, layout, direction, bytes(range(1, n + 1))))
                json.dumps(d)
                bad = problems(d, "decode")
                assert not bad, f"{prof.name} {layout} {direction}: {bad}"
                seen += 1
    assert seen >= 40


def test_decode_names():
    d = one_doc(pdrive("decode", "moeller", "--ppo", "1", "--request", "3017 0000 0000 0190 047F 2000",
                       "--json"))
    assert d["octets"] == "30 17 00 00 00 00 01 90 04 7f 20 00"
    # HSW 0x2000 = 50 % of A004 (50 Hz, the profile default) = 25 Hz
    assert (d["reference"]["reference_percent"], d["reference"]["reference_hz"]) == (50.0, 25.0)
    # STW 0x047F: bits 0-6 and 10 set
    assert d["control_word"]["flags"][:3] == ["ON", "no OFF2", "no OFF3"]
    assert len(d["control_word"]["flags"]) == 8


def test_gsd_show_list_prm():
    d = one_doc(pdrive("gsd", "show", "0xFD01", "--json"))
    assert_contract(d, "gsd show")
    assert d["modules"][0]["cfg"] == "f3 f1"            # PPO1: F3 F1 in FUJIFD01.GSD
    assert_contract(one_doc(pdrive("gsd", "list", "--json")), "gsd list")
    d = one_doc(pdrive("gsd", "prm", "0xFD01", "-m", "1", "--json"))
    assert_contract(d, "gsd prm")
    assert (d["ident"], d["ident_hex"], d["chk_cfg"]) == (0xFD01, "0xFD01", "f3 f1")


GSD_WITH_PRM = """#Profibus_DP
Ident_Number = 0x1234
Vendor_Name = "test"
Model_Name = "with user parameters"
Protocol_Ident = 0
Station_Type = 0
9.6_supp = 1
PrmText = 1
Text(-1) = "minus one"
Text(0) = "zero"
EndPrmText
ExtUserPrmData = 1 "s16"
Signed16 -2 -100-100
Prm_Text_Ref = 1
EndExtUserPrmData
ExtUserPrmData = 3 "list"
BitArea(4-6) 3 1,3,5
EndExtUserPrmData
Ext_User_Prm_Data_Const(0) = 0xFF, 0xFF, 0xFF
Ext_User_Prm_Data_Ref(0) = 1
Ext_User_Prm_Data_Ref(2) = 3
Module = "M" 0x10
EndModule
"""


def test_gsd_with_user_parameters(tmp_path):
    f = tmp_path / "prm.gsd"
    f.write_text(GSD_WITH_PRM)
    assert_contract(one_doc(pdrive("gsd", "show", str(f), "--json")), "gsd show")
    d = one_doc(pdrive("gsd", "prm", str(f), "-m", "1", "--json"))
    assert_contract(d, "gsd prm")
    # -2 -> FF FE; BitArea(4-6) = 3 into 0xFF keeps bits 7 and 0..3 -> 0xBF; lower case
    assert d["user_prm"] == "ff fe bf"
    assert [r["octets"] for r in d["user_prm_fields"]] == ["ff fe", "bf"]


def test_gsd_match_offline_and_on_the_simulator():
    """Issue 27: `gsd match` offline (a fit), with --configured (explain), on sim:// (Get_Cfg)."""
    d = one_doc(pdrive("gsd", "match", "--cfg", "F3 F1", "--ident", "0xFD01", "--json"))
    assert_contract(d, "gsd match")
    assert d["station"] is None and d["fits"][0]["slots"][0]["modules"][0]["name"].startswith("PPO1")
    d = one_doc(pdrive("gsd", "match", "3", *SIM, "--configured", "F3 F9", "--json"), code=1)
    assert_contract(d, "gsd match")
    assert d["cfg_from"] == "get_cfg" and len(d["explain"]) == 2
    d = one_doc(pdrive("gsd", "match", "--cfg", "F3 F9", "--ident", "0xFD01", "--json"), code=1)
    assert_contract(d, "gsd match")
    assert d["fits"] == [] and d["unmatched_at"] == 0


def test_io_stream_by_module_and_sniff_by_module(tmp_path):
    """Issue 27: io's `modules`, sniff's `decoded.layout` / `prm` / `modules` against the contract."""
    lines = lines_of(pdrive("io", "7", "--cfg", "72", "--count", "1", *SIM, "--json"))
    assert assert_stream(lines, "io") == ["cycle"] and lines[0]["modules"][0]["name"] == "Basic data"
    from profidrive_cli.fdl import frames as F
    srd = F.request_fc(F.SRD_HIGH, fcv=True)
    frames = [F.make(3, 2, srd, bytes.fromhex("88 01 01 0b fd 01 00"), 61, 62),      # Set_Prm 0xFD01
              F.make(3, 2, srd, bytes.fromhex("f3 f1"), 62, 62),                      # Chk_Cfg PPO1
              F.Frame(F.SD2, 3, 2, srd, bytes(12)), F.Frame(F.SD2, 2, 3, F.DL, bytes(12))]
    raw = tmp_path / "de.raw"
    raw.write_bytes(b"".join(F.encode(f) for f in frames))
    lines = lines_of(pdrive("sniff", "--from-file", str(raw), "--json"))
    assert assert_stream(lines, "sniff") == ["frame"] * 4
    assert lines[1]["decoded"]["layout"][0]["cfg"] == "f3 f1"
    assert [len(d["decoded"]["modules"]) for d in lines[2:]] == [1, 1]
    ext = TESTDATA.parent / "external" / "pyprofibus26-et200s-startup.raw"
    real = TESTDATA / "proview"
    if ext.exists() and real.is_dir():              # the real ET200S with its real GSD: prm rows
        lines = lines_of(pdrive("sniff", "--from-file", str(ext), "--gsd-dir", str(real), "--json"))
        assert len(assert_stream(lines, "sniff")) == 15
        assert any(d.get("decoded", {}).get("prm") for d in lines)


TESTDATA = Path(os.environ.get("PDRIVE_GSD_TESTDATA", ROOT.parent / "shared" / "testdata" / "gsd"))


@pytest.mark.skipif(not TESTDATA.is_dir(), reason="the real GSD test files are not present")
def test_gsd_show_of_real_files():
    files = sorted(p for p in TESTDATA.rglob("*") if p.suffix.lower() in (".gsd", ".gse", ".gsg"))
    for p in files:
        r = pdrive("gsd", "show", str(p), "--json")
        if r.returncode == 0:
            assert_contract(json.loads(r.stdout), "gsd show")
        else:
            assert_contract(json.loads(r.stdout), "error")


def test_sim_endpoint_on_a_pty():
    p = subprocess.Popen(pdrive_cmd() + ["sim", "--pty", "--json"], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, cwd=ROOT,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        d = json.loads(p.stdout.readline())
    finally:
        p.terminate()
        p.wait(timeout=10)
    assert_contract(d, "sim")
    assert [s["station"] for s in d["stations"]] == [3, 4, 5, 6, 7]


def test_sim_with_its_control_and_sim_ctl_state():
    p = subprocess.Popen(pdrive_cmd() + ["sim", "--pty", "--json", "--control", "127.0.0.1:0"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        d = json.loads(p.stdout.readline())
        assert_contract(d, "sim")
        assert d["control"].startswith("http://127.0.0.1:") and d["token"] is None
        r = pdrive("sim-ctl", "--control", d["control"].removeprefix("http://"), "state", "--json")
        assert r.returncode == 0, r.stderr
        state = json.loads(r.stdout)
        assert_contract(state, "sim-ctl state")
        assert [s["station"] for s in state["stations"]] == [3, 4, 5, 6, 7]
    finally:
        p.terminate()
        p.wait(timeout=10)


def test_scan_over_the_pty_simulator():
    with pty_sim_process() as port:
        d = one_doc(pdrive("scan", "--port", port, "--from", "3", "--to", "4", "--json"))
    assert_contract(d, "scan")
    assert [s["station"] for s in d["stations"]] == [3, 4]


CHECKLIST = """\
name: json contract
port: sim://
stations:
  - name: conveyor
    address: 3
    profile: fuji-g1
    layout: ppo1
snapshot: [F07]
steps:
  - expect_identity
  - read: {param: F03, expect: 60}
  - run: {hz: 5, direction: forward, duration: 0.2, tolerance: 60, within: 5}
  - stop: {within: 10}
"""


def test_checklist_validate_and_run(tmp_path):
    f = tmp_path / "c.yaml"
    f.write_text(CHECKLIST)
    d = one_doc(pdrive("checklist", "validate", str(f), "--json"))
    assert_contract(d, "checklist validate")
    assert (d["stations"][0]["station"], d["stations"][0]["ident_hex"]) == (3, "0xFD01")
    r = pdrive("checklist", "run", str(f), "--json", "--yes")
    d = json.loads(r.stdout)
    assert_contract(d, "checklist run")
    assert r.returncode == (0 if d["passed"] else 1)
    fs = d["stations"][0]["final_status"]
    assert isinstance(fs["flags"], list) and "actual_hz" in fs
    stop = next(s for s in d["stations"][0]["steps"] if s["type"] == "stop")["measured"]
    assert isinstance(stop["flags"], list) and "actual_hz" in stop and "speed_hz" not in stop


def test_checklist_report_file_is_the_same_contract(tmp_path):
    f = tmp_path / "c.yaml"
    f.write_text(CHECKLIST)
    rep = tmp_path / "r.json"
    pdrive("checklist", "run", str(f), "--yes", "--report", str(rep))
    assert_contract(json.loads(rep.read_text()), "checklist run")


def _raw_frames() -> bytes:
    from profidrive_cli.fdl import frames as F
    req = F.encode(F.Frame(F.SD1, 3, 2, F.request_fc(F.FDL_STATUS)))
    return req + bytes([0xE5]) + b"\x68\x05\x05\x68\x83\x82\x3c\x3e\x00\x00"   # SC, then a bad frame


def test_sniff_stream_from_a_file(tmp_path):
    raw = tmp_path / "cap.bin"
    raw.write_bytes(_raw_frames())
    lines = lines_of(pdrive("sniff", "--from-file", str(raw), "--json"))
    events = assert_stream(lines, "sniff")
    assert events[:2] == ["frame", "frame"] and "bad_frame" in events
    assert lines[0]["raw"] == _raw_frames()[:6].hex(" ")


def test_sniff_decoded_objects(tmp_path):
    """Issue 26: the `decoded` object of every DU kind sniff decodes, against the contract; one
    Slave_Diag with every extended-diagnosis block kind (identifier, channel, device as vendor data,
    DP-V1 alarm, DP-V1 Module_Status with bad modules, reserved)."""
    from profidrive_cli.dp import services as S
    from profidrive_cli.fdl import frames as F
    srd = F.request_fc(F.SRD_HIGH, fcv=True)
    dl = F.response_fc(0x08)
    diag = bytes.fromhex("08 0c 00 02 12 34 44 00 01 00 88 41 21 04 10 20 30 06 04 05 0d aa bb"
                         " 06 82 00 01 e4 00 c0")
    frames = [
        F.make(5, 2, srd, bytes.fromhex("b8 1e 01 00 80 6a 01 c4 01 00 11 21"), 61, 62),   # Set_Prm, DP-V1
        F.make(5, 2, srd, bytes.fromhex("88 01 01 0b 00 0b 00 00 0a 00"), 61, 62),         # not DP-V1
        F.make(5, 2, srd, bytes.fromhex("00 10 20"), 62, 62),                               # Chk_Cfg
        F.make(2, 5, dl, diag, 62, 60),                                                      # Slave_Diag reply
        F.make(127, 2, F.request_fc(F.SDN_HIGH), bytes((S.GC_CLEAR, 0)), 58, 62),          # Global_Control
    ]
    raw = tmp_path / "dus.raw"
    raw.write_bytes(b"".join(F.encode(f) for f in frames))
    lines = lines_of(pdrive("sniff", "--from-file", str(raw), "--json"))
    assert assert_stream(lines, "sniff") == ["frame"] * 5
    assert all("decoded" in d for d in lines)
    kinds = [b["kind"] for b in lines[3]["decoded"]["blocks"]]
    assert kinds == ["identifier", "channel", "device", "device", "device", "reserved"]
    ext = TESTDATA.parent / "external" / "pyprofibus26-et200s-startup.raw"
    if ext.exists():                                # the real ET200S start-up (../shared)
        assert len(assert_stream(lines_of(pdrive("sniff", "--from-file", str(ext), "--json")), "sniff")) == 15


def test_sniff_dpv1_decoded_objects(tmp_path):
    """Issue 39: the `decoded.msac` and `decoded.ds47` objects of DP-V1 acyclic telegrams (a DS47
    read as a master runs it, a negative answer, a change request, an Alarm_Ack, a class-2 Initiate,
    a negative parameter response, a malformed PDU and record: tests/test_sniff_dpv1.py's octets)
    against the contract."""
    from test_sniff_dpv1 import BAD_LENGTH, CAPTURE, READ_RES_NEGATIVE, SHORT_RECORD, WRITE_964
    extra = [WRITE_964, READ_RES_NEGATIVE, BAD_LENGTH, SHORT_RECORD]
    raw = tmp_path / "dpv1.raw"
    raw.write_bytes(b"".join(CAPTURE + extra))
    lines = lines_of(pdrive("sniff", "--from-file", str(raw), "--json"))
    assert assert_stream(lines, "sniff") == ["frame"] * (len(CAPTURE) + len(extra))
    assert all("msac" in d["decoded"] for d in lines)
    assert sum("ds47" in d["decoded"] for d in lines) == 6


# ---------------------------------------------------------------------------------------------
# the commands merged with their own JSON: scan --watch, commloss-test, run 3,4,5, sniff --station /
# --live, sim --plc, config show / path, wireshark install, the bus_health and comm_loss steps
# ---------------------------------------------------------------------------------------------

VIRTUAL = ("--port", "sim://?timing=virtual")


def test_scan_watch_stream():
    lines = lines_of(pdrive("scan", *SIM, "--to", "8", "--watch", "--duration", "0.3", "--interval",
                            "0.1", "--json"))
    events = assert_stream(lines, "scan watch")
    assert events[0] == "watch" and events[-1] == "end" and set(events[:-1]) == {"watch"}
    s3 = lines[-1]["stations"][0]
    # the OPC-G1-PDP's ident (FUJIFD01.GSD); never parameterised: Prm_Req -> "waiting"
    assert (s3["station"], s3["ident"], s3["ident_hex"], s3["category"]) == (3, 0xFD01, "0xFD01", "waiting")
    assert lines[-1]["t_s"] >= 0.3


def test_commloss_stream_silence():
    lines = lines_of(pdrive("commloss-test", "3", "--hz", "5", *VIRTUAL, "--json"))
    events = assert_stream(lines, "commloss-test")
    assert events == ["start", "reaction", "started", "at_speed", "silence", "back", "result"]
    start, res = lines[0], lines[-1]
    assert (start["station"], start["ident"], start["ident_hex"]) == (3, 0xFD01, "0xFD01")
    assert start["watchdog_s"] == 0.5                   # --watchdog default 500 ms
    # o27 = 0 (the factory setting, fuji-opc-g1-pdp.md): coast to a stop at once and trip Er5
    assert res["reaction"]["stop"] == "trip" and res["reaction"]["alarm"] == "Er5"
    assert res["watchdog_s"] == 0.5 and res["passed"] is True
    assert "duration_s" in res["stop"]


def test_commloss_stream_clear():
    lines = lines_of(pdrive("commloss-test", "7", "--hz", "5", "--mode", "clear", *VIRTUAL, "--json"))
    events = assert_stream(lines, "commloss-test")
    assert events == ["start", "reaction", "started", "at_speed", "clear", "result"]
    assert lines[-1]["watchdog_expired"] is None and lines[-1]["hold_s"] == 0.0


def test_run_several_stations_stream():
    lines = lines_of(pdrive("run", "3,6", "--hz", "5", "--duration", "3", *VIRTUAL, "--json"))
    events = assert_stream(lines, "run multi")
    assert events[0] == "start" and events[-1] == "end"
    assert {d["station"] for d in lines if d["event"] == "update"} == {3, 6}
    start, end = lines[0], lines[-1]
    assert [(s["station"], s["ident_hex"]) for s in start["stations"]] == [(3, "0xFD01"), (6, "0xFD06")]
    assert start["watchdog_s"] == 0.5
    # 5 Hz of F03 = 60 Hz (Fuji) and of A004 = 50 Hz (Moeller)
    assert [s["reference_percent"] for s in start["stations"]] == [pytest.approx(8.3333), 10.0]
    assert all(s["stop"]["how"] == "normal" and s["stop"]["duration_s"] >= 0 for s in end["stations"])
    assert end["failed"] is False


def _moeller_capture(tmp_path) -> Path:
    from profidrive_cli.fdl import frames as F

    def req(data, fcb=True, fcv=True, dsap=None, ssap=None):
        return F.encode(F.Frame(F.SD2, 6, 2, F.request_fc(F.SRD_HIGH, fcb, fcv), bytes(data), dsap, ssap))
    prm = bytes([0x88, 1, 1, 11, 0xFD, 0x06, 0])
    raw = (req(prm, fcv=False, dsap=61, ssap=62) + F.encode(F.Frame(F.SC))
           + req(b"\xF3\xF1", fcb=False, dsap=62, ssap=62) + F.encode(F.Frame(F.SC))
           # moeller-de6-net-dp.md example 1: write F002 = 4.00 s, STW 0x047F, HSW 0x2000 (50 %)
           + req(bytes.fromhex("30 17 00 00 00 00 01 90 04 7F 20 00"))
           + F.encode(F.Frame(F.SD2, 2, 6, F.DL, bytes.fromhex("20 17 00 00 00 00 01 90 03 37 20 00"))))
    f = tmp_path / "cap.raw"
    f.write_bytes(raw)
    return f


def test_sniff_station_drive_object(tmp_path):
    f = _moeller_capture(tmp_path)
    lines = lines_of(pdrive("sniff", "--from-file", str(f), "--station", "6=moeller", "--json"))
    assert assert_stream(lines, "sniff") == ["frame"] * 6
    req, rep = lines[4]["drive"], lines[5]["drive"]
    assert_contract(req, "sniff drive")
    assert_contract(rep, "sniff drive")
    # STW 0x047F: bits 0-6 and 10 set (8 names); ZSW 0x0337: S4 operation
    assert req["control_word"] == "0x047F" and len(req["flags"]) == 8 and req["flags"][0] == "ON"
    assert (rep["status_word"], rep["state"]) == ("0x0337", "S4 operation")
    assert "operation enabled" in rep["flags"]
    # HSW 0x2000 = 50 % of A004 = 50 Hz
    assert (req["reference_hz"], rep["actual_hz"]) == (25.0, 25.0)


def test_sniff_live_events(tmp_path):
    f = _moeller_capture(tmp_path)
    lines = lines_of(pdrive("sniff", "--from-file", str(f), "--station", "6=moeller", "--live", "--json"))
    assert assert_stream(lines, "sniff") == ["live"]
    (live,) = lines
    assert live["final"] is True and live["masters"] == [2]
    (s6,) = live["stations"]
    assert (s6["station"], s6["ident_hex"], s6["state"]) == (6, "0xFD06", "data exchange")
    assert s6["drive"]["request"]["flags"][0] == "ON"
    # one Data_Exchange heard: no cycle measured yet
    assert (s6["cycle_min_s"], s6["cycles_measured"]) == (None, 0)


def test_sniff_live_refresh_events_on_a_port():
    lines = lines_of(pdrive("sniff", *SIM, "--live", "--duration", "0.7", "--json"))
    assert_stream(lines, "sniff")
    assert [d["final"] for d in lines][-1] is True and False in [d["final"] for d in lines]


def test_sim_plc_endpoint_on_a_pty():
    p = subprocess.Popen(pdrive_cmd() + ["sim", "--plc", "--pty", "--json"], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, cwd=ROOT,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        d = json.loads(p.stdout.readline())
    finally:
        p.terminate()
        p.wait(timeout=10)
    assert_contract(d, "sim")
    assert d["plc"] is True


CONFIG = """\
baud: 93750
ports:
  rig: 'sim://?timing=virtual'
  line1:
    port: 'sim://?timing=virtual'
    baud: 187500
    master_address: 1
    stations:
      3: {layout: ppo3, fmax: 50}
"""


def test_config_show_and_path(tmp_path):
    f = tmp_path / "pdrive.yaml"
    f.write_text(CONFIG)
    env = {"PDRIVE_CONFIG": str(f)}
    d = _with_env(env, "config", "show", "--port", "line1", "--json")
    assert_contract(d, "config show")
    assert d["port"]["name"] == "line1" and [p["name"] for p in d["ports"]] == ["rig", "line1"]
    assert d["stations"][0]["station"] == 3 and d["stations"][0]["layout"]["value"] == "ppo3"
    assert_contract(_with_env(env, "config", "path", "--json"), "config path")


def _with_env(extra: dict, *args):
    env = {**os.environ, "PYTHONPATH": str(ROOT), **extra}
    env.pop("PDRIVE_PORT", None)
    r = subprocess.run(pdrive_cmd() + list(args), capture_output=True, text=True, timeout=60, cwd=ROOT,
                       env=env)
    return one_doc(r)


def test_wireshark_install(tmp_path):
    d = one_doc(pdrive("wireshark", "install", "--dir", str(tmp_path), "--station",
                       "6=moeller:ppo1", "--json"))
    assert_contract(d, "wireshark install")
    assert d["stations"] == [{"station": 6, "profile": "moeller-de6-net-dp", "layout": "ppo1"}]
    assert [Path(x).name for x in d["files"]] == ["pdrive.lua", "pdrive_stations.lua"]


CHECKLIST_STEPS = """\
name: measured
port: 'sim://?timing=virtual'
stations:
  - name: conveyor
    address: 3
    profile: fuji-g1
    layout: ppo1
steps:
  - bus_health: {seconds: 0.5}
  - comm_loss: {hz: 5}
"""


def test_checklist_measured_of_bus_health_and_comm_loss(tmp_path):
    f = tmp_path / "c.yaml"
    f.write_text(CHECKLIST_STEPS)
    d = one_doc(pdrive("checklist", "run", str(f), "--json", "--yes"))
    assert_contract(d, "checklist run")
    bh, cl = d["stations"][0]["steps"]
    assert_contract(bh["measured"], "checklist measured bus_health")
    assert bh["measured"]["duration_s"] == 0.5 and "seconds" not in bh["measured"]
    assert_contract({"event": "result", **cl["measured"]}, "commloss-test event=result")
    assert cl["expected"]["watchdog_s"] == 0.5 and "watchdog_ms" not in cl["expected"]


# =============================================================================================
# errors: a JSON object under --json, the same exit code as the text
# =============================================================================================


ERRORS = [
    # (arguments, exit code): a usage error and a bus/station error for each command
    (("scan", "--bogus", *SIM), 2),
    (("scan", "--from", "9", "--to", "3", *SIM), 2),
    (("scan", "--port", "/dev/pdrive-no-such-port"), 1),
    (("diag", "200", *SIM), 2),
    (("diag", "50", *SIM), 1),
    (("io", "3", *SIM), 2),
    (("io", "50", "--cfg", "f3", *SIM), 1),
    (("status", "50", *SIM), 1),
    (("status", "3", "--ppo", "9", *SIM), 2),
    (("param", "get", "3", "NOPE", *SIM), 2),
    (("param", "get", "50", "F07", *SIM), 1),
    (("param", "set", "3", "F07", "abc", *SIM), 2),
    (("param", "dump", "50", "-o", "/tmp/pdrive-json-contract-never.yaml", *SIM), 1),
    (("param", "diff", "3", "/nonexistent/d.yaml", *SIM), 2),
    (("faults", "50", *SIM), 1),
    (("run", "3", *SIM), 2),
    (("run", "50", "--hz", "5", *SIM), 1),
    (("jog", "3", "--duration", "0.2", *SIM), 2),
    (("jog", "50", "--duration", "0.2", *SIM), 1),
    (("doctor", "--port", "sim://", "--baud", "auto"), 2),
    (("decode", "moeller", "--request", "00"), 2),
    (("gsd", "show", "0x1234"), 2),
    (("gsd", "prm", "0xFD01", "-m", "99"), 2),
    (("sim", "--pty", "--listen", "127.0.0.1:0"), 2),
    (("sniff", "--duration", "0", *SIM), 2),
    (("sniff", "--port", "/dev/pdrive-no-such-port", "--duration", "0.1"), 1),
    (("checklist", "validate", "/nonexistent/c.yaml"), 2),
    (("checklist", "run", "/nonexistent/c.yaml", *SIM), 2),
    (("scan", "--watch", "--interval", "0", *SIM), 2),
    (("scan", "--watch", "--duration", "0.2", "--port", "/dev/pdrive-no-such-port"), 1),
    (("commloss-test", "3", "--hz", "nan", *SIM), 2),
    (("commloss-test", "50", "--hz", "5", *SIM), 1),
    (("run", "3,6", *SIM), 2),
    (("run", "3,50", "--hz", "5", *SIM), 1),
    (("sniff", "--live", "--station", "6=nosuchprofile", *SIM), 2),
    (("config", "show", "--master-address", "200"), 2),
    (("wireshark", "install", "--station", "6=nosuchprofile"), 2),
]


@pytest.mark.parametrize("args,code", ERRORS, ids=[" ".join(a[:3]) for a, _ in ERRORS])
def test_error_is_json_with_the_text_exit_code(args, code):
    text = pdrive(*args)
    js = pdrive(*args, "--json")
    assert text.returncode == js.returncode == code, (text.stderr, js.stderr)
    out = [json.loads(x) for x in js.stdout.splitlines() if x.strip()]
    err = out[-1]
    assert_contract(err, "error")
    assert err["exit_code"] == code
    # the same one line on stderr as without --json
    assert js.stderr.strip().splitlines()[-1] == text.stderr.strip().splitlines()[-1] == f"pdrive: {err['error']}"
    stream = args[0] in ("io", "run", "jog", "sniff", "commloss-test") or args[:2] == ("scan", "--watch")
    assert (err.get("event") == "error") == stream
    if not stream:
        assert len(out) == 1                           # one document on stdout


@pytest.mark.parametrize("as_json", [False, True])
def test_os_error_last_defence_is_json_too(monkeypatch, capsys, as_json):
    """An OSError no place turned into its own message: one line, exit 1, and the error object."""
    import errno
    from profidrive_cli.cli.main import main
    from profidrive_cli.dp import scan as scan_mod

    def broken(*a, **kw):
        raise OSError(errno.EIO, "Input/output error", "/dev/ttyUSB9")
    monkeypatch.setattr(scan_mod, "scan", broken)
    with pytest.raises(SystemExit) as e:
        main(["scan", "--port", "sim://"] + (["--json"] if as_json else []))
    assert e.value.code == 1
    out, err = capsys.readouterr()
    assert err.strip() == "pdrive: /dev/ttyUSB9: Input/output error"
    if as_json:
        d = json.loads(out)
        assert_contract(d, "error")
        assert d == {"error": "/dev/ttyUSB9: Input/output error", "exit_code": 1}
    else:
        assert out == ""


def test_bad_checklist_error_lists_the_problems(tmp_path):
    f = tmp_path / "c.yaml"
    f.write_text(CHECKLIST.replace("read: {param: F03, expect: 60}", "read: {param: NOPE}"))
    text, js = pdrive("checklist", "validate", str(f)), pdrive("checklist", "validate", str(f), "--json")
    assert text.returncode == js.returncode == 2
    d = json.loads(js.stdout)
    assert_contract(d, "error")
    assert d["problems"] and all(str(f) in p for p in d["problems"])   # file:line each


def test_text_output_has_no_json():
    r = pdrive("diag", "50", *SIM)
    assert r.stdout == "" and r.returncode == 1


if __name__ == "__main__":                              # pragma: no cover
    sys.exit(pytest.main([__file__]))
