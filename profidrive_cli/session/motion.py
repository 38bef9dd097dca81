"""Motion: start / run / jog / torque and the safe stop of one station's drive; the only owner of
"may it turn" (may_run). The maximum frequency that 100 % stands for (read from the drive, --fmax,
or the profile default), percent for Hz, the reference, start (which first reads what the safe stop
needs), poll, status and the Sample of a status; jog (session/jog.py) and torque runs
(session/torque.py); the stop and the shutdown on every way out (session/safestop.py: SafeStop).
Commands the drive only through drives.base.Drive. Reads of its station (DriveStation today) only
what MotionStation names.

may_run turns True when Motion starts or jogs the drive, and when anything else tells the Drive to
turn the motor (Drive.on_motion: the checklist's steps command the session's Drive directly); it
turns False only when a stop confirms the drive stopped (safestop.stop_drives, the one stop path, for
stop() and for a group's stop of several drives in one round, reports it to _finished()).
"""

from __future__ import annotations

import math
from typing import Any, Protocol

from profidrive_cli import UsageError
from profidrive_cli.config import source_of
from profidrive_cli.drives.base import Drive, DriveError, DriveStatus, ParamValue
from profidrive_cli.drives.profile import Profile
import profidrive_cli.session.jog as _jog
import profidrive_cli.session.torque as _torque
from profidrive_cli.session.cycle import Sample
from profidrive_cli.session.safestop import (OnSample, SafeStop, StopReport, StopStation,
                                             read_comm_loss, read_decel)


class MotionStation(StopStation, Protocol):
    """What Motion reads of its station beyond the safe stop's (StopStation)."""

    @property
    def t0(self) -> float: ...
    @property
    def achieved_hz(self) -> float: ...
    @property
    def cycles(self) -> int: ...
    @property
    def counters(self) -> dict[str, Any]: ...
    @property
    def warnings(self) -> list[str]: ...


