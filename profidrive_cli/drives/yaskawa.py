"""Yaskawa PROFIBUS-DP option SI-P1 (GPD515/G5, F7, P7, G7): codec and Drive.

Spec: ../shared/spec/yaskawa-profibus-dp.md ("spec §x" below). The card is not PROFIdrive: it has its own
3/16/6-word messages, a Yaskawa run-command word and status word, and parameter access to the drive's
MEMOBUS registers through a handshake byte, because the drive needs 10-15 ms per request.

Layouts (names fixed in docs/architecture.md), bytes each way:

    basic      cfg 72     6 bytes: out command, reference, torque ref   in status, speed feedback, current
    extended1  cfg 5F 6F  32 bytes: fast I/O 0-15, parameter access 16-31 (up to 4 registers)
    extended2  cfg 55 65  12 bytes: fast I/O 0-3,  parameter access 4-11  (1 register)

Parameter-access area (offsets inside the area; 16 bytes in extended1, 8 in extended2):

    0 function code (00 none, 03 read, 10 write; replies 83/90 = error)   1-2 start register MSB, LSB
    3 data quantity in bytes (2 per register)    4.. data words MSB first    last byte: handshake
    command HS byte: bit 7 = HS (toggled to submit)
    response HS byte: bit 7 = HS (echo), bits 6-5 STATUS (00 idle, 01 sending, 10 waiting, 11 done),
                      bits 4-1 watchdog counter (about every 64 ms)

Everything sans-IO is at module level (command/status words, frequency scaling, parameter area, the
ParamAccess handshake machine, decode_area); YaskawaDrive couples it with a CyclicChannel.

Decisions on the manual's errata are in the profile's `decisions:` list; the ones that shape code are
repeated where they apply ("E<n>" = the spec's errata number, §10).
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass, field
from typing import Any

from profidrive_cli import UsageError
from profidrive_cli.datafile import DataFileError, LineDict
from profidrive_cli.drives.values import raw_value_problem, value_problem
from profidrive_cli.drives.base import (Drive, DriveError, DriveStatus, FaultRecord, ParamError,
                                        ParamValue)

FAMILY = "yaskawa"

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


# ---------------------------------------------------------------------------------------------------
# Parameter-access area (spec §4)
# ---------------------------------------------------------------------------------------------------

FC_NONE, FC_READ, FC_WRITE = 0x00, 0x03, 0x10
FUNCTION_NAMES = {FC_NONE: "no request", FC_READ: "read", FC_WRITE: "write",
                  0x80 | FC_READ: "read error", 0x80 | FC_WRITE: "write error"}

# error code -> (name, meaning); own wording of the manual's Table 3.15 (E6: 0x03 read as "data quantity
# not allowed for this format")
ERROR_CODES: dict[int, tuple[str, str]] = {
    0x01: ("function error", "the function code is neither 03h (read) nor 10h (write)"),
    0x02: ("address error", "the drive has no such register (the manual: start address above 600h)"),
    0x03: ("data quantity error", "the data quantity is not allowed (2, 4, 6 or 8 bytes; "
                                  "Extended Data 2: 2 only)"),
    0x21: ("data content error", "the value is outside the parameter's lower/upper limit"),
    0x22: ("write fault", "writing is not allowed now: drive running or in under-voltage, ENTER "
                          "while running, read-only data, or parameters being stored"),
}

HS_STATUS_NAMES = {0: "idle", 1: "sending to drive", 2: "waiting for drive", 3: "response received"}


def error_text(code: int) -> str:
    name, meaning = ERROR_CODES.get(code, (f"unknown (0x{code:02X})", "not in the manual's table"))
    return f"0x{code:02X} {name}: {meaning}"


def decode_hs(b: int) -> tuple[int, int, int]:
    """Response handshake byte -> (HS, STATUS, WD). E9: STATUS is the 2-bit field in bits 6-5."""
    return (b >> 7) & 1, (b >> 5) & 3, (b >> 1) & 0x0F


@dataclass(frozen=True)
class ParamRequest:
    function: int                   # FC_READ or FC_WRITE
    start: int                      # first MEMOBUS register
    count: int                      # registers
    values: tuple[int, ...] = ()    # write data, one 16-bit value per register

    @classmethod
    def read(cls, start: int, count: int = 1) -> ParamRequest:
        return cls(FC_READ, start, count)

    @classmethod
    def write(cls, start: int, values) -> ParamRequest:
        vals = tuple(int(v) for v in values)
        return cls(FC_WRITE, start, len(vals), vals)

    def check(self, fmt: AreaFormat) -> None:
        if not fmt.has_params:
            raise DriveError(f"yaskawa {fmt.name}: this layout has no parameter access")
        if not 0 <= self.start <= 0xFFFF:
            raise UsageError(f"register 0x{self.start:X} is not a 16-bit register number")
        if not 1 <= self.count <= fmt.max_registers:
            raise UsageError(f"yaskawa {fmt.name}: {self.count} registers requested, this layout carries "
                             f"1..{fmt.max_registers} per request")
        if self.start + self.count - 1 > 0xFFFF:
            raise UsageError(f"registers 0x{self.start:04X}+{self.count} run past 0xFFFF")
        if self.function == FC_WRITE:
            if len(self.values) != self.count:
                raise UsageError("write request: one value per register")
            for v in self.values:
                if not 0 <= v <= 0xFFFF:
                    raise UsageError(f"value {v} does not fit a 16-bit register")
        elif self.function != FC_READ:
            raise UsageError(f"function code 0x{self.function:02X}: only 03h (read) and 10h (write)")

    def describe(self) -> str:
        regs = f"0x{self.start:04X}" + (f"..0x{self.start + self.count - 1:04X}" if self.count > 1 else "")
        if self.function == FC_READ:
            return f"read {regs}"
        return f"write {regs} := " + ", ".join(f"0x{v:04X}" for v in self.values)


def encode_param_area(fmt: AreaFormat, req: ParamRequest | None, hs: int) -> bytes:
    """The command area: FC, start MSB/LSB, data quantity, data words MSB first, reserved zeros, HS.

    E4: write data sits in the data words (bytes 20-27 / 8-9); for a read they are all zero.
    """
    a = bytearray(fmt.param_len)
    if req is not None:
        a[0] = req.function
        a[1], a[2] = req.start >> 8 & 0xFF, req.start & 0xFF
        a[3] = 2 * req.count
        if req.function == FC_WRITE:
            for i, v in enumerate(req.values[:fmt.max_registers]):
                a[4 + 2 * i], a[5 + 2 * i] = v >> 8 & 0xFF, v & 0xFF
    a[-1] = 0x80 if hs else 0x00        # only bit 7 is used in the command HS byte
    return bytes(a)


@dataclass
class ParamArea:
    """A decoded parameter-access area (either direction)."""
    function: int
    start: int
    quantity: int
    data: list[int]
    hs_byte: int

    @classmethod
    def parse(cls, fmt: AreaFormat, area: bytes) -> ParamArea:
        data = [area[4 + 2 * i] << 8 | area[5 + 2 * i] for i in range(fmt.max_registers)]
        return cls(area[0], area[1] << 8 | area[2], area[3], data, area[-1])

    @property
    def is_error(self) -> bool:        # E5: error replies are the function code OR 0x80
        return bool(self.function & 0x80)

    @property
    def error_code(self) -> int:       # error code in the low byte of data 1 (byte 21 / 9)
        return self.data[0] & 0xFF if self.data else 0


@dataclass
class ParamResult:
    request: ParamRequest
    ok: bool
    values: list[int] = field(default_factory=list)
    error_code: int | None = None
    timeout: bool = False
    message: str = ""


class ParamAccess:
    """Sans-IO parameter access over the handshake byte (spec §4.7 and E11).

    Per cycle: put outputs() into the parameter-access area of the output image, exchange, then
    feed(input area, now); feed returns a ParamResult once the request has completed, failed or timed
    out, else None. submit() starts a request (one at a time).

    Phases: align (function code 00h, command HS set once to the response HS) -> load (request in the
    area, HS unchanged, settle_cycles exchanges) -> wait (HS toggled; done when the response HS equals
    the command HS and STATUS = 11) -> idle (function code 00h, HS held).
    """

    def __init__(self, fmt: AreaFormat, timeout: float = 1.0, settle_cycles: int = 1, hs: int = 0):
        if not fmt.has_params:
            raise ValueError(f"yaskawa {fmt.name}: no parameter-access area")
        self.fmt = fmt
        self.timeout = timeout
        self.settle_cycles = max(1, settle_cycles)
        self.hs = hs & 1                 # E11: the command HS starts cleared unless told otherwise
        self.phase = "align"
        self.request: ParamRequest | None = None
        self.realignments = 0
        self._settled = 0
        self._hold = 0
        self._deadline = 0.0
        self._wd: int | None = None
        self._wd_changed = 0.0

    @property
    def busy(self) -> bool:
        return self.request is not None

    def submit(self, request: ParamRequest, now: float) -> None:
        if self.request is not None:
            raise DriveError("a parameter request is already in progress")
        request.check(self.fmt)
        self.request = request
        self._deadline = now + self.timeout
        self._settled = 0
        if self.phase == "idle":
            self.phase = "load"

    def outputs(self) -> bytes:
        loaded = self.request if self.phase in ("load", "wait") else None
        return encode_param_area(self.fmt, loaded, self.hs)

    def feed(self, area: bytes, now: float) -> ParamResult | None:
        if len(area) != self.fmt.param_len:
            raise ValueError(f"parameter area is {len(area)} octets, {self.fmt.name} has {self.fmt.param_len}")
        hs, status, wd = decode_hs(area[-1])
        if wd != self._wd:
            self._wd, self._wd_changed = wd, now
        in_progress = status in (1, 2)

        if self.phase in ("align", "idle"):
            if in_progress:
                pass                          # an earlier request is still running: let it finish
            elif hs != self.hs:
                self.phase = "align"
                if self._hold:
                    self._hold -= 1
                else:
                    # E11: take over the option's HS while the area carries function code 00h, so
                    # the change starts no request; then do not realign again for two cycles, so
                    # that a late echo of our own earlier HS is not chased
                    self.hs = hs
                    self.realignments += 1
                    self._hold = 2
            else:
                self._hold = 0
                self.phase = "load" if self.request is not None else "idle"
        elif self.phase == "load":
            if hs == self.hs and not in_progress:
                self._settled += 1
                if self._settled >= self.settle_cycles:
                    self.hs ^= 1              # spec §4.7 step 4: toggle and hold
                    self.phase = "wait"
            else:
                # the response HS moved under a loaded request: back to 00h and realign first
                self._settled = 0
                self.phase = "align"
        elif self.phase == "wait":
            if hs == self.hs and status == 3:
                return self._finish(self._complete(ParamArea.parse(self.fmt, area)))

        if self.request is not None and now > self._deadline:
            return self._finish(self._timed_out(now))
        return None

    def _finish(self, result: ParamResult) -> ParamResult:
        self.request = None
        if result.timeout:
            # the state of the option is unknown: realign before the next request
            self.phase = "align"
        else:
            self.phase = "idle"
        return result

    def _complete(self, resp: ParamArea) -> ParamResult:
        req = self.request
        assert req is not None
        if resp.is_error:
            code = resp.error_code
            fn = FUNCTION_NAMES.get(resp.function & 0x7F, f"function 0x{resp.function & 0x7F:02X}")
            return ParamResult(req, False, error_code=code,
                               message=f"{req.describe()}: {fn} refused, error {error_text(code)}")
        # address is echoed only in normal replies (spec §4.3: not checked on errors)
        if resp.function != req.function or resp.start != req.start:
            return ParamResult(req, False, message=(
                f"{req.describe()}: the reply (function 0x{resp.function:02X}, register "
                f"0x{resp.start:04X}) does not match the request"))
        values = resp.data[:req.count] if req.function == FC_READ else []
        return ParamResult(req, True, values=values)

    def _timed_out(self, now: float) -> ParamResult:
        req = self.request
        assert req is not None
        where = {"align": "waiting for the option's handshake to settle",
                 "load": "loading the request", "wait": "waiting for STATUS 11 with our HS"}[self.phase]
        msg = f"{req.describe()}: no reply within {self.timeout:g} s ({where})"
        if now - self._wd_changed > 0.2 and self._wd is not None:
            msg += "; the handshake watchdog counter is frozen: the option CPU may have stopped"
        return ParamResult(req, False, timeout=True, message=msg)


# ---------------------------------------------------------------------------------------------------
# Family keys of the profile (validated with file:line)
# ---------------------------------------------------------------------------------------------------

LED_STATES = ("off", "green", "red", "green-flash", "red-flash")
REGISTER_SOURCES = ("printed", "inferred", "external")
ALARM_KINDS = ("fault", "ope", "cpf", "alarm")


@dataclass
class YaskawaConfig:
    reference_unit_hz: float = 0.01
    feedback_unit_hz: float = 0.1
    o1_03: int = 0
    rated_current_a: float | None = None
    fast_stop_input: int | None = None
    timeout_s: float = 1.0
    settle_cycles: int = 1
    enter_register: int | None = None
    fault_history: list[tuple[str, str]] = field(default_factory=list)   # (position, param code)
    alarm_kinds: dict[str, str] = field(default_factory=dict)            # code -> fault|ope|cpf|alarm
    led_diagnostics: list[dict] = field(default_factory=list)


def _num(path, node: LineDict, key, default, types=(int, float), allow_none=False):
    if key not in node:
        return default
    v = node[key]
    if v is None and allow_none:
        return None
    if isinstance(v, bool) or not isinstance(v, types):
        raise DataFileError(path, node.line_of(key), f"'{key}' must be a number, got {v!r}")
    return v


def family_config(profile) -> YaskawaConfig:
    """Validate and return the Yaskawa keys of a profile (cached on the profile object)."""
    cached = getattr(profile, "_yaskawa_config", None)
    if cached is not None:
        return cached
    path = profile.path or profile.name
    raw = profile.raw if isinstance(profile.raw, LineDict) else LineDict()
    cfg = YaskawaConfig()

    layouts_node = raw.get("layouts")
    for name, lay in profile.layouts.items():
        line = layouts_node.line_of(name) if isinstance(layouts_node, LineDict) else None
        lnode = layouts_node.get(name) if isinstance(layouts_node, LineDict) else None
        if name not in FORMATS:
            raise DataFileError(path, line, f"layout '{name}': the yaskawa codec knows "
                                f"{', '.join(FORMATS)}")
        if lay.cfg != FORMATS[name].cfg:
            if isinstance(lnode, LineDict):
                line = lnode.line_of("cfg")
            raise DataFileError(path, line, f"layout '{name}': cfg must be {FORMATS[name].cfg.hex(' ').upper()}")

    y = raw.get("yaskawa", LineDict())
    if not isinstance(y, LineDict):
        raise DataFileError(path, raw.line_of("yaskawa"), "'yaskawa' must be a mapping")
    cfg.reference_unit_hz = float(_num(path, y, "reference_unit_hz", cfg.reference_unit_hz))
    cfg.feedback_unit_hz = float(_num(path, y, "feedback_unit_hz", cfg.feedback_unit_hz))
    for k in ("reference_unit_hz", "feedback_unit_hz"):
        if getattr(cfg, k) <= 0:
            raise DataFileError(path, y.line_of(k), f"'{k}' must be > 0")
    cfg.o1_03 = _num(path, y, "o1_03", 0, int)
    if not 0 <= cfg.o1_03 <= 39999:
        raise DataFileError(path, y.line_of("o1_03"), "'o1_03' must be 0..39999")
    rc = _num(path, y, "rated_current_a", None, allow_none=True)
    if rc is not None and rc <= 0:
        raise DataFileError(path, y.line_of("rated_current_a"), "'rated_current_a' must be > 0 or null")
    cfg.rated_current_a = None if rc is None else float(rc)
    fs = _num(path, y, "fast_stop_input", None, int, allow_none=True)
    if fs is not None and not 3 <= fs <= 12:
        raise DataFileError(path, y.line_of("fast_stop_input"),
                            "'fast_stop_input' must be a multi-function input 3..12 or null")
    cfg.fast_stop_input = fs

    hsn = y.get("handshake", LineDict())
    if not isinstance(hsn, LineDict):
        raise DataFileError(path, y.line_of("handshake"), "'handshake' must be a mapping")
    cfg.timeout_s = float(_num(path, hsn, "timeout_s", 1.0))
    cfg.settle_cycles = _num(path, hsn, "settle_cycles", 1, int)
    if cfg.timeout_s <= 0 or cfg.settle_cycles < 1:
        raise DataFileError(path, hsn.line, "handshake: timeout_s must be > 0 and settle_cycles >= 1")

    en = y.get("enter_register")
    if en is not None:
        if not isinstance(en, LineDict) or not isinstance(en.get("register"), int):
            raise DataFileError(path, y.line_of("enter_register"),
                                "'enter_register' must be a mapping with an integer 'register'")
        _check_source(path, en)
        cfg.enter_register = en["register"]

    fh = y.get("fault_history", [])
    if not isinstance(fh, list):
        raise DataFileError(path, y.line_of("fault_history"), "'fault_history' must be a list")
    for i, item in enumerate(fh):
        line = fh.line_of(i) if hasattr(fh, "line_of") else None
        if not isinstance(item, LineDict) or not isinstance(item.get("position"), str) \
                or not isinstance(item.get("param"), str):
            raise DataFileError(path, line, "fault_history entries need 'position' and 'param' (strings)")
        p = profile.param(item["param"])
        if p is None or p.register is None:
            raise DataFileError(path, item.line_of("param"),
                                f"fault_history: {item['param']} is not a parameter with a register")
        cfg.fault_history.append((item["position"], p.code))

    for code, p in profile.parameters.items():
        node = _param_node(raw, p.line)
        src = p.extra.get("register_source")
        if src is not None and src not in REGISTER_SOURCES:
            raise DataFileError(path, node.line_of("register_source") if node else p.line,
                                f"{code}: register_source must be one of {', '.join(REGISTER_SOURCES)}")
        vals = p.extra.get("values")
        if vals is not None and not isinstance(vals, dict):
            raise DataFileError(path, node.line_of("values") if node else p.line,
                                f"{code}: 'values' must be a mapping of value -> meaning")
        if p.register is not None and not 0 <= p.register <= 0xFFFF:
            raise DataFileError(path, node.line_of("register") if node else p.line,
                                f"{code}: register must be 0..0xFFFF")

    alarms = raw.get("alarms", [])
    for i, a in enumerate(alarms if isinstance(alarms, list) else []):
        if not isinstance(a, LineDict):
            continue
        kind = a.get("kind", "fault")
        if kind not in ALARM_KINDS:
            raise DataFileError(path, a.line_of("kind"), f"alarm kind must be one of {', '.join(ALARM_KINDS)}")
        cfg.alarm_kinds[str(a.get("code")).upper()] = kind

    leds = raw.get("led_diagnostics", [])
    if not isinstance(leds, list):
        raise DataFileError(path, raw.line_of("led_diagnostics"), "'led_diagnostics' must be a list")
    for item in leds:
        if not isinstance(item, LineDict):
            raise DataFileError(path, getattr(item, "line", None), "an LED row must be a mapping")
        for k in ("pwr", "com", "err", "wd"):
            if item.get(k) is False:        # YAML 1.1 reads a bare `off` as false
                item[k] = "off"
            if item.get(k) not in LED_STATES:
                raise DataFileError(path, item.line_of(k) if k in item else item.line,
                                    f"LED row: '{k}' must be one of {', '.join(LED_STATES)}")
        if not isinstance(item.get("condition"), str):
            raise DataFileError(path, item.line, "LED row: 'condition' (text) is missing")
        cfg.led_diagnostics.append({k: str(v) for k, v in item.items()})

    decisions = raw.get("decisions", [])
    if not isinstance(decisions, list) or not all(isinstance(d, str) for d in decisions):
        raise DataFileError(path, raw.line_of("decisions"), "'decisions' must be a list of strings")

    try:
        profile._yaskawa_config = cfg
    except AttributeError:   # pragma: no cover - a frozen profile object
        pass
    return cfg


def _check_source(path, node: LineDict) -> None:
    src = node.get("register_source")
    if src is not None and src not in REGISTER_SOURCES:
        raise DataFileError(path, node.line_of("register_source"),
                            f"register_source must be one of {', '.join(REGISTER_SOURCES)}")


def _param_node(raw: LineDict, line: int) -> LineDict | None:
    for node in raw.get("parameters", []) or []:
        if isinstance(node, LineDict) and node.line == line:
            return node
    return None


def led_diagnosis(profile, pwr: str, com: str, err: str, wd: str) -> dict:
    """The LED table row for a state (pwr, com, err, wd), or an 'unspecified' row (spec §1.7)."""
    for row in family_config(profile).led_diagnostics:
        if (row["pwr"], row["com"], row["err"], row["wd"]) == (pwr, com, err, wd):
            return row
    return {"pwr": pwr, "com": com, "err": err, "wd": wd, "condition": "Unspecified option error",
            "cause": "LED combination not in the manual's table", "remedy": "Treat as an option fault"}


def register_name(profile, reg: int) -> str | None:
    for p in profile.parameters.values():
        if p.register == reg:
            return p.code
    return None


# ---------------------------------------------------------------------------------------------------
# decode_area: captured areas -> named fields (pdrive decode)
# ---------------------------------------------------------------------------------------------------


def _flags_text(word: int, flags: dict[str, bool], names: dict[str, str]) -> str:
    on = [names.get(k, k) for k, v in flags.items() if v]
    return f"0x{word:04X}" + (": " + ", ".join(on) if on else ": (none)")


def _reg_label(profile, reg: int) -> str:
    n = register_name(profile, reg)
    return f"0x{reg:04X}" + (f" ({n})" if n else "")


def decode_area(profile, layout: str, direction: str, data: bytes) -> dict:
    """Decode one captured output area (direction "request") or input area ("response")."""
    if layout not in FORMATS or layout not in profile.layouts:
        raise UsageError(f"{profile.name}: no layout '{layout}' (known: {', '.join(profile.layouts)})")
    if direction not in ("request", "response"):
        raise UsageError(f"direction must be request or response, got {direction!r}")
    fmt = FORMATS[layout]
    data = bytes(data)
    if len(data) != fmt.size:
        raise UsageError(f"{profile.name} {layout}: a {direction} area is {fmt.size} octets, got {len(data)}")
    cfg = family_config(profile)
    fmax = float(profile.max_frequency_default)
    scale = FrequencyScale(cfg.o1_03, fmax, cfg.reference_unit_hz, cfg.feedback_unit_hz)
    names = fmt.out_words if direction == "request" else fmt.in_words
    fast = data[:2 * len(names)]
    words = dict(zip(names, unpack_words(fast, profile.word_order)))
    out: dict[str, Any] = {"profile": profile.name, "layout": layout, "direction": direction,
                           "word_order": profile.word_order, "words": dict(words)}
    text: list[str] = []

    for name, w in words.items():
        if name == "command":
            fl = decode_command(w)
            out["command"] = {"raw": w, "flags": fl}
            text.append("run command " + _flags_text(w, fl, COMMAND_TEXT))
            if fl["forward_run"] and fl["reverse_run"]:
                text.append("  forward and reverse together: the drive stops and shows an alarm")
        elif name == "status":
            fl = decode_status(w)
            out["status"] = {"raw": w, "flags": fl}
            text.append("drive status " + _flags_text(w, fl, STATUS_TEXT))
        elif name == "reference":
            hz = scale.raw_to_hz(w, "reference")
            out["frequency_reference"] = {"raw": w, "hz": hz, "unit": scale.unit_text("reference")}
            text.append(f"frequency reference {w} = {hz:g} Hz ({scale.unit_text('reference')}/count, "
                        f"o1-03 = {cfg.o1_03} assumed)")
        elif name in ("speed_feedback", "frequency_reference", "output_frequency"):
            hz = scale.raw_to_hz(w, "feedback")
            out[name] = {"raw": w, "hz": hz, "unit": scale.unit_text("feedback")}
            label = {"speed_feedback": "speed feedback", "frequency_reference": "frequency reference (drive)",
                     "output_frequency": "output frequency"}[name]
            text.append(f"{label} {w} = {hz:g} Hz ({scale.unit_text('feedback')}/count)")
        elif name in ("torque_reference", "torque_compensation"):
            pct = round(_s16(w) * 0.1, 1)
            out[name] = {"raw": w, "percent": pct}
            text.append(f"{name.replace('_', ' ')} {_s16(w)} = {pct:g} % (flux-vector control only)")
        elif name == "output_current":
            pct = round(w * 100.0 / 8192, 2)
            entry: dict[str, Any] = {"raw": w, "percent_of_rating": pct}
            line = f"output current {w} = {pct:g} % of the drive rating"
            if cfg.rated_current_a:
                entry["amps"] = round(w * cfg.rated_current_a / 8192, 3)
                line += f" = {entry['amps']:g} A"
            out[name] = entry
            text.append(line)
        elif name in ("analog_out1", "analog_out2", "analog_in1"):
            out[name] = {"raw": w, "signed": _s16(w)}
            text.append(f"{name.replace('_', ' ')} {_s16(w)} (count scaling not given by the manual)")
        elif name == "pg_count":
            out[name] = {"raw": w, "signed": _s16(w)}
            text.append(f"PG count {_s16(w)}")
        elif name == "mf_outputs":
            fl = decode_bits(w, MFO_BITS)
            out[name] = {"raw": w, "flags": fl}
            text.append("MF outputs " + _flags_text(w, fl, {}))
            if w & 0xFF00:
                text.append("  bits 8-15 are reserved but set")
        elif name == "reserved":
            out[name] = w
            if w:
                text.append(f"reserved word 0x{w:04X} (should be 0)")

    if fmt.has_params:
        area = data[fmt.param_offset:]
        pa, ptext = _decode_param(profile, fmt, direction, area)
        out["parameter_access"] = pa
        text.extend(ptext)
    out["text"] = text
    return out


def _decode_param(profile, fmt: AreaFormat, direction: str, area: bytes) -> tuple[dict, list[str]]:
    p = ParamArea.parse(fmt, area)
    fn = p.function
    d: dict[str, Any] = {"function": fn, "function_name": FUNCTION_NAMES.get(fn, "invalid"),
                         "start_register": p.start, "data_quantity": p.quantity, "data": p.data}
    text: list[str] = []
    nregs = p.quantity // 2 if p.quantity % 2 == 0 else 0
    if direction == "request":
        hs = area[-1] >> 7 & 1
        d["handshake"] = {"raw": area[-1], "hs": hs}
        if fn == FC_NONE:
            text.append(f"parameter access: no request (HS {hs})")
        elif fn in (FC_READ, FC_WRITE):
            what = "read" if fn == FC_READ else "write"
            line = f"parameter access: {what} {nregs or '?'} register(s) from {_reg_label(profile, p.start)} (HS {hs})"
            text.append(line)
            if p.quantity not in fmt.data_quantities:
                text.append(f"  data quantity {p.quantity} is not allowed here "
                            f"({'/'.join(map(str, fmt.data_quantities))}): the drive answers 0x03")
            if fn == FC_WRITE:
                for i, v in enumerate(p.data[:max(1, min(nregs, fmt.max_registers))]):
                    text.append(f"  {_reg_label(profile, p.start + i)} := 0x{v:04X} ({v})")
            elif any(p.data):
                text.append("  data words should be 0 in a read request")
        else:
            text.append(f"parameter access: function code 0x{fn:02X} is invalid (drive answers 0x01)")
        if area[-1] & 0x7F:
            text.append(f"  handshake bits 6-0 should be 0 (0x{area[-1]:02X})")
        return d, text

    hs, status, wd = decode_hs(area[-1])
    d["handshake"] = {"raw": area[-1], "hs": hs, "status": status, "status_name": HS_STATUS_NAMES[status],
                      "wd": wd, "complete": status == 3}
    text.append(f"handshake 0x{area[-1]:02X}: HS {hs}, STATUS {status:02b} ({HS_STATUS_NAMES[status]}), "
                f"watchdog {wd}")
    valid = "" if status == 3 else " (not valid yet: STATUS is not 11)"
    if fn == FC_NONE:
        text.append("parameter access: no reply data")
    elif p.is_error and (fn & 0x7F) in (FC_READ, FC_WRITE):
        code = p.error_code
        name, meaning = ERROR_CODES.get(code, (f"unknown (0x{code:02X})", "not in the manual's table"))
        d.update({"error": True, "error_code": code, "error_name": name, "error_meaning": meaning})
        text.append(f"parameter access: {FUNCTION_NAMES[fn]}, code {error_text(code)}{valid}")
    elif fn in (FC_READ, FC_WRITE):
        d["error"] = False
        if fn == FC_READ:
            vals = p.data[:max(0, min(nregs, fmt.max_registers))]
            d["values"] = vals
            text.append(f"parameter access: read reply from {_reg_label(profile, p.start)}{valid}")
            for i, v in enumerate(vals):
                text.append(f"  {_reg_label(profile, p.start + i)} = 0x{v:04X} ({v})")
        else:
            text.append(f"parameter access: write to {_reg_label(profile, p.start)} accepted "
                        f"({nregs} register(s)){valid}")
    else:
        text.append(f"parameter access: function code 0x{fn:02X} is not a valid reply")
    return d, text


# ---------------------------------------------------------------------------------------------------
# Drive
# ---------------------------------------------------------------------------------------------------

_REG_RE = re.compile(r"^REG(?:0X([0-9A-F]{1,4})|([0-9]{1,5}))$", re.IGNORECASE)


def parse_register_code(code: str) -> int | None:
    """'REG0x0180' (hex) or 'REG384' (decimal) -> register number; None if not that form."""
    m = _REG_RE.match(code.strip())
    if not m:
        return None
    return int(m.group(1), 16) if m.group(1) else int(m.group(2))


class YaskawaDrive(Drive):
    family = FAMILY

    def __init__(self, channel, profile, layout: str | None = None):
        super().__init__(channel, profile, layout)
        if self.layout not in profile.layouts or self.layout not in FORMATS:
            raise UsageError(f"{profile.name}: no layout '{self.layout}' (known: {', '.join(profile.layouts)})")
        self.cfg = family_config(profile)
        self.fmt = FORMATS[self.layout]
        self.order = profile.word_order
        self.params = (ParamAccess(self.fmt, self.cfg.timeout_s, self.cfg.settle_cycles)
                       if self.fmt.has_params else None)
        self._result: ParamResult | None = None
        # command state
        self._run = False
        self._ref_percent = 0.0
        self._ref_raw = 0
        self._base_block = False
        self._fast_stop = False
        self._external_fault = False
        self._mfi: set[int] = set()
        self._pulses: dict[int, int] = {}
        self.torque_reference = 0.0          # % (flux vector only)
        # cached drive settings (read through the handshake when there is a parameter channel)
        self._fmax: float | None = None
        self._o1_03: int | None = None
        self.last: DriveStatus | None = None

    # -- cyclic --------------------------------------------------------------------------------
    @property
    def has_param_channel(self) -> bool:
        return self.fmt.has_params

    def command_word(self) -> int:
        w = 0
        if self._run:
            w |= 1 << (COMMAND_BITS["reverse_run"] if self._ref_percent < 0 else COMMAND_BITS["forward_run"])
        if self._base_block:
            w |= 1 << COMMAND_BITS["external_base_block"]
        if self._external_fault:
            w |= 1 << COMMAND_BITS["external_fault"]
        for n in self._mfi:
            w |= 1 << mfi_bit(n)
        if self._fast_stop and self.cfg.fast_stop_input:
            w |= 1 << mfi_bit(self.cfg.fast_stop_input)
        for bit, left in self._pulses.items():
            if left > 0:
                w |= 1 << bit
        return w

    def output_image(self) -> bytes:
        vals = {"command": self.command_word(), "reference": self._ref_raw,
                "torque_reference": int(round(self.torque_reference * 10)) & 0xFFFF}
        img = pack_words([vals.get(n, 0) for n in self.fmt.out_words], self.order)
        if self.params is not None:
            img += bytes(self.fmt.param_offset - len(img)) + self.params.outputs()
        return img

    def cycle(self) -> DriveStatus:
        inputs = self.channel.exchange(self.output_image())
        if len(inputs) != self.fmt.size:
            raise DriveError(f"yaskawa {self.layout}: station answered {len(inputs)} octets, "
                             f"expected {self.fmt.size}")
        for bit in list(self._pulses):
            self._pulses[bit] -= 1
            if self._pulses[bit] <= 0:
                del self._pulses[bit]
        if self.params is not None:
            r = self.params.feed(inputs[self.fmt.param_offset:], self.channel.now())
            if r is not None:
                self._result = r
        self.last = self._decode(inputs)
        return self.last

    def _scale(self) -> FrequencyScale:
        o1 = self._o1_03 if self._o1_03 is not None else self.cfg.o1_03
        fmax = self._fmax if self._fmax is not None else float(self.profile.max_frequency_default)
        return FrequencyScale(o1, fmax, self.cfg.reference_unit_hz, self.cfg.feedback_unit_hz)

    def _decode(self, inputs: bytes) -> DriveStatus:
        names = self.fmt.in_words
        words = dict(zip(names, unpack_words(inputs[:2 * len(names)], self.order)))
        fl = decode_status(words["status"])
        scale = self._scale()
        hz = scale.raw_to_hz(words["speed_feedback"], "feedback")
        if fl["reverse"]:
            hz = -hz
        pct = round(100.0 * hz / scale.max_hz, 3) if scale.max_hz else None
        ref_pct = self._ref_percent
        if "frequency_reference" in words and scale.max_hz:
            ref_hz = scale.raw_to_hz(words["frequency_reference"], "feedback")
            ref_pct = round(100.0 * ref_hz / scale.max_hz * (-1 if self._ref_percent < 0 else 1), 3)
        if fl["fault"]:
            state = "fault"
        elif fl["ope_error"]:
            state = "OPE setting error"
        elif fl["running"]:
            state = "running reverse" if fl["reverse"] else "running forward"
        elif self._base_block:
            state = "base block"
        elif not fl["ready"]:
            state = "not ready"
        else:
            state = "stopped"
        return DriveStatus(state=state, running=fl["running"], fault=fl["fault"], flags=fl,
                           speed_percent=pct, speed_hz=hz, reference_percent=ref_pct,
                           raw=dict(words))

    # -- motion --------------------------------------------------------------------------------
    def _hint_not_remote(self, st: DriveStatus) -> str:
        if st.flags.get("remote"):
            return ""
        return ("; the status word says local: the drive takes its run command from the bus only "
                "when b1-02 = 3 (option card)")

    def start(self, timeout: float = 5.0) -> DriveStatus:
        st = self.cycle()
        if st.fault:
            raise DriveError("yaskawa: the drive is in fault; reset it first (pdrive reset)")
        self._prepare_reference()
        self._base_block = False
        self._fast_stop = False
        self._run = True
        try:
            st = self.cycles_until(lambda s: s.running or s.fault, timeout, "the drive to run")
        except DriveError as e:
            raise DriveError(f"{e}{self._hint_not_remote(self.last or st)}") from None
        if st.fault:
            self._run = False
            raise DriveError(f"yaskawa: the drive tripped while starting{self._fault_suffix()}")
        return st

    def stop(self, mode: str = "normal", wait: bool = True, timeout: float = 30.0) -> DriveStatus:
        if mode == "quick":
            if self.cfg.fast_stop_input is None:
                raise DriveError("yaskawa SI-P1: the command word has no fast-stop bit; program a "
                                 "multi-function input for fast stop and name it in the profile "
                                 "(yaskawa.fast_stop_input), or use a normal or coast stop")
            self._fast_stop = True
        elif mode == "coast":
            self._base_block = True     # external base block: output cut, the motor coasts
        elif mode != "normal":
            raise UsageError(f"stop mode must be normal, quick or coast, got {mode!r}")
        self._run = False               # run bit off: the drive stops by b1-03 (ramp by default)
        if not wait:
            return self.cycle()
        st = self.cycles_until(lambda s: (not s.running and s.flags["zero_speed"]) or s.fault,
                               timeout, "the drive to stop")
        self._fast_stop = False
        return st

    def set_speed(self, percent: float) -> None:
        if not -100.0 <= percent <= 100.0:
            raise UsageError(f"speed {percent:g} % is outside -100..100 % of the maximum frequency")
        self._ref_percent = float(percent)
        self._prepare_reference()

    def _prepare_reference(self) -> None:
        if self.has_param_channel:
            self._read_units()
        scale = self._scale()
        hz = abs(self._ref_percent) / 100.0 * scale.max_hz
        self._ref_raw = min(scale.hz_to_raw(hz, "reference"), 0xFFFF)

    def _read_units(self) -> None:
        if self._fmax is None:
            self._fmax = self.max_frequency()
        if self._o1_03 is None:
            p = self.profile.param("o1-03")
            self._o1_03 = int(self.read_param("o1-03").raw) if p is not None and p.register is not None \
                else self.cfg.o1_03

    def set_mfi(self, n: int, on: bool) -> None:
        """Multi-function input n (3..12) of the command word (its function is set in the drive)."""
        mfi_bit(n)
        (self._mfi.add if on else self._mfi.discard)(n)

    def external_fault(self, on: bool = True) -> None:
        """Command-word bit 8: the drive trips with EF0 while it is set."""
        self._external_fault = on

    def reset_fault(self, timeout: float = 5.0) -> DriveStatus:
        self._run = False
        self._external_fault = False
        self._pulses[COMMAND_BITS["fault_reset"]] = 2     # a pulse, never left set
        while self._pulses:
            self.cycle()
        try:
            return self.cycles_until(lambda s: not s.fault, timeout, "the fault to clear")
        except DriveError:
            raise DriveError(f"yaskawa: the fault is still present after the reset pulse; remove its "
                             f"cause first{self._fault_suffix()}") from None

    def clear_error_log(self) -> None:
        """Pulse command-word bit 14 (Clear Error Log)."""
        self._pulses[COMMAND_BITS["clear_error_log"]] = 2
        while self._pulses:
            self.cycle()

    def status(self) -> DriveStatus:
        st = self.cycle()
        if st.fault and self.has_param_channel:
            code = self._current_fault_code()
            if code:
                st.fault_code = code
        return st

    def _current_fault_code(self) -> str | None:
        cur = next((c for pos, c in self.cfg.fault_history if pos == "current"), None)
        if cur is None:
            return None
        try:
            raw = self.read_param(cur).raw
        except DriveError:
            return None
        if not raw:
            return None
        al = self.profile.alarms_for(raw)
        return "/".join(a.code for a in al) if al else f"0x{raw:04X}"

    def _fault_suffix(self) -> str:
        if not self.has_param_channel:
            return ""
        code = self._current_fault_code()
        return f" (fault {code})" if code else ""

    # -- parameters ----------------------------------------------------------------------------
    def _no_channel(self) -> DriveError:
        return DriveError("yaskawa basic layout (3 words) has no parameter access; configure "
                          "extended1 (16 words) or extended2 (6 words)")

    def _transact(self, req: ParamRequest) -> ParamResult:
        if self.params is None:
            raise self._no_channel()
        self._result = None
        self.params.submit(req, self.channel.now())
        while self._result is None:
            self.cycle()
        r, self._result = self._result, None
        if r.timeout:
            raise DriveError(f"yaskawa: {r.message}")
        if not r.ok:
            raise ParamError(f"yaskawa: {r.message}", r.error_code)
        return r

    def read_registers(self, start: int, count: int = 1) -> list[int]:
        """Read `count` consecutive MEMOBUS registers (extended1: up to 4 per request)."""
        if self.params is None:
            raise self._no_channel()
        out: list[int] = []
        while count > 0:
            n = min(count, self.fmt.max_registers)
            out += self._transact(ParamRequest.read(start, n)).values
            start, count = start + n, count - n
        return out

    def write_registers(self, start: int, values) -> None:
        if self.params is None:
            raise self._no_channel()
        values = list(values)
        while values:
            chunk, values = values[:self.fmt.max_registers], values[self.fmt.max_registers:]
            self._transact(ParamRequest.write(start, chunk))
            start += len(chunk)

    def _resolve(self, code: str):
        reg = parse_register_code(code)
        if reg is not None:
            if reg > 0xFFFF:
                raise UsageError(f"{code}: register numbers are 16 bits")
            return reg, None
        p = self.profile.param(code)
        if p is None:
            raise UsageError(f"{self.profile.name}: unknown parameter {code!r} (use a code from the "
                             f"profile or a raw register such as REG0x0180)")
        if p.register is None:
            raise DriveError(f"{p.code}: the profile gives no MEMOBUS register for it")
        return p.register, p

    def _value(self, code: str, p, raw: int) -> ParamValue:
        if p is None:
            n = register_name(self.profile, self._resolve(code)[0])
            reg = parse_register_code(code)
            return ParamValue(code=f"REG0x{reg:04X}", name=f"MEMOBUS register{' (' + n + ')' if n else ''}",
                              raw=raw, value=raw)
        return ParamValue(code=p.code, name=p.name, raw=raw, value=p.from_raw(raw), unit=p.unit)

    def read_param(self, code: str) -> ParamValue:
        if self.params is None:
            raise self._no_channel()
        reg, p = self._resolve(code)
        raw = self.read_registers(reg, 1)[0]
        return self._value(code, p, raw)

    def write_param(self, code: str, value: float | int) -> ParamValue:
        if self.params is None:
            raise self._no_channel()
        reg, p = self._resolve(code)
        msg = self.check_value(p, value) if p is not None else raw_value_problem(code, value, 16)
        if msg:
            raise UsageError(msg)
        if p is not None:
            if not p.writable:
                raise DriveError(f"{p.code} ({p.name}) is read-only")
            raw = p.to_raw(value)
            if p.signed and raw < 0:
                raw += 0x10000
        else:
            if float(value) != int(value):
                raise UsageError(f"{code}: raw register values are integers, got {value!r}")
            raw = int(value)
        if not 0 <= raw <= 0xFFFF:
            raise UsageError(f"{code}: {value!r} does not fit a 16-bit register")
        # The profile's limits were checked above (exact value, listed codes, min..max); the drive's own
        # limits (they differ between F7, G7, P7 and depend on other settings) may be narrower: its
        # refusal (0x21 / 0x22) is explained below.
        try:
            self.write_registers(reg, [raw])
        except ParamError as e:
            raise ParamError(self._explain(code, p, value, e), e.number) from None
        if p is not None and p.code.upper() in ("E1-04", "O1-03") or reg in self._unit_registers():
            self._fmax = None
            self._o1_03 = None
        return self.read_param(code)

    def check_value(self, p, value) -> str | None:
        """The exact-value check (drives/values.py) against the profile's entry: resolution, the
        listed codes, min..max, the 16-bit register. The drive may still refuse a value its own
        limits (which differ between F7, G7 and P7) do not allow."""
        return value_problem(p, value)

    def _unit_registers(self) -> set[int]:
        regs = set()
        for c in ("E1-04", "o1-03"):
            p = self.profile.param(c)
            if p is not None and p.register is not None:
                regs.add(p.register)
        return regs

    def _explain(self, code: str, p, value, e: ParamError) -> str:
        what = f"{p.code} ({p.name})" if p else code
        u = f" {p.unit}" if p is not None and p.unit else ""
        msg = f"yaskawa: {what}: the drive refused {value:g}{u}: error {error_text(e.number or 0)}"
        if e.number == 0x21 and p is not None and p.min is not None and p.max is not None:
            msg += f" (profile range {p.min:g}..{p.max:g}{u})"
        if e.number == 0x22 and self.last is not None and self.last.running and p is not None \
                and p.access == "stop":
            msg += f"; {p.code} can be changed only while the drive is stopped"
        return msg

    def save(self) -> None:
        """Write the ENTER command register (stores the parameters in the drive's EEPROM)."""
        if self.params is None:
            raise self._no_channel()
        if self.cfg.enter_register is None:
            raise DriveError("yaskawa: the profile names no ENTER command register "
                             "(yaskawa.enter_register); the SI-P1 manual does not give one")
        try:
            self.write_registers(self.cfg.enter_register, [0])
        except ParamError as e:
            raise ParamError(f"yaskawa: ENTER (register 0x{self.cfg.enter_register:04X}) refused: "
                             f"{error_text(e.number or 0)}", e.number) from None

    def fault_history(self) -> list[FaultRecord]:
        if self.params is None:
            raise self._no_channel()
        if not self.cfg.fault_history:
            raise DriveError("yaskawa: the profile names no fault registers (yaskawa.fault_history)")
        regs = [(pos, self.profile.param(c).register) for pos, c in self.cfg.fault_history]
        values = self._read_many([r for _, r in regs])
        out = []
        for pos, reg in regs:
            raw = values[reg]
            if not raw:
                continue
            al = self.profile.alarms_for(raw)
            if al:
                out.append(FaultRecord(pos, raw, [a.code for a in al], [a.meaning for a in al]))
            else:
                out.append(FaultRecord(pos, raw, [f"0x{raw:04X}"],
                                       ["not in the profile's fault table (see the drive's MODBUS manual)"]))
        return out

    def _read_many(self, regs: list[int]) -> dict[int, int]:
        """Read a set of registers, grouping consecutive runs up to the format's registers/request."""
        out: dict[int, int] = {}
        todo = sorted(set(regs))
        while todo:
            start = todo[0]
            n = 1
            while n < self.fmt.max_registers and start + n in todo:
                n += 1
            for i, v in enumerate(self.read_registers(start, n)):
                out[start + i] = v
            todo = [r for r in todo if r not in out]
        return out

    def max_frequency(self) -> float:
        if not self.has_param_channel or not self.profile.max_frequency_param:
            return float(self.profile.max_frequency_default)
        if self._fmax is None:
            self._fmax = float(self.read_param(self.profile.max_frequency_param).value)
        return self._fmax


def make_drive(channel, profile, layout: str | None = None) -> YaskawaDrive:
    return YaskawaDrive(channel, profile, layout)
