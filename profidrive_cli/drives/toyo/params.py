"""Toyo PBUS66-Z parameter access: value scaling (no decimal point on the wire, the 400 V class
scale), PKW frames (IND as one 16-bit word), and addressing: monitor names, console codes, TBnn[r,p]
traceback points, FH[n], PNU<n>[ind] -> ParamRef.

Sans-IO; the request/response exchange itself is the PROFIdrive core's PKW channel. May touch:
drives/profidrive (ParamRef, PkwFrame), config, codec.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

from profidrive_cli import UsageError
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.toyo.codec import traceback_ind
from profidrive_cli.drives.toyo.config import ToyoConfig, toyo_config

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import ParamDef, Profile


def effective_scale(profile: Profile, p: ParamDef) -> float:
    if toyo_config(profile).voltage_class == 400 and "scale_400v" in p.extra:
        return float(p.extra["scale_400v"])
    return p.scale


def value_from_wire(profile: Profile, p: ParamDef, raw: int) -> float | int:
    raw &= 0xFFFF
    if p.signed and raw & 0x8000:
        raw -= 0x10000
    sc = effective_scale(profile, p)
    v = raw * sc
    if float(sc).is_integer():
        return int(round(v))
    return round(v, 6)


def wire_from_value(profile: Profile, p: ParamDef, value: float) -> int:
    """Setting values go without their decimal point (15.0 with scale 0.1 -> 150)."""
    sc = effective_scale(profile, p)
    raw = round(value / sc) if sc else int(value)
    return int(raw) & 0xFFFF


def param_value(profile: Profile, param: ParamDef, raw: int) -> float | int:
    """Hook used by the core decoder."""
    return value_from_wire(profile, param, raw)


def param_at(profile: Profile, pnu: int) -> ParamDef | None:
    for p in profile.parameters.values():
        if p.pnu == pnu:
            return p
    return None


def _toyo_frame(ak: int, pnu: int, ind: int = 0, value: int = 0) -> pd.PkwFrame:
    return pd.PkwFrame(ak, pnu, (ind >> 8) & 0xFF, value & 0xFFFF, ind_low=ind & 0xFF)


_TB_RE = re.compile(r"^TB(\d{1,2})\s*\[\s*(\d)\s*[,:]\s*(\d{1,3})\s*\]$", re.I)


def find_param(profile: Profile, text: str) -> ParamDef | None:
    t = text.strip()
    p = profile.param(t)
    if p is not None:
        return p
    for q in profile.parameters.values():
        if q.code.lower() == t.lower():
            return q
    return None


def resolve_param(profile: Profile, tc: ToyoConfig, code: str) -> pd.ParamRef:
    """Monitor names ('dc-voltage'), console codes ('A-00', needs a pnu in the profile),
    'TB06[1,10]' (traceback: recording 0-3, point 0-99), 'FH[2]' (fault history), 'PNU688',
    'PNU720[3]' (IND word), '688'."""
    t = code.strip()
    m = _TB_RE.match(t)
    if m:
        ch, rec, pt = int(m.group(1)), int(m.group(2)), int(m.group(3))
        if not 0 <= ch < tc.traceback_channels or rec > 3 or pt >= tc.traceback_points:
            raise UsageError(f"{code}: channel 0..{tc.traceback_channels - 1}, recording 0..3, "
                             f"point 0..{tc.traceback_points - 1}")
        p = param_at(profile, tc.traceback_pnu + ch)
        tb_ind = traceback_ind(rec, pt)
        return pd.ParamRef(f"TB{ch:02d}[{rec},{pt}]", p.name if p else "", tc.traceback_pnu + ch,
                           tb_ind, True, 16, p)
    m = re.fullmatch(r"(?i)(?:PNU\s*)?(0x[0-9a-f]+|\d+)(?:\s*\[\s*(0x[0-9a-f]+|\d+)\s*\])?", t)
    base = None
    ind = None
    if m:
        pnu = int(m.group(1), 0)
        ind = int(m.group(2), 0) if m.group(2) is not None else None
        if not 0 < pnu <= 0x7FF:
            raise UsageError(f"{code}: PNU must be 1..2047 (bit 10 = 2nd setting block)")
        p = param_at(profile, pnu)
        base = (pnu, p)
    else:
        m2 = re.fullmatch(r"(.+?)\s*\[\s*(0x[0-9a-f]+|\d+)\s*\]", t, re.I)
        name, ind = (m2.group(1), int(m2.group(2), 0)) if m2 else (t, None)
        p = find_param(profile, name)
        if p is None:
            raise UsageError(f"unknown parameter '{code}' in {profile.name} (monitor names such as "
                             f"dc-voltage, TB06[0,10], FH[1], or PNU<n>)")
        if p.pnu is None:
            raise UsageError(f"{p.code} ({p.name}): Toyo does not publish its PNU; add `pnu:` to the "
                             f"profile (values travel without the decimal point)")
        base = (p.pnu, p)
    pnu, p = base
    sub = pnu == tc.history_pnu or \
        tc.traceback_pnu <= (pnu & 0x3FF) < tc.traceback_pnu + tc.traceback_channels
    if sub and ind is None:
        ind = 1 if pnu == tc.history_pnu else 0
    codename = p.code if p is not None and (pnu & 0x3FF) == p.pnu else f"PNU{pnu}"
    if ind is not None and sub:
        codename += f"[{ind}]"
    return pd.ParamRef(codename, p.name if p is not None else "", pnu, ind or 0, sub, 16, p)


def frame_for(ref: pd.ParamRef, write: bool = False, value: int = 0) -> pd.PkwFrame:
    if write:
        return _toyo_frame(2, ref.pnu, 0, value)
    return _toyo_frame(6 if ref.array else 1, ref.pnu, ref.subindex if ref.array else 0)
