"""The YAML loader (datafile.load_yaml_text) under hostile input: only DataFileError comes out, with a
line when the problem has one, a message of bounded length, and line tracking unchanged."""

from __future__ import annotations

import signal

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from profidrive_cli.datafile import (
    MAX_YAML_DEPTH, DataFileError, LineDict, LineList, load_yaml_text, read_input_file,
)

TOKENS = ["!!float x", "!!int '12a'", "!!timestamp 2020-13-45", "!!timestamp x", "!!binary '@'", "!!set {a}",
          "!!omap [1]", "!!python/object:os.system x", "&a [1, 2]", "*a", "*b", "<<: *a", "1" * 5000, "[" * 300,
          "]", "{", "}", "0x" + "f" * 5000, "1e99999", "'", '"', "\t", "- ", ": ", "\n", "\n  ", ",", "?", "a",
          "7", "!!str", "!!map", "!!seq", "%YAML 1.1\n", "---\n", "\x00", "\u2028", "2001-02-30"]


@pytest.mark.parametrize("text,line,words", [
    ("a: 1\nb: !!float x\n", 2, "bad float value 'x'"),
    ("a: !!int '12a'\n", 1, "bad int value '12a'"),
    ("a:\n  - !!timestamp 2020-13-45\n", 2, "bad timestamp value '2020-13-45': month must be in 1..12"),
    ("a: !!timestamp yesterday\n", 1, "bad timestamp value 'yesterday'"),
    ("a: " + "1" * 5000 + "\n", 1, "number too long (5000 characters, limit 100)"),
    ("a:\n b: " + "[" * 5000 + "]" * 5000 + "\n", 2, f"nested deeper than {MAX_YAML_DEPTH} levels"),
    ("a: &x [1]\nb: *x\n", 2, "aliases (*x) are not supported"),
    ("a: 1\na: 2\n", 2, "duplicate key 'a'"),
])
def test_constructor_errors_are_one_line_with_the_line(text, line, words):
    with pytest.raises(DataFileError) as ei:
        load_yaml_text(text, "f.yaml")
    e = ei.value
    assert e.line == line and words in e.message and "\n" not in str(e)


def test_alias_bomb_is_refused_before_anything_expands():
    """9**12 strings if expanded: refused at the first alias, in well under a second of CPU."""
    lines = ['a0: &a0 ["lolololololololololololol"]'] + [
        f"a{i}: &a{i} [" + ",".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 13)]
    text = "\n".join(lines) + "\n"
    assert len(text) < 700
    signal.setitimer(signal.ITIMER_REAL, 5.0)        # a hang guard, not a timing assertion
    try:
        with pytest.raises(DataFileError, match=r"f.yaml:2: YAML error: aliases \(\*a0\)"):
            load_yaml_text(text, "f.yaml")
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)


def test_long_values_are_quoted_short():
    with pytest.raises(DataFileError) as ei:
        load_yaml_text("a: !!timestamp " + "x" * 5000 + "\n", "f.yaml")
    assert len(str(ei.value)) < 300 and "..." in str(ei.value)


def test_line_tracking_is_unchanged():
    doc = load_yaml_text("name: t\nstations:\n  - {address: 3}\n  - address: 4\n    profile: x\n", "f.yaml")
    assert isinstance(doc, LineDict) and doc.line == 1 and doc.line_of("stations") == 2
    st_ = doc["stations"]
    assert isinstance(st_, LineList) and st_.item_lines == [3, 4] and st_[1].line_of("profile") == 5


def test_read_input_file_refuses_fifo_device_folder_and_size(tmp_path):
    import os
    os.mkfifo(tmp_path / "f")
    for path, words in ((tmp_path / "f", "is a FIFO"), ("/dev/zero", "is a device"),
                        (tmp_path, "is a folder"), (tmp_path / "nope", "file not found")):
        with pytest.raises(DataFileError, match=words):
            read_input_file(path, "checklist", 1000)
    (tmp_path / "big").write_bytes(b"x" * 1001)
    with pytest.raises(DataFileError, match=r"too large for a checklist: 1001 bytes \(limit 1000\)"):
        read_input_file(tmp_path / "big", "checklist", 1000)
    (tmp_path / "ok").write_bytes(b"x" * 1000)
    assert read_input_file(tmp_path / "ok", "checklist", 1000) == b"x" * 1000


@settings(max_examples=400, deadline=None)
@given(st.lists(st.sampled_from(TOKENS), max_size=30))
def test_token_soup_only_raises_datafileerror(parts):
    try:
        load_yaml_text("".join(parts), "soup.yaml")
    except DataFileError as e:
        assert str(e).startswith("soup.yaml") and "\n" not in str(e) and len(str(e)) < 700


def test_mutated_checklists_through_validate_never_crash(tmp_path):
    """200 seeded mutations of the example checklists through `checklist validate` (the subset of
    tools/fuzz_files.py): exit 0 or 2, never a traceback, each within 5 s."""
    from test_gsd_fuzz import _fuzz_tool
    fz = _fuzz_tool()
    old = signal.signal(signal.SIGALRM, fz._alarm)
    try:
        c = fz.fuzz("checklist", 200, seed=2024, hang_s=5.0, out_dir=None, tmp=tmp_path)
    finally:
        signal.signal(signal.SIGALRM, old)
    assert (c["crash"], c["hang"]) == (0, 0)
    assert c["exit0"] > 0 and c["exit2"] > 0
