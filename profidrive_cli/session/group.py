"""Group: several stations on one bus cycle -- the one coordinator of `pdrive run 3,4,5` (multirun.py),
the checklist's `together` step and the API's drives (api/bus.py: the keep-alive and the stop on close).

Its rules, each written here once:

- the cycle (GroupCycle): every station of the group gets one Data_Exchange per round, whichever of
  their drives asks for it, so a drive that waits for its own handshake (start, a parameter read, its
  stop) never lets the others' watchdogs expire; with Sync (and Freeze) each round ends with one
  Global_Control broadcast. A station that leaves data exchange is never waited for (StationOut).
- the keep rule: a station put on the group is kept in data exchange by the master while the master
  brings up or talks to another station (dp.poller.Master.keep: at least once a period, a quarter of
  the watchdog at the latest); between calls (the API) every member other than the busy one whose last
  Data_Exchange is `within` old gets one (Group.keep_others); a member not held -- its last
  Data_Exchange older than its DP watchdog, or found out of data exchange and brought up again -- is
  returned (KeepMiss), for the caller to report.
- the pace: one round is one Data_Exchange per station, so its wire time is the sum of the stations'
  (Group.rate); the watchdog every member needs outlasts three such rounds (min_watchdog_ms,
  Group.watchdog_for), raised before the stations are parameterised.
- the stop of all in one round (Group.stop_all): safestop.stop_drives, the one stop path, on the
  group's rounds: the normal stop command of every drive in one round, a bounded wait for all
  together, a coast stop for each one not stopped in its time.

Talks to the bus through dp.poller.Master only; no click and no rich.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Iterable, Sequence

from profidrive_cli import BusError
from profidrive_cli.dp import services as S
from profidrive_cli.dp.station import RELEASED, StationMachine
from profidrive_cli.link.base import LinkLost
from profidrive_cli.session.cycle import Sample, default_cycle_hz
from profidrive_cli.session.safestop import StationOut, StopMember, stop_drives

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.dp.poller import Master
    from profidrive_cli.session.station import DriveStation

#: (address, session, the speed in % it may be running at, None: unknown) of a drive to stop
StopItem = tuple[int, "DriveStation", "float | None"]


@dataclass(frozen=True)
class KeepMiss:
    """A station the keep rule between calls did not hold (Group.keep_others)."""

    address: int
    #: seconds since its Data_Exchange before, when the keep-alive came to it
    gap_s: float
    #: its DP watchdog in seconds (0: none armed)
    watchdog_s: float
    #: it had left data exchange (its watchdog ran out) and was brought up again
    restarted: bool = False

    def words(self) -> str:
        """One line: what happened, in figures."""
        text = (f"station {self.address}: the keep-alive fell behind by {self.gap_s:.2f} s against "
                f"a watchdog of {self.watchdog_s:g} s" if self.watchdog_s and
                self.gap_s > self.watchdog_s else
                f"station {self.address}: {self.gap_s:.2f} s without a Data_Exchange "
                f"(watchdog {self.watchdog_s:g} s)")
        if self.restarted:
            text += ("; the station had left data exchange and was brought up again: the drive "
                     "reacted as to a lost master (see its faults)")
        return text


def min_watchdog_ms(round_s: float) -> float:
    """The shortest DP watchdog (ms, a multiple of 10) a station of a group can hold: a station waits
    up to two rounds for its next Data_Exchange (exchanged early in one round; a drive that asks
    twice completes the next round early and its own exchange opens it, so the others go last),
    plus a third round for a retry or a keep-alive round of the bring-up in between."""
    return float(math.ceil(3.0 * round_s * 1000.0 / 10.0 - 1e-9) * 10)


def wire_round_s(wire_hz: Iterable[float]) -> float:
    """The wire time of one round: one Data_Exchange per station, each at its own wire limit."""
    return sum(1.0 / hz for hz in wire_hz)


class GroupCycle:
    """The rounds. exchange(address, outputs) is lazy: the first exchange of a round waits for the
    period and opens the round; each station is exchanged at most once per round; when a station asks
    a second time, the round is completed first (the stations not yet exchanged get their last outputs
    again), then the next one opens. While a station is brought up (or talks to the bus outside the
    rounds) the master keeps the group's stations (Master.keep / keep_alive): those keep-alives are
    exchanges like any other but no rounds: the period and the Sync/Freeze broadcasts stay the rounds'."""

    def __init__(self, master: "Master", period: float = 0.0, sync: bool = False,
                 freeze: bool = False) -> None:
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

    def _out(self, address: int, st: StationMachine) -> StationOut:
        why = self.out.setdefault(address, st.last_error or st.state)
        self.dropped.setdefault(address, why)
        return StationOut(address, why)


class GroupChannel:
    """The inner channel of a station's MeteredChannel inside a group (see StationChannel)."""

    def __init__(self, group: GroupCycle, address: int) -> None:
        self.group = group
        self.address = address
        self.master = group.master
        self.cycles = 0

    def now(self) -> float:
        return self.group.now()

    def exchange(self, outputs: bytes) -> bytes:
        self.cycles += 1
        return self.group.exchange(self.address, outputs)


