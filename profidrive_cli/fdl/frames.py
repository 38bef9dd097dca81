"""FDL telegrams (reference §2): SD1, SD2, SD3, SD4 (token), SC; FCS; FC decoding; a streaming receiver.

Hot path: encode() and Receiver.parse() are plain Python on bytes (no construct), measured in
benchmarks/bench_fdl.py.
"""

from __future__ import annotations

from dataclasses import dataclass

SD1, SD2, SD3, SD4, SC, ED = 0x10, 0x68, 0xA2, 0xDC, 0xE5, 0x16
START_DELIMITERS = (SD1, SD2, SD3, SD4, SC)

ADDR_EXT = 0x80          # DA/SA bit 7: a SAP extension octet follows FC
ADDR_MASK = 0x7F
BROADCAST = 127
DEFAULT_MASTER = 2

# request functions (FC bits 3..0 with bit 6 set)
FC_REQ = 0x40
FC_FCB = 0x20
FC_FCV = 0x10
TE, SDA_LOW, SDN_LOW, SDA_HIGH, SDN_HIGH, MSRD = 0, 3, 4, 5, 6, 7
FDL_STATUS, SRD_LOW, SRD_HIGH, IDENT, LSAP_STATUS = 9, 12, 13, 14, 15

REQUEST_NAMES = {
    0: "time event", 3: "SDA low", 4: "SDN low", 5: "SDA high", 6: "SDN high", 7: "MSRD",
    9: "FDL status request", 12: "SRD low", 13: "SRD high", 14: "ident request",
    15: "LSAP status request",
}
NEEDS_REPLY = {SDA_LOW, SDA_HIGH, MSRD, FDL_STATUS, SRD_LOW, SRD_HIGH, IDENT, LSAP_STATUS}

# response status (FC bits 3..0 with bit 6 clear)
OK, UE, RR, RS, DL, NR, DH, RDL, RDH = 0, 1, 2, 3, 8, 9, 10, 12, 13
RESPONSE_NAMES = {
    0: "OK", 1: "UE user error", 2: "RR no resources", 3: "RS SAP not enabled",
    8: "DL data low", 9: "NR no response data", 10: "DH data high (diagnosis pending)",
    12: "RDL data not received, low", 13: "RDH data not received, high",
}
NEGATIVE = {UE, RR, RS, NR, RDL, RDH}
STATION_TYPES = {0: "slave", 1: "master not ready", 2: "master ready", 3: "master in ring"}


def fcs(data: bytes | bytearray | memoryview) -> int:
    return sum(data) & 0xFF


def request_fc(function: int, fcb: bool = False, fcv: bool = False) -> int:
    return FC_REQ | (FC_FCB if fcb else 0) | (FC_FCV if fcv else 0) | (function & 0x0F)


def response_fc(status: int, station_type: int = 0) -> int:
    return ((station_type & 3) << 4) | (status & 0x0F)


def is_request(fc: int) -> bool:
    return bool(fc & FC_REQ)


def describe_fc(fc: int) -> str:
    """FC in words: 'SRD high, FCB=1 FCV=0' or 'DL data low (slave)'."""
    if fc & FC_REQ:
        fn = fc & 0x0F
        name = REQUEST_NAMES.get(fn, f"reserved function {fn}")
        if fc & 0x80 and fn == 0:
            name = "CV clock value"
        return f"{name}, FCB={int(bool(fc & FC_FCB))} FCV={int(bool(fc & FC_FCV))}"
    st = fc & 0x0F
    return f"{RESPONSE_NAMES.get(st, f'reserved status {st}')} ({STATION_TYPES[(fc >> 4) & 3]})"


@dataclass(frozen=True, slots=True)
class Frame:
    """One telegram. `data` excludes the SAP octets; dsap/ssap are None when absent."""
    sd: int
    da: int = 0          # station address 0..127 (extension bit stripped)
    sa: int = 0
    fc: int = 0
    data: bytes = b""
    dsap: int | None = None
    ssap: int | None = None

    @property
    def is_sc(self) -> bool:
        return self.sd == SC

    @property
    def is_token(self) -> bool:
        return self.sd == SD4

    @property
    def is_request(self) -> bool:
        return self.sd not in (SC, SD4) and bool(self.fc & FC_REQ)

    @property
    def function(self) -> int:
        return self.fc & 0x0F

    @property
    def fcb(self) -> bool:
        return bool(self.fc & FC_FCB)

    @property
    def fcv(self) -> bool:
        return bool(self.fc & FC_FCV)

    @property
    def station_type(self) -> int:
        return (self.fc >> 4) & 3

    def encode(self, force_sd2: bool = False) -> bytes:
        return encode(self, force_sd2)


