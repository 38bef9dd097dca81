"""Capture files as streams: raw octets, pcap, pcapng (per-packet direction and comments) and
ProfiTrace .ptd, read and written one packet at a time (memory flat in the file's length).

A packet is `Packet(t, raw, direction, comment)`: `t` the wall-clock time in seconds (time.time()
scale), `raw` one telegram's octets SD .. ED (or a framing error's octets), `direction` "in", "out" or
None (pcapng epb_flags), `comment` a text or None (pcapng opt_comment; for raw files the framing error).

    reader = open_capture("bus.ptd")          # format by extension; the header is read and checked now
    for p in reader: ...                      # packets, read in buffered chunks as they are needed
    with open("bus.pcapng", "wb") as fh:
        w = open_writer(fh, "pcapng")         # or capture_format(path) for the format of a path
        w.write(p); ...; w.close()

Formats (what each keeps):
  raw     the octets as they came (`pdrive sniff --raw`); no times: every packet carries the file's
          modification time (as `sniff --from-file --pcap` stamps them); framed here with dp.capture.
  pcap    classic pcap, link type 147 (DLT_USER0, pdrive's dissector) or 257 (PROFIBUS_DL); read also
          big-endian and nanosecond files; written with dp.capture.PcapWriter. No direction, no comment.
  pcapng  Section Header, one Interface Description (link type 147 or 257), Enhanced Packet Blocks with
          epb_flags (inbound / outbound) and opt_comment. Read: every section and interface, Simple
          Packet Blocks too; other blocks are skipped.
  ptd     ProfiTrace, from the public reverse-engineered layout (KU Leuven's MATLAB uart.m ptdread /
          ptdwrite, github.com/fredericdepuydt/matlab-libraries): a 1000-octet header, then one record
          per telegram, 66 66 LEN ... LEN 77 77, with a timestamp in bit times since the recording's
          start. A record keeps the telegram's fields, not its octets: the FCS is computed again, a bad
          FCS or a framing error is kept as pdrive's own "illegal" record (type 0, the octets as data).
          What is unverified is listed in docs/commands.md ("pdrive convert").

Errors in a file are one line naming the file and the octet offset (CaptureFileError, exit 2).

Time ranges. A Packet's time is a date from 1970-01-01 to 9999-12-31 UTC (0 <= t < T_MAX, the
range of Python's dates: what every part of pdrive can show and the .ptd header can hold); a reader
refuses a packet outside it ("FILE: octet M: packet N: time ... is out of range"), and a pcap
fraction that is not below one second. What each format holds beyond that is its writer's check
(dp.capture.TimeRangeError, "packet N: time T s is out of range for FORMAT (...)"):
  pcap    u32 seconds + microseconds: 0 <= t < 2^32 s (2106-02-07 06:28:16 UTC)
  pcapng  u64 ticks of if_tsresol (pdrive writes 10^-6): 0 <= t < 2^64 us (never binding under T_MAX);
          read: ticks x if_tsresol + if_tsoffset (a signed count of seconds)
  ptd     the header's date (u16 year; pdrive reads and writes 1970..9999) and u64 bit times since
          the first packet's whole second: a packet before that second cannot be held
A pcapng block shorter than its type's fixed part is "FILE: not a valid pcapng: ... block at offset
N is too short".
"""

from __future__ import annotations

import calendar
import math
import os
import stat
import struct
import time
from pathlib import Path
from typing import IO, Any, BinaryIO, Callable, Iterator, NamedTuple

from profidrive_cli import UsageError
from profidrive_cli.dp.capture import (LINKTYPE_PROFIBUS_DL, LINKTYPE_USER0, T_MAX, Capture, PcapWriter,
                                       TimeRangeError, check_time, merge_errors)
from profidrive_cli.fdl import frames as F

