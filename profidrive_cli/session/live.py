"""The live loop of `pdrive run` and `pdrive jog` on an open DriveStation, in the shape of multirun.py's:
start the drive, cycle it until its --duration, a trip, the user (on_cycle: the CLI's keys) or a lost
link ends it, then the stop. The CLI keeps the options, the keys (terminal input) and the rendering;
it sees the loop through callbacks: on_sample(sample) every cycle, on_phase(words, sample or None) at
each change of phase, on_cycle(live) -> quit after each sample (the CLI reads its keys there and calls
set_reference / set_torque / pause / resume), on_end(live) when the loop ends by itself.

Also here: Reach, the one rule of "the drive reached its reference" (settled inside the band, not
passed through; beyond it on the far side is an overshoot): run's `reached`, each drive of run 3,4,5,
the API's Drive.run(wait=True) and the checklist's run step all feed it.

No click and no rich here. An exception leaving the loop (Ctrl-C, SIGTERM, a bus error) leaves the
drive to the session's own safe stop on exit (DriveStation.close).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

from profidrive_cli.link.base import LinkLost

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.drives.base import DriveStatus
    from profidrive_cli.drives.profile import Profile
    from profidrive_cli.session.cycle import Sample
    from profidrive_cli.session.station import DriveStation
    from profidrive_cli.session.safestop import StopReport

#: the verdict of a run whose actual speed never settled at its reference (Reach) before its --duration
#: ended (also each drive's of run 3,4,5: multirun.StationRun.problem)
NOT_REACHED = "did not reach its reference"

#: "settled": the actual stays inside the band for at least SETTLE_SAMPLES samples in a row spanning at
#: least SETTLE_S seconds. Three samples: one or two samples inside the band can be a single pass
#: through it between cycles; three in a row mean it stayed for two whole cycle periods. 0.1 s: three
#: times the longest pass through the default band of the simulated drives (the torque axis passing
#: 30 Hz of 60 at 18 Hz/s crosses the +-0.3 Hz band in 0.6 / 18 = 0.033 s) and three cycles at 30/s.
#: A slower pass (a ramp of minutes) can look settled: the overshoot half of the rule catches it as
#: soon as the actual leaves the band on the far side.
SETTLE_SAMPLES = 3
SETTLE_S = 0.1


def default_tolerance(ref: float) -> float:
    """run's band around a reference, both in % of the max frequency: 1 % of the reference, at least
    0.05 % of the max frequency (near zero)."""
    return max(0.01 * abs(ref), 0.05)


def end_status(session: "DriveStation") -> "DriveStatus | None":
    """The drive's last status: the stop's own where it has one (a fault's code is read there, the
    cycle's words may not carry it), else the last one seen."""
    rep = session.motion.stop_report
    return rep.status if rep is not None and rep.status is not None else session.motion.final_status


def fault_name(profile: "Profile | None", code: str | None) -> str | None:
    """A fault code's name as `pdrive faults` gives it (the meaning in the profile's alarm table);
    None where the table has none or there is no code."""
    alarm = profile.alarm_by_code(code) if profile is not None and code else None
    return alarm.meaning if alarm is not None and alarm.meaning else None


def trip_words(profile: "Profile | None", code: str | None) -> str:
    """'tripped (EF0): External fault ...' (the code and its name where known), or 'tripped'."""
    name = fault_name(profile, code)
    return "tripped" + (f" ({code})" if code else "") + (f": {name}" if name else "")


@dataclass
class Reach:
    """The one "reached" rule (run, each drive of run 3,4,5, the API's Drive.run(wait=True), the
    checklist's run step): feed it the actual speed sample by sample, in the unit of `reference` and
    `tolerance` (the band is reference +- tolerance).

    reached: the actual has settled inside the band, SETTLE_SAMPLES samples in a row over at least
    SETTLE_S; reached_after = when it entered the band that last time, counted from t0 (the time the
    reference was given; default the first sample fed). Passing through the band is not reaching it.
    overshoot: the actual went beyond the reference by more than the tolerance on the far side (the
    side away from where it came: `start`, else the first sample fed; a start inside the band counts
    as coming from zero; reference 0 from inside has no far side). `peak` is the actual furthest
    beyond. A verdict once given stays. unit / scale only shape the words (value x scale, unit)."""
    reference: float
    tolerance: float
    start: float | None = None
    t0: float | None = None
    unit: str = "%"
    scale: float = 1.0
    reached_after: float | None = None
    overshoot: bool = False
    peak: float | None = None
    _side: int | None = None
    _entered: float | None = None
    _count: int = 0

    def __post_init__(self) -> None:
        if self.start is not None:
            self._side = self._side_of(self.start)

    def _side_of(self, act: float) -> int:
        d = act - self.reference
        if abs(d) > self.tolerance:
            return 1 if d > 0 else -1
        return -1 if self.reference > 0 else (1 if self.reference < 0 else 0)

    @property
    def reached(self) -> bool:
        return self.reached_after is not None

    def missed(self, now: float, deadline: float) -> bool:
        """Not reached by `deadline`: it has passed, and the actual is not inside a band it entered by
        then (one that did may still settle)."""
        return (self.reached_after is None and now > deadline
                and (self._entered is None or self._entered > deadline))

    def feed(self, t: float, actual: float | None) -> None:
        """One sample: time (s) and the actual speed (None: not known, skipped)."""
        if actual is None:
            return
        if self.t0 is None:
            self.t0 = t
        if self._side is None:
            self._side = self._side_of(actual)
        d = actual - self.reference
        if abs(d) <= self.tolerance:
            if self._entered is None:
                self._entered, self._count = t, 0
            self._count += 1
            if (self.reached_after is None and self._count >= SETTLE_SAMPLES
                    and t - self._entered >= SETTLE_S - 1e-9):
                self.reached_after = round(self._entered - self.t0, 3)
            return
        self._entered, self._count = None, 0
        if self._side and d * self._side < 0:          # beyond the reference, on the far side
            self.overshoot = True
            if self.peak is None or abs(d) > abs(self.peak - self.reference):
                self.peak = actual

    @classmethod
    def of_run(cls, percent: float, sample: "Sample | None" = None) -> "Reach":
        """run's rule for a speed reference in % of the max frequency: its default band, words in
        Hz (the sample's max frequency); the sample (the one the reference went with) gives the
        start and t0."""
        fmax = float(sample.fmax_hz) if sample is not None and getattr(sample, "fmax_hz", None) else 0.0
        return cls(percent, default_tolerance(percent),
                   start=sample.actual_percent if sample is not None else None,
                   t0=sample.t if sample is not None else None,
                   unit="Hz" if fmax else "%", scale=fmax / 100.0 if fmax else 1.0)

    def overshoot_words(self) -> str:
        """'overshoot: reference 30 Hz, peak actual 31.2 Hz, tolerance +- 0.3 Hz'."""
        def f(v: float) -> str:
            return f"{round(v * self.scale, 3):g}{'' if self.unit == '%' else ' '}{self.unit}"
        return (f"overshoot: reference {f(self.reference)}, peak actual "
                f"{f(self.peak if self.peak is not None else self.reference)}, tolerance ± "
                f"{f(self.tolerance)}")


@dataclass
class Live:
    """One drive in a live loop. start() starts it (run: start / start_torque at `percent`; jog: the
    card's jog), release() (jog) ends the jog before its stop. duration: seconds from the start to the
    end (None: until on_cycle quits). reconnect_s: on a lost link, wait this long for the port and
    resume data exchange (the drive, stopped by its watchdog meanwhile, is not restarted). judge:
    feed the speed to Reach and remember when it reached the reference (reached_after); must_reach:
    an overshoot ends the loop as a failure (its words in problem), and so does the --duration
    ending before the reference was reached (NOT_REACHED)."""
    session: "DriveStation"
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
    reach: Reach | None = None            # the rule of the reference in force (judge)
    tripped: bool = False                 # the loop ended in a trip
    fault_code: str | None = None         # its code (read at the stop where the cycle had none)

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
        self.reach = Reach.of_run(self.percent, sample)
        self._phase(running, sample)
        return sample

    def resume(self, starting: str, running: str) -> None:
        """Start it again after pause() (the keys: space)."""
        self._phase(starting)
        sample = self.start()
        self.running = True
        self.reach = Reach.of_run(self.percent, sample)
        self._phase(running)

    def pause(self, stopping: str, stopped: str) -> "StopReport":
        """The normal stop (then coast; bounded), the drive stays connected; `stopped` may name {how}."""
        self._phase(stopping, self.release() if self.release is not None else None)
        rep = self.session.motion.stop()
        self.running = False
        self._phase(stopped.format(how=rep.how))
        return rep

    def set_reference(self, percent: float) -> None:
        """A new speed reference: judged on reaching it again."""
        self.percent = percent
        self.session.motion.set_reference(percent)
        self.reached_after = None
        self.reach = Reach.of_run(percent, self.last)

    def set_torque(self, percent: float) -> None:
        self.torque = percent
        self.session.motion.set_torque(percent)

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
            return s.motion.poll()
        except LinkLost as e:
            if self.reconnect_s is None:
                raise
            # the link is gone: nothing can be sent; the station's watchdog stops the drive. Wait
            # for the port, resume data exchange, never restart.
            self._phase(f"link lost ({e}); reconnecting for up to {self.reconnect_s:g} s")
            s.master.reconnect(timeout=self.reconnect_s)
            self._phase("link restored: the drive was stopped by its watchdog and is not restarted")
            rep = s.motion.stop()
            self.running = False
            if self.on_cycle is None:
                self.reason = f"link lost and restored; stop: {rep.how}"
                self.exit_code = 1
            else:
                self._phase(f"stopped ({rep.how}) — space starts, q quits")
            return None

    def _judged(self, sample: "Sample") -> bool:
        """The figures of one cycle; True when they end the loop (a trip, the duration)."""
        reach = self.reach
        if self.judge and self.running and reach is not None:
            reach.feed(sample.t, sample.actual_percent)
            if self.reached_after is None and reach.reached_after is not None:
                self.reached_after = round(reach.reached_after + (reach.t0 or 0.0) - self.t_start, 3)
        act = sample.actual_hz
        if act is not None and (self.peak_hz is None or abs(act) > abs(self.peak_hz)):
            self.peak_hz = act
        st = sample.status
        if st.fault:
            self.tripped, self.fault_code = True, st.fault_code
            self._name_trip()
            self.failed, self.exit_code = True, 1
            return True
        if self.must_reach and self.running and reach is not None and reach.overshoot:
            # beyond the reference on the far side: not reached, whatever came before; the run
            # ends at once (the drive does what it was not asked)
            self.reason = reach.overshoot_words()
            self.failed, self.problem, self.exit_code = True, self.reason, 1
            return True
        if self.duration is not None and sample.t - self.t_start >= self.duration:
            self.reason = f"duration {self.duration:g} s reached"
            if self.must_reach and self.running and self.reached_after is None:
                # the time is up and the actual speed never settled at the reference (Reach; a
                # torque run has no speed to reach: not judged)
                self.failed, self.problem, self.exit_code = True, NOT_REACHED, 1
                self.short_of = sample.actual_hz
            return True
        return False

    def finish(self) -> None:
        """The stop at the end, when the drive may be turning: phase stopping (with the last sample,
        or the jog's release), the session's stop, phase stopped (with the final status)."""
        s = self.session
        if not s.motion.may_run:
            return
        self._phase("stopping", self.release() if self.release is not None else self.last)
        s.motion.stop()
        rep = s.motion.stop_report
        st = end_status(s)                 # with a fault's code, so the last line names it
        if self.tripped and self.fault_code is None and st is not None and st.fault_code:
            self.fault_code = st.fault_code
            self._name_trip()
        if rep is not None and rep.how in ("normal", "coast"):
            self._phase("stopped", s.motion.sample(st) if st else None)

    def _name_trip(self) -> None:
        self.problem = trip_words(self.session.profile, self.fault_code)
        self.reason = "the drive " + self.problem


__all__ = ["NOT_REACHED", "SETTLE_S", "SETTLE_SAMPLES", "Live", "LinkLost", "Reach",
           "default_tolerance", "end_status", "fault_name", "trip_words"]
