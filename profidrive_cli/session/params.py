"""Parameter services on the session's station: how the family addresses a code (with the closest
codes, or the family a foreign code belongs to), parsing a typed value, reading, and the checked write
(writable, not dangerous unless allowed, the exact-value check of drives/values.py, stop-only
parameters only while stopped, read back); saving to non-volatile memory. Reads and writes only
through drives.base.Drive.read_param / write_param / save.
"""

from __future__ import annotations

import difflib
import math
from profidrive_cli import UsageError
from profidrive_cli.drives.base import DriveError, ParamInfo, ParamValue
from profidrive_cli.drives.formats import display_text, value_from_text
from profidrive_cli.drives.profile import Profile, all_profiles
from profidrive_cli.drives.values import danger
from profidrive_cli.session.cycle import Sample


def suggest_codes(profile: Profile, code: str, n: int = 5) -> list[str]:
    by_lower = {c.lower(): c for c in profile.parameters}
    hits = difflib.get_close_matches(code.strip().lower(), list(by_lower), n=n, cutoff=0.5)
    return [by_lower[h] for h in hits]


def profiles_with_code(code: str) -> list[Profile]:
    c = code.strip().lower()
    return [p for p in all_profiles() if any(k.lower() == c for k in p.parameters)]


def param_info(sess, code: str) -> ParamInfo:
    """How the station's family addresses `code` (no bus traffic). UsageError with the closest
    codes of the family, or with the family the code belongs to."""
    d = sess.need_drive()
    text = code.strip()
    if not text:
        raise UsageError("empty parameter code")
    try:
        return d.param_info(text)
    except UsageError as e:
        raise UsageError(unknown_code_message(sess, text, str(e))) from None


def unknown_code_message(sess, code: str, why: str) -> str:
    prof = sess.profile
    if any(k.lower() == code.lower() for k in prof.parameters):
        return why                         # ours, but not reachable (e.g. no published PNU)
    where = f"station {sess.address} is {prof.name} ({prof.title}, family {prof.family})"
    others = [p for p in profiles_with_code(code) if p.family != prof.family]
    near = suggest_codes(prof, code)
    hint = f"; closest {prof.family} codes: {', '.join(near)}" if near else ""
    if others:
        fams = sorted({p.family for p in others})
        names = ", ".join(p.name for p in others)
        return (f"{code} is a {'/'.join(fams)} code ({names}); {where}{hint}")
    if near:
        return f"unknown parameter '{code}' for {prof.name}{hint}"
    return f"{why}" if why else f"unknown parameter '{code}' for {prof.name}"


def parse_value(sess, code: str, text: str | float | int, info: ParamInfo | None = None):
    """A value typed by the user -> int/float; UsageError saying what was expected."""
    info = info or param_info(sess, code)
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        return text
    t = str(text).strip()
    raw = value_from_text(sess.profile, info.param, t)     # the card's own notation (Fuji o40 "041A")
    if raw is not None:
        return raw
    try:
        if t.lower().startswith(("0x", "-0x")):
            return int(t, 16)
        v = float(t)
        if not math.isfinite(v):
            raise ValueError
        return int(v) if v.is_integer() and "." not in t and "e" not in t.lower() else v
    except ValueError:
        p = info.param
        rng = ""
        if p is not None and p.min is not None and p.max is not None:
            rng = f" {p.min:g}..{p.max:g}"
        unit = f" {info.unit}" if info.unit else ""
        kind = "a number" if p is None or (p.scale and not float(p.scale).is_integer()) else "a whole number"
        raise UsageError(f"{info.code}: expected {kind}{rng}{unit}, got {t!r}") from None


def read_param(sess, code: str) -> ParamValue:
    param_info(sess, code)                 # unknown codes: the closest ones / the right family
    return with_text(sess.profile, sess.drive.read_param(code.strip()))


def with_text(profile, pv: ParamValue) -> ParamValue:
    """Fill ParamValue.text from the parameter's `format:` (alarm names, function codes, baud rates)."""
    if pv is not None and pv.text is None:
        pv.text = display_text(profile, profile.param(pv.code), pv.raw, pv.value)
    return pv


def danger_of(sess, info: ParamInfo) -> str | None:
    """What writing this parameter does, in words, when the profile marks it `dangerous: true`
    (also when it is reached by its raw PNU/index or register); None otherwise."""
    if info.param is not None:
        return danger(info.param)
    d = sess.drive
    try:
        hits = d.params_at(info)
    except (UsageError, DriveError, AttributeError):
        return None
    return next((danger(q) for q in hits if danger(q)), None)


def check_dangerous(sess, info: ParamInfo, allow_dangerous: bool = False) -> None:
    """UsageError (exit 2) for a dangerous parameter unless allow_dangerous."""
    what = danger_of(sess, info)
    if what and not allow_dangerous:
        raise UsageError(f"{info.code} ({info.name}) is dangerous: writing it {what}; nothing was "
                         f"written (add --allow-dangerous to write it)")


def check_write(sess, info: ParamInfo, value, allow_dangerous: bool = False) -> None:
    """Every check before a write, no bus traffic: writable, dangerous, exact value (resolution,
    range, listed codes, wire width: drives/values.py)."""
    p = info.param
    if p is not None and not p.writable:
        raise UsageError(f"{info.code} ({info.name}) is read-only")
    check_dangerous(sess, info, allow_dangerous)
    msg = sess.drive.value_problem(info, value)
    if msg:
        raise UsageError(msg)


def stopped_for(sess, info: ParamInfo) -> str | None:
    """None when the parameter may be written now; else why not (stop-only while running)."""
    if info.access != "stop":
        return None
    st = sess.drive.cycle()
    if st.running or not st.stopped:
        hz = Sample(0, st, sess.fmax_hz,
                    0, 0, {}).actual_hz
        return (f"{info.code} ({info.name}) can only be changed while the motor is "
                f"stopped (the drive is {st.state}" + (f", {hz:g} Hz" if hz else "") + "); stop it first")
    return None


def write_param(sess, code: str, value, *, check_running: bool = True,
                allow_dangerous: bool = False) -> ParamValue:
    """Checked write (writable, not dangerous unless allow_dangerous, exact value, stop-only
    parameters while running); returns the value read back from the drive."""
    info = param_info(sess, code)
    if isinstance(value, str):
        value = parse_value(sess, code, value, info)
    check_write(sess, info, value, allow_dangerous)
    if check_running:
        why = stopped_for(sess, info)
        if why:
            raise DriveError(why)
    return with_text(sess.profile, sess.drive.write_param(code.strip(), value))


def notes(sess) -> list[str]:
    """Remarks the codec collected (e.g. Fuji: 'o30 takes effect after a power cycle'); cleared."""
    return sess.drive.take_notes() if sess.drive is not None else []


def save_support(sess) -> str:
    """'command' (the card has a save command), 'automatic' (every write is stored), or
    'unsupported'."""
    return sess.need_drive().save_support()


def save(sess) -> str:
    """Store parameters in non-volatile memory; returns what happened in words."""
    how = save_support(sess)
    if how == "automatic":
        return f"{sess.profile.name}: every parameter write is stored by the card itself (no separate save)"
    if how == "unsupported":
        raise DriveError(f"{sess.profile.name}: this card has no save command; the value is "
                         f"written but may be lost at power-off")
    sess.drive.save()
    return "saved to non-volatile memory"