FORMATS = ("raw", "pcap", "pcapng", "ptd")
EXTENSIONS = {".raw": "raw", ".pcap": "pcap", ".pcapng": "pcapng", ".ptd": "ptd"}
LINKTYPES = (LINKTYPE_USER0, LINKTYPE_PROFIBUS_DL)
#: dp.capture's decoder (its constructor carries no annotations: called through Any under --strict)
_CAPTURE: Any = Capture
CHUNK = 1 << 20                 # raw files are read in chunks of this many octets
MAX_PACKET = 1 << 18            # a pcap / pcapng record longer than this is a broken file
#: pcapng block types -> (name, the fixed part's octets: header, fixed fields and trailer)
PCAPNG_FIXED = {0x0A0D0D0A: ("section header", 28), 1: ("interface description", 20), 3: ("simple packet", 16),
                6: ("enhanced packet", 32)}


class Packet(NamedTuple):
    t: float
    raw: bytes
    direction: str | None = None      # "in", "out" or None (unknown)
    comment: str | None = None


class CaptureFileError(UsageError):
    """A capture file that cannot be read: one line with the path and the octet offset."""

    def __init__(self, path: str | os.PathLike[str], offset: int | None, message: str):
        where = f"{path}: octet {offset}" if offset is not None else str(path)
        super().__init__(f"{where}: {message}")


def capture_format(path: str | os.PathLike[str], default: str | None = None) -> str:
    """The format of a file by its extension (.raw .pcap .pcapng .ptd); `default` for any other
    extension, or UsageError when there is none."""
    ext = Path(path).suffix.lower()
    fmt = EXTENSIONS.get(ext, default)
    if fmt is None:
        raise UsageError(f"{path}: unknown capture format {ext or '(no extension)'!r}: the extension says "
                         f"the format ({', '.join(EXTENSIONS)})")
    return fmt


# -------------------------------------------------------------------------------------------------
# reading

