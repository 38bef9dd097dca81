"""Capabilities known before anything runs: each profile's `capabilities:` (drives/capabilities.py), the
checklist validator refusing a step the station's card cannot run (file:line, the reason), and the drive
refusing the same in the same words. Expected values from the manuals (spec lines quoted)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from profidrive_cli.checklist.spec import ChecklistError, load_checklist_text
from profidrive_cli.datafile import DataFileError
from profidrive_cli.drives.capabilities import CAPABILITIES
from profidrive_cli.drives.profile import all_profiles, load_profile, load_profile_file

ROOT = Path(__file__).resolve().parents[1]


def test_every_shipped_profile_declares_every_capability():
    for prof in all_profiles():
        assert set(prof.capabilities.decl) == set(CAPABILITIES), prof.name


# fuji-opc-g1-pdp.md L271: "| 8, 9 | not used |" (no jog bit); L188/L206: PCD1-4 in PPO2/PPO4 only
# moeller-de6-net-dp.md L279: "| 8 | 0x0100 | Inching 1 ON | ... A038 (PNU 61)"; L180-183: PZD3.. in PPO2/4/5
# toyo-vf66-pbus66z.md L278-279: "Jog 1 ON (forward jog)", "Jog 2 ON (reverse jog)"; torque command in PPO2/4/5
# yaskawa-profibus-dp.md L280-297: no fast-stop and no jog bit; L341: torque reference / limit in Extended Data 1
@pytest.mark.parametrize("name, cap, yes, no", [
    ("fuji-g1", "jog", [], ["ppo1", "ppo2", "ppo3", "ppo4"]),
    ("fuji-pdp3", "jog", [], ["ppo1", "ppo2"]),
    ("fuji-g1", "monitor_words", ["ppo2", "ppo4"], ["ppo1", "ppo3"]),
    ("fuji-g1", "quick_stop", ["ppo1", "ppo2", "ppo3", "ppo4"], []),
    ("fuji-g1", "torque", [], ["ppo1", "ppo2"]),
    ("moeller", "jog", ["ppo1", "ppo2", "ppo3", "ppo4", "ppo5"], []),
    ("moeller", "monitor_words", ["ppo2", "ppo4", "ppo5"], ["ppo1", "ppo3"]),
    ("moeller", "torque", [], ["ppo1", "ppo5"]),
    ("moeller", "param_channel", ["ppo1", "ppo2", "ppo5"], ["ppo3", "ppo4"]),
    ("toyo", "jog", ["ppo1", "ppo3", "toyo"], ["toyo_plch"]),   # PLCH: the jog bit is PLC contact I00021
    ("toyo", "torque", ["ppo2", "ppo4", "ppo5", "toyo"], ["ppo1", "ppo3", "toyo_plch"]),
    ("toyo", "quick_stop", ["ppo1", "ppo5"], ["toyo", "toyo_plch"]),
    ("toyo", "coast_stop", ["ppo2"], ["toyo"]),
    ("yaskawa", "quick_stop", [], ["basic", "extended1", "extended2"]),
    ("yaskawa", "coast_stop", ["basic", "extended1", "extended2"], []),
    ("yaskawa", "jog", [], ["extended1"]),
    ("yaskawa", "torque", ["basic", "extended1"], ["extended2"]),
    ("yaskawa", "torque_limit", ["extended1"], ["basic", "extended2"]),
    ("yaskawa", "param_channel", ["extended1", "extended2"], ["basic"]),
])
def test_capabilities_per_layout_follow_the_manuals(name, cap, yes, no):
    caps = load_profile(name).capabilities
    for lay in yes:
        assert caps.has(cap, lay), (name, cap, lay, caps.why_not(cap, lay))
    for lay in no:
        assert not caps.has(cap, lay), (name, cap, lay)
        assert caps.why_not(cap, lay)
    assert (cap in caps) == bool(yes)


def test_the_accessor_gives_names_layouts_and_details():
    caps = load_profile("moeller").capabilities
    assert "jog" in caps and "torque" not in caps
    assert caps.layouts("monitor_words") == ("ppo2", "ppo4", "ppo5")
    assert caps.detail("jog")["param"] == "A038"          # L279: inching set-point 1 = A038
    assert caps.detail("monitor_words")["words"] == {"ppo2": 4, "ppo4": 4, "ppo5": 8}   # PZD3-6 / PZD3-10
    assert caps.for_layout("ppo3") == {"quick_stop", "coast_stop", "jog"}


def test_yaskawa_quick_stop_holds_once_the_fast_stop_input_is_named(tmp_path):
    src = load_profile("yaskawa").path.read_text(encoding="utf-8")
    assert "  fast_stop_input: null\n" in src
    f = tmp_path / "yaskawa-fs.yaml"
    f.write_text(src.replace("  fast_stop_input: null\n", "  fast_stop_input: 3\n"), encoding="utf-8")
    assert load_profile_file(f).capabilities.has("quick_stop", "extended1")


@pytest.mark.parametrize("decl, words", [
    ("  torque_limits: {}", "unknown capability 'torque_limits'"),
    ("  torque_limit: {layouts: [ppo9]}", "ppo9 not in layouts"),
    ("  torque_limit: 3", "a mapping (the card can) or a text"),
    ("  torque_limit: {needs: profidrive.nothing}", "'needs' wants a 'reason'"),
])
def test_a_bad_capabilities_section_names_file_and_line(tmp_path, decl, words):
    src = load_profile("moeller").path.read_text(encoding="utf-8")
    lines = src.splitlines()
    i = next(n for n, line in enumerate(lines) if line.startswith("  torque_limit: "))
    lines[i] = decl
    f = tmp_path / "m.yaml"
    f.write_text("\n".join(lines) + "\n", encoding="utf-8")
    with pytest.raises(DataFileError) as e:
        load_profile_file(f)
    assert f"m.yaml:{i + 1}" in str(e.value) and words in str(e.value)


# --- checklist validate --------------------------------------------------------------------------

YASKAWA_QUICK = """\
name: t
stations:
  - {name: mixer, address: 7, profile: yaskawa, layout: extended1}
