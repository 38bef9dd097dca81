"""Motion and speed: the maximum frequency that 100 % stands for (read from the drive, --fmax, or
the profile default), percent for Hz, the reference, start (which first reads what the safe stop
needs), poll and status. Commands the drive only through drives.base.Drive (set_speed, start,
cycle, status); never stops it (safestop.py does).
"""

from __future__ import annotations

import math

from profidrive_cli import UsageError
from profidrive_cli.drives.base import DriveError
from profidrive_cli.session.cycle import Sample, make_sample
from profidrive_cli.session.safestop import read_comm_loss, read_decel


def fmax(sess, override: float | None = None) -> tuple[float, str]:
    """(max frequency in Hz = 100 %, where it came from). With a parameter channel the drive's own
    value is read; without one `override` (--fmax) or the profile default is used."""
    d = sess.need_drive()
    if sess._fmax is not None and override == sess._fmax_override:
        return sess._fmax
    code = sess.profile.max_frequency_param
    pdef = sess.profile.param(code) if code else None
    readable = pdef is not None and (pdef.pnu is not None or pdef.register is not None)
    # an fmax from a config file keeps its FILE:LINE (config.FileHz): the label names that line
    source = getattr(override, "source", None)
    given = f"fmax {override:g} Hz from {source}" if hasattr(override, "source") else \
        f"--fmax {override:g}" if override is not None else ""
    if d.has_param_channel and readable:
        hz = float(d.max_frequency())
        src = f"read from the drive ({code})"
        if override is not None and not math.isclose(override, hz, rel_tol=1e-3):
            sess.warn(f"{given}{'' if hasattr(override, 'source') else ' Hz'} ignored: the drive "
                       f"says {code} = {hz:g} Hz")
    elif override is not None:
        if override <= 0:
            raise UsageError(f"{given}: must be above 0 Hz")
        hz = float(override)
        src = f"from {getattr(override, 'source', '--fmax')}"
        set_drive_fmax(sess, hz)
    else:
        hz = float(sess.profile.max_frequency_default)
        if not d.has_param_channel:
            why = f"layout {sess.layout} has no parameter channel"
        elif code:
            why = f"{code} has no published parameter number"
        else:
            why = "the profile names no max-frequency parameter"
        src = (f"the profile default ({why}; {code or 'max frequency'} not read — "
               f"give --fmax if the drive is set otherwise)")
        set_drive_fmax(sess, hz)
    sess._fmax, sess._fmax_override = (hz, src), override
    return sess._fmax


def set_drive_fmax(sess, hz: float) -> None:
    # without a parameter channel the codec would scale speed words with the profile default:
    # keep it consistent with ours
    sess.drive.use_max_frequency(hz)


def percent_for_hz(sess, hz: float, fmax_override: float | None = None) -> float:
    top, src = fmax(sess, fmax_override)
    pct = 100.0 * hz / top
    if abs(pct) > 100.0 + 1e-9:
        raise UsageError(f"{hz:g} Hz is above the maximum frequency {top:g} Hz ({src})")
    return pct


def set_reference(sess, percent: float) -> None:
    if not -100.0 <= percent <= 100.0:
        raise UsageError(f"speed {percent:g} % is outside -100..100 % of the maximum frequency")
    sess.need_drive().set_speed(percent)


def start(sess, percent: float | None = None, timeout: float = 5.0) -> Sample:
    """Set the reference (if given) and step the drive to operation."""
    d = sess.need_drive()
    if sess._decel_s is None:
        sess._decel_s = read_decel(sess)
    if sess.comm_loss_text is None:
        sess.comm_loss_text = read_comm_loss(sess)
    if percent is not None:
        set_reference(sess, percent)
    sess._may_run = True
    st = d.start(timeout=timeout)
    return make_sample(sess, st)


def poll(sess) -> Sample:
    """One Data_Exchange with the current command, decoded."""
    st = sess.need_drive().cycle()
    if st.fault and st.fault_code is None:
        st = sess.need_drive().status()
    return make_sample(sess, st)


def status(sess) -> Sample:
    """One read of the status, with the current fault named where the card can say it."""
    d = sess.need_drive()
    if d.has_param_channel:
        try:
            fmax(sess)
        except DriveError:
            pass
    return make_sample(sess, d.status())
