"""A frame-level trace of what a command sends and receives: `-vv` logs every telegram, `--trace
FILE.pcap` records them.

`TraceLink` wraps any Link. Every octet written is decoded as a request ("->"), every octet read as
a reply ("<-"), through the same capture decoder `pdrive sniff` uses, and each telegram is

- logged on the `profidrive_cli.trace` logger at DEBUG (time since the link was opened, direction,
  SD, addresses, SAPs, FC in words, the DP service's name, the data in hex), and
- written to a pcap recorder, when one is given (anything with write(t, raw): dp.capture.PcapWriter).

The recorder sits in the link's write and read path, in the middle of every Data_Exchange and of
the safe stop's own telegrams: it must never break them. A recorder that raises (a full disk, any
bug) is dropped at once and its exception kept in `recorder_error`; the telegram itself has been
sent (write) or is returned (read) as if nothing happened. Whoever gave the recorder reports the
error when the command is over (cli/common.py: one line, exit 1).

The DP service steps (station start-up, diagnosis, retries, re-parameterisation) are logged by the
poller on `profidrive_cli.dp` at INFO (`-v`). A library user configures these loggers like any other.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any, Protocol

from profidrive_cli.dp.capture import Capture, format_line, merge_errors
from profidrive_cli.link.base import Link

log = logging.getLogger("profidrive_cli.trace")


class PacketRecorder(Protocol):
    """Where TraceLink records each telegram (a PcapWriter): its wall-clock time and octets."""

    def write(self, t: float, raw: bytes) -> None: ...


class TraceLink(Link):
    def __init__(self, inner: Link, recorder: PacketRecorder | None = None,
                 wall_clock: Callable[[], float] = time.time):
        self.inner = inner
        self.recorder = recorder
        self.name = inner.name
        self.is_simulator = inner.is_simulator
        self.instant = inner.instant
        self.latency = inner.latency
        self.us_timing = inner.us_timing
        self._t0 = inner.now()
        self._wall0 = wall_clock()
        self._tx = Capture()
        self._rx = Capture()
        #: telegrams seen each way (tests, summaries)
        self.sent = 0
        self.received = 0
        #: the exception the recorder raised (recording stopped there), else None
        self.recorder_error: BaseException | None = None

    def __getattr__(self, name: str) -> Any:      # whatever the wrapped link offers
        # anything else the wrapped link offers (ser, reopen hooks, …)
        return getattr(self.inner, name)

    def _emit(self, cap: Capture, data: bytes, arrow: str) -> int:
        t = self.inner.now() - self._t0
        n = 0
        for c in merge_errors(cap.feed(data, t)):
            n += 1
            if self.recorder is not None and c.frame is not None:
                try:
                    self.recorder.write(self._wall0 + c.t, c.raw)
                except Exception as e:      # noqa: BLE001  (never from inside an exchange)
                    self.recorder, self.recorder_error = None, e
            if log.isEnabledFor(logging.DEBUG):
                log.debug(format_line(c, arrow))
        return n

    def write(self, data: bytes) -> None:
        self.inner.write(data)
        self.sent += self._emit(self._tx, bytes(data), "->")

    def read(self, deadline: float) -> bytes:
        data = self.inner.read(deadline)
        if data:
            self.received += self._emit(self._rx, data, "<-")
        return data

    def flush_input(self) -> None:
        self.inner.flush_input()
        self._rx.rx.reset()         # a retry starts a new reply

    def now(self) -> float:
        return self.inner.now()

    def sleep(self, seconds: float) -> None:
        self.inner.sleep(seconds)

    def reopen(self) -> None:
        self.inner.reopen()
        self._tx.rx.reset()
        self._rx.rx.reset()

    def close(self) -> None:
        self.inner.close()
