"""pdrive checklist through click: every example on sim:// with all three reports, a failing checklist
(measured value in the reports, drive left stopped), a broken one (file:line, exit 2, nothing written),
SIGTERM during a run, --dry-run, prompts without a terminal."""

import json
import os
import select
import signal
import subprocess
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from click.testing import CliRunner

from conftest import pdrive_cmd, pty_sim_process
from profidrive_cli.cli.main import cli

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples" / "checklists"

# fast ramps and short holds for the tests (the examples' own values are realistic: seconds each)
FAST = {
    "fuji-g1": ["accel_s=1", "decel_s=1", "hold_s=0.2"],
    "fuji-pdp3": ["accel_s=1", "decel_s=1", "hold_s=0.2"],
    "moeller": ["accel_s=1", "decel_s=1", "hold_s=0.2"],
    "yaskawa": ["accel_s=1", "decel_s=1", "hold_s=0.2"],
    "toyo": ["hold_s=0.2"],
}


def run(*args, env=None):
    return CliRunner().invoke(cli, [str(a) for a in args], env=env or {"PDRIVE_PORT": ""})


def var_args(items):
    out = []
    for v in items:
        out += ["--var", v]
    return out


@pytest.mark.parametrize("stem", sorted(FAST))
def test_example_passes_on_sim_and_writes_three_reports(stem, tmp_path):
    js, md, xml = tmp_path / "r.json", tmp_path / "r.md", tmp_path / "r.xml"
    r = run("checklist", "run", EX / f"{stem}.yaml", "--yes", "--cycle-hz", "200", *var_args(FAST[stem]),
            "--report", js, "--report", md, "--report", xml)
    assert r.exit_code == 0, r.output + r.stderr
    doc = json.loads(js.read_text())
    assert doc["status"] == "passed" and doc["passed"] is True and doc["port"] == "sim://"
    st = doc["stations"][0]
    steps = st["steps"]
    assert steps and all(s["status"] == "passed" for s in steps)
    assert st["identity"]["ident"] == st["expected_identity"]["ident"]
    assert st["final_status"]["stopped"] is True
    assert st["snapshot_before"] and set(st["snapshot_before"]) == set(st["snapshot_after"])
    runs = [s for s in steps if s["type"] == "run"]
    assert [round(s["measured"]["actual_hz"]) for s in runs] == [10, -10]
    assert all(s["started"] and s["finished"] for s in steps)
    # JUnit: one test case per step, none failed
    root = ET.parse(xml).getroot()
    cases = root.findall("./testsuite/testcase")
    assert len(cases) == len(steps) and root.get("failures") == "0" and root.get("errors") == "0"
    assert not root.findall(".//failure") and not root.findall(".//error")
    props = {p.get("name"): p.get("value") for p in root.findall("./testsuite/properties/property")}
    assert props["identity.ident"] == st["identity"]["ident_hex"]
    # Markdown mentions every step
    text = md.read_text()
    assert "**PASSED**" in text
    for s in steps:
        assert s["title"].replace("|", "\\|") in text


def test_dry_run_rehearses_on_a_simulated_station_of_the_same_profile(tmp_path):
    src = (EX / "moeller.yaml").read_text().replace("port: sim://", "port: /dev/ttyNOPE")
    # the plant's station sits at another address and has the vendor's ident
    src = src.replace("    address: 6\n", "    address: 21\n    ident: 0x0A55\n")
    f = tmp_path / "plant.yaml"
    f.write_text(src)
    js = tmp_path / "dry.json"
    r = run("checklist", "run", f, "--dry-run", "--cycle-hz", "200", *var_args(FAST["moeller"]), "--report", js)
    assert r.exit_code == 0, r.output + r.stderr
    doc = json.loads(js.read_text())
    assert doc["dry_run"] is True and doc["port"] == "sim://?stations=21:moeller-de6-net-dp"
    ident_step = doc["stations"][0]["steps"][0]
    assert ident_step["status"] == "passed" and "dry run" in ident_step["message"]
    prompt = next(s for s in doc["stations"][0]["steps"] if s["type"] == "prompt")
    assert prompt["measured"]["by"] == "dry run"


