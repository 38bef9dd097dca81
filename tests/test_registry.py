"""The one family table (drives/registry.py): a profile's `family:` names a row, or the profile is refused
where it says so (file:line, exit 2); every shipped profile's family has a codec, a Drive class, a config
reader and (where it has one) a sim model, all found through the table."""

from __future__ import annotations

import importlib
import textwrap
from pathlib import Path

from profidrive_cli.drives import registry
from profidrive_cli.drives.profile import all_profiles

from test_exit_codes import pdrive              # the in-process CLI runner

ROOT = Path(__file__).resolve().parents[1]

#: docs/architecture.md, "Families": the family (codec) column, plus `profidrive` (the generic
#: PROFIdrive core, docs/architecture.md "drives/profidrive"; tests/test_profidrive_sim.py uses it)
FAMILIES = ["fuji", "moeller", "profidrive", "toyo", "yaskawa"]

CUSTOM = textwrap.dedent("""\
    profile: foo-test
    family: foo
    title: A drive of no family pdrive knows
    identity: {ident: 0x1234}
    layouts:
      ppo1: {cfg: "F3 F1", pkw: true}
    default_layout: ppo1
    """)




def test_a_custom_profile_of_an_unknown_family_is_refused_on_its_line(tmp_path, capsys, monkeypatch):
    f = tmp_path / "foo.yaml"
    f.write_text(CUSTOM, encoding="utf-8")
    area = ["00"] * 12                    # PPO1 request: 4 PKW + 2 PZD words = 12 octets
    code, out, err = pdrive(capsys, monkeypatch, "decode", str(f), "--ppo", "1", "--request", *area)
    assert code == 2 and out == ""
    # line 2 of CUSTOM is `family: foo`
    assert err.strip().splitlines() == [
        f"pdrive: {f}:2: family 'foo' unknown (known: {', '.join(FAMILIES)})"], err
    assert "Traceback" not in err


def test_a_known_family_in_a_custom_profile_still_loads(tmp_path, capsys, monkeypatch):
    f = tmp_path / "generic.yaml"
    f.write_text(CUSTOM.replace("family: foo", "family: profidrive"), encoding="utf-8")
    # PPO1 request, CTW 0x047F (PZD1 at octets 8-9): the PROFIdrive core decodes it
    area = ["00"] * 8 + ["04", "7F", "00", "00"]
    code, out, err = pdrive(capsys, monkeypatch, "decode", str(f), "--ppo", "1", "--request", *area)
    assert code == 0, err
    assert "0x047F" in out


def test_the_table_has_the_families_and_every_reference_resolves():
    assert sorted(registry.FAMILIES) == FAMILIES
    from profidrive_cli.drives.base import Drive
    for fam in registry.FAMILIES.values():
        assert isinstance(registry.resolve(fam.codec).make_drive, type(lambda: 0))
        assert callable(registry.resolve(fam.codec).decode_area)
        assert issubclass(registry.resolve(fam.drive_class), Drive)
        assert callable(registry.resolve(fam.config))
        if fam.core_config is not None:
            assert callable(registry.resolve(fam.core_config))
        if fam.sim_model is not None:
            mod, _, fn = fam.sim_model.partition(":")
            assert callable(getattr(importlib.import_module(mod), fn))
        if fam.wire_fields is not None:
            assert callable(registry.resolve(fam.wire_fields))
        assert fam.sim_diag_len >= 6                       # Slave_Diag's six standard octets


def test_every_shipped_profile_names_a_row_with_a_sim_model():
    for prof in all_profiles():
        fam = registry.family_of(prof)
        assert fam.sim_model is not None, prof.name
        assert registry.drive_class(prof).__name__.lower().startswith(prof.family), prof.name
        registry.family_config(prof)          # reads and checks the family keys: no error


def test_reading_the_table_imports_no_codec_and_no_sim():
    import subprocess
    import sys
    code = ("import sys; import profidrive_cli.drives.registry as r; r.FAMILIES; "
            "print(sorted(m for m in sys.modules if m.startswith(('profidrive_cli.sim', "
            "'profidrive_cli.drives.fuji', 'profidrive_cli.drives.toyo', 'profidrive_cli.drives.yaskawa', "
            "'profidrive_cli.drives.moeller', 'profidrive_cli.drives.profidrive'))))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]"
