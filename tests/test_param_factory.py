"""Issue 28: `param diff --defaults` (what changed from the factory), `param dump --changed`, the
profiles' parameter groups and `param restore --only / --exclude`, on the in-process simulated bus.

Factory values: Fuji F07 6.0 s and E31 60.0 Hz (the profiles' defaults, tests/test_drive_cmds.py
WRITABLE), y98 factory 0 and "Set y98 = 3 for run and frequency commands from PROFIBUS"
(../shared/spec/fuji-opc-g1-pdp.md L721, L754); Yaskawa C1-01 10.0 s (F7, the profile's
default_source), b1-01 / b1-02 = 3 for the option card (yaskawa-profibus-dp.md L213-214); Moeller: the
manual states no factory defaults (moeller-de6-net-dp.md L1230), so none is known.
"""

import json

import pytest
import yaml

from profidrive_cli.datafile import DataFileError
from profidrive_cli.drives.profile import load_profile, load_profile_file
from profidrive_cli.session.paramtypes import ParamRow
from profidrive_cli.session.restore import apply_scope, scope_problem
from conftest import run_main

#: station -> (its own set= code, value): each family's station of the default plant
OWN_SET = {3: ("F07", "5"), 4: ("E31", "40"), 5: ("J-03", "5"), 6: ("F002", "2"), 7: ("C1-01", "4")}
#: what each station's diff must list as changed (the URL's code where the profile knows its default)
CHANGED = {3: ["F07"], 4: ["E31"], 5: [], 6: [], 7: ["C1-01"]}
BUS = {3: ["y98"], 4: ["y98"], 5: [], 6: [], 7: ["b1-01", "b1-02"]}


def pd(capsys, monkeypatch, *args):
    r = run_main(capsys, monkeypatch, *args)
    return r


@pytest.mark.parametrize("address", [3, 4, 5, 6, 7])
def test_diff_defaults_lists_what_the_url_changed(capsys, monkeypatch, address):
    code, value = OWN_SET[address]
    port = f"sim://?set={address}:{code}={value}"
    r = pd(capsys, monkeypatch, "param", "diff", address, "--defaults", "--port", port, "--json")
    d = json.loads(r.stdout)
    assert d["compared_with"] == "factory defaults"
    changed = [x["code"] for x in d["rows"] if x["result"] == "differs"]
    assert changed == CHANGED[address]
    # Toyo (no setting with a PNU, PBUS66-Z manual L4201) and Moeller (no factory default known):
    # nothing compared, no verdict: exit 1 (test_audit_manuals.py)
    assert r.exit_code == (1 if changed or address in (5, 6) else 0), r.stderr
    assert [x["code"] for x in d["rows"] if x["result"] == "bus setting"] == BUS[address]
    if address == 6:            # Moeller: the manual gives no factory value: not "changed"
        row = next(x for x in d["rows"] if x["code"] == code)
        assert row["result"] == "unknown" and row["reason"] == "no factory default known"
        assert row["drive_value"] == pytest.approx(2.0)


def test_diff_defaults_text(capsys, monkeypatch):
    r = pd(capsys, monkeypatch, "param", "diff", "3", "--defaults", "--port", "sim://?set=3:F07=5")
    assert r.exit_code == 1
    assert "station 3: 1 setting(s) changed from the factory default" in r.stdout
    assert "F07" in r.stdout and "y98 = 3" in r.stdout
    assert "no factory default known (4): S01, S05, S06, S19" in r.stdout
    r = pd(capsys, monkeypatch, "param", "diff", "3", "--defaults", "--port", "sim://")
    assert r.exit_code == 0 and "0 changed" in r.stdout


def test_diff_defaults_takes_no_file(capsys, monkeypatch, tmp_path):
    r = pd(capsys, monkeypatch, "param", "diff", "3", str(tmp_path / "x.yaml"), "--defaults",
           "--port", "sim://")
    assert r.exit_code == 2 and "expected [ADDRESS] only" in r.stderr


def test_dump_changed(capsys, monkeypatch, tmp_path):
    f = tmp_path / "c.yaml"
    r = pd(capsys, monkeypatch, "param", "dump", "3", "-o", f, "--changed", "--json",
           "--port", "sim://?set=3:F07=5,o28=2")
    assert r.exit_code == 0, r.stderr
    doc = yaml.safe_load(f.read_text())
    # F07 and o28 from the URL; y98 = 3 differs from the factory 0 too (the bus setting a restore needs)
    assert sorted(doc["parameters"]) == ["F07", "o28", "y98"]
    assert doc["parameters"]["F07"]["value"] == pytest.approx(5.0)
    assert doc["parameters"]["F07"]["factory"] == pytest.approx(6.0)
    assert doc["changed_only"] is True and doc["readonly"] == {}
    assert doc["no_factory_default"] == ["S01", "S05", "S06", "S19"]
    assert doc["count"] == 3 and f.read_text().endswith("end: pdrive_dump\n")
    d = json.loads(r.stdout)
    assert d["settings"] == 3 and d["no_factory_default"] == 4


