"""The comm-loss acceptance test: does the drive stop (or trip) when its master goes away, within the
time its settings promise?

    run_commloss(sess, hz, mode="silence", timeout=None, ack=False, on_event=None) -> CommLossResult

Sequence (the session is open, in data exchange): read the drive's configured reaction
(read_reaction: Fuji o27/o28 + F08, Moeller P002 (+ P001 shown), Yaskawa F6-01 + C1-02/C1-09, Toyo
fixed protection 18), start at `hz` and wait until at speed, then the break:

  silence  the master sends nothing at all to the station for `hold` seconds (the DP watchdog
           armed in Set_Prm, a quarter more for the station's clock, and -- for a reaction that
           forgives a link that returns within its delay (Fuji o27 = 2 / 12) -- that delay), then
           comes back: the start-up again (Set_Prm, Chk_Cfg) and Data_Exchange with the same
           outputs as before the break, as a PLC whose program still says "run" would; a drive
           that ignored the loss is then seen running.
  clear    Global_Control Clear_Data to the station, then Data_Exchange with all-zero outputs
           (the master in CLEAR), until the drive reports stopped or tripped; then Operate again.

The measured time runs from the last telegram before the break (the Global_Control in clear mode)
to the first cycle in which the drive reports stopped or tripped; after a silence it is observed
once the station is back in data exchange, so a reaction that happened during the silence is
measured as the moment the master could see it (`not_before_s` is the earliest it can have been:
the watchdog). Verdict: PASS when the drive reports stopped or tripped within the expected bound
(watchdog + configured delay + stop time at this speed + tolerance); FAIL when the configured reaction
is "ignore / keep running" (said in words, whatever was measured), or when the drive is still
running at the bound. Either way the drive ends stopped (the session's safe stop); a fault is
acknowledged only with ack=True.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

from profidrive_cli import UsageError
from profidrive_cli.drives.base import DriveError, DriveStatus

MODES = ("silence", "clear")
#: the station's watchdog clock may run slow: the master stays silent this much longer
HOLD_FACTOR = 1.25
HOLD_EXTRA_S = 0.05
#: tolerance added to the expected bound: reconnection (Set_Prm, Chk_Cfg, first exchanges) and
#: the cycle in which the reaction is seen
TOL_S = 0.25
TOL_WD_FACTOR = 0.5
#: how far to ramp before "at speed": within this fraction of the reference (at least AT_SPEED_HZ)
AT_SPEED_FRAC = 0.01
AT_SPEED_HZ = 0.2
START_TIMEOUT_S = 120.0

_YASKAWA_F601 = {0: ("ramp", "C1-02", "ramp to stop with C1-02, then the BUS fault"),
                 1: ("coast", None, "coast to stop and trip BUS"),
                 2: ("ramp", "C1-09", "fast stop with C1-09, then the BUS fault"),
                 3: ("none", None, "alarm only: BUS is shown and the drive keeps running")}


@dataclass
class Reaction:
    """The drive's configured reaction to a lost master, read from the drive."""
    words: str                     # e.g. "o27 = 0: coast to a stop at once, then trip Er5"
    stop: str                      # "coast" | "ramp" | "trip" | "none"
    delay_s: float = 0.0           # configured delay after the watchdog
    recover: bool = False          # forgotten when the link returns within the delay
    alarm: str | None = None       # the fault the drive shows
    decel_s: float | None = None   # ramp time from max frequency to 0 (stop == "ramp")
    settings: dict = field(default_factory=dict)   # code -> value read from the drive

    def stop_s(self, hz: float, fmax_hz: float) -> float:
        if self.stop != "ramp" or not self.decel_s or fmax_hz <= 0:
            return 0.0
        return self.decel_s * min(1.0, abs(hz) / fmax_hz)


