"""Issue 35, a recorder that keeps recording: the --out pattern checked against every value its
fields can carry, the disk bound (--max-disk, --keep: the recorder's own files, oldest first, each
removal counted), and a capture that cannot be written (full disk, read-only, directory gone) as
an event for that capture while the recording goes on, exit 1 only at the end.

The file system's faults are injected at the store's boundary (bustools/ringstore.py Disk, and
outfile.OutputFile under it): deterministic, and root's chmod would not stop a write. A real full
file system (a small tmpfs) where one can be mounted, skipped otherwise."""

from __future__ import annotations

import contextlib
import errno
import json
import os
import subprocess
from pathlib import Path

import pytest

from conftest import run_main
from profidrive_cli import UsageError
from profidrive_cli.bustools import ringstore
from profidrive_cli.bustools.ringstore import (
    DEFAULT_NAME, Disk, DiskState, Failed, Removed, Store, check_pattern, out_pattern, parse_size,
)


class FakeDisk(Disk):
    """A directory in memory: {name: (size, mtime)}, a capacity (a full disk raises ENOSPC), a
    read-only switch (EROFS), a wall clock the test moves."""

    def __init__(self, capacity: int | None = None):
        self.files_: dict[str, tuple[int, float]] = {}
        self.capacity = capacity
        self.other = 0                 # bytes other programs take on the same file system
        self.read_only = False
        self.clock = 1_000_000.0
        self.removed: list[str] = []

    def files(self, directory):
        return [(name, size, mtime) for name, (size, mtime) in self.files_.items()]

    def remove(self, path):
        if self.read_only:
            raise OSError(errno.EROFS, os.strerror(errno.EROFS))
        self.removed.append(Path(path).name)
        del self.files_[Path(path).name]

    def used(self) -> int:
        return sum(size for size, _ in self.files_.values())

    def write(self, path, fill):
        if self.read_only:
            raise OSError(errno.EROFS, os.strerror(errno.EROFS))
        sink = _Counter()
        fill(sink)
        name = Path(path).name
        old = self.files_.get(name, (0, 0.0))[0]
        if self.capacity is not None and self.other + self.used() - old + sink.n > self.capacity:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self.files_[name] = (sink.n, self.clock)

    def now(self):
        return self.clock

    def free(self, directory):
        return None if self.capacity is None else max(0, self.capacity - self.other - self.used())


class _Counter:
    def __init__(self):
        self.n = 0

    def write(self, data):
        self.n += len(data)


def _fill(n):
    return lambda fh: fh.write(b"x" * n)


# -- the pattern ----------------------------------------------------------------------------------

@pytest.mark.parametrize("pattern, words", [
    # the three: an int cannot be indexed, a str has no attribute x, and station 3 takes
    # :03d but a bus-wide event's station "bus" does not
    ("o/{n}{n[0]}.pcap", "the field {n[0]} fails for capture 1: TypeError"),
    ("o/{n}{time.x}.pcap", "the field {time.x} fails for the event's time (YYYYMMDD-HHMMSS): "
                           "AttributeError"),
    ("o/{n}-{station:03d}.pcap", "the field {station:03d} fails for station bus (a bus-wide event"),
    # a trigger label is text: a number format fails for the first one (lost(*) -> lostall)
    ("o/{n}-{trigger:d}.pcap", "the field {trigger:d} fails for trigger lost(*)"),
    # a nested field that does not exist
    ("o/{n:{width}}.pcap", "the field {n:{width}} fails for capture 1: KeyError"),
    ("o/{trigger}/{n}.pcap", "{trigger} is in the directory"),
    ("o/{n}}.pcap", "Single '}'"),
    ("o/{}.pcap", "a pattern may use only {n}, {time}, {trigger}, {station}"),
])
def test_a_pattern_that_fails_for_any_field_value_is_refused_before_the_bus_opens(
        capsys, monkeypatch, tmp_path, pattern, words):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "o").mkdir()
    # a port that does not exist: were it opened, the exit would be 1 (cannot open the port)
    r = run_main(capsys, monkeypatch, "sniff", "--port", str(tmp_path / "no-such-tty"), "--ring", "1",
                 "--after", "0.5", "--trigger", "cycle>1ms", "--out", pattern)
    assert r.exit_code == 2, r.output
    assert words in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert list((tmp_path / "o").iterdir()) == [] and sorted(os.listdir(tmp_path)) == ["o"]


def test_patterns_that_hold_for_every_value_are_accepted(tmp_path):
    for ok in ("{n}.pcap", "{time}-{station}-{trigger}.pcap", "{n:06d}-{station!s:>3}.pcap",
               "ev-{time}.pcap", "{n}-{trigger!r}.pcap"):
        check_pattern(str(tmp_path / ok))


