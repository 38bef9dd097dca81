"""The monitor's history (issue 37): `monitor.sqlite3` (stdlib sqlite3, schema in docs/monitor.md) and
its `captures/` directory, in one directory the user names (`--db DIR`; pdrive creates no directory
the user named, only its own `captures/` inside it).

What it promises, for a monitor left on a line for weeks:

- One disk bound (`max_bytes`) over the database, its -wal and -shm files and the own captures:
  before a write, while the total would go over it, the oldest go first -- everything (sample rows,
  bus rows, events, capture files) up to a cut-off time, so that nothing newer goes before
  something older; the stations table and the runs are kept; an event whose capture went keeps its
  row (its capture shows as gone). The database gives the pages back (auto_vacuum=INCREMENTAL,
  incremental_vacuum, a TRUNCATE checkpoint), so the file shrinks. After a write the total is
  within the bound (a reader holding the WAL may delay the checkpoint to the next write). Every
  removal is counted and reported (StoreNote "removed").
- `keep_s`: rows and captures older than the newest time written minus keep_s go too (the
  caller's clock -- the virtual plant's in a soak -- never time.time()).
- A full disk (SQLITE_FULL, ENOSPC/EDQUOT on a capture) is a state: StoreNote "full" once, the
  rows wait in a bounded queue (`pending_max` rows, the oldest dropped and counted), retried on the
  next writes; StoreNote "room" when a write succeeds again. Any other fault: StoreNote "failed",
  and it goes on. No write method raises.
- A restart resumes: the earlier rows are there, a new run row, capture numbers go on.
- Reads go through `Reader` (reader()): a connection of its own (WAL: readers never block the
  writer), every query bounded (limits, at most MAX_BUCKETS trend buckets).
"""

from __future__ import annotations

import json
import math
import os
import re
import sqlite3
import threading
from collections import deque
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import IO, Any

from profidrive_cli import PdriveError, UsageError
from profidrive_cli.bustools.ringstore import DISK_FULL, Disk, _why, size_text
from profidrive_cli.dp.capture import PcapWriter
from profidrive_cli.monitor.model import (SAMPLE_COUNTERS, BusSample, MonEvent, Sample,
                                          StationInfo, StoreNote)

DB_NAME = "monitor.sqlite3"
CAPTURES_DIR = "captures"
DEFAULT_MAX_BYTES = 1 << 30
SCHEMA_VERSION = 1
#: the smallest bound a store is opened with: an empty database (about 15 pages of 4 KiB), its
#: -shm (32 KiB) and the WAL of a few writes
MIN_MAX_BYTES = 256 << 10
#: what an empty store takes beside its rows: the database's schema pages, the -shm, one write's WAL
_BASE_BYTES = 160 << 10
#: the most the writer waits for a reader (a TRUNCATE checkpoint waits for the readers to leave the
#: WAL; past this it checkpoints what it can and tries again later): the monitor's loop never waits
#: long for the web page
BUSY_S = 0.1
#: the pcap link type of the captures (LINKTYPE_PROFIBUS_DL)
LINKTYPE = 147
#: the most buckets a trend has (the page's plots are a few hundred pixels wide)
MAX_BUCKETS = 2000
#: the most rows one read returns
MAX_LIMIT = 10_000
APP = "pdrive monitor"
#: an own capture file's name: number, hint
CAPTURE_RX = re.compile(r"(?P<n>[0-9]{6,})-(?P<hint>[A-Za-z0-9_-]{0,40})\.pcap")
_TMP_RX = re.compile(r"\.[0-9]{6,}-[A-Za-z0-9_-]{0,40}\.pcap\..*\.tmp")
_HINT_BAD = re.compile(r"[^A-Za-z0-9_-]+")

_SCHEMA = [
    "CREATE TABLE meta(key TEXT PRIMARY KEY, value TEXT NOT NULL)",
    "CREATE TABLE runs(id INTEGER PRIMARY KEY, started REAL NOT NULL, ended REAL, port TEXT NOT NULL,"
    " baud INTEGER, end_reason TEXT)",
    "CREATE TABLE stations(station INTEGER PRIMARY KEY, ident INTEGER, profile TEXT,"
    " first_seen REAL NOT NULL, last_seen REAL NOT NULL, state TEXT NOT NULL)",
    "CREATE TABLE samples(id INTEGER PRIMARY KEY, t REAL NOT NULL, interval_s REAL NOT NULL,"
    " station INTEGER NOT NULL, state TEXT NOT NULL, "
    + ", ".join(f"{c} INTEGER NOT NULL DEFAULT 0" for c in SAMPLE_COUNTERS)
    + ", cycle_mean_s REAL)",
    "CREATE INDEX samples_station_t ON samples(station, t)",
    "CREATE TABLE bus_samples(id INTEGER PRIMARY KEY, t REAL NOT NULL, interval_s REAL NOT NULL,"
    " frames INTEGER NOT NULL, tokens INTEGER NOT NULL, errors INTEGER NOT NULL,"
    " load_percent REAL, rotation_s REAL, masters TEXT NOT NULL)",
    "CREATE INDEX bus_samples_t ON bus_samples(t)",
    "CREATE TABLE events(id INTEGER PRIMARY KEY, t REAL NOT NULL, kind TEXT NOT NULL, station INTEGER,"
    " text TEXT NOT NULL, cause TEXT, evidence TEXT NOT NULL, repeats INTEGER NOT NULL,"
    " capture TEXT)",
    "CREATE INDEX events_t ON events(t)",
    "CREATE INDEX events_station_t ON events(station, t)",
    "CREATE TABLE captures(number INTEGER PRIMARY KEY, name TEXT NOT NULL UNIQUE, t REAL NOT NULL,"
    " bytes INTEGER NOT NULL)",
]


