"""Files pdrive writes: a temporary file beside the target, renamed over it only on success.

Every file pdrive writes (parameter dumps, pcap and raw captures, run logs, checklist reports) goes
through `OutputFile`, so a failed write never destroys the file the user had:

    check_output_path(path)            # before anything moves: the directory must exist and be writable
    with OutputFile(path, "w") as f:   # writes path.<random>.tmp in the same directory
        f.write(...)
    # on a clean exit: flushed, fsynced, renamed over `path`; on an exception: the temporary file is
    # removed and `path` is untouched

pdrive creates no directory. A target that is not a regular file (a character device such as
/dev/null or /dev/full, a FIFO) is written directly: there is no file there to lose, and a rename
would replace the device.

Errors are one line: `OutputPathError` (a UsageError, exit 2) for a path that cannot be written before
anything is written; `OutputWriteError` (exit 1) for a failure while writing (disk full, I/O error).
This module imports nothing of pdrive but the error base classes: every layer may use it.
"""

from __future__ import annotations

import errno
import os
import stat
import tempfile
from pathlib import Path
from types import TracebackType
from typing import IO, Any, Literal, NoReturn

from profidrive_cli import PdriveError, UsageError


class OutputPathError(UsageError):
    """The target cannot be written (missing directory, not a directory, no permission): exit 2."""

    #: the operating system's errno and its words, when an OSError was the cause (a caller that
    #: goes on after a failed write -- the recorder -- tells a full disk from the rest by it)
    errno: int | None = None
    reason: str | None = None


class OutputWriteError(PdriveError):
    """Writing failed part-way (disk full, I/O error); the previous file is untouched: exit 1."""

    errno: int | None = None
    reason: str | None = None


def _reason(e: OSError) -> str:
    return e.strerror or str(e)


def _is_special(p: Path) -> bool:
    """An existing target that is not a regular file (device, FIFO, socket)."""
    try:
        st = os.stat(p)
    except OSError:
        return False
    return not stat.S_ISREG(st.st_mode) and not stat.S_ISDIR(st.st_mode)


def format_by_suffix(path: str | os.PathLike[str], formats: dict[str, str], what: str,
                     named: str) -> str:
    """The format a report option writes, by the file name's extension (`formats`: suffix -> format,
    lower case); OutputPathError (exit 2, before anything is written) for another extension, so a
    page never lands in a file whose name says something else. named: the extensions in words
    (".svg or .png")."""
    fmt = formats.get(Path(str(path)).suffix.lower())
    if fmt is None:
        raise OutputPathError(f"{what} {path}: the file name must end in {named} (the format follows "
                              f"the extension)")
    return fmt


def check_output_path(path: str | os.PathLike[str], what: str = "output file") -> Path:
    """Check, before anything is sent or written, that `path` can be written; creates nothing.

    Raises OutputPathError with the path and the reason in one line.
    """
    p = Path(path)
    if str(path) == "":
        raise OutputPathError(f"{what}: empty path")
    if p.is_dir():
        raise _path_error(what, p, "is a directory")
    if _is_special(p):
        if not os.access(p, os.W_OK):
            raise _path_error(what, p, "permission denied")
        return p
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.exists():
        raise _path_error(what, p, f"directory {parent} does not exist (pdrive creates no "
                                   f"directories)")
    if not parent.is_dir():
        raise _path_error(what, p, f"{parent} is not a directory")
    if not os.access(parent, os.W_OK | os.X_OK):
        if _read_only(parent):
            raise _path_error(what, p, os.strerror(errno.EROFS), errno.EROFS)
        raise _path_error(what, p, f"no permission to write in {parent}")
    if p.exists() and not os.access(p, os.W_OK):
        raise _path_error(what, p, "permission denied")
    return p


def _read_only(directory: Path) -> bool:
    """The directory's file system is mounted read-only (POSIX statvfs; False where unknown)."""
    try:
        return bool(os.statvfs(directory).f_flag & os.ST_RDONLY)
    except (OSError, AttributeError):
        return False


def _path_error(what: str, p: Path | str, reason: str, code: int | None = None) -> OutputPathError:
    """`{what} {path}: {reason}`, the reason (and errno) kept apart for a caller that goes on."""
    e = OutputPathError(f"{what} {p}: {reason}")
    e.errno, e.reason = code, reason
    return e


