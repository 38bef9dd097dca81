"""The safe stop: the family's normal stop with a bounded wait (from the drive's deceleration time
where it can be read), escalation to a coast stop when the drive does not stop or a second signal
hurries it, and the shutdown on every way out of a session (stop if the drive may be running,
release the station; with the link lost, say what the station's watchdog and the drive will do).
Sends only stop commands (drives.base.Drive.stop) and the release; reads parameters only to size the
wait and to name the comm-loss behaviour.

SafeStop keeps what the stop knows and reports (deceleration time, comm-loss words, stop report, the
last status, the after_stop hooks); session/motion.py's Motion is one and says whether the drive may
be turning (may_run). It reads of its station only what StopStation names.

Nothing the caller hands in can skip the stop: an exception of a sample or message callback during
the stop (a closed stdout, a bug) is kept in `callback_error`, the callback is not called again,
and the stop and the release go on; shutdown raises it after the release when nothing else went
wrong (the command then ends with its one line).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable, Protocol

from profidrive_cli import PdriveError, UsageError
from profidrive_cli.drives.base import Drive, DriveError, DriveStatus
from profidrive_cli.session.cycle import Sample
from profidrive_cli.session.signals import Guard
from profidrive_cli.session.view import StationView

COAST_TIMEOUT_S = 10.0
DEFAULT_STOP_TIMEOUT_S = 30.0

OnSample = Callable[[Sample], None]


@dataclass
class StopReport:
    how: str                       # "normal", "coast", "not needed", "not sent (link lost)", "failed"
    stopped: bool
    seconds: float = 0.0
    message: str = ""
    status: DriveStatus | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"how": self.how, "stopped": self.stopped, "seconds": round(self.seconds, 3),
                "message": self.message,
                "state": self.status.state if self.status is not None else None}


class StopStation(StationView, Protocol):
    """What the safe stop reads of its station (DriveStation) beyond its face; link_lost it also sets."""
    link_lost: bool

    @property
    def signals(self) -> Guard: ...
    @property
    def watchdog_ms(self) -> float: ...
    @property
    def stop_timeout_s(self) -> float | None: ...
    @property
    def on_sample(self) -> OnSample | None: ...


def read_decel(d: Drive, profile: Any) -> float | None:
    """The deceleration time (s from the max frequency to 0) read from the drive: the parameter the
    family names (Drive.ramp_param), None without a parameter channel or when it cannot be read."""
    if not d.has_param_channel:
        return None
    code = d.ramp_param("decel")
    if not code or profile.param(code) is None:
        return None
    try:
        return float(d.read_param(code).value)
    except (DriveError, UsageError, ValueError, TypeError):
        return None


def read_comm_loss(d: Drive) -> str:
    """What the drive does when the master goes silent: read from its settings where the family can
    (Drive.comm_loss_summary), else the family's words (Drive.comm_loss_words)."""
    try:
        said = d.comm_loss_summary() if d.has_param_channel else None
        if said:
            return said
    except (DriveError, UsageError):
        pass
    return d.comm_loss_words