def _is_full(e: BaseException) -> bool:
    if isinstance(e, sqlite3.OperationalError):
        code = getattr(e, "sqlite_errorcode", None)
        return code == 13 or "database or disk is full" in str(e)       # SQLITE_FULL
    if isinstance(e, OSError):
        return e.errno in DISK_FULL
    return getattr(e, "errno", None) in DISK_FULL


def _check_directory(directory: str | os.PathLike[str], write: bool) -> Path:
    d = Path(directory)
    if not d.exists():
        raise UsageError(f"--db {d}: no such directory (pdrive creates no directory; make it first)")
    if not d.is_dir():
        raise UsageError(f"--db {d}: not a directory")
    if write and not os.access(d, os.W_OK | os.X_OK):
        raise UsageError(f"--db {d}: permission denied (the store writes its files there)")
    return d


def _check_store(con: sqlite3.Connection, path: Path) -> None:
    """UsageError unless `con` is a pdrive monitor store this pdrive reads."""
    try:
        names = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        if "meta" not in names:
            raise UsageError(f"--db {path}: not a pdrive monitor store (no meta table)")
        meta = dict(con.execute("SELECT key, value FROM meta").fetchall())
    except sqlite3.DatabaseError as e:
        raise UsageError(f"--db {path}: not a readable SQLite database ({e})") from None
    if meta.get("app") != APP:
        raise UsageError(f"--db {path}: not a pdrive monitor store (app {meta.get('app')!r})")
    try:
        version = int(meta.get("schema_version", ""))
    except ValueError:
        raise UsageError(f"--db {path}: not a pdrive monitor store (schema_version "
                         f"{meta.get('schema_version')!r})") from None
    if version > SCHEMA_VERSION:
        raise UsageError(f"--db {path}: written by a newer pdrive (schema version {version}; this "
                         f"pdrive reads version {SCHEMA_VERSION})")
    if version < 1:
        raise UsageError(f"--db {path}: not a pdrive monitor store (schema version {version})")


class _Run:
    """A run row not yet in the database (a full disk at its start)."""

    def __init__(self, t: float, port: str, baud: int | None):
        self.t, self.port, self.baud = t, port, baud
        self.prev_newest: float | None = None
        self.ended: float | None = None
        self.reason: str | None = None
        self.id: int | None = None


#: one queued row: ("sample" | "bus" | "station" | "event" | "capture" | "run" | "run_end", record)
_Item = tuple[str, Any]


