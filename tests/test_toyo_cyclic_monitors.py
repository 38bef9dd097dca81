"""Toyo monitors from the cyclic words where the layout carries them (run --monitor).

Toyo PBUS66-Z manual (/work/shared/seeds/002_e31e7b20f4f4e720.txt), PPO4 input frame L1609-1635:
  "+6 実効電流値 (L) <- 10000/100%", "+8 トルク指令値 (L) <- 5000/定格値", "+10 直流電圧 (L) <- 200V系:
  Vdc x10" -- effective current, torque command value and DC voltage every cycle; PPO4 has no PKW
  (spec toyo-vf66-pbus66z.md L89: "PPO types 3 and 4 have no PKW"). PPO2/PPO5 carry the same words
  (profile layouts, spec §2), mode 1 also the output voltage. The monitor PNUs 686-689 have the same
  scaling (spec L674-677), so the word and the parameter read give the same value.
Expected figures (hand calculation, as tests/test_monitors.py): 30 of 60 Hz, steady, 30 % load ->
torque 30 %, current 10 A x hypot(0.3, 0.3) = 4.2 A, DC link 283.0 V (the manual's example D1).
"""

import json

import pytest

from profidrive_cli import UsageError
from profidrive_cli.drives.monitors import cyclic_monitors
from profidrive_cli.drives.profile import load_profile
from profidrive_cli.session.monitors import monitor_codes
from test_run_safety import pdrive

TOYO = load_profile("toyo")


def test_which_layouts_carry_which_monitors():
    three = {"current": "current", "torque": "torque", "dc-voltage": "dc_voltage"}
    for lay in ("ppo2", "ppo4", "ppo5"):
        assert cyclic_monitors(TOYO, lay) == three
    assert cyclic_monitors(TOYO, "toyo") == {**three, "output-voltage": "output_voltage"}
    for lay in ("ppo1", "ppo3", "toyo_plch"):                  # PLCH: the words are PLC registers
        assert cyclic_monitors(TOYO, lay) == {}


def test_ppo4_default_set_is_what_its_words_carry():
    assert monitor_codes(TOYO, "ppo4", "default") == ["current", "torque", "dc-voltage"]
    assert monitor_codes(TOYO, "ppo4", "dc-voltage,current") == ["dc-voltage", "current"]


def test_ppo4_refuses_a_monitor_only_the_parameter_channel_has():
    with pytest.raises(UsageError) as e:
        monitor_codes(TOYO, "ppo4", "current,output-voltage")
    assert "output-voltage" in str(e.value) and "no parameter channel" in str(e.value)
    assert "current, torque, dc-voltage" in str(e.value)
    with pytest.raises(UsageError, match="no parameter channel"):
        monitor_codes(TOYO, "ppo3", "default")                   # PPO3: no PKW, no monitor word


def _run(*args):
    r = pdrive("run", "5", "--hz", "30", "--monitor", "default", "--json", "--port", "sim://", *args,
               timeout=180)
    assert r.returncode == 0, r.stderr
    events = [json.loads(line) for line in r.stdout.splitlines() if line.startswith("{")]
    return events[0], events[-1]


def test_run_ppo4_monitors_from_the_cyclic_words():
    start, end = _run("--ppo", "4", "--duration", "10")
    assert [m["code"] for m in start["monitors"]] == ["current", "torque", "dc-voltage"]
    mon = end["monitors"]
    assert {c: v["via"] for c, v in mon.items()} == {"current": "cyclic", "torque": "cyclic",
                                                     "dc-voltage": "cyclic"}
    assert mon["torque"]["value"] == pytest.approx(30.0, abs=0.05)
    assert mon["current"]["value"] == pytest.approx(4.2, abs=0.05)
    assert mon["dc-voltage"]["value"] == pytest.approx(283.0)
    assert not end.get("monitors_dropped")


def test_run_ppo5_only_output_voltage_through_the_parameter_channel():
    start, end = _run("--ppo", "5", "--duration", "3")
    via = {c: v["via"] for c, v in end["monitors"].items()}
    assert via == {"current": "cyclic", "torque": "cyclic", "dc-voltage": "cyclic",
                   "output-voltage": "parameter channel"}
