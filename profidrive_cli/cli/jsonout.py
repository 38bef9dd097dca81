"""The JSON contract of every `--json` output (docs/json.md): the shared shapes, in one place.

- `station`: the bus address (int); `ident` (int) with `ident_hex` ("0x%04X");
- octet strings: lower-case hex, single spaces (`bytes.hex(" ")`);
- flags: a list of the names that are set;
- speeds `reference_hz` / `actual_hz`, times in seconds with a `_s` suffix;
- streams: JSON Lines, each object with an `"event"` key;
- an error: `{"error": "<the one line>", "exit_code": N}` (plus `"event": "error"` in a stream).
"""

from __future__ import annotations

from typing import Any


def ident_fields(ident: int | None) -> dict[str, Any]:
    """{"ident": 64769, "ident_hex": "0xFD01"} (both None when unknown)."""
    return {"ident": ident, "ident_hex": None if ident is None else f"0x{ident:04X}"}


def ident_int(value: Any) -> int | None:
    """An ident given as an int or as "0xFD01" text -> int (None stays None)."""
    if value is None or isinstance(value, int):
        return value
    return int(str(value), 16)


def flag_list(flags: Any) -> list[str]:
    """The names that are set: a {name: bool} dict becomes the list of its true keys; a list stays."""
    if isinstance(flags, dict):
        return [k for k, v in flags.items() if v]
    return list(flags or [])


def octets(text_or_bytes: Any) -> str:
    """Lower-case hex octets with single spaces, from bytes or from hex text in any case/spacing."""
    if isinstance(text_or_bytes, (bytes, bytearray)):
        return bytes(text_or_bytes).hex(" ")
    text = str(text_or_bytes or "").strip()
    if text in ("", "-"):
        return ""
    return " ".join(text.split()).lower()


def renamed(d: dict[str, Any], names: dict[str, str]) -> dict[str, Any]:
    """A copy of `d` with keys renamed (old -> new), the order kept."""
    return {names.get(k, k): v for k, v in d.items()}


def station_identity(d: dict[str, Any]) -> dict[str, Any]:
    """An identity dict (address, ident as int or "0x...") in the contract's shape: station, ident,
    ident_hex; the other keys kept in their order."""
    out: dict[str, Any] = {}
    for k, v in d.items():
        if k == "address":
            out["station"] = v
        elif k == "ident":
            out.update(ident_fields(ident_int(v)))
        elif k != "ident_hex":
            out[k] = v
    return out


def error_object(message: str, exit_code: int, stream: bool) -> dict[str, Any]:
    d: dict[str, Any] = {"event": "error"} if stream else {}
    d.update({"error": message, "exit_code": exit_code})
    return d