def test_the_recorder_knows_its_own_files_by_the_pattern(tmp_path):
    p = out_pattern(str(tmp_path))
    assert p.text == str(tmp_path / DEFAULT_NAME)
    assert p.owns("pdrive-20261126-140556-1-lostall.pcap")
    assert p.owns("pdrive-20261126-140556-12-cycle3.pcap")
    assert p.owns("pdrive-20261126-140556-12-fcs-13.pcap")         # a second capture, same second
    for other in ("notes.pcap", "pdrive-x.pcap", "pdrive-20261126-140556-1-lostall.pcapng",
                  ".pdrive-20261126-140556-1-lostall.pcap.abc.tmp", "my-20261126-140556-1-x.pcap"):
        assert not p.owns(other), other
    p = check_pattern(str(tmp_path / "ev-{n}-{station}.pcap"))
    assert p.owns("ev-3-bus.pcap") and p.owns("ev-3-126.pcap") and not p.owns("ev-3-x.pcap")


@pytest.mark.parametrize("text, size", [
    ("100M", 100 << 20), ("2G", 2 << 30), ("512k", 512 << 10), ("1.5G", 3 << 29), ("1000", 1000),
    ("64KiB", 64 << 10)])
def test_sizes(text, size):
    assert parse_size(text) == size


@pytest.mark.parametrize("text", ["", "10X", "-1M", "0", "M"])
def test_bad_sizes(text):
    with pytest.raises(UsageError, match="--max-disk"):
        parse_size(text)


@pytest.mark.parametrize("args, words", [
    (["--max-disk", "lots"], "expected a size such as 100M"),
    (["--keep", "0"], "--keep must be above 0 days"),
])
def test_bound_refusals(capsys, monkeypatch, tmp_path, args, words):
    r = run_main(capsys, monkeypatch, "sniff", "--port", "sim://", "--ring", "1", "--trigger",
                 "lost(*)", "--out", str(tmp_path), *args)
    assert r.exit_code == 2 and words in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_max_disk_without_ring_is_refused(capsys, monkeypatch):
    r = run_main(capsys, monkeypatch, "sniff", "--port", "sim://", "--max-disk", "1M")
    assert r.exit_code == 2 and "give --ring SECONDS" in r.stderr


# -- the store: bound, age, faults ----------------------------------------------------------------

def _store(tmp_path, disk, **kw):
    return Store(check_pattern(str(tmp_path / "ev-{n}.pcap")), disk=disk, **kw)


def test_max_disk_removes_the_oldest_own_files_first_and_counts(tmp_path):
    disk = FakeDisk()
    disk.files_["notes.txt"] = (5000, 0.0)           # not the recorder's: never counted nor removed
    store = _store(tmp_path, disk, max_bytes=1000)
    for n in range(1, 4):                            # 3 x 300 = 900 of 1000
        disk.clock += 10
        assert store.save(n, str(tmp_path / f"ev-{n}.pcap"), 300, _fill(300)) == (True, [])
    # the 4th: 900 + 300 > 1000, so the oldest (ev-1) goes: 600 + 300 = 900
    disk.clock += 10
    ok, events = store.save(4, str(tmp_path / "ev-4.pcap"), 300, _fill(300))
    assert ok and [(type(e), Path(e.path).name, e.count) for e in events] == [(Removed, "ev-1.pcap", 1)]
    # the 5th is 700: 900 + 700 > 1000 -> ev-2 (600 + 700 > 1000) and ev-3 (300 + 700 = 1000) go
    disk.clock += 10
    ok, events = store.save(5, str(tmp_path / "ev-5.pcap"), 700, _fill(700))
    assert ok and [(Path(e.path).name, e.count) for e in events] == [("ev-2.pcap", 2), ("ev-3.pcap", 3)]
    assert all(isinstance(e, Removed) and e.why == "--max-disk 1000 B" for e in events)
    assert sorted(disk.files_) == ["ev-4.pcap", "ev-5.pcap", "notes.txt"]
    assert store.removed == 3 and disk.used() - 5000 <= 1000
    # a capture larger than the bound alone is not written; nothing is removed for it
    ok, events = store.save(6, str(tmp_path / "ev-6.pcap"), 1001, _fill(1001))
    assert not ok and isinstance(events[0], Failed) and "more than --max-disk 1000 B alone" in events[0].reason
    assert store.failed == 1 and sorted(disk.files_) == ["ev-4.pcap", "ev-5.pcap", "notes.txt"]