class CaptureReader:
    """An open capture file: iterate for its packets. The header is read and checked when the
    reader is made, so a wrong file is refused before anything is written. `linktype` (pcap: from
    the header; pcapng: the first interface's), `baud` (ptd: from the header) may be None."""

    def __init__(self, path: str | os.PathLike[str], fmt: str):
        self.path = Path(path)
        self.format = fmt
        self.linktype: int | None = None
        self.baud: int | None = None
        self._fh = _open_input(self.path)
        self._pos = 0
        self._at = 0                    # where the packet being read starts (octet)
        #: packets read so far (the next one is number packets + 1)
        self.packets = 0
        try:
            self._it: Iterator[Packet] = self._checked({"raw": self._raw, "pcap": self._pcap,
                                                        "pcapng": self._pcapng, "ptd": self._ptd}[fmt]())
            self._first = next(self._it, None)
        except BaseException:
            self._fh.close()
            raise

    def __iter__(self) -> Iterator[Packet]:
        try:
            if self._first is not None:
                first, self._first = self._first, None
                yield first
                yield from self._it
        finally:
            self._fh.close()

    def close(self) -> None:
        self._fh.close()

    # -- helpers ----------------------------------------------------------------------------------
    def _fail(self, offset: int | None, message: str) -> CaptureFileError:
        return CaptureFileError(self.path, offset, message)

    def _checked(self, packets: Iterator[Packet]) -> Iterator[Packet]:
        """The format's packets, counted, each time inside 0 <= t < T_MAX (the module doc)."""
        for p in packets:
            self.packets += 1
            if not 0.0 <= p.t < T_MAX:
                raise self._fail(self._at, f"packet {self.packets}: time {p.t:.6f} s is out of range "
                                           f"(a date from 1970-01-01 to 9999-12-31 UTC)")
            yield p

    def _read(self, n: int, what: str, eof_ok: bool = False) -> bytes:
        """Exactly n octets (b"" at a clean end of file when eof_ok)."""
        try:
            data = self._fh.read(n)
        except OSError as e:
            raise self._fail(self._pos, f"cannot read: {e.strerror or e}") from None
        if len(data) != n and not (eof_ok and not data):
            raise self._fail(self._pos, f"file ends inside {what} ({len(data)} of {n} octets)")
        self._pos += len(data)
        return data

    # -- raw --------------------------------------------------------------------------------------
    def _raw(self) -> Iterator[Packet]:
        t = os.fstat(self._fh.fileno()).st_mtime
        cap = _CAPTURE()
        while True:
            try:
                data = self._fh.read(CHUNK)
            except OSError as e:
                raise self._fail(self._pos, f"cannot read: {e.strerror or e}") from None
            self._pos += len(data)
            if not data:
                break
            for c in merge_errors(cap.feed(data, 0.0)):
                yield Packet(t, c.raw, None, c.error or None)
        if len(cap.rx):
            yield Packet(t, bytes(cap.rx.buf), None, "truncated frame at end of input")

    # -- pcap -------------------------------------------------------------------------------------
    def _pcap(self) -> Iterator[Packet]:
        head = self._read(24, "the pcap header")
        magic = head[:4]
        forms = {b"\xd4\xc3\xb2\xa1": ("<", 1e-6), b"\xa1\xb2\xc3\xd4": (">", 1e-6),
                 b"\x4d\x3c\xb2\xa1": ("<", 1e-9), b"\xa1\xb2\x3c\x4d": (">", 1e-9)}
        if magic not in forms:
            raise self._fail(0, "not a pcap file (magic " + magic.hex(" ") + ")")
        order, unit = forms[magic]
        per_second = round(1 / unit)
        self.linktype = struct.unpack(order + "I", head[20:24])[0] & 0x0FFFFFFF
        self._check_linktype(self.linktype, 20)
        rec = struct.Struct(order + "IIII")
        while True:
            at = self._at = self._pos
            h = self._read(16, "a packet header", eof_ok=True)
            if not h:
                return
            sec, frac, incl, _ = rec.unpack(h)
            if frac >= per_second:
                raise self._fail(at + 4, f"packet {self.packets + 1}: time fraction {frac} is out of range "
                                         f"(0 to {per_second - 1} {'us' if per_second == 10**6 else 'ns'})")
            if incl > MAX_PACKET:
                raise self._fail(at, f"packet of {incl} octets: not a PROFIBUS telegram (broken file?)")
            yield Packet(sec + frac * unit, self._read(incl, "a packet"))

    def _check_linktype(self, lt: int, offset: int) -> None:
        if lt not in LINKTYPES:
            raise self._fail(offset, f"link type {lt} is not PROFIBUS (pdrive reads 147 DLT_USER0 and "
                                     f"257 PROFIBUS_DL)")

    # -- pcapng -----------------------------------------------------------------------------------
    def _pcapng(self) -> Iterator[Packet]:
        order = "<"
        ifaces: list[tuple[int, float, int]] = []   # (link type, seconds per tick, if_tsoffset)
        first = True
        while True:
            at = self._at = self._pos
            h = self._read(8, "a block header", eof_ok=True)
            if not h:
                if first:
                    raise self._fail(0, "empty file: no pcapng section header")
                return
            btype = struct.unpack("<I", h[:4])[0]
            if first and btype != 0x0A0D0D0A:
                raise self._fail(0, "not a pcapng file (no section header block)")
            first = False
            if btype == 0x0A0D0D0A:
                bom = self._read(4, "the byte-order magic")
                if bom == b"\x4d\x3c\x2b\x1a":
                    order = "<"
                elif bom == b"\x1a\x2b\x3c\x4d":
                    order = ">"
                else:
                    raise self._fail(at + 8, "bad pcapng byte-order magic " + bom.hex(" "))
                total = self._block_length(btype, struct.unpack(order + "I", h[4:])[0], at)
                self._read(total - 12, "the section header")
                ifaces = []
                continue
            total = self._block_length(btype, struct.unpack(order + "I", h[4:])[0], at)
            body = self._read(total - 8, "a block")[:-4]
            if btype == 1:                                          # Interface Description
                lt = struct.unpack(order + "H", body[:2])[0]
                self._check_linktype(lt, at + 8)
                if self.linktype is None:
                    self.linktype = lt
                opts = _options(body[8:], order)
                offset = opts.get(14, [b""])[0]                     # if_tsoffset: s64 seconds
                ifaces.append((lt, _tsresol(opts.get(9, [])),
                               struct.unpack(order + "q", offset)[0] if len(offset) == 8 else 0))
            elif btype == 6:                                        # Enhanced Packet
                iface, hi, lo, caplen, _ = struct.unpack(order + "IIIII", body[:20])
                if iface >= len(ifaces):
                    raise self._fail(at + 8, f"packet of interface {iface}, which is not described")
                if 20 + caplen > len(body):
                    raise self._fail(at + 20, f"captured length {caplen} exceeds the block")
                data = body[20:20 + caplen]
                opts = _options(body[20 + _pad4(caplen):], order)
                direction = None
                if 2 in opts and len(opts[2][0]) == 4:
                    d = struct.unpack(order + "I", opts[2][0])[0] & 3
                    direction = {1: "in", 2: "out"}.get(d)
                comment = opts[1][0].decode("utf-8", "replace") if 1 in opts else None
                _, resol, offset = ifaces[iface]
                yield Packet(((hi << 32) | lo) * resol + offset, data, direction, comment)
            elif btype == 3:                                        # Simple Packet: no time
                if not ifaces:
                    raise self._fail(at + 8, "simple packet before any interface description")
                (orig,) = struct.unpack(order + "I", body[:4])
                yield Packet(0.0, body[4:4 + orig])
            # other blocks (name resolution, statistics, custom ...) say nothing about telegrams

    def _block_length(self, btype: int, total: int, at: int) -> int:
        """A block's total length, checked: at least its type's fixed part, a multiple of 4, bounded."""
        name, need = PCAPNG_FIXED.get(btype, ("a", 12))
        if total < need:
            raise CaptureFileError(self.path, None, f"not a valid pcapng: {name} block at offset {at} is "
                                   f"too short ({total} octets; its fixed part is {need})")
        if total % 4 or total > MAX_PACKET + 64:
            raise self._fail(at + 4, f"bad block length {total}")
        return total

    # -- ProfiTrace .ptd --------------------------------------------------------------------------
    def _ptd(self) -> Iterator[Packet]:
        head = self._read(PTD_HEADER, "the 1000-octet ProfiTrace header")
        code = head[36]
        if code >= len(PTD_BAUDS):
            raise self._fail(36, f"unknown ProfiTrace baud rate code {code}")
        self.baud = baud = PTD_BAUDS[code]
        start = _ptd_date(head, 65)
        while True:
            at = self._at = self._pos
            h = self._read(4, "a record", eof_ok=True)
            if not h:
                return
            if h[:2] != b"\x66\x66":
                raise self._fail(at, f"record does not start with 66 66 (found {h[:2].hex(' ')})")
            size = struct.unpack("<H", h[2:])[0] + 13
            if size < 35:
                raise self._fail(at + 2, f"record length {size} is shorter than a record header")
            rec = h + self._read(size - 4, "a record")
            if rec[-2:] != b"\x77\x77":
                raise self._fail(at + size - 2, "record does not end with 77 77")
            if rec[-4:-2] != rec[2:4]:
                raise self._fail(at + size - 4, "the record's two lengths differ")
            bits = struct.unpack("<Q", rec[13:21])[0]
            yield Packet(start + bits / baud, *_ptd_octets(rec, lambda m: self._fail(at, m)))


