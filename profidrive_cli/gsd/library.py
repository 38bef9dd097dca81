"""The GSD library: pdrive's own files (`gsd/` at the repo root, `profidrive_cli/gsd_files` when installed)
plus the user's folders (`--gsd-dir DIR`, then `$PDRIVE_GSD_DIR`). User files win over the library: a
lookup by ident searches the user folders first.

Parsed files are cached per path, keyed by (mtime, size), so naming every station of a bus scan parses each
file once per process. A lookup by ident first reads only the `Ident_Number` line of each candidate file
(also cached), then parses the one that matches. Naming a station from pdrive's own library reads only
the `Vendor_Name` / `Model_Name` lines of that file (the tests parse every library file and check the
name is the parsed one); a user's file is parsed in full, so one that does not parse never names one.
The parser is imported on the first parse.

A file that does not parse (or is incomplete) never shadows another: lookups skip it with one warning on
stderr that names it. A user folder that does not exist is an error, whether it comes from --gsd-dir or
$PDRIVE_GSD_DIR (station naming in a bus scan only warns and goes on with the library).
"""

from __future__ import annotations

import os
import re
import sys
from dataclasses import dataclass
from pathlib import Path

from profidrive_cli import UsageError
from profidrive_cli.data import gsd_dir, user_gsd_dirs
from typing import TYPE_CHECKING

from profidrive_cli.datafile import DataFileError, read_input_file, short
from profidrive_cli.gsd.lexer import MAX_GSD_BYTES, MAX_NUMBER_CHARS, decode

if TYPE_CHECKING:
    from profidrive_cli.gsd.model import Gsd

# .gsd is the default language; .gse English, .gsg German, .gsf French, .gsi Italian, .gsp Portuguese,
# .gss Spanish. In one folder, for one file stem, the first in this order is used.
GSD_SUFFIXES = (".gsd", ".gse", ".gsg", ".gsf", ".gsi", ".gsp", ".gss")

_IDENT = re.compile(r"^[ \t]*Ident_Number[ \t]*=[ \t]*(0[xX][0-9a-fA-F]+|[0-9]+)", re.I | re.M)
#: a one-line quoted name; anything else (continued lines, no quotes) leaves naming to the parser
_NAME = {k: re.compile(rf'^[ \t]*{k}[ \t]*=[ \t]*"([^"\r\n]*)"[ \t]*(?:;[^\r\n]*)?\r?$', re.I | re.M)
         for k in ("Vendor_Name", "Model_Name")}

_warned: set[str] = set()


def _warn_stderr(message: str) -> None:
    sys.stderr.write(f"pdrive: warning: {message}\n")


warn_hook = _warn_stderr     # where skipped files / folders are reported (once per message and process)


def _warn(message: str) -> None:
    if message not in _warned:
        _warned.add(message)
        warn_hook(message)

_parsed: dict[str, tuple[tuple[int, int], Gsd]] = {}
#: path -> (stamp, (ident, title from the header lines or None))
_heads: dict[str, tuple[tuple[int, int], tuple[int | None, str | None]]] = {}


def parse_gsd(path: str | Path) -> Gsd:
    """gsd.parser.parse_gsd, imported on first use (naming stations needs no parser)."""
    from profidrive_cli.gsd.parser import parse_gsd as parse
    return parse(path)


def _stamp(p: Path) -> tuple[int, int]:
    st = p.stat()
    return st.st_mtime_ns, st.st_size


def clear_cache() -> None:
    _parsed.clear()
    _heads.clear()
    _warned.clear()


def parse_cached(path: str | Path) -> Gsd:
    """parse_gsd with a per-process cache keyed by (path, mtime, size)."""
    p = Path(path)
    try:
        stamp = _stamp(p)
    except FileNotFoundError:
        raise DataFileError(p, None, "file not found") from None
    except OSError as e:
        raise DataFileError(p, None, f"cannot read: {e.strerror or e}") from None
    key = str(p.resolve())
    hit = _parsed.get(key)
    if hit and hit[0] == stamp:
        return hit[1]
    g = parse_gsd(p)
    _parsed[key] = (stamp, g)
    return g


