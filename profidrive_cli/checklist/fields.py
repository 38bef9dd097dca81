"""The checklist's field toolkit: what every step type's schema check is built from.

FieldChecker collects problems with file:line (err, fail) and reads a step's fields (fields, num,
code_field, need_param_channel, need_capability: the profile's capabilities); ParamTarget is a
parameter resolved for one station's profile. It knows the YAML shape (datafile.LineDict / LineList)
and the profiles (drives/), nothing of stations on a bus, of the checklist header (spec.py) or of
running (runner.py). spec.py's validator is a FieldChecker; each step
type in checklist/steps/ gets it to check its own fields.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, NoReturn, Protocol, Sequence, TypeGuard, overload

from profidrive_cli import PdriveError, UsageError
from profidrive_cli.datafile import DataFileError, LineDict, LineList

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.drives.profile import ParamDef, Profile


def tname(v: object) -> str:
    if isinstance(v, bool):
        return "true/false"
    if isinstance(v, (int, float)):
        return "a number"
    if isinstance(v, str):
        return "text"
    if isinstance(v, list):
        return "a list"
    if isinstance(v, dict):
        return "a mapping"
    if v is None:
        return "nothing"
    return type(v).__name__


def is_num(v: object) -> TypeGuard[float]:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def fmt(v: object) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def line_at(node: object, key: object = None, default: int = 0) -> int:
    if key is not None and isinstance(node, LineDict):
        return node.line_of(key)
    if key is not None and isinstance(node, LineList) and isinstance(key, int):
        return node.line_of(key)
    line: int | None = getattr(node, "line", default)     # LineDict / LineList: int
    return line or default


# What a step type's check gets of spec.py (which imports the step types, so they cannot import it):
# spec.Step, spec.StationSpec and spec._RawStep satisfy these.

#: a step's typed fields (validate's args, spec.Step.args): field name -> value (ParamTarget, number, ...)
StepArgs = dict[str, Any]


class StepFacts(Protocol):
    """spec.Step: one step as it runs on one station."""
    @property
    def index(self) -> int: ...
    @property
    def type(self) -> str: ...
    @property
    def args(self) -> StepArgs: ...


class StationFacts(Protocol):
    """spec.StationSpec: the station a step is validated for and runs on."""
    @property
    def name(self) -> str: ...
    @property
    def address(self) -> int: ...
    @property
    def profile(self) -> Profile: ...
    @property
    def ident(self) -> int: ...
    @property
    def gsd(self) -> str | None: ...
    @property
    def layout(self) -> str: ...
    @property
    def flag_names(self) -> list[str]: ...
    @property
    def steps(self) -> Sequence[StepFacts]: ...


class RawStepFacts(Protocol):
    """spec._RawStep: the step as written (before a station's variables and checks)."""
    @property
    def index(self) -> int: ...
    @property
    def type(self) -> str: ...
    @property
    def line(self) -> int: ...
    @property
    def body_line(self) -> int: ...
    @property
    def stations(self) -> list[tuple[str, int]] | None: ...


class Skip(Exception):
    """Abandon the current item (its error is already recorded)."""


@dataclass
class ParamTarget:
    """A parameter a step reads or writes, resolved for one station's profile."""
    code: str                      # as the checklist wrote it (after variables)
    label: str                     # canonical code for the family ("F07", "PNU947[9]", "REG0x0180")
    param: ParamDef | None = None  # the profile's, None for raw addresses
    unit: str = ""

    @property
    def step_tolerance(self) -> float:
        """Half a wire step: what a read-back may differ by after scaling."""
        if self.param is not None and self.param.scale:
            return abs(float(self.param.scale)) / 2 + 1e-9
        return 1e-9


class FieldChecker:
    """Problems with file:line, collected once each; the step field readers every step type uses."""

    def __init__(self, path: Path):
        self.path = path
        self.errors: list[DataFileError] = []
        self._seen: set[tuple[int | None, str]] = set()

    def err(self, line: int | None, msg: str) -> None:
        key = (line, msg)
        if key not in self._seen:           # the same problem found for several stations: once
            self._seen.add(key)
            self.errors.append(DataFileError(self.path, line, msg))

    def fail(self, line: int | None, msg: str) -> NoReturn:
        self.err(line, msg)
        raise Skip()

    def unknown_key(self, k: object, known: Sequence[str], what: str) -> str:
        close = difflib.get_close_matches(str(k), list(known), 1)
        return f"unknown {what} {k!r}" + (f" (did you mean {close[0]}?)" if close else
                                          f" (known: {', '.join(known)})")

    def param(self, st: StationFacts, code: str, line: int, where: str) -> ParamTarget:
        try:
            label, p = resolve_param(st.profile, code)
        except PdriveError as e:
            self.fail(line, f"{where}: {e} (station {st.name!r})")
        return ParamTarget(code=code, label=label, param=p, unit=(p.unit if p is not None else ""))

    def fields(self, rs: RawStepFacts, body: Any, allowed: tuple[str, ...], shorthand: str | None = None,
               required: tuple[str, ...] = ()) -> LineDict:
        """The step's mapping (or its shorthand scalar as `shorthand: value`), unknown keys rejected."""
        w = f"step {rs.index} ({rs.type})"
        if body is None:
            d = LineDict()
            d.line, d.key_lines = rs.body_line, {}
        elif isinstance(body, LineDict):
            d = body
        elif shorthand is not None and not isinstance(body, (list, dict)):
            d = LineDict({shorthand: body})
            d.line, d.key_lines = rs.body_line, {shorthand: rs.body_line}
        else:
            self.fail(rs.body_line, f"{w}: expected a mapping with {', '.join(allowed) or 'no fields'}, "
                      f"got {tname(body)}")
        bad = False
        for k in d:
            if k not in allowed:
                self.err(d.line_of(k), f"{w}: " + self.unknown_key(k, allowed, "field") if allowed else
                         f"{w}: takes no fields, got {k!r}")
                bad = True
        for k in required:
            if k not in d:
                self.err(rs.body_line, f"{w}: missing field '{k}'")
                bad = True
        if bad:
            raise Skip()
        return d

    @overload
    def num(self, rs: RawStepFacts, d: LineDict, key: str, default: float, minimum: float | None = None,
            positive: bool = False, required: bool = False) -> float: ...

    @overload
    def num(self, rs: RawStepFacts, d: LineDict, key: str, default: None = None, minimum: float | None = None,
            positive: bool = False, *, required: Literal[True]) -> float: ...

    @overload
    def num(self, rs: RawStepFacts, d: LineDict, key: str, default: None = None, minimum: float | None = None,
            positive: bool = False, required: bool = False) -> float | None: ...

    def num(self, rs: RawStepFacts, d: LineDict, key: str, default: float | None = None,
            minimum: float | None = None, positive: bool = False, required: bool = False) -> float | None:
        """The number d[key] (int or float, checked), else `default` (None: not given)."""
        w = f"step {rs.index} ({rs.type})"
        if key not in d:
            if required:
                self.fail(d.line or rs.body_line, f"{w}: missing field '{key}'")
            return default
        v = d[key]
        if not is_num(v):
            self.fail(d.line_of(key), f"{w}: '{key}' must be a number, got {tname(v)} {v!r}")
        if minimum is not None and v < minimum:
            self.fail(d.line_of(key), f"{w}: '{key}' must be at least {fmt(minimum)}, got {fmt(v)}")
        if positive and v <= 0:
            self.fail(d.line_of(key), f"{w}: '{key}' must be above 0, got {fmt(v)}")
        return v

    def code_field(self, st: StationFacts, rs: RawStepFacts, d: LineDict, key: str = "param") -> ParamTarget:
        v = d[key]
        if not isinstance(v, (str, int)) or isinstance(v, bool):
            self.fail(d.line_of(key), f"step {rs.index} ({rs.type}): '{key}' must be a parameter code, "
                      f"got {tname(v)}")
        return self.param(st, str(v), d.line_of(key), f"step {rs.index} ({rs.type})")

    def need_param_channel(self, st: StationFacts, rs: RawStepFacts) -> None:
        """Fail the step when the station's layout has no parameter channel (PKW / handshake)."""
        if not layout_has_params(st.profile, st.layout):
            self.fail(rs.line, f"step {rs.index} ({rs.type}): station {st.name!r} uses layout {st.layout}, "
                      f"which has no parameter channel (choose a layout with one, e.g. "
                      f"{param_layouts(st.profile)})")


    def need_capability(self, st: StationFacts, rs: RawStepFacts, name: str, line: int | None = None) -> bool:
        """Fail the step when the station's card cannot do `name` on its layout (the profile's
        `capabilities:`), in the words the CLI and the drive use; True when it can."""
        caps = st.profile.capabilities
        assert caps is not None                 # every loaded profile has them (parse_capabilities)
        msg = caps.refusal(name, st.layout)
        if msg is None:
            return True
        self.fail(line or rs.line, f"step {rs.index} ({rs.type}): station {st.name!r}: {msg}")
        return False


def resolve_param(profile: Profile, code: str) -> tuple[str, ParamDef | None]:
    """(canonical label, ParamDef or None for a raw address) for `code` in this profile's family, the way
    the family's Drive resolves it; UsageError naming the closest codes when it is unknown."""
    from profidrive_cli.drives import drive_class
    text = str(code).strip()
    try:
        found: tuple[str, ParamDef | None] = drive_class(profile).param_label_for(profile, text)  # a class fact
        return found                                                    # (no Drive built)
    except UsageError as e:
        msg = str(e)
        if "unknown" in msg.lower():
            from profidrive_cli.drives.profile import foreign_profiles_with_code
            from profidrive_cli.api.station import suggest_codes
            others = sorted({p.family for p in foreign_profiles_with_code(text, profile)})
            near = suggest_codes(profile, text, 3)
            msg = f"unknown parameter '{text}' for {profile.name}"
            if others:
                msg += f" ({text} is a {'/'.join(others)} code; this station is family {profile.family})"
            if near:
                msg += f"; closest {profile.family} codes: {', '.join(near)}"
        raise UsageError(msg) from None


def range_problem(p: ParamDef, value: float) -> str | None:
    """The profile's limits for a value (Moeller-style `ranges` lists first), None when inside."""
    rg = p.extra.get("ranges")
    u = f" {p.unit}" if p.unit else ""
    if rg:
        if any(lo - 1e-9 <= value <= hi + 1e-9 for lo, hi in rg):
            return None
        allowed = ", ".join(f"{lo:g}..{hi:g}" if lo != hi else f"{lo:g}" for lo, hi in rg)
        return f"{p.code} ({p.name}): {value:g}{u} is outside {allowed}{u}"
    lo = p.min - 1e-9 if p.min is not None else None
    hi = p.max + 1e-9 if p.max is not None else None
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        return (f"{p.code} ({p.name}): {value:g}{u} is outside "
                f"{'-inf' if p.min is None else f'{p.min:g}'}..{'inf' if p.max is None else f'{p.max:g}'}{u}")
    return None


def layout_has_params(profile: Profile, layout: str) -> bool:
    return bool(profile.layouts[layout].pkw)


def param_layouts(profile: Profile) -> str:
    return ", ".join(n for n, l in profile.layouts.items() if l.pkw) or "none"

