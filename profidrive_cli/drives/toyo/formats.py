"""Toyo value texts for the profile's `format:` names bits, speed and history (drives/formats.py finds
them as FORMATTERS through the family module). Pure functions of the profile; no bus."""

from __future__ import annotations

from typing import TYPE_CHECKING

from profidrive_cli.drives.formats import hex_word
from profidrive_cli.drives.toyo.codec import bit_names, decode_history_word, speed_percent

if TYPE_CHECKING:
    from profidrive_cli.drives.formats import Formatter
    from profidrive_cli.drives.profile import ParamDef, Profile


def bits_text(profile: Profile, param: ParamDef, raw: int, value: object) -> str:
    """A bit word: hex and the names of the set bits from the profile's `bits:` table."""
    table = param.extra.get("bits", "")
    return f"{hex_word(param, raw)}: {', '.join(bit_names(profile, table, raw & 0xFFFF)) or 'none'}"


def speed_text(profile: Profile, param: ParamDef, raw: int, value: object) -> str:
    """A signed speed word in percent of the profile's full scale."""
    return f"{speed_percent(profile, raw & 0xFFFF):g} %"


def history_text(profile: Profile, param: ParamDef, raw: int, value: object) -> str:
    """A fault-history word: protection code and name, inverter mode, block."""
    w = raw & 0xFFFF
    return f"0x{w:04X} ({decode_history_word(profile, w)['text']})"


FORMATTERS: dict[str, Formatter] = {"bits": bits_text, "speed": speed_text, "history": history_text}
