"""The PROFIdrive base-mode parameter access over DP-V1: the parameter request and response that
travel in data record 47 (DS47), encoded and decoded, sans-IO.

A class-1 master writes the parameter request with a Write of DS47 and fetches the parameter response
with Reads of DS47 (the drive answers "state conflict" until it is ready: dp/msac1.py and
dp/acyclic.py do that part). This module only turns those octets into typed values and back: no bus,
no time, no profile, no parameter meanings beyond the PNU 964 layout. It imports nothing above
drives/profidrive/. Every malformed octet string raises Ds47Error, which says what is wrong and at
which octet (counted from 0, the request reference); `encode` refuses with Ds47Error what the wire
cannot carry (more than 240 octets, more than 39 parameters, a value outside its format).

The wire (every word big-endian, high octet first):

    request   reference, request id (0x01 read, 0x02 change), axis, number of parameters (1..39)
              then per parameter a 6-octet address: attribute (0x10 value, 0x20 description, 0x30
              text), number of elements (0..234), PNU (word), subindex (word)
              change only: then per parameter a value block (below), in the addresses' order
    response  reference and axis mirrored, response id (0x01 / 0x02 positive, 0x81 / 0x82
              negative: bit 7), number of parameters
              read (0x01, 0x81): a block per parameter, values or (negative) an error block
              change positive (0x02): the header alone
              change negative (0x82): a block per parameter, 0x40 Zero with no values for those
              that were changed, an error block for those that were not
    value     format, number of values (0..234), the values (each the format's size); when the
    block     values take an odd number of octets, one 0x00 follows so the next field starts on a
              word (a missing pad after the very last block is accepted on decode)
    error     0x44, number of values 1 or 2, the error number (word), the additional information
    block     (word, when 2; SINAMICS: often the subindex the error occurred at)

Formats (FORMATS): the PROFIdrive data types 0x01..0x36 whose size is known here, 0x40 Zero, 0x41
Byte, 0x42 Word, 0x43 Double word, 0x44 Error. Integer formats travel as Python ints (signed for
IntegerN), FloatingPoint as floats (IEEE 754 single), VisibleString and OctetString as bytes (one
value an octet). The other PROFIdrive types (N2..X4, the time and date types) travel as the unsigned
int of their octets; scaling them is the caller's business. 0x0D TimeDifference is named but refused:
its values are 4 or 6 octets and a block does not say which.

Sources (each rule from at least one; the wording here is ours):
  - SINAMICS S120 Function Manual 11/2017 (6SL3097-4AB00-0BP5), "Description of fields in the
    parameter request and response": header fields, response ids 0x01/0x02/0x81/0x82, number of
    parameters 1..39 "limited by DPV1 telegram length", subindex and PNU words.
    https://www.easymanua.ls/siemens/sinamics-s120/manual/3298?p=755
  - SINAMICS configuration manual A.1 (fields table): formats 0x02..0x08 and 0x40..0x44, number of
    values 0..234, a zero octet appended to values or error values of odd length.
    https://manualshive.com/en/manual/siemens/sinamics/376255?page=97
  - SINAMICS Function Manual 06/2012 (6SL3097-4AB10-0BP4) 9.2: the multi-parameter change example
    (reference 0x40, axis 2, p1055/p1056/p1058/p1059) and the error value table.
    http://38.142.81.21:8001/manual/siemens/eh-85m-21e/technical-data-english/page-624.html
    http://38.142.81.21:8001/manual/siemens/eh-85m-21e/technical-data-english/page-617.html
  - SINAMICS S120 function manual, "Error values in parameter responses" (0x19, 0x20, 0x21).
    http://www.manualslib.com./manual/1563374/Siemens-Sinamics-S120-Series.html?page=58
  - SINAMICS G120X operating instructions 06/2019: formats 0x0A, 0x0D, 0x34..0x36; the negative
    change response (0x40 Zero with 0 values, 0x44 with 1 or 2 error values).
    https://www.easymanua.ls/siemens/sinamics-g120x/manual?p=223 (and ?p=225)
  - ABB FPBA-01 user manual: request header table (number of elements 0, 1..234; PNU and subindex
    words; the pad octet), DP-V1 examples 1a, 1b, 2a, 2b, 3; error numbers 0x16..0x18, 0x65..0xFF
    manufacturer-specific.
    https://abb.manymanuals.es/networking/fpba-01/user-manual-13023/94
    https://easymanua.ls/abb/fpba-01-profibus-dp/manual?p=170
    https://abb.manymanuals.de/networking/fpba-01/user-manual-13023/97
  - ABB RETA-02 manual: error 0x19 "DO nonexistent"; the fault buffer (PNU 945 fault code, PNU 947
    fault number). https://www.easymanua.ls/abb/reta-02/manual?p=88 (and ?p=102)
  - Toshiba E6581738 (PDP003Z, PROFIBUS DP-V1) "Example 2" and its appendix (error numbers and
    formats; the appendix prints decimal 10, 12, 13 with a 0x prefix: OctetString is 0x0A).
    https://kitchen.manualsonline.com/manuals/mfg/toshiba/vfmb1s15.html?p=34
    https://www.manualslib.com/manual/539538/Toshiba-Tosvert-Vf-Mb1-S15.html?page=38
  - Toshiba E6582051 (PNE001Z) 6.2.3: the error block of the negative change response.
    https://easymanua.ls/toshiba/pne001z/manual?p=43
  - Lenze EDS84DMOTPBUS (8400 motec PROFIBUS) and i550: read responses, the error block with 1 or 2
    values (error code, additional information).
    https://www.easymanua.ls/lenze/e84dgfcp-series/manual?p=66
    https://easymanua.ls/lenze/i55ae155f/manual?p=307
  - Beckhoff Tc2_IoFunctions E_PD_Datatype, ST_Dpv1ParamAddrEx, E_PD_Dpv1Error: the data type
    numbers (N2..X4 0x21..0x2C, Date 0x32, the time types and their octets), attribute 0x80..0xF0
    manufacturer-specific, number of elements 0 a special function.
    https://infosys.beckhoff.com/content/1033/tcplclib_tc2_iofunctions/948619403.html
    https://infosys.beckhoff.com/content/1033/tcplclib_tc2_iofunctions/59241995.html
    https://infosys.beckhoff.com/content/1033/tcplclib_tc2_iofunctions/948627211.html
  - Yaskawa Sigma-7 PROFINET manual (SIEP YEUOC7P 02A) 15.3 and Vacon OPTE9 table 70: PNU 964's
    subindices (manufacturer, drive unit type, version xxyy decimal, year yyyy decimal, day/month
    ddmm decimal, number of drive objects); Vacon: PNU 947 fault number.
    https://www.easymanua.ls/yaskawa/sigma-7-sgd7s-series/manual?p=527
    https://manualshive.com/ru/manual/vacon/opte9/847712?page=110
  - The 240-octet limit: a DP-V1 read or write carries at most 240 octets (C1_Max_Data_Len; see
    dp/msac1.py MAX_DATA and its sources); 4 + 39 x 6 = 238 is why the profile stops at 39
    parameters.
"""

