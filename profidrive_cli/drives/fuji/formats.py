"""Fuji value texts for the profile's `format:` names fcode, alarm, alarm947 and baud (drives/formats.py
finds them as FORMATTERS through the family module). Pure functions of the profile; no bus."""

from __future__ import annotations

import difflib
import re
from typing import TYPE_CHECKING

from profidrive_cli import UsageError
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.formats import hex_word
from profidrive_cli.drives.fuji.codes import (alarm_by_mcode, alarm_text, parse_function_code,
                                              pcd_assignment_code)

if TYPE_CHECKING:
    from profidrive_cli.drives.formats import Formatter, Parser
    from profidrive_cli.drives.profile import ParamDef, Profile


def fcode_text(profile: Profile, param: ParamDef, raw: int, value: object) -> str:
    """o40-o43 / o48-o51 / PNU915-916: group << 8 | number in four hex digits and the function code
    (fuji-opc-g1-pdp.md L243: "F26 -> group F = 0x04, number 26 = 0x1A, giving assignment 041A")."""
    w = raw & 0xFFFF
    if w == 0:
        return "0x0000 (not assigned)"
    return f"{hex_word(param, w)} ({pcd_assignment_code(profile, w) or 'no such function code'})"


def alarm_code_text(profile: Profile, param: ParamDef, raw: int, value: object) -> str:
    """M16-M19: the inverter alarm code in decimal (fuji-opc-g1-pdp.md L603, L611-616: 1 = OC1)."""
    if raw == 0:
        return "0 (no alarm)"
    a = alarm_by_mcode(profile, raw)
    return f"{raw} ({a.code} {a.meaning})" if a else f"{raw} (alarm code not in the manual's table)"


def alarm947_text(profile: Profile, param: ParamDef, raw: int, value: object) -> str:
    """PNU947: the PROFIdrive malfunction code in hex and every alarm it can stand for (L657)."""
    w = raw & 0xFFFF
    return f"0x{w:04X} ({alarm_text(profile, w)})"


def baud_text(profile: Profile, param: ParamDef, raw: int, value: object) -> str:
    """PNU963: the card's code and its rate (fuji-opc-g1-pdp.md L579-591: 10 = 12M)."""
    return f"{raw} ({pd.config(profile).baud_codes.get(raw, 'not in the manual table')})"


def fcode_value(profile: Profile, param: ParamDef, text: str) -> int:
    """A typed o40-o51 / PNU915-916 value -> the assignment word. Accepted as the manual writes it
    (G1 manual 001_02ee17c3305f1f71.txt L2440-2453: "F => Function code group 04hex", "26 Function code
    number 1Ahex", "041A"): four hex digits (041A), 0x041A, the function code itself (F26), or 0 (not
    assigned). Anything else, or a word naming no function-code group: UsageError with the forms."""
    t = text.strip()
    example = "041A or 0x041A (F26)"
    m = re.fullmatch(r"(0[xX])?([0-9A-Fa-f]{1,4})", t)
    if t == "0":
        return 0
    if m and (m.group(1) or len(m.group(2)) == 4):
        w = int(m.group(2), 16)
        hx = pcd_assignment_code(profile, w) if w else None
        dec = pcd_assignment_code(profile, int(t)) if not m.group(1) and t.isdigit() and int(t) != w else None
        as_dec = f"0x{int(t):04X} / {dec}" if dec else ""
        if w and hx is None:
            raise UsageError(f"{param.code}: {hex_word(param, w)} names no function code (group "
                             f"0x{w >> 8:02X} is not one of {profile.name}'s); write the assignment as the "
                             f"manual does: {example}, or the code: F26; 0 = not assigned"
                             + (f" (as a decimal number {t} is {as_dec})" if dec else ""))
        if dec:                                 # "1050": hex 0x1050 (W80) or decimal = 0x041A (F26)?
            raise UsageError(f"{param.code}: {t!r} reads two ways: as the manual writes assignments (hex) "
                             f"0x{w:04X} ({hx}), as a decimal number 0x{int(t):04X} ({dec}); write "
                             f"0x{w:04X} or {as_dec}")
        return w
    r = parse_function_code(profile, t)
    if r is not None:
        return r[1] << 8 | r[3]
    near = difflib.get_close_matches(t.upper(), [c.upper() for c in profile.parameters], n=3, cutoff=0.6)
    near = [next(c for c in profile.parameters if c.upper() == n) for n in near]
    raise UsageError(f"{param.code}: expected a function code (F26) or its assignment word as the manual "
                     f"writes it ({example}; 0 = not assigned), got {t!r}"
                     + (f" (closest codes: {', '.join(near)})" if near else ""))


#: the typed text -> raw word, per `format:` (drives/formats.py value_from_text)
PARSERS: dict[str, Parser] = {"fcode": fcode_value}

FORMATTERS: dict[str, Formatter] = {"fcode": fcode_text, "alarm": alarm_code_text,
                                    "alarm947": alarm947_text, "baud": baud_text}