def test_prompts_without_a_terminal_need_yes(tmp_path):
    r = run("checklist", "run", EX / "toyo.yaml", "--report", tmp_path / "r.json")
    assert r.exit_code == 2
    assert "toyo.yaml:" in r.stderr and "--yes" in r.stderr
    assert not (tmp_path / "r.json").exists()


def test_report_extension_is_checked_before_anything_runs(tmp_path):
    r = run("checklist", "run", EX / "fuji-g1.yaml", "--yes", "--report", tmp_path / "r.pdf")
    assert r.exit_code == 2 and ".json, .md, .xml or .html" in r.stderr


def test_validate_prints_the_plan_and_lists_every_problem(tmp_path):
    r = run("checklist", "validate", EX / "yaskawa.yaml")
    assert r.exit_code == 0 and "is valid" in r.output and "C1-01" in r.output
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: b\nstations:\n  - {address: 7, profile: yaskawa}\nsteps:\n"
                   "  - write: {param: C1-01, value: 9000}\n  - explode\n")
    r = run("checklist", "validate", bad)
    assert r.exit_code == 2
    assert f"{bad}:5: step 1 (write): C1-01 (Acceleration time 1): 9000 s is outside 0..6000 s" in r.stderr
    assert f"{bad}:6: step 2: unknown step type 'explode'" in r.stderr


# =============================================================================================
# through `pdrive sim --pty`: the drive's state outlives the checklist run
# =============================================================================================


@pytest.fixture
def pty_sim():
    with pty_sim_process("--plant", "sim://?stations=3:fuji-g1") as port:
        yield port


def status_of(port):
    r = run("status", "3", "--port", port, "--json")
    assert r.exit_code == 0, r.output + r.stderr
    return json.loads(r.output)


def param_of(port, code):
    r = run("param", "get", "3", code, "--port", port, "--json")
    assert r.exit_code == 0, r.output + r.stderr
    return json.loads(r.output)["parameters"][0]["value"]


FAILING = """\
name: deliberately wrong
stations:
  - {name: c1, address: 3, profile: fuji-g1}
steps:
  - write: {param: F07, value: 0.5}
  - write: {param: F08, value: 0.5}
  - run: {hz: 10, duration: 0.3}
  - read: {param: F07, expect: 5.0}
    name: wrong expectation
  - stop
  - faults: none
"""


def test_wrong_expectation_fails_at_that_step_and_the_drive_is_left_stopped(pty_sim, tmp_path):
    f = tmp_path / "wrong.yaml"
    f.write_text(FAILING)
    js, md, xml = tmp_path / "r.json", tmp_path / "r.md", tmp_path / "r.xml"
    r = run("checklist", "run", f, "--port", pty_sim, "--yes", "--report", js, "--report", md, "--report", xml)
    assert r.exit_code == 1, r.output + r.stderr
    assert f"step 4 ({f}:8): F07 = 0.5 s, expected 5 s" in r.output
    doc = json.loads(js.read_text())
    steps = doc["stations"][0]["steps"]
    assert [s["status"] for s in steps] == ["passed", "passed", "passed", "failed", "not run", "not run"]
    assert steps[3]["measured"]["value"] == 0.5 and steps[3]["expected"]["value"] == 5.0
    assert doc["stations"][0]["final_status"]["stopped"] is True
    fail = ET.parse(xml).getroot().find(".//testcase/failure")
    assert fail is not None and "F07 = 0.5 s" in fail.get("message") and '"value": 0.5' in fail.text
    assert "| 4 | wrong expectation" in md.read_text() and "value: 0.5" in md.read_text()
    # a separate pdrive process-level look at the drive: stopped, not turning
    st = status_of(pty_sim)
    assert st["running"] is False and st["stopped"] is True and st["actual_hz"] == 0.0