def test_keep_removes_captures_older_than_the_days(tmp_path):
    disk = FakeDisk()
    store = _store(tmp_path, disk, max_bytes=None, keep_s=2 * 86400.0)
    store.save(1, str(tmp_path / "ev-1.pcap"), 10, _fill(10))
    disk.clock += 86400
    store.save(2, str(tmp_path / "ev-2.pcap"), 10, _fill(10))
    disk.clock += 86400 + 1                          # ev-1 is 2 days and 1 s old, ev-2 1 day and 1 s
    ok, events = store.save(3, str(tmp_path / "ev-3.pcap"), 10, _fill(10))
    assert ok and [(Path(e.path).name, e.why) for e in events] == [("ev-1.pcap", "older than --keep 2 days")]


def test_a_full_disk_is_a_state_entered_once_and_left(tmp_path):
    disk = FakeDisk(capacity=1000)
    disk.other = 1000                                # another program filled the file system
    store = _store(tmp_path, disk, max_bytes=10_000)
    got = [store.save(n, str(tmp_path / f"ev-{n}.pcap"), 100, _fill(100)) for n in (1, 2, 3)]
    assert [ok for ok, _ in got] == [False, False, False]
    # one DiskState(full) at the first, then one Failed per capture, each naming its path
    assert isinstance(got[0][1][0], DiskState) and got[0][1][0].full
    assert [[type(e) for e in events] for _, events in got] == [[DiskState, Failed], [Failed], [Failed]]
    assert [e.path for _, events in got for e in events if isinstance(e, Failed)] == [
        str(tmp_path / f"ev-{n}.pcap") for n in (1, 2, 3)]
    assert all(e.reason == os.strerror(errno.ENOSPC) for _, ev in got for e in ev if isinstance(e, Failed))
    disk.other = 0                                   # the space came back
    ok, events = store.save(4, str(tmp_path / "ev-4.pcap"), 100, _fill(100))
    assert ok and len(events) == 1 and isinstance(events[0], DiskState) and not events[0].full
    assert (store.written, store.failed, store.first_failure.n) == (1, 3, 1)


def test_on_a_full_disk_the_oldest_own_captures_make_room_for_the_newest(tmp_path):
    # 1000 bytes of file system, the recorder's bound 10,000: 4 captures of 250 fill it; the 5th
    # meets ENOSPC, the oldest (250 >= 250 needed) goes and the write is tried again: no full state
    disk = FakeDisk(capacity=1000)
    store = _store(tmp_path, disk, max_bytes=10_000)
    for n in range(1, 5):
        disk.clock += 1
        assert store.save(n, str(tmp_path / f"ev-{n}.pcap"), 250, _fill(250))[0]
    disk.clock += 1
    ok, events = store.save(5, str(tmp_path / "ev-5.pcap"), 250, _fill(250))
    assert ok and [(Path(e.path).name, e.why) for e in events] == [
        ("ev-1.pcap", "disk full (No space left on device)")]
    assert not store.full and sorted(disk.files_) == [f"ev-{n}.pcap" for n in range(2, 6)]


def test_read_only_mid_run_fails_each_capture_and_recovers(tmp_path):
    disk = FakeDisk()
    store = _store(tmp_path, disk)
    results = []
    for n in range(1, 7):
        disk.read_only = 3 <= n <= 4                 # remounted read-only for captures 3 and 4
        results.append(store.save(n, str(tmp_path / f"ev-{n}.pcap"), 10, _fill(10)))
    assert [ok for ok, _ in results] == [True, True, False, False, True, True]
    fails = [e for _, ev in results for e in ev]
    assert [(e.n, e.reason, e.full) for e in fails] == [
        (3, "Read-only file system", False), (4, "Read-only file system", False)]
    assert (store.written, store.failed) == (4, 2)


# -- the writer with the real disk: the fault injected at the outfile boundary -------------------

class _FailingFile:
    """A file object whose writes fail with `code` (ENOSPC: the disk is full)."""

    def __init__(self, f, code):
        self._f, self._code = f, code

    def write(self, data):
        raise OSError(self._code, os.strerror(self._code))

    def __getattr__(self, name):
        return getattr(self._f, name)


def failing_outfile(code, after=0):
    """An OutputFile class whose files fail with `code` from the (after+1)-th on."""
    opened = [0]

    class Failing(ringstore.OutputFile):
        def open(self):
            f = super().open()
            opened[0] += 1
            if opened[0] > after:
                self.file = _FailingFile(f, code)
            return self.file
    return Failing


