"""PROFIdrive N2 scaling: 0x4000 = 100 %, two's complement for reverse; percent and Hz.

Pure arithmetic on 16-bit words; knows nothing of profiles or the bus.
"""

from __future__ import annotations

import math

N2_FULL = 0x4000  # = 100 %


def to_signed16(word: int) -> int:
    word &= 0xFFFF
    return word - 0x10000 if word & 0x8000 else word


def n2_to_percent(word: int) -> float:
    return to_signed16(word) * 100.0 / N2_FULL


def n2_from_percent(pct: float) -> int:
    """Percent -> N2 word (two's complement), rounded, clamped to -200 % .. +199.99 %."""
    if math.isnan(pct):
        raise ValueError("reference is NaN")
    raw = round(pct * N2_FULL / 100.0)
    raw = max(-0x8000, min(0x7FFF, raw))
    return raw & 0xFFFF


def n2_to_hz(word: int, fmax: float) -> float:
    return to_signed16(word) * fmax / N2_FULL


def n2_from_hz(hz: float, fmax: float) -> int:
    if fmax <= 0:
        raise ValueError(f"max frequency must be > 0, got {fmax}")
    return n2_from_percent(100.0 * hz / fmax)
