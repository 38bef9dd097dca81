"""The monitor's history (profidrive_cli/monitor/store.py): resumed after a restart, one disk bound
over the database and the captures held over a long run (oldest first, counted), the retention, a
full disk (a real SQLITE_FULL through max_page_count; ENOSPC on a capture) and its queue, capture
numbering and capture_path, refused directories and files."""

from __future__ import annotations

import errno
import os
import sqlite3
import struct
from pathlib import Path
from typing import IO, Callable

import pytest

from profidrive_cli import UsageError
from profidrive_cli.bustools.ringstore import Disk
from profidrive_cli.monitor.model import BusSample, MonEvent, Sample, StationInfo
from profidrive_cli.monitor.store import DB_NAME, MIN_MAX_BYTES, SCHEMA_VERSION, History, Reader

T0 = 1_800_000_000.0        # 2027-01-15: any epoch time does


def samples(t: float, stations=(3, 5), retries: int = 1) -> list[Sample]:
    return [Sample(t, 1.0, s, "data exchange",
                   {"exchanges": 100, "retries": retries, "no_answer": 0, "illegal": 0,
                    "reparams": 0}, 0.004) for s in stations]


def packets(n: int, size: int = 20) -> list[tuple[float, bytes]]:
    return [(0.001 * k, bytes([0x10, 5, 2, 0x7D, 0x16]) * (size // 5)) for k in range(n)]


def test_resume_after_restart(tmp_path: Path) -> None:
    h = History(tmp_path)
    assert not h.resumed
    h.begin_run(T0, "/dev/ttyUSB0", 1_500_000)
    h.write(samples=samples(T0 + 1), bus=BusSample(T0 + 1, 1.0, 500, 100, 0, 10.0, 0.002),
            stations=[StationInfo(T0 + 1, 5, 0x80B5, "sinamics", "data exchange")],
            events=[MonEvent(T0 + 1, "rr", 5, "retry limit", "cable", ("a", "b"))])
    h.close()                                   # no end_run: as if the process was killed
    h2 = History(tmp_path)
    assert h2.resumed
    h2.begin_run(T0 + 100, "/dev/ttyUSB0", None)
    h2.write(events=[MonEvent(T0 + 101, "lost", 3, "lost")])
    h2.end_run(T0 + 102, "SIGTERM")
    r = h2.reader()
    try:
        ev = r.events()
        assert [(e["kind"], e["station"]) for e in ev] == [("lost", 3), ("rr", 5)]
        assert ev[1]["evidence"] == ["a", "b"] and ev[1]["cause"] == "cable"
        runs = r.runs()
        assert [x["started"] for x in runs] == [T0, T0 + 100]
        # the first run was left open: ended at the newest time it wrote
        assert runs[0]["ended"] == T0 + 1 and "interrupted" in runs[0]["end_reason"]
        assert runs[1]["ended"] == T0 + 102 and runs[1]["end_reason"] == "SIGTERM"
        assert r.totals(None, None) == {
            3: {"exchanges": 100, "retries": 1, "no_answer": 0, "illegal": 0, "reparams": 0,
                "samples": 1, "seconds": 1.0},
            5: {"exchanges": 100, "retries": 1, "no_answer": 0, "illegal": 0, "reparams": 0,
                "samples": 1, "seconds": 1.0}}
        assert r.stations() == [{"station": 5, "ident": 0x80B5, "ident_hex": "0x80B5",
                                 "profile": "sinamics", "first_seen": T0 + 1, "last_seen": T0 + 1,
                                 "state": "data exchange"}]
    finally:
        r.close()
        h2.close()


def test_capture_numbering_and_file(tmp_path: Path) -> None:
    h = History(tmp_path)
    name, notes = h.save_capture(T0, "lost(5)/x", packets(3), T0 - 1.0)
    assert name == "000001-lost_5_x.pcap" and notes == []
    data = (tmp_path / "captures" / name).read_bytes()
    magic, _, _, _, _, _, linktype = struct.unpack_from("<IHHiIII", data)
    assert magic == 0xA1B2C3D4 and linktype == 147
    sec, usec, incl, _ = struct.unpack_from("<IIII", data, 24)
    assert (sec, incl) == (int(T0 - 1.0), 20) and usec == 0
    assert len(data) == 24 + 3 * (16 + 20)
    assert h.save_capture(T0 + 1, "", packets(1), T0)[0] == "000002-event.pcap"
    h.close()
    h = History(tmp_path)
    assert h.save_capture(T0 + 2, "rr", packets(1), T0)[0] == "000003-rr.pcap"
    r = h.reader()
    try:
        assert r.capture_path("000003-rr.pcap") == tmp_path / "captures" / "000003-rr.pcap"
        for bad in ("../x", "a/b", "..", "000009-rr.pcap", "monitor.sqlite3", "000001-lost_5_x.pcap/",
                    "../captures/000001-lost_5_x.pcap", "x.pcap", ""):
            assert r.capture_path(bad) is None, bad
    finally:
        r.close()
        h.close()


def test_bound_held_over_a_long_run(tmp_path: Path) -> None:
    bound = 600 << 10
    h = History(tmp_path, max_bytes=bound)
    h.begin_run(T0, "sim://", 1_500_000)
    removed_notes = 0
    names = []
    try:
        for i in range(1200):
            t = T0 + i
            notes = h.write(samples=samples(t, (3, 4, 5)),
                            bus=BusSample(t, 1.0, 500, 100, i % 2, 12.0, 0.002),
                            stations=[StationInfo(t, 5, 0x80B5, None, "data exchange")],
                            events=[MonEvent(t, "rr", 5, f"event {i}", capture=None)]
                            if i % 4 == 0 else [])
            if i % 25 == 0:
                name, more = h.save_capture(t, "rr5", packets(150), t - 1.0)
                assert name is not None
                names.append(name)
                notes += more
                h.write(events=[MonEvent(t, "rr", 5, f"capture {i}", capture=name)])
            removed_notes += sum(n.count for n in notes if n.kind == "removed")
            assert not [n for n in notes if n.kind in ("failed", "full")]
            if i > 10:
                assert h.size_bytes() <= bound, i
        assert h.removed_rows > 0 and h.removed_captures > 0
        assert removed_notes == h.removed_rows + h.removed_captures
        assert h.status()["removed"] == removed_notes and h.status()["bytes"] <= bound
        r = h.reader()
        try:
            ev = r.events(limit=10_000)
            ids = sorted(e["id"] for e in ev)
            assert ids == list(range(ids[0], ids[-1] + 1))      # what is kept: the newest, unbroken
            assert ev[0]["text"] == "event 1196"                  # the newest kept
            assert ev[-1]["t"] > T0                               # the oldest went
            kept = sorted(p.name for p in (tmp_path / "captures").iterdir())
            assert kept == names[len(names) - len(kept):] and names[-1] in kept
            assert names[0] not in kept
            present = {e["capture"]: e["capture_present"] for e in ev if e["capture"]}
            assert all(v == (k in kept) for k, v in present.items())
            # oldest first across the kinds: the oldest capture kept and the oldest event kept
            # lie within one interval between captures (25 s) of each other
            first_kept = int(kept[0][:6])
            assert abs(T0 + (first_kept - 1) * 25 - ev[-1]["t"]) <= 25
            assert r.stations()[0]["first_seen"] == T0            # the stations table kept
            assert r.runs()[0]["started"] == T0
        finally:
            r.close()
    finally:
        h.close()


def test_retention_from_the_newest_time(tmp_path: Path) -> None:
    h = History(tmp_path, keep_s=100.0)
    try:
        for i in range(400):
            t = T0 + i
            h.write(samples=samples(t), events=[MonEvent(t, "rr", 5, str(i))])
            if i % 50 == 0:
                h.save_capture(t, "x", packets(2), t)
        r = h.reader()
        try:
            ev = r.events(limit=1000)
            # kept: newer than newest - keep_s (removed in steps of a hundredth of keep_s)
            assert ev[0]["t"] == T0 + 399
            assert T0 + 399 - 100 - 1 - 1e-6 <= ev[-1]["t"] <= T0 + 399 - 100 + 1e-6
            assert r.totals(None, None)[3]["samples"] == 102            # t 298 .. 399
            kept = sorted(p.name for p in (tmp_path / "captures").iterdir())
            assert kept == ["000007-x.pcap", "000008-x.pcap"]    # t 300 and 350; 250 too old
        finally:
            r.close()
        assert h.removed_rows == 3 * 400 - 3 * len(ev) and h.removed_captures == 6
    finally:
        h.close()


def test_full_database_queue_and_room(tmp_path: Path) -> None:
    h = History(tmp_path, pending_max=30)
    try:
        h.write(samples=samples(T0))
        h._db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        pages = h._db.execute("PRAGMA page_count").fetchone()[0]
        h._db.execute(f"PRAGMA max_page_count={pages}")       # a real SQLITE_FULL from here on
        notes: list = []
        i = 1
        while not h.full and i < 500:
            notes += h.write(samples=samples(T0 + i), events=[MonEvent(T0 + i, "rr", 5, str(i))])
            i += 1
        assert h.full and [n.kind for n in notes] == ["full"]
        full_at = i - 1
        r = h.reader()
        try:
            assert r.events(limit=1000)[0]["text"] == str(full_at - 1)   # the queued not there
            assert h.pending == 3
            more = h.write(samples=samples(T0 + 1000))                   # still full: queued
            assert more == [] and h.pending == 5 and h.dropped_pending == 0
            for k in range(10):                                          # 30 rows more
                h.write(samples=samples(T0 + 2000 + k),
                        events=[MonEvent(T0 + 2000 + k, "lost", 3, f"q{k}")])
            # 35 rows for 30 places: the 5 oldest (full_at's 3, T0+1000's 2) dropped
            assert h.pending == 30 and h.dropped_pending == 5
            h._db.execute("PRAGMA max_page_count=1073741823")
            room = h.write(events=[MonEvent(T0 + 3000, "back", 3, "back")])
            assert [n.kind for n in room] == ["room"] and not h.full and h.pending == 0
            texts = [e["text"] for e in r.events(limit=1000)]
            assert texts[:12] == (["back"] + [f"q{k}" for k in reversed(range(10))]
                                  + [str(full_at - 1)])
            assert r.totals(T0 + 2000, T0 + 2009)[5]["samples"] == 10
            assert r.totals(T0 + 1000, T0 + 1000) == {}
        finally:
            r.close()
    finally:
        h.close()


def test_full_queue_keeps_rows_and_counts_drops(tmp_path: Path) -> None:
    h = History(tmp_path, pending_max=4)
    try:
        h.write(samples=samples(T0))
        h._db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        pages = h._db.execute("PRAGMA page_count").fetchone()[0]
        h._db.execute(f"PRAGMA max_page_count={pages}")
        i = 1
        while not h.full and i < 500:
            h.write(events=[MonEvent(T0 + i, "rr", 5, str(i))])
            i += 1
        assert h.full and h.pending == 1 and h.dropped_pending == 0
        for k in range(5):
            h.write(events=[MonEvent(T0 + 1000 + k, "rr", 5, f"q{k}")])
        # 1 + 5 events queued, 4 kept: the two oldest dropped
        assert h.pending == 4 and h.dropped_pending == 2
        h._db.execute("PRAGMA max_page_count=1073741823")
        assert [n.kind for n in h.write()] == ["room"]
        r = h.reader()
        try:
            assert [e["text"] for e in r.events(limit=4)] == ["q4", "q3", "q2", "q1"]
        finally:
            r.close()
    finally:
        h.close()


class FullDisk(Disk):
    def __init__(self) -> None:
        self.full = False
        self.broken = False

    def write(self, path: str, fill: Callable[[IO[bytes]], None]) -> None:
        if self.full:
            raise OSError(errno.ENOSPC, "No space left on device")
        if self.broken:
            raise OSError(errno.EIO, "Input/output error")
        super().write(path, fill)


def test_capture_on_a_full_disk_and_other_faults(tmp_path: Path) -> None:
    disk = FullDisk()
    h = History(tmp_path, disk=disk)
    try:
        disk.full = True
        name, notes = h.save_capture(T0, "lost3", packets(2), T0)
        assert name is None and [n.kind for n in notes] == ["full", "failed"] and h.full
        name, notes = h.save_capture(T0 + 1, "lost3", packets(2), T0)
        assert name is None and [n.kind for n in notes] == ["failed"]       # "full" said once
        disk.full = False
        name, notes = h.save_capture(T0 + 2, "lost3", packets(2), T0)
        assert name is not None and [n.kind for n in notes] == ["room"] and not h.full
        disk.broken = True
        name, notes = h.save_capture(T0 + 3, "lost3", packets(2), T0)
        assert name is None and [n.kind for n in notes] == ["failed"] and not h.full
        assert "Input/output error" in notes[0].text
    finally:
        h.close()


def test_an_event_keeps_its_row_when_its_capture_goes(tmp_path: Path) -> None:
    h = History(tmp_path)
    name, _ = h.save_capture(T0, "rr5", packets(2), T0)
    assert name is not None
    h.write(events=[MonEvent(T0, "rr", 5, "retry", capture=name)])
    r = h.reader()
    assert r.events()[0]["capture_present"] is True
    r.close()
    h.close()
    (tmp_path / "captures" / name).unlink()          # gone (by hand, or by an earlier bound)
    h = History(tmp_path)
    r = h.reader()
    try:
        e = r.events()[0]
        assert e["capture"] == name and e["capture_present"] is False
        assert r.capture_path(name) is None
        assert h.size_bytes() == sum(os.path.getsize(tmp_path / f) for f in os.listdir(tmp_path)
                                     if f.startswith(DB_NAME))
    finally:
        r.close()
        h.close()


def test_a_capture_larger_than_the_bound_is_not_written(tmp_path: Path) -> None:
    h = History(tmp_path, max_bytes=MIN_MAX_BYTES)
    try:
        name, notes = h.save_capture(T0, "big", packets(10_000, 20), T0)
        assert name is None and [n.kind for n in notes] == ["failed"]
        assert "more than the store holds" in notes[0].text
        assert list((tmp_path / "captures").iterdir()) == []
    finally:
        h.close()


def test_other_database_fault_is_a_note(tmp_path: Path) -> None:
    h = History(tmp_path)
    try:
        h._db.execute("DROP TABLE events")          # every insert of an event fails from here
        notes = h.write(events=[MonEvent(T0, "rr", 5, "x")])
        assert [n.kind for n in notes] == ["failed"] and not h.full
        assert h.write(samples=samples(T0 + 1)) == []
    finally:
        h.close()


def one_line(e: pytest.ExceptionInfo[UsageError]) -> str:
    text = str(e.value)
    assert "\n" not in text
    return text


def test_refused_directories_and_files(tmp_path: Path) -> None:
    with pytest.raises(UsageError) as e:
        History(tmp_path / "missing")
    assert "missing" in one_line(e) and "no such directory" in one_line(e)
    assert not (tmp_path / "missing").exists()
    (tmp_path / "file").write_text("x")
    with pytest.raises(UsageError) as e:
        History(tmp_path / "file")
    assert "not a directory" in one_line(e)
    with pytest.raises(UsageError) as e:
        History(tmp_path, max_bytes=100 << 10)
    assert "256 KiB" in one_line(e)
    with pytest.raises(UsageError) as e:
        Reader(tmp_path)
    assert "no pdrive monitor store" in one_line(e)

    corrupt = tmp_path / "corrupt"
    corrupt.mkdir()
    (corrupt / DB_NAME).write_bytes(b"this is not an sqlite file at all" * 100)
    for opener in (History, Reader):
        with pytest.raises(UsageError) as e:
            opener(corrupt)
        assert str(corrupt / DB_NAME) in one_line(e)

    other = tmp_path / "other"
    other.mkdir()
    con = sqlite3.connect(other / DB_NAME)
    con.execute("CREATE TABLE t(x)")
    con.commit()
    con.close()
    with pytest.raises(UsageError) as e:
        History(other)
    assert "not a pdrive monitor store" in one_line(e)

    newer = tmp_path / "newer"
    newer.mkdir()
    History(newer).close()
    con = sqlite3.connect(newer / DB_NAME)
    con.execute("UPDATE meta SET value=? WHERE key='schema_version'", (str(SCHEMA_VERSION + 1),))
    con.commit()
    con.close()
    for opener in (History, Reader):
        with pytest.raises(UsageError) as e:
            opener(newer)
        assert "newer pdrive" in one_line(e) and str(newer / DB_NAME) in one_line(e)


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root writes anywhere")
def test_unwritable_directory(tmp_path: Path) -> None:
    d = tmp_path / "ro"
    d.mkdir()
    d.chmod(0o500)
    try:
        with pytest.raises(UsageError) as e:
            History(d)
        assert "permission denied" in one_line(e)
    finally:
        d.chmod(0o700)


def test_trend_buckets(tmp_path: Path) -> None:
    h = History(tmp_path)
    try:
        for i in range(10):
            t = T0 + i
            h.write(samples=[Sample(t, 1.0, 5, "data exchange" if i < 7 else "no answer",
                                    {"exchanges": 10, "retries": i, "no_answer": 0, "illegal": 0,
                                     "reparams": 0})],
                    bus=BusSample(t, 1.0, 100, 10, 1, float(i), None))
        r = h.reader()
        try:
            tr = r.trend(5, T0, T0 + 20, buckets=4)                 # 5 s each
            assert tr["t"] == [T0, T0 + 5, T0 + 10, T0 + 15]
            assert tr["series"]["retries"] == [0 + 1 + 2 + 3 + 4, 5 + 6 + 7 + 8 + 9, None, None]
            assert tr["series"]["exchanges"] == [50, 50, None, None]
            assert tr["series"]["state"] == ["data exchange", "no answer", None, None]
            bus = r.trend(None, T0, T0 + 10, buckets=2)
            assert bus["series"]["frames"] == [500, 500]
            assert bus["series"]["load_percent"] == [2.0, 7.0]
            assert bus["series"]["rotation_s"] == [None, None]
            assert len(r.trend(None, T0, T0 + 10, buckets=10 ** 6)["t"]) == 2000
        finally:
            r.close()
    finally:
        h.close()


def test_readers_in_threads_while_the_monitor_writes(tmp_path: Path) -> None:
    import threading
    bound = MIN_MAX_BYTES
    h = History(tmp_path, max_bytes=bound)
    r = h.reader()
    stop = threading.Event()
    errors: list[BaseException] = []
    reads = [0]

    def read() -> None:
        try:
            while not stop.is_set():
                r.events(limit=50)
                r.trend(5, T0, T0 + 400, 50)
                r.totals(T0, T0 + 400)
                reads[0] += 1
                stop.wait(0.002)
        except BaseException as e:                # noqa: BLE001 -- reported by the test
            errors.append(e)

    threads = [threading.Thread(target=read) for _ in range(2)]
    for th in threads:
        th.start()
    try:
        for i in range(600):
            notes = h.write(samples=samples(T0 + i, (3, 4, 5)),
                            events=[MonEvent(T0 + i, "rr", 5, str(i))])
            assert not [n for n in notes if n.kind in ("failed", "full")], notes
    finally:
        stop.set()
        for th in threads:
            th.join(timeout=60)
    try:
        assert not errors and reads[0] > 0
        h.write(samples=samples(T0 + 600))          # no reader now: the bound made good
        assert h.size_bytes() <= bound and h.removed_rows > 0
        assert r.events(limit=1)[0]["text"] == "599"
    finally:
        r.close()
        h.close()