from __future__ import annotations

import datetime
import struct
from dataclasses import dataclass
from typing import Mapping, Sequence

from profidrive_cli.drives.profidrive.pnu import PNU_DEVICE_ID, PNU_FAULT_NUMBER

#: the data record (DS47) index the parameter channel uses
INDEX = 47
#: the most octets a DS47 request or response may take (one DP-V1 read or write)
MAX_LEN = 240
#: number of parameters in one request: 1..39
MAX_PARAMETERS = 39
#: number of elements of an address, number of values of a block: 0..234
MAX_ELEMENTS = 234
MAX_VALUES = 234

REQUEST_READ = 0x01
REQUEST_CHANGE = 0x02
RESPONSE_READ = 0x01
RESPONSE_CHANGE = 0x02
RESPONSE_READ_NEGATIVE = 0x81
RESPONSE_CHANGE_NEGATIVE = 0x82
#: bit 7 of the response id: the request was not (wholly) executed
NEGATIVE = 0x80

ATTR_VALUE = 0x10
ATTR_DESCRIPTION = 0x20
ATTR_TEXT = 0x30

REQUEST_NAMES: dict[int, str] = {REQUEST_READ: "read", REQUEST_CHANGE: "change"}
RESPONSE_NAMES: dict[int, str] = {RESPONSE_READ: "read ok", RESPONSE_CHANGE: "change ok",
                                  RESPONSE_READ_NEGATIVE: "read negative",
                                  RESPONSE_CHANGE_NEGATIVE: "change negative"}
ATTRIBUTES: dict[int, str] = {ATTR_VALUE: "value", ATTR_DESCRIPTION: "description", ATTR_TEXT: "text"}

FORMAT_BOOLEAN = 0x01
FORMAT_INTEGER8 = 0x02
FORMAT_INTEGER16 = 0x03
FORMAT_INTEGER32 = 0x04
FORMAT_UNSIGNED8 = 0x05
FORMAT_UNSIGNED16 = 0x06
FORMAT_UNSIGNED32 = 0x07
FORMAT_FLOAT = 0x08
FORMAT_VISIBLE_STRING = 0x09
FORMAT_OCTET_STRING = 0x0A
FORMAT_TIME_DIFFERENCE = 0x0D
FORMAT_ZERO = 0x40
FORMAT_BYTE = 0x41
FORMAT_WORD = 0x42
FORMAT_DWORD = 0x43
FORMAT_ERROR = 0x44