@dataclass
class CommLossResult:
    address: int
    mode: str
    hz: float
    watchdog_ms: float
    reaction: Reaction
    expected_s: float              # the bound: watchdog + delay + stop time + tolerance
    hold_s: float = 0.0            # how long the master stayed silent (silence mode)
    at_speed_hz: float | None = None
    measured_s: float | None = None        # last telegram -> first report of stopped / tripped
    not_before_s: float | None = None      # the earliest the reaction can have been
    reacted: bool = False
    passed: bool = False
    verdict: str = ""
    final_state: str | None = None
    fault_code: str | None = None
    acknowledged: bool = False
    watchdog_expired: bool | None = None   # the station had left data exchange when the master came back
    back_s: float | None = None            # last telegram -> the first cycle after the master came back
    stop: dict | None = None               # the stop pdrive sent afterwards (needed: it was running)
    counters: dict = field(default_factory=dict)   # the station's bus counters at the end

    def to_dict(self) -> dict:
        r = self.reaction
        return {"event": "result", "station": self.address, "mode": self.mode, "reference_hz": self.hz,
                "watchdog_s": self.watchdog_ms / 1000.0,
                "reaction": {"words": r.words, "stop": r.stop, "delay_s": r.delay_s,
                             "recover": r.recover, "alarm": r.alarm, "decel_s": r.decel_s,
                             "settings": r.settings},
                "expected_s": _r(self.expected_s), "hold_s": _r(self.hold_s),
                "at_speed_hz": self.at_speed_hz, "measured_s": _r(self.measured_s),
                "not_before_s": _r(self.not_before_s), "reacted": self.reacted,
                "passed": self.passed, "verdict": self.verdict, "final_state": self.final_state,
                "fault_code": self.fault_code, "acknowledged": self.acknowledged,
                "watchdog_expired": self.watchdog_expired, "back_s": _r(self.back_s),
                "stop": _stop_json(self.stop), "counters": self.counters}


def _stop_json(stop: dict | None) -> dict | None:
    """The stop pdrive sent, with its time as `duration_s` (docs/json.md)."""
    if stop is None:
        return None
    return {("duration_s" if k == "seconds" else k): v for k, v in stop.items()}


def _r(v: float | None) -> float | None:
    return None if v is None else round(v, 3)


# -- the configured reaction, per family ----------------------------------------------------------
def _read(sess, code: str):
    return sess.drive.read_param(code)


def read_reaction(sess) -> Reaction:
    """What the drive is set to do when its master goes away, read from the drive (family rules
    from the card manuals; see the profiles' decisions)."""
    fam = sess.profile.family
    d = sess.drive
    if fam != "toyo" and not d.has_param_channel:
        raise UsageError(f"station {sess.address}: layout {sess.layout} has no parameter channel, so "
                         f"the comm-loss setting cannot be read (choose a layout with one, e.g. --ppo 1)")
    try:
        if fam == "fuji":
            return _fuji_reaction(sess)
        if fam == "moeller":
            vals = d.comm_loss_setting()
            code = d.mc.comm_loss_param
            main = vals[code]
            shown = {k: int(v.raw) for k, v in vals.items()}
            others = ", ".join(f"{k} = {v}" for k, v in shown.items() if k != code)
            extra = f" ({others} shown as well: the card's slot decides which one applies)" if others else ""
            if int(main.raw) == 1:
                return Reaction(f"{code} = 1: keep running on the last command{extra}", "none",
                                settings=shown)
            return Reaction(f"{code} = {int(main.raw)}: trip {d.mc.comm_loss_alarm} (output off, "
                            f"the motor coasts){extra}", "trip", alarm=d.mc.comm_loss_alarm,
                            settings=shown)
        if fam == "yaskawa":
            return _yaskawa_reaction(sess)
        if fam == "toyo":
            return Reaction("protection 18 (COMM, communication timeout): trip, run commands forced "
                            "off (fixed: the manual names no setting)", "trip", alarm="COMM")
    except (DriveError, KeyError, ValueError) as e:
        raise DriveError(f"station {sess.address}: cannot read the comm-loss setting: {e}") from None
    raise UsageError(f"station {sess.address}: the comm-loss test knows no comm-loss reaction for "
                     f"the {fam} family (profile {sess.profile.name})")


def _fuji_reaction(sess) -> Reaction:
    from profidrive_cli.drives import fuji as fj
    d = sess.drive
    fc = d.fc if hasattr(d, "fc") else fj.fuji_config(sess.profile)
    o27 = int(_read(sess, fc.comm_loss_param).raw)
    o28 = float(_read(sess, fc.comm_loss_timer).value)
    act = fj.comm_loss_action(sess.profile, o27)
    words = fj.comm_loss_text(sess.profile, o27, o28)
    settings = {fc.comm_loss_param: o27, fc.comm_loss_timer: o28}
    if act.stop == "none":
        return Reaction(words + " -- the drive keeps running without a master", "none",
                        settings=settings)
    decel = None
    if act.stop == "ramp":
        decel = float(_read(sess, fc.comm_loss_decel).value)
        if decel == 0.0:             # 0 = the F03 time as the sim and the manual's ramps say
            decel = None
        settings[fc.comm_loss_decel] = decel
    stop = "ramp" if act.stop == "ramp" else ("trip" if act.trip else "coast")
    return Reaction(words, stop, delay_s=o28 if act.delayed else 0.0,
                    recover=act.recover and act.delayed, alarm=fc.comm_loss_alarm if act.trip else None,
                    decel_s=decel, settings=settings)


