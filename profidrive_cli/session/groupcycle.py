"""One bus cycle for several stations on one master (pdrive run 3,4,5): every station in the group gets
one Data_Exchange per period, whichever of their drives asks for it, so a drive that waits for its own
handshake (start, a parameter read, its stop) never lets the others' watchdogs expire.

GroupCycle.exchange(address, outputs) is lazy: the first exchange of a round waits for the period and
opens the round; each station is exchanged at most once per round; when a station asks a second time,
the round is completed first (the stations not yet exchanged get their last outputs again), then the
next one opens. With Sync (and Freeze) the round ends with one Global_Control broadcast, so the
outputs of the round take effect in the same instant on every station (and the inputs read in the
next round were sampled in that instant too).

A station that leaves data exchange is never waited for: each round sends it one request of its
start-up (Master.step) and its exchange raises StationOut, so the others keep their cycle. While a
station is brought up (or talks to the bus outside the rounds), the master itself keeps the group's
stations in data exchange (Master.keep / keep_alive); those keep-alives are exchanges like any
other but no rounds: the period and the Sync/Freeze broadcasts stay the rounds'.
Talks to the bus through dp.poller.Master only.
"""

from __future__ import annotations

import math

from profidrive_cli import BusError
from profidrive_cli.dp import services as S
from profidrive_cli.dp.station import RELEASED


def min_watchdog_ms(round_s: float) -> float:
    """The shortest DP watchdog (ms, a multiple of 10) a station of a group can hold: a station waits
    up to two rounds for its next Data_Exchange (exchanged early in one round; a drive that asks
    twice completes the next round early and its own exchange opens it, so the others go last),
    plus a third round for a retry or a keep-alive round of the bring-up in between."""
    return float(math.ceil(3.0 * round_s * 1000.0 / 10.0 - 1e-9) * 10)


class StationOut(BusError):
    """A station of the group is not in data exchange (dropped out, or not back yet)."""

    def __init__(self, address: int, why: str):
        super().__init__(f"station {address} is out of data exchange ({why})")
        self.address = address
        self.why = why


class GroupCycle:
    def __init__(self, master, period: float = 0.0, sync: bool = False, freeze: bool = False):
        self.master = master
        self.period = period
        self.command = (S.GC_SYNC if sync else 0) | (S.GC_FREEZE if freeze else 0)
        self.addresses: list[int] = []
        self.outputs: dict[int, bytes] = {}
        #: stations out of data exchange now: address -> why
        self.out: dict[int, str] = {}
        #: every station that was out of data exchange at some time during the run: address -> why
        self.dropped: dict[int, str] = {}
        self.rounds = 0
        self.global_controls = 0
        self._done: set[int] = set()
        self._next: float | None = None

    def add(self, address: int) -> None:
        if address not in self.addresses:
            self.addresses.append(address)

    def channel(self, address: int) -> "GroupChannel":
        """The station's channel; from now on it is kept in the cycle (with the outputs it has), and
        by the master while it brings up or talks to another station (Master.keep: at least once a
        period, a quarter of the watchdog at the latest)."""
        self.add(address)
        st = self.master.stations.get(address)
        if st is not None and address not in self.outputs:
            self.outputs[address] = bytes(st.outputs)
        if st is not None and (self.period or address not in self.master.kept):
            self.master.keep(address, self.period)
        return GroupChannel(self, address)

    def now(self) -> float:
        return self.master.link.now()

    # -- the round ----------------------------------------------------------------------------
    def exchange(self, address: int, outputs: bytes) -> bytes:
        self.outputs[address] = bytes(outputs)
        if address in self._done:
            self.end_round()
        if not self._done:
            self._pace()
        self._done.add(address)
        return self._one(address)

    def exchanged(self, address: int) -> bool:
        """Whether the station was exchanged in the open round."""
        return address in self._done

    def end_round(self) -> None:
        """Exchange the stations not yet exchanged in this round (with their last outputs), then the
        Sync/Freeze broadcast. Nothing when no round is open. A station out of data exchange does not
        stop the others (it is in `out`)."""
        if not self._done:
            return
        try:
            for a in self.addresses:
                if a not in self._done and a in self.outputs and \
                        self.master.stations[a].state != RELEASED:
                    self._done.add(a)
                    try:
                        self._one(a)
                    except StationOut:
                        pass
            if self.command:
                self.master.global_control(self.command)
                self.global_controls += 1
        finally:
            self._done.clear()
            self.rounds += 1

    def finish(self) -> None:
        """End the open round; with Sync/Freeze in force, Unsync/Unfreeze to every station (best
        effort: the release that follows takes the stations out of data exchange anyway)."""
        self.end_round()
        if self.command:
            undo = (S.GC_UNSYNC if self.command & S.GC_SYNC else 0) | \
                   (S.GC_UNFREEZE if self.command & S.GC_FREEZE else 0)
            try:
                self.master.global_control(undo)
                self.global_controls += 1
            except BusError:
                pass
            self.command = 0

    def _pace(self) -> None:
        if not self.period:
            return
        link = self.master.link
        now = link.now()
        if self._next is None:
            self._next = now
        if now < self._next:
            link.sleep(self._next - now)
        self._next = max(self._next + self.period, link.now())

    def _one(self, address: int) -> bytes:
        """One Data_Exchange; a station not in data exchange gets one start-up request instead."""
        m = self.master
        st = m.stations[address]
        if st.state == RELEASED:           # let go of on purpose: never parameterised again here
            raise StationOut(address, "released")
        st.set_outputs(self.outputs[address])
        if not st.in_data_exchange:
            m.step(st)                     # one request of its start-up, never a wait
            raise self._out(address, st)
        st.fresh_inputs = False
        m.step(st)
        if st.state == "absent" or not (st.in_data_exchange or st.fresh_inputs):
            raise self._out(address, st)
        self.out.pop(address, None)
        return st.inputs

    def _out(self, address: int, st) -> StationOut:
        why = self.out.setdefault(address, st.last_error or st.state)
        self.dropped.setdefault(address, why)
        return StationOut(address, why)


class GroupChannel:
    """The inner channel of a station's MeteredChannel inside a group (see StationChannel)."""

    def __init__(self, group: GroupCycle, address: int):
        self.group = group
        self.address = address
        self.master = group.master
        self.cycles = 0

    def now(self) -> float:
        return self.group.now()

    def exchange(self, outputs: bytes) -> bytes:
        self.cycles += 1
        return self.group.exchange(self.address, outputs)
