"""The black-box recorder's captures on disk (`sniff --ring --out`, issue 35): the file pattern, the
recorder's own files, the disk bound and the write faults -- so that a recorder left running for days
keeps recording whatever the disk does.

- The pattern (`--out`) is checked at start against every value each of its fields can carry (the
  capture number, the time, every trigger form, stations 0..126 and `bus`): a field that fails for
  any of them is refused then (UsageError, naming the field), never at the first bus-wide event.
  Its fields belong in the file name: the recorder keeps its captures in one directory, where it
  finds its own files again by the pattern (and only those: another file there is never touched).
- The disk bound: before each write the recorder's own files are listed and, oldest first (by
  modification time), removed while the new capture would take them over `max_bytes` or while they
  are older than `keep_s`; each removal is an event (`Removed`, counted). A capture larger than the
  bound alone is not written (`Failed`).
- A capture that cannot be written (disk full, read-only, directory gone, I/O error) is an event
  (`Failed`: the path and the operating system's words) and the recording goes on. On a full file
  system (ENOSPC, EDQUOT) the oldest own captures make room for the new one when they can (the
  free space and their sizes say so; each removal an event) and the write is tried once more;
  when they cannot, the disk is full: a state, reported when it starts and when a write succeeds
  again (`DiskState`), the own captures kept.

The file system is reached only through `Disk` (list, remove, write through outfile.OutputFile, the
wall clock); a test or the soak gives one of its own that fills, frees and fails.
"""

from __future__ import annotations

import errno
import os
import re
import string
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import IO, Any

from profidrive_cli import PdriveError, UsageError
from profidrive_cli.bustools.triggers import MAX_STATION, every_label
from profidrive_cli.outfile import OutputFile, check_output_path

#: the file name in a --out directory; a pattern may use the same fields
DEFAULT_NAME = "pdrive-{time}-{n}-{trigger}.pcap"
FIELDS = ("n", "time", "trigger", "station")
TIME_FORMAT = "%Y%m%d-%H%M%S"
#: what each field gives when it stands alone ({n}, no format spec): its file names are matched by it
_PLAIN = {"n": r"[0-9]+", "time": r"[0-9]{8}-[0-9]{6}", "trigger": r"[A-Za-z0-9-]+",
          "station": r"(?:[0-9]+|bus)"}
#: the errno values of a full file system (no space, quota exceeded): the "disk full" state
DISK_FULL = frozenset({errno.ENOSPC, errno.EDQUOT})
#: --max-disk when none is given: 1 GiB. The largest capture (the ring's 250,000 telegrams before
#: and 250,000 after, bustools/recorder.py MAX_RING, at 16 + 21 octets each in the pcap) is about
#: 18.5 MB, so 1 GiB holds at least 55 of them and thousands of ordinary ones, and it is a small
#: part of the smallest card a Raspberry Pi runs from (8 GB)
DEFAULT_MAX_DISK = 1 << 30
_UNITS = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}


def file_trigger(label: str) -> str:
    """lost(3) -> lost3, cycle(*)>20ms -> cycleall: safe in a file name."""
    return "".join(ch for ch in label.replace("*", "all").split(">")[0] if ch.isalnum() or ch == "-")


def parse_size(text: str, what: str = "--max-disk") -> int:
    """100M, 2G, 512K, 1.5G, 1000000 (bytes; K, M, G, T are powers of 1024, an optional B or iB
    after them) -> bytes, above 0; UsageError otherwise."""
    m = re.fullmatch(r"\s*([0-9]+(?:\.[0-9]*)?)\s*([KMGT]?)(?:i?B)?\s*", text, re.IGNORECASE)
    if not m:
        raise UsageError(f"{what} {text!r}: expected a size such as 100M or 2G (K, M, G, T: "
                         f"powers of 1024)")
    size = int(float(m.group(1)) * _UNITS[m.group(2).upper()])
    if size <= 0:
        raise UsageError(f"{what} {text!r}: must be above 0")
    return size


