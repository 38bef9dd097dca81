"""The two YAML parsers under datafile.load_yaml_text: PyYAML's pure-Python one and libyaml's (C) one.
Both must give the same data and the same line numbers for every file pdrive ships, and every limit
(size, depth, digits, no aliases, file:line errors) must hold under either."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from profidrive_cli import datafile
from profidrive_cli.datafile import (
    MAX_YAML_BYTES, MAX_YAML_DEPTH, DataFileError, LineDict, LineList, load_yaml_head, load_yaml_text,
)

ROOT = Path(__file__).resolve().parent.parent
SHIPPED = sorted((ROOT / "profiles").glob("*.yaml")) + sorted((ROOT / "examples" / "checklists").glob("*.yaml"))

needs_libyaml = pytest.mark.skipif(datafile._CLoader is None, reason="PyYAML built without libyaml")
LOADERS = [pytest.param(True, id="pure"), pytest.param(False, id="libyaml", marks=needs_libyaml)]


def _same(a, b, where="") -> None:
    """a and b equal, of the same types, with the same line numbers everywhere (node, keys, items)."""
    assert type(a) is type(b), where
    if isinstance(a, LineDict):
        assert (a.line, a.key_lines) == (b.line, b.key_lines), where
        assert list(a) == list(b), where
        for k in a:
            _same(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, LineList):
        assert (a.line, a.item_lines, len(a)) == (b.line, b.item_lines, len(b)), where
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{where}[{i}]")
    else:
        assert a == b, where


def test_the_shipped_files_are_all_there():
    assert len(SHIPPED) >= 10       # five profiles, five example checklists


@needs_libyaml
@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_pure_and_libyaml_give_the_same_data_and_lines(path):
    text = path.read_text(encoding="utf-8")
    pure = load_yaml_text(text, path, pure=True)
    fast = load_yaml_text(text, path, pure=False)
    assert isinstance(pure, LineDict) and pure.line >= 1
    _same(pure, fast, path.name)


def test_libyaml_is_the_default_and_the_environment_can_turn_it_off(monkeypatch):
    monkeypatch.delenv("PDRIVE_PURE_YAML", raising=False)
    expected = datafile._PureLoader if datafile._CLoader is None else datafile._CLoader
    assert datafile._loader_class(None) is expected
    monkeypatch.setenv("PDRIVE_PURE_YAML", "1")
    assert datafile._loader_class(None) is datafile._PureLoader


@pytest.mark.parametrize("pure", LOADERS)
@pytest.mark.parametrize("text,line,words", [
    ("a: 1\nb: !!float x\n", 2, "bad float value 'x'"),
    ("a: !!int '12a'\n", 1, "bad int value '12a'"),
    ("a:\n  - !!timestamp 2020-13-45\n", 2, "bad timestamp value '2020-13-45'"),
    ("a: " + "1" * 5000 + "\n", 1, "number too long (5000 characters, limit 100)"),
    ("a: 0x" + "f" * 200 + "\n", 1, "number too long (202 characters, limit 100)"),
    ("a:\n b: " + "[" * 5000 + "]" * 5000 + "\n", 2, f"nested deeper than {MAX_YAML_DEPTH} levels"),
    # the mapping on line n is level n; the key k63 on line 64 is level 65
    ("a:\n" + "".join(" " * i + f"k{i}:\n" for i in range(1, 80)), MAX_YAML_DEPTH,
     f"nested deeper than {MAX_YAML_DEPTH} levels"),
    ("a: &x [1]\nb: *x\n", 2, "aliases (*x) are not supported"),
    ("a: &x {k: 1}\nb:\n  - 1\n  - *x\n", 4, "aliases (*x) are not supported"),
    ("a: 1\na: 2\n", 2, "duplicate key 'a'"),
    ("a: 1\n  b: 2\n", 2, "YAML error"),
    ("a: [1, 2\nb: 3\n", None, "YAML error"),
    ("a: !!python/object:os.system x\n", 1, "YAML error"),
])
def test_every_limit_holds_under_both_parsers(pure, text, line, words):
    with pytest.raises(DataFileError) as ei:
        load_yaml_text(text, "f.yaml", pure=pure)
    e = ei.value
    assert words in e.message and "\n" not in str(e) and str(e).startswith("f.yaml")
    if line is not None:
        assert e.line == line


@pytest.mark.parametrize("pure", LOADERS)
def test_a_lone_surrogate_is_a_data_file_error_not_a_traceback(pure):
    """libyaml cannot even take such a text (it is not UTF-8): the pure reader refuses it."""
    for load in (lambda t: load_yaml_text(t, "f.yaml", pure=pure),
                 lambda t: load_yaml_head(t, ("b",), "f.yaml", pure=pure)):
        with pytest.raises(DataFileError, match=r"f.yaml: YAML error: unacceptable character #xdc80"):
            load("a: \udc80\n")


@pytest.mark.parametrize("pure", LOADERS)
def test_a_document_too_large_is_refused_before_parsing(pure):
    with pytest.raises(DataFileError, match="too large"):
        load_yaml_text("a: 1\n" + "#" * MAX_YAML_BYTES, "f.yaml", pure=pure)


@pytest.mark.parametrize("pure", LOADERS)
def test_very_deep_nesting_is_an_error_not_a_crash(pure):
    """400 000 open brackets: refused at depth 65 (line 1), never recursing into C or Python deeply."""
    signal.setitimer(signal.ITIMER_REAL, 20.0)       # a hang guard, not a timing assertion
    try:
        with pytest.raises(DataFileError, match=r"f.yaml:1: .*nested deeper than"):
            load_yaml_text("[" * 400_000, "f.yaml", pure=pure)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)


@pytest.mark.parametrize("pure", LOADERS)
def test_an_alias_bomb_is_refused_at_the_first_alias(pure):
    lines = ['a0: &a0 ["lolololololololololololol"]'] + [
        f"a{i}: &a{i} [" + ",".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 13)]
    with pytest.raises(DataFileError, match=r"f.yaml:2: YAML error: aliases \(\*a0\)"):
        load_yaml_text("\n".join(lines) + "\n", "f.yaml", pure=pure)


@pytest.mark.parametrize("pure", LOADERS)
def test_the_head_of_a_profile_is_what_the_full_load_gives(pure):
    for path in sorted((ROOT / "profiles").glob("*.yaml")):
        text = path.read_text(encoding="utf-8")
        full = load_yaml_text(text, path, pure=True)
        head = load_yaml_head(text, ("profile", "aliases", "family", "identity"), path, pure=pure)
        assert set(head) == {"profile", "aliases", "family", "identity"}
        assert head.line == full.line
        for k in head:
            assert head.key_lines[k] == full.key_lines[k]
            _same(head[k], full[k], f"{path.name}.{k}")


@pytest.mark.parametrize("pure", LOADERS)
def test_the_head_stops_reading_once_it_has_its_keys(pure):
    """What follows the wanted keys is not parsed: a syntax error there does not matter to the head
    (the full load reports it with its line)."""
    text = "profile: p\nfamily: f\nlayouts:\n  a: [1, 2\n  b: ]]]\n"
    head = load_yaml_head(text, ("profile", "family"), "f.yaml", pure=pure)
    assert dict(head) == {"profile": "p", "family": "f"} and head.key_lines == {"profile": 1, "family": 2}
    with pytest.raises(DataFileError) as ei:
        load_yaml_text(text, "f.yaml", pure=pure)
    assert ei.value.line in (4, 5)


@pytest.mark.parametrize("pure", LOADERS)
def test_the_head_keeps_the_limits_and_skips_other_keys(pure):
    text = "title: t\nprofile: p\nother: {x: [1, 2]}\nfamily: &a f\n"
    assert dict(load_yaml_head(text, ("profile",), "f.yaml", pure=pure)) == {"profile": "p"}
    with pytest.raises(DataFileError, match=r"f.yaml:5: YAML error: aliases \(\*a\)"):
        load_yaml_head(text + "x: *a\n", ("profile", "family", "x"), "f.yaml", pure=pure)
    with pytest.raises(DataFileError, match=r"f.yaml:2: .*nested deeper"):
        load_yaml_head("profile: p\nfamily: " + "[" * 100 + "]" * 100 + "\n", ("family",), "f.yaml",
                       pure=pure)
    assert load_yaml_head("- a\n- b\n", ("profile",), "f.yaml", pure=pure) is None
    assert load_yaml_head("", ("profile",), "f.yaml", pure=pure) is None


def test_pdrive_pure_yaml_gives_the_same_command_output():
    """The whole path (profile load, codec, rendering) is the same with either parser."""
    cmd = [sys.executable, "-m", "profidrive_cli", "decode", "moeller", "--ppo", "1", "--request",
           "3017 0000 0000 0190 047F 2000"]
    outs = []
    for pure in ("1", "0"):
        env = dict(os.environ, PDRIVE_PURE_YAML=pure)
        r = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=60)
        assert r.returncode == 0, r.stderr
        outs.append(r.stdout)
    assert outs[0] == outs[1] and "PNU 23" in outs[0]


# ------------------------------------------------------------------ the direct path (events -> data)

from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

_scalars = st.one_of(st.integers(-10**30, 10**30), st.floats(allow_nan=False), st.booleans(), st.none(),
                     st.text(max_size=12), st.dates(),
                     st.sampled_from(["0x1F", "0o17", "1_000", "+5", ".inf", "-.Inf", ".NaN", "yes", "Off", "~",
                                      "2001-12-14t21:59:43.10-05:00", "1:30", "0b101", "<<", "=", "", "012"]))
_docs = st.recursive(_scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.one_of(st.text(max_size=6), st.integers(0, 99)), inner,
                                                 max_size=4)), max_leaves=25)


def _c_node_path(text):
    loader = datafile._CLoader(text)
    try:
        return loader.get_single_data()
    finally:
        loader.dispose()


@needs_libyaml
@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_the_shipped_files_take_the_direct_path(path):
    text = path.read_text(encoding="utf-8")
    loader = datafile._CLoader(text)
    try:
        direct = datafile._direct_data(loader)      # raises _Fallback if it gave up
    finally:
        loader.dispose()
    _same(load_yaml_text(text, path, pure=True), direct, path.name)


@needs_libyaml
@settings(max_examples=300, deadline=None)
@given(doc=_docs, flow=st.sampled_from([None, True, False]), width=st.sampled_from([8, 80]))
def test_the_direct_path_builds_what_the_node_path_builds(doc, flow, width):
    import yaml
    text = yaml.safe_dump(doc, default_flow_style=flow, width=width, allow_unicode=True)
    loader = datafile._CLoader(text)
    try:
        direct = datafile._direct_data(loader)
    except datafile._Fallback:
        return                                       # left to the node path: nothing to compare
    finally:
        loader.dispose()
    _same(_c_node_path(text), direct)


@needs_libyaml
@pytest.mark.parametrize("text", [
    "a: &x 1\n", "a: !!str 1\n", "<<: {b: 1}\nc: 2\n", "a: 1\n---\nb: 2\n", "? [1]\n: 2\n", "a: 1\na: 2\n",
    "", "a: " + "1" * 200 + "\n", "= : 1\n", "a: [1, 2\n",
])
def test_the_direct_path_leaves_the_unusual_to_the_node_path(text):
    """Tags, anchors, merge keys, several documents, complex keys, duplicates, long numbers, errors."""
    loader = datafile._CLoader(text)
    try:
        with pytest.raises(datafile._Fallback):
            datafile._direct_data(loader)
    finally:
        loader.dispose()
    try:
        expected = load_yaml_text(text, "f.yaml", pure=True)
    except DataFileError as e:
        with pytest.raises(DataFileError) as ei:
            load_yaml_text(text, "f.yaml", pure=False)
        assert ei.value.line == e.line
    else:
        _same(expected, load_yaml_text(text, "f.yaml", pure=False))


# ------------------------------------------------------------------ libyaml's own limits and words

def _shallow_libyaml(levels: int):
    """A libyaml of another version: it refuses nesting deeper than `levels` in words of its own (as
    libyaml 0.2.6 does beyond 1000 levels with "exceeded maximum nesting depth", while scanning ahead)."""
    import yaml

    class Shallow(datafile._CLoader):
        _levels = 0

        def get_event(self):
            ev = super().get_event()
            if isinstance(ev, (yaml.SequenceStartEvent, yaml.MappingStartEvent)):
                self._levels += 1
                if self._levels > levels:
                    raise yaml.scanner.ScannerError("while scanning", ev.start_mark,
                                                    "too deep for this libyaml", ev.start_mark)
            elif isinstance(ev, (yaml.SequenceEndEvent, yaml.MappingEndEvent)):
                self._levels -= 1
            return ev
    return Shallow


@needs_libyaml
@pytest.mark.parametrize("text", [
    "a:\n b: " + "[" * 5000 + "]" * 5000 + "\n",
    "[" * 400_000,
    "a:\n" + "".join(" " * i + f"k{i}:\n" for i in range(1, 80)),
    "a:\n b: [1, [2, 3]\n",                                     # a syntax error: the pure loader's words
])
@pytest.mark.parametrize("levels", [10, 1000])
def test_pdrive_s_limits_and_words_whatever_libyaml_refuses(monkeypatch, text, levels):
    """Whatever libyaml's own nesting limit and words, the error is the pure loader's: pdrive's words
    ("nested deeper than 64 levels") at pdrive's file:line."""
    with pytest.raises(DataFileError) as pure:
        load_yaml_text(text, "f.yaml", pure=True)
    monkeypatch.setattr(datafile, "_CLoader", _shallow_libyaml(levels))
    with pytest.raises(DataFileError) as fast:
        load_yaml_text(text, "f.yaml", pure=False)
    assert str(fast.value) == str(pure.value)
    assert "too deep for this libyaml" not in str(fast.value)


@needs_libyaml
def test_a_file_within_pdrive_s_limits_loads_even_if_libyaml_refuses_it(monkeypatch):
    """A libyaml stricter than pdrive (10 levels) does not turn a good file (20 levels) into an error:
    the data and lines are the pure loader's; so is the head."""
    text = "profile: p\nfamily:\n  x: " + "[" * 19 + "1" + "]" * 19 + "\n"
    pure = load_yaml_text(text, "f.yaml", pure=True)
    pure_head = load_yaml_head(text, ("family",), "f.yaml", pure=True)
    monkeypatch.setattr(datafile, "_CLoader", _shallow_libyaml(10))
    _same(pure, load_yaml_text(text, "f.yaml", pure=False))
    _same(pure_head, load_yaml_head(text, ("family",), "f.yaml", pure=False))
    with pytest.raises(DataFileError, match=r"f.yaml:1: .*nested deeper than 64 levels"):
        load_yaml_head("profile: " + "[" * 5000, ("profile",), "f.yaml", pure=False)