#: format octet -> name
FORMATS: dict[int, str] = {
    0x01: "Boolean", 0x02: "Integer8", 0x03: "Integer16", 0x04: "Integer32",
    0x05: "Unsigned8", 0x06: "Unsigned16", 0x07: "Unsigned32", 0x08: "FloatingPoint",
    0x09: "VisibleString", 0x0A: "OctetString",
    0x0C: "TimeOfDay with date indication", 0x0D: "TimeDifference",
    0x21: "N2", 0x22: "N4", 0x23: "V2", 0x24: "L2", 0x25: "R2", 0x26: "T2", 0x27: "T4",
    0x28: "D2", 0x29: "E2", 0x2A: "C4", 0x2B: "X2", 0x2C: "X4",
    0x32: "Date", 0x34: "TimeOfDay without date indication",
    0x35: "TimeDifference with date indication", 0x36: "TimeDifference without date indication",
    0x40: "Zero", 0x41: "Byte", 0x42: "Word", 0x43: "Double word", 0x44: "Error",
}

#: how a format's values travel: (octets a value, kind): "s" signed int, "u" unsigned int, "f" IEEE
#: 754 single, "o" octets (bytes, one value an octet). Zero and Error are blocks of their own;
#: TimeDifference (0x0D) is missing on purpose (4 or 6 octets a value).
_CODING: dict[int, tuple[int, str]] = {
    0x01: (1, "u"), 0x02: (1, "s"), 0x03: (2, "s"), 0x04: (4, "s"),
    0x05: (1, "u"), 0x06: (2, "u"), 0x07: (4, "u"), 0x08: (4, "f"),
    0x09: (1, "o"), 0x0A: (1, "o"),
    0x0C: (6, "u"),
    0x21: (2, "u"), 0x22: (4, "u"), 0x23: (2, "u"), 0x24: (2, "u"), 0x25: (2, "u"),
    0x26: (2, "u"), 0x27: (4, "u"), 0x28: (2, "u"), 0x29: (2, "u"), 0x2A: (4, "u"),
    0x2B: (2, "u"), 0x2C: (4, "u"),
    0x32: (7, "u"), 0x34: (4, "u"), 0x35: (6, "u"), 0x36: (4, "u"),
    0x41: (1, "u"), 0x42: (2, "u"), 0x43: (4, "u"),
}
#: formats whose values read best in hex (bit sequences)
_HEX_FORMATS = frozenset({0x23, 0x41, 0x42, 0x43})

#: PROFIdrive parameter access error numbers (the error block's first word); 0x65..0xFF are
#: manufacturer-specific
ERRORS: dict[int, str] = {
    0x00: "impermissible parameter number",
    0x01: "parameter value cannot be changed",
    0x02: "low or high limit exceeded",
    0x03: "faulty subindex",
    0x04: "no array",
    0x05: "incorrect data type",
    0x06: "setting not permitted (may only be reset)",
    0x07: "description element cannot be changed",
    0x09: "no description data available",
    0x0B: "no operation priority (no parameter change rights)",
    0x0F: "no text array available",
    0x11: "request cannot be executed because of operating state",
    0x14: "value impermissible",
    0x15: "response too long",
    0x16: "parameter address impermissible",
    0x17: "illegal format",
    0x18: "number of values inconsistent",
    0x19: "axis/DO nonexistent",
    0x20: "parameter text element cannot be changed",
    0x21: "service not supported",
}
ERROR_RESPONSE_TOO_LONG = 0x15
#: the first manufacturer-specific error number
ERROR_MANUFACTURER = 0x65

#: PNU 945: fault code (the fault buffer's codes); PNU 947: fault number; PNU 964: device
#: identification (pnu.py holds 947 and 964)
PNU_FAULT_CODE = 945


class Ds47Error(ValueError):
    """A DS47 parameter request or response that is malformed, or that the wire cannot carry; the
    message says what and at which octet (from 0, the request reference)."""


def error_text(number: int) -> str:
    """An error number in words: "0x11 request cannot be executed because of operating state";
    numbers the profile does not define are named as unknown or manufacturer-specific."""
    text = ERRORS.get(number)
    if text is not None:
        return f"0x{number:02X} {text}"
    if ERROR_MANUFACTURER <= number <= 0xFF:
        return f"0x{number:02X} manufacturer-specific error"
    return f"0x{number:02X} unknown error number"


def format_name(fmt: int) -> str:
    """A format octet's name ("Unsigned16"), "format 0xNN" for one not in FORMATS."""
    return FORMATS.get(fmt, f"format 0x{fmt:02X}")


@dataclass(frozen=True)
class ParamAddress:
    """One parameter of a request: its number, the first subindex, how many elements from there,
    and what of it (ATTR_VALUE, ATTR_DESCRIPTION, ATTR_TEXT)."""
    pnu: int
    subindex: int = 0
    elements: int = 1
    attribute: int = ATTR_VALUE

    def describe(self) -> str:
        """ "PNU964[0] (1 element)"; the attribute named when it is not the value."""
        attr = ""
        if self.attribute != ATTR_VALUE:
            attr = " " + ATTRIBUTES.get(self.attribute, f"attribute 0x{self.attribute:02X}")
        s = "" if self.elements == 1 else "s"
        return f"PNU{self.pnu}[{self.subindex}]{attr} ({self.elements} element{s})"


