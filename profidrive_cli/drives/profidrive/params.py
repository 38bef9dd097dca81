"""PROFIdrive parameter addressing and formatting: code -> PNU/subindex (ParamRef), value text.

Resolves a native code ("F26"), a code with an index ("PNU947[9]") or a raw "PNU<n>[<ind>]" against
the profile's parameters and the card config (array PNUs). Reads the profile only; no bus.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import TYPE_CHECKING

from profidrive_cli import UsageError
from profidrive_cli.drives.profidrive.config import ProfidriveConfig, config
from profidrive_cli.drives.profile import per_profile

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.drives.profile import ParamDef, Profile

_RAW_RE = re.compile(r"^PNU\s*(0x[0-9a-f]+|\d+)\s*(?:\[\s*(0x[0-9a-f]+|\d+)\s*\])?$", re.I)
_CODE_IND_RE = re.compile(r"^(.+?)\s*\[\s*(0x[0-9a-f]+|\d+)\s*\]$", re.I)


@dataclass
class ParamRef:
    """Where a parameter lives on the PKW channel."""
    code: str
    name: str
    pnu: int
    subindex: int = 0
    array: bool = False
    size: int = 16                  # 16 or 32 bits (selects the word / long-word AK)
    param: ParamDef | None = None   # the profile's ParamDef, when known

    @property
    def label(self) -> str:
        return f"{self.code} ({self.name})" if self.name else self.code


def _build_param_index(profile: Profile) -> dict[tuple[int, int | None], ParamDef]:
    idx: dict[tuple[int, int | None], ParamDef] = {}
    for p in profile.parameters.values():
        if p.pnu is not None:
            idx.setdefault((p.pnu, p.index), p)
    return idx


_param_index = per_profile(_build_param_index)


def param_index(profile: Profile) -> dict[tuple[int, int | None], ParamDef]:
    """(pnu, index) -> ParamDef, cached per profile."""
    return _param_index(profile)


def param_for(profile: Profile, pnu: int, subindex: int = 0) -> ParamDef | None:
    """The profile's ParamDef at PNU/subindex (function-code style first, then the whole PNU)."""
    idx = param_index(profile)
    return idx.get((pnu, subindex)) or idx.get((pnu, None)) or (idx.get((pnu, 0)) if subindex == 0
                                                                 else None)


def resolve_code(profile: Profile, code: str, cfg: ProfidriveConfig | None = None) -> ParamRef:
    """Native code ("F002", "A004"), code with index ("PNU947[9]") or raw "PNU<n>[<ind>]"."""
    cfg = cfg or config(profile)
    text = code.strip()
    p = profile.param(text)
    sub = None
    if p is None:
        m = _CODE_IND_RE.match(text)
        if m and profile.param(m.group(1)) is not None:
            p = profile.param(m.group(1))
            sub = int(m.group(2), 0)
    if p is not None:
        if p.pnu is None:
            raise UsageError(f"{p.code}: no PNU in profile {profile.name}")
        array = p.pnu in cfg.array_pnus or bool(p.extra.get("array"))
        if sub is None:
            sub = p.index or 0
            if array and p.index is None:
                sub = 1
        return ParamRef(p.code, p.name, p.pnu, sub, array, p.size, p)
    m = _RAW_RE.match(text)
    if not m:
        raise UsageError(f"unknown parameter '{code}' in profile {profile.name} "
                         f"(use a code such as {next(iter(profile.parameters), 'F03')} or PNU<n>[<ind>])")
    pnu = int(m.group(1), 0)
    sub = int(m.group(2), 0) if m.group(2) is not None else 0
    # PKW's PKE holds 11 bits of PNU; DS47 (a `dpv1:` card) a whole word
    top = 0xFFFF if cfg.dpv1 is not None else 0x7FF
    if not 0 < pnu <= top or not 0 <= sub <= 255:
        raise UsageError(f"{code}: PNU must be 1..{top} and subindex 0..255")
    p = param_for(profile, pnu, sub)
    array = pnu in cfg.array_pnus or bool(p is not None and p.extra.get("array"))
    if p is not None:
        return ParamRef(p.code, p.name, pnu, sub, array, p.size, p)
    return ParamRef(f"PNU{pnu}" + (f"[{sub}]" if sub else ""), "", pnu, sub, array, 16, None)


def decimals_for(scale: float) -> int:
    if not scale or float(scale).is_integer():
        return 0
    return max(0, min(6, -math.floor(math.log10(abs(scale)) + 1e-9)))


def format_value(param: ParamDef | None, value: object, raw: int | None = None) -> str:
    """Engineering value with the parameter's resolution and unit ("4.00 s", "0x1F", "2")."""
    if param is None:
        return str(value)
    fmt = param.extra.get("format")
    if fmt in ("hex", "bits") and raw is not None:
        return f"0x{raw:X}"
    d = decimals_for(param.scale)
    text = f"{value:.{d}f}" if isinstance(value, float) or d else str(value)
    return f"{text} {param.unit}" if param.unit else text