def size_text(n: int) -> str:
    """Bytes in words: 1073741824 -> 1 GiB, 104857600 -> 100 MiB, 1536 -> 1.5 KiB, 512 -> 512 B."""
    for unit, factor in (("TiB", 1 << 40), ("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if n >= factor:
            return f"{n / factor:.4g} {unit}"
    return f"{n} B"


def _values() -> dict[str, list[tuple[Any, str]]]:
    """Every kind of value each field can carry, with the words that name it in a refusal."""
    return {
        "n": [(1, "capture 1"), (10 ** 9, "capture 1000000000")],
        "time": [("20261126-140556", "the event's time (YYYYMMDD-HHMMSS)")],
        "trigger": [(file_trigger(label), f"trigger {label}") for label in every_label()],
        "station": [(0, "station 0"), (MAX_STATION, f"station {MAX_STATION}"),
                    ("bus", "station bus (a bus-wide event: fcs, framing)")],
    }


_SAMPLE = {"n": 1, "time": "20261126-140556", "trigger": "lost3", "station": 3}


@dataclass(frozen=True)
class Pattern:
    """A checked --out pattern: where its captures go and how its own files are known again."""
    text: str
    directory: Path
    name_rx: re.Pattern[str]

    def path(self, n: int, wall: float, trigger_label: str, station: int | None) -> str:
        stamp = datetime.fromtimestamp(wall).strftime(TIME_FORMAT)
        return self.text.format(n=n, time=stamp, trigger=file_trigger(trigger_label),
                                station="bus" if station is None else station)

    def _match(self, name: str) -> re.Match[str] | None:
        m = self.name_rx.fullmatch(name)
        if m is None:                              # the -N of a second capture of the same name
            stem, dot, ext = name.rpartition(".")
            bare = re.sub(r"-[0-9]+$", "", stem if dot else name)
            m = self.name_rx.fullmatch(f"{bare}.{ext}" if dot else bare)
        return m

    def owns(self, name: str) -> bool:
        """A file name the pattern gives (also with the `-N` a second capture of the same name gets
        before its extension)."""
        return self._match(name) is not None

    def number(self, name: str) -> int | None:
        """The capture number in one of its file names (a pattern with a plain {n}), else None."""
        m = self._match(name)
        return int(m.group("n")) if m is not None and "n" in self.name_rx.groupindex else None


def unique(path: str, n: int) -> str:
    """The path for capture n when `path` is taken already (two captures in one second, {time}
    only): -n before the file name's extension."""
    head, tail = os.path.split(path)
    stem, dot, ext = tail.rpartition(".")
    return os.path.join(head, f"{stem}-{n}.{ext}" if dot else f"{tail}-{n}")


def check_pattern(pattern: str, shown: str | None = None) -> Pattern:
    """A --out file pattern, checked before the port opens: only the known fields, each of them
    formatting every value it can carry, none in the directory part, {n} or {time} present, the
    directory writable. UsageError (exit 2), one line naming the field."""
    where = f"--out {shown if shown is not None else pattern}"
    try:
        parts = list(string.Formatter().parse(pattern))
    except ValueError as e:
        raise UsageError(f"{where}: {e} (a literal brace is written {{{{ or }}}})") from None
    names: list[str] = []
    values = _values()
    for _, name, spec, conv in parts:
        if name is None:
            continue
        field = "{" + name + (f"!{conv}" if conv else "") + (f":{spec}" if spec else "") + "}"
        base = re.split(r"[.\[]", name, maxsplit=1)[0]
        if base not in FIELDS:
            raise UsageError(f"{where}: {field}: a pattern may use only "
                             + ", ".join("{" + f + "}" for f in FIELDS))
        names.append(base)
        for key in [base] + [k for k in FIELDS if k != base]:     # its own values named first
            for value, words in values[key]:
                try:
                    field.format(**{**_SAMPLE, key: value})
                except Exception as e:        # format runs the spec on the value: anything may come
                    raise UsageError(f"{where}: the field {field} fails for {words}: "
                                     f"{type(e).__name__}: {e}") from None
    head, tail = os.path.split(pattern)
    for _, name, _, _ in string.Formatter().parse(head):
        if name is not None:
            raise UsageError(f"{where}: {{{name}}} is in the directory; the fields belong in the file "
                             f"name (the recorder keeps its captures in one directory and creates none)")
    if "n" not in names and "time" not in names:
        raise UsageError(f"{where}: not a directory, and as a file pattern it needs {{n}} or {{time}} "
                         f"(one file per event), e.g. events/ev-{{time}}-{{n}}.pcap")
    rx: list[str] = []
    for literal, name, spec, conv in string.Formatter().parse(tail):
        rx.append(re.escape(literal))
        if name is not None:
            plain = name in _PLAIN and not spec and not conv
            first_n = plain and name == "n" and "(?P<n>" not in "".join(rx)
            rx.append(f"(?P<n>{_PLAIN[name]})" if first_n else _PLAIN[name] if plain else ".+?")
    check_output_path(pattern.format(**_SAMPLE), "--out")
    directory = "".join(lit for lit, _, _, _ in string.Formatter().parse(head)) if head else "."
    return Pattern(pattern, Path(directory), re.compile("".join(rx)))


def out_pattern(out_opt: str | None) -> Pattern:
    """--out DIR (an existing directory: DEFAULT_NAME in it) or a file pattern; checked."""
    target = out_opt or "."
    if Path(target).is_dir():
        return check_pattern(str(Path(target) / DEFAULT_NAME), target)
    return check_pattern(target)


# -- the store ------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Removed:
    """One of the recorder's own captures removed to keep the bound (`why`), or not removable."""
    path: str
    size: int
    why: str
    count: int                   # removals so far (this one included)
    error: str | None = None     # the file could not be removed: the operating system's words


@dataclass(frozen=True)
class Failed:
    """A capture not written: its number, the path it was meant for and why."""
    n: int
    path: str
    reason: str
    full: bool                   # the disk is full (ENOSPC, EDQUOT)


@dataclass(frozen=True)
class DiskState:
    """The disk became full (a write failed for lack of space) or has room again (a write succeeded)."""
    full: bool
    directory: str
    reason: str


class Disk:
    """The file system as the store uses it; a test gives its own (full, read-only, failing)."""

    def files(self, directory: Path) -> list[tuple[str, int, float]]:
        """(name, size, modification time) of each regular file in `directory`."""
        out = []
        with os.scandir(directory) as it:
            for e in it:
                try:
                    if e.is_file(follow_symlinks=False):
                        st = e.stat(follow_symlinks=False)
                        out.append((e.name, st.st_size, st.st_mtime))
                except OSError:
                    continue                       # gone while listed
        return out

    def remove(self, path: Path) -> None:
        os.unlink(path)

    def write(self, path: str, fill: Callable[[IO[bytes]], None]) -> None:
        """The file through OutputFile (replaces `path` only when complete); raises its errors."""
        f = OutputFile(path, "wb", what="--out")
        try:
            f.open()
            fill(f)                                # type: ignore[arg-type]
            f.commit()
        finally:
            if not f.committed:
                f.discard()

    def free(self, directory: Path) -> int | None:
        """Bytes free for an ordinary user on the directory's file system (None: not known)."""
        try:
            st = os.statvfs(directory)
        except (OSError, AttributeError):           # no statvfs on Windows
            return None
        return st.f_bavail * st.f_frsize

    def now(self) -> float:
        return time.time()


def _why(e: Exception) -> tuple[str, int | None]:
    """The operating system's words and errno of a failed write (OSError or outfile's errors)."""
    if isinstance(e, OSError):
        return e.strerror or str(e), e.errno
    return getattr(e, "reason", None) or str(e), getattr(e, "errno", None)


Event = Removed | Failed | DiskState


class Store:
    """The recorder's captures in the pattern's directory, within `max_bytes` (None: no bound) and
    `keep_s` seconds (None: any age). save() writes one and says what happened on the way."""

    def __init__(self, pattern: Pattern, max_bytes: int | None = DEFAULT_MAX_DISK,
                 keep_s: float | None = None, disk: Disk | None = None):
        self.pattern = pattern
        self.max_bytes = max_bytes
        self.keep_s = keep_s
        self.disk = disk or Disk()
        self.written = 0
        self.failed = 0
        self.removed = 0
        self.full = False
        self.first_failure: Failed | None = None

    def save(self, n: int, path: str, size: int,
             fill: Callable[[IO[bytes]], None]) -> tuple[bool, list[Event]]:
        """Write capture n (`size` bytes, written by `fill`) at `path` after making room for it:
        (written, the events on the way, in order)."""
        if self.max_bytes is not None and size > self.max_bytes:
            return False, [self._failed(Failed(n, path, f"{size_text(size)}: more than --max-disk "
                                                        f"{size_text(self.max_bytes)} alone", False))]
        events: list[Event] = list(self._make_room(size))
        why = self._write(path, fill)
        if why is not None and why[1] in DISK_FULL:
            # the file system is full below the bound (other files took the space): the oldest own
            # captures make room for the newest, as the bound does, and the write is tried again
            freed = self._make_room(size, full=why[0])
            events += freed
            if any(r.error is None for r in freed):
                why = self._write(path, fill)
        if why is not None:
            reason, code = why
            full = code in DISK_FULL
            if full and not self.full:
                self.full = True
                events.append(DiskState(True, str(self.pattern.directory), reason))
            events.append(self._failed(Failed(n, path, reason, full)))
            return False, events
        if self.full:
            self.full = False
            events.append(DiskState(False, str(self.pattern.directory), "a capture was written"))
        self.written += 1
        return True, events

    def _write(self, path: str, fill: Callable[[IO[bytes]], None]) -> tuple[str, int | None] | None:
        """None when written, else the operating system's words and errno."""
        try:
            self.disk.write(path, fill)
        except (OSError, PdriveError) as e:
            return _why(e)
        return None

    def last_number(self) -> int:
        """The highest capture number of the own files already there (an earlier run's; 0: none,
        or a pattern without a plain {n}): the recorder numbers on from it, so that a restart
        (systemd, a reboot) never writes over an earlier capture of the same number."""
        try:
            files = self.disk.files(self.pattern.directory)
        except OSError:
            return 0
        return max((n for n in (self.pattern.number(f[0]) for f in files) if n is not None), default=0)

    def _failed(self, f: Failed) -> Failed:
        self.failed += 1
        if self.first_failure is None:
            self.first_failure = f
        return f

    def _make_room(self, size: int, full: str | None = None) -> list[Removed]:
        """Oldest first: the own files older than keep_s, then while the new one would go over the
        bound -- or, on a full disk (`full`: the reason), until as much as it needs is freed."""
        d = self.pattern.directory
        try:
            own = [f for f in self.disk.files(d) if self.pattern.owns(f[0])]
        except OSError:
            return []                              # the write that follows says what is wrong
        own.sort(key=lambda f: (f[2], f[0]))
        used = sum(f[1] for f in own)
        now = self.disk.now()
        # on a full disk only what the new capture lacks: nothing when the space is there (the
        # ENOSPC came from elsewhere -- inodes, a quota -- and removing would not help)
        freed = 0 if full is None else self._free(d)
        if full is not None and freed + used < size:
            return []                              # all of them would not make room: keep them
        out: list[Removed] = []
        for name, fsize, mtime in own:
            old = self.keep_s is not None and now - mtime > self.keep_s
            over = self.max_bytes is not None and used + size > self.max_bytes
            short = full is not None and freed < size
            if not (old or over or short):
                break                              # the rest are newer, and there is room
            why = (f"older than --keep {self.keep_s / 86400:g} days" if old and self.keep_s
                   else f"--max-disk {size_text(self.max_bytes or 0)}" if over
                   else f"disk full ({full})")
            path = str(d / name)
            try:
                self.disk.remove(Path(path))
            except OSError as e:                   # the next ones would fail alike (read-only)
                out.append(Removed(path, fsize, why, self.removed, e.strerror or str(e)))
                break
            used -= fsize
            freed += fsize
            self.removed += 1
            out.append(Removed(path, fsize, why, self.removed))
        return out

    def _free(self, d: Path) -> int:
        try:
            return max(0, self.disk.free(d) or 0)
        except OSError:
            return 0


__all__ = ["DEFAULT_MAX_DISK", "DEFAULT_NAME", "Disk", "DiskState", "Failed", "Pattern", "Removed",
           "Store", "check_pattern", "file_trigger", "out_pattern", "parse_size", "size_text",
           "unique"]
