"""outfile: the old file survives every failed write; nothing is created that the user did not ask for."""

import os

import pytest

from profidrive_cli import UsageError
from profidrive_cli.outfile import (OutputFile, OutputPathError, OutputWriteError,
                                    check_output_path, write_text_atomic)


def test_success_replaces_and_leaves_no_temp(tmp_path):
    p = tmp_path / "backup.yaml"
    p.write_text("old\n")
    write_text_atomic(p, "new\n")
    assert p.read_text() == "new\n"
    assert sorted(os.listdir(tmp_path)) == ["backup.yaml"]


def test_exception_keeps_old_file_byte_for_byte(tmp_path):
    p = tmp_path / "backup.yaml"
    p.write_bytes(b"old contents \x00\xff\n")
    with pytest.raises(RuntimeError):
        with OutputFile(p, "w") as f:
            f.write("half a dump")
            raise RuntimeError("link lost")
    assert p.read_bytes() == b"old contents \x00\xff\n"
    assert sorted(os.listdir(tmp_path)) == ["backup.yaml"]


def test_missing_directory_is_a_usage_error_and_creates_nothing(tmp_path):
    target = tmp_path / "nodir" / "x.json"
    with pytest.raises(OutputPathError) as ei:
        check_output_path(target)
    assert isinstance(ei.value, UsageError)
    assert "does not exist" in str(ei.value)
    assert not (tmp_path / "nodir").exists()


def test_directory_target_refused(tmp_path):
    with pytest.raises(OutputPathError, match="is a directory"):
        check_output_path(tmp_path)


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full")
def test_dev_full_is_a_write_error_not_a_rename():
    f = OutputFile("/dev/full", "w")
    f.open()
    f.write("x" * 10)
    with pytest.raises(OutputWriteError, match="/dev/full"):
        f.commit()
    assert os.path.exists("/dev/full") and not os.path.isfile("/dev/full")


@pytest.mark.skipif(os.geteuid() == 0, reason="root can write anywhere")
def test_unwritable_directory(tmp_path):
    d = tmp_path / "ro"
    d.mkdir()
    d.chmod(0o500)
    try:
        with pytest.raises(OutputPathError, match="no permission"):
            check_output_path(d / "x")
    finally:
        d.chmod(0o700)


def test_mode_of_existing_file_kept(tmp_path):
    p = tmp_path / "log.csv"
    p.write_text("a\n")
    p.chmod(0o640)
    write_text_atomic(p, "b\n")
    assert (p.stat().st_mode & 0o777) == 0o640


def test_after_a_failed_write_every_use_raises_the_same_one_line_error(tmp_path):
    """A file that failed (disk full) is gone: a later write, flush or commit says so again as
    OutputWriteError -- never AttributeError on the dropped file object (issue: a failed --trace
    made the safe stop's own telegrams raise AttributeError)."""
    import errno
    p = tmp_path / "t.pcap"
    out = OutputFile(p, "wb", what="trace file")
    out.open()

    class Full:
        def write(self, data):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        def close(self):
            pass
    out.file = Full()
    with pytest.raises(OutputWriteError) as first:
        out.write(b"x")
    text = str(first.value)
    assert text == f"trace file {p}: write failed: No space left on device"
    for use in (lambda: out.write(b"y"), out.flush, out.commit):
        with pytest.raises(OutputWriteError) as again:
            use()
        assert str(again.value) == text
    assert os.listdir(tmp_path) == []                  # the temporary file is gone, none created