SC_FRAME = Frame(SC)

#: Frame(...) for the receiver's hot path: the frozen dataclass's __init__ sets each field through
#: object.__setattr__; its slots' own setters do the same at about half the cost (the same object)
_new = object.__new__
(_set_sd, _set_da, _set_sa, _set_fc, _set_data, _set_dsap, _set_ssap) = (
    Frame.__dict__[n].__set__ for n in ("sd", "da", "sa", "fc", "data", "dsap", "ssap"))


def _frame(sd: int, da: int, sa: int, fc: int, data: bytes, dsap: int | None,
           ssap: int | None) -> Frame:
    f: Frame = _new(Frame)
    _set_sd(f, sd)
    _set_da(f, da)
    _set_sa(f, sa)
    _set_fc(f, fc)
    _set_data(f, data)
    _set_dsap(f, dsap)
    _set_ssap(f, ssap)
    return f


def make(da: int, sa: int, fc: int, data: bytes = b"", dsap: int | None = None,
         ssap: int | None = None) -> Frame:
    """A data frame; the start delimiter is chosen by encode()."""
    return Frame(SD2, da, sa, fc, bytes(data), dsap, ssap)


def token(da: int, sa: int) -> Frame:
    return Frame(SD4, da, sa)


def encode(f: Frame, force_sd2: bool = False) -> bytes:
    """Frame -> octets. No DU and no SAPs -> SD1; exactly 8 octets of SAPs+data -> SD3; else SD2."""
    if f.sd == SC:
        return b"\xE5"
    if f.sd == SD4:
        return bytes((SD4, f.da & ADDR_MASK, f.sa & ADDR_MASK))
    if (f.dsap is None) != (f.ssap is None):
        raise ValueError("a DP telegram carries both SAPs or none")
    if not 0 <= f.da <= 127 or not 0 <= f.sa <= 127:
        raise ValueError(f"address out of range: DA {f.da} SA {f.sa}")
    if f.dsap is not None and f.ssap is not None:        # (both or none: checked above)
        body = bytes((f.da | ADDR_EXT, f.sa | ADDR_EXT, f.fc, f.dsap, f.ssap)) + f.data
    else:
        body = bytes((f.da, f.sa, f.fc)) + f.data
    du_len = len(body) - 3
    if du_len == 0 and not force_sd2:
        return bytes((SD1,)) + body + bytes((sum(body) & 0xFF, ED))
    if du_len == 8 and not force_sd2:
        return bytes((SD3,)) + body + bytes((sum(body) & 0xFF, ED))
    le = len(body)
    if le > 249:
        raise ValueError(f"telegram too long: {du_len} DU octets (max 246)")
    return bytes((SD2, le, le, SD2)) + body + bytes((sum(body) & 0xFF, ED))


# ---------------------------------------------------------------------------------------------
# Receiver

class FrameError:
    """A typed framing error. `used` octets were consumed (always >= 1)."""
    __slots__ = ("kind", "detail", "used")

    # kinds
    GARBAGE = "garbage"        # octet that cannot start a telegram
    LENGTH = "length"          # LE != LEr, LE out of 4..249, second SD of SD2 wrong
    FCS = "fcs"                # checksum mismatch
    ED = "ed"                  # end delimiter missing
    SAP = "sap"                # extension bit set but DU too short for the SAP octet(s)

    def __init__(self, kind: str, detail: str, used: int):
        self.kind = kind
        self.detail = detail
        self.used = used

    def __repr__(self) -> str:
        return f"FrameError({self.kind}: {self.detail}, used {self.used})"


NEED_MORE = None


