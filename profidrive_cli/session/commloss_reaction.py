"""The comm-loss test's expectations, read from the drive (session/commloss.py runs the test):

    read_reaction(sess) -> Reaction      silence mode: what the drive does when its master goes away
    clear_reaction(sess) -> Reaction     clear mode: what it does with all-zero outputs
    check_bus_control(sess)              DriveError when the bus cannot run the drive (Fuji y98)
    read_accel(sess) -> (s, code)        the acceleration time, for the wait until at speed

Family rules from the card manuals (see the profiles' decisions), answered by each codec's Drive hooks
(drives/base.py comm_loss_reaction, zero_data_reaction, bus_run_refusal, normal_stop_warnings,
ramp_param):
Fuji o27/o28 + F08 (Table 9.1), H81 (light alarms), y98, OPC-PDP3 o32 (Table 10.1; drives/fuji/
reaction.py); Moeller P002 (+ P001 shown); Yaskawa F6-01 + C1-02 / C1-09, b1-03; Toyo protection 18
(fixed), control word bit 10 and C-00.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from profidrive_cli import UsageError
from profidrive_cli.drives.base import DriveError, ParamValue, Reaction

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.session.station import DriveStation

__all__ = ["Reaction", "read_reaction", "clear_reaction", "check_bus_control", "read_accel"]

# -- reads ----------------------------------------------------------------------------------
def _read(sess: "DriveStation", code: str) -> ParamValue:
    return sess.need_drive().read_param(code)


def _readable(sess: "DriveStation", code: str) -> bool:
    assert sess.profile is not None
    p = sess.profile.param(code)
    return (p is not None and (p.pnu is not None or p.register is not None)
            and sess.need_drive().has_param_channel)


def read_reaction(sess: "DriveStation") -> Reaction:
    """What the drive is set to do when its master goes away, read from the drive (the family's
    Drive.comm_loss_reaction: the card manuals' rules; see the profiles' decisions)."""
    d, prof = sess.need_drive(), sess.profile
    assert prof is not None
    if not d.comm_loss_reaction_fixed and not d.has_param_channel:
        raise UsageError(f"station {sess.address}: layout {sess.layout} has no parameter channel, so "
                         f"the comm-loss setting cannot be read (choose a layout with one, e.g. --ppo 1)")
    try:
        r = d.comm_loss_reaction()
    except (DriveError, KeyError, ValueError) as e:
        raise DriveError(f"station {sess.address}: cannot read the comm-loss setting: {e}") from None
    if r is not None:
        return r
    raise UsageError(f"station {sess.address}: the comm-loss test knows no comm-loss reaction for "
                     f"the {prof.family} family (profile {prof.name})")


def check_bus_control(sess: "DriveStation") -> None:
    """Refuse (DriveError, before anything moves) a drive the bus cannot run (the family's
    Drive.bus_run_refusal: Fuji y98 must be 3)."""
    why = sess.need_drive().bus_run_refusal()
    if why:
        raise DriveError(f"station {sess.address}: {why}")


def clear_reaction(sess: "DriveStation") -> Reaction:
    """Clear mode: the outputs go to zero (control word 0, bit 10 = 0). Fuji OPC-PDP3: o32 decides
    (Table 10.1, L6562-6584); OPC-G1-PDP and Toyo (PROFIdrive mode): bit 10 = 0 keeps the last
    command; otherwise the drive stops by its normal stop (its deceleration time where it can be
    read; Yaskawa b1-03 = 1 coasts)."""
    d = sess.need_drive()
    head = "Global_Control Clear_Data: the outputs go to zero (control word 0, no run command)"
    try:
        r = d.zero_data_reaction(head)
        if r is not None:
            return r
    except DriveError as e:
        raise DriveError(f"station {sess.address}: cannot read the all-zero-data setting: {e}") from None
    from profidrive_cli.session.safestop import read_decel
    decel = read_decel(d, sess.profile)
    extra = [] if decel else d.normal_stop_warnings()
    return Reaction(head + "; the drive must stop by its normal stop" +
                    (f" (deceleration time {decel:g} s from max frequency)" if decel else
                     " (its deceleration time cannot be read: the limit counts no stop time)"),
                    "ramp", decel_s=decel, warnings=extra)


def read_accel(sess: "DriveStation") -> tuple[float | None, str | None]:
    """(acceleration time from 0 to the max frequency, its code) where the drive says it."""
    code = sess.need_drive().ramp_param("accel")      # the profile's ramps, else the card's own
    if not code or not _readable(sess, code):
        return None, code
    try:
        return float(_read(sess, code).value), code
    except (DriveError, UsageError, ValueError, TypeError):
        return None, code