PTD_HEADER = 1000
#: the header's baud rate code (octet 36) -> bit/s, as the reverse-engineered reader lists them
PTD_BAUDS = (9600, 19200, 38400, 187500, 500000, 1500000, 3000000, 6000000, 12000000)
#: record type (octet 21) per start delimiter; 0 = illegal (pdrive: the octets as data)
PTD_TYPES = {F.SD1: 1, F.SD2: 2, F.SD3: 4, F.SD4: 8, F.SC: 16}


def _ptd_octets(rec: bytes, fail: Callable[[str], CaptureFileError]) -> tuple[bytes, None, str | None]:
    """A record's telegram as octets (encoded again from its fields: the FCS is computed)."""
    kind, sa, da, ssap, dsap, fc, n = rec[21], rec[23], rec[24], rec[25], rec[26], rec[27], rec[28]
    if 31 + n > len(rec) - 4:
        raise fail(f"data length {n} exceeds the record")
    data = rec[31:31 + n]
    if kind == 16:
        return b"\xE5", None, None
    if kind == 8:
        return F.encode(F.token(da & 0x7F, sa & 0x7F)), None, None
    if kind in (1, 2, 4):
        saps = (None, None) if (ssap, dsap) == (255, 255) else (dsap, ssap)
        try:
            raw = F.encode(F.Frame(F.SD2, da & 0x7F, sa & 0x7F, fc, data, saps[0], saps[1]), kind == 2)
        except ValueError as e:
            raise fail(f"record cannot be a telegram: {e}") from None
        want = {1: F.SD1, 2: F.SD2, 4: F.SD3}[kind]
        if raw[0] != want:
            raise fail(f"record type {kind} with {n} data octets is not an SD{(1, 2, 0, 3)[kind - 1]} telegram")
        return raw, None, None
    return data, None, ("illegal telegram" if kind == 0 else f"ProfiTrace record type {kind}")


