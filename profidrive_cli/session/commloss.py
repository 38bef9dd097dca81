"""The comm-loss acceptance test: does the drive stop (or trip) when its master goes away, within the
time its settings promise -- and can the master prove it?

    run_commloss(sess, hz, mode="silence", timeout=None, ack=False, on_event=None,
                 tolerance=None, start_timeout=None) -> CommLossResult

Sequence (the session is open, in data exchange): read the drive's configured reaction
(read_reaction: Fuji o27/o28 + F08, H81 shown; Moeller P002 (+ P001 shown); Yaskawa F6-01 +
C1-02/C1-09; Toyo fixed protection 18; clear mode: clear_reaction, Fuji OPC-PDP3 o32), check that
the bus can run the drive at all (Fuji y98 = 3), start at `hz` and wait until at speed (the limit
said on the session's message line: 2 x the acceleration time for this speed + 5 s, or
`start_timeout`), then the break:

  silence  the master sends nothing at all to the station for `hold` seconds (the DP watchdog
           armed in Set_Prm, a quarter more for the station's clock, and -- for a reaction that
           forgives a link that returns within its delay (Fuji o27 = 2 / 12) -- that delay), then
           comes back: the start-up again (Set_Prm, Chk_Cfg) and Data_Exchange with the same
           outputs as before the break, as a PLC whose program still says "run" would; a drive
           that ignored the loss is then seen running. Any telegram to the station restarts its
           watchdog, so the master cannot look earlier.
  clear    Global_Control Clear_Data to the station, then Data_Exchange with all-zero outputs
           (the master in CLEAR), so the master looks at the drive every cycle; then Operate again.

The limit = watchdog (silence) + configured delay + stop time at this speed (ramp time from max
frequency x speed / max frequency) + tolerance (default 0.25 s + half the watchdog: the station's
clock and the card's reaction, and the time the master needs to be back in data exchange; an
option). Every look is timed from the last telegram before the break: the request going out (the
drive was in the state it reports at that moment or later) and the answer coming in (... at that
moment or earlier). When the master is in data exchange by then, two looks are timed at the limit:
one whose answer comes in at the limit, one that goes out at it. Verdict, from the figures only:
  PASS          a look that came back no later than the limit saw the drive stopped or tripped;
  FAIL          the drive is set to keep running without a master (said in words), or a look that
                went out at or after the limit still saw it running;
  INCONCLUSIVE  the figures cannot decide: the first look that saw it stopped came back after the
                limit, and no look at or after the limit saw it running (the master was away until
                after the limit, or the limit fell between two looks), or the station's watchdog did
                not expire; the verdict says why and what to change.
Either way the drive ends stopped (the session's safe stop); a fault is acknowledged only with ack.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable

from profidrive_cli import UsageError
from profidrive_cli.drives.base import CyclicChannel, DriveError, DriveStatus
from profidrive_cli.session.cycle import Sample, make_sample
from profidrive_cli.session.commloss_reaction import (Reaction, check_bus_control, clear_reaction,
                                                      read_accel, read_reaction)

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.session.station import DriveStation

MODES = ("silence", "clear")
OUTCOMES = ("pass", "fail", "inconclusive")
#: the station's watchdog clock may run slow: the master stays silent this much longer
HOLD_FACTOR = 1.25
HOLD_EXTRA_S = 0.05
#: default tolerance added to the limit: the station's clock, the card's reaction and the master's
#: way back into data exchange (Set_Prm, Chk_Cfg, the first exchange)
TOL_S = 0.25
TOL_WD_FACTOR = 0.5
#: how far to ramp before "at speed": within this fraction of the reference (at least AT_SPEED_HZ)
AT_SPEED_FRAC = 0.01
AT_SPEED_HZ = 0.2
#: the wait for "at speed": START_FACTOR x the acceleration time for this speed + START_MARGIN_S;
#: START_TIMEOUT_S where the acceleration time cannot be read
START_FACTOR = 2.0
START_MARGIN_S = 5.0
START_TIMEOUT_S = 120.0


@dataclass
class Limit:
    """The limit and its parts (seconds after the last telegram)."""
    watchdog_s: float
    delay_s: float
    stop_s: float
    tolerance_s: float

    @property
    def total(self) -> float:
        return self.watchdog_s + self.delay_s + self.stop_s + self.tolerance_s

    def words(self) -> str:
        return (f"{_down(self.total):.3f} s = watchdog {self.watchdog_s:.3f} + delay {self.delay_s:.3f} + "
                f"stop {self.stop_s:.3f} + tolerance {self.tolerance_s:.3f}")

    def to_dict(self) -> dict[str, Any]:
        return {"watchdog_s": _r(self.watchdog_s), "delay_s": _r(self.delay_s),
                "stop_s": _r(self.stop_s), "tolerance_s": _r(self.tolerance_s)}


@dataclass
class CommLossResult:
    address: int
    mode: str
    hz: float
    watchdog_ms: float
    reaction: Reaction
    expected_s: float              # the limit: watchdog + delay + stop time + tolerance
    hold_s: float = 0.0            # how long the master stayed silent (silence mode)
    limit: Limit | None = None
    at_speed_hz: float | None = None
    measured_s: float | None = None        # the first look that saw stopped / tripped came back
    not_before_s: float | None = None      # the earliest the reaction can have been
    last_running_s: float | None = None    # the last look (going out) that saw it still running
    reacted: bool = False
    passed: bool = False
    outcome: str = "inconclusive"
    verdict: str = ""
    final_state: str | None = None
    fault_code: str | None = None
    acknowledged: bool = False
    watchdog_expired: bool | None = None   # the station had left data exchange when the master came back
    back_s: float | None = None            # last telegram -> the first cycle after the master came back
    stop: dict[str, Any] | None = None               # the stop pdrive sent afterwards (needed: it was running)
    counters: dict[str, Any] = field(default_factory=dict)   # the station's bus counters at the end

    def to_dict(self) -> dict[str, Any]:
        r = self.reaction
        return {"event": "result", "station": self.address, "mode": self.mode, "reference_hz": self.hz,
                "watchdog_s": self.watchdog_ms / 1000.0,
                "reaction": {"words": r.words, "stop": r.stop, "delay_s": r.delay_s,
                             "recover": r.recover, "alarm": r.alarm, "decel_s": r.decel_s,
                             "settings": r.settings, "warnings": list(r.warnings)},
                "expected_s": _r(self.expected_s),
                "limit": self.limit.to_dict() if self.limit else None, "hold_s": _r(self.hold_s),
                "at_speed_hz": self.at_speed_hz, "measured_s": _r(self.measured_s),
                "not_before_s": _r(self.not_before_s), "last_running_s": _r(self.last_running_s),
                "reacted": self.reacted, "passed": self.passed, "outcome": self.outcome,
                "verdict": self.verdict, "final_state": self.final_state,
                "fault_code": self.fault_code, "acknowledged": self.acknowledged,
                "watchdog_expired": self.watchdog_expired, "back_s": _r(self.back_s),
                "stop": _stop_json(self.stop), "counters": self.counters}


def _up(x: float) -> float:
    """To the millisecond, up (a "by then at the latest" figure stays one; float noise below 1 us
    is ignored), so that the printed figures compare as the verdict does."""
    return math.ceil(x * 1000.0 - 1e-3) / 1000.0


def _down(x: float) -> float:
    """To the millisecond, down (the limit, and a "still running at" figure)."""
    return math.floor(x * 1000.0 + 1e-3) / 1000.0


def _stop_json(stop: dict[str, Any] | None) -> dict[str, Any] | None:
    """The stop pdrive sent, with its time as `duration_s` (docs/json.md)."""
    if stop is None:
        return None
    return {("duration_s" if k == "seconds" else k): v for k, v in stop.items()}


def _r(v: float | None) -> float | None:
    return None if v is None else round(v, 3)


# -- the test ------------------------------------------------------------------------------------
class _ZeroOutputs:
    """A CyclicChannel that sends all-zero outputs (the master in CLEAR) whatever the drive asks."""

    def __init__(self, inner: CyclicChannel) -> None:
        self.inner = inner

    def now(self) -> float:
        return self.inner.now()

    def exchange(self, outputs: bytes) -> bytes:
        return self.inner.exchange(bytes(len(outputs)))


def _reacted(st: DriveStatus) -> bool:
    return bool(st.fault) or st.stopped


def check_args(hz: float, mode: str, timeout: float | None, tolerance: float | None,
               start_timeout: float | None) -> None:
    """The test's options in range (UsageError): called by the CLI before the bus is opened."""
    if mode not in MODES:
        raise UsageError(f"--mode {mode!r}: must be {' or '.join(MODES)}")
    if not math.isfinite(hz) or hz == 0:
        raise UsageError(f"--hz {hz:g}: the test needs a speed other than 0 Hz")
    for name, v, zero_ok in (("--timeout", timeout, False), ("--tolerance", tolerance, True),
                             ("--start-timeout", start_timeout, False)):
        if v is not None and (not math.isfinite(v) or v < 0 or (v == 0 and not zero_ok)):
            raise UsageError(f"{name} {v:g} must be above 0 s" if not zero_ok else
                             f"{name} {v:g} must be 0 s or more")


