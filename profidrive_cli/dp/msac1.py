"""DP-V1 class-1 acyclic services (MSAC_C1): the PDUs that travel on SAP 51, sans-IO.

A class-1 master reads and writes a DP-V1 slave's data records while the slave is in data exchange:
an SRD request to DSAP 51 from SSAP 51 carries the request PDU; the slave acknowledges it without data
while it prepares the answer, and the master fetches the answer by polling the same SAPs with an empty
DU until a reply with data comes (at most `C1_Response_Timeout` of the slave's GSD, in 10 ms).

PDU layouts (a public profichip VPC3+ slave header, section "11 DPV1": DPV1_READ_PDU, DPV1_WRITE_PDU,
DPV1_NEG_RES_PDU, MSAC_C1_ALARM_ACK_PDU; the TMG i-tec DPC1 slave stack: READ_REQ_PDU 0x5E, WRITE_REQ_PDU
0x5F, ALARM_ACK_REQ_PDU 0x5C, WRITE_RES_PDU_LEN = ERROR_RES_PDU_LEN = 4, a negative answer 0xDE / 0xDF):

    read request     5E slot index length              (length: octets wanted, 1..240)
    read response    5E slot index length data...       (length: octets returned)
    write request    5F slot index length data...
    write response   5F slot index length               (length: octets written)
    error response   DE|DF Error_Decode Error_Code_1 Error_Code_2    (function | 0x80)
    alarm ack        5C slot alarm_type specifier

Error_Decode 0x80 is DP-V1 (0xFE FMS, 0xFF HART); Error_Code_1 holds the class in its high nibble
(0xA application, 0xB access, 0xC resource, 0xD-0xF user) and the code in its low nibble; the same
header's DPV1_ERRCL_* table names them. A Siemens system reads them as one word W#16#80B5 ("state
conflict"): a PROFIdrive drive answers a Read DS47 with it while its parameter response is not ready.
"""

from __future__ import annotations

from dataclasses import dataclass

#: the slave's and the class-1 master's SAP for MSAC_C1 read/write (reference line 196)
SAP_C1 = 51
#: the class-1 alarm SAP of the slave, and the class-2 SAPs (named in sniff, not used by the master)
SAP_C1_ALARM = 50
SAP_C2 = 49

READ = 0x5E
WRITE = 0x5F
ALARM_ACK = 0x5C
ERROR_BIT = 0x80

#: function number -> name (class 1 and the class-2 ones sniff may hear)
FUNCTIONS: dict[int, str] = {READ: "Read", WRITE: "Write", ALARM_ACK: "Alarm_Ack", 0x57: "Initiate",
                             0x58: "Abort", 0x48: "Idle", 0x51: "Data_Transport", 0x56: "RM"}
#: the most octets one read or write carries (C1_Max_Data_Len is at most 240; a PDU is 4 + 240)
MAX_DATA = 240

ERROR_DECODE = {0x80: "DPV1", 0xFE: "FMS", 0xFF: "HART"}
ERROR_CLASSES = {0xA: "application", 0xB: "access", 0xC: "resource"}
ERROR_CODES: dict[int, dict[int, str]] = {
    0xA: {0: "read error", 1: "write error", 2: "module failure", 8: "version conflict",
          9: "feature not supported"},
    0xB: {0: "invalid index", 1: "write length error", 2: "invalid slot", 3: "type conflict",
          4: "invalid area", 5: "state conflict", 6: "access denied", 7: "invalid range",
          8: "invalid parameter", 9: "invalid type"},
    0xC: {0: "read constraint conflict", 1: "write constraint conflict", 2: "resource busy",
          3: "resource unavailable"},
}
#: Error_Code_1 of the answers a caller waits out (the slave is busy, ask again)
STATE_CONFLICT = 0xB5
RESOURCE_BUSY = 0xC2


class Msac1Error(ValueError):
    """A malformed MSAC_C1 PDU; the message says what and at which octet."""


def error_text(decode: int, code1: int, code2: int = 0) -> str:
    """'DPV1 access: state conflict (80 B5 00)' for an error response's three octets."""
    octets = f"({decode:02X} {code1:02X} {code2:02X})"
    if decode != 0x80:
        return f"{ERROR_DECODE.get(decode, 'reserved error decode')} error {octets}"
    cls, code = code1 >> 4, code1 & 0x0F
    if cls >= 0xD:
        return f"DPV1 user-specific error {octets}"
    if cls not in ERROR_CLASSES:
        return f"DPV1 reserved error class {cls} {octets}"
    name = ERROR_CODES[cls].get(code, "user-specific" if code >= (8 if cls == 0xC else 10) else "reserved")
    return f"DPV1 {ERROR_CLASSES[cls]}: {name} {octets}"


