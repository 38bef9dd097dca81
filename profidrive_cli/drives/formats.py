"""A parameter's value as text, by the profile's `format:` key: the one place every format is handled.

    FORMATS                                 every `format:` name a profile may use
    display_text(profile, param, raw, value) -> str | None   the value as the card's tables name it,
                                            None for a plain number (shown with value_text)
    formatter_for(profile, fmt)             the family's formatter (its module's FORMATTERS) or a
                                            generic one (code, hex, bits)

drives/profile.py refuses a `format:` not in FORMATS (file:line); tests/test_manual_tables.py checks
that every format each shipped profile uses has a formatter for its family. Family formatters live in
the family (Fuji function codes, M-codes, PNU947/963 in fuji/formats.py; Toyo bit tables, speed and
history words in toyo/formats.py; Moeller's PNU 963 in moeller.py), found through drives.codec_module. No bus.
"""

from __future__ import annotations

from typing import Any, Callable, Optional, Protocol

from profidrive_cli.drives.registry import ProfileLike


class FormatParam(Protocol):
    """What the formats read of a drives.profile.ParamDef (profile.py imports this module)."""
    @property
    def size(self) -> int: ...
    @property
    def extra(self) -> dict[str, Any]: ...


#: a formatter by `format:` name: (profile, parameter, raw word, engineering value) -> the text as the
#: card's tables write it, None: shown as a plain number. A family's take its own Profile and
#: ParamDef, which this module cannot name (profile.py imports it): hence the `...`
Formatter = Callable[..., Optional[str]]
#: a parser by `format:` name: (profile, parameter, text) -> the raw word (UsageError when refused)
Parser = Callable[..., int]


def hex_word(param: FormatParam, raw: int) -> str:
    return f"0x{raw:0{8 if param.size == 32 else 4}X}"


def _plain(profile: ProfileLike, param: FormatParam, raw: int, value: object) -> str | None:
    return None


def _hex_text(profile: ProfileLike, param: FormatParam, raw: int, value: object) -> str | None:
    return hex_word(param, raw)


#: every `format:` name a profile may use, and what it means
FORMATS = {
    "code": "a selection code: the number as the manual's table lists it",
    "hex": "a word shown in hex",
    "bits": "a bit field: hex, and the names of the set bits where the family names them (Toyo bits:)",
    "fcode": "a function-code assignment group << 8 | number in four hex digits and the code (Fuji o40-o51)",
    "alarm": "an inverter alarm code in the M-code numbering and its name (Fuji M16-M19)",
    "alarm947": "a PNU947 fault-memory entry and every alarm it can stand for (Fuji: malfunction code in hex; "
                "Moeller: Table 8 fault number)",
    "baud": "the card's own baud-rate code and its rate (PNU963)",
    "speed": "a signed speed word in percent of full scale (Toyo)",
    "history": "a fault-history word: protection, inverter mode, block (Toyo)",
}

#: formatters every family shares; a family module adds or overrides its own in FORMATTERS
GENERIC: dict[str, Formatter] = {"code": _plain, "hex": _hex_text, "bits": _hex_text}


def formatter_for(profile: ProfileLike, fmt: str) -> Formatter | None:
    """The formatter(profile, param, raw, value) for `fmt` on this profile's family, or None."""
    from profidrive_cli.drives import codec_module
    fam: dict[str, Formatter] = getattr(codec_module(profile), "FORMATTERS", {})
    return fam.get(fmt) or GENERIC.get(fmt)


def value_from_text(profile: ProfileLike, param: FormatParam | None, text: str) -> int | None:
    """A value typed as the card's tables write it (the family's PARSERS by `format:`, e.g. Fuji o40
    "041A" or "F26") -> the raw word; None when the format has no such notation (parse as a number).
    Raises UsageError (with the accepted forms) for text the notation refuses."""
    if param is None or not isinstance(text, str):
        return None
    fmt = param.extra.get("format")
    if fmt is None:
        return None
    from profidrive_cli.drives import codec_module
    parsers: dict[str, Parser] = getattr(codec_module(profile), "PARSERS", {})
    fn = parsers.get(fmt)
    return fn(profile, param, text) if fn is not None else None


def display_text(profile: ProfileLike, param: FormatParam | None, raw: int | None, value: object) -> str | None:
    """The value as text for a parameter with a `format:`; None when it is shown as a plain number."""
    if param is None or raw is None or isinstance(raw, bool) or not isinstance(raw, int):
        return None
    fmt = param.extra.get("format")
    if fmt is None:
        return None
    fn = formatter_for(profile, fmt)
    if fn is None:
        return hex_word(param, raw)
    return fn(profile, param, raw, value)