@pytest.mark.parametrize("as_json", [False, True])
def test_the_writer_reports_a_capture_it_cannot_write_and_goes_on(tmp_path, capsys, monkeypatch,
                                                                    as_json):
    from test_json_contract import assert_stream
    from test_recorder import _one_done

    from profidrive_cli.cli.sniff_ring import _Writer
    monkeypatch.setattr(ringstore, "OutputFile", failing_outfile(errno.ENOSPC, after=1))
    tset, done = _one_done()
    w = _Writer(out_pattern(str(tmp_path)), 147, as_json, tset)
    capsys.readouterr()
    assert w.write(done) is True                     # the first file is written
    done.n = 2
    assert w.write(done) is False                    # the second meets a full disk: no exception
    text = capsys.readouterr().out
    (f,) = tmp_path.iterdir()                        # the first capture; no temporary file left
    assert f.name.endswith("-1-lostall.pcap")
    if as_json:
        lines = [json.loads(x) for x in text.splitlines()]
        assert assert_stream(lines, "sniff") == ["trigger", "disk", "error", "trigger"]
        assert lines[0]["written"] is True and lines[3]["written"] is False
        err = lines[2]
        assert (err["capture"], err["reason"], err["exit_code"]) == (2, "No space left on device", 1)
        assert err["path"] == lines[3]["capture"] and err["path"].endswith("-2-lostall.pcap")
    else:
        lines = text.splitlines()
        assert len(lines) == 4
        assert "disk full in" in lines[1] and "still listening" in lines[1]
        assert "error: capture 2 not written: --out " in lines[2] and "No space left on device" in lines[2]
        assert "-2-lostall.pcap NOT WRITTEN (" in lines[3]


@contextlib.contextmanager
def tmpfs(tmp_path, size):
    """A tmpfs of `size` mounted at tmp_path/mnt for the with-block (unmounted after, whatever
    happens: no fault left for the next test); skips where it cannot be mounted."""
    mnt = tmp_path / "mnt"
    mnt.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(mnt)],
                      capture_output=True).returncode != 0:
        pytest.skip("cannot mount a tmpfs here")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", str(mnt)], capture_output=True)


def test_a_real_full_file_system_when_a_tmpfs_can_be_mounted(tmp_path):
    """A 32 KiB tmpfs (8 pages of 4 KiB): captures of 5000 octets take 2 pages each, so 4 fit; the
    5th meets ENOSPC and the oldest own capture makes room for it."""
    with tmpfs(tmp_path, "32k") as mnt:
        store = Store(check_pattern(str(mnt / "ev-{n}.pcap")), max_bytes=1 << 20)
        got = []
        for n in range(1, 7):
            got.append(store.save(n, str(mnt / f"ev-{n}.pcap"), 5000, _fill(5000)))
            if got[-1][0]:
                os.utime(mnt / f"ev-{n}.pcap", (n, n))     # oldest first, whatever the clock's grain
        assert all(ok for ok, _ in got)
        removed = [Path(e.path).name for _, ev in got for e in ev if isinstance(e, Removed)]
        assert removed and removed == [f"ev-{i}.pcap" for i in range(1, len(removed) + 1)]
        assert all("disk full" in e.why for _, ev in got for e in ev if isinstance(e, Removed))
        assert sorted(os.listdir(mnt)) == sorted(f"ev-{n}.pcap" for n in range(len(removed) + 1, 7))
        # the captures taken away, another program fills the file system: nothing of the
        # recorder's own can make room any more
        for name in os.listdir(mnt):
            os.unlink(mnt / name)
        with open(mnt / "filler", "wb") as fh:
            try:
                fh.write(b"\0" * (64 << 10))
                fh.flush()
            except OSError:
                pass
        ok, events = store.save(7, str(mnt / "ev-7.pcap"), 5000, _fill(5000))
        assert not ok and isinstance(events[0], DiskState) and events[0].full
        assert isinstance(events[-1], Failed) and events[-1].reason == os.strerror(errno.ENOSPC)
        assert not [n for n in os.listdir(mnt) if n.endswith(".tmp")]      # nothing half-written


