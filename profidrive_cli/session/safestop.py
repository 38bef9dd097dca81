"""The safe stop: the family's normal stop with a bounded wait (from the drive's deceleration time
where it can be read), escalation to a coast stop when the drive does not stop or a second signal
hurries it, and the shutdown on every way out of a session (stop if the drive may be running,
release the station; with the link lost, say what the station's watchdog and the drive will do).
Sends only stop commands (drives.base.Drive.stop) and the release; reads parameters only to size the
wait and to name the comm-loss behaviour.

stop_drives is the one stop path: the stop of one drive (SafeStop.stop: a group of one, its own
cycle() the exchange) and of several in rounds of one bus cycle (session/group.py Group.stop_all,
which hands in its end_round and the stations out of data exchange: StationOut is defined here).
Each member's SafeStop records its own report (_finished); Motion clears may_run on a stopped one.

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
from dataclasses import dataclass, field
from typing import Any, Callable, Protocol, Sequence

from profidrive_cli import BusError, PdriveError, UsageError
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
        not (or a signal hurries it). The report is also kept in .stop_report. stop_drives with
        this one drive: its own cycle() is the exchange; an on_sample that raises is kept in
        callback_error and the stop goes on without it."""
        sta = self.station
        d = sta.need_drive()
        last = d.last_seen()
        cb = on_sample or sta.on_sample

        def guarded(smp: Sample) -> None:
            nonlocal cb
            if cb is None:
                return
            try:
                cb(smp)
            except Exception as e:              # noqa: BLE001  (the stop goes on without it)
                self.callback_failed(e)
                cb = None

        def hurried() -> bool:
            h = bool(sta.signals.hurry)
            if h and member.mode == "normal":
                sta.signals.hurry = False       # the coast wait is not hurried away by the same one
            return h
        member = StopMember(self, last.speed_percent if last is not None else None, timeout,
                            on_sample=guarded if cb is not None else None)
        stop_drives([member], now=self._now, hurry=hurried, hurry_ends_coast=True,
                    state_in_coast_report=False)
        assert self.stop_report is not None     # stop_drives reports every member it returns for
        return self.stop_report

    def _finished(self, report: StopReport) -> None:
        """The stop engine (stop_drives) reports this drive's stop: kept as .stop_report (with its
        status as final_status when it stopped); Motion clears may_run on a stopped report."""
        if report.stopped:
            self.final_status = report.status
        self.stop_report = report

    def wait_stopped(self, timeout: float, on_sample: OnSample | None) -> DriveStatus | None:
        """Cycle (no command) until the drive reports stopped or in fault (its status), None after
        `timeout` s or a second signal. Not the stop: that is stop() / stop_drives."""
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


# -- the one stop path: one drive (SafeStop.stop) or several in rounds (group.Group.stop_all) ------

class StationOut(BusError):
    """A station of a group is not in data exchange (dropped out, or not back yet): raised by a
    group's channel (session/group.py), waited out by stop_drives when it is told which stations
    are out (`out`)."""

    def __init__(self, address: int, why: str):
        super().__init__(f"station {address} is out of data exchange ({why})")
        self.address = address
        self.why = why


@dataclass(eq=False)
class StopMember:
    """One drive for stop_drives: its Motion (a SafeStop, which records the report), the speed in %
    it may be running at (None: unknown) for its stop time, the user's stop time if given, the
    prefix of its warning ("station 3: " in a group) and what sees each of its cycles' Sample."""

    stopper: SafeStop
    percent: float | None = None
    timeout: float | None = None
    prefix: str = ""
    on_sample: OnSample | None = None
    #: the engine's state: "normal" or "coast", when that one is given up, its time, why coasting
    mode: str = field(default="normal", init=False)
    deadline: float = field(default=0.0, init=False)
    limit: float = field(default=0.0, init=False)
    why: str = field(default="", init=False)