def _run_to_speed(sess: "DriveStation", hz: float, pct: float, fmax_hz: float, start_timeout: float | None,
                  emit: Callable[[dict[str, Any]], None]) -> Sample:
    """Start and wait until at speed; says on the session's message line what it waits for and how
    long at most."""
    if start_timeout is not None:
        limit, why = start_timeout, "--start-timeout"
    else:
        acc, code = read_accel(sess)
        if acc:
            limit = START_FACTOR * acc * min(1.0, abs(hz) / fmax_hz) + START_MARGIN_S
            why = (f"{START_FACTOR:g} x {code} = {acc:g} s from {fmax_hz:g} Hz for {abs(hz):g} Hz + "
                   f"{START_MARGIN_S:g} s; --start-timeout to change")
        else:
            limit = START_TIMEOUT_S
            why = (f"the acceleration time{f' ({code})' if code else ''} cannot be read; "
                   f"--start-timeout to change")
    band = max(AT_SPEED_HZ, AT_SPEED_FRAC * abs(hz))
    channel = sess.channel
    assert channel is not None                  # the session is connected
    sess.say(f"waiting for the drive to reach {hz:g} Hz (± {band:g} Hz), at most {limit:.3g} s ({why})")
    sample = sess.motion.start(pct)
    emit({"event": "started", "t_s": round(sample.t, 3)})
    end = channel.now() + limit
    while True:
        sample = sess.motion.poll()
        st = sample.status
        if st.fault:
            raise DriveError(f"station {sess.address}: the drive tripped before reaching {hz:g} Hz"
                             + (f" ({st.fault_code})" if st.fault_code else ""))
        if sample.actual_hz is not None and abs(sample.actual_hz - hz) <= band:
            return sample
        if channel.now() > end:
            raise DriveError(f"station {sess.address}: not at {hz:g} Hz (± {band:g} Hz) after "
                             f"{limit:.3g} s (actual {sample.actual_hz} Hz; limit: {why})")