@dataclass(frozen=True)
class ParamValues:
    """A value block: the format and its values (ints for the integer, Byte, Word and Double word
    formats, signed for IntegerN; floats for FloatingPoint; bytes for VisibleString and
    OctetString). FORMAT_ZERO with no values is a negative change response's "this one was
    changed"."""
    format: int
    values: tuple[int | float, ...] | bytes

    @property
    def format_name(self) -> str:
        return format_name(self.format)

    def describe(self) -> str:
        """ "Unsigned16 3", "Word 0x0258", "VisibleString 'abc'"; at most 8 values, then their
        number."""
        if self.format == FORMAT_ZERO:
            return "Zero"
        vals = self.values
        if isinstance(vals, (bytes, bytearray)):
            if self.format == FORMAT_VISIBLE_STRING:
                return f"{self.format_name} {bytes(vals).decode('latin-1')!r}"
            return f"{self.format_name} {bytes(vals).hex(' ') or '(none)'}"
        width = 2 * _CODING.get(self.format, (2, "u"))[0]
        shown = []
        for v in vals[:8]:
            if isinstance(v, float):
                shown.append(f"{v:g}")
            elif self.format in _HEX_FORMATS:
                shown.append(f"0x{v:0{width}X}")
            else:
                shown.append(str(v))
        more = f" ... ({len(vals)} values)" if len(vals) > 8 else ""
        return f"{self.format_name} {', '.join(shown) or '(none)'}{more}"


@dataclass(frozen=True)
class ParamFault:
    """An error block (format 0x44) in a response: the error number and, when the drive sends it,
    the additional information word."""
    number: int
    extra: int | None = None

    @property
    def text(self) -> str:
        """The error number in words (error_text); `extra` is not part of it."""
        return error_text(self.number)

    def describe(self) -> str:
        tail = "" if self.extra is None else f" (additional information {self.extra})"
        return f"error {self.text}{tail}"


# -- value blocks --------------------------------------------------------------------------------

def _coding(fmt: int, where: str) -> tuple[int, str]:
    """The size and kind of a format's values, or Ds47Error naming `where`."""
    coding = _CODING.get(fmt)
    if coding is not None:
        return coding
    if fmt == FORMAT_TIME_DIFFERENCE:
        raise Ds47Error(f"{where}: format 0x0D TimeDifference is not supported (4 or 6 octets a "
                        "value, and the block does not say which)")
    if fmt in FORMATS:
        raise Ds47Error(f"{where}: format 0x{fmt:02X} {FORMATS[fmt]} is not a value format here")
    raise Ds47Error(f"{where}: format 0x{fmt:02X} is reserved or unknown (its values' size is not "
                    "known)")


def _encode_number(v: object, size: int, kind: str, name: str, where: str) -> bytes:
    if kind == "f":
        if not isinstance(v, (int, float)):
            raise Ds47Error(f"{where}: {name} value {v!r} is not a number")
        try:
            return struct.pack(">f", v)
        except (OverflowError, struct.error):
            raise Ds47Error(f"{where}: {v!r} does not fit {name} (IEEE 754 single)") from None
    if not isinstance(v, int):
        raise Ds47Error(f"{where}: {name} value {v!r} is not an integer")
    signed = kind == "s"
    lo, hi = (-(1 << (8 * size - 1)), (1 << (8 * size - 1)) - 1) if signed else (0, (1 << (8 * size)) - 1)
    if not lo <= v <= hi:
        raise Ds47Error(f"{where}: {v} does not fit {name} ({lo}..{hi})")
    return int(v).to_bytes(size, "big", signed=signed)


def _encode_block(item: ParamValues | ParamFault, where: str, pos: int) -> bytes:
    """One value or error block with its pad octet; `pos` the octet it starts at (for messages)."""
    if isinstance(item, ParamFault):
        if not 0 <= item.number <= 0xFFFF:
            raise Ds47Error(f"{where}, octet {pos + 2}: error number {item.number} outside 0..65535")
        words = [item.number]
        if item.extra is not None:
            if not 0 <= item.extra <= 0xFFFF:
                raise Ds47Error(f"{where}, octet {pos + 4}: additional information {item.extra} "
                                "outside 0..65535")
            words.append(item.extra)
        return bytes((FORMAT_ERROR, len(words))) + b"".join(w.to_bytes(2, "big") for w in words)
    fmt = item.format
    if fmt == FORMAT_ERROR:
        raise Ds47Error(f"{where}, octet {pos}: format 0x44 Error is a ParamFault, not ParamValues")
    if fmt == FORMAT_ZERO:
        if len(item.values):
            raise Ds47Error(f"{where}, octet {pos + 1}: format 0x40 Zero carries no values, "
                            f"not {len(item.values)}")
        return bytes((FORMAT_ZERO, 0))
    if not 0 <= fmt <= 0xFF:
        raise Ds47Error(f"{where}, octet {pos}: format {fmt} outside 0..255")
    size, kind = _coding(fmt, f"{where}, octet {pos}")
    name = FORMATS[fmt]
    values = item.values
    if kind == "o":
        if not isinstance(values, (bytes, bytearray)):
            raise Ds47Error(f"{where}, octet {pos + 2}: {name} values are octets (bytes), not "
                            f"{type(values).__name__}")
        body = bytes(values)
        n = len(body)
    else:
        if isinstance(values, (bytes, bytearray)):
            raise Ds47Error(f"{where}, octet {pos + 2}: {name} values are numbers, not bytes")
        n = len(values)
        body = b"".join(_encode_number(v, size, kind, name, f"{where}, octet {pos + 2 + i * size}")
                        for i, v in enumerate(values))
    if n > MAX_VALUES:
        raise Ds47Error(f"{where}, octet {pos + 1}: {n} values, a block carries at most {MAX_VALUES}")
    return bytes((fmt, n)) + body + (b"\x00" if len(body) % 2 else b"")


