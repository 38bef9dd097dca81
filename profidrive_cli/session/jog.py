"""Jog: the card's own jog / inching function (Toyo CTW bits 8/9 or run-command bit 1, Moeller CTW
bit 8 at A038), started and released through drives.base.Drive.jog. Families without jog are refused
before anything is sent (UsageError, exit 2). The release ends in the session's normal safe stop
(safestop.py), the same as `run` on every exit path (DriveSession.close stops a drive that may run).
"""

from __future__ import annotations

from profidrive_cli import UsageError
from profidrive_cli.drives.base import DriveError, ParamValue
from profidrive_cli.session.cycle import Sample, make_sample
from profidrive_cli.session.safestop import read_comm_loss, read_decel


def refusal(sess) -> str | None:
    """Why this station cannot jog (one line), None when it can."""
    d = sess.need_drive()
    return None if d.supports_jog else d.jog_refusal()


def check(sess) -> None:
    why = refusal(sess)
    if why is not None:
        raise UsageError(why)


def jog_speed(sess) -> ParamValue | None:
    """The jog speed parameter read from the drive (Moeller A038), None where the card names none or
    the layout has no parameter channel."""
    d = sess.need_drive()
    code = d.jog_reference()
    if code is None or not d.has_param_channel:
        return None
    return d.read_param(code)


def start(sess, reverse: bool = False, timeout: float = 5.0) -> Sample:
    """Jog on; waits until the drive reports running (or moving); DriveError with the family's hint
    after `timeout` s."""
    check(sess)
    d = sess.need_drive()
    if sess._decel_s is None:
        sess._decel_s = read_decel(sess)
    if sess.comm_loss_text is None:
        sess.comm_loss_text = read_comm_loss(sess)
    st = d.cycle()
    if st.fault:
        raise DriveError("the drive is in fault: reset it first")
    sess._may_run = True
    d.jog(True, reverse=reverse)
    try:
        st = d.cycles_until(lambda s: s.fault or s.running or not s.stopped, timeout, "the jog to start")
    except DriveError as e:
        last = d.last_seen()
        hint = d.start_hint(last) if last is not None else None
        raise DriveError(f"{e}; {hint}" if hint else str(e)) from None
    if st.fault:
        raise DriveError(f"the drive tripped at the jog ({st.fault_code or st.state})")
    return make_sample(sess, st)


def release(sess) -> Sample:
    """Jog off (one cycle); the caller then stops the drive (DriveSession.stop)."""
    d = sess.need_drive()
    d.jog(False)
    return make_sample(sess, d.cycle())