def parse(buf: bytes | bytearray, pos: int = 0) -> tuple[Frame, int] | FrameError | None:
    """Look for one telegram at buf[pos:].

    Returns NEED_MORE (None) when the octets so far are a valid prefix, (Frame, used) for a telegram,
    or a FrameError whose .used >= 1 tells how many octets to drop (resynchronisation: one octet at a
    time, so a real start delimiter hidden inside garbage is found).
    """
    n = len(buf) - pos
    if n <= 0:
        return NEED_MORE
    sd = buf[pos]
    if sd == SC:
        return SC_FRAME, 1
    if sd == SD1:
        if n < 6:
            return NEED_MORE
        total = 6
        body_start, body_end = pos + 1, pos + 4
    elif sd == SD2:
        if n < 4:
            if n >= 2 and not 4 <= buf[pos + 1] <= 249:
                return FrameError(FrameError.LENGTH, f"LE {buf[pos + 1]} outside 4..249", 1)
            if n >= 3 and buf[pos + 2] != buf[pos + 1]:
                return FrameError(FrameError.LENGTH, "LE != LEr", 1)
            return NEED_MORE
        le = buf[pos + 1]
        if not 4 <= le <= 249:
            return FrameError(FrameError.LENGTH, f"LE {le} outside 4..249", 1)
        if buf[pos + 2] != le:
            return FrameError(FrameError.LENGTH, f"LE {le} != LEr {buf[pos + 2]}", 1)
        if buf[pos + 3] != SD2:
            return FrameError(FrameError.LENGTH, "second SD2 missing", 1)
        total = le + 6
        if n < total:
            return NEED_MORE
        body_start, body_end = pos + 4, pos + 4 + le
    elif sd == SD3:
        if n < 14:
            return NEED_MORE
        total = 14
        body_start, body_end = pos + 1, pos + 12
    elif sd == SD4:
        if n < 3:
            return NEED_MORE
        return _frame(SD4, buf[pos + 1] & ADDR_MASK, buf[pos + 2] & ADDR_MASK, 0, b"", None, None), 3
    else:
        return FrameError(FrameError.GARBAGE, f"0x{sd:02X} is no start delimiter", 1)
    if (sum(buf[body_start:body_end]) & 0xFF) != buf[body_end]:
        return FrameError(FrameError.FCS, f"FCS 0x{buf[body_end]:02X} wrong", 1)
    if buf[body_end + 1] != ED:
        return FrameError(FrameError.ED, f"end delimiter 0x{buf[body_end + 1]:02X}", 1)
    da, sa, fc = buf[body_start], buf[body_start + 1], buf[body_start + 2]
    i = body_start + 3
    dsap = ssap = None
    if da & ADDR_EXT:
        if i >= body_end:
            return FrameError(FrameError.SAP, "DSAP announced but missing", 1)
        dsap = buf[i] & 0x3F
        i += 1
    if sa & ADDR_EXT:
        if i >= body_end:
            return FrameError(FrameError.SAP, "SSAP announced but missing", 1)
        ssap = buf[i] & 0x3F
        i += 1
    return _frame(sd, da & ADDR_MASK, sa & ADDR_MASK, fc, bytes(buf[i:body_end]), dsap, ssap), total


def missing(buf: bytes | bytearray, pos: int = 0) -> int:
    """Octets still missing for the telegram that starts at buf[pos] (as far as its start delimiter
    and length octet tell; at least 1 while parse() says NEED_MORE, 0 for an empty buffer)."""
    n = len(buf) - pos
    if n <= 0:
        return 0
    sd = buf[pos]
    if sd == SD1:
        total = 6
    elif sd == SD3:
        total = 14
    elif sd == SD4:
        total = 3
    elif sd == SD2:
        total = buf[pos + 1] + 6 if n >= 2 else 7
    else:
        return 1
    return max(1, total - n)


class Receiver:
    """Streaming receiver: feed octets, take frames or typed errors. Never loops without consuming."""

    def __init__(self) -> None:
        self.buf = bytearray()

    def feed(self, data: bytes) -> None:
        self.buf += data

    def reset(self) -> None:
        self.buf.clear()

    def __len__(self) -> int:
        return len(self.buf)

    def next(self) -> Frame | FrameError | None:
        """NEED_MORE (None), a Frame, or a FrameError; consumed octets are dropped from the buffer."""
        r = parse(self.buf)
        if r is None:
            return None
        if isinstance(r, FrameError):
            del self.buf[:r.used]
            return r
        frame, used = r
        del self.buf[:used]
        return frame

    def drain(self) -> list[Frame | FrameError]:
        """Every complete frame / error currently in the buffer."""
        out: list[Frame | FrameError] = []
        while True:
            r = self.next()
            if r is None:
                return out
            out.append(r)