def _decode_block(data: bytes, pos: int, k: int, count: int) -> tuple[ParamValues | ParamFault, int]:
    """The block of parameter k (1-based) of `count` at octet `pos` -> (block, the octet after it)."""
    what = f"parameter {k} of {count}"
    if pos + 2 > len(data):
        raise Ds47Error(f"octet {pos}: the block of {what} (format, number of values) runs past "
                        f"the end ({len(data)} octets)")
    fmt, n = data[pos], data[pos + 1]
    if fmt == FORMAT_ERROR:
        if n not in (1, 2):
            raise Ds47Error(f"octet {pos + 1}: the error block of {what} carries 1 or 2 values, "
                            f"not {n}")
        end = pos + 2 + 2 * n
        if end > len(data):
            raise Ds47Error(f"octet {pos + 2}: the error block of {what} needs {2 * n} octets, "
                            f"{len(data) - pos - 2} left")
        number = int.from_bytes(data[pos + 2:pos + 4], "big")
        extra = int.from_bytes(data[pos + 4:pos + 6], "big") if n == 2 else None
        return ParamFault(number, extra), end
    if fmt == FORMAT_ZERO:
        if n:
            raise Ds47Error(f"octet {pos + 1}: the Zero block of {what} carries no values, not {n}")
        return ParamValues(FORMAT_ZERO, ()), pos + 2
    size, kind = _coding(fmt, f"octet {pos}")
    if n > MAX_VALUES:
        raise Ds47Error(f"octet {pos + 1}: {n} values for {what}, a block carries at most "
                        f"{MAX_VALUES}")
    start = pos + 2
    end = start + n * size
    if end > len(data):
        raise Ds47Error(f"octet {start}: {n} {FORMATS[fmt]} value(s) of {what} need {n * size} "
                        f"octets, {len(data) - start} left")
    raw = data[start:end]
    values: tuple[int | float, ...] | bytes
    if kind == "o":
        values = bytes(raw)
    elif kind == "f":
        values = tuple(float(x) for (x,) in struct.iter_unpack(">f", raw))
    else:
        values = tuple(int.from_bytes(raw[i:i + size], "big", signed=kind == "s")
                       for i in range(0, len(raw), size))
    if (n * size) % 2 and end < len(data):
        end += 1                                # the pad octet (may be missing after the last block)
    return ParamValues(fmt, values), end


def _check(value: int, lo: int, hi: int, what: str, octet: int) -> None:
    if not lo <= value <= hi:
        raise Ds47Error(f"octet {octet}: {what} {value} outside {lo}..{hi}")


def _check_attribute(attribute: int, octet: int) -> None:
    """0x10 value, 0x20 description, 0x30 text; 0x80..0xF0 manufacturer-specific; else reserved."""
    if attribute not in ATTRIBUTES and not 0x80 <= attribute <= 0xF0:
        raise Ds47Error(f"octet {octet}: attribute 0x{attribute:02X} is reserved (0x10 value, 0x20 "
                        "description, 0x30 text, 0x80..0xF0 manufacturer-specific)")


def _check_length(n: int, what: str) -> None:
    if n > MAX_LEN:
        raise Ds47Error(f"octet {MAX_LEN}: the {what} takes {n} octets, a DS47 record carries at "
                        f"most {MAX_LEN}")


# -- request -------------------------------------------------------------------------------------

def _header(data: bytes, kind: str, ids: Mapping[int, str], not_one: str) -> tuple[int, int, int, int]:
    """The 4-octet header of a parameter request or response (`kind`): reference, request or
    response id (one of `ids`, else "... `not_one`"), axis, number of parameters, checked."""
    _check_length(len(data), kind)
    if len(data) < 4:
        raise Ds47Error(f"octet {len(data)}: short header: {len(data)} octet(s), a parameter "
                        f"{kind} starts with 4 (reference, {kind} id, axis, number of "
                        "parameters)")
    reference, ident, axis, count = data[0], data[1], data[2], data[3]
    _check(reference, 1, 255, "request reference", 0)
    if ident not in ids:
        raise Ds47Error(f"octet 1: {kind} id 0x{ident:02X} {not_one}")
    _check(count, 1, MAX_PARAMETERS, "number of parameters", 3)
    return reference, ident, axis, count


