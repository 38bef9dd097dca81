"""Yaskawa SI-P1 cyclic codec: the three layouts, the run-command and status words, frequency scaling.

Spec: ../shared/spec/yaskawa-profibus-dp.md ("spec §x"; "E<n>" = the spec's errata number, §10).
Pure data and arithmetic: bytes and words in, words and Hz out. Imports nothing of pdrive.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

# ---------------------------------------------------------------------------------------------------
# Layouts
# ---------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class AreaFormat:
    name: str
    cfg: bytes
    size: int                       # octets each way
    out_words: tuple[str, ...]      # fast-I/O words master -> drive, in order
    in_words: tuple[str, ...]       # fast-I/O words drive -> master
    param_offset: int | None        # start of the parameter-access area (None: no parameter access)
    max_registers: int = 0          # registers per request

    @property
    def has_params(self) -> bool:
        return self.param_offset is not None

    @property
    def param_len(self) -> int:
        return 0 if self.param_offset is None else self.size - self.param_offset

    @property
    def data_quantities(self) -> tuple[int, ...]:
        """Data-quantity bytes this format accepts (E6: one-register access is valid)."""
        return tuple(2 * n for n in range(1, self.max_registers + 1))


FORMATS: dict[str, AreaFormat] = {
    "basic": AreaFormat(
        "basic", b"\x72", 6,
        ("command", "reference", "torque_reference"),
        ("status", "speed_feedback", "output_current"),
        None, 0),
    "extended1": AreaFormat(
        "extended1", b"\x5f\x6f", 32,
        ("command", "reference", "torque_reference", "torque_compensation", "reserved",
         "analog_out1", "analog_out2", "mf_outputs"),
        ("status", "speed_feedback", "torque_reference", "pg_count", "frequency_reference",
         "output_frequency", "output_current", "analog_in1"),
        16, 4),
    "extended2": AreaFormat(
        "extended2", b"\x55\x65", 12,
        ("command", "reference"),
        ("status", "speed_feedback"),
        4, 1),
}

# words read as two's complement (spec §2.7 [DERIVED]: torque and analog values signed, frequencies not)
SIGNED_WORDS = {"torque_reference", "torque_compensation", "analog_out1", "analog_out2", "analog_in1",
                "pg_count"}


def pack_words(words: list[int], order: str = "big") -> bytes:
    fmt = (">" if order == "big" else "<") + "H"
    return b"".join(struct.pack(fmt, w & 0xFFFF) for w in words)


def unpack_words(data: bytes, order: str = "big") -> list[int]:
    fmt = (">" if order == "big" else "<") + "H"
    return [struct.unpack_from(fmt, data, i)[0] for i in range(0, len(data) - 1, 2)]


def _s16(w: int) -> int:
    return w - 0x10000 if w & 0x8000 else w


# ---------------------------------------------------------------------------------------------------
# Run-command word (output bytes 0-1, spec §2.2) and drive status word (input bytes 0-1, spec §2.3)
# ---------------------------------------------------------------------------------------------------

COMMAND_BITS: dict[str, int] = {
    "forward_run": 0, "reverse_run": 1,
    "mfi3": 2, "mfi4": 3, "mfi5": 4, "mfi6": 5, "mfi7": 6, "mfi8": 7,
    "external_fault": 8, "fault_reset": 9,
    "mfi9": 10, "mfi10": 11, "mfi11": 12, "mfi12": 13,
    "clear_error_log": 14, "external_base_block": 15,
}
COMMAND_TEXT = {
    "forward_run": "forward run", "reverse_run": "reverse run",
    **{f"mfi{n}": f"multi-function input {n}" for n in range(3, 13)},
    "external_fault": "external fault (EF0)", "fault_reset": "fault reset",
    "clear_error_log": "clear error log", "external_base_block": "external base block",
}

STATUS_BITS: dict[str, int] = {
    "running": 0, "zero_speed": 1, "reverse": 2, "reset_signal": 3, "frequency_agree": 4,
    "ready": 5, "alarm": 6, "fault": 7, "ope_error": 8, "fault_restart": 9, "remote": 10,
    "mfo1": 11, "mfo2": 12, "mfo3": 13, "motor2_selected": 14, "zero_servo_complete": 15,
}
STATUS_TEXT = {
    "running": "running", "zero_speed": "zero speed", "reverse": "reverse",
    "reset_signal": "fault-reset input active", "frequency_agree": "frequency agree",
    "ready": "ready", "alarm": "alarm (minor fault)", "fault": "fault (major fault)",
    "ope_error": "OPE setting error", "fault_restart": "fault restart",
    "remote": "remote", "mfo1": "MF output 1 closed", "mfo2": "MF output 2 closed",
    "mfo3": "MF output 3 closed", "motor2_selected": "motor 2 selected",
    "zero_servo_complete": "zero-servo complete",
}

# extended1 output bytes 14-15 (E26: outputs in bits 0-7, bits 8-15 reserved)
MFO_BITS: dict[str, int] = {
    "output1": 0, "pch1": 1, "pch2": 2, "pch3": 3, "pch4": 4,
    "fault_contact_enable": 6, "fault_contact_state": 7,
}


def mfi_bit(n: int) -> int:
    """Command-word bit of multi-function input n (3..12)."""
    if not 3 <= n <= 12:
        raise ValueError(f"multi-function input {n}: the command word carries inputs 3..12")
    return COMMAND_BITS[f"mfi{n}"]


def encode_command(**flags: bool) -> int:
    w = 0
    for name, on in flags.items():
        if name not in COMMAND_BITS:
            raise ValueError(f"unknown command bit {name!r}")
        if on:
            w |= 1 << COMMAND_BITS[name]
    return w


def decode_bits(word: int, bits: dict[str, int]) -> dict[str, bool]:
    return {name: bool(word >> b & 1) for name, b in bits.items()}


def decode_command(word: int) -> dict[str, bool]:
    return decode_bits(word, COMMAND_BITS)


def decode_status(word: int) -> dict[str, bool]:
    return decode_bits(word, STATUS_BITS)


# ---------------------------------------------------------------------------------------------------
# Frequency scaling (spec §2.7, E2)
# ---------------------------------------------------------------------------------------------------


@dataclass
class FrequencyScale:
    """Counts <-> Hz for the reference word (master -> drive) and the frequency words drive -> master.

    o1-03 = 0: the manual's units, reference 0.01 Hz, feedback 0.1 Hz (per-profile override).
    o1-03 = 1: 0.01 % of max frequency; 2..39: r/min with o1-03 = motor poles; 40..39999: user units,
    the last four digits = the value at max frequency, the fifth = decimals (Yaskawa convention from
    sister manuals; both directions use the same unit).
    """

    o1_03: int = 0
    max_hz: float = 60.0
    reference_unit_hz: float = 0.01
    feedback_unit_hz: float = 0.1

    def _mode(self) -> str:
        if self.o1_03 == 1:
            return "percent"
        if 2 <= self.o1_03 <= 39:
            return "rpm"
        if self.o1_03 >= 40 and self.o1_03 % 10000:
            return "user"
        return "hz"

    def unit_text(self, direction: str) -> str:
        mode = self._mode()
        if mode == "hz":
            u = self.reference_unit_hz if direction == "reference" else self.feedback_unit_hz
            return f"{u:g} Hz"
        if mode == "percent":
            return "0.01 % of max frequency"
        if mode == "rpm":
            return f"1 r/min ({self.o1_03}-pole motor)"
        return f"user units ({self.o1_03 % 10000} counts = max frequency)"

    def _hz_per_count(self, direction: str) -> float:
        mode = self._mode()
        if mode == "hz":
            return self.reference_unit_hz if direction == "reference" else self.feedback_unit_hz
        if mode == "percent":
            return self.max_hz / 10000.0
        if mode == "rpm":
            return self.o1_03 / 120.0
        return self.max_hz / (self.o1_03 % 10000)

    def hz_to_raw(self, hz: float, direction: str = "reference") -> int:
        return int(round(abs(hz) / self._hz_per_count(direction)))

    def raw_to_hz(self, raw: int, direction: str = "feedback") -> float:
        return round(raw * self._hz_per_count(direction), 6)
