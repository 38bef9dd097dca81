"""Families answer family questions (docs/architecture.md, issue 25 step 1): session/ and checklist/
ask the Drive (its hooks in drives/base.py, each codec filling what differs) or a class-level fact
on the family's Drive class (drives.drive_class), instead of branching on the family's name or on
hasattr. Counted from the source, as the layering tests read imports: the count may only go down.

The grep this counts (43 lines, 47 matches before step 1; 7 after it; 5 after step 3a, Motion; 0 now):

    grep -rn "family ==\\|family !=\\|fam ==\\|fam !=\\|hasattr(" profidrive_cli/session profidrive_cli/checklist

The last sites went: session/params.py unknown_code_message and checklist/fields.py resolve_param
picked the OTHER profiles a foreign code belongs to with `p.family != prof.family` (now
drives.profile.foreign_profiles_with_code); session/discovery.py and motion.py asked a config value
for its FILE:LINE with hasattr/getattr(x, "source") (now config.source_of).

Family-keyed tables and getattr duck-typing on a session or a Drive, counted by TABLES_AND_GETATTR
(22 matches before step 3a; 5 after it; 0 after step 2 and the runner's reads): the tables
safestop._DECEL_CODES / _COMM_LOSS_WORDS and commloss_reaction._ACCEL_CODES became Drive.ramp_param /
ramp_codes and Drive.comm_loss_words; cfg.ramps in safestop.read_decel / commloss_reaction.read_accel
Drive.ramp_param; cycle.make_sample's drive._fmax Drive.speed_scale_hz; bringup's getattr(sess,
"dp_sync" / "dp_freeze" / "log_extra") attributes DriveStation declares; safestop's callback_error /
after_stop SafeStop's own; bringup's track_motion wrapper Drive.on_motion. Step 2 (Parameters) turned
backup.py's `hasattr(params, "line_of")` into isinstance(LineDict), the getattr(drive, "fmt" / "ppo" /
"last_area") dispatches of session/monitors.py into Drive hooks (input_words, pzd_input_count,
last_pzd, param_from_word) and checklist/steps/write.py's getattr(d, "notes") into Drive.take_notes();
checklist/runner.py reads drive.has_param_channel and the session's station directly.
"""

import re
from pathlib import Path

PKG = Path(__file__).resolve().parent.parent / "profidrive_cli"

#: the brief's grep, as a regular expression
SITES = re.compile(r"family ==|family !=|fam ==|fam !=|hasattr\(")
#: a family compared with a literal name: none may remain
BY_NAME = re.compile(r"""\b(?:family|fam)\s*[!=]=\s*["']""")

MAX_SITES = 0

#: a family-keyed table above drives/, or getattr duck-typing directly on a session or a Drive
TABLES_AND_GETATTR = re.compile(r"_DECEL_CODES|_COMM_LOSS_WORDS|_ACCEL_CODES|"
                                r"getattr\((?:sess|session|drive|d|sess\.drive)\s*,")
MAX_TABLES_AND_GETATTR = 0
#: getattr on a Drive for what a family has (an attribute a family may lack): none in monitors.py
#: (fmt, ppo, last_area) nor in checklist/steps/write.py (notes)
DRIVE_GETATTR = re.compile(r"getattr\((?:getattr\()?(?:drive|d|self\.sess\.drive|sess\.drive)\b")


def _sites(pattern: re.Pattern, root: Path = PKG) -> list[str]:
    out = []
    for sub in ("session", "checklist"):
        for f in sorted((root / sub).rglob("*.py")):
            for n, line in enumerate(f.read_text(encoding="utf-8").splitlines(), 1):
                out += [f"{f.relative_to(root.parent).as_posix()}:{n}: {line.strip()}"] * \
                    len(pattern.findall(line))
    return out


def test_family_branches_and_hasattr_dispatches_only_go_down():
    found = _sites(SITES)
    assert len(found) <= MAX_SITES, "new family branch / hasattr dispatch:\n" + "\n".join(found)


def test_family_tables_and_getattr_dispatches_only_go_down():
    found = _sites(TABLES_AND_GETATTR)
    assert len(found) <= MAX_TABLES_AND_GETATTR, "new family table / getattr dispatch:\n" + "\n".join(found)


