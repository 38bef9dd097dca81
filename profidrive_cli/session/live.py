"""The live loop of `pdrive run` and `pdrive jog` on an open DriveSession, in the shape of multirun.py's:
start the drive, cycle it until its --duration, a trip, the user (on_cycle: the CLI's keys) or a lost
link ends it, then the stop. The CLI keeps the options, the keys (terminal input) and the rendering;
it sees the loop through callbacks: on_sample(sample) every cycle, on_phase(words, sample or None) at
each change of phase, on_cycle(live) -> quit after each sample (the CLI reads its keys there and calls
set_reference / set_torque / pause / resume), on_end(live) when the loop ends by itself.

Also here: at_reference, the one rule of "the drive is at its reference" (run's `reached`, each drive
of run 3,4,5, the API's Drive.run(wait=True)).

No click and no rich here. An exception leaving the loop (Ctrl-C, SIGTERM, a bus error) leaves the
drive to the session's own safe stop on exit (DriveSession.close).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

from profidrive_cli.link.base import LinkLost

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.session.cycle import Sample
    from profidrive_cli.session.drivesession import DriveSession
    from profidrive_cli.session.safestop import StopReport

#: the verdict of a run whose actual speed never came within at_reference before its --duration ended
#: (also each drive's of run 3,4,5: multirun.StationRun.problem)
NOT_REACHED = "did not reach its reference"


def at_reference(ref: float | None, act: float | None) -> bool:
    """The actual speed is at the reference (both in % of the max frequency): within 1 % of it, or
    0.05 % of the max frequency near zero."""
    if ref is None or act is None:
        return False
    return abs(act - ref) <= max(0.01 * abs(ref), 0.05)


def sample_at_reference(sample: "Sample") -> bool:
    """at_reference of a Sample's reference and actual speed."""
    return at_reference(sample.reference_percent, sample.actual_percent)