def _ptd_date(head: bytes, at: int) -> float:
    """The header's date (day, month, _, year LE16, hour, minute, second at `at`) as seconds since
    the epoch, read as UTC (unverified: ProfiTrace may write local time); 0 when it is not a date."""
    day, month, year = head[at], head[at + 1], struct.unpack("<H", head[at + 3:at + 5])[0]
    hour, minute, sec = head[at + 5], head[at + 6], head[at + 7]
    try:
        return float(calendar.timegm((year, month, day, hour, minute, sec, 0, 0, 0))) \
            if 1 <= month <= 12 and 1 <= day <= 31 and year >= 1970 else 0.0
    except (ValueError, OverflowError):
        return 0.0


def _pad4(n: int) -> int:
    return (n + 3) & ~3


def _options(buf: bytes, order: str) -> dict[int, list[bytes]]:
    """pcapng options: code -> values (until opt_endofopt or the end of the buffer)."""
    out: dict[int, list[bytes]] = {}
    pos = 0
    while pos + 4 <= len(buf):
        code, ln = struct.unpack(order + "HH", buf[pos:pos + 4])
        if code == 0:
            break
        out.setdefault(code, []).append(buf[pos + 4:pos + 4 + ln])
        pos += 4 + _pad4(ln)
    return out


def _tsresol(values: list[bytes]) -> float:
    """if_tsresol: seconds per timestamp unit (default 10^-6)."""
    if not values or not values[0]:
        return 1e-6
    r = values[0][0]
    return 2.0 ** -(r & 0x7F) if r & 0x80 else 10.0 ** -r


def _open_input(path: Path) -> BinaryIO:
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise CaptureFileError(path, None, "file not found") from None
    except (OSError, ValueError) as e:
        raise CaptureFileError(path, None, f"cannot read: {getattr(e, 'strerror', None) or e}") from None
    if stat.S_ISDIR(st.st_mode):
        raise CaptureFileError(path, None, "is a folder, not a capture file")
    if not stat.S_ISREG(st.st_mode):
        raise CaptureFileError(path, None, "is not a regular file (a capture file expected)")
    try:
        return open(path, "rb")
    except OSError as e:
        raise CaptureFileError(path, None, f"cannot read: {e.strerror or e}") from None


def open_capture(path: str | os.PathLike[str], fmt: str | None = None,
                 default_format: str | None = None) -> CaptureReader:
    """The packets of a capture file, format by extension (or `fmt`); `default_format` for an
    unknown extension (sniff --from-file: "raw"), else an unknown extension is a UsageError."""
    return CaptureReader(path, fmt or capture_format(path, default_format))


# -------------------------------------------------------------------------------------------------
# writing

class CaptureWriter:
    """write(packet) for each packet, close() at the end (the file itself is the caller's)."""

    count = 0

    def write(self, p: Packet) -> None:
        raise NotImplementedError

    def close(self) -> None:
        pass


class RawWriter(CaptureWriter):
    def __init__(self, fh: IO[bytes]):
        self.fh = fh

    def write(self, p: Packet) -> None:
        self.fh.write(p.raw)
        self.count += 1


class PcapFileWriter(CaptureWriter):
    """pcap through dp.capture.PcapWriter (times as given: its start is 0)."""

    def __init__(self, fh: IO[bytes], linktype: int = LINKTYPE_USER0):
        self.w = PcapWriter(fh, linktype, 0.0)

    def write(self, p: Packet) -> None:
        self.w.write(p.t, p.raw)
        self.count += 1


