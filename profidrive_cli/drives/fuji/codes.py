"""Fuji dialect lookups: function codes <-> PNU/subindex, PCD assignment words, alarms and M-codes,
o30 PPO selection, o27/o28 communication-loss actions, the decoder's value hook.

Pure functions of the profile and its FujiConfig (drives/fuji/config.py); no bus, no drive.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

from profidrive_cli import UsageError
from profidrive_cli.drives.fuji.config import CommLossAction, fuji_config

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import Alarm, ParamDef, Profile

# =============================================================================================
# function codes
# =============================================================================================

def parse_function_code(profile: Profile, text: str) -> tuple[str, int, int, int] | None:
    """'F26' -> ('F26', group code 4, pnu 0x104, subindex 26); None when it is not a function code.

    Group letters match in any case ('Y98' = 'y98'). A two-character group (W1, J1, o1, ...) wins when
    exactly two digits follow ('J101' = J1 number 1); otherwise one letter and 1..3 digits ('y100').
    """
    fc = fuji_config(profile)
    t = text.strip()
    low = fc.by_lower
    m = re.fullmatch(r"([A-Za-z])([A-Za-z0-9]?)(\d+)", t)
    if not m:
        return None
    g2 = (m.group(1) + m.group(2)).lower()
    digits = m.group(3)
    if m.group(2) and m.group(2).isdigit():
        # letter + digit + digits: could be a two-character group or a one-letter code
        two = (m.group(1) + m.group(2)).lower()
        if two in low and len(digits) == 2:
            g, num = low[two], int(digits)
        elif m.group(1).lower() in low:
            g, num = low[m.group(1).lower()], int(m.group(2) + digits)
        else:
            return None
    elif m.group(2):
        if g2 not in low:
            return None
        g, num = low[g2], int(digits)
    else:
        if m.group(1).lower() not in low:
            return None
        g, num = low[m.group(1).lower()], int(digits)
    if not 0 <= num <= 255:
        return None
    return f"{g}{num:02d}", fc.groups[g], fc.pnu_base + fc.groups[g], num


def function_code_name(profile: Profile, pnu: int, subindex: int) -> str | None:
    """PNU 0x104, subindex 26 -> 'F26' (None outside the function-code PNUs)."""
    fc = fuji_config(profile)
    code = pnu - fc.pnu_base
    for g, c in fc.groups.items():
        if c == code and 0 <= code <= 0xFF:
            return f"{g}{subindex:02d}"
    return None


def pcd_assignment(profile: Profile, code: str) -> int:
    """The o40-o51 / PNU915/916 word for a function code: group << 8 | number (F26 -> 0x041A)."""
    r = parse_function_code(profile, code)
    if r is None:
        raise UsageError(f"{code} is not a function code of {profile.name}")
    return r[1] << 8 | r[3]


def pcd_assignment_code(profile: Profile, word: int) -> str | None:
    """0x041A -> 'F26'; 0 -> None (not assigned)."""
    if word == 0:
        return None
    fc = fuji_config(profile)
    return function_code_name(profile, fc.pnu_base + (word >> 8), word & 0xFF)


# =============================================================================================
# alarms, PPO selection, communication loss
# =============================================================================================


def alarm_candidates(profile: Profile, number: int) -> list[Alarm]:
    """Every alarm that a PNU947 malfunction code can stand for (several for 0x2212 etc.)."""
    return profile.alarms_for(number)


def alarm_by_mcode(profile: Profile, mcode: int) -> Alarm | None:
    fc = fuji_config(profile)
    for a in profile.alarms:
        if fc.mcodes.get(a.code) == mcode:
            return a
    return None


def mcode_of(profile: Profile, code: str) -> int | None:
    return fuji_config(profile).mcodes.get(code)


def alarm_text(profile: Profile, number: int) -> str:
    if number == 0:
        return "no alarm"
    al = alarm_candidates(profile, number)
    if not al:
        return f"unknown malfunction code 0x{number:04X}"
    txt = " or ".join(f"{a.code} ({a.meaning})" for a in al)
    return txt if len(al) == 1 else f"one of {txt}"


def ppo_for_o30(profile: Profile, value: int) -> str | None:
    for name, vals in fuji_config(profile).ppo_values.items():
        if value in vals:
            return name
    return None


def o30_for_layout(profile: Profile, layout: str) -> int | None:
    vals = fuji_config(profile).ppo_values.get(layout)
    if not vals:
        return None
    n = re.fullmatch(r"ppo(\d)", layout)
    if n and int(n.group(1)) in vals:
        return int(n.group(1))
    return min(vals)


def comm_loss_action(profile: Profile, o27: int) -> CommLossAction:
    for a in fuji_config(profile).comm_loss_actions:
        if o27 in a.values:
            return a
    # outside the table: the factory behaviour (coast and trip)
    return CommLossAction(frozenset({o27}), "coast", False, False, True)


def comm_loss_text(profile: Profile, o27: int, o28: float) -> str:
    fc = fuji_config(profile)
    a = comm_loss_action(profile, o27)
    if a.stop == "none":
        return f"{fc.comm_loss_param} = {o27}: a communication loss is ignored (no {fc.comm_loss_alarm})"
    stop = "coast to a stop" if a.stop == "coast" else f"decelerate with {fc.comm_loss_decel}"
    when = f"after {fc.comm_loss_timer} = {o28:g} s" if a.delayed else "at once"
    rec = (f" unless the link returns within {o28:g} s" if a.recover else "") if a.delayed else ""
    return f"{fc.comm_loss_param} = {o27}: {stop} {when}{rec}, then trip {fc.comm_loss_alarm}"


def param_value(profile: Profile, param: ParamDef, raw: int) -> float | int:
    """Hook used by the core decoder: engineering value of a wire value."""
    return param.from_raw(raw & 0xFFFF)