# -- groups and scopes -----------------------------------------------------------------------------

def test_every_profile_has_the_four_groups():
    for name in ("fuji-g1", "fuji-pdp3", "toyo", "moeller", "yaskawa"):
        p = load_profile(name)
        assert list(p.groups) == ["motor", "communication", "protection", "application"], name
    m = load_profile("moeller")
    # H: motor constants, A003 base frequency (moeller-de6-parameters.csv); P002: the option-error reaction
    assert m.group_of("H020") == "motor" and m.group_of("A003") == "motor"
    assert m.group_of("P002") == "communication" and m.group_of("F002") == "application"
    f = load_profile("fuji-g1")
    assert f.group_of("P04") == "motor" and f.group_of("PNU927") == "communication"
    assert f.group_of("o31") == "communication" and f.group_of("F07") == "application"


@pytest.mark.parametrize("groups, words", [
    ("groups:\n  motor: [ZZ*]\n", "groups.motor: 'ZZ*' matches no parameter of this profile"),
    ("groups:\n  Motor: [E1-*]\n", "groups: 'Motor' is not a group name"),
    ("groups:\n  motor: E1-04\n", "groups.motor must be a list of parameter codes or patterns"),
    ("groups: [motor]\n", "'groups' must be LineDict"),
    ("bus_settings: {Q9: 1}\n", "bus_settings: Q9 is not a parameter of this profile"),
    ("bus_settings: {b1-01: x}\n", "bus_settings: b1-01 must be a number"),
])
def test_groups_and_bus_settings_are_checked_with_file_and_line(tmp_path, groups, words):
    src = load_profile("yaskawa").path.read_text()
    src = src[:src.index("\ngroups:")] + "\n" if "\ngroups:" in src else src
    src = src.replace("\nbus_settings:", "\n_old_bus_settings:")
    path = tmp_path / "y.yaml"
    path.write_text(src + groups)
    n = len(src.splitlines()) + len(groups.splitlines())      # the offending key's line
    with pytest.raises(DataFileError) as e:
        load_profile_file(path)
    assert words in str(e.value) and f"{path}:{n}" in str(e.value)


def test_a_factory_default_outside_the_range_is_refused_with_file_and_line(tmp_path):
    src = load_profile("yaskawa").path.read_text()
    bad = src.replace("min: 0, max: 3, access: rw, default: 1, default_source: F7,",
                      "min: 0, max: 3, access: rw, default: 4, default_source: F7,")
    assert bad != src                                    # F6-01's entry (0..3, the F7's 1)
    path = tmp_path / "y.yaml"
    path.write_text(bad)
    n = 1 + bad.splitlines().index(next(x for x in bad.splitlines() if "default: 4," in x))
    with pytest.raises(DataFileError) as e:
        load_profile_file(path)
    assert str(e.value) == f"{path}:{n}: F6-01: the factory default 4 is outside 0..3"


def test_scope_rows():
    p = load_profile("moeller")
    rows = [ParamRow(c, "", "", 1, 0, "differs") for c in ("H020", "F002", "P002", "b012")]
    apply_scope(p, rows, (), ("motor",))
    assert [r.result for r in rows] == ["skipped", "differs", "differs", "differs"]
    assert rows[0].why == "out of scope" and rows[0].reason == "group motor excluded (--exclude)"
    rows = [ParamRow(c, "", "", 1, 0, "differs") for c in ("H020", "F002", "P002", "b012")]
    apply_scope(p, rows, ("application", "protection"), ())
    assert [r.result for r in rows] == ["skipped", "differs", "skipped", "differs"]
    assert scope_problem(p, ("motr",), ()) == ("unknown parameter group 'motr' for moeller-de6-net-dp "
                                               "(groups: motor, communication, protection, application)")
    assert scope_problem(p, ("motor",), ("application",)) is None


def _get(capsys, monkeypatch, port, *codes):
    r = pd(capsys, monkeypatch, "param", "get", "6", *codes, "--json", "--port", port)
    assert r.exit_code == 0, r.stderr
    return {x["code"]: x["value"] for x in json.loads(r.stdout)["parameters"]}


def test_restore_exclude_motor_leaves_the_motor_group_untouched(sim, capsys, monkeypatch, tmp_path):
    port = "sim://"
    f = tmp_path / "s6.yaml"
    assert pd(capsys, monkeypatch, "param", "dump", "6", "-o", f, "--port", port).exit_code == 0
    before = _get(capsys, monkeypatch, port, "A003", "F002")
    # the drive is changed afterwards: a motor code (A003 base frequency) and an application one
    for code, value in (("A003", "55"), ("F002", "2")):
        r = pd(capsys, monkeypatch, "param", "set", "6", code, value, "--port", port)
        assert r.exit_code == 0, r.stderr
    r = pd(capsys, monkeypatch, "param", "restore", "6", f, "--exclude", "motor", "--json", "--port", port)
    assert r.exit_code == 0, r.stderr
    rows = {x["code"]: x for x in json.loads(r.stdout)["rows"]}
    assert rows["A003"]["result"] == "skipped" and rows["A003"]["why"] == "out of scope"
    assert rows["F002"]["result"] == "applied"
    now = _get(capsys, monkeypatch, port, "A003", "F002")        # read back from the drive
    assert now["A003"] == pytest.approx(55.0)                    # untouched
    assert now["F002"] == pytest.approx(before["F002"])          # restored
    r = pd(capsys, monkeypatch, "param", "restore", "6", f, "--only", "motor", "--port", port)
    assert r.exit_code == 0, r.stderr
    assert _get(capsys, monkeypatch, port, "A003")["A003"] == pytest.approx(before["A003"])


