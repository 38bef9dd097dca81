"""The Link interface: what the master needs from a transport. Implement it for other hardware.

    write(data)             send octets (returns when they are handed to the transport)
    read(deadline)          octets that arrived, waiting at most until `deadline` (monotonic seconds)
                            for the first one; b"" when nothing came in time
    flush_input()           drop whatever is buffered (after a timeout, before a retry)
    now()                   the clock deadlines are expressed in (time.monotonic for real ports)
    sleep(seconds)          wait on that clock (the poller's only way to pass time): a plain sleep,
                            or precise_sleep when the link keeps µs timing (`us_timing`)
    reopen()                close and open the same port again (after LinkLost); raises BusError
                            (LinkLost included) while the port is not back
    close()

A Link raises LinkLost when the port disappears (USB pulled, pty closed, socket dropped).
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from types import TracebackType
from typing import TypeVar

from profidrive_cli import BusError


#: the last part of a wait is spent polling the clock: the OS wakes a sleeping thread ~0.1 ms late,
#: which at 187.5 kbit/s and above is more than the idle times the master has to keep. Only worth its
#: CPU on a link that keeps µs timing itself (Link.us_timing): a pty, a USB adapter or a TCP
#: converter adds a millisecond or more of its own, and there the spin would burn CPU for nothing.
SPIN_S = 0.0002


def precise_sleep(seconds: float, clock: Callable[[], float] = time.monotonic) -> None:
    """Sleep, then poll the clock for the last SPIN_S: returns close after `seconds`, never early."""
    if seconds <= 0:
        return
    end = clock() + seconds
    if seconds > SPIN_S:
        time.sleep(seconds - SPIN_S)
    while clock() < end:
        pass


def plain_sleep(seconds: float, clock: Callable[[], float] = time.monotonic) -> None:
    """Sleep without spinning: never returns early (the OS may wake the thread a little late)."""
    if seconds <= 0:
        return
    end = clock() + seconds
    while True:
        time.sleep(seconds)
        seconds = end - clock()
        if seconds <= 0:
            return


class LinkLost(BusError):
    """The port went away under us.

    port      the port name (as given to --port)
    counters  {station address: counters dict} at the moment of the loss, when a master raised it
    """

    def __init__(self, message: str, port: str = "", counters: dict[int, dict[str, int]] | None = None):
        super().__init__(message)
        self.port = port
        self.counters = dict(counters or {})


_L = TypeVar("_L", bound="Link")


class Link(ABC):
    name: str = ""
    is_simulator: bool = False
    #: True when the transport takes no wire time (the instant simulator): the master then skips
    #: the idle gaps (TSYN/TID1) that a real line needs
    instant: bool = False
    #: seconds the transport itself adds to every reply, when it knows (the simulator: 0);
    #: None = unknown, the master keeps the latency margin of its BusParams
    latency: float | None = None
    #: True when the transport keeps sub-millisecond timing (the wire-timed simulator, a link that
    #: drives the line itself): sleep() then spins for the last SPIN_S to meet the bus's idle
    #: times. False (ptys, USB adapters, TCP: a millisecond or more of latency of their own):
    #: sleep() sleeps, spending no CPU on precision the line cannot keep.
    us_timing: bool = False

    @abstractmethod
    def write(self, data: bytes) -> None: ...

    @abstractmethod
    def read(self, deadline: float) -> bytes: ...

    @abstractmethod
    def flush_input(self) -> None: ...

    def now(self) -> float:
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        if self.us_timing:
            precise_sleep(seconds)
        else:
            plain_sleep(seconds)

    def reopen(self) -> None:
        raise LinkLost(f"{self.name or 'the link'}: cannot be reopened", self.name)

    def close(self) -> None:
        pass

    def __enter__(self: _L) -> _L:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
