"""Jog: the card's own jog / inching function (Toyo CTW bits 8/9 or run-command bit 1, Moeller CTW
bit 8 at A038), started and released through drives.base.Drive.jog. Families without jog are refused
before anything is sent (UsageError, exit 2). Motion (session/motion.py) runs these steps and owns
what they mean for the stop: the release ends in its normal safe stop, the same as `run` on every
exit path.
"""

from __future__ import annotations

from profidrive_cli import UsageError
from profidrive_cli.drives.base import Drive, DriveError, DriveStatus, ParamValue


def refusal(d: Drive) -> str | None:
    """Why this card cannot jog (one line), None when it can."""
    return None if d.supports_jog else d.jog_refusal()


def check(d: Drive) -> None:
    why = refusal(d)
    if why is not None:
        raise UsageError(why)


def jog_speed(d: Drive) -> ParamValue | None:
    """The jog speed parameter read from the drive (Moeller A038), None where the card names none or
    the layout has no parameter channel."""
    code = d.jog_reference()
    if code is None or not d.has_param_channel:
        return None
    return d.read_param(code)


def check_not_in_fault(d: Drive) -> None:
    st = d.cycle()
    if st.fault:
        raise DriveError("the drive is in fault: reset it first")


def jog_on(d: Drive, reverse: bool, timeout: float) -> DriveStatus:
    """Jog on; waits until the drive reports running (or moving); DriveError with the family's hint
    after `timeout` s."""
    d.jog(True, reverse=reverse)
    try:
        st = d.cycles_until(lambda s: s.fault or s.running or not s.stopped, timeout, "the jog to start")
    except DriveError as e:
        last = d.last_seen()
        hint = d.start_hint(last) if last is not None else None
        raise DriveError(f"{e}; {hint}" if hint else str(e)) from None
    if st.fault:
        raise DriveError(f"the drive tripped at the jog ({st.fault_code or st.state})")
    return st


def release(d: Drive) -> DriveStatus:
    """Jog off (one cycle); the caller then stops the drive."""
    d.jog(False)
    return d.cycle()
