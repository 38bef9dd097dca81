"""The safe stop: the family's normal stop with a bounded wait (from the drive's deceleration time
where it can be read), escalation to a coast stop when the drive does not stop or a second signal
hurries it, and the shutdown on every way out of a session (stop if the drive may be running,
release the station; with the link lost, say what the station's watchdog and the drive will do).
Sends only stop commands (drives.base.Drive.stop) and the release; reads parameters only to size the
wait and to name the comm-loss behaviour.

Nothing the caller hands in can skip the stop: an exception of a sample or message callback during
the stop (a closed stdout, a bug) is kept in `sess.callback_error`, the callback is not called again,
and the stop and the release go on; shutdown raises it after the release when nothing else went
wrong (the command then ends with its one line).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from profidrive_cli import PdriveError, UsageError
from profidrive_cli.drives.base import DriveError, DriveStatus
from profidrive_cli.session.cycle import make_sample

COAST_TIMEOUT_S = 10.0
DEFAULT_STOP_TIMEOUT_S = 30.0

#: deceleration-time parameter per family when the profile's `profidrive.ramps` names none
_DECEL_CODES = {"fuji": "F08", "moeller": "F003", "yaskawa": "C1-02"}
#: what the drive does when the master goes silent, per family (when it cannot be read)
_COMM_LOSS_WORDS = {
    "fuji": "its o27/o28 setting (o27 = 3 or 13..15 ignores the loss: the motor keeps running)",
    "moeller": "P002 (0 = trip E70 and coast; 1 = keep running on the last command)",
    "toyo": "protection 18 (COMM): the inverter trips and coasts",
    "yaskawa": "a BUS fault after the option's communication timeout (the drive stops by its BUS "
               "fault setting)",
}


@dataclass
class StopReport:
    how: str                       # "normal", "coast", "not needed", "not sent (link lost)", "failed"
    stopped: bool
    seconds: float = 0.0
    message: str = ""
    status: DriveStatus | None = None

    def to_dict(self) -> dict:
        return {"how": self.how, "stopped": self.stopped, "seconds": round(self.seconds, 3),
                "message": self.message,
                "state": self.status.state if self.status is not None else None}


def read_decel(sess) -> float | None:
    d = sess.drive
    if not d.has_param_channel:
        return None
    code = getattr(getattr(d, "cfg", None), "ramps", {}) or {}
    code = code.get("decel") if isinstance(code, dict) else None
    code = code or _DECEL_CODES.get(sess.profile.family)
    if not code or sess.profile.param(code) is None:
        return None
    try:
        return float(d.read_param(code).value)
    except (DriveError, UsageError, ValueError, TypeError):
        return None


def read_comm_loss(sess) -> str:
    d = sess.drive
    fam = sess.profile.family
    try:
        said = d.comm_loss_summary() if d.has_param_channel else None
        if said:
            return said
    except (DriveError, UsageError):
        pass
    return _COMM_LOSS_WORDS.get(fam, "its communication-loss setting")


def stop_timeout(sess, percent: float | None = None) -> float:
    if sess.stop_timeout_s is not None:
        return float(sess.stop_timeout_s)
    if sess._decel_s is None:
        return DEFAULT_STOP_TIMEOUT_S
    frac = 1.0
    if percent is not None:
        frac = min(1.0, abs(percent) / 100.0)
    return max(5.0, min(600.0, 1.5 * sess._decel_s * frac + 3.0))


def stop(sess, on_sample, timeout) -> StopReport:
    """Normal stop, bounded wait, coast if it does not stop (or a signal hurries it)."""
    d = sess.need_drive()
    t_start = sess.channel.now()
    last = d.last_seen()
    pct = last.speed_percent if last is not None else None
    limit = timeout if timeout is not None else sess.stop_timeout(pct)
    st = None
    why = ""
    try:
        d.stop("normal", wait=False)
        st, on_sample = _wait(sess, limit, on_sample)
        if st is not None:
            sess._may_run = False
            how = "normal"
            msg = (f"the drive is in fault{f' ({st.fault_code})' if st.fault_code else ''}: "
                   f"its output is off" if st.fault else "stopped")
            return StopReport(how, True, sess.channel.now() - t_start, msg, st)
        why = ("stop hurried by a second signal" if sess.signals.hurry else
               f"not stopped after {limit:g} s")
    except DriveError as e:
        why = f"normal stop failed: {e}"
    # escalate: coast (OFF2 / base block / run bit off)
    _tell(sess, sess.warn, f"{why}: coasting")
    try:
        d.stop("coast", wait=False)
        sess.signals.hurry = False
        st, on_sample = _wait(sess, COAST_TIMEOUT_S, on_sample)
    except DriveError as e:
        return StopReport("failed", False, sess.channel.now() - t_start,
                          f"{why}; coast stop not possible: {e}", sess.final_status)
    if st is None:
        return StopReport("failed", False, sess.channel.now() - t_start,
                          f"{why}; the drive does not report stopped after a coast stop either",
                          sess.final_status)
    sess._may_run = False
    return StopReport("coast", True, sess.channel.now() - t_start, f"{why}; coasted", st)


def wait_stopped(sess, timeout: float, on_sample) -> DriveStatus | None:
    return _wait(sess, timeout, on_sample)[0]


def _wait(sess, timeout: float, on_sample):
    """(the status once stopped or in fault, else None; on_sample, or None once it raised)."""
    d = sess.drive
    end = sess.channel.now() + timeout
    while True:
        st = d.cycle()
        if on_sample is not None:
            try:
                on_sample(make_sample(sess, st))
            except Exception as e:          # noqa: BLE001  (the stop goes on without it)
                callback_failed(sess, e)
                on_sample = None
        if on_sample is None:
            sess.final_status = st
        if st.fault or st.stopped:
            if st.fault and st.fault_code is None:
                try:
                    st = d.status()
                except DriveError:
                    pass
            return st, on_sample
        if sess.signals.hurry or sess.channel.now() > end:
            return None, on_sample


def callback_failed(sess, e: BaseException) -> None:
    """Keep the first exception a callback raised during the stop (reported after the release)."""
    if getattr(sess, "callback_error", None) is None:
        sess.callback_error = e


def _tell(sess, say, text: str) -> None:
    """sess.say / sess.warn: the text is kept in the session even when on_message raises."""
    try:
        say(text)
    except Exception as e:                  # noqa: BLE001
        callback_failed(sess, e)


def link_lost_words(sess, e: BaseException | None) -> str:
    """What the watchdog does now that no stop can be sent; `e`: the LinkLost, None when the link
    was found lost before (sess.link_lost) and the session is closed without an exception."""
    fam_text = sess.comm_loss_text or _COMM_LOSS_WORDS.get(
        sess.profile.family if sess.profile else "", "its communication-loss setting")
    return (f"link lost{f' ({e})' if e is not None else ''}: pdrive cannot send a stop. The station's DP watchdog "
            f"({sess.watchdog_ms:g} ms) takes it out of data exchange within "
            f"{sess.watchdog_ms / 1000.0:g} s of the last telegram; the drive then stops by "
            f"{fam_text}")


def shutdown(sess, exc: BaseException | None) -> None:
    """The stop and the release on every way out; a callback's exception during them is raised
    after the release (when `exc` is None: the session's own error comes first)."""
    _shutdown(sess, exc)
    late = getattr(sess, "callback_error", None)
    if late is not None and exc is None:
        sess.callback_error = None
        raise late


def _shutdown(sess, exc: BaseException | None) -> None:
    from profidrive_cli.link.base import LinkLost
    if isinstance(exc, LinkLost):
        sess.link_lost = True
    if sess.drive is None or sess.address is None:
        return
    if sess.link_lost:
        if sess._may_run:
            sess.stop_report = StopReport("not sent (link lost)", False, 0.0,
                                          link_lost_words(sess, exc))
            _tell(sess, sess.say, sess.stop_report.message)
        _after_stop(sess, False)
        return
    if exc is not None:
        # an interrupted request may have left a reply on the line: start clean
        try:
            time.sleep(min(0.05, sess.master.params.reply_timeout(64)))
            sess.master.link.flush_input()
        except Exception:
            pass
    if sess._may_run:
        try:
            r = sess.stop()
            if r.how == "normal":
                _tell(sess, sess.say, f"stopped (normal stop, {r.seconds:.1f} s)"
                      if not (r.status and r.status.fault) else r.message)
            elif r.how == "coast":
                _tell(sess, sess.say, f"stopped by a coast stop after {r.seconds:.1f} s ({r.message})")
            else:
                _tell(sess, sess.say, f"could not confirm the stop: {r.message}")
        except LinkLost as e:
            sess.link_lost = True
            sess.stop_report = StopReport("not sent (link lost)", False, 0.0, link_lost_words(sess, e))
            _tell(sess, sess.say, sess.stop_report.message)
            _after_stop(sess, False)
            return
        except PdriveError as e:
            sess.stop_report = StopReport("failed", False, 0.0, f"stop failed: {e}")
            _tell(sess, sess.say, f"stop failed: {e}; the station's watchdog "
                                   f"({sess.watchdog_ms:g} ms) ends data exchange when pdrive lets go")
    elif sess.stop_report is None:
        sess.stop_report = StopReport("not needed", True, 0.0, "not started by this session",
                                      sess.final_status)
    _after_stop(sess, True)
    try:
        sess.master.release(sess.address)
    except PdriveError:
        pass


def _after_stop(sess, link_ok: bool) -> None:
    """The session's after_stop hooks (e.g. restoring a PZD mapping), after the stop and before the
    station is released; told whether the link still works. Their errors are said, never raised."""
    for hook in getattr(sess, "after_stop", ()):
        try:
            hook(link_ok)
        except Exception as e:          # noqa: BLE001  (the stop is done; say what was left)
            _tell(sess, sess.say, f"after the stop: {e}")