@dataclass(frozen=True)
class ParamRequest:
    """A parameter request: read (REQUEST_READ) the addressed parameters, or change
    (REQUEST_CHANGE) them to `values`, one block per address."""
    reference: int
    request_id: int
    axis: int
    addresses: tuple[ParamAddress, ...]
    values: tuple[ParamValues, ...] = ()

    def encode(self) -> bytes:
        """The request's octets; Ds47Error when a field is out of its range, the values do not
        match the addresses, or the whole would not fit in MAX_LEN octets."""
        _check(self.reference, 1, 255, "request reference", 0)
        if self.request_id not in REQUEST_NAMES:
            raise Ds47Error(f"octet 1: request id {self.request_id} is neither 0x01 (read) nor "
                            "0x02 (change)")
        _check(self.axis, 0, 255, "axis", 2)
        count = len(self.addresses)
        _check(count, 1, MAX_PARAMETERS, "number of parameters", 3)
        out = bytearray((self.reference, self.request_id, self.axis, count))
        for a in self.addresses:
            pos = len(out)
            _check_attribute(a.attribute, pos)
            _check(a.elements, 0, MAX_ELEMENTS, "number of elements", pos + 1)
            _check(a.pnu, 0, 0xFFFF, "parameter number", pos + 2)
            _check(a.subindex, 0, 0xFFFF, "subindex", pos + 4)
            out += struct.pack(">BBHH", a.attribute, a.elements, a.pnu, a.subindex)
        if self.request_id == REQUEST_READ:
            if self.values:
                raise Ds47Error(f"octet {len(out)}: a read request carries no values "
                                f"({len(self.values)} given)")
        else:
            if len(self.values) != count:
                raise Ds47Error(f"octet {len(out)}: a change request carries one value block per "
                                f"parameter: {count} parameters, {len(self.values)} blocks")
            for k, v in enumerate(self.values, 1):
                if not isinstance(v, ParamValues) or v.format == FORMAT_ZERO:
                    raise Ds47Error(f"parameter {k} of {count}, octet {len(out)}: a change "
                                    f"request carries values, not {v!r}")
                out += _encode_block(v, f"parameter {k} of {count}", len(out))
        _check_length(len(out), "request")
        return bytes(out)

    @classmethod
    def decode(cls, data: bytes) -> ParamRequest:
        """A request from its octets (a Write DS47's data); Ds47Error names what is malformed
        and the octet."""
        data = bytes(data)
        reference, request_id, axis, count = _header(
            data, "request", REQUEST_NAMES, "is neither 0x01 (read) nor 0x02 (change)")
        pos = 4
        addresses = []
        for k in range(1, count + 1):
            if pos + 6 > len(data):
                raise Ds47Error(f"octet {pos}: the address of parameter {k} of {count} needs 6 "
                                f"octets, {len(data) - pos} left (the number of parameters does "
                                "not match the data)")
            attribute, elements, pnu, subindex = struct.unpack_from(">BBHH", data, pos)
            _check_attribute(attribute, pos)
            _check(elements, 0, MAX_ELEMENTS, "number of elements", pos + 1)
            addresses.append(ParamAddress(pnu, subindex, elements, attribute))
            pos += 6
        values = []
        if request_id == REQUEST_CHANGE:
            for k in range(1, count + 1):
                start = pos
                block, pos = _decode_block(data, pos, k, count)
                if not isinstance(block, ParamValues) or block.format == FORMAT_ZERO:
                    raise Ds47Error(f"octet {start}: parameter {k} of {count} has a 0x{data[start]:02X} "
                                    f"{format_name(data[start])} block; a change request carries "
                                    "values")
                values.append(block)
        if pos != len(data):
            raise Ds47Error(f"octet {pos}: {len(data) - pos} octet(s) after the last parameter "
                            f"(the number of parameters, {count}, does not match the data)")
        return cls(reference, request_id, axis, tuple(addresses), tuple(values))

    def describe(self) -> str:
        """One line: "ref 1 read axis 1: PNU964[0] (1 element)"."""
        head = (f"ref {self.reference} {REQUEST_NAMES.get(self.request_id, f'0x{self.request_id:02X}')}"
                f" axis {self.axis}: ")
        if self.request_id != REQUEST_CHANGE:
            return head + ", ".join(a.describe() for a in self.addresses)
        parts = []
        for i, a in enumerate(self.addresses):
            v = self.values[i].describe() if i < len(self.values) else "?"
            parts.append(f"{a.describe()} = {v}")
        return head + "; ".join(parts)


# -- response ------------------------------------------------------------------------------------

