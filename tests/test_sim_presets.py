"""sim://?set=ADDR:CODE=VALUE: a simulated drive that starts with given settings (one commissioned
before), so every command works on sim:// without a persistent plant — e.g. a Yaskawa torque run,
which needs flux vector (A1-02 = 3)."""

import json
import subprocess
import sys

import pytest


def _pdrive(*args):
    return subprocess.run([sys.executable, "-m", "profidrive_cli", *args], capture_output=True,
                          text=True, stdin=subprocess.DEVNULL, timeout=120)


@pytest.mark.parametrize("url,address,code,raw", [
    ("sim://?set=7:A1-02=3", 7, "A1-02", 3),
    ("sim://?set=6:F002=2.5", 6, "F002", 250),        # Moeller 0.01 s steps
    ("sim://?set=3:F07=2.5", 3, "F07", 25),           # Fuji 0.1 s steps
])
def test_preset_values_read_back(url, address, code, raw):
    p = _pdrive("param", "get", str(address), code, "--port", url, "--json")
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["parameters"][0]["raw"] == raw


@pytest.mark.parametrize("url,words", [
    ("sim://?set=9:F07=1", "not on the bus"),
    ("sim://?set=3:XX=1", "XX is not a parameter"),
    ("sim://?set=3:F07", "must be CODE=NUMBER"),
    ("sim://?set=3:F07=fast", "must be CODE=NUMBER"),
    # F07 has a 0.1 s resolution (profile: scale 0.1): 0.01 s cannot be held, and was taken as 0
    ("sim://?set=3:F07=0.01", "F07 = 0.01 s cannot be held exactly: resolution 0.1 s; nearest 0 s or 0.1 s"),
    # E1-04 (max output frequency) 40.0..400.0 Hz (Yaskawa profile): 1000 is outside
    ("sim://?set=7:E1-04=1000", "E1-04"),
])
def test_bad_presets_are_one_line_exit_2(url, words):
    p = _pdrive("status", "3", "--port", url)
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and words in lines[0]


def test_yaskawa_torque_run_on_sim_with_flux_vector():
    p = _pdrive("run", "7", "--torque", "20", "--hz", "30", "--duration", "3", "--json",
                "--port", "sim://?set=7:A1-02=3,d5-01=1")        # d5-01 = 1: torque control
    assert p.returncode == 0, p.stderr
    events = [json.loads(line) for line in p.stdout.splitlines()]
    updates = [e for e in events if e["event"] == "update" and e["phase"] == "running"]
    assert updates and max(abs(e["actual_hz"]) for e in updates) > 1.0
    assert any(e.get("torque_ref_percent") == 20.0 for e in updates)
    assert events[-1]["event"] == "end" and events[-1]["stopped"] is True