def _head(path: str | Path) -> tuple[int | None, str | None]:
    """(Ident_Number, "Vendor Model") of a GSD file from its header lines, without parsing it;
    cached per path like parsed files. The title is None when the name lines are not plain one-line
    strings (or both are empty)."""
    p = Path(path)
    try:
        stamp = _stamp(p)
    except OSError:
        return None, None
    key = str(p.resolve())
    hit = _heads.get(key)
    if hit and hit[0] == stamp:
        return hit[1]
    try:
        text, _ = decode(read_input_file(p, "GSD file", MAX_GSD_BYTES))
    except DataFileError:
        return None, None
    m = _IDENT.search(text)
    ident = None
    if m and len(m.group(1)) <= MAX_NUMBER_CHARS:
        t = m.group(1)
        ident = int(t[2:], 16) if t[:2].lower() == "0x" else int(t)
    parts = []
    for rx in _NAME.values():
        n = rx.search(text)
        if n and n.group(1).strip():
            parts.append(n.group(1).strip())
    _heads[key] = (stamp, (ident, " ".join(parts) or None))
    return _heads[key][1]


def quick_ident(path: str | Path) -> int | None:
    """The Ident_Number of a GSD file from its first `Ident_Number =` line (no full parse); None if absent."""
    return _head(path)[0]


def _user_dirs(extra_dir: str | Path | None, strict: bool = True) -> list[Path]:
    """--gsd-dir, then each folder of $PDRIVE_GSD_DIR. One that is not a folder raises UsageError
    (strict) or is skipped with a warning."""
    labelled = []
    if extra_dir is not None:
        labelled.append(("--gsd-dir", Path(extra_dir)))
    labelled += [("PDRIVE_GSD_DIR", d) for d in user_gsd_dirs(None)]
    out = []
    for label, d in labelled:
        if d.is_dir():
            out.append(d)
            continue
        why = "not a folder" if os.path.exists(d) else "no such folder"
        if strict:
            raise UsageError(f"{label} {d}: {why}")
        _warn(f"{label} {d}: {why} (ignored)")
    return out


def search_dirs(extra_dir: str | Path | None = None, strict: bool = True) -> list[tuple[Path, str]]:
    """(folder, "user" | "library") in lookup order: user folders first. A user folder that is not a
    folder raises UsageError (strict) or is skipped with a warning."""
    out = [(d, "user") for d in _user_dirs(extra_dir, strict)]
    lib = gsd_dir()
    if lib.is_dir():
        out.append((lib, "library"))
    return out


def gsd_files(folder: Path) -> list[Path]:
    """GSD files in one folder (not recursive), one per stem, sorted by name."""
    by_stem: dict[str, Path] = {}
    try:
        entries = sorted(folder.iterdir(), key=lambda p: p.name.lower())
    except OSError:
        return []
    for p in entries:
        suf = p.suffix.lower()
        if suf not in GSD_SUFFIXES or not p.is_file():
            continue
        stem = p.stem.lower()
        old = by_stem.get(stem)
        if old is None or GSD_SUFFIXES.index(suf) < GSD_SUFFIXES.index(old.suffix.lower()):
            by_stem[stem] = p
    return sorted(by_stem.values(), key=lambda p: p.name.lower())


@dataclass
class LibraryEntry:
    path: Path
    source: str                  # "user" | "library"
    ident: int | None
    vendor: str | None = None
    model: str | None = None
    modules: int = 0
    error: str | None = None     # the parse error, if the file does not parse
    shadowed_by: Path | None = None   # a user file with the same ident that wins over this one

    def to_dict(self) -> dict[str, str | int | None]:
        return {"path": str(self.path), "source": self.source,
                "ident": self.ident, "ident_hex": None if self.ident is None else f"0x{self.ident:04X}",
                "vendor": self.vendor, "model": self.model, "modules": self.modules, "error": self.error,
                "shadowed_by": None if self.shadowed_by is None else str(self.shadowed_by)}


def list_library(extra_dir: str | Path | None = None) -> list[LibraryEntry]:
    """Every GSD file of the user folders and the library, user files first. Broken files are listed
    with their error instead of raising."""
    out: list[LibraryEntry] = []
    first_by_ident: dict[int, Path] = {}
    for folder, source in search_dirs(extra_dir):
        for p in gsd_files(folder):
            try:
                g = parse_cached(p)
                e = LibraryEntry(path=p, source=source, ident=g.ident_number, vendor=g.vendor_name,
                                 model=g.model_name, modules=len(g.modules))
            except DataFileError as err:
                e = LibraryEntry(path=p, source=source, ident=quick_ident(p), error=str(err))
            if e.ident is not None and e.error is None:
                if e.ident in first_by_ident:
                    e.shadowed_by = first_by_ident[e.ident]
                else:
                    first_by_ident[e.ident] = p
            out.append(e)
    return out


