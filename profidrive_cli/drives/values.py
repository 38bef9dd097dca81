"""Exact values and dangerous parameters: the one check every write path uses.

`value_problem(p, value)` says why a parameter cannot hold a value exactly (None when it can):

  * not a number, NaN or infinite, a bool;
  * not a whole multiple of the parameter's resolution (its `scale`, the wire step). Compared in exact
    decimal arithmetic (the value's shortest decimal text over the step's), with a tolerance of 1e-9
    of a step for float noise — never a bare round: F07 = 0.05 s with a 0.1 s step is refused, 2.55 s
    is refused, 2.5 s and 0.30000000000000004 s are accepted;
  * a non-integer for a code / integer parameter (scale 1: o27 = 10.7 is refused);
  * outside min..max, outside the Moeller-style `ranges` list, not one of the listed `values:` codes;
  * a wire value that does not fit the parameter's width (16 or 32 bits, signed or not).

The message names the parameter, the value with its unit, and the nearest values it can hold
("F07 = 0.05 s cannot be held exactly: resolution 0.1 s; nearest 0 s or 0.1 s").

`danger(p)` is the profile's `danger:` text for a parameter marked `dangerous: true` (None otherwise):
such a parameter is written only on an explicit --allow-dangerous / `allow_dangerous: true`.
"""

from __future__ import annotations

import math
import re
from decimal import Decimal, InvalidOperation
from fractions import Fraction
from typing import TYPE_CHECKING, Sequence, Union

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import ParamDef, Profile

#: a number value_problem reads exactly
Number = Union[float, Fraction, Decimal]
#: allowed intervals (None: unbounded on that side)
Ranges = Sequence[tuple[Union[Fraction, None], Union[Fraction, None]]]

NOISE = Fraction(1, 10**9)        # of one resolution step


def _frac(x: Number) -> Fraction:
    if isinstance(x, Fraction):
        return x
    if isinstance(x, int):
        return Fraction(x)
    return Fraction(Decimal(repr(float(x))))


def _num(f: Fraction) -> str:
    """A Fraction as short decimal text (values here are multiples of decimal steps)."""
    if f.denominator == 1:
        return str(f.numerator)
    try:
        return f"{float(f):.10g}"
    except OverflowError:
        return str(f)


def _u(p: ParamDef) -> str:
    return f" {p.unit}" if getattr(p, "unit", "") else ""


def _step(p: ParamDef, scale: float | None = None) -> Fraction | None:
    sc = p.scale if scale is None else scale
    if not sc:
        return None
    return abs(_frac(sc))


def code_values(p: ParamDef) -> list[tuple[int, int]] | None:
    """The listed codes of a parameter (`values: {0: ..., 2-39: ...}`) as (low, high) ranges."""
    vals = p.extra.get("values")
    if not isinstance(vals, dict) or not vals:
        return None
    out: list[tuple[int, int]] = []
    for k in vals:
        if isinstance(k, int) and not isinstance(k, bool):
            out.append((k, k))
            continue
        m = re.fullmatch(r"\s*(-?\d+)\s*-\s*(-?\d+)\s*", str(k))
        if m:
            out.append((int(m.group(1)), int(m.group(2))))
        elif str(k).strip().lstrip("-").isdigit():
            out.append((int(k), int(k)))
    return sorted(out) or None


def _ranges(p: ParamDef) -> Ranges | None:
    """Allowed intervals: `values` codes, else `ranges`, else min..max (None: unbounded)."""
    cv = code_values(p)
    if cv:
        rg = [(Fraction(lo), Fraction(hi)) for lo, hi in cv]
        if p.min is not None or p.max is not None:      # min/max still bound the listed codes
            lo_b = _frac(p.min) if p.min is not None else None
            hi_b = _frac(p.max) if p.max is not None else None
            rg = [(max(lo, lo_b) if lo_b is not None else lo, min(hi, hi_b) if hi_b is not None else hi)
                  for lo, hi in rg]
            rg = [(lo, hi) for lo, hi in rg if lo <= hi]
        return rg
    listed = p.extra.get("ranges")
    if isinstance(listed, list) and listed:
        return [(_frac(lo), _frac(hi)) for lo, hi in listed]
    if p.min is None and p.max is None:
        return None
    return [(_frac(p.min) if p.min is not None else None, _frac(p.max) if p.max is not None else None)]


def _wire_bounds(p: ParamDef, step: Fraction | None) -> tuple[Fraction, Fraction] | None:
    bits = 8 * int(p.extra.get("bytes", 0)) if isinstance(p.extra.get("bytes"), int) else int(p.size or 16)
    if step is None:
        return None
    if p.signed:
        lo, hi = -(1 << (bits - 1)), (1 << (bits - 1)) - 1
    else:
        lo, hi = 0, (1 << bits) - 1
    return Fraction(lo) * step, Fraction(hi) * step


def _inside(v: Fraction, rg: Ranges) -> bool:
    return any((lo is None or v >= lo) and (hi is None or v <= hi) for lo, hi in rg)


def _allowed_text(p: ParamDef, rg: Ranges) -> str:
    parts: list[str] = []
    for lo, hi in rg:
        if lo is not None and hi is not None and lo == hi:
            parts.append(_num(lo))
        else:
            parts.append(f"{'-inf' if lo is None else _num(lo)}..{'inf' if hi is None else _num(hi)}")
    return ", ".join(parts)


def _snap_down(x: Fraction, step: Fraction) -> Fraction:
    return math.floor(x / step) * step


def _snap_up(x: Fraction, step: Fraction) -> Fraction:
    return math.ceil(x / step) * step