class PcapngWriter(CaptureWriter):
    """pcapng: one section, one interface (microsecond times), Enhanced Packet Blocks with
    epb_flags for a known direction and opt_comment for a comment."""

    def __init__(self, fh: IO[bytes], linktype: int = LINKTYPE_USER0, application: str = "pdrive"):
        self.fh = fh
        shb_opts = _opt(4, application.encode("utf-8")) + _opt_end()     # shb_userappl
        fh.write(_block(0x0A0D0D0A, struct.pack("<IHHq", 0x1A2B3C4D, 1, 0, -1) + shb_opts))
        idb_opts = _opt(2, b"pdrive") + _opt(9, b"\x06") + _opt_end()    # if_name, if_tsresol 10^-6
        fh.write(_block(1, struct.pack("<HHI", linktype, 0, 0) + idb_opts))

    def write(self, p: Packet) -> None:
        check_time(self.count + 1, p.t, 0.0, PCAPNG_T_MAX, "pcapng", PCAPNG_RANGE)
        ts = int(round(p.t * 1e6))
        if ts >= 1 << 64:                       # rounded up past the last tick
            raise TimeRangeError(self.count + 1, p.t, "pcapng", PCAPNG_RANGE)
        n = len(p.raw)
        opts = b""
        if p.direction in ("in", "out"):
            opts += _opt(2, struct.pack("<I", 1 if p.direction == "in" else 2))
        if p.comment:
            opts += _opt(1, p.comment.encode("utf-8"))
        if opts:
            opts += _opt_end()
        body = struct.pack("<IIIII", 0, (ts >> 32) & 0xFFFFFFFF, ts & 0xFFFFFFFF, n, n) + p.raw \
            + b"\0" * (_pad4(n) - n) + opts
        self.fh.write(_block(6, body))
        self.count += 1


def _opt(code: int, value: bytes) -> bytes:
    return struct.pack("<HH", code, len(value)) + value + b"\0" * (_pad4(len(value)) - len(value))


def _opt_end() -> bytes:
    return b"\0\0\0\0"


def _block(btype: int, body: bytes) -> bytes:
    total = 12 + len(body)
    return struct.pack("<II", btype, total) + body + struct.pack("<I", total)


#: pcapng as pdrive writes it: u64 microseconds since 1970
PCAPNG_T_MAX = 2.0 ** 64 / 1e6
PCAPNG_RANGE = "0 to 2^64 us: u64 microseconds since 1970"
#: ProfiTrace: the header's date (pdrive: the years 1970..9999), u64 bit times since the first packet
PTD_RANGE = ("a date from 1970-01-01 to 9999-12-31 UTC, not before the first packet's whole second "
             "{start:.0f}: u64 bit times from there")