def _find(ident: int, extra_dir: str | Path | None, strict: bool = True) -> tuple[Path, Gsd] | None:
    """The first file (user folders first) whose Ident_Number is `ident` and that parses; a candidate
    that does not parse is skipped with a warning naming it, so it never shadows a good file."""
    for folder, _ in search_dirs(extra_dir, strict):
        for p in gsd_files(folder):
            if quick_ident(p) != ident:
                continue
            try:
                g = parse_cached(p)
            except DataFileError as e:
                _warn(f"skipped a GSD file that does not parse: {e}")
                continue
            if g.ident_number == ident:
                return p, g
    return None


def find_path_by_ident(ident: int, extra_dir: str | Path | None = None) -> Path | None:
    """The path of the GSD file find_by_ident would use; None if no file has the ident."""
    hit = _find(ident, extra_dir)
    return None if hit is None else hit[0]


def find_by_ident(ident: int, extra_dir: str | Path | None = None) -> Gsd | None:
    """The GSD for a PROFIBUS ident number: user folders first, then the library; None if no readable
    file has it. Files that do not parse are skipped with a warning; a missing user folder raises."""
    hit = _find(ident, extra_dir)
    return None if hit is None else hit[1]


def station_name(ident: int, extra_dir: str | Path | None = None) -> str | None:
    """"Vendor Model" for an ident, for naming stations in a bus scan; None when unknown. Missing user
    folders and broken files are reported as warnings, not errors: a name is only a label."""
    dirs = search_dirs(extra_dir, strict=False)
    if not any(quick_ident(p) == ident for folder, source in dirs if source == "user"
               for p in gsd_files(folder)):
        # no user file can win: pdrive's own file (they all parse, the tests check) names it by
        # its header lines, without importing the parser
        for folder, _ in dirs:
            hit = next((h for h in map(_head, gsd_files(folder)) if h[0] == ident), None)
            if hit is not None and hit[1] is not None:
                return hit[1]
    found = _find(ident, extra_dir, strict=False)
    return None if found is None else found[1].title


def _as_ident(text: str) -> int | None:
    t = text.strip()
    if re.fullmatch(r"0[xX][0-9a-fA-F]{1,4}", t):
        return int(t, 16)
    if t.isascii() and t.isdigit() and len(t) <= 5 and int(t) <= 0xFFFF:
        return int(t)
    return None


def load_gsd(path_or_ident: str | Path | int, extra_dir: str | Path | None = None) -> Gsd:
    """A GSD by file path, by ident (int, "0x00CA", "202") or by library file name ("YASK00CA.GSD" or
    "YASK00CA"). Raises UsageError / DataFileError (one line) when nothing fits or the file is broken."""
    if isinstance(path_or_ident, int) and not isinstance(path_or_ident, bool):
        g = find_by_ident(path_or_ident, extra_dir)
        if g is None:
            raise UsageError(f"no GSD file with ident 0x{path_or_ident:04X} in the library"
                             + ("" if extra_dir else " (add your vendor's file with --gsd-dir DIR)"))
        return g
    if isinstance(path_or_ident, bool):
        raise TypeError(f"load_gsd: a path, a file name or an ident, not {path_or_ident!r}")
    p = Path(path_or_ident)
    try:
        is_file, exists = p.is_file(), p.exists()
    except (OSError, ValueError):        # a name too long for a path, a NUL in it
        is_file = exists = False
    if is_file:
        return parse_cached(p)
    text = str(path_or_ident)
    ident = _as_ident(text)
    if ident is not None:
        return load_gsd(ident, extra_dir)
    if p.parent == Path(".") or str(p.parent) == "":
        want = text.strip().lower()
        for folder, _ in search_dirs(extra_dir):
            for q in gsd_files(folder):
                if q.name.lower() == want or q.stem.lower() == want:
                    return parse_cached(q)
    if exists:
        raise DataFileError(p, None, "is not a file")
    raise UsageError(f"{short(text)[1:-1]}: no such GSD file, ident or library name (try `pdrive gsd list`)")
