"""The cache of parsed data files (profidrive_cli/datacache.py): a profile loads the same from the cache
as from its text, line numbers included; a changed text is parsed anew; errors are never kept; a file
in the cache that is not our data is refused (and parsed anew); the folder stays within its bound;
a cache that cannot be written changes nothing."""

import os
import pickle

import pytest

from profidrive_cli import datacache
from profidrive_cli.datafile import DataFileError, LineDict, load_yaml
from profidrive_cli.drives import profile as profiles


@pytest.fixture
def cache(tmp_path, monkeypatch):
    d = tmp_path / "cache"
    monkeypatch.setenv("PDRIVE_CACHE_DIR", str(d))
    return d


def _lines(data):
    """Every line number of a parsed document, in order (mappings: their own and each key's; lists:
    their own and each item's)."""
    out = []
    if isinstance(data, dict):
        out += [data.line, sorted(data.key_lines.items(), key=repr)]
        for v in data.values():
            out += _lines(v)
    elif isinstance(data, list):
        out += [data.line, list(data.item_lines)]
        for v in data:
            out += _lines(v)
    return out


def test_every_shipped_profile_reads_back_the_same_data_and_lines(cache, monkeypatch):
    for e in profiles.profile_index():
        parsed = load_yaml(e.path, cached=True)             # parsed, and kept
        assert len(list(cache.glob("*.pickle"))) >= 1
        monkeypatch.setattr("profidrive_cli.datafile.load_yaml_text",
                            lambda *a, **k: pytest.fail("parsed again"))
        again = load_yaml(e.path, cached=True)              # from the cache only
        monkeypatch.undo()
        monkeypatch.setenv("PDRIVE_CACHE_DIR", str(cache))
        assert again == parsed and again is not parsed
        assert type(again) is LineDict
        assert _lines(again) == _lines(parsed)
        assert again == load_yaml(e.path)                   # what the plain parse gives
    assert len(list(cache.glob("*.pickle"))) == len(profiles.profile_index())


def test_a_profile_loaded_through_the_cache_is_the_same_profile(cache):
    for e in profiles.profile_index():
        first = profiles.load_profile_file(e.path)
        second = profiles.load_profile_file(e.path)         # from the cache
        assert second.name == first.name and second.parameters.keys() == first.parameters.keys()
        assert second.raw == first.raw and _lines(second.raw) == _lines(first.raw)


def test_a_changed_file_is_parsed_anew(cache, tmp_path):
    f = tmp_path / "d.yaml"
    f.write_text("a: 1\nb: [x, y]\n")
    assert load_yaml(f, cached=True) == {"a": 1, "b": ["x", "y"]}
    f.write_text("a: 2\n\nb: [x]\n")
    d = load_yaml(f, cached=True)
    assert d == {"a": 2, "b": ["x"]} and d.line_of("b") == 3
    assert len(list(cache.glob("*.pickle"))) == 2


def test_an_error_is_never_kept_and_still_says_file_and_line(cache, tmp_path):
    f = tmp_path / "bad.yaml"
    f.write_text("a: 1\nb: [unclosed\n")
    for _ in range(2):
        with pytest.raises(DataFileError) as e:
            load_yaml(f, cached=True)
        assert "bad.yaml" in str(e.value)
    assert not cache.exists() or not list(cache.glob("*.pickle"))


def test_a_cache_file_that_is_not_our_data_is_refused_and_replaced(cache, tmp_path, monkeypatch):
    f = tmp_path / "d.yaml"
    f.write_text("a: 1\n")
    load_yaml(f, cached=True)
    (entry,) = cache.glob("*.pickle")
    entry.write_bytes(pickle.dumps(os.getpid, protocol=2))   # a global an unrestricted unpickler imports
    calls = []
    monkeypatch.setattr(os, "getpid", lambda: calls.append(1))
    from profidrive_cli.datafile import _loader_class
    loader = _loader_class(None, "a: 1\n").__name__
    assert datacache.get("a: 1\n", loader) is datacache.MISS and calls == []     # refused, not called
    assert load_yaml(f, cached=True) == {"a": 1}            # parsed anew
    with open(entry, "rb") as g:                            # and the entry written anew
        assert pickle.load(g) == {"a": 1}
    entry.write_bytes(b"\x80\x05garbage")
    assert load_yaml(f, cached=True) == {"a": 1}


def test_the_cache_keeps_at_most_its_bound_and_drops_the_oldest(cache, tmp_path, monkeypatch):
    monkeypatch.setattr(datacache, "MAX_ENTRIES", 3)
    f = tmp_path / "d.yaml"
    for i in range(5):
        f.write_text(f"n: {i}\n")
        load_yaml(f, cached=True)
        for j, p in enumerate(sorted(cache.glob("*.pickle"), key=lambda p: p.stat().st_mtime_ns)):
            os.utime(p, ns=(j * 10**9, j * 10**9))           # in the order written, whatever the clock
    kept = sorted(cache.glob("*.pickle"))
    assert len(kept) == 3
    values = sorted(pickle.loads(p.read_bytes())["n"] for p in kept)
    assert values == [2, 3, 4]


def test_off_and_unwritable_change_nothing(tmp_path, monkeypatch):
    f = tmp_path / "d.yaml"
    f.write_text("a: 1\n")
    monkeypatch.setenv("PDRIVE_CACHE_DIR", "off")
    assert datacache.cache_dir() is None
    assert load_yaml(f, cached=True) == {"a": 1}
    blocked = tmp_path / "file-not-dir"
    blocked.write_text("")
    monkeypatch.setenv("PDRIVE_CACHE_DIR", str(blocked / "sub"))
    assert load_yaml(f, cached=True) == {"a": 1}
    monkeypatch.delenv("PDRIVE_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert datacache.cache_dir() == tmp_path / "xdg" / "pdrive" / "yaml"


def test_the_pure_loader_is_not_answered_from_libyamls_entry(cache, tmp_path, monkeypatch):
    f = tmp_path / "d.yaml"
    f.write_text("a: 1\n")
    load_yaml(f, cached=True)
    monkeypatch.setenv("PDRIVE_PURE_YAML", "1")
    load_yaml(f, cached=True)
    from profidrive_cli.datafile import _CLoader
    assert len(list(cache.glob("*.pickle"))) == (2 if _CLoader is not None else 1)
