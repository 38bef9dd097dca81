"""PROFIdrive PPO areas: 16-bit words <-> octets (word order) and the PPO layouts (PKW + PZD words).

Sans-IO, pure data: what one direction's cyclic area looks like and how it is packed. Touches only
the profile's layouts (sizes, `pkw:` flag, word order); no parameter or state-machine logic.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Iterable, Literal

from profidrive_cli import UsageError

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import Profile

def _check_order(word_order: str) -> Literal["big", "little"]:
    if word_order not in ("big", "little"):
        raise ValueError(f"word order must be big or little, got {word_order!r}")
    return "big" if word_order == "big" else "little"


def words_to_bytes(words: Iterable[int], word_order: str = "big") -> bytes:
    """16-bit words to octets; `word_order` big = high octet first (PROFIBUS default)."""
    order = _check_order(word_order)
    out = bytearray()
    for w in words:
        out += (int(w) & 0xFFFF).to_bytes(2, order)
    return bytes(out)


def bytes_to_words(data: bytes, word_order: str = "big") -> list[int]:
    order = _check_order(word_order)
    if len(data) % 2:
        raise ValueError(f"{len(data)} octets is not a whole number of words")
    return [int.from_bytes(data[i:i + 2], order) for i in range(0, len(data), 2)]


# =============================================================================================
# PPO layouts
# =============================================================================================

#: PPO type -> (PKW present, PZD words); the same in both directions
PPO_TYPES: dict[int, tuple[bool, int]] = {1: (True, 2), 2: (True, 6), 3: (False, 2), 4: (False, 6),
                                          5: (True, 10)}
PKW_WORDS = 4


@dataclass(frozen=True)
class PpoLayout:
    name: str
    pkw: bool
    pzd_out: int          # PZD words master -> drive
    pzd_in: int           # PZD words drive -> master
    word_order: str = "big"

    @property
    def output_len(self) -> int:
        return 2 * ((PKW_WORDS if self.pkw else 0) + self.pzd_out)

    @property
    def input_len(self) -> int:
        return 2 * ((PKW_WORDS if self.pkw else 0) + self.pzd_in)

    def length(self, direction: str) -> int:
        return self.output_len if direction == "request" else self.input_len

    def pzd_words(self, direction: str) -> int:
        return self.pzd_out if direction == "request" else self.pzd_in

    @classmethod
    def ppo(cls, n: int, word_order: str = "big") -> "PpoLayout":
        pkw, pzd = PPO_TYPES[n]
        return cls(f"ppo{n}", pkw, pzd, pzd, word_order)


def ppo_layout(profile: Profile, layout_name: str | None = None) -> PpoLayout:
    """The PPO layout of a profile layout: PKW from the layout's `pkw:` flag, PZD words from its cfg."""
    name = layout_name or profile.default_layout
    lay = profile.layouts.get(name)
    if lay is None:
        raise UsageError(f"profile {profile.name} has no layout '{name}' "
                         f"(known: {', '.join(profile.layouts)})")
    pkw_octets = 2 * PKW_WORDS if lay.pkw else 0
    if lay.output_len < pkw_octets + 4 or lay.input_len < pkw_octets + 4 \
            or lay.output_len % 2 or lay.input_len % 2:
        raise UsageError(f"profile {profile.name}: layout '{name}' is not a PPO layout "
                         f"({lay.output_len} out / {lay.input_len} in octets)")
    return PpoLayout(name, lay.pkw, (lay.output_len - pkw_octets) // 2,
                     (lay.input_len - pkw_octets) // 2, profile.word_order)


@dataclass
class PpoArea:
    """One direction's data: the 4 PKW words (None without PKW) and the PZD words (PZD1 first)."""
    pkw: tuple[int, int, int, int] | None
    pzd: list[int] = field(default_factory=list)

    @property
    def word1(self) -> int:
        """PZD1: the control word (request) or the status word (response)."""
        return self.pzd[0]

    @property
    def word2(self) -> int:
        """PZD2: the main reference (request) or the main actual value (response), N2."""
        return self.pzd[1]


def encode_area(layout: PpoLayout, area: PpoArea, direction: str = "request") -> bytes:
    n = layout.pzd_words(direction)
    pzd = list(area.pzd)[:n] + [0] * max(0, n - len(area.pzd))
    words: list[int] = []
    if layout.pkw:
        words += list(area.pkw or (0, 0, 0, 0))
    words += pzd
    return words_to_bytes(words, layout.word_order)


def decode_area_bytes(layout: PpoLayout, data: bytes, direction: str = "request") -> PpoArea:
    want = layout.length(direction)
    if len(data) != want:
        raise ValueError(f"{layout.name.upper()} {direction} is {want} octets, got {len(data)}")
    words = bytes_to_words(data, layout.word_order)
    if layout.pkw:
        return PpoArea(tuple(words[:4]), words[4:])  # type: ignore[arg-type]
    return PpoArea(None, words)
