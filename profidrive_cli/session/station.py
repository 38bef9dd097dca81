"""DriveStation: one drive station in Data_Exchange behind the Drive interface, with a safe stop on
every way out. Ties the session's parts together and keeps their shared state; the work is done in
discovery.py, cycle.py, bringup.py, motion.py (Motion: run, jog, torque, the safe stop of
safestop.py, may_run) + signals.py, cyclelog.py, paramtypes.py,
backup.py + dumpfile.py + restore.py (the API is described in session/__init__.py). No click and no
rich here.
"""

from __future__ import annotations

import os
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, Callable, Literal, Mapping

from profidrive_cli import PdriveError, UsageError
from profidrive_cli.outfile import OutputWriteError
from profidrive_cli.drives.base import Drive, DriveStatus, FaultRecord, ParamValue
from profidrive_cli.drives.profile import Profile
from profidrive_cli.session.bringup import bring_up
from profidrive_cli.session.cycle import MeteredChannel, Sample, choose_rate
from profidrive_cli.session.cyclelog import CycleLog, Extra
from profidrive_cli.session.discovery import Candidate, choose_profile, locate, resolve_layout
from profidrive_cli.session.motion import Motion
from profidrive_cli.session.parameters import Parameters
from profidrive_cli.session.paramtypes import ParamInfo, ParamRow
from profidrive_cli.session.safestop import StopReport
from profidrive_cli.session.signals import Guard, SignalGuard

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.dp.poller import Master
    from profidrive_cli.session.monitors import TripRecords

DEFAULT_WATCHDOG_MS = 500