steps:
  - run: {hz: 10, duration: 1}
  - stop: {mode: quick}
"""


def test_checklist_validate_rejects_a_quick_stop_on_the_yaskawa_station():
    with pytest.raises(ChecklistError) as ei:
        load_checklist_text(YASKAWA_QUICK, "t.yaml")
    errs = ei.value.errors
    assert len(errs) == 1 and errs[0].line == 6
    assert errs[0].message == ("step 2 (stop): station 'mixer': yaskawa-si-p1 (layout extended1) cannot make a "
                               "quick stop: the SI-P1 command word has no fast-stop bit; program a multi-function "
                               "input for fast stop and name it in the profile (yaskawa.fast_stop_input), or use "
                               "a normal or coast stop")


def test_checklist_validate_rejects_a_coast_stop_in_toyo_mode_1_but_not_in_mode_0():
    text = YASKAWA_QUICK.replace("address: 7, profile: yaskawa, layout: extended1",
                                 "address: 5, profile: toyo, layout: toyo").replace("quick", "coast")
    with pytest.raises(ChecklistError) as ei:
        load_checklist_text(text, "t.yaml")
    assert "cannot make a coast stop: mode 1 (Toyo original frame) has only the run bit" in ei.value.errors[0].message
    load_checklist_text(text.replace("layout: toyo", "layout: ppo1"), "t.yaml")     # mode 0: OFF2 (L271)


def test_checklist_validate_accepts_a_quick_stop_where_the_card_has_one():
    for station in ("address: 3, profile: fuji-g1", "address: 6, profile: moeller"):
        load_checklist_text(YASKAWA_QUICK.replace("address: 7, profile: yaskawa, layout: extended1", station),
                            "t.yaml")


def test_checklist_validate_cli_exits_2_with_file_and_line(tmp_path):
    f = tmp_path / "quick.yaml"
    f.write_text(YASKAWA_QUICK, encoding="utf-8")
    r = subprocess.run([sys.executable, "-m", "profidrive_cli", "checklist", "validate", str(f)],
                       capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert r.returncode == 2
    assert f"{f}:6" in r.stderr + r.stdout
    assert "cannot make a quick stop" in r.stderr + r.stdout
    assert "Traceback" not in r.stderr


# --- the drive refuses in the same words ---------------------------------------------------------

def test_the_yaskawa_drive_refuses_a_quick_stop_in_the_same_words():
    from profidrive_cli.drives import make_drive
    from profidrive_cli.drives.base import DriveError
    from profidrive_cli.sim.direct import DirectChannel
    from profidrive_cli.sim.plant import make_model
    prof = load_profile("yaskawa")
    model = make_model(prof)
    drive = make_drive(DirectChannel(model, prof.layouts["extended1"].cfg), prof, "extended1")
    with pytest.raises(DriveError) as e:
        drive.stop("quick", wait=False)
    assert str(e.value) == prof.capabilities.refusal("quick_stop", "extended1")


def test_require_raises_a_usage_error_with_the_refusal():
    from profidrive_cli import UsageError
    caps = load_profile("fuji-g1").capabilities
    with pytest.raises(UsageError) as e:
        caps.require("jog", "ppo1")
    assert str(e.value) == caps.refusal("jog", "ppo1")
    assert "CTW bits 8 and 9 are not used" in str(e.value)     # fuji-opc-g1-pdp.md L271
    caps.require("quick_stop", "ppo1")                          # L265: OFF3 with H56