def _yaskawa_reaction(sess) -> Reaction:
    if sess.profile.param("F6-01") is None:
        return Reaction("BUS fault (the profile has no F6-01: assumed coast)", "trip", alarm="BUS")
    f601 = int(_read(sess, "F6-01").raw)
    stop, ramp_code, words = _YASKAWA_F601.get(f601, ("coast", None, "outside 0..3: assumed coast"))
    settings = {"F6-01": f601}
    decel = None
    if ramp_code:
        decel = float(_read(sess, ramp_code).value)
        settings[ramp_code] = decel
    return Reaction(f"F6-01 = {f601}: {words}", "trip" if stop == "coast" else stop,
                    alarm=None if stop == "none" else "BUS", decel_s=decel, settings=settings)


def clear_reaction(sess) -> Reaction:
    """Clear mode: the outputs go to zero (control word 0); the drive stops by its normal stop at
    worst (its deceleration time where it can be read)."""
    from profidrive_cli.session.safestop import read_decel
    decel = read_decel(sess)
    return Reaction("Global_Control Clear_Data: the outputs go to zero (control word 0, no run "
                    "command); the drive must stop" +
                    (f" (deceleration time {decel:g} s from max frequency)" if decel else ""),
                    "ramp" if decel else "coast", decel_s=decel)


# -- the test ------------------------------------------------------------------------------------
class _ZeroOutputs:
    """A CyclicChannel that sends all-zero outputs (the master in CLEAR) whatever the drive asks."""

    def __init__(self, inner):
        self.inner = inner

    def now(self) -> float:
        return self.inner.now()

    def exchange(self, outputs: bytes) -> bytes:
        return self.inner.exchange(bytes(len(outputs)))


def _reacted(st: DriveStatus) -> bool:
    return bool(st.fault) or st.stopped


