"""Fuji value texts for the profile's `format:` names fcode, alarm, alarm947 and baud (drives/formats.py
finds them as FORMATTERS through the family module). Pure functions of the profile; no bus."""

from __future__ import annotations

from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.formats import hex_word
from profidrive_cli.drives.fuji.codes import alarm_by_mcode, alarm_text, pcd_assignment_code


def fcode_text(profile, param, raw, value) -> str:
    """o40-o43 / o48-o51 / PNU915-916: group << 8 | number in four hex digits and the function code
    (fuji-opc-g1-pdp.md L243: "F26 -> group F = 0x04, number 26 = 0x1A, giving assignment 041A")."""
    w = raw & 0xFFFF
    if w == 0:
        return "0x0000 (not assigned)"
    return f"{hex_word(param, w)} ({pcd_assignment_code(profile, w) or 'no such function code'})"


def alarm_code_text(profile, param, raw, value) -> str:
    """M16-M19: the inverter alarm code in decimal (fuji-opc-g1-pdp.md L603, L611-616: 1 = OC1)."""
    if raw == 0:
        return "0 (no alarm)"
    a = alarm_by_mcode(profile, raw)
    return f"{raw} ({a.code} {a.meaning})" if a else f"{raw} (alarm code not in the manual's table)"


def alarm947_text(profile, param, raw, value) -> str:
    """PNU947: the PROFIdrive malfunction code in hex and every alarm it can stand for (L657)."""
    w = raw & 0xFFFF
    return f"0x{w:04X} ({alarm_text(profile, w)})"


def baud_text(profile, param, raw, value) -> str:
    """PNU963: the card's code and its rate (fuji-opc-g1-pdp.md L579-591: 10 = 12M)."""
    return f"{raw} ({pd.config(profile).baud_codes.get(raw, 'not in the manual table')})"


FORMATTERS = {"fcode": fcode_text, "alarm": alarm_code_text, "alarm947": alarm947_text, "baud": baud_text}