class PtdWriter(CaptureWriter):
    """ProfiTrace .ptd: the header (written again with the counts at close: the file must be
    seekable), one record per packet with its time in bit times since the first packet's whole
    second. A framing error or a telegram with a bad FCS becomes an illegal record (type 0) holding
    its octets, in pieces of at most 255."""

    def __init__(self, fh: IO[bytes], baud: int = 1_500_000, note: str = "written by pdrive"):
        if baud not in PTD_BAUDS:
            raise UsageError(f"ProfiTrace files know the baud rates {', '.join(map(str, PTD_BAUDS))}; "
                             f"{baud} has no code there")
        self.fh = fh
        self.baud = baud
        self.note = note
        self.start: float | None = None
        self.last = 0.0
        self.packets = 0                        # packets given (count: records written)
        self.size = PTD_HEADER
        fh.write(self._header())

    def _header(self) -> bytes:
        h = bytearray(PTD_HEADER)
        h[0], h[1], h[896] = 9, 2, 5                        # version 2.9.5, as the known writer says
        h[4:12] = struct.pack("<Q", self.size)
        h[32:36] = struct.pack("<I", self.count)
        h[36] = PTD_BAUDS.index(self.baud)
        h[124:164] = b"\xff" * 40
        h[900:904] = b"\xff" * 4
        for at, t in ((65, self.start), (77, self.last if self.start is not None else None)):
            if t is not None:
                tm = time.gmtime(t)
                h[at], h[at + 1] = tm.tm_mday, tm.tm_mon
                h[at + 3:at + 5] = struct.pack("<H", tm.tm_year)
                h[at + 5], h[at + 6], h[at + 7] = tm.tm_hour, tm.tm_min, tm.tm_sec
        note = self.note.encode("latin-1", "replace")[:80]
        h[164:164 + len(note)] = note
        return bytes(h)

    def write(self, p: Packet) -> None:
        self.packets += 1
        start = self.start
        if start is None:
            start = float(math.floor(p.t)) if math.isfinite(p.t) else 0.0
        limits = PTD_RANGE.format(start=start)
        check_time(self.packets, p.t, max(start, 0.0), T_MAX, "ptd", limits)
        bits = int(round((p.t - start) * self.baud))
        if bits >= 1 << 64:                     # never under T_MAX (2^64 bit times at 12M: 48 700 years)
            raise TimeRangeError(self.packets, p.t, "ptd", limits)
        self.start = start
        self.last = p.t
        for fields in _ptd_fields(p.raw):
            self.count += 1
            self._record(bits, fields)

    def _record(self, bits: int, fields: tuple[int, int, int, int, int, int, bytes]) -> None:
        kind, sa, da, ssap, dsap, fc, data = fields
        size = 35 + len(data)
        r = bytearray(size)
        r[0:2] = b"\x66\x66"
        r[2:4] = r[size - 4:size - 2] = struct.pack("<H", size - 13)
        r[4] = 1
        r[5:9] = r[9:13] = struct.pack("<I", self.count)
        r[13:21] = struct.pack("<Q", bits)
        r[21], r[23], r[24], r[25], r[26], r[27], r[28] = kind, sa, da, ssap, dsap, fc, len(data)
        r[31:31 + len(data)] = data
        r[size - 2:] = b"\x77\x77"
        self.fh.write(bytes(r))
        self.size += size

    def close(self) -> None:
        self.fh.seek(0)
        self.fh.write(self._header())
        self.fh.seek(0, os.SEEK_END)


def _ptd_fields(raw: bytes) -> list[tuple[int, int, int, int, int, int, bytes]]:
    """(type, SA, DA, SSAP, DSAP, FC, data) records for one packet's octets."""
    r = F.parse(raw) if raw else None
    if r is not None and not isinstance(r, F.FrameError) and r[1] == len(raw) \
            and _encodes_back(r[0], raw):
        f = r[0]
        kind = PTD_TYPES[f.sd]
        if f.sd == F.SC:
            return [(kind, 0, 0, 0, 0, 0, b"")]
        if f.sd == F.SD4:
            return [(kind, f.sa, f.da, 0, 0, 0, b"")]
        ssap, dsap = (255, 255) if f.dsap is None else (f.ssap if f.ssap is not None else 0, f.dsap)
        return [(kind, f.sa, f.da, ssap, dsap, f.fc, f.data)]
    return [(0, 0, 0, 0, 0, 0, raw[i:i + 255]) for i in range(0, max(len(raw), 1), 255)]


def _encodes_back(f: F.Frame, raw: bytes) -> bool:
    """A record keeps fields, not octets: only a telegram that pdrive's encoder writes back octet
    for octet is stored as one (SAP octets with high bits, a lone SAP: an illegal record)."""
    try:
        return F.encode(f, f.sd == F.SD2) == raw
    except ValueError:
        return False


def open_writer(fh: IO[bytes], fmt: str, *, linktype: int = LINKTYPE_USER0, baud: int = 1_500_000) -> CaptureWriter:
    """A writer of `fmt` onto an open binary file (the header is written now)."""
    if fmt == "raw":
        return RawWriter(fh)
    if fmt == "pcap":
        return PcapFileWriter(fh, linktype)
    if fmt == "pcapng":
        return PcapngWriter(fh, linktype)
    if fmt == "ptd":
        return PtdWriter(fh, baud)
    raise UsageError(f"unknown capture format {fmt!r} ({', '.join(FORMATS)})")


__all__ = ["Packet", "CaptureFileError", "CaptureReader", "CaptureWriter", "open_capture", "open_writer",
           "capture_format", "FORMATS", "EXTENSIONS", "PTD_BAUDS"]
