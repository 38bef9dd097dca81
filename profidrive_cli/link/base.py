"""The Link interface: what the master needs from a transport. Implement it for other hardware.

    write(data)             send octets (returns when they are handed to the transport)
    read(deadline)          octets that arrived, waiting at most until `deadline` (monotonic seconds)
                            for the first one; b"" when nothing came in time
    flush_input()           drop whatever is buffered (after a timeout, before a retry)
    now()                   the clock deadlines are expressed in (time.monotonic for real ports)
    close()

A Link raises LinkLost when the port disappears (USB pulled, pty closed, socket dropped).
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod

from profidrive_cli import BusError


class LinkLost(BusError):
    """The port went away under us."""


class Link(ABC):
    name: str = ""
    is_simulator: bool = False
    #: True when the transport takes no wire time (the instant simulator): the master then skips
    #: the idle gaps (TSYN/TID1) that a real line needs
    instant: bool = False

    @abstractmethod
    def write(self, data: bytes) -> None: ...

    @abstractmethod
    def read(self, deadline: float) -> bytes: ...

    @abstractmethod
    def flush_input(self) -> None: ...

    def now(self) -> float:
        return time.monotonic()

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
