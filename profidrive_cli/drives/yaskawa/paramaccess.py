"""Yaskawa SI-P1 parameter access: the MEMOBUS register area and its handshake machine (spec §4).

The card reaches the drive's registers through a handshake byte (the drive needs 10-15 ms per
request). Sans-IO: ParamAccess takes the input area and the time and gives the output area; it never
waits. May touch: codec (AreaFormat), drives/base (errors).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Iterable

from profidrive_cli import UsageError
from profidrive_cli.drives.base import DriveError
from profidrive_cli.drives.yaskawa.codec import AreaFormat


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


def refusal_words(code: str, p: Any, value: float | int, number: int | None, running: bool) -> str:
    """The one line for a write the drive refused with error `number` (0x21 outside its range, 0x22
    not now), naming the parameter (`p`: its profile entry, None for a raw register `code`);
    `running`: the drive was running at the last exchange."""
    what = f"{p.code} ({p.name})" if p else code
    u = f" {p.unit}" if p is not None and p.unit else ""
    msg = f"yaskawa: {what}: the drive refused {value:g}{u}: error {error_text(number or 0)}"
    if number == 0x21 and p is not None and p.min is not None and p.max is not None:
        msg += f" (profile range {p.min:g}..{p.max:g}{u})"
    if number == 0x22 and running and p is not None and p.access == "stop":
        msg += f"; {p.code} can be changed only while the drive is stopped"
    return msg


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
    def write(cls, start: int, values: Iterable[int]) -> ParamRequest:
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

    def __init__(self, fmt: AreaFormat, timeout: float = 1.0, settle_cycles: int = 1, hs: int = 0,
                 min_exchanges: int = 1):
        if not fmt.has_params:
            raise ValueError(f"yaskawa {fmt.name}: no parameter-access area")
        self.fmt = fmt
        self.timeout = timeout
        #: a request times out only after `timeout` s AND this many exchanges since it was submitted:
        #: on a slow bus (a group of stations at 9.6k, 0.3-0.4 s a round) the handshake's few
        #: exchanges take longer than the time alone allows
        self.min_exchanges = max(1, min_exchanges)
        self._fed = 0
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
        self._fed = 0
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

        if self.request is not None:
            self._fed += 1
            if now > self._deadline and self._fed >= self.min_exchanges:
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
        within = f"{self.timeout:g} s" + (f" and {self._fed} exchanges" if self.min_exchanges > 1 else "")
        msg = f"{req.describe()}: no reply within {within} ({where})"
        if now - self._wd_changed > 0.2 and self._wd is not None:
            msg += "; the handshake watchdog counter is frozen: the option CPU may have stopped"
        return ParamResult(req, False, timeout=True, message=msg)
