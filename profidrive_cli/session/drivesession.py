"""DriveSession: one drive station in Data_Exchange behind the Drive interface, with a safe stop on
every way out. Ties the session's parts together and keeps their shared state; the work is done in
discovery.py, cycle.py, bringup.py, motion.py (Motion: run, jog, torque, the safe stop of
safestop.py, may_run) + signals.py, cyclelog.py, params.py,
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
import profidrive_cli.session.bringup as bringup
from profidrive_cli.session.cycle import MeteredChannel, Sample, choose_rate
from profidrive_cli.session.cyclelog import CycleLog, Extra
from profidrive_cli.session.discovery import DriveStation, locate
from profidrive_cli.session.motion import Motion
from profidrive_cli.session.parameters import Parameters
from profidrive_cli.session.params import ParamInfo, ParamRow
from profidrive_cli.session.safestop import StopReport
from profidrive_cli.session.signals import Guard, SignalGuard

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.dp.poller import Master
    from profidrive_cli.session.monitors import TripRecords

DEFAULT_WATCHDOG_MS = 500


class DriveSession:
    """See session/__init__.py for the constructor's arguments and the API."""

    def __init__(self, master: "Master", address: int | None = None, *, profile: str | None = None,
                 layout: str | None = None, ppo: int | None = None, fmt: str | None = None,
                 watchdog_ms: float = DEFAULT_WATCHDOG_MS, cycle_hz: float | None = None,
                 stop_timeout: float | None = None, close_link: bool = True,
                 handle_signals: bool = True,
                 before_connect: Callable[["DriveSession"], None] | None = None,
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

        self.station: DriveStation | None = None
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
    def __enter__(self) -> "DriveSession":
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

    def open(self) -> "DriveSession":
        if self.station is None:
            self.identify()
        if self.drive is None:
            if self.before_connect is not None:
                self.before_connect(self)
            self.connect()
        return self

    def identify(self) -> DriveStation:
        """Step 1: which station, which profile, which layout; the cycle rate (discovery.py, cycle.py)."""
        locate(self)
        choose_rate(self)
        assert self.station is not None         # locate() found it (or raised)
        return self.station

    def connect(self) -> Drive:
        """Step 2: Set_Prm/Chk_Cfg, Data_Exchange, the family's Drive (bringup.py), watched by
        Motion for anything that may set the motor turning."""
        drive = bringup.connect(self)
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

    @property
    def fmax_hz(self) -> float:
        """The maximum frequency (Hz) that 100 % stands for, as known so far: read from the drive or
        given (fmax()), else the profile default. No bus traffic."""
        return self.motion.fmax_hz

    def need_drive(self) -> Drive:
        if self.drive is None:
            raise PdriveError("DriveSession: not connected (use it as a context manager or call open())")
        return self.drive

    def _sample(self, st: DriveStatus) -> Sample:
        return self.motion.sample(st)

    # -- motion: speed, run, jog, torque, the safe stop (motion.py Motion) ----------------------
    @property
    def may_run(self) -> bool:
        return self.motion.may_run

    @property
    def stop_report(self) -> StopReport | None:
        return self.motion.stop_report

    @stop_report.setter
    def stop_report(self, report: StopReport | None) -> None:
        self.motion.stop_report = report

    @property
    def final_status(self) -> DriveStatus | None:
        return self.motion.final_status

    @final_status.setter
    def final_status(self, st: DriveStatus | None) -> None:
        self.motion.final_status = st

    @property
    def comm_loss_text(self) -> str | None:
        return self.motion.comm_loss_text

    @property
    def after_stop(self) -> list[Callable[[bool], object]]:
        """Called with link_ok after the safe stop on close, before the station is released."""
        return self.motion.after_stop

    def fmax(self, override: float | None = None) -> tuple[float, str]:
        return self.motion.fmax(override)

    def percent_for_hz(self, hz: float, fmax_override: float | None = None) -> float:
        return self.motion.percent_for_hz(hz, fmax_override)

    def set_reference(self, percent: float) -> None:
        self.motion.set_reference(percent)

    def start(self, percent: float | None = None, timeout: float = 5.0) -> Sample:
        return self.motion.start(percent, timeout)

    def start_torque(self, torque_percent: float | None, limit_percent: float | None = None,
                     percent: float | None = None, timeout: float = 5.0) -> Sample:
        """A torque run (torque.py): torque reference or torque limit, then start."""
        return self.motion.start_torque(torque_percent, limit_percent, percent, timeout)

    def check_torque(self, torque_percent: float | None, limit_percent: float | None = None) -> None:
        self.motion.check_torque(torque_percent, limit_percent)

    def set_torque(self, percent: float) -> None:
        self.motion.set_torque(percent)

    def poll(self) -> Sample:
        return self.motion.poll()

    def status(self) -> Sample:
        return self.motion.status()

    def jog_refusal(self) -> str | None:
        """Why this station cannot jog (one line), None when it can."""
        return self.motion.jog_refusal()

    def jog_speed(self) -> ParamValue | None:
        return self.motion.jog_speed()

    def jog(self, reverse: bool = False, timeout: float = 5.0) -> Sample:
        """The card's jog on (UsageError where the card has none); stop() ends it."""
        return self.motion.jog(reverse, timeout)

    def release_jog(self) -> Sample:
        return self.motion.release_jog()

    def stop_timeout(self, percent: float | None = None) -> float:
        return self.motion.stop_timeout(percent)

    def stop(self, on_sample: Callable[[Sample], None] | None = None,
             timeout: float | None = None) -> StopReport:
        """The family's normal stop; wait (bounded) until the drive reports stopped; coast if it does
        not. A second SIGINT/SIGTERM during the wait (when signals are handled) coasts at once.
        The report is also kept in .stop_report."""
        return self.motion.stop(on_sample, timeout)

    # -- parameters (parameters.py: Parameters) ---------------------------------------------------
    def param_info(self, code: str) -> ParamInfo:
        return self.params.info(code)

    def parse_value(self, code: str, text: str | float | int, info: ParamInfo | None = None
                    ) -> float | int:
        return self.params.parse(info or code, text)

    def read_param(self, code: str) -> ParamValue:
        return self.params.read(code)

    def danger_of(self, info: ParamInfo) -> str | None:
        return self.params.danger_of(info)

    def check_dangerous(self, info: ParamInfo, allow_dangerous: bool = False) -> None:
        self.params.check_dangerous(info, allow_dangerous)

    def stopped_for(self, info: ParamInfo) -> str | None:
        return self.params.stopped_for(info)

    def write_param(self, code: str, value: str | float | int, *, check_running: bool = True,
                    allow_dangerous: bool = False) -> ParamValue:
        """Parameters.write: plan (resolved and checked once), then execute (read back)."""
        return self.params.write(code, value, check_running=check_running,
                                 allow_dangerous=allow_dangerous)

    def notes(self) -> list[str]:
        return self.params.notes()

    def save_support(self) -> str:
        return self.params.save_support()

    def save(self) -> str:
        return self.params.save()

    # -- faults ---------------------------------------------------------------------------------
    def current_fault(self) -> Sample:
        return self.status()

    def fault_history(self) -> list[FaultRecord]:
        return self.need_drive().fault_history()

    def trip_records(self) -> "TripRecords":
        """The card's trip records (session/monitors.py): TripRecords, .supported False when it keeps none."""
        from profidrive_cli.session.monitors import trip_records
        return trip_records(self)

    def clear_fault(self, timeout: float = 5.0) -> Sample:
        """Acknowledge the current fault (the cause must be gone). The history stays."""
        st = self.need_drive().reset_fault(timeout=timeout)
        return self._sample(st)

    # -- dump / compare / restore (parameters.py: backup.py, dumpfile.py, restore.py) --------------
    def dump_plan(self) -> list[tuple[str, Any, str]]:
        return self.params.dump_plan()

    def dump(self, progress: Callable[[int, int, str], None] | None = None) -> dict[str, Any]:
        return self.params.dump(progress)

    load_dump = staticmethod(Parameters.load_dump)

    def compare(self, doc: dict[str, Any], progress: Callable[[int, int, str], None] | None = None,
                allow_dangerous: bool = False, check_identity: bool = True) -> list[ParamRow]:
        return self.params.compare(doc, progress, allow_dangerous, check_identity)

    def restore_problems(self, doc: dict[str, Any], rows: list[ParamRow], allow_dangerous: bool = False
                         ) -> list[str]:
        """Every reason not to write anything, one line each (restore.py)."""
        return self.params.restore_problems(doc, rows, allow_dangerous)

    def restore(self, doc: dict[str, Any], dry_run: bool = False,
                progress: Callable[[int, int, str], None] | None = None,
                allow_dangerous: bool = False) -> list[ParamRow]:
        """Validate every row, then write what differs, reading each write back (restore.py):
        RestoreRefused (nothing written) / RestoreInterrupted (which rows landed)."""
        return self.params.restore(doc, dry_run, progress, allow_dangerous)