@dataclass(frozen=True)
class ParamResponse:
    """A parameter response: the request's reference and axis mirrored, the response id
    (RESPONSE_READ, RESPONSE_CHANGE, or either with NEGATIVE set), the number of parameters and
    the blocks: read, one per parameter; change negative, one per parameter (Zero for those that
    were changed); change positive, none."""
    reference: int
    response_id: int
    axis: int
    count: int
    items: tuple[ParamValues | ParamFault, ...]

    @property
    def ok(self) -> bool:
        """Positive: bit 7 of the response id clear."""
        return not self.response_id & NEGATIVE

    def encode(self) -> bytes:
        """The response's octets (a Read DS47's data); Ds47Error when a field is out of range, the
        blocks do not fit the response id and count, or the whole exceeds MAX_LEN octets."""
        out = self._encode()
        _check_length(len(out), "response")
        return out

    def _encode(self) -> bytes:
        _check(self.reference, 1, 255, "request reference", 0)
        if self.response_id not in RESPONSE_NAMES:
            raise Ds47Error(f"octet 1: response id 0x{self.response_id:02X} is not one of 0x01, "
                            "0x02, 0x81, 0x82")
        _check(self.axis, 0, 255, "axis", 2)
        _check(self.count, 1, MAX_PARAMETERS, "number of parameters", 3)
        out = bytearray((self.reference, self.response_id, self.axis, self.count))
        if self.response_id == RESPONSE_CHANGE:
            if self.items:
                raise Ds47Error(f"octet 4: a positive change response is the header alone "
                                f"({len(self.items)} blocks given)")
            return bytes(out)
        if len(self.items) != self.count:
            raise Ds47Error(f"octet 4: {self.count} parameters, {len(self.items)} blocks")
        for k, item in enumerate(self.items, 1):
            where = f"parameter {k} of {self.count}"
            if self.response_id == RESPONSE_READ and isinstance(item, ParamFault):
                raise Ds47Error(f"{where}, octet {len(out)}: an error block in a positive read "
                                "response (0x81 is the negative one)")
            if self.response_id == RESPONSE_CHANGE_NEGATIVE and not (
                    isinstance(item, ParamFault) or item.format == FORMAT_ZERO):
                raise Ds47Error(f"{where}, octet {len(out)}: a negative change response carries "
                                f"Zero or Error blocks, not {item.format_name}")
            if isinstance(item, ParamValues) and item.format == FORMAT_ZERO \
                    and self.response_id != RESPONSE_CHANGE_NEGATIVE:
                raise Ds47Error(f"{where}, octet {len(out)}: a Zero block belongs to a negative "
                                "change response")
            out += _encode_block(item, where, len(out))
        return bytes(out)

    @classmethod
    def decode(cls, data: bytes) -> ParamResponse:
        """A response from its octets (a Read DS47's data); Ds47Error names what is malformed and
        the octet. Lenient where the structure allows: blocks are read as they come (a Zero
        block in a read response is kept, a missing pad after the last block accepted)."""
        data = bytes(data)
        reference, response_id, axis, count = _header(
            data, "response", RESPONSE_NAMES, "is not one of 0x01, 0x02, 0x81, 0x82")
        pos = 4
        items: list[ParamValues | ParamFault] = []
        if response_id == RESPONSE_CHANGE:
            if len(data) > 4:
                raise Ds47Error(f"octet 4: a positive change response is the header alone, "
                                f"{len(data) - 4} octet(s) follow")
        else:
            for k in range(1, count + 1):
                block, pos = _decode_block(data, pos, k, count)
                items.append(block)
            if pos != len(data):
                raise Ds47Error(f"octet {pos}: {len(data) - pos} octet(s) after the last block (the "
                                f"number of parameters, {count}, does not match the data)")
        return cls(reference, response_id, axis, count, tuple(items))

    def describe(self) -> str:
        """One line: "ref 9 read ok axis 1: Word 0x0003"."""
        head = (f"ref {self.reference} "
                f"{RESPONSE_NAMES.get(self.response_id, f'0x{self.response_id:02X}')} "
                f"axis {self.axis}: ")
        if not self.items:
            s = "" if self.count == 1 else "s"
            return head + f"{self.count} parameter{s}"
        return head + "; ".join(i.describe() for i in self.items)


# -- building and answering ----------------------------------------------------------------------

def read_request(reference: int, axis: int, addresses: Sequence[ParamAddress]) -> ParamRequest:
    """A read request for `addresses`; Ds47Error at once when it could not be sent."""
    req = ParamRequest(reference, REQUEST_READ, axis, tuple(addresses))
    req.encode()
    return req


def change_request(reference: int, axis: int,
                   items: Sequence[tuple[ParamAddress, ParamValues]]) -> ParamRequest:
    """A change request: each address with the values to write there; Ds47Error at once when it
    could not be sent (a value outside its format, over MAX_LEN octets, ...)."""
    req = ParamRequest(reference, REQUEST_CHANGE, axis, tuple(a for a, _ in items),
                       tuple(v for _, v in items))
    req.encode()
    return req