def run_commloss(sess: "DriveStation", hz: float, mode: str = "silence", timeout: float | None = None,
                 ack: bool = False, on_event: Callable[[dict[str, Any]], None] | None = None,
                 tolerance: float | None = None, start_timeout: float | None = None) -> CommLossResult:
    """The whole test on an open DriveStation (see the module docstring). Raises UsageError for bad
    arguments before anything moves; the session's close does the safe stop on every other way out."""
    check_args(hz, mode, timeout, tolerance, start_timeout)
    emit = on_event or (lambda ev: None)
    drive, channel, address = sess.need_drive(), sess.channel, sess.address
    assert channel is not None and address is not None      # the session is connected
    fmax_hz, _ = sess.motion.fmax()
    pct = sess.motion.percent_for_hz(hz)           # refuses speeds the drive cannot hold
    reaction = read_reaction(sess) if mode == "silence" else clear_reaction(sess)
    check_bus_control(sess)
    wd_s = sess.watchdog_ms / 1000.0
    tol = TOL_S + TOL_WD_FACTOR * wd_s if tolerance is None else float(tolerance)
    stop_s = reaction.stop_s(hz, fmax_hz)
    if mode == "silence":
        limit = Limit(wd_s, reaction.delay_s if reaction.stop != "none" else 0.0, stop_s, tol)
        hold = wd_s * HOLD_FACTOR + HOLD_EXTRA_S + (reaction.delay_s if reaction.recover else 0.0)
    else:
        limit = Limit(0.0, 0.0, stop_s, tol)
        hold = 0.0
    expected = _down(limit.total)
    res = CommLossResult(address, mode, hz, sess.watchdog_ms, reaction, expected, hold, limit)
    emit({"event": "reaction", "station": sess.address, "words": reaction.words,
          "settings": reaction.settings, "warnings": list(reaction.warnings),
          "expected_s": round(expected, 3), "limit": limit.to_dict()})

    # 1. run at speed
    sample = _run_to_speed(sess, hz, pct, fmax_hz, start_timeout, emit)
    res.at_speed_hz = sample.actual_hz
    emit({"event": "at_speed", "t_s": round(sample.t, 3), "actual_hz": sample.actual_hz})

    # 2. the break
    master, addr = sess.master, address
    reparams_before = sess.counters.get("reparams", 0)
    inner_channel = drive.channel
    if mode == "silence":
        t_last = channel.now()
        emit({"event": "silence", "t_s": round(t_last - sess.t0, 3), "hold_s": round(hold, 3)})
        master.link.sleep(hold)
    else:
        from profidrive_cli.dp import services as S
        master.global_control(S.GC_CLEAR, da=addr)
        t_last = channel.now()
        emit({"event": "clear", "t_s": round(t_last - sess.t0, 3)})
        inner_channel = _ZeroOutputs(channel)
    drive.channel = inner_channel

    # 3. look until stopped / tripped, or until the limit (+ the timeout) has passed; one look goes
    #    out at the limit itself. The station channel's own pacing is off meanwhile (the looks are
    #    paced here, so that a look's time is the moment its request went out). A look is one
    #    cycle: the fault code is read after the loop, so its reading does not stretch the figure.
    watch = expected + (timeout if timeout is not None else max(2.0, 0.5 * expected))
    station_ch = getattr(sess.channel, "inner", None)
    period = float(getattr(station_ch, "period", 0.0) or 0.0)
    st = sample.status
    late_seen = None                   # a look that went out at or after the limit saw it running
    try:
        if station_ch is not None and period:
            station_ch.period = 0.0
        prev, rtt, at_limit = None, None, False
        while True:
            now = channel.now()
            due = now if prev is None else max(now, prev + period)
            # the two looks at the limit: one back by it, one going out at it
            for at in ((expected - rtt - 0.001,) if rtt is not None else ()) + (expected,):
                if now < t_last + at < due:
                    due = t_last + at
                    break
            if now >= t_last + expected and not at_limit:
                due = now
            if due > now:
                master.link.sleep(due - now)
            sent = channel.now()
            st = drive.cycle()            # one look: the status of this exchange (no fault-code read)
            back = now = channel.now()
            sample = make_sample(sess, st)
            prev = sent
            at_limit = at_limit or sent >= t_last + expected
            if res.watchdog_expired is not None or mode == "clear":     # not the start-up again
                rtt = back - sent if rtt is None else min(rtt, back - sent)
            if res.watchdog_expired is None and mode == "silence":
                res.watchdog_expired = sess.counters.get("reparams", 0) > reparams_before
                res.back_s = _up(back - t_last)
                emit({"event": "back", "t_s": round(sample.t, 3),
                      "after_s": round(now - t_last, 3), "watchdog_expired": res.watchdog_expired})
            if _reacted(st):
                res.reacted = True
                res.measured_s = _up(back - t_last)
                break
            res.last_running_s = _down(sent - t_last)
            if late_seen is None and res.last_running_s >= expected:
                late_seen = (res.last_running_s, sample.actual_hz)
            if now - t_last > watch or (reaction.stop == "none" and late_seen is not None):
                break
    finally:
        drive.channel = channel
        if station_ch is not None and period:
            station_ch.period = period
        if mode == "clear":
            from profidrive_cli.dp import services as S
            try:
                master.global_control(0, da=addr)          # Operate again
            except Exception:                               # noqa: BLE001 (the stop follows anyway)
                pass
    res.not_before_s = max(wd_s if mode == "silence" else 0.0, res.last_running_s or 0.0)
    res.final_state, res.fault_code = st.state, st.fault_code
    if st.fault and st.fault_code is None:
        try:
            s2 = sess.motion.status().status
            res.fault_code = s2.fault_code
        except DriveError:
            pass

    # 4. verdict
    _verdict(res, st, sample, late_seen)

    # 5. leave it stopped (the stop command replaces the run outputs, also after a trip);
    #    acknowledge only when asked
    was_running = not (st.fault or st.stopped)
    rep = sess.motion.stop()
    res.stop = dict(rep.to_dict(), needed=was_running)
    if rep.status is not None:
        res.final_state = rep.status.state
        res.fault_code = rep.status.fault_code or res.fault_code
    if ack and sess.motion.final_status is not None and sess.motion.final_status.fault:
        s3 = sess.clear_fault()
        res.acknowledged = not s3.status.fault
        res.final_state, res.fault_code = s3.status.state, s3.status.fault_code
        if sess.motion.stop_report is not None:
            sess.motion.stop_report.status = s3.status     # what the drive is left in: acknowledged
    res.counters = dict(sess.counters)
    emit(res.to_dict())
    return res


