"""Passive listening: the reading loop of `pdrive sniff` and of the Wireshark extcap capture.

Reads a Link until a duration has passed (or forever, until the caller is interrupted) and hands every
chunk of octets to a callback with its time since the start (monotonic clock). Never transmits.
Decoding (dp/capture.py) and output (pcap, text, JSON) stay with the caller.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Callable

if TYPE_CHECKING:
    from profidrive_cli.link.base import Link

#: a read returns at least this often, so that a duration ends on time on a silent bus
POLL_S = 0.2


def listen(link: Link, duration: float | None, on_data: Callable[[bytes, float], None],
           clock: Callable[[], float] = time.monotonic,
           on_tick: Callable[[float], None] | None = None, poll_s: float = POLL_S) -> None:
    """Read `link` for `duration` seconds (None: until an exception, e.g. KeyboardInterrupt or a
    closed pcap pipe, ends it); on_data(octets, seconds since the start) for every chunk read, and
    on_tick(seconds since the start) after every read, data or not (a live view refreshes there);
    a read returns at least every `poll_s` seconds of the clock."""
    start = clock()
    end = None if duration is None else start + duration
    while end is None or clock() < end:
        now = clock()
        data = link.read(now + poll_s if end is None else min(end, now + poll_s))
        if data:
            on_data(data, clock() - start)
        if on_tick is not None:
            on_tick(clock() - start)
