"""Finding the bus baud rate (`--baud auto`): listen first, then probe.

1. Listen: at each DP rate, read the line for a while without transmitting. A running master's
   telegrams decode only at the right rate; two telegrams with a valid FCS and end delimiter (SD1,
   SD2 or SD3 — an SD4 token or a lone SC could be line noise) settle it. A bus with a PLC on it is
   never disturbed.
2. Probe: at each rate, FDL status requests (one attempt each) to the given station, or to every
   address until one answers. A slave locked to the bus rate answers only at that rate. A named
   station gets up to dp/scan.py's WARMUP_PROBES at each rate (a slave still searching the rate,
   Baud_Search, answers only after a few: see there); every address gets one (127 addresses times
   ten rates: the warm-up there would cost minutes at the slow rates).

A line without a baud rate of its own -- a pty (`pdrive sim --pty`), a TCP connection (socket://, a
converter or `pdrive sim --listen`), the simulator without baud= -- carries the octets whatever rate
the master sets, so every rate "answers" and the first one tried would be reported. There nothing can
be found: the station's answer (or the master heard) is reported with the words that the line has no
rate of its own, and RATELESS_BAUD, the rate the commands use without --baud, is used.

The caller opens the link at a rate (`open_link(rate)`) and makes a Master on it (`make_master`);
this module does the reading and the probing through the Link and Master interfaces and closes every
link it opened except the one it returns.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Iterable, TypeAlias

from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.timing import BAUD_NAMES, CHAR_BITS

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.dp.poller import Master
    from profidrive_cli.link.base import Link

#: the rates tried, most common on drive buses first
PROBE_ORDER = (1500000, 187500, 19200, 500000, 93750, 12000000, 45450, 9600, 3000000, 6000000)

#: telegrams with FCS that must be heard to take a rate from listening
HEARD_NEEDED = 2

#: the rate used on a line that has none of its own: the commands' default without --baud
RATELESS_BAUD = 19200


@dataclass
class BaudFound:
    baud: int
    how: str            # "heard N telegrams of a running master" / "station N answered"

    def describe(self) -> str:
        return f"baud rate {BAUD_NAMES[self.baud]} ({self.how})"


#: (the rate found, the master made on it or, listening only, the link), or (None, None)
_Found: TypeAlias = "tuple[BaudFound, Master | Link] | tuple[None, None]"


def rateless(link: Link) -> str | None:
    """What the line is when it has no baud rate of its own (a pty, a TCP connection, the simulator
    without baud=), None for a serial line (or rfc2217://, which sets the converter's rate)."""
    from profidrive_cli.link.serial_link import _is_pty
    name = str(getattr(link, "name", "") or "")
    if name.startswith("socket://"):
        return "a TCP connection (socket://)"
    if _is_pty(name):
        return f"a pty ({name})"
    if name.startswith("sim://") and getattr(getattr(link, "ser", None), "locked_baud", 0) is None:
        return "the simulator without baud="
    return None


def listen_window(baud: int) -> float:
    """How long to listen at one rate: 300 character times, at least 80 ms (a PLC's DP cycle is
    well under that at the rates where 300 characters take less)."""
    return max(0.08, 300 * CHAR_BITS / baud)


def heard_telegrams(link: Link, seconds: float) -> int:
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


def detect_baud(open_link: Callable[[int], Link], make_master: Callable[[Link, int], Master],
                addresses: Iterable[int] | None = None, *, listen: bool = True,
                probe: bool = True, rates: Iterable[int] = PROBE_ORDER,
                progress: Callable[[str], None] | None = None) -> _Found:
    """(BaudFound, master-or-link) at the rate found, or (None, None).

    With probe=False only listening is done (and the open link is returned instead of a master).
    """
    rates = tuple(rates)
    checked = False                      # the first link opened says whether the line has a rate
    if listen:
        for baud in rates:
            link = open_link(baud)
            what, checked = (rateless(link) if not checked else None), True
            if what is not None:
                return _on_a_rateless_line(link, what, make_master, addresses, listen=listen,
                                           probe=probe, progress=progress)
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
        what, checked = (rateless(link) if not checked else None), True
        if what is not None:
            return _on_a_rateless_line(link, what, make_master, addresses, listen=False,
                                       probe=True, progress=progress)
        try:
            master = make_master(link, baud)
            hit = None
            for addr in targets:
                if addr == master.address:
                    continue
                if _answers(master, addr, named=addresses is not None):
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


def _on_a_rateless_line(link: Link, what: str, make_master: Callable[[Link, int], Master],
                        addresses: Iterable[int] | None, *, listen: bool, probe: bool,
                        progress: Callable[[str], None] | None) -> _Found:
    """detect_baud on a line without a rate: listen and probe once on `link` (opened at whatever
    rate: the octets are the same) with a master at RATELESS_BAUD, and say so."""
    name = BAUD_NAMES[RATELESS_BAUD]
    why = f"{what} has no baud rate of its own, so any rate answers; {name} is used, the default"
    try:
        if listen and not getattr(link, "instant", False):
            if progress:
                progress(f"listening on {what}")
            n = heard_telegrams(link, listen_window(RATELESS_BAUD))
            if n >= HEARD_NEEDED:
                found = BaudFound(RATELESS_BAUD, f"heard {n} telegrams of a running master; {why}")
                return (found, link) if not probe else (found, make_master(link, RATELESS_BAUD))
        if not probe:
            link.close()
            return None, None
        if progress:
            progress(f"probing on {what}")
        master = make_master(link, RATELESS_BAUD)
        targets = list(addresses) if addresses is not None else list(range(0, 127))
        hit = next((a for a in targets if a != master.address
                    and _answers(master, a, named=addresses is not None)), None)
    except BaseException:
        link.close()
        raise
    if hit is None:
        link.close()
        return None, None
    master.fdl.counters.clear()          # the probes are not the command's traffic
    return BaudFound(RATELESS_BAUD, f"station {hit} answered; {why}"), master


def _answers(master: Master, addr: int, named: bool) -> bool:
    """An FDL status answer from `addr`: a named station gets the warm-up probes (dp/scan.py wake),
    an address of a search through all of them one probe."""
    from profidrive_cli.dp.scan import probe, wake
    if named:
        return wake(master, addr)[0] is not None
    return probe(master, addr) is not None
