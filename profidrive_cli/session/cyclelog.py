"""The --log CSV: one row per Data_Exchange (time, cycle, control word, reference, status word,
actual, output and input octets), written through outfile.OutputFile to a temporary file beside the
target and renamed over it when the session closes, also after Ctrl-C or a trip (the log of such a
run is the one wanted). A write that fails mid-run, or any exception while a row is made (a
column's value), never disturbs the cycle (nor the stop): logging ends, the temporary file is
dropped, the old file stays, and `error` holds the OutputWriteError the session raises on close
(exit 1). Reads the drive's layout only to name the words; no bus traffic.
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any, Callable, Sequence

from profidrive_cli.outfile import OutputFile, OutputWriteError


#: (column names, row()) of values logged beside each exchange (run --monitor)
Extra = tuple[Sequence[str], Callable[[], Sequence[object]]]


class CycleLog:
    """Opened at once (header row written); hooked onto `channel` (a MeteredChannel). `drive_of()`
    gives the Drive whose layout names the words (None before it exists); `warn(text)` is told when
    logging stops. close() renames the file into place (or keeps the error in .error)."""

    def __init__(self, path: str | Path, channel: Any, t0: float, drive_of: Callable[[], object],
                 warn: Callable[[str], None],
                 extra: Extra | None = None):
        self.path = path
        #: (column names, row()) of values logged beside each exchange (run --monitor), or None
        self.extra = extra
        self.channel = channel
        self.t0 = t0
        self.drive_of = drive_of
        self.warn = warn
        #: OutputWriteError when the --log file could not be written
        self.error: OutputWriteError | None = None
        out = OutputFile(path, "w", newline="", what="--log")
        f = out.open()
        self._file: OutputFile | None = out
        self._writer = csv.writer(f)
        channel.hooks.append(self.log_cycle)
        self._row(["time_s", "cycle", "control_word", "reference", "status_word",
                   "actual", "outputs", "inputs"] + (list(extra[0]) if extra else []))

    def log_cycle(self, t: float, outputs: bytes, inputs: bytes) -> None:
        # called inside every Data_Exchange, the safe stop's too: nothing may escape from here
        if self._file is None:
            return
        try:
            ctw, ref, stw, act = cycle_words(self.drive_of(), outputs, inputs)
            row = [f"{t - self.t0:.4f}", self.channel.cycles, _hex4(ctw), _s16(ref), _hex4(stw),
                   _s16(act), outputs.hex(), inputs.hex()] + (list(self.extra[1]()) if self.extra
                                                              else [])
        except Exception as e:              # noqa: BLE001  (a column's value: logging stops)
            self._failed(e)
            return
        self._row(row)

    def _row(self, row: Sequence[object]) -> None:
        try:
            self._writer.writerow(row)
        except Exception as e:              # noqa: BLE001  (OSError: disk full; any other: logging stops)
            self._failed(e)

    def _failed(self, e: Exception) -> None:
        out, self._file = self._file, None
        assert out is not None              # only while logging (log_cycle checks it)
        kept = out.path.is_file()           # a regular file there: it stays as it was
        out.discard()
        why = (f"write failed: {e.strerror or e}" if isinstance(e, OSError) else
               f"logging failed: {type(e).__name__}: {e}")
        self.error = OutputWriteError(f"--log {self.path}: {why}"
                                      + ("; the previous file is untouched" if kept else ""))
        try:
            self.warn(f"{self.error}; logging stopped")
        except Exception:                   # noqa: BLE001  (said again when the session closes)
            pass

    def close(self) -> None:
        out, self._file = self._file, None
        if out is None:
            return
        try:
            out.commit()
        except OutputWriteError as e:
            self.error = e


def _hex4(v: int | None) -> str:
    return "" if v is None else f"0x{v & 0xFFFF:04X}"


def _s16(v: int | None) -> str:
    if v is None:
        return ""
    v &= 0xFFFF
    return str(v - 0x10000 if v & 0x8000 else v)


def cycle_words(drive: Any, outputs: bytes, inputs: bytes
                ) -> tuple[int | None, int | None, int | None, int | None]:
    """(control word, reference, status word, actual) of one exchange, whatever the family."""
    try:
        words: tuple[int | None, int | None, int | None, int | None] = drive.cycle_words(outputs, inputs)
        return words                                     # drives.base.Drive: the codec's own words
    except Exception:
        pass
    return None, None, None, None
