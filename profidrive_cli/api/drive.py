"""Drive: the public face of one drive station in data exchange on a Bus (a DriveStation, the one
owner of the station's state; held() hands it to a tool under the bus lock): status, run / stop,
parameters, faults. Every call holds the bus lock; writes on a real port need the bus
opened with allow_real_port_writes=True. The safe stop of a drive this API started happens on
Bus.close() (also on an exception leaving the `with`), or on Drive.close()."""

from __future__ import annotations

import contextlib
import math
from typing import TYPE_CHECKING, Any

from profidrive_cli import UsageError
from profidrive_cli.api.results import (AuditFinding, AuditResult, AuditSkip, Fault, Faults, Param,
                                        Status, StopResult)
from profidrive_cli.drives.base import DriveError
from profidrive_cli.session.live import Reach

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.drives.base import ParamValue
    from profidrive_cli.drives.profile import Profile
    import threading
    from typing import Iterator

    from profidrive_cli.session import DriveStation, Sample

#: run(wait=True) without a timeout waits at most this long for the reference
DEFAULT_RUN_TIMEOUT_S = 60.0


class Drive:
    """A drive station opened with Bus.drive(); see docs/api.md."""

    def __init__(self, bus: Any, station: "DriveStation", fmax: float | None = None):
        self._bus = bus
        #: the station this is the face of (the station level: held())
        self._station = station
        self._fmax_override = fmax
        self._closed = False
        if fmax is not None:
            station.motion.fmax(fmax)

    # -- identity ---------------------------------------------------------------------------------
    @property
    def station(self) -> int:
        address = self._station.address
        assert address is not None                  # Bus.drive() opened the session
        return int(address)

    @property
    def ident(self) -> int | None:
        return self._station.ident

    @property
    def ident_hex(self) -> str | None:
        return None if self.ident is None else "0x%04X" % self.ident

    @property
    def profile(self) -> str:
        return self._profile().name

    @property
    def family(self) -> str:
        return self._profile().family

    def _profile(self) -> "Profile":
        prof = self._station.profile
        assert prof is not None                     # Bus.drive() opened the session
        return prof

    @property
    def layout(self) -> str:
        return str(self._station.layout)

    @property
    def fmax_hz(self) -> float:
        """The frequency 100 % stands for (read from the drive where it can be)."""
        with self._bus._call():
            self._check()
            return self._station.motion.fmax(self._fmax_override)[0]

    @property
    def warnings(self) -> list[str]:
        return list(self._station.warnings)

    def __repr__(self) -> str:
        return f"<Drive station {self.station} {self.profile} on {self._bus.port}>"

    # -- checks -------------------------------------------------------------------------------------
    def _check(self) -> None:
        if self._closed:
            raise UsageError(f"station {self.station}: this drive was closed")
        self._bus._check_open(self.station)

    def _status(self, sample: "Sample") -> Status:
        st = sample.status
        return Status(self.station, self.profile, st.state, bool(st.running), bool(st.stopped),
                      bool(st.fault), st.fault_code, tuple(k for k, v in st.flags.items() if v),
                      sample.actual_hz, sample.actual_percent, sample.reference_hz,
                      sample.reference_percent, float(sample.fmax_hz), round(sample.t, 3),
                      dict(sample.counters))

    # -- status -------------------------------------------------------------------------------------
    def status(self) -> Status:
        """One read of the status (the current fault named where the card can say it)."""
        with self._bus._call():
            self._check()
            return self._status(self._station.motion.status())

    # -- motion -------------------------------------------------------------------------------------
    def run(self, hz: float | None = None, *, percent: float | None = None, wait: bool = False,
            timeout: float | None = None, cancel: "threading.Event | None" = None) -> Status:
        """Run at `hz` (or `percent` of fmax; negative = reverse): start the drive, or change the
        reference when it already runs. wait=True: until the actual speed has settled at the
        reference (the rule of `pdrive run`, docs/commands.md; DriveError after `timeout` s, default
        60, when the drive trips, or when the actual goes beyond the reference by more than the
        tolerance: an overshoot). A speed above fmax is
        refused (UsageError), never clipped. `cancel` (a threading.Event; the asyncio face sets it
        when its task is cancelled): once set, the wait ends early with the last status, and the
        caller stops the drive."""
        return self._run(hz, percent, wait, timeout, cancel)

    def _run(self, hz: float | None, percent: float | None, wait: bool, timeout: float | None,
             cancel: "threading.Event | None") -> Status:
        if (hz is None) == (percent is None):
            raise UsageError("run: give hz or percent (one of them)")
        v = hz if hz is not None else percent
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise UsageError(f"run: {v!r} is not a speed")
        if timeout is not None and not timeout > 0:
            raise UsageError(f"run: timeout {timeout!r} must be above 0 s")
        with self._bus._call():
            self._check()
            s = self._station
            pct = float(percent) if percent is not None else s.motion.percent_for_hz(float(v),
                                                                               self._fmax_override)
            self._bus._check_write(f"run station {self.station} at "
                                   f"{f'{hz:g} Hz' if hz is not None else f'{percent:g} %'}")
            if s.motion.may_run:
                s.motion.set_reference(pct)
                sample = s.motion.poll()
            else:
                sample = s.motion.start(pct)
            if wait:
                limit = DEFAULT_RUN_TIMEOUT_S if timeout is None else float(timeout)
                end = sample.t + limit
                # the one "reached" rule of run (session/live.py Reach): settled in the band, an
                # overshoot beyond it is an error
                reach = Reach.of_run(pct, sample)
                while not reach.reached:
                    if cancel is not None and cancel.is_set():
                        break
                    if sample.status.fault:
                        raise DriveError(f"station {self.station}: the drive tripped"
                                         + (f" ({sample.status.fault_code})"
                                            if sample.status.fault_code else "")
                                         + " while accelerating")
                    if reach.overshoot:
                        raise DriveError(f"station {self.station}: {reach.overshoot_words()}")
                    if sample.t > end:
                        act = sample.actual_hz
                        raise DriveError(f"station {self.station}: reference "
                                         f"{sample.reference_hz if sample.reference_hz is not None else pct:g}"
                                         f"{' Hz' if sample.reference_hz is not None else ' %'} not "
                                         f"reached within {limit:g} s (actual "
                                         f"{'-' if act is None else f'{act:g} Hz'})")
                    sample = s.motion.poll()
                    if not sample.status.fault:
                        reach.feed(sample.t, sample.actual_percent)
            return self._status(sample)

    def stop(self, *, timeout: float | None = None) -> StopResult:
        """The family's normal stop, waiting (bounded: `timeout`, default from the drive's
        deceleration time) until the drive reports stopped; a coast stop when it does not."""
        with self._bus._call():
            self._check()
            r = self._station.motion.stop(timeout=timeout)
            return StopResult(r.how, bool(r.stopped), round(r.seconds, 3), r.message)

    # -- parameters --------------------------------------------------------------------------------
    def param(self, code: str) -> Param:
        """Read one parameter by its native code ("F07", "A004", "C1-01", "PNU23[1]", ...)."""
        with self._bus._call():
            self._check()
            return _param(self._station.params.read(code))

    def set_param(self, code: str, value: float | int | str, *, allow_dangerous: bool = False
                  ) -> Param:
        """Write one parameter and return the value read back. A value the parameter cannot hold
        exactly is refused (UsageError), never rounded; a parameter the profile marks dangerous
        needs allow_dangerous=True; one that may only change at standstill is refused while the
        drive runs (DriveError)."""
        if isinstance(value, bool) or not isinstance(value, (int, float, str)):
            raise UsageError(f"set_param {code}: {value!r} is not a value")
        with self._bus._call():
            self._check()
            params = self._station.params
            # resolved once, every check once (writable, dangerous, exact value), nothing written
            plan = params.plan(code, value, allow_dangerous=allow_dangerous)
            self._bus._check_write(f"write {code} = {value} on station {self.station}")
            return _param(params.execute(plan))

    # -- faults ---------------------------------------------------------------------------------------
    def faults(self) -> Faults:
        """The current fault and the fault history (alarm names; every candidate where one number
        means several)."""
        with self._bus._call():
            self._check()
            cur = self._station.motion.status().status
            hist = self._station.fault_history()
            return Faults(self.station, bool(cur.fault), cur.fault_code, cur.state,
                          tuple(Fault(str(r.position), int(r.raw), tuple(r.codes), tuple(r.meanings))
                                for r in hist))

    def clear_fault(self) -> Status:
        """Acknowledge the current fault (its cause must be gone); the history stays."""
        with self._bus._call():
            self._check()
            self._bus._check_write(f"acknowledge the fault of station {self.station}")
            return self._status(self._station.clear_fault())

    # -- audit --------------------------------------------------------------------------------------
    def audit(self, *, max_reaction_s: float | None = None, cycle_s: float | None = None,
              watchdog_s: float | None = None) -> AuditResult:
        """Lint the drive's safety- and commissioning-relevant settings by its family's rules
        (session/audit.py; docs/commands.md `pdrive audit`): read only, nothing written, the drive
        not started. max_reaction_s: how long the process allows the drive to run on without its
        master; cycle_s: the master's bus cycle (default this bus's); watchdog_s: the watchdog the
        master sets (default the one this drive was opened with)."""
        from profidrive_cli.session.audit import audit_session
        with self._bus._call():
            self._check()
            rep = audit_session(self._station, watchdog_s=watchdog_s, cycle_s=cycle_s,
                                max_reaction_s=max_reaction_s)
            return audit_result(rep)

    @property
    def last_stop(self) -> StopResult | None:
        """How this drive's last stop ended (stop(), the stop on close or on the way out of the
        bus's `with`), None before any; readable after the bus is closed."""
        r = self._station.motion.stop_report
        return None if r is None else StopResult(r.how, bool(r.stopped), round(r.seconds, 3), r.message)

    # -- the station level ---------------------------------------------------------------------------
    @contextlib.contextmanager
    def held(self) -> "Iterator[DriveStation]":
        """The station itself (the station level, profidrive_cli.api.station: its .motion and
        .params), for the block, under the bus lock: the keep-alive thread keeps off the master
        meanwhile, as during every call here. For tools (pdrive status renders its Sample)."""
        with self._bus._call():
            self._check()
            yield self._station

    # -- end ------------------------------------------------------------------------------------------
    def close(self) -> StopResult | None:
        """Stop the drive if this API started it, release the station (it leaves data exchange);
        the bus stays open. Bus.close() does this for every drive still open."""
        with self._bus._call():
            if self._closed:
                return None
            self._bus._drives.pop(self.station, None)
            self._close(None)
            r = self._station.motion.stop_report
            return None if r is None else StopResult(r.how, bool(r.stopped), round(r.seconds, 3),
                                                     r.message)

    def _close(self, exc: BaseException | None) -> None:
        if self._closed:
            return
        self._closed = True
        self._station.close(exc)


def audit_result(rep: Any) -> AuditResult:
    """The API's AuditResult of a session.audit.AuditReport."""
    return AuditResult(
        rep.station, rep.profile, rep.layout, rep.ident, rep.watchdog_s, rep.cycle_s,
        rep.max_reaction_s,
        tuple(AuditFinding(f.severity, f.rule, f.code, f.value, f.why, f.fix, f.manual,
                           None if f.check is None else dict(f.check)) for f in rep.findings),
        tuple(AuditSkip(k.rule, k.topic, k.reason, k.manual) for k in rep.not_applicable),
        tuple(AuditSkip(k.rule, k.topic, k.reason, k.manual) for k in rep.not_checked),
        tuple(rep.checked))


def _param(pv: "ParamValue") -> Param:
    return Param.of(pv)