def nearest_valid(p: ParamDef, v: Fraction, scale: float | None = None) -> list[Fraction]:
    """The valid values just below and just above v (one or two, ascending)."""
    step = _step(p, scale) or Fraction(1)
    rg = _ranges(p) or [(None, None)]
    wb = _wire_bounds(p, _step(p, scale))
    cands: set[Fraction] = set()
    for lo, hi in rg:
        if wb is not None:
            lo = wb[0] if lo is None else max(lo, wb[0])
            hi = wb[1] if hi is None else min(hi, wb[1])
        lo_s = _snap_up(lo, step) if lo is not None else None
        hi_s = _snap_down(hi, step) if hi is not None else None
        if lo_s is not None and hi_s is not None and lo_s > hi_s:
            continue
        down, up = _snap_down(v, step), _snap_up(v, step)
        for c in (down, up, lo_s, hi_s):
            if c is None:
                continue
            if (lo_s is None or c >= lo_s) and (hi_s is None or c <= hi_s):
                cands.add(c)
    below = [c for c in cands if c <= v]
    above = [c for c in cands if c >= v]
    out: list[Fraction] = []
    if below:
        out.append(max(below))
    if above and (not out or min(above) != out[0]):
        out.append(min(above))
    return out


def _nearest_words(p: ParamDef, v: Fraction, scale: float | None = None) -> str:
    near = nearest_valid(p, v, scale)
    if not near:
        return ""
    return "; nearest " + " or ".join(f"{_num(c)}{_u(p)}" for c in near)


def value_problem(p: ParamDef, value: object, scale: float | None = None, label: str | None = None
                  ) -> str | None:
    """None when parameter `p` (a profile ParamDef) can hold `value` exactly, else one line saying why
    with the nearest values it can hold. `scale` overrides p.scale (Toyo 400 V class)."""
    what = label or p.code
    if isinstance(value, bool) or not isinstance(value, (int, float, Fraction, Decimal)):
        return f"{what} ({p.name}): {value!r} is not a number"
    if isinstance(value, float) and not math.isfinite(value):
        return f"{what} ({p.name}): {value!r} is not a value a parameter can hold"
    try:
        v = _frac(value)
    except (InvalidOperation, ValueError, OverflowError):
        return f"{what} ({p.name}): {value!r} is not a number"
    shown = f"{what} = {_num(v)}{_u(p)}"
    step = _step(p, scale)
    if step is not None:
        q = v / step
        n = round(q)
        if abs(q - n) > NOISE:
            if step == 1:
                return (f"{shown} cannot be held exactly: {what} takes whole numbers only"
                        + _nearest_words(p, v, scale))
            return (f"{shown} cannot be held exactly: resolution {_num(step)}{_u(p)}"
                    + _nearest_words(p, v, scale))
        v = n * step
    rg = _ranges(p)
    if rg is not None and not _inside(v, rg):
        kind = "is not one of its codes" if code_values(p) else "is outside"
        return f"{what} ({p.name}): {_num(v)}{_u(p)} {kind} {_allowed_text(p, rg)}{_u(p)}" \
            + _nearest_words(p, v, scale)
    wb = _wire_bounds(p, step)
    if wb is not None and not (wb[0] <= v <= wb[1]):
        return (f"{what} ({p.name}): {_num(v)}{_u(p)} does not fit the parameter's "
                f"{'signed ' if p.signed else ''}wire word ({_num(wb[0])}..{_num(wb[1])}{_u(p)})"
                + _nearest_words(p, v, scale))
    return None


def profile_value_problem(profile: Profile, p: ParamDef, value: object) -> str | None:
    """value_problem() with the scale the family uses for this profile (Toyo: the 400 V class scale):
    for checks made from the profile alone, before a drive is connected (checklist validate, the
    prompt of param set)."""
    from profidrive_cli.drives import codec_module
    # a family whose wire scale depends on the drive's settings says so (Toyo: the 400 V class)
    hook = getattr(codec_module(profile), "effective_scale", None)
    return value_problem(p, value, scale=hook(profile, p) if hook else None)


def raw_value_problem(label: str, value: object, bits: int = 16) -> str | None:
    """For raw PNU / register access (no profile entry): a whole number that fits `bits` (a negative
    number is taken as two's complement)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            (isinstance(value, float) and not math.isfinite(value)):
        return f"{label}: {value!r} is not a value a parameter can hold"
    v = _frac(value)
    if v.denominator != 1:
        return (f"{label} = {_num(v)} cannot be held exactly: raw values are whole numbers; nearest "
                f"{math.floor(v)} or {math.ceil(v)}")
    if not -(1 << (bits - 1)) <= v < (1 << bits):
        return f"{label}: {_num(v)} does not fit {bits} bits"
    return None


def exact_raw(p: ParamDef, value: Number, scale: float | None = None) -> int:
    """The wire integer of a value value_problem() accepted (exact: no rounding beyond float noise)."""
    step = _step(p, scale)
    if step is None:
        return int(value)
    return int(round(_frac(value) / step))


# -- dangerous parameters ------------------------------------------------------------------------

DEFAULT_DANGER = "initialises data or runs the motor on its own (marked dangerous in the profile)"


def is_dangerous(p: ParamDef | None) -> bool:
    return p is not None and bool(p.extra.get("dangerous"))


def danger(p: ParamDef | None) -> str | None:
    """What writing `p` does, in words, when the profile marks it dangerous; None otherwise."""
    if p is None or not is_dangerous(p):
        return None
    text = p.extra.get("danger")
    return str(text) if text else DEFAULT_DANGER