class Group:
    """Several stations on one bus cycle (see the module doc). The sessions join it once connected
    (join); the rounds are the GroupCycle's (end_round, exchanged, dropped, out, finish)."""

    def __init__(self, master: "Master", period: float = 0.0, sync: bool = False,
                 freeze: bool = False) -> None:
        self.master = master
        self.cycle = GroupCycle(master, period, sync=sync, freeze=freeze)

    # -- pace and watchdog: decided before the stations are parameterised ------------------------
    @staticmethod
    def rate(master: "Master", wire_hz: Iterable[float]) -> tuple[float, float]:
        """(default rounds per second, the wire limit of a round) of stations with these wire limits
        (DriveStation.wire_hz): one Data_Exchange per station."""
        wire = 1.0 / wire_round_s(wire_hz)
        return default_cycle_hz(master.link, wire), wire

    @staticmethod
    def watchdog_for(asked_ms: float, round_s: float, stations: int) -> tuple[float, str | None]:
        """The watchdog (ms) every station of a group of `stations` with rounds of `round_s` holds:
        the one asked for, raised to three rounds (min_watchdog_ms) when shorter -- a slow bus (5
        stations at 9.6k: 0.31 s a round) would let it expire between two exchanges of the group;
        with the words of the warning when raised (else None)."""
        need = min_watchdog_ms(round_s)
        if asked_ms >= need:
            return asked_ms, None
        return need, (f"watchdog raised from {asked_ms:g} ms to {need:g} ms: one round of {stations} "
                      f"stations takes {round_s * 1000:.0f} ms, and a station may wait up to two "
                      f"rounds (plus a retry) for its next exchange")

    # -- members ---------------------------------------------------------------------------------
    def join(self, session: "DriveStation") -> Callable[[], None]:
        """Put a connected session's cyclic channel on the group; returns the function that takes it
        off (its channel back to its own)."""
        metered = session.channel
        address = session.address
        assert metered is not None and address is not None      # the session is connected
        old = metered.inner
        metered.inner = self.cycle.channel(address)

        def leave() -> None:
            metered.inner = old
            if address in self.cycle.addresses:
                self.cycle.addresses.remove(address)
        return leave

    # -- the rounds (GroupCycle) -----------------------------------------------------------------
    @property
    def period(self) -> float:
        return self.cycle.period

    @period.setter
    def period(self, value: float) -> None:
        self.cycle.period = value

    @property
    def cycling(self) -> bool:
        """Stations are on the rounds (joined): each gets its Data_Exchange there."""
        return bool(self.cycle.addresses)

    @property
    def rounds(self) -> int:
        return self.cycle.rounds

    @property
    def global_controls(self) -> int:
        return self.cycle.global_controls

    @property
    def dropped(self) -> dict[int, str]:
        return self.cycle.dropped

    @property
    def out(self) -> dict[int, str]:
        return self.cycle.out

    def end_round(self) -> None:
        self.cycle.end_round()

    def exchanged(self, address: int) -> bool:
        return self.cycle.exchanged(address)

    def finish(self) -> None:
        self.cycle.finish()

    # -- the keep rule between calls (the API) ---------------------------------------------------
    def keep_others(self, members: Iterable[int], busy: int | None, last: dict[int, float],
                    within: float) -> list["KeepMiss"]:
        """A Data_Exchange (with its last outputs) for every member other than `busy` whose last one
        (`last`, updated here) is `within` old. Returns the members the keep-alive did not hold: the
        time since their last Data_Exchange outlasted their DP watchdog (the caller was late: a
        thread that did not get the CPU or the GIL), or the station had left data exchange and was
        brought up again (its watchdog ran out; the drive then reacts as to a lost master). A
        station that cannot be kept is left to its own next call (which then reports it); a lost
        link is raised."""
        missed: list[KeepMiss] = []
        for a in list(members):
            if a == busy:
                continue
            now = self.master.link.now()
            # the last request to it, whoever sent it (a call's own cycle, the master's keep-alive
            # while it brings up another station): what restarted its watchdog
            sent = self.master.last_request(a)
            gap = now - max(last.get(a, now), sent if sent is not None else float("-inf"))
            if gap >= within:
                last[a] = now
                st = self.master.stations.get(a)
                reparams = st.counters.reparams if st is not None else 0
                try:
                    self.master.exchange(a, None)
                except LinkLost:
                    raise
                except BusError:
                    pass
                last[a] = self.master.link.now()
                if st is None:
                    continue
                wd_s = (st.config.wd_ms or 0.0) / 1000.0
                restarted = st.counters.reparams > reparams
                if restarted or (wd_s > 0 and gap > wd_s):
                    missed.append(KeepMiss(a, gap, wd_s, restarted))
        return missed

    # -- the stop of all in one round --------------------------------------------------------------
    def stop_all(self, items: Sequence[StopItem], hurry: Callable[[], bool] = lambda: False,
                 on_sample: Callable[[int, Sample], None] | None = None) -> None:
        """The stop of several drives at once: safestop.stop_drives on the group's rounds. items:
        (address, DriveStation, percent) of the drives that may be running, all on the group. The
        normal stop command of every drive goes in one round; then rounds until each reports stopped
        (or in fault); a drive not stopped within its own stop time (safestop.stop_timeout), or every
        one when hurry() says so (a second signal), gets a coast stop; one still not stopped after
        that is reported failed. A station out of data exchange keeps its stop command for when it
        is back. Each session's Motion records its own stop_report (and final_status, may_run).
        on_sample(address, Sample) sees every cycle."""
        members = [StopMember(s.motion, pct, prefix=f"station {a}: ",
                              on_sample=None if on_sample is None else _for(on_sample, a))
                   for a, s, pct in items]
        stop_drives(members, now=self.master.link.now, end_round=self.end_round, hurry=hurry,
                    out=self.out.get)


def _for(on_sample: Callable[[int, Sample], None], address: int) -> Callable[[Sample], None]:
    return lambda smp: on_sample(address, smp)


__all__ = ["Group", "GroupChannel", "GroupCycle", "KeepMiss", "StationOut", "StopItem", "min_watchdog_ms",
           "wire_round_s"]
