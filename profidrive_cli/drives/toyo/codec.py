"""Toyo PBUS66-Z words: speed words (20000 = A-00), bit tables, the mode-1 run-command word, the
mode-0 control word's meaning, protection codes, the fault-history word and the traceback IND word.

Sans-IO arithmetic over the profile's tables. May touch: drives/profidrive (word helpers), config.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.toyo.config import toyo_config

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import Profile


def speed_word(profile: Profile, percent: float) -> int:
    """Percent of A-00 -> speed word (20000 = 100 %), two's complement, clamped to 16 bits."""
    fs = toyo_config(profile).speed_full_scale
    raw = round(percent * fs / 100.0)
    return max(-0x8000, min(0x7FFF, raw)) & 0xFFFF


def speed_percent(profile: Profile, word: int) -> float:
    return pd.to_signed16(word) * 100.0 / toyo_config(profile).speed_full_scale


def protection(profile: Profile, code: int) -> tuple[str, str]:
    """Protection code -> (short name, meaning)."""
    al = profile.alarms_for(code)
    if al:
        return al[0].code, al[0].meaning
    if code >= 33:
        return f"GAC{code}", f"GAC protection {code} (GAC-equipped models; see the model's manual)"
    return f"?{code}", f"unknown protection code {code}"


def history_word(code: int, mode: int = 0, block: int = 0) -> int:
    return (code & 0xFF) | (mode & 0x3) << 8 | (block & 1) << 12


def decode_history_word(profile: Profile, word: int) -> dict[str, Any]:
    tc = toyo_config(profile)
    code = word & tc.history_code_mask
    mode = (word >> tc.history_mode_shift) & 0x3
    block = (word >> tc.history_block_bit) & 1
    name, meaning = protection(profile, code)
    return {"word": word, "code": code, "name": name, "meaning": meaning, "mode": mode,
            "mode_text": tc.history_modes.get(mode, str(mode)), "block": block + 1,
            "text": f"protection {code} {name} ({meaning}); inverter mode {tc.history_modes.get(mode, mode)}; "
                    f"setting block {block + 1}"}


def traceback_ind(recording: int, point: int) -> int:
    """recording 0 = newest .. 3 = oldest, point 0..99 -> IND word."""
    if not 0 <= recording <= 3 or not 0 <= point <= 0xFF:
        raise ValueError("recording must be 0..3 and point 0..255")
    return recording << 8 | point


def decode_traceback_ind(ind: int) -> tuple[int, int]:
    return (ind >> 8) & 0x3, ind & 0xFF


RECORDING_TEXT = {0: "newest", 1: "2nd newest", 2: "3rd newest", 3: "oldest (4th)"}


def bit_names(profile: Profile, table: str, word: int) -> list[str]:
    names = toyo_config(profile).bits.get(table, {})
    return [names.get(b, f"bit {b}") for b in range(16) if word >> b & 1]


def run_cmd_fields(word: int) -> dict[str, Any]:
    preset = (word >> 6) & 0x7
    accdec = (word >> 9) & 0x3
    return {"run": bool(word & 1), "jog": bool(word & 2), "reverse": bool(word & 4),
            "initial_excitation": bool(word & 8), "dc_brake": bool(word & 0x10), "reset": bool(word & 0x20),
            "preset_speed": preset, "accel_set": accdec + 1, "speed_up": bool(word & 0x800),
            "speed_down": bool(word & 0x1000), "speed_hold": bool(word & 0x2000),
            "s_curve_inhibit": bool(word & 0x4000), "max_speed_reduction": bool(word & 0x8000)}


def ctw_command(word: int) -> str:
    """What a mode-0 control word asks the VF66 for (priority OFF2 > OFF3 > OFF1)."""
    if not word & pd.Ctw.CONTROL_BY_PLC:
        return "master control invalid (bit 10 = 0: the previous command is kept)"
    parts: list[str] = []
    if not word & pd.Ctw.NO_OFF2:
        parts.append("OFF2 coast stop")
    elif not word & pd.Ctw.NO_OFF3:
        parts.append("OFF3 quick stop")
    elif not word & pd.Ctw.ON:
        parts.append("OFF1 normal stop" + (" (bit 3 = 1: runs as soon as bit 0 goes to 1)"
                                           if word & pd.Ctw.ENABLE_OPERATION else " (ready to switch on)"))
    elif not word & pd.Ctw.ENABLE_OPERATION:
        parts.append("ON (ready, run inhibited)")
    else:
        missing = [t for b, t in ((4, "ramp inhibit (ARC = 0)"), (5, "ramp stop (ARC held)"),
                                  (6, "setpoint inhibit")) if not word >> b & 1]
        parts.append("RUN" + (" with " + ", ".join(missing) if missing else ""))
    if word & (pd.Ctw.ENABLE_RFG | pd.Ctw.UNFREEZE_RFG | pd.Ctw.ENABLE_SETPOINT) == 0 and \
            word & (pd.Ctw.JOG1 | pd.Ctw.JOG2) and word & pd.Ctw.ON and word & pd.Ctw.NO_OFF2 \
            and word & pd.Ctw.NO_OFF3:
        parts.append("forward jog (jog 1)" if word & pd.Ctw.JOG1 else "reverse jog (jog 2)")
    elif word & (pd.Ctw.JOG1 | pd.Ctw.JOG2):
        parts.append("jog bit ignored (needs bits 4-6 = 0)")
    if word & pd.Ctw.FAULT_ACK:
        parts.append("fault acknowledge")
    return "; ".join(parts)