def test_restore_unknown_group_is_one_line_and_writes_nothing(sim, capsys, monkeypatch, tmp_path):
    port = "sim://"
    f = tmp_path / "s6.yaml"
    assert pd(capsys, monkeypatch, "param", "dump", "6", "-o", f, "--port", port).exit_code == 0
    assert pd(capsys, monkeypatch, "param", "set", "6", "F002", "2", "--port", port).exit_code == 0
    r = pd(capsys, monkeypatch, "param", "restore", "6", f, "--exclude", "motors", "--port", port)
    assert r.exit_code == 2
    assert r.stderr.strip().splitlines()[-1].endswith(
        "unknown parameter group 'motors' for moeller-de6-net-dp (groups: motor, communication, "
        "protection, application)")
    assert "Traceback" not in r.stderr
    assert _get(capsys, monkeypatch, port, "F002")["F002"] == pytest.approx(2.0)


def test_restore_only_motor_leaves_every_other_group_alone(sim, capsys, monkeypatch, tmp_path):
    """--only motor while a motor code (A003) and an application code (F002) both differ from the
    dump: only A003 goes back; F002 keeps the drive's value (read back)."""
    port = "sim://"
    f = tmp_path / "s6.yaml"
    assert pd(capsys, monkeypatch, "param", "dump", "6", "-o", f, "--port", port).exit_code == 0
    before = _get(capsys, monkeypatch, port, "A003", "F002")
    for code, value in (("A003", "55"), ("F002", "2")):
        assert pd(capsys, monkeypatch, "param", "set", "6", code, value, "--port", port).exit_code == 0
    r = pd(capsys, monkeypatch, "param", "restore", "6", f, "--only", "motor", "--json", "--port", port)
    assert r.exit_code == 0, r.stderr
    rows = {x["code"]: x for x in json.loads(r.stdout)["rows"]}
    assert rows["A003"]["result"] == "applied"
    assert rows["F002"]["result"] == "skipped" and rows["F002"]["why"] == "out of scope"
    assert rows["F002"]["reason"] == "group application not in --only"
    now = _get(capsys, monkeypatch, port, "A003", "F002")
    assert now["A003"] == pytest.approx(before["A003"])
    assert now["F002"] == pytest.approx(2.0)


def test_the_session_level_restore_checks_the_groups_itself(tmp_path):
    """restore() refuses an unknown group before anything (the CLI checks earlier, the session level
    does not rely on it): one line naming the groups, nothing written."""
    import profidrive_cli as pdrive
    from profidrive_cli.session.dumpfile import load_dump, write_dump
    f = tmp_path / "s6.yaml"
    with pdrive.open_bus("sim://?timing=virtual", env={}) as bus:
        with bus.station(6, handle_signals=False) as s:
            write_dump(s.params.dump(), f)
    doc = load_dump(f)
    with pdrive.open_bus("sim://?timing=virtual", env={}) as bus:
        with bus.station(6, handle_signals=False) as s:
            with pytest.raises(pdrive.UsageError) as e:
                s.params.restore(doc, exclude=("motr",))
    assert str(e.value) == ("unknown parameter group 'motr' for moeller-de6-net-dp (groups: motor, "
                            "communication, protection, application)")


def test_apply_scope_says_why_a_code_in_no_group_is_left_out():
    p = load_profile("moeller")
    ungrouped = next(c for c in p.parameters if p.group_of(c) is None)
    rows = [ParamRow(ungrouped, "", "", 1, 0, "differs")]
    apply_scope(p, rows, ("motor",), ())
    assert (rows[0].result, rows[0].why, rows[0].reason) == ("skipped", "out of scope",
                                                             "in no group (--only)")
    assert scope_problem(p, (), ("protection",)) is None


def test_a_profile_without_groups_says_so(tmp_path):
    f = tmp_path / "g.yaml"
    f.write_text("profile: no-groups\nfamily: profidrive\ntitle: t\nidentity: {ident: 0x1234}\n"
                 "layouts:\n  ppo1: {cfg: \"F3 F1\", pkw: true}\ndefault_layout: ppo1\n")
    p = load_profile_file(f)
    assert scope_problem(p, ("motor",), ()) == "unknown parameter group 'motor' for no-groups (groups: none)"
