"""Parameter codes and values, for session/parameters.py (Parameters): how an unknown code is
explained (the closest codes of the family, or the family a foreign code belongs to), parsing a value
typed by the user, the card's own value text, the write plan (WritePlan: a code resolved once and
every check made once, for Parameters.execute), and the two views these modules share: Host, the
station's public attributes Parameters reads, and ParamView, the part of Parameters that backup.py
and restore.py use, with ParamRow, one row of their tables. No bus traffic here.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
from dataclasses import dataclass
from typing import Any, Callable, Protocol

from profidrive_cli import UsageError
from profidrive_cli.drives.base import Drive, ParamInfo, ParamValue
from profidrive_cli.drives.formats import display_text, value_from_text
from profidrive_cli.drives.profile import Profile, all_profiles, foreign_profiles_with_code
from profidrive_cli.session.view import StationView

__all__ = ["Host", "ParamInfo", "ParamRow", "ParamView", "WritePlan", "dangerous_words", "parse_text",
           "profiles_with_code", "suggest_codes", "unknown_code_message", "with_text"]


def suggest_codes(profile: Profile, code: str, n: int = 5) -> list[str]:
    by_lower = {c.lower(): c for c in profile.parameters}
    hits = difflib.get_close_matches(code.strip().lower(), list(by_lower), n=n, cutoff=0.5)
    return [by_lower[h] for h in hits]


def profiles_with_code(code: str) -> list[Profile]:
    c = code.strip().lower()
    return [p for p in all_profiles() if any(k.lower() == c for k in p.parameters)]


def unknown_code_message(prof: Profile, address: int | None, code: str, why: str) -> str:
    """The one line for a code the station's family does not address: the closest codes of the
    family, or the family the code belongs to."""
    if any(k.lower() == code.lower() for k in prof.parameters):
        return why                         # ours, but not reachable (e.g. no published PNU)
    where = f"station {address} is {prof.name} ({prof.title}, family {prof.family})"
    others = foreign_profiles_with_code(code, prof)
    near = suggest_codes(prof, code)
    hint = f"; closest {prof.family} codes: {', '.join(near)}" if near else ""
    if others:
        fams = sorted({p.family for p in others})
        names = ", ".join(p.name for p in others)
        return (f"{code} is a {'/'.join(fams)} code ({names}); {where}{hint}")
    if near:
        return f"unknown parameter '{code}' for {prof.name}{hint}"
    return f"{why}" if why else f"unknown parameter '{code}' for {prof.name}"


def parse_text(profile: Profile, info: ParamInfo, text: str | float | int) -> float | int:
    """A value typed by the user -> int/float; UsageError saying what was expected."""
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        return text
    t = str(text).strip()
    raw = value_from_text(profile, info.param, t)     # the card's own notation (Fuji o40 "041A")
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


def with_text(profile: Profile, pv: ParamValue) -> ParamValue:
    """Fill ParamValue.text from the parameter's `format:` (alarm names, function codes, baud rates)."""
    if pv is not None and pv.text is None:
        pv.text = display_text(profile, profile.param(pv.code), pv.raw, pv.value)
    return pv


def dangerous_words(info: ParamInfo, what: str) -> str:
    """The refusal of a dangerous parameter written without allow_dangerous."""
    return (f"{info.code} ({info.name}) is dangerous: writing it {what}; nothing was "
            f"written (add --allow-dangerous to write it)")


@dataclass
class ParamRow:
    """One line of restore / diff: result applied | refused | unchanged | would apply | differs |
    missing (in the file, not readable) | skipped."""
    code: str
    name: str
    unit: str
    file_value: Any
    drive_value: Any
    result: str
    reason: str = ""
    new_value: Any = None
    line: int = 0                  # the row's line in the file (0: unknown)
    why: str = ""                  # for 'skipped': unknown | read-only | not restored | dangerous | out of scope

    def to_dict(self) -> dict[str, Any]:
        return {k: v for k, v in dataclasses.asdict(self).items()}


@dataclass(frozen=True)
class WritePlan:
    """One parameter write, resolved once and checked once (Parameters.plan): Parameters.execute
    writes it without resolving or checking again."""
    code: str                      # the code as given (stripped)
    info: ParamInfo                # how the family addresses it (Drive.param_info, with its ref)
    value: float | int             # the value to write (parsed from `text` when typed)
    text: str                      # the value as given
    danger: str | None             # what writing it does when the profile marks it dangerous
    allowed: bool                  # allow_dangerous was given (a dangerous plan exists only then)
    stop_only: bool                # may only be written while the motor is stopped

    @property
    def dangerous(self) -> bool:
        return self.danger is not None


class _Fmax(Protocol):
    @property
    def fmax_hz(self) -> float: ...


class Host(StationView, Protocol):
    """The station Parameters works on (session.DriveStation): its face and its Motion's max
    frequency."""

    @property
    def motion(self) -> _Fmax: ...


class ParamView(Protocol):
    """What backup.py (dump, compare) and restore.py use of Parameters (session/parameters.py)."""

    @property
    def profile(self) -> Profile: ...

    @property
    def address(self) -> int | None: ...

    @property
    def ident(self) -> int | None: ...

    @property
    def layout(self) -> str | None: ...

    @property
    def port(self) -> str: ...

    def need_drive(self) -> Drive: ...

    def warn(self, text: str) -> None: ...

    def info(self, code: str) -> ParamInfo: ...

    def danger_of(self, info: ParamInfo) -> str | None: ...

    def plan(self, code: str | ParamInfo, value: str | float | int, *,
             allow_dangerous: bool = False) -> WritePlan: ...

    def execute(self, plan: WritePlan, *, check_running: bool = True) -> ParamValue: ...


    def compare(self, doc: dict[str, Any], progress: Callable[[int, int, str], None] | None = None,
                allow_dangerous: bool = False, check_identity: bool = True) -> list[ParamRow]: ...