class History:
    """The store in `directory` (an existing directory). UsageError (one line, the path) for a
    directory that is missing, not a directory or not writable, a database that is not a pdrive
    store, a newer schema or a damaged file, and a bound below MIN_MAX_BYTES."""

    def __init__(self, directory: str | os.PathLike[str], max_bytes: int = DEFAULT_MAX_BYTES,
                 keep_s: float | None = None, disk: Disk | None = None, pending_max: int = 10_000):
        self.directory = _check_directory(directory, write=True)
        if max_bytes < MIN_MAX_BYTES:
            raise UsageError(f"--max-disk {size_text(max_bytes)}: below the smallest store "
                             f"({size_text(MIN_MAX_BYTES)})")
        if keep_s is not None and not keep_s > 0:
            raise UsageError(f"--keep {keep_s}: must be above 0 seconds")
        self.max_bytes = max_bytes
        self.keep_s = keep_s
        self.disk = disk or Disk()
        self.pending_max = max(1, pending_max)
        self.path = self.directory / DB_NAME
        self.captures = self.directory / CAPTURES_DIR
        self.full = False
        self.removed_rows = 0
        self.removed_captures = 0
        self.dropped_pending = 0
        self.failed = 0
        self._pending: deque[_Item] = deque()
        self._run: _Run | None = None
        self._closed = False
        #: the hysteresis: a removal frees this much beyond what the write needs
        self._headroom = max(32 << 10, max_bytes // 16)
        self._wal_limit = max(64 << 10, min(8 << 20, max_bytes // 32))
        self.resumed = self.path.exists()
        if self.captures.exists() and not self.captures.is_dir():
            raise UsageError(f"--db {self.directory}: {self.captures} is not a directory")
        try:
            self.captures.mkdir(exist_ok=True)
        except OSError as e:
            raise UsageError(f"--db {self.directory}: cannot create {self.captures}: "
                             f"{e.strerror or e}") from None
        self._db = self._open()
        try:
            self._newest = self._newest_t()
            self._capture_bytes, self._next_number = self._reconcile()
        except sqlite3.DatabaseError as e:
            self._db.close()
            raise UsageError(f"--db {self.path}: damaged ({e})") from None

    # -- opening ----------------------------------------------------------------------------------
    def _open(self) -> sqlite3.Connection:
        if self.path.exists() and not self.path.is_file():
            raise UsageError(f"--db {self.path}: not a regular file")
        try:
            con = sqlite3.connect(str(self.path), isolation_level=None, timeout=BUSY_S)
        except sqlite3.Error as e:
            raise UsageError(f"--db {self.path}: cannot open ({e})") from None
        try:
            if self.resumed and self.path.stat().st_size > 0:
                _check_store(con, self.path)
            else:
                con.execute("PRAGMA auto_vacuum=INCREMENTAL")
                con.execute("PRAGMA page_size=4096")
                con.execute("BEGIN IMMEDIATE")
                for stmt in _SCHEMA:
                    con.execute(stmt)
                con.executemany("INSERT INTO meta(key, value) VALUES (?, ?)",
                                [("app", APP), ("schema_version", str(SCHEMA_VERSION))])
                con.execute("COMMIT")
                self.resumed = False
            mode = con.execute("PRAGMA journal_mode=WAL").fetchone()[0]
            if str(mode).lower() != "wal":
                raise UsageError(f"--db {self.path}: cannot use the WAL journal here ({mode})")
            con.execute("PRAGMA synchronous=NORMAL")
            con.execute(f"PRAGMA wal_autocheckpoint={max(16, self._wal_limit // 4096)}")
            con.execute(f"PRAGMA journal_size_limit={self._wal_limit}")
            self._page = int(con.execute("PRAGMA page_size").fetchone()[0])
        except UsageError:
            con.close()
            raise
        except sqlite3.DatabaseError as e:
            con.close()
            raise UsageError(f"--db {self.path}: not a readable pdrive monitor store ({e})") from None
        return con

    def _newest_t(self) -> float | None:
        vals: list[float] = []
        for q in ("SELECT max(t) FROM events", "SELECT max(t) FROM bus_samples",
                  "SELECT t FROM samples ORDER BY id DESC LIMIT 1", "SELECT max(t) FROM captures",
                  "SELECT max(started) FROM runs"):
            r = self._db.execute(q).fetchone()
            if r is not None and r[0] is not None:
                vals.append(float(r[0]))
        return max(vals) if vals else None

    def _reconcile(self) -> tuple[int, int]:
        """The captures table and the directory agreed: an own file without a row gets one, a row
        without its file goes, an own temporary file left by a crash is removed. Returns the own
        captures' bytes and the next capture number."""
        try:
            files = self.disk.files(self.captures)
        except OSError:
            files = []
        rows = {r[0]: (r[1], r[2]) for r in self._db.execute("SELECT name, number, bytes FROM captures")}
        present: set[str] = set()
        adopt = []
        for name, size, mtime in files:
            m = CAPTURE_RX.fullmatch(name)
            if m is not None:
                present.add(name)
                if name not in rows:
                    adopt.append((int(m.group("n")), name, mtime, size))
            elif _TMP_RX.fullmatch(name):
                try:
                    self.disk.remove(self.captures / name)
                except OSError:
                    pass
        gone = [name for name in rows if name not in present]
        if adopt or gone:
            self._db.execute("BEGIN IMMEDIATE")
            self._db.executemany("DELETE FROM captures WHERE name=?", [(n,) for n in gone])
            self._db.executemany("INSERT OR REPLACE INTO captures(number, name, t, bytes) "
                                 "VALUES (?, ?, ?, ?)", adopt)
            self._db.execute("COMMIT")
        total = self._db.execute("SELECT coalesce(sum(bytes), 0), coalesce(max(number), 0) "
                                 "FROM captures").fetchone()
        top = max([int(total[1])] + [int(m.group("n")) for m in
                                     (CAPTURE_RX.fullmatch(f[0]) for f in files) if m])
        return int(total[0]), top + 1

    # -- sizes ------------------------------------------------------------------------------------
    def _file_bytes(self) -> int:
        n = 0
        for suffix in ("", "-wal", "-shm"):
            try:
                n += os.stat(f"{self.path}{suffix}").st_size
            except OSError:
                pass
        return n

    @property
    def newest_t(self) -> float | None:
        """The newest time the history holds (None: empty)."""
        return self._newest

    def size_bytes(self) -> int:
        """The database, its -wal and -shm files and every own capture file, in bytes."""
        return self._file_bytes() + self._capture_bytes

    def status(self) -> dict[str, Any]:
        return {"path": str(self.directory), "bytes": self.size_bytes(), "max_bytes": self.max_bytes,
                "full": self.full, "removed": self.removed_rows + self.removed_captures}

    def reader(self) -> Reader:
        return Reader(self.directory)

    # -- runs -------------------------------------------------------------------------------------
    def begin_run(self, t: float, port: str, baud: int | None) -> list[StoreNote]:
        """A new run row; a run an earlier process left open is ended at the newest time it wrote."""
        self._run = _Run(t, port, baud)
        self._run.prev_newest = self._newest
        self._seen(t)
        return self._write_items([("run", self._run)])

    def end_run(self, t: float, reason: str) -> list[StoreNote]:
        run = self._run
        if run is None:
            return []
        self._seen(t)
        run.ended, run.reason = t, reason
        if run.id is None:              # still queued: written complete when there is room
            return []
        return self._write_items([("run_end", run)])

    # -- writes -----------------------------------------------------------------------------------
    def write(self, *, samples: Sequence[Sample] = (), bus: BusSample | None = None,
              stations: Sequence[StationInfo] = (), events: Sequence[MonEvent] = ()) -> list[StoreNote]:
        """One transaction (with the queued rows of a full disk before them); never raises."""
        items: list[_Item] = [("sample", s) for s in samples]
        if bus is not None:
            items.append(("bus", bus))
        items += [("station", s) for s in stations]
        items += [("event", e) for e in events]
        for kind, rec in items:
            self._seen(rec.t)
        if not items and not self._pending:
            return []
        return self._write_items(items)

    def _seen(self, t: float) -> None:
        if math.isfinite(t) and (self._newest is None or t > self._newest):
            self._newest = t

    def _estimate(self, n_rows: int) -> int:
        """The most a write of n rows adds to the files (its WAL frames): the pages it touches."""
        pages = 6 + 2 * math.ceil(n_rows * 160 / self._page)
        return pages * (self._page + 24)

    def _write_items(self, items: list[_Item]) -> list[StoreNote]:
        if self._closed:
            return [StoreNote("failed", f"{self.path}: the store is closed; {len(items)} rows not "
                                        f"written")]
        notes: list[StoreNote] = []
        todo = list(self._pending) + items
        notes += self._retention()
        notes += self._make_room(self._estimate(len(todo)))
        try:
            self._db.execute("BEGIN IMMEDIATE")
            for kind, rec in todo:
                self._insert(kind, rec)
            self._db.execute("COMMIT")
        except (sqlite3.Error, OSError) as e:
            self._rollback()
            for kind, rec in todo:
                if kind == "run":
                    rec.id = None               # its insert was rolled back with the rest
            if _is_full(e):
                notes += self._became_full(str(e), "rows")
                self._queue(items)
            else:
                self.failed += 1
                notes.append(StoreNote("failed", f"{self.path}: {len(items)} rows not written: {e}",
                                       len(items)))
            return notes
        self._pending.clear()
        if self.full:
            self.full = False
            notes.append(StoreNote("room", f"{self.path}: written again, {len(todo)} rows "
                                           f"(queued ones included)", len(todo)))
        notes += self._after_write()
        return notes

    def _rollback(self) -> None:
        try:
            if self._db.in_transaction:
                self._db.execute("ROLLBACK")
        except sqlite3.Error:
            pass

    def _became_full(self, why: str, what: str) -> list[StoreNote]:
        if self.full:
            return []
        self.full = True
        return [StoreNote("full", f"{self.directory}: disk full ({why}); {what} wait in memory "
                                  f"(at most {self.pending_max} rows) until there is room")]

    def _queue(self, items: Iterable[_Item]) -> None:
        for it in items:
            self._pending.append(it)
        while len(self._pending) > self.pending_max:
            self._pending.popleft()
            self.dropped_pending += 1

    @property
    def pending(self) -> int:
        return len(self._pending)

    def _insert(self, kind: str, rec: Any) -> None:
        db = self._db
        if kind == "sample":
            s: Sample = rec
            db.execute("INSERT INTO samples(t, interval_s, station, state, "
                       + ", ".join(SAMPLE_COUNTERS) + ", cycle_mean_s) VALUES (?, ?, ?, ?, "
                       + ", ".join("?" for _ in SAMPLE_COUNTERS) + ", ?)",
                       (s.t, s.interval_s, s.station, s.state,
                        *(int(s.counts.get(c, 0)) for c in SAMPLE_COUNTERS), s.cycle_mean_s))
        elif kind == "bus":
            b: BusSample = rec
            db.execute("INSERT INTO bus_samples(t, interval_s, frames, tokens, errors, load_percent,"
                       " rotation_s, masters) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                       (b.t, b.interval_s, b.frames, b.tokens, b.errors, b.load_percent,
                        b.rotation_s, json.dumps(list(b.masters))))
        elif kind == "station":
            i: StationInfo = rec
            db.execute("INSERT INTO stations(station, ident, profile, first_seen, last_seen, state)"
                       " VALUES (?, ?, ?, ?, ?, ?) ON CONFLICT(station) DO UPDATE SET"
                       " ident=coalesce(excluded.ident, ident),"
                       " profile=coalesce(excluded.profile, profile),"
                       " first_seen=min(first_seen, excluded.first_seen),"
                       " last_seen=max(last_seen, excluded.last_seen), state=excluded.state",
                       (i.station, i.ident, i.profile, i.t, i.t, i.state))
        elif kind == "event":
            e: MonEvent = rec
            db.execute("INSERT INTO events(t, kind, station, text, cause, evidence, repeats, capture)"
                       " VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                       (e.t, e.kind, e.station, e.text, e.cause, json.dumps(list(e.evidence)),
                        e.repeats, e.capture))
        elif kind == "capture":
            db.execute("INSERT OR REPLACE INTO captures(number, name, t, bytes) VALUES (?, ?, ?, ?)",
                       rec)
        elif kind == "run":
            r: _Run = rec
            if r.id is None:
                # a run an earlier process left open ended, at the latest, at the newest time the
                # store held when this one began
                db.execute("UPDATE runs SET ended=max(started, ?), end_reason=? WHERE ended IS NULL",
                           (r.prev_newest if r.prev_newest is not None else r.t,
                            "interrupted (the store was not closed)"))
                cur = db.execute("INSERT INTO runs(started, ended, port, baud, end_reason) "
                                 "VALUES (?, ?, ?, ?, ?)", (r.t, r.ended, r.port, r.baud, r.reason))
                r.id = cur.lastrowid
        elif kind == "run_end":
            r2: _Run = rec
            db.execute("UPDATE runs SET ended=?, end_reason=? WHERE id=?", (r2.ended, r2.reason, r2.id))

    def _after_write(self) -> list[StoreNote]:
        """The WAL checkpointed when it grew past its limit; the bound made good (a write larger
        than its estimate)."""
        notes: list[StoreNote] = []
        try:
            if os.stat(f"{self.path}-wal").st_size > self._wal_limit:
                self._checkpoint()
        except OSError:
            pass
        if self.size_bytes() > self.max_bytes:
            notes += self._make_room(0)
        return notes

    def _checkpoint(self) -> bool:
        """A TRUNCATE checkpoint: the WAL copied into the database and emptied (False: a reader
        held it, tried again later)."""
        try:
            busy = self._db.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchone()[0]
        except sqlite3.Error:
            return False
        return not busy

    # -- the bound and the retention --------------------------------------------------------------
    def _retention(self) -> list[StoreNote]:
        if self.keep_s is None or self._newest is None:
            return []
        cut = self._newest - self.keep_s
        oldest = self._oldest()
        if oldest is None or oldest >= cut - self.keep_s / 100:
            return []                    # in steps of a hundredth of keep_s: not every write
        rows, caps, err = self._remove_upto(cut, inclusive=False)
        notes = self._removed_note(rows, caps, f"older than --keep ({self.keep_s:g} s before the "
                                               f"newest time written)")
        if err:
            notes.append(err)
        self._shrink()
        return notes

    def _oldest(self) -> float | None:
        db = self._db
        vals = []
        for q in ("SELECT t FROM samples ORDER BY id LIMIT 1", "SELECT min(t) FROM bus_samples",
                  "SELECT min(t) FROM events", "SELECT t FROM captures ORDER BY number LIMIT 1"):
            r = db.execute(q).fetchone()
            if r is not None and r[0] is not None:
                vals.append(float(r[0]))
        return min(vals) if vals else None

    def _used(self) -> int:
        """The bytes the rows and captures hold (the database's pages in use beyond the empty
        schema's, and the captures)."""
        db = self._db
        pages = int(db.execute("PRAGMA page_count").fetchone()[0])
        free = int(db.execute("PRAGMA freelist_count").fetchone()[0])
        return max(0, (pages - free - 16) * self._page) + self._capture_bytes

    def _make_room(self, need: int) -> list[StoreNote]:
        """Oldest first, until the total and `need` more fit in the bound (with the headroom)."""
        if self.size_bytes() + need <= self.max_bytes:
            return []
        try:
            self._checkpoint()
            if self.size_bytes() + need <= self.max_bytes:
                return []
            notes: list[StoreNote] = []
            goal = self.max_bytes - self._headroom - need
            rows = caps = 0
            newest = self._newest
            for attempt in range(64):
                excess = self.size_bytes() - goal
                if excess <= 0:
                    break
                oldest = self._oldest()
                if oldest is None or newest is None or oldest >= newest:
                    break                            # only the newest left: nothing older to go
                used = max(1, self._used())
                frac = min(1.0, excess * 1.2 * (2 ** min(attempt, 10)) / used,
                           max(self.max_bytes / 16, 256 << 10) / used)
                cut = min(oldest + (newest - oldest) * frac, newest)
                if cut <= oldest:
                    cut = oldest
                r, c, err = self._remove_upto(cut, inclusive=True, before=newest)
                rows += r
                caps += c
                if err is not None:
                    notes.append(err)
                    break
                if not self._shrink() or (r == 0 and c == 0):
                    break                            # a reader holds the WAL: the next write goes on
            notes[:0] = self._removed_note(rows, caps, f"--max-disk {size_text(self.max_bytes)}")
            return notes
        except (sqlite3.Error, OSError) as e:
            self._rollback()
            if _is_full(e):
                return self._became_full(str(e), "rows")
            self.failed += 1
            return [StoreNote("failed", f"{self.path}: making room failed: {e}")]

    def _removed_note(self, rows: int, caps: int, why: str) -> list[StoreNote]:
        if rows == 0 and caps == 0:
            return []
        return [StoreNote("removed", f"{self.directory}: removed the oldest {rows} rows and {caps} "
                                     f"captures ({why})", rows + caps,
                          {"rows": rows, "captures": caps, "why": why})]

    def _remove_upto(self, cut: float, inclusive: bool,
                     before: float | None = None) -> tuple[int, int, StoreNote | None]:
        """Rows and captures at or before `cut` (before it: not inclusive) removed; never one at
        `before` or later (the newest). (rows, captures, a note when a capture could not go)."""
        op = "<=" if inclusive else "<"
        db = self._db
        rows = 0
        db.execute("BEGIN IMMEDIATE")
        try:
            lim = before if before is not None else math.inf
            r = db.execute(f"SELECT id FROM samples WHERE NOT (t {op} ? AND t < ?) ORDER BY id LIMIT 1",
                           (cut, lim)).fetchone()
            if r is None:
                rows += db.execute("DELETE FROM samples").rowcount
            else:
                rows += db.execute("DELETE FROM samples WHERE id < ?", (r[0],)).rowcount
            rows += db.execute(f"DELETE FROM bus_samples WHERE t {op} ? AND t < ?", (cut, lim)).rowcount
            rows += db.execute(f"DELETE FROM events WHERE t {op} ? AND t < ?", (cut, lim)).rowcount
            db.execute("COMMIT")
        except BaseException:
            self._rollback()
            raise
        self.removed_rows += rows
        caps = 0
        err: StoreNote | None = None
        while True:
            batch = db.execute(f"SELECT number, name, bytes FROM captures WHERE t {op} ? AND t < ? "
                               "ORDER BY number LIMIT 100", (cut, lim)).fetchall()
            if not batch:
                break
            done = []
            for number, name, size in batch:
                try:
                    self.disk.remove(self.captures / name)
                except FileNotFoundError:
                    pass
                except OSError as e:
                    self.failed += 1
                    err = StoreNote("failed", f"{self.captures / name}: cannot remove: "
                                              f"{e.strerror or e}")
                    break
                done.append(number)
                self._capture_bytes = max(0, self._capture_bytes - int(size))
            db.execute("BEGIN IMMEDIATE")
            try:
                db.executemany("DELETE FROM captures WHERE number=?", [(n,) for n in done])
                db.execute("COMMIT")
            except BaseException:
                self._rollback()
                raise
            caps += len(done)
            self.removed_captures += len(done)
            if err is not None:
                break
        return rows, caps, err

    def _shrink(self) -> bool:
        """The freed pages given back: incremental_vacuum, a TRUNCATE checkpoint."""
        self._db.executescript("PRAGMA incremental_vacuum;")
        return self._checkpoint()

    # -- captures ---------------------------------------------------------------------------------
    def save_capture(self, t: float, hint: str, packets: list[tuple[float, bytes]],
                     start_wall: float) -> tuple[str | None, list[StoreNote]]:
        """captures/<number>-<hint>.pcap (classic pcap, link type 147, times start_wall + t):
        (its file name, or None when not written; the notes on the way). Never raises."""
        if self._closed:
            return None, [StoreNote("failed", f"{self.captures}: the store is closed; capture not "
                                              f"written")]
        self._seen(t)
        size = 24 + sum(16 + len(raw) for _, raw in packets)
        safe = _HINT_BAD.sub("_", hint).strip("_")[:40] or "event"
        number = self._next_number
        self._next_number += 1
        name = f"{number:06d}-{safe}.pcap"
        path = self.captures / name
        notes: list[StoreNote] = []
        room = self.max_bytes - self._headroom - _BASE_BYTES
        if size > room:
            self.failed += 1
            return None, [StoreNote("failed", f"{path}: {size_text(size)}: more than the store holds "
                                              f"beside its database (--max-disk "
                                              f"{size_text(self.max_bytes)})")]
        notes += self._retention()
        notes += self._make_room(size + self._estimate(1))

        def fill(fh: IO[bytes]) -> None:
            w = PcapWriter(fh, LINKTYPE, start_wall)
            for pt, raw in packets:
                w.write(pt, raw)
        try:
            self.disk.write(str(path), fill)
        except (OSError, PdriveError) as e:
            reason, code = _why(e)
            if code in DISK_FULL:
                notes += self._became_full(reason, "captures are not written and rows")
                notes.append(StoreNote("failed", f"{path}: not written: {reason}"))
            else:
                self.failed += 1
                notes.append(StoreNote("failed", f"{path}: not written: {reason}"))
            return None, notes
        self._capture_bytes += size
        notes += self._write_items([("capture", (number, name, t, size))])
        return name, notes

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        try:
            self._checkpoint()
            self._db.close()
        except sqlite3.Error:
            pass


def _ident_hex(ident: int | None) -> str | None:
    return None if ident is None else f"0x{ident:04X}"


class Reader:
    """Read-only queries on a store (its own connection, guarded by a lock: the web page's threads
    share it). Opening checks the store as History does and creates nothing."""

    def __init__(self, directory: str | os.PathLike[str]):
        self.directory = _check_directory(directory, write=False)
        self.path = self.directory / DB_NAME
        self.captures = self.directory / CAPTURES_DIR
        if not self.path.is_file():
            raise UsageError(f"--db {self.directory}: no pdrive monitor store there (no {DB_NAME})")
        try:
            con = sqlite3.connect(f"{self.path.resolve().as_uri()}?mode=ro", uri=True,
                                  check_same_thread=False, timeout=5.0)
        except sqlite3.Error as e:
            raise UsageError(f"--db {self.path}: cannot open ({e})") from None
        try:
            _check_store(con, self.path)
        except UsageError:
            con.close()
            raise
        self._db = con
        self._lock = threading.Lock()

    def _q(self, sql: str, args: Sequence[Any] = ()) -> list[tuple[Any, ...]]:
        with self._lock:
            return self._db.execute(sql, tuple(args)).fetchall()

    def events(self, since: float | None = None, until: float | None = None,
               station: int | None = None, limit: int = 1000) -> list[dict[str, Any]]:
        """MonEvent.as_dict() keys, "id" and "capture_present", newest first."""
        where, args = ["1"], []
        if since is not None:
            where.append("e.t >= ?")
            args.append(since)
        if until is not None:
            where.append("e.t <= ?")
            args.append(until)
        if station is not None:
            where.append("e.station = ?")
            args.append(station)
        limit = max(0, min(int(limit), MAX_LIMIT))
        rows = self._q("SELECT e.id, e.t, e.kind, e.station, e.text, e.cause, e.evidence, e.repeats,"
                       " e.capture, c.number FROM events e LEFT JOIN captures c ON c.name = e.capture"
                       f" WHERE {' AND '.join(where)} ORDER BY e.t DESC, e.id DESC LIMIT ?",
                       args + [limit])
        out = []
        for r in rows:
            try:
                evidence = list(json.loads(r[6]))
            except ValueError:
                evidence = []
            out.append({"id": r[0], "t": r[1], "kind": r[2], "station": r[3], "text": r[4],
                        "cause": r[5], "evidence": evidence, "repeats": r[7], "capture": r[8],
                        "capture_present": r[8] is not None and r[9] is not None})
        return out

    def event_counts(self, since: float | None = None, until: float | None = None,
                     station: int | None = None) -> dict[str, int]:
        """Events per kind in the window."""
        where, args = ["1"], []
        for cond, val in (("t >= ?", since), ("t <= ?", until), ("station = ?", station)):
            if val is not None:
                where.append(cond)
                args.append(val)
        return {str(k): int(n) for k, n in self._q(
            f"SELECT kind, count(*) FROM events WHERE {' AND '.join(where)} GROUP BY kind "
            "ORDER BY kind", args)}

    def stations(self) -> list[dict[str, Any]]:
        return [{"station": r[0], "ident": r[1], "ident_hex": _ident_hex(r[1]), "profile": r[2],
                 "first_seen": r[3], "last_seen": r[4], "state": r[5]}
                for r in self._q("SELECT station, ident, profile, first_seen, last_seen, state "
                                 "FROM stations ORDER BY station")]

    def trend(self, station: int | None, since: float, until: float,
              buckets: int = 120) -> dict[str, Any]:
        """Per bucket: a station's counter sums, its last state and mean cycle; the bus's frames,
        tokens, errors sums and its load and rotation means. A bucket without rows: None."""
        n = max(1, min(int(buckets), MAX_BUCKETS))
        if not until > since:
            until = since + 1.0
        w = (until - since) / n
        starts = [since + i * w for i in range(n)]
        bucket = f"min(CAST((t - ?) / ? AS INTEGER), {n - 1})"
        series: dict[str, list[Any]] = {}
        if station is not None:
            names = list(SAMPLE_COUNTERS) + ["cycle_mean_s", "state"]
            rows = self._q(f"SELECT {bucket} AS b, " + ", ".join(f"sum({c})" for c in SAMPLE_COUNTERS)
                           + ", avg(cycle_mean_s), state, max(t) FROM samples"
                           " WHERE station = ? AND t >= ? AND t <= ? GROUP BY b",
                           (since, w, station, since, until))
        else:
            names = ["frames", "tokens", "errors", "load_percent", "rotation_s"]
            rows = self._q(f"SELECT {bucket} AS b, sum(frames), sum(tokens), sum(errors),"
                           " avg(load_percent), avg(rotation_s) FROM bus_samples"
                           " WHERE t >= ? AND t <= ? GROUP BY b", (since, w, since, until))
        for name in names:
            series[name] = [None] * n
        for r in rows:
            b = int(r[0])
            if 0 <= b < n:
                for k, name in enumerate(names):
                    series[name][b] = r[1 + k]
        return {"station": station, "since": since, "until": until, "t": starts, "series": series}

    def runs(self, since: float | None = None, until: float | None = None,
             limit: int = 1000) -> list[dict[str, Any]]:
        """The runs that overlap the window, oldest first (at most `limit`, the newest)."""
        where, args = ["1"], []
        if until is not None:
            where.append("started <= ?")
            args.append(until)
        if since is not None:
            where.append("(ended IS NULL OR ended >= ?)")
            args.append(since)
        rows = self._q("SELECT id, started, ended, port, baud, end_reason FROM runs WHERE "
                       f"{' AND '.join(where)} ORDER BY id DESC LIMIT ?",
                       args + [max(0, min(int(limit), MAX_LIMIT))])
        return [{"id": r[0], "started": r[1], "ended": r[2], "port": r[3], "baud": r[4],
                 "end_reason": r[5]} for r in reversed(rows)]

    def totals(self, since: float | None, until: float | None,
               station: int | None = None) -> dict[int, dict[str, Any]]:
        """Per station (one, or every station with samples): the counter sums over the window,
        the samples and the seconds they cover."""
        lo = -math.inf if since is None else since
        hi = math.inf if until is None else until
        if station is not None:
            stations = [station]
        else:
            stations = []
            cur = -1
            while True:                       # each station once, through the index
                r = self._q("SELECT min(station) FROM samples WHERE station > ?", (cur,))
                if not r or r[0][0] is None:
                    break
                cur = int(r[0][0])
                stations.append(cur)
        out: dict[int, dict[str, Any]] = {}
        for st in stations:
            row = self._q("SELECT count(*), coalesce(sum(interval_s), 0), "
                          + ", ".join(f"coalesce(sum({c}), 0)" for c in SAMPLE_COUNTERS)
                          + " FROM samples WHERE station = ? AND t >= ? AND t <= ?", (st, lo, hi))[0]
            if station is None and row[0] == 0:
                continue
            d: dict[str, Any] = {c: int(row[2 + k]) for k, c in enumerate(SAMPLE_COUNTERS)}
            d["samples"] = int(row[0])
            d["seconds"] = float(row[1])
            out[st] = d
        return out

    def capture_path(self, name: str) -> Path | None:
        """The path of an own capture file that exists; None for anything else (a separator, a
        name the store never gives, a file not there)."""
        if not isinstance(name, str) or "/" in name or "\\" in name or os.sep in name:
            return None
        if CAPTURE_RX.fullmatch(name) is None:
            return None
        p = self.captures / name
        return p if p.is_file() else None

    def close(self) -> None:
        with self._lock:
            self._db.close()


__all__ = ["CAPTURES_DIR", "DB_NAME", "DEFAULT_MAX_BYTES", "MIN_MAX_BYTES", "SCHEMA_VERSION",
           "History", "Reader"]
