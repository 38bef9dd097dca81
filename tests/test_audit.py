"""pdrive audit (issue 28): each family's rules (Drive.audit_rules, drives/<family> audit modules) run
by session/audit.py over a connected drive, through api Drive.audit / Bus.audit and the command.

Expected values come from the card manuals (../shared/seeds/, lines quoted at each case), never
from the code under test. The simulated plant (sim://): 3 fuji-g1, 4 fuji-pdp3, 5 toyo, 6 moeller,
7 yaskawa."""

from __future__ import annotations

import json
import os
import re
import subprocess
from pathlib import Path

import pytest

import profidrive_cli as pdrive
from conftest import pdrive_cmd
from profidrive_cli.drives import drive_class
from profidrive_cli.drives.audit import TOPICS
from profidrive_cli.drives.profile import load_profile

ROOT = Path(__file__).resolve().parent.parent
PROFILES = ("fuji-opc-g1-pdp", "fuji-opc-pdp3", "moeller-de6-net-dp", "toyo-pbus66z", "yaskawa-si-p1")


def pdrive_run(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    env.pop("PDRIVE_PORT", None)
    return subprocess.run(pdrive_cmd() + list(args), capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT, env=env)


def audit(url: str, station: int, **kw):
    with pdrive.open_bus(url) as bus:
        (res,) = bus.audit([station], **kw)
    return res


# -- the rules are class facts of each family ----------------------------------------------------

@pytest.mark.parametrize("name", PROFILES)
def test_every_topic_has_a_rule_or_a_reason_and_every_rule_cites_a_manual_line(name):
    prof = load_profile(name)
    rules = drive_class(prof).audit_rules(prof)
    assert {r.topic for r in rules} == set(TOPICS)
    for r in rules:
        assert re.search(r"\bL\d+", r.manual), (r.id, r.manual)        # a manual line
        assert (r.run is None) == bool(r.not_applicable), r.id
    ids = [r.id for r in rules]
    assert len(ids) == len(set(ids)), ids


# -- the done-when of the issue --------------------------------------------------------------------

def test_moeller_p002_keep_running_exits_1_naming_p002_and_why():
    # Moeller DE6-NET-DP manual L361-363: "P001/P002 ... 1  Continue operation according to the
    # last received command" (no trip): the classic commissioning accident
    r = pdrive_run("audit", "6", "--port", "sim://?set=6:P002=1")
    assert r.returncode == 1, r.stderr
    assert "P002 = 1" in r.stdout
    assert "ERROR" in r.stdout and "keep running on the last command" in r.stdout
    assert "L357-363" in r.stdout                          # the manual's line with the fix
    assert "set P002 = 0" in r.stdout


def test_the_factory_plant_exits_0_with_only_explained_warnings():
    r = pdrive_run("audit", "--port", "sim://", "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["errors"] == 0
    assert [s["station"] for s in doc["stations"]] == [3, 4, 5, 6, 7]      # every drive station
    for s in doc["stations"]:
        for f in s["findings"]:
            assert f["severity"] == "warning", f
            assert f["why"] and f["fix"] and re.search(r"\bL\d+", f["manual"]), f


# -- one error per family on sim:// with set= ------------------------------------------------------

@pytest.mark.parametrize("station,preset,rule,code", [
    # OPC-G1-PDP manual L2760-2778 Table 9.1: o27 = 3, 13-15 "Keep the current operation,
    # ignoring the communications error (No er5)"
    (3, "o27=3", "comm_loss.keeps_running", "o27"),
    # OPC-PDP3 manual L6508-6516: the same for 13 to 15
    (4, "o27=13", "comm_loss.keeps_running", "o27"),
    # PBUS66-Z manual L2834-2842, ZSW bit 9: 0 = local operation (the VF66's run and speed
    # commands not from the communication option: b-11, b-10, L423-617)
    (5, "b-11=1,b-10=1", "source.control_requested", "ZSW bit 9"),
    # DE6-NET-DP manual L361-363: P002 = 1 continues on the last command
    (6, "P002=1", "comm_loss.keeps_running", "P002"),
    # F6-01 = 3 "alarm only (keeps running)" (the F7's parameter; SI-P1 manual L341 BUS fault)
    (7, "F6-01=3", "comm_loss.keeps_running", "F6-01"),
    # OPC-G1-PDP manual L1846-1869, L2987: y98 must be 3 for run and frequency from PROFIBUS; 0 gives
    # the bus neither (1 and 2, one of the two, are split control: test_audit_manuals.py)
    (3, "y98=0", "source.y98", "y98"),
    # DE6-NET-DP manual L294-307: A001 = 2 (operator) for the bus reference; with A002 not 1 either
    # the card "has no control"
    (6, "A001=1,A002=2", "source.frequency", "A001"),
    # SI-P1 manual L274-282 Table 1.6: b1-02 = 3 (option PCB) for the run command; b1-01 = 1 too:
    # nothing from the bus
    (7, "b1-02=1,b1-01=1", "source.run", "b1-02"),
    # deceleration time 0 s (F08: OPC-G1-PDP manual L2756)
    (3, "F08=0", "ramps.deceleration_zero", "F08"),
])
def test_an_error_for_each_family(station, preset, rule, code):
    res = audit(f"sim://?timing=virtual&set={station}:{preset}", station)
    errors = [(f.rule, f.code) for f in res.findings if f.severity == "error"]
    assert (rule, code) in errors, res.findings
    assert res.errors == len(errors) >= 1


def test_the_same_drives_on_the_factory_plant_have_none_of_those_errors():
    with pdrive.open_bus("sim://?timing=virtual") as bus:
        results = bus.audit([3, 4, 5, 6, 7])
    assert [r.errors for r in results] == [0, 0, 0, 0, 0]
    # the rules ran (not skipped): Fuji o27, Moeller P002, Yaskawa F6-01, Toyo protection 18
    assert all("comm_loss.reaction" in r.checked for r in results)
    assert "source.control_requested" in results[2].checked


def test_pdp3_volatile_save_mode_is_a_warning_with_the_fix():
    # OPC-PDP3 manual L4325-4333 (*6): y97 = 1 writes to volatile memory, "data is deleted when the
    # power is turned OFF"; 0 (factory) saves to non-volatile memory
    res = audit("sim://?timing=virtual&set=4:y97=1", 4)
    (f,) = [f for f in res.findings if f.rule == "save_mode.volatile"]
    assert (f.severity, f.code, f.check) == ("warning", "y97", {"param": "y97", "expect": 0})
    # the OPC-G1-PDP manual documents no y97: not applicable, with the reason
    g1 = audit("sim://?timing=virtual", 3)
    assert [s.topic for s in g1.not_applicable].count("save_mode") == 1


def test_a_comm_loss_delay_against_the_process_limit():
    # OPC-PDP3 Table 9.1 (L6478-6559): o27 = 11 decelerates after the o28 time. Watchdog 0.5 s +
    # o28 2.5 s = 3.0 s on the last command: above a 1 s limit an error, without a limit a warning
    url = "sim://?timing=virtual&set=4:o27=11,o28=2.5"
    res = audit(url, 4, max_reaction_s=1.0)
    (f,) = [f for f in res.findings if f.rule == "comm_loss.delay"]
    assert f.severity == "error" and "3 s" in f.why and "2.5" in f.value
    # the fix: o28 at most 1.0 - 0.5 = 0.5 s (o28 in 0.1 s steps: OPC-PDP3 Table 5.1, 0.0-60.0 s)
    assert f.check == {"param": "o28", "max": 0.5}
    res = audit(url, 4)
    (f,) = [f for f in res.findings if f.rule == "comm_loss.delay"]
    assert f.severity == "warning"
    # 3.0 s within 3.5 s (the o32 = 0 warning, Table 10.1, is another rule's)
    assert [f for f in audit(url, 4, max_reaction_s=3.5).findings if f.rule == "comm_loss.delay"] == []


def test_the_watchdog_against_the_masters_cycle():
    # hand calculation: watchdog 500 ms; a 400 ms cycle leaves less than 3 cycles (1200 ms): a
    # warning; a 600 ms cycle is longer than the watchdog itself: an error; 100 ms: 5 cycles, fine
    with pdrive.open_bus("sim://?timing=virtual") as bus:
        d = bus.drive(6, watchdog_ms=500)       # the hand calculation's (the API default: 1000)
        assert [f.severity for f in d.audit(cycle_s=0.4).findings if f.code == "watchdog"] == ["warning"]
        assert [f.severity for f in d.audit(cycle_s=0.6).findings if f.code == "watchdog"] == ["error"]
        assert [f for f in d.audit(cycle_s=0.1).findings if f.code == "watchdog"] == []


def test_a_layout_without_a_parameter_channel_says_what_it_could_not_check():
    res = audit("sim://?timing=virtual&set=6:P002=1", 6, ppo=3)        # PPO3: no PKW
    assert res.errors == 0
    assert {"comm_loss.reaction", "source.frequency"} <= {s.rule for s in res.not_checked}
    assert all("no parameter channel" in s.reason for s in res.not_checked)


def test_the_audit_writes_nothing_and_leaves_the_drive_stopped():
    with pdrive.open_bus("sim://?timing=virtual&set=5:b-11=1,b-10=1") as bus:
        d = bus.drive(5)
        d.audit()
        st = d.status()
        assert not st.running and not st.fault
    with pdrive.open_bus("sim://?timing=virtual&set=6:P002=1") as bus:
        d = bus.drive(6)
        d.audit()
        assert d.param("P002").value == 1


# -- the command: JSON, checklist, bad input -------------------------------------------------------

def test_json_and_a_checklist_that_validates(tmp_path):
    path = tmp_path / "fix.yaml"
    r = pdrive_run("audit", "6", "7", "--port", "sim://?set=6:P002=1&set=7:F6-01=3", "--json",
                   "--checklist", str(path))
    assert r.returncode == 1, r.stderr
    doc = json.loads(r.stdout)
    assert doc["errors"] == 2 and doc["checklist"] == str(path)
    assert [f["code"] for s in doc["stations"] for f in s["findings"] if f["severity"] == "error"] \
        == ["P002", "F6-01"]
    text = path.read_text(encoding="utf-8")
    assert "param: P002" in text and "expect: 0" in text and "comm_loss:" in text
    v = pdrive_run("checklist", "validate", str(path))
    assert v.returncode == 0, v.stdout + v.stderr


def test_the_checklist_fails_until_fixed_and_passes_after(tmp_path):
    # the read steps of the written checklist fail on the drive as audited and pass on a fixed one
    path = tmp_path / "fix.yaml"
    pdrive_run("audit", "6", "--port", "sim://?set=6:P002=1", "--checklist", str(path))
    import yaml
    doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    doc["steps"] = [s for s in doc["steps"] if isinstance(s, dict) and "read" in s]
    doc.pop("port")
    only_reads = tmp_path / "reads.yaml"
    only_reads.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    bad = pdrive_run("checklist", "run", str(only_reads), "--port", "sim://?set=6:P002=1", "--yes")
    # fixed: P002 = 0 (the factory plant's)
    good = pdrive_run("checklist", "run", str(only_reads), "--port", "sim://", "--yes")
    assert bad.returncode == 1, bad.stdout + bad.stderr
    assert good.returncode == 0, good.stdout + good.stderr


@pytest.mark.parametrize("args,text", [
    (("--max-reaction", "-1"), "--max-reaction must be a number above 0"),
    (("--cycle-ms", "nan"), "--cycle-ms must be a number above 0"),
    (("200",), "200"),
])
def test_bad_input_is_one_line_and_exit_2(args, text):
    r = pdrive_run("audit", *args, "--port", "sim://")
    assert r.returncode == 2, r.stderr
    assert text in r.stderr and len(r.stderr.strip().splitlines()) == 1 and r.stdout == ""


def test_a_checklist_path_that_cannot_be_written_is_refused_before_the_bus(tmp_path):
    target = tmp_path / "no-such-dir" / "fix.yaml"
    r = pdrive_run("audit", "6", "--port", "sim://", "--checklist", str(target))
    assert r.returncode == 2 and "no-such-dir" in r.stderr
    assert not target.parent.exists()


def test_a_bus_without_drives_is_exit_1():
    r = pdrive_run("audit", "--port", "sim://?stations=")
    assert r.returncode == 1, r.stdout + r.stderr
    assert "no drive station found" in r.stderr