def answer(request: ParamRequest, items: Sequence[ParamValues | ParamFault]) -> ParamResponse:
    """The response a drive gives to `request` (reference and axis mirrored, response id negative
    when any item is a ParamFault), for the simulator.

    A read takes one item per parameter: its values, or a ParamFault. A change takes one item per
    parameter too, a ParamFault for each parameter that was not changed and anything else (the
    values written, a Zero block) for those that were; no items at all means every one was
    changed. A read answer that would not fit in MAX_LEN octets becomes what the profile's error
    0x15 says, "response too long", for every parameter (our choice of which). Ds47Error when the
    items do not match the request or do not encode."""
    items = tuple(items)
    count = len(request.addresses)
    negative = any(isinstance(i, ParamFault) for i in items)
    if request.request_id == REQUEST_CHANGE:
        if items and len(items) != count:
            raise Ds47Error(f"{count} parameters changed, {len(items)} results given")
        if not negative:
            return ParamResponse(request.reference, RESPONSE_CHANGE, request.axis, count, ())
        blocks = tuple(i if isinstance(i, ParamFault) else ParamValues(FORMAT_ZERO, ())
                       for i in items)
        res = ParamResponse(request.reference, RESPONSE_CHANGE_NEGATIVE, request.axis, count,
                            blocks)
        res.encode()
        return res
    if len(items) != count:
        raise Ds47Error(f"{count} parameters read, {len(items)} results given")
    res = ParamResponse(request.reference, RESPONSE_READ_NEGATIVE if negative else RESPONSE_READ,
                        request.axis, count, items)
    if len(res._encode()) > MAX_LEN:
        res = ParamResponse(request.reference, RESPONSE_READ_NEGATIVE, request.axis, count,
                            (ParamFault(ERROR_RESPONSE_TOO_LONG),) * count)
    return res


# -- standard parameters -------------------------------------------------------------------------

def device_identification(values: Sequence[int]) -> dict[str, object]:
    """PNU 964 (device identification) read as a whole array, in words: subindex 0 the
    manufacturer id, 1 the drive unit type, 2 the firmware version (xxyy decimal: 201 is 2.01),
    3 the firmware year (yyyy decimal), 4 day and month (ddmm decimal: 1501 is 15 January), 5 the
    number of drive objects (axes), when sent; values past 5 under "more". Ds47Error for fewer
    than 5 values. "firmware_date" is ISO (YYYY-MM-DD), None when the numbers are no date."""
    v = [int(x) for x in values]
    if len(v) < 5:
        raise Ds47Error(f"PNU {PNU_DEVICE_ID} read as a whole array has at least 5 values "
                        f"(subindices 0-4), got {len(v)}")
    version, year, day_month = v[2], v[3], v[4]
    day, month = divmod(day_month, 100)
    try:
        date: str | None = datetime.date(year, month, day).isoformat()
    except ValueError:
        date = None
    return {
        "manufacturer_id": v[0],
        "drive_unit_type": v[1],
        "firmware_version": f"{version // 100}.{version % 100:02d}",
        "firmware_year": year,
        "firmware_day": day,
        "firmware_month": month,
        "firmware_date": date,
        "drive_objects": v[5] if len(v) > 5 else None,
        "more": tuple(v[6:]),
    }


__all__ = [
    "INDEX", "MAX_LEN", "MAX_PARAMETERS", "MAX_ELEMENTS", "MAX_VALUES",
    "REQUEST_READ", "REQUEST_CHANGE", "RESPONSE_READ", "RESPONSE_CHANGE", "RESPONSE_READ_NEGATIVE",
    "RESPONSE_CHANGE_NEGATIVE", "NEGATIVE", "ATTR_VALUE", "ATTR_DESCRIPTION", "ATTR_TEXT",
    "REQUEST_NAMES", "RESPONSE_NAMES", "ATTRIBUTES",
    "FORMAT_BOOLEAN", "FORMAT_INTEGER8", "FORMAT_INTEGER16", "FORMAT_INTEGER32", "FORMAT_UNSIGNED8",
    "FORMAT_UNSIGNED16", "FORMAT_UNSIGNED32", "FORMAT_FLOAT", "FORMAT_VISIBLE_STRING",
    "FORMAT_OCTET_STRING", "FORMAT_TIME_DIFFERENCE", "FORMAT_ZERO", "FORMAT_BYTE", "FORMAT_WORD",
    "FORMAT_DWORD", "FORMAT_ERROR", "FORMATS", "ERRORS", "ERROR_RESPONSE_TOO_LONG",
    "ERROR_MANUFACTURER", "PNU_DEVICE_ID", "PNU_FAULT_NUMBER", "PNU_FAULT_CODE",
    "Ds47Error", "ParamAddress", "ParamValues", "ParamFault", "ParamRequest", "ParamResponse",
    "read_request", "change_request", "answer", "error_text", "format_name",
    "device_identification",
]