class OutputFile:
    """A file written to a temporary name beside the target and renamed over it on `commit()`.

    Use as a context manager (commit on a clean exit, discard on an exception) or call `open()`,
    `commit()` and `discard()` yourself for a file that stays open across a long run (a capture, a
    log). Write errors raise OutputWriteError; the target is then untouched.
    """

    def __init__(self, path: str | os.PathLike[str], mode: str = "w", *, encoding: str | None = "utf-8",
                 newline: str | None = None, what: str = "output file"):
        if mode not in ("w", "wb"):
            raise ValueError(mode)
        self.path = Path(path)
        self.mode = mode
        self.encoding = None if "b" in mode else encoding
        self.newline = None if "b" in mode else newline
        self.what = what
        self.file: IO[Any] | None = None
        self._tmp: str | None = None
        self.committed = False
        #: the OutputWriteError of a failed write: every later write, flush or commit raises it
        #: again (the file is gone; nothing more can be written to it)
        self.error: OutputWriteError | None = None

    # -- life cycle -------------------------------------------------------------------------------
    def open(self) -> IO[Any]:
        check_output_path(self.path, self.what)
        try:
            if _is_special(self.path):
                self._tmp = None
                self.file = open(self.path, self.mode, encoding=self.encoding,
                                 newline=self.newline)
            else:
                parent = self.path.parent if str(self.path.parent) else Path(".")
                fd, self._tmp = tempfile.mkstemp(prefix=f".{self.path.name}.", suffix=".tmp",
                                                 dir=parent)
                self.file = os.fdopen(fd, self.mode, encoding=self.encoding, newline=self.newline)
        except OSError as e:
            raise _path_error(self.what, self.path, _reason(e), e.errno) from None
        return self.file

    def write(self, data: str | bytes) -> None:      # str in mode "w", bytes in "wb"
        f = self._check_open()
        try:
            f.write(data)
        except OSError as e:
            self._fail(e)

    def flush(self) -> None:
        f = self._check_open()
        try:
            f.flush()
        except OSError as e:
            self._fail(e)

    def _check_open(self) -> IO[Any]:
        if self.file is None:
            raise self.error or OutputWriteError(f"{self.what} {self.path}: not open")
        return self.file

    def commit(self) -> Path:
        """Flush, fsync and rename over the target. Raises OutputWriteError (target untouched)."""
        if self.committed:
            return self.path
        f = self._check_open()
        try:
            f.flush()
            if self._tmp is not None:
                os.fsync(f.fileno())
            f.close()
        except OSError as e:
            self._fail(e)
        try:
            if self._tmp is not None:
                if self.path.exists():
                    try:
                        os.chmod(self._tmp, stat.S_IMODE(os.stat(self.path).st_mode))
                    except OSError:
                        pass
                else:
                    os.chmod(self._tmp, 0o666 & ~_umask())
                os.replace(self._tmp, self.path)
                self._tmp = None
        except OSError as e:
            self._fail(e)
        self.committed = True
        return self.path

    def discard(self) -> None:
        """Drop the temporary file; the target stays as it was."""
        f, self.file = self.file, None
        if f is not None:
            try:
                f.close()
            except OSError:
                pass
        if self._tmp is not None:
            try:
                os.unlink(self._tmp)
            except OSError:
                pass
            self._tmp = None

    def _fail(self, e: OSError) -> NoReturn:
        self.discard()
        kept = ("; the previous file is untouched" if self.path.exists() and not
                _is_special(self.path) else "")
        self.error = OutputWriteError(f"{self.what} {self.path}: write failed: {_reason(e)}{kept}")
        self.error.errno, self.error.reason = e.errno, _reason(e)
        raise self.error from None

    def __enter__(self) -> OutputFile:
        self.open()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> Literal[False]:
        if exc_type is None:
            self.commit()
        else:
            self.discard()
        return False


def _umask() -> int:
    m = os.umask(0)
    os.umask(m)
    return m


def write_text_atomic(path: str | os.PathLike[str], text: str, what: str = "output file") -> Path:
    """Write a whole text file at once, replacing the old one only on success."""
    with OutputFile(path, "w", what=what) as f:
        f.write(text)
    return Path(path)


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes, what: str = "output file") -> Path:
    with OutputFile(path, "wb", what=what) as f:
        f.write(data)
    return Path(path)
