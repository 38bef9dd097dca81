"""The live list: FDL status to every address, then Slave_Diag (and Get_Cfg) to each slave found."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from profidrive_cli import BusError
from profidrive_cli.dp.services import SlaveDiag
from profidrive_cli.fdl import frames as F


@dataclass
class ScanEntry:
    address: int
    station_type: str                 # slave / master not ready / master ready / master in ring
    diag: SlaveDiag | None = None
    cfg: bytes | None = None
    error: str = ""
    counters: dict = field(default_factory=dict)

    @property
    def ident(self) -> int | None:
        return self.diag.ident if self.diag else None


def probe(master, addr: int):
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
    return reply


def scan(master, first: int = 0, last: int = 126, progress=None, read_cfg: bool = False) -> list[ScanEntry]:
    """progress(address) is called before each probe (for a progress bar)."""
    found: list[ScanEntry] = []
    for addr in range(first, last + 1):
        if progress:
            progress(addr)
        if addr == master.address:
            continue
        reply = probe(master, addr)
        if reply is None:
            continue
        st = F.STATION_TYPES[reply.station_type] if reply.sd != F.SC else "slave"
        found.append(ScanEntry(addr, st))
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
    return found
