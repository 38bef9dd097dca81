"""PROFIdrive control word (CTW) and status word (STW): bit names, the state machine S1..S5.

Sans-IO and profile-free: which state a status word shows, which control word moves the drive
toward a target, what a control word asks for. Vendor bit names live in the card's config
(drives/profidrive/config.py), not here.
"""

from __future__ import annotations

from enum import Enum, IntFlag

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
DERIVED_BITS = Ctw.ON | Ctw.NO_OFF2 | Ctw.NO_OFF3 | Ctw.ENABLE_OPERATION | Ctw.FAULT_ACK \
    | Ctw.CONTROL_BY_PLC

# The same bits as plain ints for the per-cycle functions below: IntFlag arithmetic builds a new
# enum member on every `&` / `|` (about a microsecond each), and a drive decodes a status word and
# computes a control word on every Data_Exchange.
_ON, _NO_OFF2, _NO_OFF3 = int(Ctw.ON), int(Ctw.NO_OFF2), int(Ctw.NO_OFF3)
_ENABLE_OPERATION, _FAULT_ACK = int(Ctw.ENABLE_OPERATION), int(Ctw.FAULT_ACK)
_CONTROL_BY_PLC, _JOG1, _JOG2 = int(Ctw.CONTROL_BY_PLC), int(Ctw.JOG1), int(Ctw.JOG2)
_RUN_BITS = int(RUN_BITS)
_NOT_DERIVED = ~int(DERIVED_BITS) & 0xFFFF
_BASE = _NO_OFF2 | _NO_OFF3 | _CONTROL_BY_PLC
_STW_FAULT, _STW_INHIBITED = int(Stw.FAULT), int(Stw.SWITCHING_ON_INHIBITED)


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
    if stw & _STW_FAULT:
        return State.FAULT
    if stw & _STW_INHIBITED:
        return State.S1
    low = stw & 0x7
    if low == 0b111:
        return State.S4
    if low in _LOW_STATES:
        if moving:
            return State.S5
        return _LOW_STATES[low]
    # inconsistent patterns (bit 1 or 2 without bit 0): go by the highest bit
    if low & 0b100:
        return State.S4
    return State.S3 if low & 0b010 else State.S1


_LOW_STATES = {0b011: State.S3, 0b001: State.S2, 0b000: State.S1}


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
    t = target if isinstance(target, Target) else Target.parse(target)
    state = state_from_status(status_word, moving)
    base = _BASE | (int(extra_bits) & _NOT_DERIVED)
    run = base | _ON | _RUN_BITS

    if t is Target.OFF2:
        return run & ~_NO_OFF2
    if t is Target.OFF3:
        return run & ~_NO_OFF3
    if t is Target.DISABLE:
        return run & ~_ENABLE_OPERATION
    if state is State.FAULT:
        if t is Target.ACK and previous is not None and not previous & _FAULT_ACK:
            return base | _FAULT_ACK
        return base
    if t is Target.ACK:
        return base
    if t is Target.READY or t is Target.OFF1:
        # keep operation enabled while a ramp may still be running: clearing bit 3 would coast
        keep = state is State.S4 or state is State.S5 or (
            previous is not None and bool(previous & _ENABLE_OPERATION)
            and bool(previous & _NO_OFF2) and bool(previous & _NO_OFF3)
            and state is not State.S1)
        return base | _RUN_BITS if keep else base
    if state is State.S1:
        return base                       # every way up starts with OFF1 in S1
    if t is Target.SWITCHED_ON:
        return base | _ON
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


def command_from_control_word(ctw: int, names: dict[int, str] | None = None,
                              unused: frozenset[int] = frozenset()) -> str:
    """A short description of what a control word asks for (for decoders). Bits 8 and 9 are named
    as the card names them (`names`, the profile's ctw_names: jog 1 / jog 2 in the PROFIdrive
    profile, Moeller "inching 1"), and a set bit the card does not use (`unused`) as such."""
    names = CTW_NAMES if names is None else names
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
    for b in (8, 9):
        if ctw >> b & 1 and b not in unused and b in names:
            parts.append(names[b])
    off = [b for b in range(16) if ctw >> b & 1 and (b in unused or (b in (8, 9) and b not in names))]
    if off:
        parts.append(f"bit{'s' if len(off) > 1 else ''} {', '.join(map(str, off))} set "
                     f"(not used by this card)")
    return "; ".join(parts)