@dataclass(frozen=True)
class Msac1Pdu:
    """One MSAC_C1 PDU. `error` holds (Error_Decode, Error_Code_1, Error_Code_2) for a negative
    answer (then slot, index and length are 0 and data empty)."""
    function: int               # without the error bit
    slot: int = 0
    index: int = 0
    length: int = 0
    data: bytes = b""
    error: tuple[int, int, int] | None = None
    #: an alarm acknowledgement's alarm type and specifier
    alarm: tuple[int, int] | None = None

    @property
    def name(self) -> str:
        return FUNCTIONS.get(self.function, f"function 0x{self.function:02X}")

    @property
    def is_error(self) -> bool:
        return self.error is not None

    def encode(self) -> bytes:
        if self.error is not None:
            return bytes((self.function | ERROR_BIT, *self.error))
        if self.alarm is not None:
            return bytes((self.function, self.slot, *self.alarm))
        return bytes((self.function, self.slot, self.index, self.length)) + self.data

    def describe(self) -> str:
        if self.error is not None:
            return f"{self.name} error: {error_text(*self.error)}"
        if self.alarm is not None:
            return f"Alarm_Ack slot {self.slot} alarm type {self.alarm[0]} specifier 0x{self.alarm[1]:02X}"
        s = f"{self.name} slot {self.slot} index {self.index} length {self.length}"
        return s + (f": {self.data.hex(' ')}" if self.data else "")

    def to_dict(self) -> dict[str, object]:
        d: dict[str, object] = {"function": self.name}
        if self.error is not None:
            d.update(error=" ".join(f"{o:02X}" for o in self.error), error_text=error_text(*self.error))
        elif self.alarm is not None:
            d.update(slot=self.slot, alarm_type=self.alarm[0], specifier=self.alarm[1])
        else:
            d.update(slot=self.slot, index=self.index, length=self.length, data=self.data.hex(" "))
        return d


def _check(slot: int, index: int, data_len: int) -> None:
    if not 0 <= slot <= 254 or not 0 <= index <= 255:
        raise Msac1Error(f"slot {slot} / index {index} out of range (slot 0..254, index 0..255)")
    if not 0 <= data_len <= MAX_DATA:
        raise Msac1Error(f"{data_len} octets: a DP-V1 read or write carries at most {MAX_DATA}")


def read_request(slot: int, index: int, length: int) -> bytes:
    _check(slot, index, length)
    return bytes((READ, slot, index, length))


def write_request(slot: int, index: int, data: bytes) -> bytes:
    _check(slot, index, len(data))
    return bytes((WRITE, slot, index, len(data))) + bytes(data)


def read_response(slot: int, index: int, data: bytes) -> bytes:
    _check(slot, index, len(data))
    return bytes((READ, slot, index, len(data))) + bytes(data)


def write_response(slot: int, index: int, length: int) -> bytes:
    _check(slot, index, length)
    return bytes((WRITE, slot, index, length))


def error_response(function: int, code1: int, code2: int = 0, decode: int = 0x80) -> bytes:
    return bytes((function | ERROR_BIT, decode, code1, code2))


def decode_pdu(du: bytes, is_request: bool) -> Msac1Pdu:
    """A PDU from a telegram's DU (after the SAP octets). Requests: Read carries no data, Write its
    `length` octets; responses: Read its data, Write none; an error bit: four octets."""
    if len(du) < 1:
        raise Msac1Error("empty MSAC_C1 PDU")
    fn = du[0] & 0x7F
    if du[0] & ERROR_BIT:
        if is_request:
            raise Msac1Error(f"octet 0: 0x{du[0]:02X} has the error bit set in a request")
        if len(du) != 4:
            raise Msac1Error(f"error response of {len(du)} octets (4 expected)")
        return Msac1Pdu(fn, error=(du[1], du[2], du[3]))
    if len(du) < 4:
        raise Msac1Error(f"{FUNCTIONS.get(fn, f'function 0x{fn:02X}')} PDU of {len(du)} octets "
                         "(header of 4 expected)")
    if fn == ALARM_ACK:
        return Msac1Pdu(fn, du[1], alarm=(du[2], du[3]))
    slot, index, length, data = du[1], du[2], du[3], bytes(du[4:])
    carries = (fn == WRITE) if is_request else (fn == READ)
    if fn in (READ, WRITE):
        if carries and len(data) != length:
            raise Msac1Error(f"octet 3: length {length} but {len(data)} data octets follow")
        if not carries and data:
            raise Msac1Error(f"octet 4: {len(data)} octets after a {FUNCTIONS[fn]} "
                             f"{'request' if is_request else 'response'} header")
        if length > MAX_DATA:
            raise Msac1Error(f"octet 3: length {length} over {MAX_DATA}")
    return Msac1Pdu(fn, slot, index, length, data)


__all__ = ["SAP_C1", "READ", "WRITE", "ALARM_ACK", "FUNCTIONS", "MAX_DATA", "STATE_CONFLICT",
           "RESOURCE_BUSY", "Msac1Error", "Msac1Pdu", "error_text", "read_request", "write_request",
           "read_response", "write_response", "error_response", "decode_pdu"]