class DriveStation:
    """One drive station on the bus and the one owner of its state (docs/architecture.md): who it is,
    its bring-up, its place in the cycle, its messages and its end; .motion (Motion) and .params
    (Parameters) are its parts. session/__init__.py describes the constructor."""

    def __init__(self, master: "Master", address: int | None = None, *, profile: str | None = None,
                 layout: str | None = None, ppo: int | None = None, fmt: str | None = None,
                 watchdog_ms: float = DEFAULT_WATCHDOG_MS, cycle_hz: float | None = None,
                 stop_timeout: float | None = None, close_link: bool = True,
                 handle_signals: bool = True,
                 before_connect: Callable[["DriveStation"], None] | None = None,
                 on_message: Callable[[str], None] | None = None,
                 log_csv: str | Path | None = None, env: Mapping[str, str] | None = None) -> None:
        if address is not None and not 0 <= address <= 125:
            raise UsageError(f"station address {address} outside 0..125")
        if not 10 <= watchdog_ms <= 650000:
            raise UsageError(f"watchdog {watchdog_ms:g} ms outside 10..650000 ms")
        if cycle_hz is not None and cycle_hz < 0:
            raise UsageError(f"cycle rate {cycle_hz:g} Hz must be positive")
        self.master = master
        self.requested_address = address
        self.profile_name = profile
        self.layout_args = (layout, ppo, fmt)
        self.watchdog_ms = float(watchdog_ms)
        self.requested_cycle_hz = cycle_hz
        self.stop_timeout_s = stop_timeout
        self.close_link = close_link
        self.handle_signals = handle_signals
        self.before_connect = before_connect
        self.on_message = on_message
        #: called with each Sample while the session waits for a stop (also the stop on exit)
        self.on_sample: Callable[[Sample], None] | None = None
        self.log_csv = log_csv
        self.env = os.environ if env is None else env

        self.station: Candidate | None = None
        self.address: int | None = None
        self.ident: int | None = None
        self.profile: Profile | None = None
        self.layout: str | None = None
        self.drive: Drive | None = None
        self.channel: MeteredChannel | None = None
        self.cycle_hz: float = 0.0
        self.wire_hz: float = 0.0
        self.warnings: list[str] = []
        self.messages: list[str] = []
        self.link_lost = False
        self.t0 = 0.0
        self.signals: Guard = SignalGuard(handle_signals)
        self._closed = False
        #: the --log CSV once connected (cyclelog.CycleLog)
        self.cyclelog: CycleLog | None = None
        #: (column names, row()) the --log CSV writes beside each exchange (set before connecting)
        self.log_extra: Extra | None = None
        #: Sync_Req / Freeze_Req with the parameters (MultiRun --sync / --freeze sets them)
        self.dp_sync = False
        self.dp_freeze = False
        #: start / jog / torque, the safe stop and may_run (motion.py)
        self.motion = Motion(self)
        #: parameters: plan / execute, read, save, dump / compare / restore (parameters.py)
        self.params = Parameters(self)


    # -- messages ------------------------------------------------------------------------------
    def warn(self, text: str) -> None:
        self.warnings.append(text)
        if self.on_message:
            self.on_message(f"warning: {text}")

    def say(self, text: str) -> None:
        self.messages.append(text)
        if self.on_message:
            self.on_message(text)

    # -- context manager -----------------------------------------------------------------------
    def __enter__(self) -> "DriveStation":
        self.signals.install()
        try:
            self.open()
        except BaseException as e:
            self.close(e)
            raise
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> Literal[False]:
        self.close(exc)
        return False

    def open(self) -> "DriveStation":
        if self.station is None:
            self.identify()
        if self.drive is None:
            if self.before_connect is not None:
                self.before_connect(self)
            self.connect()
        return self

    def settle(self, *, watchdog_ms: float | None = None, cycle_hz: float | None = None,
               sync: bool | None = None, freeze: bool | None = None,
               log_extra: Extra | None = None) -> None:
        """What a coordinator decides between identify() and connect() (MultiRun: the group's rate,
        a watchdog raised for the round, Sync / Freeze; run --monitor: its --log columns); refused
        once the station is connected (its Set_Prm is sent)."""
        if self.drive is not None:
            raise PdriveError(f"station {self.address}: connected already; its Set_Prm is sent")
        if watchdog_ms is not None:
            self.watchdog_ms = float(watchdog_ms)
        if cycle_hz is not None:
            self.cycle_hz = float(cycle_hz)
        if sync is not None:
            self.dp_sync = sync
        if freeze is not None:
            self.dp_freeze = freeze
        if log_extra is not None:
            self.log_extra = log_extra

    def identify(self) -> Candidate:
        """Step 1: which station, which profile, which layout; the cycle rate (discovery.py, cycle.py
        answer; the station keeps)."""
        found = locate(self.master, self.requested_address, self.env, bool(self.profile_name))
        self.station = found
        self.address, self.ident = found.address, found.ident
        self.profile, warns = choose_profile(self.ident, self.profile_name, self.address)
        for w in warns:
            self.warn(w)
        self.layout = resolve_layout(self.profile, *self.layout_args)
        lay = self.profile.layouts[self.layout]
        self.wire_hz, self.cycle_hz, too_fast = choose_rate(
            self.master.params.baud, self.master.link, lay.output_len, lay.input_len,
            self.requested_cycle_hz)
        if too_fast is not None:
            self.warn(too_fast)
        return found

    def connect(self) -> Drive:
        """Step 2: Set_Prm/Chk_Cfg, Data_Exchange (bringup.py), the --log CSV, the family's Drive,
        watched by Motion for anything that may set the motor turning."""
        from profidrive_cli.drives import make_drive
        assert (self.address is not None and self.ident is not None and self.profile is not None
                and self.layout is not None)                  # identify() chose them
        channel = bring_up(self.master, self.address, self.ident, self.profile, self.layout,
                           watchdog_ms=self.watchdog_ms, cycle_hz=self.cycle_hz,
                           sync=self.dp_sync, freeze=self.dp_freeze)
        self.channel = channel
        self.t0 = channel.now()
        if self.log_csv:
            self.cyclelog = CycleLog(self.log_csv, channel, self.t0, lambda: self.drive, self.warn,
                                     self.log_extra)
        drive: Drive = make_drive(channel, self.profile, self.layout)
        self.drive = drive
        self.motion.watch(drive)
        return drive

    def close(self, exc: BaseException | None = None) -> None:
        """Safe stop (if the drive may be running), release the station, close the link. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self.signals.guard()
        try:
            self.motion.shutdown(exc)
        finally:
            if self.cyclelog is not None:
                self.cyclelog.close()
            if self.close_link:
                try:
                    self.master.link.close()
                except Exception:
                    pass
            self.signals.restore()
        if self.log_error is not None:
            if exc is None:
                raise self.log_error          # the run went well, its log did not: exit 1
            self.say(str(self.log_error))

    @property
    def log_error(self) -> OutputWriteError | None:
        """OutputWriteError when the --log file could not be written (raised by close())."""
        return self.cyclelog.error if self.cyclelog is not None else None

    # -- bus figures ----------------------------------------------------------------------------
    @property
    def counters(self) -> dict[str, Any]:
        if self.address is None:
            return {}
        counters: dict[str, Any] = self.master.fdl.counters_for(self.address).as_dict()
        return counters

    @property
    def achieved_hz(self) -> float:
        return self.channel.rate if self.channel is not None else 0.0

    @property
    def cycles(self) -> int:
        return self.channel.cycles if self.channel is not None else 0

    def need_drive(self) -> Drive:
        if self.drive is None:
            raise PdriveError("DriveStation: not connected (use it as a context manager or call open())")
        return self.drive

    # -- faults ---------------------------------------------------------------------------------
    def fault_history(self) -> list[FaultRecord]:
        return self.need_drive().fault_history()

    def trip_records(self) -> "TripRecords":
        """The card's trip records (session/monitors.py): TripRecords, .supported False when it keeps none."""
        from profidrive_cli.session.monitors import trip_records
        return trip_records(self)

    def clear_fault(self, timeout: float = 5.0) -> Sample:
        """Acknowledge the current fault (the cause must be gone). The history stays."""
        st = self.need_drive().reset_fault(timeout=timeout)
        return self.motion.sample(st)
