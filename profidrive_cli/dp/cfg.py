"""Chk_Cfg / Get_Cfg identifier octets (reference §3.2), compact and special format.

decode_cfg(bytes) -> list of CfgModule, one per identifier, each knowing its input/output sizes in octets,
the raw octets it used, and a readable description. encode is simply the raw octets: a master sends the
GSD's module bytes verbatim (including 0x00 empty-slot identifiers).
"""

from __future__ import annotations

from dataclasses import dataclass


class CfgError(ValueError):
    """Identifier octets that cannot be decoded (truncated special format, reserved count)."""


@dataclass(frozen=True)
class CfgModule:
    raw: bytes                 # the octets of this identifier
    inputs: int = 0            # input octets (slave -> master)
    outputs: int = 0           # output octets (master -> slave)
    words: bool = False
    consistent: bool = False
    special: bool = False
    manufacturer: bytes = b""  # manufacturer-specific octets (special format)
    in_words: bool | None = None   # special format: the unit of each direction may differ
    out_words: bool | None = None

    @property
    def empty(self) -> bool:
        return self.inputs == 0 and self.outputs == 0

    def describe(self) -> str:
        if self.empty and not self.manufacturer:
            return "empty slot"
        def amount(n_octets: int, words: bool | None) -> str:
            words = self.words if words is None else words
            unit = "word" if words else "byte"
            n = n_octets // 2 if words else n_octets
            return f"{n} {unit}{'s' if n != 1 else ''}"
        parts = []
        if self.inputs and self.outputs and self.inputs == self.outputs:
            parts.append(f"{amount(self.inputs, self.in_words)} in+out")
        else:
            if self.outputs:
                parts.append(f"{amount(self.outputs, self.out_words)} out")
            if self.inputs:
                parts.append(f"{amount(self.inputs, self.in_words)} in")
        if self.consistent:
            parts.append("consistent")
        if self.manufacturer:
            parts.append("manufacturer data " + self.manufacturer.hex(" "))
        return ", ".join(parts)


def _length_octet(b: int) -> tuple[int, bool, bool]:
    """Special-format length octet: bits 5..0 = length-1, bit 6 words, bit 7 consistency."""
    words = bool(b & 0x40)
    n = (b & 0x3F) + 1
    return (n * 2 if words else n), words, bool(b & 0x80)


def decode_cfg(data: bytes) -> list[CfgModule]:
    mods: list[CfgModule] = []
    i = 0
    data = bytes(data)
    while i < len(data):
        b = data[i]
        if b & 0x30:  # compact format
            words = bool(b & 0x40)
            n = (b & 0x0F) + 1
            octets = n * 2 if words else n
            direction = (b >> 4) & 3
            mods.append(CfgModule(
                raw=data[i:i + 1],
                inputs=octets if direction in (1, 3) else 0,
                outputs=octets if direction in (2, 3) else 0,
                words=words, consistent=bool(b & 0x80)))
            i += 1
            continue
        # special format
        nman = b & 0x0F
        if nman == 15:
            raise CfgError(f"identifier 0x{b:02X} at octet {i}: manufacturer count 15 is reserved")
        kind = (b >> 6) & 3
        start = i
        i += 1
        outputs = inputs = 0
        out_words = in_words = None
        consistent = False
        if kind in (2, 3):
            if i >= len(data):
                raise CfgError(f"identifier 0x{b:02X} at octet {start}: output length octet missing")
            outputs, out_words, c1 = _length_octet(data[i])
            consistent = consistent or c1
            i += 1
        if kind in (1, 3):
            if i >= len(data):
                raise CfgError(f"identifier 0x{b:02X} at octet {start}: input length octet missing")
            inputs, in_words, c2 = _length_octet(data[i])
            consistent = consistent or c2
            i += 1
        if i + nman > len(data):
            raise CfgError(f"identifier 0x{b:02X} at octet {start}: "
                           f"{nman} manufacturer octets announced, {len(data) - i} present")
        man = data[i:i + nman]
        i += nman
        mods.append(CfgModule(raw=data[start:i], inputs=inputs, outputs=outputs,
                              words=bool(out_words or in_words), consistent=consistent,
                              special=True, manufacturer=man, in_words=in_words,
                              out_words=out_words))
    return mods


def io_sizes(data: bytes) -> tuple[int, int]:
    """(input octets, output octets) that a configuration implies."""
    mods = decode_cfg(data)
    return sum(m.inputs for m in mods), sum(m.outputs for m in mods)


def parse_hex(text: str) -> bytes:
    """'F3 F1', 'f3f1', '0xF3,0xF1' -> b'\\xf3\\xf1'. Raises ValueError with what was wrong."""
    t = text.replace(",", " ").replace(":", " ").strip()
    toks = t.split()
    out = bytearray()
    for tok in toks:
        if tok.lower().startswith("0x"):
            tok = tok[2:]
        if len(tok) % 2:
            raise ValueError(f"odd number of hex digits in {tok!r}")
        try:
            out += bytes.fromhex(tok)
        except ValueError:
            raise ValueError(f"not hex: {tok!r}") from None
    return bytes(out)
