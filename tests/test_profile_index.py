"""The profile index: a command loads only the profile it asks for (by name, alias or ident); the
index reads each file's first keys only. Expected values are from docs/architecture.md's family table."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from profidrive_cli import UsageError
from profidrive_cli.datafile import DataFileError
from profidrive_cli.drives import profile as profmod

ROOT = Path(__file__).resolve().parent.parent

# docs/architecture.md, "Families": profile, aliases, family, ident
TABLE = [
    ("fuji-opc-g1-pdp", ("fuji-g1",), "fuji", 0xFD01),
    ("fuji-opc-pdp3", ("fuji-pdp3",), "fuji", 0xFD02),
    ("moeller-de6-net-dp", ("moeller",), "moeller", 0xFD06),
    ("profidrive-dpv1", ("dpv1-axis",), "profidrive", 0x8158),
    ("toyo-pbus66z", ("toyo",), "toyo", 0x0BE7),
    ("yaskawa-si-p1", ("yaskawa",), "yaskawa", 0x00CA),
]


@pytest.fixture
def fresh():
    profmod.clear_cache()
    yield
    profmod.clear_cache()


@pytest.fixture
def loads(monkeypatch, fresh):
    """The file names load_profile_file is called for (a full load)."""
    seen: list[str] = []
    real = profmod.load_profile_file

    def counting(path):
        seen.append(Path(path).name)
        return real(path)
    monkeypatch.setattr(profmod, "load_profile_file", counting)
    return seen


@pytest.fixture
def tmp_profiles(tmp_path, monkeypatch, fresh):
    d = tmp_path / "profiles"
    d.mkdir()
    monkeypatch.setattr(profmod, "profiles_dir", lambda: d)
    return d


def test_the_index_knows_every_shipped_profile_without_loading_one(loads):
    got = [(e.name, e.aliases, e.family, e.ident) for e in profmod.profile_index()]
    assert sorted(got) == sorted(TABLE)
    assert loads == []


@pytest.mark.parametrize("name,aliases,family,ident", TABLE)
def test_a_lookup_loads_only_the_profile_asked_for(loads, name, aliases, family, ident):
    p = profmod.load_profile(aliases[0].upper())
    assert (p.name, p.family, p.ident) == (name, family, ident)
    assert loads == [f"{name}.yaml"]
    assert profmod.load_profile(name) is p and loads == [f"{name}.yaml"]     # cached
    q = profmod.profile_for_ident(ident)
    assert q is p and loads == [f"{name}.yaml"]


def test_an_unknown_ident_loads_nothing(loads):
    assert profmod.profile_for_ident(0x1234) is None
    assert loads == []


def test_an_unknown_name_lists_the_known_ones_without_loading(loads):
    with pytest.raises(UsageError, match=r"unknown profile 'nosuch' \(known: fuji-opc-g1-pdp, fuji-opc-pdp3, "
                       r"moeller-de6-net-dp, profidrive-dpv1, toyo-pbus66z, yaskawa-si-p1\)"):
        profmod.load_profile("nosuch")
    assert loads == []


def test_a_broken_profile_does_not_stop_another_from_loading(tmp_profiles):
    shutil.copy(ROOT / "profiles" / "moeller-de6-net-dp.yaml", tmp_profiles)
    text = (ROOT / "profiles" / "yaskawa-si-p1.yaml").read_text(encoding="utf-8")
    lines = text.splitlines(keepends=True)
    at = next(i for i, line in enumerate(lines) if line.startswith("layouts:"))
    lines.insert(at + 1, "  bad: [1, 2\n   : ]]\n")
    (tmp_profiles / "yaskawa-si-p1.yaml").write_text("".join(lines), encoding="utf-8")
    assert profmod.load_profile("moeller").name == "moeller-de6-net-dp"
    assert profmod.profile_for_ident(0xFD06).name == "moeller-de6-net-dp"
    with pytest.raises(DataFileError) as ei:          # asked for: its error, with file:line
        profmod.load_profile("yaskawa")
    assert ei.value.path.endswith("yaskawa-si-p1.yaml") and ei.value.line in (at + 2, at + 3)
    with pytest.raises(DataFileError):
        profmod.all_profiles()


def test_a_file_whose_header_does_not_read_is_reported_when_nothing_else_answers(tmp_profiles):
    """aaa.yaml sorts first and is broken in its first lines: a good profile still loads; a name no
    readable profile has gets aaa.yaml's file:line error (it might have been that one)."""
    shutil.copy(ROOT / "profiles" / "toyo-pbus66z.yaml", tmp_profiles)
    (tmp_profiles / "aaa.yaml").write_text("profile: aaa\nfamily: [oops\n", encoding="utf-8")
    assert profmod.load_profile("toyo").ident == 0x0BE7
    with pytest.raises(DataFileError) as ei:
        profmod.load_profile("aaa")
    assert ei.value.path.endswith("aaa.yaml") and ei.value.line is not None
    with pytest.raises(DataFileError):
        profmod.profile_for_ident(0x4242)


def test_an_edited_profile_is_read_again(tmp_profiles):
    p = tmp_profiles / "toyo-pbus66z.yaml"
    shutil.copy(ROOT / "profiles" / p.name, p)
    assert profmod.profile_for_ident(0x0BE7).name == "toyo-pbus66z"
    text = p.read_text(encoding="utf-8").replace("ident: 0x0BE7", "ident: 0x0BE8", 1)
    assert "0x0BE8" in text
    p.write_text(text, encoding="utf-8")
    st = p.stat()
    os.utime(p, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    assert profmod.profile_for_ident(0x0BE7) is None
    assert profmod.profile_for_ident(0x0BE8).ident == 0x0BE8