def _verdict(res: CommLossResult, st: DriveStatus, sample: Sample,
             late: tuple[float | None, float | None] | None) -> None:
    """PASS / FAIL / INCONCLUSIVE from the figures (module docstring); sets outcome, passed, verdict."""
    reaction, lim = res.reaction, res.expected_s
    late_seen, late_hz = late if late is not None else (None, None)
    what = "tripped" if st.fault else "stopped"
    code = f" ({res.fault_code})" if res.fault_code else ""
    limit = f"limit {res.limit.words()}" if res.limit else f"limit {lim:.3f} s"
    warn = "".join(f"; note: {w}" for w in reaction.warnings)
    seen = (f"{what}{code} at the latest {res.measured_s:.3f} s after the last telegram"
            if res.reacted else "")

    def done(outcome: str, text: str) -> None:
        res.outcome, res.passed = outcome, outcome == "pass"
        res.verdict = f"{outcome.upper()}: {text}"

    if reaction.stop == "none":
        done("fail", "the drive is set to keep running " + ("without a master" if res.mode == "silence"
                                                          else "on all-zero outputs (master in CLEAR)") +
             " (" + reaction.words + ")" +
             (f"; it reported {what} anyway after {res.measured_s:.3f} s" if res.reacted else
              f"; it was still running at {sample.actual_hz} Hz {res.last_running_s:.3f} s after "
              f"the last telegram") + warn)
        return
    if res.mode == "silence" and res.watchdog_expired is False:
        done("inconclusive", f"the station was still in data exchange when the master came back after "
             f"{res.hold_s:.3f} s: its watchdog did not expire, so the link was never lost (is the "
             f"station's watchdog longer than the {res.watchdog_ms:g} ms set, or switched off?)")
        return
    if late_seen is not None:
        done("fail", f"still running at {late_hz} Hz {late_seen:.3f} s after the last telegram (a look "
             f"that went out then), at or after the {limit}"
             + (f"; {seen}" if res.reacted else
                f"; still running at {sample.actual_hz} Hz {res.last_running_s:.3f} s after it") + warn)
        return
    if not res.reacted:              # the watch ended before a look at the limit (cannot happen)
        done("fail", f"no stop or trip seen ({limit})" + warn)
        return
    assert res.measured_s is not None       # set with reacted
    if res.measured_s <= lim:
        done("pass", f"{what}{code} within {res.measured_s:.3f} s of the last telegram (a look that "
             f"came back then saw it); {limit}")
        return
    # reacted, but first seen after the limit and never seen running at or after it
    if res.last_running_s is None:
        why = (f"the master was away until after the limit (silent {res.hold_s:.3f} s so that the "
               f"watchdog expires even on a slow station clock, then the start-up again; first "
               f"cycle back {res.back_s:.3f} s after the last telegram), so it cannot tell whether the "
               f"drive reacted in time")
        change = ("a faster baud rate or a layout with fewer octets (the start-up is shorter), or a "
                  "larger --tolerance if the plant allows that much")
    else:
        why = (f"it was last seen running {res.last_running_s:.3f} s after the last telegram, and the "
               f"limit falls between that look and the next")
        change = "a faster cycle (--cycle-hz) or a faster baud rate, so that the looks are closer"
    if not reaction.stop_known:
        why += "; the stop time could not be read, so the limit counts none"
        change += ", or make the deceleration time readable"
    done("inconclusive", f"{seen}, after the {limit}; {why}. To decide: {change}" + warn)