class Motion(SafeStop):
    """The drive's motion on one station: DriveStation builds it as `self.motion = Motion(self)`."""

    #: the station (SafeStop stores it): Motion reads more of it than the safe stop does
    station: MotionStation

    def __init__(self, station: MotionStation) -> None:
        super().__init__(station)
        self._may_run = False
        self._fmax: tuple[float, str] | None = None
        self._fmax_override: float | None = None

    # -- may it turn ------------------------------------------------------------------------------
    @property
    def may_run(self) -> bool:
        """True from the first command that may set the motor turning until a stop confirms it
        stopped."""
        return self._may_run

    def watch(self, drive: Drive) -> None:
        """Hear of every command that may set `drive`'s motor turning, whoever gives it (the
        checklist's steps command the session's Drive directly): the shutdown then stops it."""
        drive.on_motion(self._commanded)

    def _commanded(self) -> None:
        self._may_run = True

    def stop(self, on_sample: OnSample | None = None, timeout: float | None = None) -> StopReport:
        r = super().stop(on_sample, timeout)
        if r.stopped:
            self._may_run = False
        return r

    def _finished(self, report: StopReport) -> None:
        """The stop (safestop.stop_drives: stop(), a group's stop of several drives in one round)
        reports this drive's: kept, and may_run cleared when it is confirmed stopped."""
        super()._finished(report)
        if report.stopped:
            self._may_run = False

    def confirm_stopped(self) -> None:
        """A stop run elsewhere saw this drive stopped."""
        self._may_run = False

    # -- speed -----------------------------------------------------------------------------------
    def _profile(self) -> Profile:
        p = self.station.profile
        assert p is not None                    # connected
        return p

    @property
    def fmax_readable(self) -> bool:
        """The drive's own maximum frequency can be read (a parameter channel, and a parameter
        number or register for the profile's max-frequency parameter): the one rule, for fmax() and
        for the CLI's config-file fmax default (left unused then)."""
        prof = self._profile()
        code = prof.max_frequency_param
        pdef = prof.param(code) if code else None
        return bool(self.station.need_drive().has_param_channel and pdef is not None
                    and (pdef.pnu is not None or pdef.register is not None))

    def fmax(self, override: float | None = None) -> tuple[float, str]:
        """(max frequency in Hz = 100 %, where it came from). With a parameter channel the drive's
        own value is read; without one `override` (--fmax) or the profile default is used."""
        d = self.station.need_drive()
        if self._fmax is not None and override == self._fmax_override:
            return self._fmax
        prof = self._profile()
        code = prof.max_frequency_param
        # an fmax from a config file keeps its FILE:LINE (config.FileHz): the label names that line
        source = source_of(override)
        given = f"fmax {override:g} Hz from {source}" if source is not None else \
            f"--fmax {override:g}" if override is not None else ""
        if self.fmax_readable and d.fmax_unread is None:
            hz = float(d.max_frequency())
            src = f"read from the drive ({code})"
            if override is not None and not math.isclose(override, hz, rel_tol=1e-3):
                self.station.warn(f"{given}{'' if source is not None else ' Hz'} ignored: the drive "
                                  f"says {code} = {hz:g} Hz")
        elif override is not None:
            if override <= 0:
                raise UsageError(f"{given}: must be above 0 Hz")
            hz = float(override)
            src = f"from {source if source is not None else '--fmax'}"
            # without a parameter channel the codec would scale speed words with the profile
            # default: keep it consistent with ours
            d.use_max_frequency(hz)
        else:
            hz = float(prof.max_frequency_default)
            if d.fmax_unread is not None:
                why = f"{code} could not be read: {d.fmax_unread}"
            elif not d.has_param_channel:
                why = f"layout {self.station.layout} has no parameter channel"
            elif code:
                why = f"{code} has no published parameter number"
            else:
                why = "the profile names no max-frequency parameter"
            src = (f"the profile default ({why}; {code or 'max frequency'} not read — "
                   f"give --fmax if the drive is set otherwise)")
            d.use_max_frequency(hz)
        self._fmax, self._fmax_override = (hz, src), override
        return self._fmax

    @property
    def fmax_hz(self) -> float:
        """The maximum frequency (Hz) that 100 % stands for, as known so far: read from the drive or
        given (fmax()), else the profile default. No bus traffic."""
        if self._fmax is not None:
            return float(self._fmax[0])
        return float(self._profile().max_frequency_default)

    def percent_for_hz(self, hz: float, fmax_override: float | None = None) -> float:
        top, src = self.fmax(fmax_override)
        pct = 100.0 * hz / top
        if abs(pct) > 100.0 + 1e-9:
            raise UsageError(f"{hz:g} Hz is above the maximum frequency {top:g} Hz ({src})")
        return pct

    def set_reference(self, percent: float) -> None:
        if not -100.0 <= percent <= 100.0:
            raise UsageError(f"speed {percent:g} % is outside -100..100 % of the maximum frequency")
        self.station.need_drive().set_speed(percent)

    # -- run -------------------------------------------------------------------------------------
    def read_stop_facts(self) -> None:
        """Read once what the safe stop needs: the deceleration time, the comm-loss behaviour."""
        d = self.station.need_drive()
        if self.decel_s is None:
            self.decel_s = read_decel(d, self.station.profile)
        if self.comm_loss_text is None:
            self.comm_loss_text = read_comm_loss(d)

    def start(self, percent: float | None = None, timeout: float = 5.0) -> Sample:
        """Set the reference (if given) and step the drive to operation."""
        d = self.station.need_drive()
        self.read_stop_facts()
        if percent is not None:
            self.set_reference(percent)
        self._may_run = True
        return self.sample(d.start(timeout=timeout))

    def poll(self) -> Sample:
        """One Data_Exchange with the current command, decoded."""
        d = self.station.need_drive()
        st = d.cycle()
        if st.fault and st.fault_code is None:
            st = d.status()
        return self.sample(st)

    def status(self) -> Sample:
        """One read of the status, with the current fault named where the card can say it."""
        d = self.station.need_drive()
        if d.has_param_channel:
            try:
                self.fmax()
            except DriveError:
                pass
        return self.sample(d.status())

    def sample(self, st: DriveStatus) -> Sample:
        """A Sample of status `st` on the station's clock (also remembered as final_status)."""
        sta = self.station
        if self._fmax is not None:
            fmax = self._fmax[0]
        else:
            scale = sta.drive.speed_scale_hz() if sta.drive is not None else None
            fmax = scale or float(self._profile().max_frequency_default)
        self.final_status = st
        return Sample(self._now() - sta.t0, st, float(fmax), sta.achieved_hz, sta.cycles,
                      sta.counters)

    # -- jog (session/jog.py) ----------------------------------------------------------------------
    def jog_refusal(self) -> str | None:
        """Why this station cannot jog (one line), None when it can."""
        return _jog.refusal(self.station.need_drive())

    def jog_speed(self) -> ParamValue | None:
        return _jog.jog_speed(self.station.need_drive())

    def jog(self, reverse: bool = False, timeout: float = 5.0) -> Sample:
        """The card's jog on (UsageError where the card has none); stop() ends it. Waits until the
        drive reports running (or moving); DriveError with the family's hint after `timeout` s."""
        d = self.station.need_drive()
        _jog.check(d)
        self.read_stop_facts()
        _jog.check_not_in_fault(d)
        self._may_run = True
        return self.sample(_jog.jog_on(d, reverse, timeout))

    def release_jog(self) -> Sample:
        """Jog off (one cycle); the caller then stops the drive (stop)."""
        return self.sample(_jog.release(self.station.need_drive()))

    # -- torque (session/torque.py) ----------------------------------------------------------------
    def check_torque(self, torque_percent: float | None, limit_percent: float | None = None) -> None:
        _torque.check(self.station.need_drive(), torque_percent, limit_percent)

    def start_torque(self, torque_percent: float | None, limit_percent: float | None = None,
                     percent: float | None = None, timeout: float = 5.0) -> Sample:
        """A torque run: check, warn what the drive's own settings must be, set the torque
        reference or limit, then start (with the speed reference `percent` if given)."""
        d = self.station.need_drive()
        _torque.check(d, torque_percent, limit_percent)
        for note in d.torque_notes():
            if note not in self.station.warnings:
                self.station.warn(note)
        _torque.set_words(d, torque_percent, limit_percent)
        return self.start(percent, timeout)

    def set_torque(self, percent: float) -> None:
        """A new torque reference while running (keys in the live view)."""
        d = self.station.need_drive()
        _torque.check(d, percent, None)
        d.set_torque(percent)