@dataclass
class Live:
    """One drive in a live loop. start() starts it (run: start / start_torque at `percent`; jog: the
    card's jog), release() (jog) ends the jog before its stop. duration: seconds from the start to the
    end (None: until on_cycle quits). reconnect_s: on a lost link, wait this long for the port and
    resume data exchange (the drive, stopped by its watchdog meanwhile, is not restarted). judge:
    remember when the actual speed first reached the reference (reached_after); must_reach: the
    --duration ending before that is a failure (NOT_REACHED)."""
    session: "DriveSession"
    start: Callable[[], "Sample"]
    release: Callable[[], "Sample"] | None = None
    duration: float | None = None
    reconnect_s: float | None = None
    judge: bool = False
    must_reach: bool = False
    percent: float = 0.0                  # the speed reference (%) start() and the keys use
    torque: float | None = None           # the torque reference (%) of a torque run
    on_sample: Callable[["Sample"], None] | None = None
    on_phase: Callable[[str, "Sample | None"], None] | None = None
    on_cycle: Callable[["Live"], bool] | None = None
    on_end: Callable[["Live"], None] | None = None
    # -- what happened -------------------------------------------------------------------------
    started: bool = False                 # begin() started the drive
    running: bool = False                 # the drive is meant to turn now
    t_start: float = 0.0
    reached_after: float | None = None
    peak_hz: float | None = None          # the largest actual speed seen (by magnitude)
    reason: str = ""
    failed: bool = False
    problem: str | None = None
    short_of: float | None = None         # the actual speed (Hz) when the time was up, not reached
    exit_code: int = 0
    last: "Sample | None" = None

    def _phase(self, words: str, sample: "Sample | None" = None) -> None:
        if self.on_phase is not None:
            self.on_phase(words, sample)

    # -- what the drive is told ---------------------------------------------------------------
    def begin(self, starting: str = "starting", running: str = "running") -> "Sample":
        """Start the drive; its clock (t_start) runs from the start's last sample."""
        self._phase(starting)
        sample = self.start()
        self.started = self.running = True
        self.t_start = sample.t
        self.last = sample
        self._phase(running, sample)
        return sample

    def resume(self, starting: str, running: str) -> None:
        """Start it again after pause() (the keys: space)."""
        self._phase(starting)
        self.start()
        self.running = True
        self._phase(running)

    def pause(self, stopping: str, stopped: str) -> "StopReport":
        """The normal stop (then coast; bounded), the drive stays connected; `stopped` may name {how}."""
        self._phase(stopping, self.release() if self.release is not None else None)
        rep = self.session.stop()
        self.running = False
        self._phase(stopped.format(how=rep.how))
        return rep

    def set_reference(self, percent: float) -> None:
        """A new speed reference: judged on reaching it again."""
        self.percent = percent
        self.session.set_reference(percent)
        self.reached_after = None

    def set_torque(self, percent: float) -> None:
        self.torque = percent
        self.session.set_torque(percent)

    # -- the loop ---------------------------------------------------------------------------------
    def loop(self) -> int:
        """Cycle until the duration, a trip, on_cycle's quit or a lost link ends it; 0, or 1 when it
        ended in a trip, a reference not reached in time or a link lost and restored."""
        while True:
            sample = self._poll()
            if sample is None:
                if self.on_cycle is None:           # nobody to start it again: the run is over
                    break
                continue
            self.last = sample
            if self.on_sample is not None:
                self.on_sample(sample)
            if self._judged(sample):
                break
            if self.on_cycle is not None and self.on_cycle(self):
                self.reason = "q pressed"
                break
        if self.on_end is not None:
            self.on_end(self)
        return self.exit_code

    def _poll(self) -> "Sample | None":
        """The next cycle's sample; None after a lost link came back (the drive is stopped)."""
        s = self.session
        try:
            return s.poll()
        except LinkLost as e:
            if self.reconnect_s is None:
                raise
            # the link is gone: nothing can be sent; the station's watchdog stops the drive. Wait
            # for the port, resume data exchange, never restart.
            self._phase(f"link lost ({e}); reconnecting for up to {self.reconnect_s:g} s")
            s.master.reconnect(timeout=self.reconnect_s)
            self._phase("link restored: the drive was stopped by its watchdog and is not restarted")
            rep = s.stop()
            self.running = False
            if self.on_cycle is None:
                self.reason = f"link lost and restored; stop: {rep.how}"
                self.exit_code = 1
            else:
                self._phase(f"stopped ({rep.how}) — space starts, q quits")
            return None

    def _judged(self, sample: "Sample") -> bool:
        """The figures of one cycle; True when they end the loop (a trip, the duration)."""
        if self.judge and self.running and self.reached_after is None and sample_at_reference(sample):
            self.reached_after = round(sample.t - self.t_start, 3)
        act = sample.actual_hz
        if act is not None and (self.peak_hz is None or abs(act) > abs(self.peak_hz)):
            self.peak_hz = act
        st = sample.status
        if st.fault:
            code = f" ({st.fault_code})" if st.fault_code else ""
            self.reason = "the drive tripped" + code
            self.failed, self.problem, self.exit_code = True, "tripped" + code, 1
            return True
        if self.duration is not None and sample.t - self.t_start >= self.duration:
            self.reason = f"duration {self.duration:g} s reached"
            if self.must_reach and self.running and self.reached_after is None:
                # the time is up and the actual speed never came within at_reference (multirun's
                # rule; a torque run has no speed to reach: not judged)
                self.failed, self.problem, self.exit_code = True, NOT_REACHED, 1
                self.short_of = sample.actual_hz
            return True
        return False

    def finish(self) -> None:
        """The stop at the end, when the drive may be turning: phase stopping (with the last sample,
        or the jog's release), the session's stop, phase stopped (with the final status)."""
        s = self.session
        if not s.may_run:
            return
        self._phase("stopping", self.release() if self.release is not None else self.last)
        s.stop()
        rep = s.stop_report
        if rep is not None and rep.how in ("normal", "coast"):
            self._phase("stopped", s.motion.sample(s.final_status) if s.final_status else None)


__all__ = ["NOT_REACHED", "Live", "LinkLost", "at_reference", "sample_at_reference"]
