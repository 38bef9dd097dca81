"""The live list: FDL status to every address, then Slave_Diag (and Get_Cfg) to each slave found.

Two passes. The quick pass sends one FDL status to every address (a second only after a garbled
answer): its wire time is that of an empty bus. The warm-up pass then sends up to WARMUP_PROBES - 1
more FDL status requests to each address that stayed silent, one after the other, stopping at the
first answer: a slave still searching the baud rate (Baud_Search, IEC 61158; every GSD file in gsd/
declares Auto_Baud_supp = 1) answers nothing until it has heard a few telegrams at the bus rate.

WARMUP_PROBES = 5, the bound, and why: a real Siemens ET200S answered only the 5th FDL status
request at 19.2 kbit/s (pyprofibus issue #26; ../shared/testdata/external/
pyprofibus26-et200s-startup.txt: four unanswered requests, then the answer), and kolod/profibus sends
5 to 10 "warm-up" FDL status probes before a Siemens CBP2 drive board answers: five wakes the
ET200S and the lower end of the CBP2 figure. A slower slave is woken by the bring-up of a drive
command, which keeps asking the address it was given (dp/poller.py Master.slave_diag(wake=True),
then bring_up's start-up for its whole timeout). The price: on an empty bus the warm-up pass is
WARMUP_PROBES - 1 more short requests per address (each one telegram and a slot time); `quick=`
(`pdrive scan --quick`) leaves it out.

A station is listed only when its answer is a valid telegram, or a short acknowledgement (SC, the
single octet 0xE5) that a second probe confirms: a lone noise octet 0xE5 reads as an SC and must not
make a phantom station (issue 26). And since an SC carries no address, a station known only from SCs
is kept only when its Slave_Diag is then answered with a valid telegram: noise that happened to
fill two slots in a row (a noisy line) still lists nothing that is not there.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol
from dataclasses import dataclass, field

from profidrive_cli import BusError
from profidrive_cli.dp.services import SlaveDiag
from profidrive_cli.fdl import frames as F

if TYPE_CHECKING:
    from profidrive_cli.fdl.master import FdlMaster
    from profidrive_cli.fdl.timing import BusParams


class ScanMaster(Protocol):
    """What a scan uses of dp.poller.Master (which imports this module)."""

    params: BusParams

    @property
    def address(self) -> int: ...

    @property
    def fdl(self) -> FdlMaster: ...

    def fdl_status(self, da: int) -> F.Frame | None: ...

    def slave_diag(self, da: int, wake: bool = False) -> SlaveDiag | None: ...

    def get_cfg(self, da: int) -> bytes | None: ...

#: FDL status requests to one silent address before it counts as empty (see the module text)
WARMUP_PROBES = 5


@dataclass
class ScanEntry:
    address: int
    station_type: str                 # slave / master not ready / master ready / master in ring
    diag: SlaveDiag | None = None
    cfg: bytes | None = None
    error: str = ""
    counters: dict[str, int] = field(default_factory=dict)
    #: FDL status requests it left unanswered before its answer (0: it answered the first;
    #: more: it was still searching the baud rate, the warm-up pass woke it)
    unanswered: int = 0
    #: its only answers were short acknowledgements (SC: no address in them)
    sc_only: bool = False

    @property
    def ident(self) -> int | None:
        return self.diag.ident if self.diag else None


def probe(master: ScanMaster, addr: int) -> F.Frame | None:
    """One FDL status request, as a live list sends it: a single attempt, and a second (with the
    configured retries) only where something answered garbled. An empty address costs one request
    and one slot time, not 1 + retries of them. The reply frame, or None."""
    params = master.params
    before = master.fdl.counters_for(addr).illegal
    master.params = dataclasses.replace(params, retries=0)
    try:
        reply = master.fdl_status(addr)
    finally:
        master.params = params
    if reply is None and master.fdl.counters_for(addr).illegal > before:
        reply = master.fdl_status(addr)
    if reply is not None and reply.sd == F.SC:
        # an SC carries no address: a lone noise octet 0xE5 looks the same. Listed only when a
        # second probe confirms it (a real station answers again; noise does not repeat itself)
        reply = master.fdl_status(addr)
    return reply


def wake(master: ScanMaster, addr: int, probes: int = WARMUP_PROBES) -> tuple[F.Frame | None, int]:
    """Up to `probes` FDL status requests (probe()) to `addr` until one is answered: a slave still
    searching the baud rate answers only after a few. (reply frame, unanswered probes before it), or
    (None, probes) when the address stayed silent."""
    for n in range(probes):
        reply = probe(master, addr)
        if reply is not None:
            return reply, n
    return None, probes


def _entry(addr: int, reply: F.Frame, unanswered: int = 0) -> ScanEntry:
    sc = reply.sd == F.SC
    return ScanEntry(addr, "slave" if sc else F.STATION_TYPES[reply.station_type],
                     unanswered=unanswered, sc_only=sc)


def scan(master: ScanMaster, first: int = 0, last: int = 126,
         progress: Callable[[int], object] | None = None, read_cfg: bool = False,
         quick: bool = False) -> list[ScanEntry]:
    """progress(address) is called before each probe of the quick pass (for a progress bar).
    quick: no warm-up pass (one FDL status per address; a slave in Baud_Search is missed)."""
    found: list[ScanEntry] = []
    silent: list[int] = []
    for addr in range(first, last + 1):
        if progress:
            progress(addr)
        if addr == master.address:
            continue
        reply = probe(master, addr)
        if reply is None:
            silent.append(addr)
            continue
        found.append(_entry(addr, reply))
    if not quick and WARMUP_PROBES > 1:
        for addr in silent:
            reply, n = wake(master, addr, WARMUP_PROBES - 1)
            if reply is not None:
                found.append(_entry(addr, reply, 1 + n))
        found.sort(key=lambda e: e.address)
    for e in found:
        if e.station_type != "slave":
            continue
        try:
            e.diag = master.slave_diag(e.address)
            if e.diag is None:
                e.error = "no answer to Slave_Diag"
            elif read_cfg:
                e.cfg = master.get_cfg(e.address)
        except BusError as ex:
            e.error = str(ex)
        e.counters = master.fdl.counters_for(e.address).as_dict()
    # known only from SCs and no valid telegram to Slave_Diag either: noise, not a station
    return [e for e in found if not (e.sc_only and e.diag is None)]
