"""PROFIdrive V2 core: PPO areas, CTW/STW, the state machine, N2 scaling, the PKW channel, PNU 9xx.

Sans-IO except for `ProfidriveDrive`, which couples the codec with a CyclicChannel (the channel does
the waiting; nothing here sleeps). The family codecs (moeller, fuji, toyo) build on this module; the
API below is meant to stay stable.

Public API
----------
Words and layouts
    words_to_bytes(words, word_order="big") -> bytes
    bytes_to_words(data, word_order="big") -> list[int]
    PPO_TYPES: {n: (pkw: bool, pzd_words: int)}            PPO1..5
    PpoLayout(name, pkw, pzd_out, pzd_in, word_order)       .output_len / .input_len (octets)
    ppo_layout(profile, layout_name) -> PpoLayout           from the profile's layouts (cfg sizes)
    PpoArea(pkw: tuple[4 words] | None, pzd: list[int])     PZD1 = CTW/STW, PZD2 = MRV/MAV, PZD3..
    encode_area(layout, area) -> bytes
    decode_area_bytes(layout, data) -> PpoArea

Control and status words
    Ctw, Stw: IntFlag with the generic PROFIdrive bit names
    CTW_NAMES, STW_NAMES: {bit: text}; ctw_names(profile) / stw_names(profile) add the vendor names
    bit_list(word, names) -> list[str]                      names of the set bits
    State (str Enum): S1..S5, FAULT;  state_from_status(stw, moving=None) -> State
    Target (str Enum): READY (= OFF1 stop), SWITCHED_ON, OPERATE, OFF1, OFF2, OFF3, DISABLE, ACK
    next_control_word(status_word, target, extra_bits=0, *, previous=None, moving=None) -> int
    target_reached(status_word, target, moving=None) -> bool
    command_from_control_word(ctw) -> str                   what a control word asks for (decoders)

N2 scaling (0x4000 = 100 %, two's complement for reverse)
    n2_from_percent(pct) -> word;  n2_to_percent(word) -> float
    n2_from_hz(hz, fmax) -> word;  n2_to_hz(word, fmax) -> float
    to_signed16(word) -> int

PKW channel
    encode_pke(ak, pnu, spm=0) -> int;  decode_pke(pke) -> (ak, spm, pnu)
    PkwFrame(ak, pnu, subindex=0, value=0, spm=0, ind_low=0)   .words() / PkwFrame.from_words(words)
    REQUEST_TEXT, RESPONSE_TEXT, POSITIVE_RESPONSES, ERROR_RESPONSES, GENERIC_ERRORS
    PkwResult(request, response, error, error_text, timed_out)  .ok / .value
    PkwChannel(timeout=2.0, zero_after_error=False, zero_between_identical=False,
               error_texts=None, max_zero_cycles=20)
        .submit(request, now=None)  .outputs() -> 4 words  .feed(input_words, now) -> PkwResult | None
        .busy  .cancel()
    read_request(pnu, subindex=0, array=False) -> PkwFrame
    write_request(pnu, value, subindex=0, array=False, long=False) -> PkwFrame

PNU 9xx helpers
    PNU_PZD_SETPOINT 915, PNU_PZD_ACTUAL 916, PNU_NODE_ADDRESS 918, PNU_EDIT_RIGHTS 927,
    PNU_CONTROL_RIGHTS 928, PNU_FAULT_NUMBER 947, PNU_BAUD 963, PNU_DEVICE_ID 964, PNU_PROFILE 965,
    PNU_CONTROL_WORD 967, PNU_STATUS_WORD 968, PNU_SAVE 971
    pzd_map_read(direction, slot) / pzd_map_write(direction, slot, pnu) -> PkwFrame
        direction "setpoint" (915, master->drive) or "actual" (916, drive->master); slot 1 = PZD3
    fault_memory_requests(cfg) -> list[(position label, PkwFrame)]
    save_requests(pnu=971) -> [write 0, write 1]            the 0->1 edge
    decode_baud(code, cfg) -> str;  decode_device_id(word, cfg) -> str

Per-card configuration (the profile's `profidrive:` section, validated with file:line errors)
    ProfidriveConfig.from_profile(profile);  config(profile) -> ProfidriveConfig (cached)
    a family module may define profidrive_config(profile) -> ProfidriveConfig instead (own keys)
    keys (all optional):
      labels: {control: STW, status: ZSW, reference: HSW, actual: HIW}   the card's own word names
      ctw_bits / stw_bits: {bit: name}          vendor names for bits (usually 8..15); null = unused
      held_ctw_bits: [4, 5, 6]                  held at 1 in every control word (extra_bits)
      array_pnus: [915, 916, 947]               PNUs addressed with the array AKs 6/7/8
      pzd_map: {setpoint: 915, actual: 916}
      pkw: {timeout_s, zero_after_error, zero_between_identical, max_zero_cycles,
            requests: [supported AKs], errors: {number: text}, error_numbers: {role: number}}
            roles: unknown_pnu read_only out_of_range bad_subindex not_array wrong_type stop_only
                   no_rights bad_request (the numbers the card answers with; the sim uses them too)
      fault_memory: {pnu: 947, subindexes: [1, 9, ...], positions: [labels]}
      save: {pnu: 971}                          absent = no save command
      baud_codes: {code: text};  device_ids: {word: text}
      ramps: {accel: CODE, decel: CODE, quick_decel: CODE};  jog_reference: CODE

Drive
    ProfidriveDrive(channel, profile, layout=None)  -- the Drive interface (drives/base.py);
    subclass hooks: resolve_param, raw_to_value, value_to_raw, check_value, start_hint,
    write_refused_message, status_extras; see the class docstring.
    Beyond the Drive interface: request(frame), read_raw / write_raw(pnu, ...), card_info(),
    set_pzd(n, raw), pzd_mapping(direction), map_pzd(direction, slot, pnu), jog(on), extra_bits
    decode_area(profile, layout, direction, data, *, max_hz=None) -> dict   (generic PPO decoder)
    make_drive(channel, profile, layout=None) -> ProfidriveDrive  (so `family: profidrive` works)
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from enum import Enum, IntFlag
from typing import Iterable, Sequence

from profidrive_cli import UsageError
from profidrive_cli.datafile import DataFileError, LineDict
from profidrive_cli.drives.values import raw_value_problem, value_problem
from profidrive_cli.drives.base import (Drive, DriveError, DriveStatus, FaultRecord, ParamError,
                                        ParamValue)

# =============================================================================================
# words <-> octets
# =============================================================================================


def _check_order(word_order: str) -> str:
    if word_order not in ("big", "little"):
        raise ValueError(f"word order must be big or little, got {word_order!r}")
    return word_order


def words_to_bytes(words: Iterable[int], word_order: str = "big") -> bytes:
    """16-bit words to octets; `word_order` big = high octet first (PROFIBUS default)."""
    _check_order(word_order)
    out = bytearray()
    for w in words:
        out += (int(w) & 0xFFFF).to_bytes(2, word_order)
    return bytes(out)


def bytes_to_words(data: bytes, word_order: str = "big") -> list[int]:
    _check_order(word_order)
    if len(data) % 2:
        raise ValueError(f"{len(data)} octets is not a whole number of words")
    return [int.from_bytes(data[i:i + 2], word_order) for i in range(0, len(data), 2)]


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


def ppo_layout(profile, layout_name: str | None = None) -> PpoLayout:
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


# =============================================================================================
# control word / status word
# =============================================================================================


class Ctw(IntFlag):
    ON = 1 << 0                  # 0 = OFF1 (ramp stop)
    NO_OFF2 = 1 << 1             # 0 = OFF2 (coast)
    NO_OFF3 = 1 << 2             # 0 = OFF3 (quick stop)
    ENABLE_OPERATION = 1 << 3
    ENABLE_RFG = 1 << 4
    UNFREEZE_RFG = 1 << 5
    ENABLE_SETPOINT = 1 << 6
    FAULT_ACK = 1 << 7           # acts on the 0 -> 1 edge
    JOG1 = 1 << 8
    JOG2 = 1 << 9
    CONTROL_BY_PLC = 1 << 10     # PZD valid; 0 = the drive ignores CTW and reference


class Stw(IntFlag):
    READY_TO_SWITCH_ON = 1 << 0
    READY_TO_OPERATE = 1 << 1
    OPERATION_ENABLED = 1 << 2
    FAULT = 1 << 3
    NO_OFF2 = 1 << 4
    NO_OFF3 = 1 << 5
    SWITCHING_ON_INHIBITED = 1 << 6
    WARNING = 1 << 7
    AT_SETPOINT = 1 << 8
    CONTROL_REQUESTED = 1 << 9
    F_REACHED = 1 << 10


CTW_NAMES: dict[int, str] = {
    0: "ON", 1: "no OFF2", 2: "no OFF3", 3: "enable operation", 4: "enable ramp generator",
    5: "unfreeze ramp generator", 6: "enable setpoint", 7: "fault acknowledge", 8: "jog 1",
    9: "jog 2", 10: "control by PLC",
}
#: what a 0 in the generic control-word bits means (for decoders)
CTW_ZERO_NAMES: dict[int, str] = {0: "OFF1", 1: "OFF2", 2: "OFF3"}
STW_NAMES: dict[int, str] = {
    0: "ready to switch on", 1: "ready to operate", 2: "operation enabled", 3: "fault",
    4: "no OFF2", 5: "no OFF3", 6: "switching on inhibited", 7: "warning", 8: "at setpoint",
    9: "control requested", 10: "f reached",
}

RUN_BITS = Ctw.ENABLE_OPERATION | Ctw.ENABLE_RFG | Ctw.UNFREEZE_RFG | Ctw.ENABLE_SETPOINT
#: bits next_control_word decides itself; extra_bits cannot override them
_DERIVED = Ctw.ON | Ctw.NO_OFF2 | Ctw.NO_OFF3 | Ctw.ENABLE_OPERATION | Ctw.FAULT_ACK \
    | Ctw.CONTROL_BY_PLC


def bit_list(word: int, names: dict[int, str]) -> list[str]:
    """Names of the set bits (unnamed set bits as 'bit n')."""
    return [names.get(b, f"bit {b}") for b in range(16) if word >> b & 1]


class State(str, Enum):
    S1 = "S1 switching on inhibited"
    S2 = "S2 ready for switching on"
    S3 = "S3 switched on"
    S4 = "S4 operation"
    S5 = "S5 switching off"
    FAULT = "fault"

    def __str__(self) -> str:
        return self.value


def state_from_status(stw: int, moving: bool | None = None) -> State:
    """The state a status word shows (bits 6, 3, 2, 1, 0).

    S3 and S5 (and S2 while an OFF1 ramp is still running) look the same in the status word;
    pass `moving` (actual value != 0) to tell them apart. Without it S5 is never reported.
    """
    if stw & Stw.FAULT:
        return State.FAULT
    if stw & Stw.SWITCHING_ON_INHIBITED:
        return State.S1
    low = stw & 0x7
    if low == 0b111:
        return State.S4
    if low in (0b011, 0b001, 0b000):
        if moving:
            return State.S5
        return {0b011: State.S3, 0b001: State.S2, 0b000: State.S1}[low]
    # inconsistent patterns (bit 1 or 2 without bit 0): go by the highest bit
    if low & 0b100:
        return State.S4
    return State.S3 if low & 0b010 else State.S1


class Target(str, Enum):
    READY = "ready"              # S2 ready for switching on; from operation this is an OFF1 ramp stop
    SWITCHED_ON = "switched_on"  # S3; from operation this disables operation (coast on most cards)
    OPERATE = "operate"          # S4
    OFF1 = "off1"                # ramp stop, then wait in S2 (same words as READY)
    OFF2 = "off2"                # coast stop -> S1
    OFF3 = "off3"                # quick stop -> S1
    DISABLE = "disable"          # operation disabled (bit 3 = 0) -> S3
    ACK = "ack"                  # acknowledge a fault with a 0 -> 1 edge on bit 7 -> S1

    @classmethod
    def parse(cls, t: "Target | str") -> "Target":
        if isinstance(t, Target):
            return t
        key = str(t).lower()
        alias = {"stop": "off1", "normal": "off1", "coast": "off2", "quick": "off3",
                 "run": "operate", "operation": "operate", "acknowledge": "ack", "reset": "ack"}
        try:
            return cls(alias.get(key, key))
        except ValueError:
            raise ValueError(f"unknown target {t!r} (known: {', '.join(x.value for x in cls)})") \
                from None


def next_control_word(status_word: int, target: "Target | str", extra_bits: int = 0, *,
                      previous: int | None = None, moving: bool | None = None) -> int:
    """The control word to send next to move the drive from its status toward `target`.

    Derived from the bit tables: B = no OFF2 | no OFF3 | control by PLC | extra_bits (extra_bits
    cannot touch bits 0-3, 7, 10), RUN = enable operation + ramp/setpoint enables (bits 3-6).

      S1 -> S2          B                       (bit 0 = 0 with bits 1, 2 = 1: 0x0406 for extra 0)
      S2/S3 -> S4       B | ON | RUN            (0x047F; S3 is passed through in the same step)
      OFF1 ramp stop    B | RUN                 (ON cleared, bit 3 kept: 0x047E; from S1-S3 just B)
      OFF2 / OFF3       B | ON | RUN minus bit 1 / bit 2        (0x047D / 0x047B)
      disable           B | ON | RUN minus bit 3                (0x0477)
      switched on       B | ON                                  (0x0407)
      acknowledge       B with bit 7 low, then high: needs `previous` (the last word sent); the
                        edge is produced when the previous word had bit 7 low.
    In fault every target except ACK gets its word with bit 7 low; the drive is never acknowledged
    without being asked to.
    """
    t = Target.parse(target)
    state = state_from_status(status_word, moving)
    extra = int(extra_bits) & ~int(_DERIVED) & 0xFFFF
    base = int(Ctw.NO_OFF2 | Ctw.NO_OFF3 | Ctw.CONTROL_BY_PLC) | extra
    run = base | int(Ctw.ON | RUN_BITS)

    if t is Target.OFF2:
        return run & ~int(Ctw.NO_OFF2)
    if t is Target.OFF3:
        return run & ~int(Ctw.NO_OFF3)
    if t is Target.DISABLE:
        return run & ~int(Ctw.ENABLE_OPERATION)
    if state is State.FAULT:
        if t is Target.ACK and previous is not None and not previous & Ctw.FAULT_ACK:
            return base | int(Ctw.FAULT_ACK)
        return base
    if t is Target.ACK:
        return base
    if t in (Target.READY, Target.OFF1):
        # keep operation enabled while a ramp may still be running: clearing bit 3 would coast
        keep = state in (State.S4, State.S5) or (
            previous is not None and bool(previous & Ctw.ENABLE_OPERATION)
            and bool(previous & Ctw.NO_OFF2) and bool(previous & Ctw.NO_OFF3)
            and state is not State.S1)
        return base | int(RUN_BITS) if keep else base
    if state is State.S1:
        return base                       # every way up starts with OFF1 in S1
    if t is Target.SWITCHED_ON:
        return base | int(Ctw.ON)
    return run                            # OPERATE


def target_reached(status_word: int, target: "Target | str", moving: bool | None = None) -> bool:
    t = Target.parse(target)
    st = state_from_status(status_word, moving)
    if t is Target.ACK:
        return st is not State.FAULT
    if t is Target.OPERATE:
        return st is State.S4
    if t is Target.SWITCHED_ON:
        return st is State.S3
    if t is Target.READY:
        return st is State.S2
    if t is Target.OFF1:
        return st in (State.S1, State.S2) and not moving
    if t in (Target.OFF2, Target.OFF3):
        return st is State.S1 and not moving
    if t is Target.DISABLE:
        return st is State.S3 and not moving
    return False


def command_from_control_word(ctw: int) -> str:
    """A short description of what a control word asks for (for decoders)."""
    if not ctw & Ctw.CONTROL_BY_PLC:
        return "no control (bit 10 = 0: control word and reference ignored)"
    parts = []
    if not ctw & Ctw.NO_OFF2:
        parts.append("OFF2 coast stop")
    elif not ctw & Ctw.NO_OFF3:
        parts.append("OFF3 quick stop")
    elif not ctw & Ctw.ON:
        parts.append("OFF1 ramp stop" if ctw & Ctw.ENABLE_OPERATION else "ready (OFF1)")
    elif not ctw & Ctw.ENABLE_OPERATION:
        parts.append("switch on, operation disabled")
    elif (ctw & RUN_BITS) == RUN_BITS:
        parts.append("operate")
    else:
        missing = [CTW_NAMES[b] for b in (4, 5, 6) if not ctw >> b & 1]
        parts.append("operate without " + ", ".join(missing))
    if ctw & Ctw.FAULT_ACK:
        parts.append("fault acknowledge")
    if ctw & Ctw.JOG1:
        parts.append("jog 1")
    if ctw & Ctw.JOG2:
        parts.append("jog 2")
    return "; ".join(parts)


# =============================================================================================
# N2 scaling
# =============================================================================================

N2_FULL = 0x4000  # = 100 %


def to_signed16(word: int) -> int:
    word &= 0xFFFF
    return word - 0x10000 if word & 0x8000 else word


def n2_to_percent(word: int) -> float:
    return to_signed16(word) * 100.0 / N2_FULL


def n2_from_percent(pct: float) -> int:
    """Percent -> N2 word (two's complement), rounded, clamped to -200 % .. +199.99 %."""
    if math.isnan(pct):
        raise ValueError("reference is NaN")
    raw = round(pct * N2_FULL / 100.0)
    raw = max(-0x8000, min(0x7FFF, raw))
    return raw & 0xFFFF


def n2_to_hz(word: int, fmax: float) -> float:
    return to_signed16(word) * fmax / N2_FULL


def n2_from_hz(hz: float, fmax: float) -> int:
    if fmax <= 0:
        raise ValueError(f"max frequency must be > 0, got {fmax}")
    return n2_from_percent(100.0 * hz / fmax)


# =============================================================================================
# PKW
# =============================================================================================


def encode_pke(ak: int, pnu: int, spm: int = 0) -> int:
    if not 0 <= ak <= 15:
        raise ValueError(f"AK {ak} outside 0..15")
    if not 0 <= pnu <= 0x7FF:
        raise ValueError(f"PNU {pnu} outside 0..2047")
    return (ak << 12) | ((spm & 1) << 11) | pnu


def decode_pke(pke: int) -> tuple[int, int, int]:
    """-> (AK, SPM, PNU)"""
    return (pke >> 12) & 0xF, (pke >> 11) & 1, pke & 0x7FF


REQUEST_TEXT: dict[int, str] = {
    0: "no task", 1: "request parameter value", 2: "change parameter value (word)",
    3: "change parameter value (long word)", 4: "request description element",
    5: "change description element", 6: "request parameter value (array)",
    7: "change parameter value (array word)", 8: "change parameter value (array long word)",
    9: "request number of array elements", 11: "change array long word and store",
    12: "change array word and store", 13: "change long word and store",
    14: "change word and store", 15: "read or change text",
}
RESPONSE_TEXT: dict[int, str] = {
    0: "no response", 1: "transfer parameter value (word)",
    2: "transfer parameter value (long word)", 3: "transfer description element",
    4: "transfer parameter value (array word)", 5: "transfer parameter value (array long word)",
    6: "transfer number of array elements", 7: "task cannot be executed",
    8: "no parameter change rights", 9: "parameter change report (word)",
    10: "parameter change report (long word)", 15: "transfer text",
}
#: request AK -> positive response AKs accepted (lenient: word/long word answers both accepted)
POSITIVE_RESPONSES: dict[int, frozenset[int]] = {
    1: frozenset({1, 2}), 2: frozenset({1, 2}), 3: frozenset({1, 2}), 4: frozenset({3}),
    5: frozenset({3}), 6: frozenset({4, 5}), 7: frozenset({4, 5}), 8: frozenset({4, 5}),
    9: frozenset({6}), 11: frozenset({4, 5}), 12: frozenset({4, 5}), 13: frozenset({1, 2}),
    14: frozenset({1, 2}), 15: frozenset({15}),
}
ERROR_RESPONSES = frozenset({7, 8})
ARRAY_REQUESTS = frozenset({6, 7, 8, 9, 11, 12})
WRITE_REQUESTS = frozenset({2, 3, 5, 7, 8, 11, 12, 13, 14})

GENERIC_ERRORS: dict[int, str] = {
    0: "parameter number does not exist",
    1: "parameter is read-only",
    2: "value outside the limits",
    3: "wrong subindex",
    4: "parameter is not an array",
    5: "wrong data type",
    6: "only 0 may be written",
    7: "description element is read-only",
    9: "description data not available",
    11: "no parameter change rights",
    12: "key word missing",
    15: "no text array",
    17: "not possible in the current operating state",
    18: "other error",
    20: "value not allowed",
    21: "response too long",
    22: "parameter address not allowed",
    23: "illegal format",
    24: "number of values inconsistent",
}


@dataclass(frozen=True)
class PkwFrame:
    """The 4 PKW words of one direction, decoded. `value` is PWE1:PWE2 as a 32-bit number."""
    ak: int
    pnu: int
    subindex: int = 0
    value: int = 0
    spm: int = 0
    ind_low: int = 0      # IND low octet: reserved in PROFIdrive V2 (Siemens: page)

    @property
    def pke(self) -> int:
        return encode_pke(self.ak, self.pnu, self.spm)

    @property
    def ind(self) -> int:
        return (self.subindex & 0xFF) << 8 | (self.ind_low & 0xFF)

    def words(self) -> tuple[int, int, int, int]:
        v = self.value & 0xFFFFFFFF
        return (self.pke, self.ind, v >> 16, v & 0xFFFF)

    @classmethod
    def from_words(cls, words: Sequence[int]) -> "PkwFrame":
        if len(words) != 4:
            raise ValueError(f"PKW is 4 words, got {len(words)}")
        ak, spm, pnu = decode_pke(words[0])
        return cls(ak=ak, pnu=pnu, subindex=(words[1] >> 8) & 0xFF, value=(words[2] << 16) | words[3],
                   spm=spm, ind_low=words[1] & 0xFF)

    @property
    def key(self) -> tuple[int, int]:
        return (self.pnu, self.subindex)


PkwRequest = PkwFrame
PkwResponse = PkwFrame
IDLE = PkwFrame(0, 0)


def read_request(pnu: int, subindex: int = 0, array: bool = False) -> PkwFrame:
    return PkwFrame(6 if array else 1, pnu, subindex)


def write_request(pnu: int, value: int, subindex: int = 0, array: bool = False,
                  long: bool = False) -> PkwFrame:
    ak = (8 if long else 7) if array else (3 if long else 2)
    return PkwFrame(ak, pnu, subindex, value & 0xFFFFFFFF)


@dataclass
class PkwResult:
    request: PkwFrame
    response: PkwFrame | None
    error: int | None = None          # the card's error number (AK 7/8), None when ok
    error_text: str = ""
    timed_out: bool = False

    @property
    def ok(self) -> bool:
        return self.response is not None and self.response.ak not in ERROR_RESPONSES \
            and not self.timed_out

    @property
    def value(self) -> int:
        return self.response.value if self.response is not None else 0

    def describe_error(self) -> str:
        if self.timed_out:
            return self.error_text
        return f"error {self.error} ({self.error_text})" if self.error is not None else "ok"


class PkwBusy(DriveError):
    """A request was submitted while another one is outstanding."""


def matches(request: PkwFrame, response: PkwFrame) -> bool:
    """Is `response` the answer to `request`? PNU must echo; subindex too (lenient on errors)."""
    if response.ak == 0 or response.pnu != request.pnu:
        return False
    if response.ak in ERROR_RESPONSES:
        return response.subindex in (request.subindex, 0)
    if response.ak not in POSITIVE_RESPONSES.get(request.ak, frozenset()):
        return False
    return response.subindex == request.subindex


class PkwChannel:
    """The parameter channel as an asynchronous request/response over cyclic data (sans-IO).

    Per cycle: `outputs()` gives the 4 PKW words to send, then `feed(input words, now)` with the
    4 PKW words received; feed returns a PkwResult when the outstanding request is answered (or
    timed out), else None. AK 0 is sent while idle; one request at a time.

    Rules selectable per card:
      zero_after_error        after an error (or a timeout) send AK 0 before the next request
      zero_between_identical  before a request to the same PNU/subindex as the previous one send
                              AK 0 (so the drive sees a new task and a stale echo cannot match)
    In both cases AK 0 goes out for at least one cycle and until the drive answers AK 0 (at most
    `max_zero_cycles` cycles).
    """

    def __init__(self, *, timeout: float = 2.0, zero_after_error: bool = False,
                 zero_between_identical: bool = False, error_texts: dict[int, str] | None = None,
                 max_zero_cycles: int = 20):
        self.timeout = timeout
        self.zero_after_error = zero_after_error
        self.zero_between_identical = zero_between_identical
        self.error_texts = dict(GENERIC_ERRORS)
        if error_texts:
            self.error_texts.update(error_texts)
        self.max_zero_cycles = max_zero_cycles
        self._req: PkwFrame | None = None
        self._deadline: float | None = None
        self._zeroing = 0            # AK 0 cycles still owed before the request goes out (>0)
        self._zero_sent = 0
        self._last: PkwFrame | None = None       # last completed request
        self._last_failed = False
        self._idle_cycles = 0                    # AK 0 cycles sent since the last completion
        self._idle_answered = False              # drive answered AK 0 since the last completion

    @property
    def busy(self) -> bool:
        return self._req is not None

    @property
    def pending(self) -> PkwFrame | None:
        return self._req

    def error_text(self, number: int) -> str:
        return self.error_texts.get(number, f"error {number}")

    def submit(self, request: PkwFrame, now: float | None = None) -> None:
        if self._req is not None:
            raise PkwBusy(f"PKW request PNU {self._req.pnu} still outstanding")
        if request.ak == 0:
            raise ValueError("AK 0 is not a request")
        need_zero = (self.zero_after_error and self._last_failed) or (
            self.zero_between_identical and self._last is not None and self._last.key == request.key)
        if need_zero and self._idle_cycles >= 1 and self._idle_answered:
            need_zero = False
        self._req = request
        self._zeroing = 1 if need_zero else 0
        self._zero_sent = 0
        self._deadline = None if now is None else now + self.timeout

    def cancel(self) -> None:
        if self._req is not None:
            self._finish(self._req, failed=True)

    def outputs(self) -> tuple[int, int, int, int]:
        if self._req is None:
            self._idle_cycles += 1
            return IDLE.words()
        if self._zeroing:
            self._zero_sent += 1
            return IDLE.words()
        return self._req.words()

    def _finish(self, req: PkwFrame, failed: bool) -> None:
        self._req = None
        self._last = req
        self._last_failed = failed
        self._idle_cycles = 0
        self._idle_answered = False
        self._zeroing = 0

    def feed(self, inputs: Sequence[int], now: float) -> PkwResult | None:
        resp = PkwFrame.from_words(inputs)
        req = self._req
        if req is None:
            if resp.ak == 0:
                self._idle_answered = True
            return None
        if self._deadline is None:
            self._deadline = now + self.timeout
        if self._zeroing:
            if self._zero_sent >= 1 and (resp.ak == 0 or self._zero_sent >= self.max_zero_cycles):
                self._zeroing = 0
            elif now > self._deadline:
                return self._timeout(req)
            return None
        if matches(req, resp):
            if resp.ak in ERROR_RESPONSES:
                num = resp.value & 0xFFFF
                text = self.error_text(num)
                if resp.ak == 8:
                    text = f"no parameter change rights ({text})" if num else \
                        "no parameter change rights"
                self._finish(req, failed=True)
                return PkwResult(req, resp, num, text)
            self._finish(req, failed=False)
            return PkwResult(req, resp)
        if now > self._deadline:
            return self._timeout(req)
        return None

    def _timeout(self, req: PkwFrame) -> PkwResult:
        self._finish(req, failed=True)
        return PkwResult(req, None, None, f"no answer to PNU {req.pnu} within {self.timeout:g} s",
                         timed_out=True)


# =============================================================================================
# PNU 9xx
# =============================================================================================

PNU_PZD_SETPOINT = 915
PNU_PZD_ACTUAL = 916
PNU_NODE_ADDRESS = 918
PNU_EDIT_RIGHTS = 927
PNU_CONTROL_RIGHTS = 928
PNU_FAULT_NUMBER = 947
PNU_BAUD = 963
PNU_DEVICE_ID = 964
PNU_PROFILE = 965
PNU_CONTROL_WORD = 967
PNU_STATUS_WORD = 968
PNU_SAVE = 971


def _pzd_map_pnu(direction: str, cfg: "ProfidriveConfig | None" = None) -> int:
    sp, act = (cfg.pzd_map if cfg else (PNU_PZD_SETPOINT, PNU_PZD_ACTUAL))
    if direction in ("setpoint", "write", "out", "request"):
        return sp
    if direction in ("actual", "read", "in", "response"):
        return act
    raise ValueError(f"PZD map direction must be setpoint or actual, got {direction!r}")


def pzd_map_read(direction: str, slot: int, cfg: "ProfidriveConfig | None" = None) -> PkwFrame:
    """Read which PNU travels in PZD(slot+2) (slot 1 = PZD3)."""
    return read_request(_pzd_map_pnu(direction, cfg), slot, array=True)


def pzd_map_write(direction: str, slot: int, pnu: int,
                  cfg: "ProfidriveConfig | None" = None) -> PkwFrame:
    """Map `pnu` into PZD(slot+2); pnu 0 frees the word."""
    return write_request(_pzd_map_pnu(direction, cfg), pnu, slot, array=True)


def save_requests(pnu: int = PNU_SAVE) -> list[PkwFrame]:
    """Store to non-volatile memory: the 0 -> 1 edge on PNU 971 (two writes)."""
    return [write_request(pnu, 0), write_request(pnu, 1)]


def fault_memory_requests(cfg: "ProfidriveConfig") -> list[tuple[str, PkwFrame]]:
    return [(pos, read_request(cfg.fault_memory_pnu, sub, array=True))
            for pos, sub in zip(cfg.fault_positions, cfg.fault_subindexes)]


def decode_baud(code: int, cfg: "ProfidriveConfig") -> str:
    return cfg.baud_codes.get(code, f"unknown baud-rate code {code}")


def decode_device_id(word: int, cfg: "ProfidriveConfig") -> str:
    return cfg.device_ids.get(word, f"unknown device 0x{word:04X}")


def _ordinal(n: int) -> str:
    suf = "th" if 10 <= n % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{suf}"


def default_fault_positions(n: int) -> list[str]:
    out = ["current", "last"]
    out += [f"{_ordinal(i)} last" for i in range(2, n)]
    return out[:n]


# =============================================================================================
# per-card configuration from the profile's `profidrive:` section
# =============================================================================================

ERROR_ROLES = ("unknown_pnu", "read_only", "out_of_range", "bad_subindex", "not_array",
               "wrong_type", "stop_only", "no_rights", "bad_request")
_DEFAULT_ERROR_NUMBERS = {"unknown_pnu": 0, "read_only": 1, "out_of_range": 2, "bad_subindex": 3,
                          "not_array": 4, "wrong_type": 5, "stop_only": 17, "no_rights": 11,
                          "bad_request": 18}


@dataclass
class ProfidriveConfig:
    labels: dict[str, str]
    ctw_names: dict[int, str]
    stw_names: dict[int, str]
    held_ctw_bits: int = 0
    array_pnus: frozenset[int] = frozenset({PNU_PZD_SETPOINT, PNU_PZD_ACTUAL, PNU_FAULT_NUMBER})
    pzd_map: tuple[int, int] = (PNU_PZD_SETPOINT, PNU_PZD_ACTUAL)
    pkw_timeout: float = 2.0
    zero_after_error: bool = False
    zero_between_identical: bool = False
    max_zero_cycles: int = 20
    supported_requests: frozenset[int] | None = None
    error_texts: dict[int, str] = field(default_factory=lambda: dict(GENERIC_ERRORS))
    error_numbers: dict[str, int] = field(default_factory=lambda: dict(_DEFAULT_ERROR_NUMBERS))
    fault_memory_pnu: int = PNU_FAULT_NUMBER
    fault_subindexes: list[int] = field(default_factory=lambda: [1, 9, 17, 25])
    fault_positions: list[str] = field(default_factory=lambda: default_fault_positions(4))
    save_pnu: int | None = None
    baud_codes: dict[int, str] = field(default_factory=dict)
    device_ids: dict[int, str] = field(default_factory=dict)
    ramps: dict[str, str] = field(default_factory=dict)
    jog_reference: str | None = None

    def error_text(self, number: int) -> str:
        return self.error_texts.get(number, f"error {number}")

    @classmethod
    def from_profile(cls, profile) -> "ProfidriveConfig":
        path = profile.path or "<profile>"
        doc = profile.raw if isinstance(profile.raw, LineDict) else LineDict()
        sec = doc.get("profidrive", LineDict())
        if not isinstance(sec, dict):
            raise DataFileError(path, doc.line_of("profidrive"), "'profidrive' must be a mapping")
        known = {"labels", "ctw_bits", "stw_bits", "held_ctw_bits", "array_pnus", "pzd_map", "pkw",
                 "fault_memory", "save", "baud_codes", "device_ids", "ramps", "jog_reference"}
        _unknown(path, sec, known, "profidrive")
        labels = {"control": "CTW", "status": "STW", "reference": "MRV", "actual": "MAV"}
        lab = _map(path, sec, "labels")
        for k, v in lab.items():
            if k not in labels or not isinstance(v, str):
                raise _e(path, lab, k, f"profidrive.labels: '{k}' must be one of "
                         f"{', '.join(labels)} with a text value")
            labels[k] = v
        ctw = dict(CTW_NAMES)
        ctw.update(_bit_names(path, sec, "ctw_bits"))
        stw = dict(STW_NAMES)
        stw.update(_bit_names(path, sec, "stw_bits"))
        ctw = {b: n for b, n in ctw.items() if n is not None}      # null = bit not used
        stw = {b: n for b, n in stw.items() if n is not None}
        held = 0
        for b in _int_list(path, sec, "held_ctw_bits", 0, 15):
            held |= 1 << b
        if held & _DERIVED:
            raise _e(path, sec, "held_ctw_bits",
                     "held_ctw_bits cannot include bits 0-3, 7 or 10 (the state machine sets them)")
        cfg = cls(labels=labels, ctw_names=ctw, stw_names=stw, held_ctw_bits=held)
        if "array_pnus" in sec:
            cfg.array_pnus = frozenset(_int_list(path, sec, "array_pnus", 1, 0x7FF))
        pm = _map(path, sec, "pzd_map")
        if pm:
            _unknown(path, pm, {"setpoint", "actual"}, "profidrive.pzd_map")
            cfg.pzd_map = (_int(path, pm, "setpoint", PNU_PZD_SETPOINT),
                           _int(path, pm, "actual", PNU_PZD_ACTUAL))
        pkw = _map(path, sec, "pkw")
        if pkw:
            _unknown(path, pkw, {"timeout_s", "zero_after_error", "zero_between_identical",
                                 "max_zero_cycles", "requests", "errors", "error_numbers"},
                     "profidrive.pkw")
            t = pkw.get("timeout_s", cfg.pkw_timeout)
            if not isinstance(t, (int, float)) or isinstance(t, bool) or t <= 0:
                raise _e(path, pkw, "timeout_s", "pkw.timeout_s must be a number > 0")
            cfg.pkw_timeout = float(t)
            for k in ("zero_after_error", "zero_between_identical"):
                if k in pkw:
                    if not isinstance(pkw[k], bool):
                        raise _e(path, pkw, k, f"pkw.{k} must be true or false")
                    setattr(cfg, k, pkw[k])
            cfg.max_zero_cycles = _int(path, pkw, "max_zero_cycles", cfg.max_zero_cycles)
            if "requests" in pkw:
                cfg.supported_requests = frozenset(_int_list(path, pkw, "requests", 0, 15))
            errs = _map(path, pkw, "errors")
            for k, v in errs.items():
                if not isinstance(k, int) or not isinstance(v, str):
                    raise _e(path, errs, k, "pkw.errors: keys are error numbers, values texts")
                cfg.error_texts[k] = v
            en = _map(path, pkw, "error_numbers")
            for k, v in en.items():
                if k not in ERROR_ROLES or not isinstance(v, int) or isinstance(v, bool):
                    raise _e(path, en, k, f"pkw.error_numbers: '{k}' must be one of "
                             f"{', '.join(ERROR_ROLES)} with a number")
                cfg.error_numbers[k] = v
        fm = _map(path, sec, "fault_memory")
        if fm:
            _unknown(path, fm, {"pnu", "subindexes", "positions"}, "profidrive.fault_memory")
            cfg.fault_memory_pnu = _int(path, fm, "pnu", PNU_FAULT_NUMBER)
            if "subindexes" in fm:
                cfg.fault_subindexes = _int_list(path, fm, "subindexes", 0, 255)
            cfg.fault_positions = default_fault_positions(len(cfg.fault_subindexes))
            if "positions" in fm:
                pos = fm["positions"]
                if not isinstance(pos, list) or len(pos) != len(cfg.fault_subindexes) \
                        or not all(isinstance(p, str) for p in pos):
                    raise _e(path, fm, "positions",
                             "fault_memory.positions must be one text per subindex")
                cfg.fault_positions = list(pos)
        sv = _map(path, sec, "save")
        if sv:
            _unknown(path, sv, {"pnu"}, "profidrive.save")
            cfg.save_pnu = _int(path, sv, "pnu", PNU_SAVE)
        for key, attr in (("baud_codes", "baud_codes"), ("device_ids", "device_ids")):
            m = _map(path, sec, key)
            for k, v in m.items():
                if not isinstance(k, int) or not isinstance(v, str):
                    raise _e(path, m, k, f"{key}: keys are numbers, values texts")
                getattr(cfg, attr)[k] = v
        rp = _map(path, sec, "ramps")
        for k, v in rp.items():
            if k not in ("accel", "decel", "quick_decel") or not isinstance(v, str):
                raise _e(path, rp, k, "ramps: keys accel, decel, quick_decel; values parameter codes")
            if profile.param(v) is None:
                raise _e(path, rp, k, f"ramps.{k}: parameter {v} is not in parameters")
            cfg.ramps[k] = v
        if "jog_reference" in sec:
            jr = sec["jog_reference"]
            if not isinstance(jr, str) or profile.param(jr) is None:
                raise _e(path, sec, "jog_reference", f"jog_reference {jr!r} is not in parameters")
            cfg.jog_reference = jr
        return cfg


def _e(path, node, key, msg) -> DataFileError:
    line = node.line_of(key) if isinstance(node, LineDict) else getattr(node, "line", None)
    return DataFileError(path, line, msg)


def _unknown(path, node, known: set, where: str) -> None:
    for k in node:
        if k not in known:
            raise _e(path, node, k, f"{where}: unknown key '{k}' (known: {', '.join(sorted(known))})")


def _map(path, node, key) -> LineDict:
    v = node.get(key, LineDict()) if isinstance(node, dict) else LineDict()
    if not isinstance(v, dict):
        raise _e(path, node, key, f"'{key}' must be a mapping")
    if not isinstance(v, LineDict):
        ld = LineDict(v)
        ld.line, ld.key_lines = 0, {}
        v = ld
    return v


def _int(path, node, key, default: int) -> int:
    v = node.get(key, default)
    if not isinstance(v, int) or isinstance(v, bool):
        raise _e(path, node, key, f"'{key}' must be an integer, got {v!r}")
    return v


def _int_list(path, node, key, lo: int, hi: int) -> list[int]:
    v = node.get(key, [])
    if not isinstance(v, list) or not all(isinstance(x, int) and not isinstance(x, bool)
                                          and lo <= x <= hi for x in v):
        raise _e(path, node, key, f"'{key}' must be a list of integers {lo}..{hi}")
    return list(v)


def _bit_names(path, node, key) -> dict[int, str]:
    m = _map(path, node, key)
    out = {}
    for k, v in m.items():
        if not isinstance(k, int) or not 0 <= k <= 15 or not (v is None or isinstance(v, str)):
            raise _e(path, m, k, f"{key}: keys are bit numbers 0..15, values names (null = unused)")
        out[k] = v
    return out


_config_cache: dict[int, tuple[object, ProfidriveConfig]] = {}


def config(profile) -> ProfidriveConfig:
    """The profile's ProfidriveConfig (validated once, cached per profile object).

    A family module drives/<family>.py may define `profidrive_config(profile) -> ProfidriveConfig`
    to build it from its own profile keys; otherwise the `profidrive:` section is read.
    """
    hit = _config_cache.get(id(profile))
    if hit is not None and hit[0] is profile:
        return hit[1]
    from profidrive_cli.drives import codec_module
    try:
        hook = getattr(codec_module(profile), "profidrive_config", None)
    except UsageError:
        hook = None
    cfg = hook(profile) if hook is not None else ProfidriveConfig.from_profile(profile)
    _config_cache[id(profile)] = (profile, cfg)
    return cfg


def ctw_names(profile) -> dict[int, str]:
    return config(profile).ctw_names


def stw_names(profile) -> dict[int, str]:
    return config(profile).stw_names


# =============================================================================================
# parameter addressing
# =============================================================================================

_RAW_RE = re.compile(r"^PNU\s*(0x[0-9a-f]+|\d+)\s*(?:\[\s*(0x[0-9a-f]+|\d+)\s*\])?$", re.I)
_CODE_IND_RE = re.compile(r"^(.+?)\s*\[\s*(0x[0-9a-f]+|\d+)\s*\]$", re.I)


@dataclass
class ParamRef:
    """Where a parameter lives on the PKW channel."""
    code: str
    name: str
    pnu: int
    subindex: int = 0
    array: bool = False
    size: int = 16                  # 16 or 32 bits (selects the word / long-word AK)
    param: object | None = None     # the profile's ParamDef, when known

    @property
    def label(self) -> str:
        return f"{self.code} ({self.name})" if self.name else self.code


def param_index(profile) -> dict[tuple[int, int | None], object]:
    """(pnu, index) -> ParamDef, cached on the profile."""
    idx = getattr(profile, "_pnu_index", None)
    if idx is None:
        idx = {}
        for p in profile.parameters.values():
            if p.pnu is not None:
                idx.setdefault((p.pnu, p.index), p)
        try:
            profile._pnu_index = idx
        except AttributeError:
            pass
    return idx


def param_for(profile, pnu: int, subindex: int = 0):
    """The profile's ParamDef at PNU/subindex (function-code style first, then the whole PNU)."""
    idx = param_index(profile)
    return idx.get((pnu, subindex)) or idx.get((pnu, None)) or (idx.get((pnu, 0)) if subindex == 0
                                                                 else None)


def resolve_code(profile, code: str, cfg: ProfidriveConfig | None = None) -> ParamRef:
    """Native code ("F002", "A004"), code with index ("PNU947[9]") or raw "PNU<n>[<ind>]"."""
    cfg = cfg or config(profile)
    text = code.strip()
    p = profile.param(text)
    sub = None
    if p is None:
        m = _CODE_IND_RE.match(text)
        if m and profile.param(m.group(1)) is not None:
            p = profile.param(m.group(1))
            sub = int(m.group(2), 0)
    if p is not None:
        if p.pnu is None:
            raise UsageError(f"{p.code}: no PNU in profile {profile.name}")
        array = p.pnu in cfg.array_pnus or bool(p.extra.get("array"))
        if sub is None:
            sub = p.index or 0
            if array and p.index is None:
                sub = 1
        return ParamRef(p.code, p.name, p.pnu, sub, array, p.size, p)
    m = _RAW_RE.match(text)
    if not m:
        raise UsageError(f"unknown parameter '{code}' in profile {profile.name} "
                         f"(use a code such as {next(iter(profile.parameters), 'F03')} or PNU<n>[<ind>])")
    pnu = int(m.group(1), 0)
    sub = int(m.group(2), 0) if m.group(2) is not None else 0
    if not 0 < pnu <= 0x7FF or not 0 <= sub <= 255:
        raise UsageError(f"{code}: PNU must be 1..2047 and subindex 0..255")
    p = param_for(profile, pnu, sub)
    array = pnu in cfg.array_pnus or bool(p is not None and p.extra.get("array"))
    if p is not None:
        return ParamRef(p.code, p.name, pnu, sub, array, p.size, p)
    return ParamRef(f"PNU{pnu}" + (f"[{sub}]" if sub else ""), "", pnu, sub, array, 16, None)


def decimals_for(scale: float) -> int:
    if not scale or float(scale).is_integer():
        return 0
    return max(0, min(6, -math.floor(math.log10(abs(scale)) + 1e-9)))


def format_value(param, value, raw: int | None = None) -> str:
    """Engineering value with the parameter's resolution and unit ("4.00 s", "0x1F", "2")."""
    if param is None:
        return str(value)
    fmt = param.extra.get("format")
    if fmt in ("hex", "bits") and raw is not None:
        return f"0x{raw:X}"
    d = decimals_for(param.scale)
    text = f"{value:.{d}f}" if isinstance(value, float) or d else str(value)
    return f"{text} {param.unit}" if param.unit else text


# =============================================================================================
# the generic Drive
# =============================================================================================


class ProfidriveDrive(Drive):
    """The Drive interface over a PPO layout (drives/base.py), generic PROFIdrive V2.

    Keeps a command (target state, reference, extra control bits, PZD3.. words) and sends it every
    cycle; blocking calls cycle until the drive answers or `timeout` passes.

    Subclass hooks (family codecs override what differs):
      resolve_param(code) -> ParamRef            code -> PNU/subindex/array/size
      raw_to_value(ref, raw) / value_to_raw(ref, value)   wire integer <-> engineering value
      check_value(ref, value) -> str | None      range check before a write (None = ok)
      write_refused_message(ref, value, result) -> str    the one-line error for a refused write
      start_hint(status) -> str                  appended when start() times out
      status_extras(area, status) -> None        add family flags/raw words to a DriveStatus
      control_extra_bits() -> int                bits ORed into every control word
    """

    family = "profidrive"

    def __init__(self, channel, profile, layout: str | None = None,
                 cfg: ProfidriveConfig | None = None):
        super().__init__(channel, profile, layout)
        self.cfg = cfg or config(profile)
        self.ppo = ppo_layout(profile, self.layout)
        self.target: Target | None = None          # None = passive (control word 0, bit 10 = 0)
        self.reference = 0                          # N2 word
        self.extra_bits = self.cfg.held_ctw_bits
        self.pzd_out: list[int] = [0] * max(0, self.ppo.pzd_out - 2)
        self.pkw: PkwChannel | None = None
        if self.ppo.pkw:
            self.pkw = PkwChannel(timeout=self.cfg.pkw_timeout,
                                  zero_after_error=self.cfg.zero_after_error,
                                  zero_between_identical=self.cfg.zero_between_identical,
                                  error_texts=self.cfg.error_texts,
                                  max_zero_cycles=self.cfg.max_zero_cycles)
        self.last_ctw: int | None = None
        self.last_stw: int | None = None
        self.last_area: PpoArea | None = None
        self.last_status: DriveStatus | None = None
        self._pkw_result: PkwResult | None = None
        self._fmax: float | None = None

    # -- hooks -------------------------------------------------------------------------------
    @property
    def has_param_channel(self) -> bool:
        return self.pkw is not None

    def control_extra_bits(self) -> int:
        return self.extra_bits

    def resolve_param(self, code: str) -> ParamRef:
        return resolve_code(self.profile, code, self.cfg)

    def raw_to_value(self, ref: ParamRef, raw: int):
        p = ref.param
        if p is None:
            return raw
        if p.size == 16:
            raw &= 0xFFFF
        return p.from_raw(raw)

    def value_to_raw(self, ref: ParamRef, value) -> int:
        p = ref.param
        raw = int(value) if p is None else p.to_raw(value)
        bits = ref.size
        return raw & ((1 << bits) - 1)

    def check_value(self, ref: ParamRef, value) -> str | None:
        """The exact-value check (drives/values.py): resolution, range, codes, wire width."""
        if ref.param is not None:
            return value_problem(ref.param, value)
        return raw_value_problem(ref.label, value, ref.size)

    def write_refused_message(self, ref: ParamRef, value, result: PkwResult) -> str:
        stop_only = self.cfg.error_numbers.get("stop_only")
        if result.error is not None and result.error == stop_only:
            return (f"{ref.label} can only be changed while the motor is stopped "
                    f"(drive answered error {result.error}: {result.error_text}); stop it first")
        if result.error is not None and result.error == self.cfg.error_numbers.get("no_rights") \
                or (result.response is not None and result.response.ak == 8):
            return (f"{ref.label}: the drive gives no parameter change rights "
                    f"({result.describe_error()}); set PNU {PNU_EDIT_RIGHTS} = 1")
        return f"{ref.label}: the drive refused the value {value}: {result.describe_error()}"

    def start_hint(self, status: DriveStatus) -> str:
        return ("check that the drive takes commands from the bus (control-word bit 10 is sent "
                "as 1; the drive's command-source parameters)")

    def status_extras(self, area: PpoArea, status: DriveStatus) -> None:
        return None

    # -- one cycle ---------------------------------------------------------------------------
    def _control_word(self) -> int:
        if self.target is None:
            return 0
        stw = self.last_stw if self.last_stw is not None else int(Stw.SWITCHING_ON_INHIBITED)
        moving = None
        if self.last_area is not None and len(self.last_area.pzd) > 1:
            moving = to_signed16(self.last_area.pzd[1]) != 0
        return next_control_word(stw, self.target, self.control_extra_bits(),
                                 previous=self.last_ctw, moving=moving)

    def _exchange_area(self, pzd_words: list[int]) -> PpoArea:
        """One Data_Exchange: this cycle's PKW words + `pzd_words` out, the decoded input area
        back; a PKW answer that completes is kept for the waiting request."""
        pkw_words = self.pkw.outputs() if self.pkw else None
        out = PpoArea(pkw_words, pzd_words)
        inputs = self.channel.exchange(encode_area(self.ppo, out, "request"))
        area = decode_area_bytes(self.ppo, inputs, "response")
        self.last_area = area
        if self.pkw is not None and area.pkw is not None:
            res = self.pkw.feed(area.pkw, self.channel.now())
            if res is not None:
                self._pkw_result = res
        return area

    def cycle(self) -> DriveStatus:
        ctw = self._control_word()
        area = self._exchange_area([ctw, self.reference] + list(self.pzd_out))
        self.last_ctw = ctw
        self.last_stw = area.word1
        st = self._decode_status(area)
        self.last_status = st
        return st

    def _decode_status(self, area: PpoArea) -> DriveStatus:
        stw, mav = area.word1, area.word2
        moving = to_signed16(mav) != 0
        state = state_from_status(stw, moving)
        pct = n2_to_percent(mav)
        fmax = self._fmax if self._fmax is not None else float(self.profile.max_frequency_default)
        names = self.cfg.stw_names
        flags = {names.get(b, f"bit {b}"): bool(stw >> b & 1) for b in range(16) if b in names}
        raw = {"status_word": stw, "actual": mav}
        for i, w in enumerate(area.pzd[2:], start=3):
            raw[f"pzd{i}"] = w
        st = DriveStatus(state=state.value, running=state in (State.S4, State.S5),
                         fault=state is State.FAULT, flags=flags, speed_percent=round(pct, 4),
                         speed_hz=round(pct * fmax / 100.0, 4),
                         reference_percent=round(n2_to_percent(self.reference), 4), raw=raw)
        self.status_extras(area, st)
        return st

    # -- PKW ---------------------------------------------------------------------------------
    def request(self, frame: PkwFrame, timeout: float | None = None) -> PkwResult:
        """Run one PKW request to completion (keeps cyclic data going)."""
        if self.pkw is None:
            raise DriveError(f"{self.profile.name}: layout {self.layout} has no parameter channel "
                             f"(use a PPO with PKW: {', '.join(n for n, l in self.profile.layouts.items() if l.pkw) or 'none'})")
        if self.cfg.supported_requests is not None and frame.ak not in self.cfg.supported_requests:
            raise DriveError(f"{self.profile.name}: the card does not support request "
                             f"AK {frame.ak} ({REQUEST_TEXT.get(frame.ak, '?')})")
        self._pkw_result = None
        self.pkw.submit(frame, self.channel.now())
        end = self.channel.now() + (timeout if timeout is not None else self.pkw.timeout) + 1.0
        while self._pkw_result is None:
            self.cycle()
            if self._pkw_result is None and self.channel.now() > end:
                self.pkw.cancel()
                raise DriveError(f"no answer to the parameter request for PNU {frame.pnu}")
        res, self._pkw_result = self._pkw_result, None
        return res

    def read_raw(self, pnu: int, subindex: int = 0, array: bool | None = None) -> int:
        if array is None:
            array = pnu in self.cfg.array_pnus
        res = self.request(read_request(pnu, subindex, array))
        if not res.ok:
            raise ParamError(f"PNU {pnu}" + (f"[{subindex}]" if subindex else "")
                             + f": {res.describe_error()}", res.error)
        return res.value

    def write_raw(self, pnu: int, value: int, subindex: int = 0, array: bool | None = None,
                  long: bool = False) -> int:
        if array is None:
            array = pnu in self.cfg.array_pnus
        res = self.request(write_request(pnu, value, subindex, array, long))
        if not res.ok:
            raise ParamError(f"PNU {pnu}" + (f"[{subindex}]" if subindex else "")
                             + f": {res.describe_error()}", res.error)
        return res.value

    def read_param(self, code: str) -> ParamValue:
        ref = self.resolve_param(code)
        res = self.request(read_request(ref.pnu, ref.subindex, ref.array))
        if not res.ok:
            raise ParamError(f"{ref.label}: the drive refused the read: {res.describe_error()}",
                             res.error)
        return self._param_value(ref, res.value)

    def _param_value(self, ref: ParamRef, wire: int) -> ParamValue:
        raw = wire & 0xFFFF if ref.size == 16 else wire & 0xFFFFFFFF
        value = self.raw_to_value(ref, raw)
        unit = ref.param.unit if ref.param is not None else ""
        return ParamValue(ref.code, ref.name, raw, value, unit)

    def write_param(self, code: str, value) -> ParamValue:
        ref = self.resolve_param(code)
        p = ref.param
        if p is not None and not p.writable:
            raise ParamError(f"{ref.label} is read-only", self.cfg.error_numbers.get("read_only"))
        msg = self.check_value(ref, value)
        if msg:
            raise ParamError(msg, self.cfg.error_numbers.get("out_of_range"))
        raw = self.value_to_raw(ref, value)
        res = self.request(write_request(ref.pnu, raw, ref.subindex, ref.array, ref.size == 32))
        if not res.ok:
            raise ParamError(self.write_refused_message(ref, value, res), res.error)
        if self.profile.max_frequency_param and ref.param is not None \
                and ref.code == self.profile.max_frequency_param:
            self._fmax = None
        if p is not None and p.access == "wo":
            return self._param_value(ref, raw)
        return self.read_param(code)

    def save(self) -> None:
        if self.cfg.save_pnu is None:
            raise DriveError(f"{self.profile.name}: this card has no separate save command")
        for frame in save_requests(self.cfg.save_pnu):
            res = self.request(frame)
            if not res.ok:
                raise ParamError(f"save (PNU {self.cfg.save_pnu} 0 -> 1): {res.describe_error()}",
                                 res.error)

    def alarm_record(self, position: str, raw: int) -> FaultRecord:
        if raw == 0:
            return FaultRecord(position, 0, [], ["no fault"])
        alarms = self.profile.alarms_for(raw)
        if not alarms:
            return FaultRecord(position, raw, [f"?{raw}"], [f"unknown fault number {raw}"])
        return FaultRecord(position, raw, [a.code for a in alarms], [a.meaning for a in alarms])

    def fault_history(self) -> list[FaultRecord]:
        out = []
        for pos, frame in fault_memory_requests(self.cfg):
            res = self.request(frame)
            if not res.ok:
                raise ParamError(f"fault memory PNU {frame.pnu}[{frame.subindex}]: "
                                 f"{res.describe_error()}", res.error)
            out.append(self.alarm_record(pos, res.value & 0xFFFF))
        return out

    def max_frequency(self) -> float:
        if self._fmax is None:
            if self.pkw is not None and self.profile.max_frequency_param:
                self._fmax = float(self.read_param(self.profile.max_frequency_param).value)
            else:
                self._fmax = float(self.profile.max_frequency_default)
        return self._fmax

    def card_info(self) -> dict[str, object]:
        """PNU 918 address, 963 baud, 964 device, 965 profile, 927/928 rights, 967/968 last words.
        Entries the card does not support are None."""
        out: dict[str, object] = {}
        for key, pnu in (("node_address", PNU_NODE_ADDRESS), ("baud", PNU_BAUD),
                         ("device", PNU_DEVICE_ID), ("profile_version", PNU_PROFILE),
                         ("edit_rights", PNU_EDIT_RIGHTS), ("control_rights", PNU_CONTROL_RIGHTS),
                         ("control_word", PNU_CONTROL_WORD), ("status_word", PNU_STATUS_WORD)):
            try:
                v = self.read_raw(pnu) & 0xFFFF
            except ParamError:
                out[key] = None
                continue
            if key == "baud" and self.cfg.baud_codes:
                out[key] = decode_baud(v, self.cfg)
            elif key == "device" and self.cfg.device_ids:
                out[key] = f"0x{v:04X} ({decode_device_id(v, self.cfg)})"
            elif key in ("control_word", "status_word", "device"):
                out[key] = f"0x{v:04X}"
            else:
                out[key] = v
        return out

    # -- PZD3.. ------------------------------------------------------------------------------
    def set_pzd(self, n: int, raw: int) -> None:
        """Set output word PZDn (n >= 3) to a raw value."""
        if not 3 <= n < 3 + len(self.pzd_out):
            raise DriveError(f"layout {self.layout} has no output PZD{n}")
        self.pzd_out[n - 3] = raw & 0xFFFF

    def pzd_mapping(self, direction: str) -> list[int]:
        n = (self.ppo.pzd_out if direction == "setpoint" else self.ppo.pzd_in) - 2
        pnu = _pzd_map_pnu(direction, self.cfg)
        return [self.read_raw(pnu, i, array=True) & 0xFFFF for i in range(1, n + 1)]

    def map_pzd(self, direction: str, slot: int, pnu: int) -> None:
        res = self.request(pzd_map_write(direction, slot, pnu, self.cfg))
        if not res.ok:
            raise ParamError(f"PZD{slot + 2} mapping: {res.describe_error()}", res.error)

    # -- motion ------------------------------------------------------------------------------
    def _ensure_fmax(self) -> None:
        """Learn the drive's max frequency once (PKW), else fall back to the profile default."""
        if self.pkw is not None and self._fmax is None:
            try:
                self.max_frequency()
            except DriveError:
                self._fmax = float(self.profile.max_frequency_default)

    def status(self) -> DriveStatus:
        self._ensure_fmax()
        st = self.cycle()
        if st.fault and self.pkw is not None:
            try:
                rec = self.alarm_record("current", self.read_raw(
                    self.cfg.fault_memory_pnu, self.cfg.fault_subindexes[0], array=True) & 0xFFFF)
                st.fault_code = "/".join(rec.codes) or None
            except DriveError:
                pass
        return st

    def set_speed(self, percent: float) -> None:
        self.reference = n2_from_percent(percent)
        self.cycle()

    def jog(self, on: bool = True) -> None:
        if on:
            self.extra_bits |= int(Ctw.JOG1)
        else:
            self.extra_bits &= ~int(Ctw.JOG1)
        self.cycle()

    def _go(self, target: Target, timeout: float, what: str, hint: bool = False) -> DriveStatus:
        self.target = target
        try:
            return self.cycles_until(
                lambda st: target_reached(st.raw["status_word"], target,
                                          moving=abs(st.speed_percent or 0) > 0), timeout, what)
        except DriveError as e:
            if hint and self.last_status is not None:
                raise DriveError(f"{e}; {self.start_hint(self.last_status)}") from None
            raise

    def start(self, timeout: float = 5.0) -> DriveStatus:
        st = self.cycle()
        if st.fault:
            raise DriveError("the drive is in fault: acknowledge it first (reset)")
        if self.pkw is not None and self._fmax is None:
            self.max_frequency()
        return self._go(Target.OPERATE, timeout, "operation", hint=True)

    def stop(self, mode: str = "normal", wait: bool = True, timeout: float = 30.0) -> DriveStatus:
        target = {"normal": Target.OFF1, "ramp": Target.OFF1, "off1": Target.OFF1,
                  "quick": Target.OFF3, "off3": Target.OFF3,
                  "coast": Target.OFF2, "off2": Target.OFF2}.get(mode)
        if target is None:
            raise UsageError(f"stop mode must be normal, quick or coast, got {mode!r}")
        self.target = target
        st = self.cycle()
        if not wait:
            return st
        return self.cycles_until(
            lambda s: s.fault or (s.stopped and target_reached(
                s.raw["status_word"], target, moving=abs(s.speed_percent or 0) > 0)),
            timeout, f"the drive to stop ({mode})")

    def reset_fault(self, timeout: float = 5.0) -> DriveStatus:
        st = self.cycle()
        if not st.fault:
            return st
        self.target = Target.ACK
        return self.cycles_until(lambda s: not s.fault, timeout,
                                 "the fault to clear (is its cause still present?)")


def make_drive(channel, profile, layout: str | None = None) -> ProfidriveDrive:
    """Family `profidrive`: a plain PROFIdrive V2 drive configured only by its profile."""
    return ProfidriveDrive(channel, profile, layout)


# =============================================================================================
# generic decoder (pdrive decode)
# =============================================================================================


def _pct_text(pct: float) -> str:
    r = round(pct, 4)
    return f"{r:g} %" if abs(r) < 1e6 else f"{r} %"


def _hz_text(hz: float) -> str:
    return f"{hz:.2f} Hz"


def describe_pkw(profile, frame: PkwFrame, direction: str, cfg: ProfidriveConfig | None = None,
                 request: PkwFrame | None = None) -> dict:
    """Named fields of one PKW frame; `text` (one line) and `summary` (short) included."""
    cfg = cfg or config(profile)
    texts = REQUEST_TEXT if direction == "request" else RESPONSE_TEXT
    d: dict = {"pke": frame.pke, "ak": frame.ak, "ak_text": texts.get(frame.ak, "reserved"),
               "spm": frame.spm, "pnu": frame.pnu, "ind": frame.ind, "subindex": frame.subindex,
               "pwe": frame.value}
    if frame.ak == 0:
        d["text"] = (f"PKE 0x{frame.pke:04X}: AK 0 ({d['ak_text']}); IND 0x{frame.ind:04X}; "
                     f"PWE 0x{frame.value:08X}")
        d["summary"] = d["ak_text"]
        return d
    p = param_for(profile, frame.pnu, frame.subindex)
    where = f"PNU {frame.pnu}" + (f"[{frame.subindex}]" if frame.subindex else "")
    if p is not None:
        d["code"], d["name"] = p.code, p.name
        named = p.code.upper() != f"PNU{frame.pnu}"
        label = f"{where} = {p.code} {p.name}" if named else f"{where} {p.name}"
        pnu_label = f"PNU {frame.pnu} = {p.code} {p.name}" if named else \
            f"PNU {frame.pnu} {p.name}"
    else:
        label = pnu_label = where if not frame.subindex else f"PNU {frame.pnu}"
    value_text = None
    is_error = direction == "response" and frame.ak in ERROR_RESPONSES
    carries_value = (direction == "request" and frame.ak in WRITE_REQUESTS) or (
        direction == "response" and frame.ak in (1, 2, 4, 5, 9, 10))
    if is_error:
        num = frame.value & 0xFFFF
        d["error"] = num
        d["error_text"] = cfg.error_text(num)
        value_text = f"error {num}: {d['error_text']}"
    elif direction == "response" and frame.ak == 6 or direction == "request" and frame.ak == 9:
        if direction == "response":
            value_text = f"{frame.value} elements"
    elif carries_value:
        value_text = _value_text(profile, cfg, p, frame, d)
    line = f"{d['ak_text']}, {label}"
    if value_text is not None:
        line += f" = {value_text}" if not is_error else f": {value_text}"
    d["value_text"] = value_text
    d["summary"] = line
    d["text"] = (f"PKE 0x{frame.pke:04X}: AK {frame.ak} {d['ak_text']}, SPM {frame.spm}, "
                 + pnu_label + f"; IND 0x{frame.ind:04X} (subindex {frame.subindex}); "
                 f"PWE 0x{frame.value:08X} = {frame.value}"
                 + (f" -> {value_text}" if value_text is not None else ""))
    return d


def _value_text(profile, cfg: ProfidriveConfig, p, frame: PkwFrame, d: dict) -> str:
    pnu = frame.pnu
    if pnu in cfg.pzd_map:
        w = frame.value & 0xFFFF
        mp = param_for(profile, w) if w else None
        d["maps"] = {"pnu": w, "code": mp.code if mp else None}
        return f"{w} (" + (f"{mp.code} {mp.name}" if mp else ("word unused" if w == 0 else "?")) + ")"
    if pnu == cfg.fault_memory_pnu:
        w = frame.value & 0xFFFF
        alarms = profile.alarms_for(w)
        d["alarms"] = [a.code for a in alarms]
        if w == 0:
            return "0 (no fault)"
        return f"{w} (" + (" / ".join(f"{a.code} {a.meaning}" for a in alarms) or "unknown") + ")"
    if pnu == PNU_DEVICE_ID and cfg.device_ids:
        w = frame.value & 0xFFFF
        return f"0x{w:04X} ({decode_device_id(w, cfg)})"
    if pnu == PNU_BAUD and cfg.baud_codes:
        return f"{frame.value} ({decode_baud(frame.value & 0xFFFF, cfg)})"
    if pnu in (PNU_CONTROL_WORD, PNU_STATUS_WORD):
        return f"0x{frame.value & 0xFFFF:04X}"
    if p is None:
        return str(frame.value)
    raw = frame.value & (0xFFFF if p.size == 16 else 0xFFFFFFFF)
    value = _family_value(profile, p, raw)
    d["raw"], d["value"], d["unit"] = raw, value, p.unit
    return format_value(p, value, raw)


def _family_value(profile, p, raw: int):
    """Engineering value; family modules may provide `param_value(profile, param, raw)`."""
    from profidrive_cli.drives import codec_module
    try:
        mod = codec_module(profile)
    except UsageError:
        mod = None
    fn = getattr(mod, "param_value", None) if mod is not None else None
    if fn is not None:
        return fn(profile, p, raw)
    return p.from_raw(raw)


def describe_control_word(profile, ctw: int, cfg: ProfidriveConfig | None = None) -> dict:
    cfg = cfg or config(profile)
    names = cfg.ctw_names
    bits = []
    for b in range(16):
        on = bool(ctw >> b & 1)
        if b in names or on:
            bits.append({"bit": b, "set": on, "name": names.get(b, f"bit {b}")})
    zero = [CTW_ZERO_NAMES[b] for b in (0, 1, 2) if not ctw >> b & 1 and ctw & Ctw.CONTROL_BY_PLC]
    command = command_from_control_word(ctw)
    lab = cfg.labels["control"]
    text = (f"{lab} (control word) 0x{ctw:04X}: " + (", ".join(bit_list(ctw, names)) or "no bits set")
            + (f" [{', '.join(zero)} active]" if zero else "") + f" -> {command}")
    return {"word": ctw, "hex": f"0x{ctw:04X}", "label": lab, "bits": bits,
            "set": bit_list(ctw, names), "command": command, "text": text}


def describe_status_word(profile, stw: int, actual: int | None = None,
                         cfg: ProfidriveConfig | None = None) -> dict:
    cfg = cfg or config(profile)
    names = cfg.stw_names
    # a captured area is one snapshot: the state comes from the status word alone; an actual value
    # != 0 with the S2/S3 pattern may also mean S5 (manual examples show 0x0331 with HIW 0x2000)
    state = state_from_status(stw)
    moving = actual is not None and to_signed16(actual) != 0
    maybe_s5 = moving and state in (State.S2, State.S3)
    bits = [{"bit": b, "set": bool(stw >> b & 1), "name": names.get(b, f"bit {b}")}
            for b in range(16) if b in names or stw >> b & 1]
    lab = cfg.labels["status"]
    text = (f"{lab} (status word) 0x{stw:04X}: " + (", ".join(bit_list(stw, names)) or "no bits set")
            + f" -> {state.value}" + (" (or S5 switching off, if the motor is still turning)"
                                       if maybe_s5 else ""))
    return {"word": stw, "hex": f"0x{stw:04X}", "label": lab, "bits": bits,
            "set": bit_list(stw, names), "state": state.value, "maybe_s5": maybe_s5,
            "text": text}


def describe_n2(word: int, max_hz: float | None, label: str, what: str, max_note: str = "") -> dict:
    pct = n2_to_percent(word)
    d = {"raw": word, "hex": f"0x{word:04X}", "percent": round(pct, 6), "label": label}
    text = f"{label} ({what}) 0x{word:04X}: {_pct_text(pct)}"
    if max_hz:
        hz = pct * max_hz / 100.0
        d["hz"] = round(hz, 6)
        d["max_hz"] = max_hz
        text += f" = {_hz_text(hz)}" + (f" ({max_note})" if max_note else "")
    d["text"] = text
    return d


def check_direction(direction: str) -> None:
    if direction not in ("request", "response"):
        raise UsageError(f"direction must be request or response, got {direction!r}")


def decode_area(profile, layout: str, direction: str, data: bytes, *,
                max_hz: float | None = None) -> dict:
    """Decode a captured PPO output (direction "request") or input ("response") area."""
    check_direction(direction)
    cfg = config(profile)
    ppo = ppo_layout(profile, layout)
    try:
        area = decode_area_bytes(ppo, bytes(data), direction)
    except ValueError as e:
        raise UsageError(str(e)) from None
    if max_hz is None:
        mhz = float(profile.max_frequency_default)
        note = (f"{profile.max_frequency_param} = {mhz:g} Hz, profile default"
                if profile.max_frequency_param else f"max frequency {mhz:g} Hz, profile default")
    else:
        mhz, note = float(max_hz), f"max frequency {max_hz:g} Hz"
    out: dict = {"profile": profile.name, "layout": ppo.name, "direction": direction,
                 "word_order": ppo.word_order, "octets": bytes(data).hex(" ").upper()}
    arrow = "master -> drive" if direction == "request" else "drive -> master"
    text = [f"{profile.name} {ppo.name.upper()} {direction} ({arrow}), {len(data)} octets: "
            f"{out['octets']}"]
    summary = []
    if area.pkw is not None:
        frame = PkwFrame.from_words(area.pkw)
        pk = describe_pkw(profile, frame, direction, cfg)
        out["pkw"] = pk
        text.append(pk["text"])
        summary.append(pk["summary"])
    if direction == "request":
        cw = describe_control_word(profile, area.word1, cfg)
        out["control_word"] = cw
        ref = describe_n2(area.word2, mhz, cfg.labels["reference"], "reference", note)
        out["reference"] = ref
        text += [cw["text"], ref["text"]]
        summary += [cw["command"], f"reference {_pct_text(ref['percent'])}"]
    else:
        sw = describe_status_word(profile, area.word1, area.word2, cfg)
        out["status_word"] = sw
        act = describe_n2(area.word2, mhz, cfg.labels["actual"], "actual value", note)
        out["actual"] = act
        text += [sw["text"], act["text"]]
        summary += [sw["state"], f"actual {_pct_text(act['percent'])}"]
    extra = []
    for i, w in enumerate(area.pzd[2:], start=3):
        extra.append({"pzd": i, "raw": w, "hex": f"0x{w:04X}"})
    if extra:
        out["pzd"] = extra
        text.append("PZD3..: " + ", ".join(f"PZD{e['pzd']} 0x{e['raw']:04X} ({e['raw']})"
                                           for e in extra)
                    + f" (raw; meaning per PNU {cfg.pzd_map[0 if direction == 'request' else 1]})")
    out["summary"] = "; ".join(summary)
    text.append("summary: " + out["summary"])
    out["text"] = text
    return out