def test_monitors_and_the_write_step_ask_the_drive_hooks_not_getattr():
    for f in (PKG / "session" / "monitors.py", PKG / "checklist" / "steps" / "write.py"):
        text = f.read_text(encoding="utf-8")
        assert DRIVE_GETATTR.findall(text) == [], f
        assert "._param_value(" not in text and ".resolve_param(" not in text, f     # codec privates


def test_no_family_is_compared_with_its_name_above_drives():
    assert _sites(BY_NAME) == []


def test_the_hooks_have_a_default_in_base_and_the_codecs_answer():
    # python-can's BusABC pattern: every hook exists on the base Drive; a family fills what differs
    from profidrive_cli.drives import drive_class
    from profidrive_cli.drives.base import Drive
    from profidrive_cli.drives.profile import load_profile
    hooks = ("param_info", "param_label", "value_problem", "params_at", "take_notes", "save_support",
             "use_max_frequency", "comm_loss_summary", "dumpable", "on_device", "not_restored",
             "pzd_assignment_param", "pzd_assigned_code", "comm_loss_reaction", "zero_data_reaction",
             "normal_stop_warnings", "bus_run_refusal", "can_read", "cycle_words", "last_seen", "start_hint",
             "ramp_param", "speed_scale_hz", "on_motion",
             "read_resolved", "write_resolved", "input_words", "pzd_input_count", "last_pzd",
             "param_from_word")
    assert [h for h in hooks if not callable(getattr(Drive, h, None))] == []
    facts = {name: (drive_class(load_profile(name)).monitor_mapping,
                    drive_class(load_profile(name)).comm_loss_reaction_fixed,
                    drive_class(load_profile(name)).area_shape)
             for name in ("fuji-g1", "moeller", "toyo-pbus66z", "yaskawa-si-p1")}
    # Fuji o48..o51 take effect after a power cycle (read, never written); Moeller PNU 916 is
    # volatile (mapped for the session); Toyo's comm-loss reaction is protection 18, fixed (PBUS66-Z
    # manual: no setting names it); Yaskawa's SI-P1 has MEMOBUS registers, no PZD mapping
    assert facts == {"fuji-g1": ("read", False, "ppo"), "moeller": ("map", False, "ppo"),
                     "toyo-pbus66z": ("", True, "ppo"), "yaskawa-si-p1": ("", False, "memobus")}


def test_the_codecs_name_their_ramp_parameters_and_comm_loss_words():
    # what safestop._DECEL_CODES / _COMM_LOSS_WORDS and commloss_reaction._ACCEL_CODES said, now
    # each codec's: Fuji F07/F08 "Acceleration / Deceleration time 1" (profiles/fuji-opc-g1-pdp.yaml
    # lines 112-113), Moeller F002/F003 (profiles/moeller-de6-net-dp.yaml line 72, its ramps), Yaskawa
    # C1-01/C1-02 "Acceleration / Deceleration time 1" (profiles/yaskawa-si-p1.yaml lines 99-101);
    # Toyo's ramps have no published PNU (sim/toyo.py)
    from profidrive_cli.drives import drive_class
    from profidrive_cli.drives.base import Drive
    from profidrive_cli.drives.profile import load_profile
    got = {}
    for name in ("fuji-g1", "moeller", "toyo-pbus66z", "yaskawa-si-p1"):
        cls = drive_class(load_profile(name))
        got[name] = (cls.ramp_codes.get("accel"), cls.ramp_codes.get("decel"), cls.comm_loss_words)
    assert got == {
        "fuji-g1": ("F07", "F08", "its o27/o28 setting (o27 = 3 or 13..15 ignores the loss: the motor "
                                  "keeps running)"),
        "moeller": ("F002", "F003", "P002 (0 = trip E70 and coast; 1 = keep running on the last command)"),
        "toyo-pbus66z": (None, None, "protection 18 (COMM): the inverter trips and coasts"),
        "yaskawa-si-p1": ("C1-01", "C1-02", "a BUS fault after the option's communication timeout (the "
                                            "drive stops by its BUS fault setting)")}
    assert Drive.comm_loss_words == "its communication-loss setting" and Drive.ramp_codes == {}