def run_commloss(sess, hz: float, mode: str = "silence", timeout: float | None = None,
                 ack: bool = False, on_event: Callable[[dict], None] | None = None) -> CommLossResult:
    """The whole test on an open DriveSession (see the module docstring). Raises UsageError for bad
    arguments before anything moves; the session's close does the safe stop on every other way out."""
    if mode not in MODES:
        raise UsageError(f"--mode {mode!r}: must be {' or '.join(MODES)}")
    if not math.isfinite(hz) or hz == 0:
        raise UsageError(f"--hz {hz:g}: the test needs a speed other than 0 Hz")
    if timeout is not None and (not math.isfinite(timeout) or timeout <= 0):
        raise UsageError(f"--timeout {timeout:g} must be above 0 s")
    emit = on_event or (lambda ev: None)
    fmax_hz, _ = sess.fmax()
    pct = sess.percent_for_hz(hz)           # refuses speeds the drive cannot hold
    reaction = read_reaction(sess) if mode == "silence" else clear_reaction(sess)
    wd_s = sess.watchdog_ms / 1000.0
    tol = TOL_S + TOL_WD_FACTOR * wd_s
    stop_s = reaction.stop_s(hz, fmax_hz)
    if mode == "silence":
        expected = wd_s + (reaction.delay_s if reaction.stop != "none" else 0.0) + stop_s + tol
        hold = wd_s * HOLD_FACTOR + HOLD_EXTRA_S + (reaction.delay_s if reaction.recover else 0.0)
    else:
        expected = stop_s + tol
        hold = 0.0
    res = CommLossResult(sess.address, mode, hz, sess.watchdog_ms, reaction, expected, hold)
    emit({"event": "reaction", "station": sess.address, "words": reaction.words,
          "settings": reaction.settings, "expected_s": round(expected, 3)})

    # 1. run at speed
    sample = sess.start(pct)
    emit({"event": "started", "t_s": round(sample.t, 3)})
    band = max(AT_SPEED_HZ, AT_SPEED_FRAC * abs(hz))
    end = sess.channel.now() + START_TIMEOUT_S
    while True:
        sample = sess.poll()
        st = sample.status
        if st.fault:
            raise DriveError(f"station {sess.address}: the drive tripped before reaching {hz:g} Hz"
                             + (f" ({st.fault_code})" if st.fault_code else ""))
        if sample.actual_hz is not None and abs(sample.actual_hz - hz) <= band:
            break
        if sess.channel.now() > end:
            raise DriveError(f"station {sess.address}: not at {hz:g} Hz after {START_TIMEOUT_S:g} s "
                             f"(actual {sample.actual_hz} Hz)")
    res.at_speed_hz = sample.actual_hz
    emit({"event": "at_speed", "t_s": round(sample.t, 3), "actual_hz": sample.actual_hz})

    # 2. the break
    master, addr = sess.master, sess.address
    reparams_before = sess.counters.get("reparams", 0)
    drive = sess.drive
    if mode == "silence":
        t_last = sess.channel.now()
        emit({"event": "silence", "t_s": round(t_last - sess._t0, 3), "hold_s": round(hold, 3)})
        master.link.sleep(hold)
    else:
        from profidrive_cli.dp import services as S
        master.global_control(S.GC_CLEAR, da=addr)
        t_last = sess.channel.now()
        emit({"event": "clear", "t_s": round(t_last - sess._t0, 3)})
        drive.channel = _ZeroOutputs(sess.channel)

    # 3. watch until stopped / tripped, or the bound (+ the timeout) has passed
    watch = expected + (timeout if timeout is not None else max(2.0, 0.5 * expected))
    st = None
    try:
        while True:
            sample = sess.poll()
            st = sample.status
            now = sess.channel.now()
            if res.watchdog_expired is None and mode == "silence":
                res.watchdog_expired = sess.counters.get("reparams", 0) > reparams_before
                res.back_s = now - t_last
                emit({"event": "back", "t_s": round(sample.t, 3),
                      "after_s": round(now - t_last, 3), "watchdog_expired": res.watchdog_expired})
            if _reacted(st):
                res.reacted = True
                res.measured_s = now - t_last
                break
            if now - t_last > watch or (reaction.stop == "none" and now - t_last > expected):
                break
    finally:
        if mode == "clear":
            drive.channel = sess.channel
            from profidrive_cli.dp import services as S
            try:
                master.global_control(0, da=addr)          # Operate again
            except Exception:                               # noqa: BLE001 (the stop follows anyway)
                pass
    if mode == "silence":
        res.not_before_s = wd_s
    res.final_state, res.fault_code = st.state, st.fault_code
    if st.fault and st.fault_code is None:
        try:
            s2 = sess.status().status
            res.fault_code = s2.fault_code
        except DriveError:
            pass

    # 4. verdict
    if reaction.stop == "none":
        res.passed = False
        res.verdict = ("FAIL: the drive is set to keep running without a master (" + reaction.words +
                       ")" + (f"; it reported {'tripped' if st.fault else 'stopped'} anyway after "
                              f"{res.measured_s:.2f} s" if res.reacted else
                              f"; it was still running at {sample.actual_hz} Hz "
                              f"{now - t_last:.2f} s after the last telegram"))
    elif not res.reacted:
        res.passed = False
        res.verdict = (f"FAIL: still running at {sample.actual_hz} Hz {now - t_last:.2f} s after the "
                       f"last telegram (expected stopped or tripped within {expected:.2f} s)")
    elif res.measured_s > expected + 1e-9 and res.measured_s != res.back_s:
        res.passed = False
        res.verdict = (f"FAIL: {'tripped' if st.fault else 'stopped'} after {res.measured_s:.2f} s, "
                       f"later than the expected {expected:.2f} s")
    else:
        # seen at the master's first cycle back: it happened while the master was away (at the
        # latest then); the time to come back is the master's, not the drive's
        res.passed = True
        first = res.measured_s == res.back_s
        res.verdict = (f"PASS: {'tripped' if st.fault else 'stopped'}"
                       f"{f' ({res.fault_code})' if res.fault_code else ''} "
                       + (f"while the master was away (seen at its first cycle back, "
                          f"{res.measured_s:.2f} s after the last telegram)" if first else
                          f"within {res.measured_s:.2f} s of the last telegram")
                       + f"; expected within {expected:.2f} s")
    if mode == "silence" and res.watchdog_expired is False:
        res.verdict += ("; the station was still in data exchange when the master came back "
                        f"after {hold:.2f} s: its watchdog did not expire")
        res.passed = False

    # 5. leave it stopped (the stop command replaces the run outputs, also after a trip);
    #    acknowledge only when asked
    was_running = not (st.fault or st.stopped)
    rep = sess.stop()
    res.stop = dict(rep.to_dict(), needed=was_running)
    if rep.status is not None:
        res.final_state = rep.status.state
        res.fault_code = rep.status.fault_code or res.fault_code
    if ack and sess.final_status is not None and sess.final_status.fault:
        s3 = sess.clear_fault()
        res.acknowledged = not s3.status.fault
        res.final_state, res.fault_code = s3.status.state, s3.status.fault_code
        if sess.stop_report is not None:
            sess.stop_report.status = s3.status     # what the drive is left in: acknowledged
    res.counters = dict(sess.counters)
    emit(res.to_dict())
    return res