def test_broken_checklist_gives_file_line_exit_2_and_writes_nothing(pty_sim, tmp_path):
    good = FAILING.replace("expect: 5.0", "expect: 0.5")
    broken = good.replace("  - stop\n", "  - stop\n  - write: {param: F07, valeu: 2}\n")
    f = tmp_path / "broken.yaml"
    f.write_text(broken)
    r = run("checklist", "run", f, "--port", pty_sim, "--yes", "--report", tmp_path / "r.json")
    assert r.exit_code == 2
    assert f"{f}:11: step 6 (write): unknown field 'valeu' (did you mean value?)" in r.stderr
    assert not (tmp_path / "r.json").exists()
    assert param_of(pty_sim, "F07") == 6.0 and param_of(pty_sim, "F08") == 6.0      # factory values
    # the same checklist without the broken step does write (so the check above can fail)
    f.write_text(good)
    r = run("checklist", "run", f, "--port", pty_sim, "--yes")
    assert r.exit_code == 0, r.output + r.stderr
    assert param_of(pty_sim, "F07") == 0.5


@pytest.mark.parametrize("sig,code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_signal_during_a_run_stops_the_drive_and_still_reports(pty_sim, tmp_path, sig, code):
    f = tmp_path / "long.yaml"
    f.write_text(FAILING.replace("expect: 5.0", "expect: 0.5").replace(
        "  - run: {hz: 10, duration: 0.3}\n", "  - note: long run\n  - run: {hz: 10, duration: 60}\n"))
    js = tmp_path / "r.json"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    p = subprocess.Popen(pdrive_cmd() + ["checklist", "run", str(f), "--port", pty_sim, "--yes", "--report", str(js)],
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    seen = []
    try:
        for line in p.stdout:
            seen.append(line)
            if "long run" in line and "PASS" in line:
                break
        time.sleep(0.8)            # the run step is under way (accelerating or holding 10 Hz)
        p.send_signal(sig)
        out, _ = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == code, "".join(seen) + out
    doc = json.loads(js.read_text())
    assert doc["status"] == "interrupted" and doc["interrupted"] == signal.Signals(sig).name
    run_step = next(s for s in doc["stations"][0]["steps"] if s["type"] == "run")
    assert run_step["status"] == "error" and "interrupted" in run_step["message"]
    assert doc["stations"][0]["final_status"]["stopped"] is True
    st = status_of(pty_sim)
    assert st["running"] is False and st["actual_hz"] == 0.0



GOOD = FAILING.replace("expect: 5.0", "expect: 0.5")


def test_a_real_port_without_a_terminal_needs_yes_and_nothing_is_sent(pty_sim, tmp_path):
    f = tmp_path / "good.yaml"
    f.write_text(GOOD)
    js = tmp_path / "r.json"
    r = run("checklist", "run", f, "--port", pty_sim, "--report", js)
    assert r.exit_code == 2, r.output + r.stderr
    assert "--yes" in r.stderr and "nothing was sent to any drive" in r.stderr
    assert not js.exists()
    assert param_of(pty_sim, "F07") == 6.0 and param_of(pty_sim, "F08") == 6.0      # factory values


def test_a_real_port_asks_once_listing_what_the_checklist_writes_and_runs(pty_sim, tmp_path):
    f = tmp_path / "good.yaml"
    f.write_text(GOOD)
    mfd, sfd = os.openpty()
    p = subprocess.Popen(pdrive_cmd() + ["checklist", "run", str(f), "--port", pty_sim],
                         stdin=sfd, stderr=sfd, stdout=subprocess.PIPE, text=True)
    os.close(sfd)
    buf = b""
    try:
        end = time.monotonic() + 20
        while b"Continue?" not in buf and time.monotonic() < end:
            r, _, _ = select.select([mfd], [], [], 0.2)
            if r:
                buf += os.read(mfd, 4096)
        os.write(mfd, b"n\n")
        out, _ = p.communicate(timeout=20)
        while True:
            r, _, _ = select.select([mfd], [], [], 0.2)
            if not r:
                break
            try:
                buf += os.read(mfd, 4096)
            except OSError:
                break
    finally:
        if p.poll() is None:
            p.kill()
        os.close(mfd)
    text = buf.decode(errors="replace")
    assert p.returncode == 1, text
    assert "station c1 (address 3, fuji-opc-g1-pdp)" in text and "F07" in text and "run forward at 10" in text
    assert text.count("Continue?") == 1 and "cancelled: nothing was sent to any drive" in text
    assert param_of(pty_sim, "F07") == 6.0                # 'n': nothing written
