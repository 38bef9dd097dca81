"""Finding the bus baud rate (`--baud auto`): listen first, then probe.

1. Listen: at each DP rate, read the line for a while without transmitting. A running master's
   telegrams decode only at the right rate; two telegrams with a valid FCS and end delimiter (SD1,
   SD2 or SD3 — an SD4 token or a lone SC could be line noise) settle it. A bus with a PLC on it is
   never disturbed.
2. Probe: at each rate, FDL status requests (one attempt each) to the given station, or to every
   address until one answers. A slave locked to the bus rate answers only at that rate.

The caller opens the link at a rate (`open_link(rate)`) and makes a Master on it (`make_master`);
this module does the reading and the probing through the Link and Master interfaces and closes every
link it opened except the one it returns.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterable

from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.timing import BAUD_NAMES, CHAR_BITS

#: the rates tried, most common on drive buses first
PROBE_ORDER = (1500000, 187500, 19200, 500000, 93750, 12000000, 45450, 9600, 3000000, 6000000)

#: telegrams with FCS that must be heard to take a rate from listening
HEARD_NEEDED = 2


@dataclass
class BaudFound:
    baud: int
    how: str            # "heard N telegrams of a running master" / "station N answered"

    def describe(self) -> str:
        return f"baud rate {BAUD_NAMES[self.baud]} ({self.how})"


def listen_window(baud: int) -> float:
    """How long to listen at one rate: 300 character times, at least 80 ms (a PLC's DP cycle is
    well under that at the rates where 300 characters take less)."""
    return max(0.08, 300 * CHAR_BITS / baud)


def heard_telegrams(link, seconds: float) -> int:
    """Telegrams with a valid FCS (SD1/SD2/SD3) read from the line within `seconds`."""
    rx = F.Receiver()
    end = link.now() + seconds
    good = 0
    while True:
        now = link.now()
        if now >= end:
            return good
        chunk = link.read(end)
        if not chunk:
            continue
        rx.feed(chunk)
        for item in rx.drain():
            if isinstance(item, F.Frame) and item.sd in (F.SD1, F.SD2, F.SD3):
                good += 1
        if good >= HEARD_NEEDED:
            return good


def detect_baud(open_link: Callable[[int], object], make_master: Callable[[object, int], object],
                addresses: Iterable[int] | None = None, *, listen: bool = True,
                probe: bool = True, rates: Iterable[int] = PROBE_ORDER,
                progress: Callable[[str], None] | None = None):
    """(BaudFound, master-or-link) at the rate found, or (None, None).

    With probe=False only listening is done (and the open link is returned instead of a master).
    """
    rates = tuple(rates)
    if listen:
        for baud in rates:
            link = open_link(baud)
            if getattr(link, "instant", False):
                # the instant simulator has no other master on it: nothing to hear
                link.close()
                break
            if progress:
                progress(f"listening at {BAUD_NAMES[baud]}")
            try:
                n = heard_telegrams(link, listen_window(baud))
            except BaseException:
                link.close()
                raise
            if n >= HEARD_NEEDED:
                found = BaudFound(baud, f"heard {n} telegrams of a running master")
                if not probe:
                    return found, link
                return found, make_master(link, baud)
            link.close()
    if not probe:
        return None, None
    targets = list(addresses) if addresses is not None else list(range(0, 127))
    for baud in rates:
        if progress:
            progress(f"probing at {BAUD_NAMES[baud]}")
        link = open_link(baud)
        try:
            from profidrive_cli.dp.scan import probe as probe_one
            master = make_master(link, baud)
            hit = None
            for addr in targets:
                if addr == master.address:
                    continue
                if probe_one(master, addr) is not None:
                    hit = addr
                    break
        except BaseException:
            link.close()
            raise
        if hit is not None:
            master.fdl.counters.clear()      # the probes are not the command's traffic
            return BaudFound(baud, f"station {hit} answered"), master
        link.close()
    return None, None
