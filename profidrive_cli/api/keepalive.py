"""The keep-alive thread of an API bus (api/bus.py): while nobody calls, it holds every opened drive
in data exchange -- one pass (Bus._keep_once: the bus lock, a Data_Exchange for each station due,
what it did not hold reported) every half keep period. It holds the bus weakly (a bus the script
drops is closed, with a ResourceWarning) and ends when the bus closes or a pass fails.

Its figures: KEEP_S between two Data_Exchanges of a station at most (a fifth of the watchdog if
shorter), and the watchdog a drive opened by the API gets unless given (API_WATCHDOG_MS), with the
margin a late thread needs."""

from __future__ import annotations

import logging
import threading
import weakref
from typing import TYPE_CHECKING, Callable, Protocol

from profidrive_cli.drives.base import DriveError

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.session.group import KeepMiss

log = logging.getLogger("profidrive_cli.api")

#: at most this long between two Data_Exchanges of an opened station (a shorter watchdog shortens
#: it to a fifth of the watchdog)
KEEP_S = 0.1

#: the DP watchdog of a drive opened with Bus.drive() unless given (ms). Between calls the station
#: is held by the keep-alive thread alone, and that thread must get the CPU and the GIL to send: with
#: 1 / 2 / 4 / 8 busy Python threads beside it in the process, the largest gap between two of its
#: Data_Exchanges was 0.17 / 0.22 / 0.39 / 0.59 s (once 0.86 s with 8; sim://, 8 s each, a 2-core
#: machine at load 2-7; 0.10 s at rest, 0.15 s by design: KEEP_S plus half of it, the thread's
#: wake-up period) -- past a 500 ms watchdog with 8, and the drive tripped. 1000 ms holds a thread
#: late by 0.85 s: a few busy threads; more (or processes at a higher priority) need a longer one,
#: or the work in another process.
API_WATCHDOG_MS = 1000.0


class Kept(Protocol):
    """What the thread needs of its bus (api.bus.Bus)."""

    def _keep_once(self) -> float | None: ...


def start(bus: Kept, stop: threading.Event) -> threading.Thread:
    """The keep-alive thread of `bus`, started; it ends when `stop` is set (or the bus is gone)."""
    t = threading.Thread(target=_loop, args=(weakref.ref(bus), stop), name="pdrive-keepalive",
                         daemon=True)
    t.start()
    return t


def _loop(ref: "weakref.ref[Kept]", stop: threading.Event) -> None:
    period: float | None = KEEP_S / 2
    while period is not None and not stop.wait(period):
        bus = ref()
        if bus is None:
            return
        period = bus._keep_once()
        del bus                              # not held while waiting: a dropped bus is collected


def failed(port: str, e: BaseException, message: Callable[[str], None]) -> None:
    """A pass failed (raised at the bus's next call): the drives are no longer kept -- said now,
    through logging and `message` (on_message)."""
    text = (f"{port}: keeping the drives in data exchange failed: {e}; their DP watchdogs end "
            f"data exchange and each drive reacts as to a lost master")
    log.warning("%s", text)
    message(f"warning: {text}")


class Missed:
    """The stations the keep-alive did not hold (session.group.KeepMiss): each said at once, through
    logging and `warn` (the drive's: its warnings and on_message), and raised by its drive's next
    call (DriveError with the same words, once)."""

    def __init__(self) -> None:
        self._texts: dict[int, str] = {}

    def note(self, miss: "KeepMiss", warn: Callable[[str], None]) -> None:
        text = miss.words()
        self._texts[miss.address] = text
        log.warning("%s", text)
        warn(text)

    def check(self, station: int) -> None:
        """DriveError when the keep-alive did not hold `station` since its last call."""
        text = self._texts.pop(station, None)
        if text is not None:
            raise DriveError(text)