class SafeStop:
    """The stop of one station's drive and the shutdown on every way out (session/motion.py: Motion
    is one and owns may_run)."""

    def __init__(self, station: StopStation) -> None:
        self.station = station
        #: deceleration time (s, max frequency -> 0), read from the drive at the first start / jog
        self.decel_s: float | None = None
        #: what the drive does when its master goes silent (read at the first start / jog)
        self.comm_loss_text: str | None = None
        #: the last stop's report (stop(), the shutdown, a group's stop)
        self.stop_report: StopReport | None = None
        #: the last status seen
        self.final_status: DriveStatus | None = None
        #: the first exception a callback raised during the stop (raised after the release)
        self.callback_error: BaseException | None = None
        #: called with link_ok after the safe stop on close, before the station is released
        self.after_stop: list[Callable[[bool], object]] = []

    @property
    def may_run(self) -> bool:
        """Whether the drive may be turning (Motion says)."""
        raise NotImplementedError

    def sample(self, st: DriveStatus) -> Sample:
        """A Sample of status `st` (Motion makes it)."""
        raise NotImplementedError

    def _now(self) -> float:
        ch = self.station.channel
        assert ch is not None
        return ch.now()

    def stop_timeout(self, percent: float | None = None) -> float:
        """How long the normal stop may take before it escalates: the user's, else 1.5 x the
        deceleration time scaled by `percent` + 3 s (5..600 s), else 30 s."""
        if self.station.stop_timeout_s is not None:
            return float(self.station.stop_timeout_s)
        if self.decel_s is None:
            return DEFAULT_STOP_TIMEOUT_S
        frac = 1.0
        if percent is not None:
            frac = min(1.0, abs(percent) / 100.0)
        return max(5.0, min(600.0, 1.5 * self.decel_s * frac + 3.0))

    def stop(self, on_sample: OnSample | None = None, timeout: float | None = None) -> StopReport:
        """The family's normal stop; wait (bounded) until the drive reports stopped; coast if it does
        not (or a signal hurries it). The report is also kept in .stop_report."""
        self.stop_report = self._stop(on_sample or self.station.on_sample, timeout)
        return self.stop_report

    def _stop(self, on_sample: OnSample | None, timeout: float | None) -> StopReport:
        sta = self.station
        d = sta.need_drive()
        t_start = self._now()
        last = d.last_seen()
        pct = last.speed_percent if last is not None else None
        limit = timeout if timeout is not None else self.stop_timeout(pct)
        try:
            d.stop("normal", wait=False)
            st, on_sample = self._wait(limit, on_sample)
            if st is not None:
                msg = (f"the drive is in fault{f' ({st.fault_code})' if st.fault_code else ''}: "
                       f"its output is off" if st.fault else "stopped")
                return StopReport("normal", True, self._now() - t_start, msg, st)
            why = ("stop hurried by a second signal" if sta.signals.hurry else
                   f"not stopped after {limit:g} s")
        except DriveError as e:
            why = f"normal stop failed: {e}"
        # escalate: coast (OFF2 / base block / run bit off)
        self._tell(sta.warn, f"{why}: coasting")
        try:
            d.stop("coast", wait=False)
            sta.signals.hurry = False
            st, on_sample = self._wait(COAST_TIMEOUT_S, on_sample)
        except DriveError as e:
            return StopReport("failed", False, self._now() - t_start,
                              f"{why}; coast stop not possible: {e}", self.final_status)
        if st is None:
            return StopReport("failed", False, self._now() - t_start,
                              f"{why}; the drive does not report stopped after a coast stop either",
                              self.final_status)
        return StopReport("coast", True, self._now() - t_start, f"{why}; coasted", st)

    def wait_stopped(self, timeout: float, on_sample: OnSample | None) -> DriveStatus | None:
        return self._wait(timeout, on_sample)[0]

    def _wait(self, timeout: float, on_sample: OnSample | None
              ) -> tuple[DriveStatus | None, OnSample | None]:
        """(the status once stopped or in fault, else None; on_sample, or None once it raised)."""
        d = self.station.need_drive()
        end = self._now() + timeout
        while True:
            st = d.cycle()
            if on_sample is not None:
                try:
                    on_sample(self.sample(st))
                except Exception as e:          # noqa: BLE001  (the stop goes on without it)
                    self.callback_failed(e)
                    on_sample = None
            if on_sample is None:
                self.final_status = st
            if st.fault or st.stopped:
                if st.fault and st.fault_code is None:
                    try:
                        st = d.status()
                    except DriveError:
                        pass
                return st, on_sample
            if self.station.signals.hurry or self._now() > end:
                return None, on_sample

    def callback_failed(self, e: BaseException) -> None:
        """Keep the first exception a callback raised during the stop (reported after the release)."""
        if self.callback_error is None:
            self.callback_error = e

    def _tell(self, say: Callable[[str], None], text: str) -> None:
        """station.say / station.warn: the text is kept even when on_message raises."""
        try:
            say(text)
        except Exception as e:                  # noqa: BLE001
            self.callback_failed(e)

    def link_lost_words(self, e: BaseException | None) -> str:
        """What the watchdog does now that no stop can be sent; `e`: the LinkLost, None when the link
        was found lost before (station.link_lost) and the session is closed without an exception."""
        d = self.station.drive
        fam_text = self.comm_loss_text or (d.comm_loss_words if d is not None
                                           else Drive.comm_loss_words)
        wd = self.station.watchdog_ms
        return (f"link lost{f' ({e})' if e is not None else ''}: pdrive cannot send a stop. The station's DP watchdog "
                f"({wd:g} ms) takes it out of data exchange within "
                f"{wd / 1000.0:g} s of the last telegram; the drive then stops by "
                f"{fam_text}")

    def shutdown(self, exc: BaseException | None) -> None:
        """The stop and the release on every way out; a callback's exception during them is raised
        after the release (when `exc` is None: the session's own error comes first)."""
        self._shutdown(exc)
        late = self.callback_error
        if late is not None and exc is None:
            self.callback_error = None
            raise late

    def _shutdown(self, exc: BaseException | None) -> None:
        from profidrive_cli.link.base import LinkLost
        sta = self.station
        if isinstance(exc, LinkLost):
            sta.link_lost = True
        if sta.drive is None or sta.address is None:
            return
        if sta.link_lost:
            if self.may_run:
                self.stop_report = StopReport("not sent (link lost)", False, 0.0,
                                              self.link_lost_words(exc))
                self._tell(sta.say, self.stop_report.message)
            self._after_stop(False)
            return
        if exc is not None:
            # an interrupted request may have left a reply on the line: start clean
            try:
                time.sleep(min(0.05, sta.master.params.reply_timeout(64)))
                sta.master.link.flush_input()
            except Exception:
                pass
        if self.may_run:
            try:
                r = self.stop()
                if r.how == "normal":
                    self._tell(sta.say, f"stopped (normal stop, {r.seconds:.1f} s)"
                               if not (r.status and r.status.fault) else r.message)
                elif r.how == "coast":
                    self._tell(sta.say, f"stopped by a coast stop after {r.seconds:.1f} s ({r.message})")
                else:
                    self._tell(sta.say, f"could not confirm the stop: {r.message}")
            except LinkLost as e:
                sta.link_lost = True
                self.stop_report = StopReport("not sent (link lost)", False, 0.0, self.link_lost_words(e))
                self._tell(sta.say, self.stop_report.message)
                self._after_stop(False)
                return
            except PdriveError as e:
                self.stop_report = StopReport("failed", False, 0.0, f"stop failed: {e}")
                self._tell(sta.say, f"stop failed: {e}; the station's watchdog "
                                    f"({sta.watchdog_ms:g} ms) ends data exchange when pdrive lets go")
        elif self.stop_report is None:
            self.stop_report = StopReport("not needed", True, 0.0, "not started by this session",
                                          self.final_status)
        self._after_stop(True)
        try:
            sta.master.release(sta.address)
        except PdriveError:
            pass

    def _after_stop(self, link_ok: bool) -> None:
        """The after_stop hooks (e.g. restoring a PZD mapping), after the stop and before the station
        is released; told whether the link still works. Their errors are said, never raised."""
        for hook in self.after_stop:
            try:
                hook(link_ok)
            except Exception as e:          # noqa: BLE001  (the stop is done; say what was left)
                self._tell(self.station.say, f"after the stop: {e}")
