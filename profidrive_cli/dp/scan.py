"""The live list: FDL status to every address, then Slave_Diag (and Get_Cfg) to each slave found.

A slave still searching the baud rate answers nothing (Baud_Search, IEC 61158; every GSD file in gsd/
declares Auto_Baud_supp = 1). It takes the rate from the first valid telegram it receives at the
line's rate -- SD1, SD2 or SD3 from any station to any station, not only one addressed to it --
once its search, rate after rate, has reached the line's (the DP slave ASIC as the ProSoft MVI46-PDPS
manual describes the SPC3; sim/slave.py SimSlave.baud_search models it). So what wakes it is traffic
on the line, and a scan makes plenty: the probes to the other addresses wake it as well as its own.

The passes. The quick pass sends one FDL status to every address (a second only after a garbled
answer): its wire time is that of an empty bus. Then, unless quick= (`pdrive scan --quick`), the
second pass sends one more FDL status to each address that stayed silent: on a full scan 0..126 a
searching slave has by then heard the 125 other probes of the quick pass (and the answers), and
had the quick pass's time to bring its search to the line's rate. An empty bus costs 2 x 126 FDL
status requests (a quick pass 126, the second 126), against 126 + 4 x 126 with five probes per
address before: at most twice the quick pass's traffic.

The bounded extra, for a narrow range (`scan --from 3 --to 3`, the Python API's scan of one address
after the other), where the quick pass alone makes too little traffic: each silent address is asked
again, pass after pass, until it has been asked once after the line carried WAKE_TELEGRAMS = 10
telegrams (counted from the master's own requests since the link opened: the answers of others
and the traffic of other masters only make it more). The figures: a real Siemens ET200S took the
rate from the 5th telegram on its line, with nothing else on the line than the four unanswered FDL
status requests to it before (pyprofibus issue #26; ../shared/testdata/external/
pyprofibus26-et200s-startup.txt), and kolod/profibus sends 5 to 10 "warm-up" FDL status requests
before a Siemens CBP2 drive board answers: ten telegrams cover both. Each extra probe is a telegram
more on the line, so the extra is at most WAKE_TELEGRAMS requests in a whole scan (none on a full
range: the second pass comes after 126 telegrams), and a scan sends at most 2 x (addresses) +
WAKE_TELEGRAMS FDL status requests (plus the second attempts after a garbled answer or a lone SC).
A slower slave is woken by the bring-up of a drive command, which keeps asking the address it was
given (dp/poller.py Master.slave_diag(wake=True): WARMUP_PROBES, then bring_up's start-up for its
whole timeout).

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

#: FDL status requests to one named station before it counts as silent (wake(): the drive
#: commands' first contact and `--baud auto` for a named station, where the requests to it are the
#: only traffic on the line: the ET200S's five, pyprofibus issue #26)
WARMUP_PROBES = 5
#: a scan asks each silent address once after the line carried this many telegrams (the module
#: text: the ET200S's 5 and the upper end of the CBP2's 5 to 10)
WAKE_TELEGRAMS = 10


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


def _sent(master: ScanMaster, addr: int) -> int:
    """Telegrams the master has sent to `addr` (requests and their repetitions)."""
    c = master.fdl.counters_for(addr)
    return c.requests + c.retries


def scan(master: ScanMaster, first: int = 0, last: int = 126,
         progress: Callable[[int], object] | None = None, read_cfg: bool = False,
         quick: bool = False) -> list[ScanEntry]:
    """progress(address) is called before each probe of the quick pass (for a progress bar).
    quick: the quick pass only (one FDL status per address; a slave still searching the baud rate
    is found only when the traffic before its probe woke it). See the module text for the passes
    and their cost."""
    found: list[ScanEntry] = []
    # the telegrams the master has put on the line (a lower bound: counters may have been cleared)
    line = sum(c.requests + c.retries for c in master.fdl.counters.values())
    asked: dict[int, int] = {}       # silent address -> FDL status requests it left unanswered
    for addr in range(first, last + 1):
        if progress:
            progress(addr)
        if addr == master.address:
            continue
        sent = _sent(master, addr)
        reply = probe(master, addr)
        line += _sent(master, addr) - sent
        if reply is not None:
            found.append(_entry(addr, reply))
            continue
        asked[addr] = 1
    if not quick:
        pending = list(asked)        # the second pass: every silent address once more
        while pending:
            later: list[int] = []
            for addr in pending:
                before, sent = line, _sent(master, addr)
                reply = probe(master, addr)
                line += _sent(master, addr) - sent
                if reply is not None:
                    found.append(_entry(addr, reply, asked.pop(addr)))
                    continue
                asked[addr] += 1
                if before < WAKE_TELEGRAMS:
                    later.append(addr)
            # the bounded extra: only addresses asked before WAKE_TELEGRAMS telegrams went by
            pending = later
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