def test_the_writer_says_each_removal_in_the_stream(tmp_path, capsys):
    from test_json_contract import assert_stream
    from test_recorder import _one_done

    from profidrive_cli.cli.sniff_ring import _Writer, pcap_size
    tset, done = _one_done()
    pattern = out_pattern(str(tmp_path))
    size = pcap_size(done.packets)                   # each capture the same size: room for one
    w = _Writer(pattern, 147, True, tset, Store(pattern, max_bytes=size + size // 2))
    capsys.readouterr()
    first = w.write(done)
    os.utime(next(tmp_path.iterdir()), (1, 1))      # the older one, whatever the clock's grain
    done.n = 2
    second = w.write(done)
    lines = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert first and second and assert_stream(lines, "sniff") == ["trigger", "removed", "trigger"]
    assert lines[1]["path"] == lines[0]["capture"] and lines[1]["count"] == 1
    assert lines[1]["bytes"] == size and lines[1]["why"].startswith("--max-disk ")
    assert [p.name for p in tmp_path.iterdir()] == [Path(lines[2]["capture"]).name]


def test_a_directory_gone_mid_run_is_an_error_for_that_capture(tmp_path, capsys):
    # the real disk: the directory removed between two captures (a mount that went away); the
    # error names the capture, its path and the reason once (not "--out PATH: --out PATH: ...")
    from test_recorder import _one_done

    from profidrive_cli.cli.sniff_ring import _Writer
    d = tmp_path / "ev"
    d.mkdir()
    tset, done = _one_done()
    w = _Writer(out_pattern(str(d)), 147, False, tset)
    assert w.write(done)
    for f in d.iterdir():
        f.unlink()
    d.rmdir()
    done.n = 2
    capsys.readouterr()
    assert w.write(done) is False
    (error, trigger) = capsys.readouterr().out.splitlines()
    assert error.count("--out ") == 1 and f"directory {d} does not exist" in error
    assert "error: capture 2 not written: --out " in error and "NOT WRITTEN" in trigger
    assert w.store.failed == 1 and w.store.first_failure.reason.startswith(f"directory {d}")


def test_a_restart_numbers_on_after_an_earlier_runs_captures(tmp_path):
    # an earlier run left ev-7 and ev-12 (and ev-12-13: a second capture named ev-12); the next
    # run's first capture is 13, so ev-{n}.pcap never writes over one of them. Other files and
    # patterns without a plain {n} give no number
    for name in ("ev-7.pcap", "ev-12.pcap", "ev-12-13.pcap", "ev-99.txt", "notes.pcap"):
        (tmp_path / name).write_bytes(b"")
    assert Store(check_pattern(str(tmp_path / "ev-{n}.pcap"))).last_number() == 12
    assert Store(check_pattern(str(tmp_path / "ev-{n:03d}.pcap"))).last_number() == 0
    assert Store(check_pattern(str(tmp_path / "x-{n}.pcap"))).last_number() == 0
    p = out_pattern(str(tmp_path))
    assert p.number("pdrive-20261126-140556-41-fcs-42.pcap") == 41


def test_the_recorder_numbers_from_first_n():
    from profidrive_cli.bustools.recorder import Recorder
    from profidrive_cli.bustools.triggers import TriggerSet, parse
    from test_recorder import _lost_line, frames
    rec = Recorder(TriggerSet(parse("lost(*)")), ring_s=0.5, after_s=1.0, first_n=13)
    (done,) = rec.feed(frames(*_lost_line()))
    assert done.n == 13 and rec.captures == 13


def test_a_real_file_system_remounted_read_only_mid_run(tmp_path):
    """Root writes through chmod, not through a read-only mount: a tmpfs remounted ro after two
    captures refuses the next two (EROFS, one Failed each, no disk-full state), rw again the rest."""
    with tmpfs(tmp_path, "1m") as mnt:
        store = Store(check_pattern(str(mnt / "ev-{n}.pcap")))
        got = []
        for n in range(1, 7):
            if n in (3, 5):
                opt = "remount,ro" if n == 3 else "remount,rw"
                assert subprocess.run(["mount", "-o", opt, str(mnt)], capture_output=True).returncode == 0
            got.append(store.save(n, str(mnt / f"ev-{n}.pcap"), 100, _fill(100)))
        assert [ok for ok, _ in got] == [True, True, False, False, True, True]
        assert [(e.n, e.reason, e.full) for _, ev in got for e in ev] == [
            (3, os.strerror(errno.EROFS), False), (4, os.strerror(errno.EROFS), False)]
        assert sorted(os.listdir(mnt)) == [f"ev-{n}.pcap" for n in (1, 2, 5, 6)]


def test_removals_a_read_only_disk_refuses_are_said_once_per_write(tmp_path):
    # 5 own files of 100 over a bound of 250: on a read-only file system the first removal fails
    # and is said (not counted); the other four are not tried for this write
    disk = FakeDisk()
    store = _store(tmp_path, disk, max_bytes=250)
    for n in range(1, 6):
        disk.files_[f"ev-{n}.pcap"] = (100, float(n))
    disk.read_only = True
    ok, events = store.save(6, str(tmp_path / "ev-6.pcap"), 100, _fill(100))
    assert not ok and [type(e) for e in events] == [Removed, Failed]
    assert events[0].error == "Read-only file system" and store.removed == 0