def stop_drives(members: Sequence[StopMember], *, now: Callable[[], float],
                end_round: Callable[[], None] = lambda: None,
                hurry: Callable[[], bool] = lambda: False,
                out: Callable[[int], str | None] | None = None,
                hurry_ends_coast: bool = False, state_in_coast_report: bool = True) -> None:
    """The stop of one drive or of several at once: the one stop path (SafeStop.stop, a group's
    Group.stop_all). The normal stop command of every member goes in one round (a command the
    drive refuses -- DriveError -- is followed at once by the coast stop); then rounds (each member's
    cycle(), then end_round(): a no-op for one drive, whose own cycle() is the exchange) until
    each reports stopped (or in fault, its fault code read where the cycle's words had none). A
    member not stopped within its time (its timeout, else stop_timeout(percent), from the start of
    the stop), or every one still under its normal stop when hurry() says so (a second signal),
    gets a coast stop (its warning `{prefix}{why}: coasting`); one still not stopped
    COAST_TIMEOUT_S after that, or whose coast stop is refused, is "failed". Each member's
    SafeStop records its own report (_finished; Motion clears may_run on a stopped one).

    out: in a group, the stations out of data exchange now (address -> why, None: in): a
    StationOut is then waited out (the command is kept for when the station is back) and a member
    still out at the end is reported so; without it a StationOut is raised like any BusError.
    hurry_ends_coast: a hurry during the coast wait ends it ("failed"; the single stop's third
    signal). state_in_coast_report: a coasted member's report starts with its state ("stopped; ...";
    the group's words) rather than only `{why}; coasted` (the single stop's). An on_sample that
    raises, a LinkLost, a BusError: raised (the single stop guards its on_sample itself)."""
    waited: tuple[type[BaseException], ...] = (StationOut,) if out is not None else ()
    unreadable: tuple[type[BaseException], ...] = (DriveError, *waited)
    t0 = now()
    pending = list(members)

    def finish(m: StopMember, report: StopReport) -> None:
        pending.remove(m)
        m.stopper._finished(report)

    def coast(m: StopMember, t: float) -> None:
        ss = m.stopper
        ss._tell(ss.station.warn, f"{m.prefix}{m.why}: coasting")
        m.mode, m.deadline, m.limit = "coast", t + COAST_TIMEOUT_S, COAST_TIMEOUT_S
        try:
            ss.station.need_drive().stop("coast", wait=False)
        except waited:
            pass                            # the command is set; it goes when the station is back
        except DriveError as e:
            finish(m, StopReport("failed", False, now() - t0,
                                 f"{m.why}; coast stop not possible: {e}", ss.final_status))

    for m in members:
        m.limit = m.timeout if m.timeout is not None else m.stopper.stop_timeout(m.percent)
        m.mode, m.deadline, m.why = "normal", t0 + m.limit, ""
        try:
            m.stopper.station.need_drive().stop("normal", wait=False)
        except waited:
            pass                            # the command is set; it goes when the station is back
        except DriveError as e:
            m.why = f"normal stop failed: {e}"
            coast(m, now())
    end_round()
    while pending:
        for m in list(pending):
            ss = m.stopper
            d = ss.station.need_drive()
            try:
                st = d.cycle()
            except waited:
                continue
            except DriveError as e:
                if m.mode == "normal":
                    m.why = f"normal stop failed: {e}"
                    coast(m, now())
                else:
                    finish(m, StopReport("failed", False, now() - t0,
                                         f"{m.why}; coast stop not possible: {e}", ss.final_status))
                continue
            if m.on_sample is not None:
                m.on_sample(ss.sample(st))
            else:
                ss.final_status = st
            if not (st.fault or st.stopped):
                continue
            if st.fault and st.fault_code is None:
                try:
                    st = d.status()
                except unreadable:
                    pass
            msg = (f"the drive is in fault{f' ({st.fault_code})' if st.fault_code else ''}: its "
                   f"output is off" if st.fault else "stopped")
            if m.mode == "coast":
                msg = f"{msg}; {m.why}; coasted" if state_in_coast_report else f"{m.why}; coasted"
            finish(m, StopReport(m.mode, True, now() - t0, msg, st))
        end_round()
        if not pending:
            break
        t = now()
        hurried = hurry()
        for m in list(pending):
            if m.mode == "normal" and (hurried or t > m.deadline):
                m.why = m.why or ("stop hurried by a second signal" if hurried else
                                  f"not stopped after {m.limit:g} s")
                coast(m, t)
            elif m.mode == "coast" and (t > m.deadline or (hurried and hurry_ends_coast)):
                ss = m.stopper
                why_out = out(ss.station.address or 0) if out is not None else None
                if why_out is not None:
                    text = (f"station {ss.station.address} out of data exchange ({why_out}): pdrive "
                            f"could not send the stop; its DP watchdog ({ss.station.watchdog_ms:g} ms) "
                            f"ends data exchange and the drive stops by "
                            f"{ss.comm_loss_text or 'its communication-loss setting'}")
                else:
                    text = f"{m.why}; the drive does not report stopped after a coast stop either"
                finish(m, StopReport("failed", False, t - t0, text, ss.final_status))
