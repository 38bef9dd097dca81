"""The Fuji decoder: the core PPO decoder plus function-code names, alarm candidates, the
direction (MRV sign XOR CTW bit 11), the S3/S5 pattern and the PCD1-4 words.

Text and JSON only; no bus.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING, Any

from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.fuji.codes import (alarm_candidates, alarm_text, function_code_name,
                                              pcd_assignment_code)
from profidrive_cli.drives.fuji.config import fuji_config

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import Profile
    from profidrive_cli.drives.speedplan import SpeedWord


def _hex_word(w: int) -> str:
    return f"0x{w:04X}"


def _replace_value_text(out: dict[str, Any], pk: dict[str, Any], new: str) -> None:
    old = pk.get("value_text")
    if not old:
        return
    for holder in (pk, out):
        holder["summary"] = holder["summary"].replace(old, new)
    pk["text"] = pk["text"].replace(f"-> {old}", f"-> {new}")
    text = out["text"]
    for i, line in enumerate(text):
        if line.startswith("PKE ") and f"-> {old}" in line:
            text[i] = line.replace(f"-> {old}", f"-> {new}")
    if text and text[-1].startswith("summary: "):
        text[-1] = "summary: " + out["summary"]
    pk["value_text"] = new


def _rename_in_summary(out: dict[str, Any], pk: dict[str, Any], code: str) -> None:
    """Say 'F26' instead of 'PNU 260[26] = F26' / 'PNU 271' in the one-line summaries."""
    pnu, sub = pk["pnu"], pk["subindex"]
    pats = [rf"PNU {pnu}\[{sub}\] = {re.escape(code)}\b", rf"PNU {pnu}\[{sub}\]", rf"PNU {pnu}\b"]
    for key, holder in (("summary", pk), ("summary", out)):
        s = holder.get(key, "")
        for pat in pats:
            s2 = re.sub(pat, code, s, count=1)
            if s2 != s:
                holder[key] = s2
                break
    text = out["text"]
    if text and text[-1].startswith("summary: "):
        text[-1] = "summary: " + out["summary"]


def decode_area(profile: Profile, layout: str, direction: str, data: bytes, *,
                max_hz: float | None = None) -> dict[str, Any]:
    """The core PPO decoder plus function-code names, alarm candidates, direction and PCD words."""
    fc = fuji_config(profile)
    out = pd.decode_area(profile, layout, direction, data, max_hz=max_hz)
    text: list[str] = out["text"]
    pk = out.get("pkw")
    if pk is not None and pk["ak"] != 0:
        code = function_code_name(profile, pk["pnu"], pk["subindex"])
        if code is not None:
            group = code.rstrip("0123456789")
            pk["function_code"] = code
            pk.setdefault("code", code)
            line = (f"function code {code}: group {group} (0x{fc.groups[group]:02X}, "
                    f"{fc.group_names.get(group, '')}) -> PNU 0x{pk['pnu']:03X}, subindex "
                    f"0x{pk['subindex']:02X} ({pk['subindex']})")
            if profile.param(code) is None:
                line += "; not in the profile table, value shown raw"
            text.insert(text.index(pk["text"]) + 1, line)
            _rename_in_summary(out, pk, code)
        if pk["pnu"] == fc.history_pnu and "error" not in pk and (
                direction == "response" and pk["ak"] in (1, 4)):
            num = pk["pwe"] & 0xFFFF
            pk["alarm_candidates"] = [{"code": a.code, "mcode": fc.mcodes.get(a.code), "meaning": a.meaning}
                                      for a in alarm_candidates(profile, num)]
            text.insert(text.index(pk["text"]) + 1, f"PNU{fc.history_pnu} malfunction code "
                        f"0x{num:04X}: {alarm_text(profile, num)}")
            if pk.get("value_text", "").startswith(f"{num} ("):
                _replace_value_text(out, pk, f"0x{num:04X}" + pk["value_text"][len(str(num)):])
        if pk["pnu"] in (pd.PNU_PZD_SETPOINT, pd.PNU_PZD_ACTUAL) and "error" not in pk and \
                (direction == "request" and pk["ak"] == 7 or direction == "response" and pk["ak"] == 4):
            w = pk["pwe"] & 0xFFFF
            c = pcd_assignment_code(profile, w)
            pk["assigned_code"] = c
            text.insert(text.index(pk["text"]) + 1, f"PCD{pk['subindex']} assignment {_hex_word(w)} = "
                        + (c if c else "not assigned"))
            _replace_value_text(out, pk, f"{_hex_word(w)} ({c or 'not assigned'})")
    if direction == "request":
        cw = out["control_word"]["word"]
        mrv = out["reference"]["raw"]
        rev = bool(cw >> 11 & 1)
        neg = pd.to_signed16(mrv) < 0
        dirn = "reverse" if (neg != rev) else "forward"
        out["control_word"]["direction"] = dirn
        note = ""
        if neg and rev:
            note = " (negative MRV with bit 11: not specified by the manual; taken as forward)"
        if cw & pd.Ctw.CONTROL_BY_PLC:
            text.insert(-1, f"direction {dirn} (sign of MRV XOR CTW bit 11 reverse){note}")
        elif cw:
            text.insert(-1, "CTW bit 10 (PCD valid) is 0: the card ignores CTW and MRV")
    else:
        sw = out["status_word"]
        stw = sw["word"]
        if stw & 0x7 == 0b011 and not stw & 0x48:
            sw["note"] = "S3 and S5 share this status pattern; MAV != 0 means S5 (stopping)"
            if pd.to_signed16(out["actual"]["raw"]) != 0:
                # the manual's ramp-stop example: 0x0233 while decelerating is S5 (decision in the profile)
                old_state = sw["state"]
                sw["state"] = pd.State.S5.value
                sw["maybe_s5"] = False
                for i, line in enumerate(text):
                    if line == sw["text"]:
                        text[i] = sw["text"] = line.split(" -> ")[0] + f" -> {pd.State.S5.value} (MAV != 0: " \
                            f"decelerating; the same pattern at standstill is S3)"
                out["summary"] = out["summary"].replace(old_state, pd.State.S5.value, 1)
                if text[-1].startswith("summary: "):
                    text[-1] = "summary: " + out["summary"]
    # PCD1-4 (PPO2 / PPO4): function-code words assigned by o40-o43 / o48-o51
    if "pzd" in out:
        which = "o40-o43 / PNU915" if direction == "request" else "o48-o51 / PNU916"
        for e in out["pzd"]:
            e["pcd"] = e["pzd"] - 2
        for i, line in enumerate(text):
            if line.startswith("PZD3..:"):
                text[i] = ("PCD1-4: " + ", ".join(f"PCD{e['pcd']} {_hex_word(e['raw'])} ({e['raw']})"
                                                  for e in out["pzd"])
                           + f" (function codes assigned by {which}; raw)")
    return out


def speed_plan(profile: Profile, layout: str, direction: str, max_hz: float | None = None
               ) -> SpeedWord | None:
    """sniff --station's fast path (drives/speedplan.py SpeedWord): MRV / MAV as the core's N2
    word. The dialect reads MRV's sign (direction, not in the drive object) and MAV != 0 (S3 or
    S5): both within the word's class."""
    return pd.speed_plan(profile, layout, direction, max_hz)
