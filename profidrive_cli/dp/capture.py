"""Passive capture: frames with timestamps from a byte stream; pcap files (DLT_USER0 = 147 by default,
which the shipped Wireshark dissector binds; LINKTYPE_PROFIBUS_DL = 257 on request).

In dp/ because it names each telegram's DP service (dp/services.py: SAP -> Set_Prm, Slave_Diag, ...);
it touches fdl.frames and dp.services only and is sans-IO (octets and times in, records out).

Streaming: Capture.feed gives the records a chunk completed and keeps only an unfinished telegram;
ErrorMerger joins a garbage run across chunks; with feed(hold=HOLD) a file read in chunks decodes as
in one piece. A frame's fields and line are kept per octets (bounded caches): a bus repeats its
telegrams, so `pdrive sniff` formats most of them once (benchmarks/bench_sniff.py). Values that
change every cycle defeat those caches: what a frame's fields, line and JSON take from its header
(SD, addresses, FC, SAPs) is made once per header (_Head), the octets' hex each time; and
Capture.feed parses a sound SD2 telegram without SAPs in place (what fdl.frames.parse gives).

DP-V1's acyclic telegrams (SAP 51, 50, 49: dp/msac1.py) are named by their PDU's function as well
("MSAC_C1 Read request", "MSAC_C1 poll", "MSAC_C1 Read error response"): their heads are made each
time, never kept, so every other telegram's head lookup stays what it was.
"""

from __future__ import annotations

import json
import math
import struct
from dataclasses import dataclass
from typing import Protocol, TypedDict

from profidrive_cli import UsageError
from profidrive_cli.dp import msac1 as M
from profidrive_cli.dp.services import service_name
from profidrive_cli.fdl import frames as F

LINKTYPE_PROFIBUS_DL = 257
#: DLT_USER0: Wireshark opens it and hands it to a dissector bound to wtap USER0 (wireshark/pdrive.lua);
#: the packets are the same (SD .. ED) as PROFIBUS_DL, which Wireshark 4.0 refuses to open
LINKTYPE_USER0 = 147
LINKTYPES = {"147": LINKTYPE_USER0, "257": LINKTYPE_PROFIBUS_DL}

#: octets that can start a telegram
_STARTS = frozenset((F.SD1, F.SD2, F.SD3, F.SD4, F.SC))
#: Capture.feed(hold=HOLD): fdl.frames.parse() needs at most 4 octets of a telegram (SD2's SD LE
#: LEr SD) to judge its start; from then on its answer is final or NEED_MORE
HOLD = 3


#: the start delimiters' names
_SD_NAMES = {F.SD1: "SD1", F.SD2: "SD2", F.SD3: "SD3", F.SD4: "SD4", F.SC: "SC"}
#: a frame's description and line are functions of its octets alone: both are kept for the octets
#: seen last (a bus repeats its telegrams cycle after cycle); cleared when this many are kept, so the
#: memory stays bounded whatever the capture's length
_CACHE_MAX = 4096


class FrameFields(TypedDict, total=False):
    """What frame_fields() tells of a frame (the JSON of `pdrive sniff`)."""
    sd: str
    raw: str
    service: str
    da: int
    sa: int
    dsap: int | None
    ssap: int | None
    fc: str
    fc_text: str
    du: str


_FIELDS: dict[bytes, FrameFields] = {}
_BODIES: dict[bytes, str] = {}


@dataclass(slots=True)
class Captured:
    t: float
    raw: bytes
    frame: F.Frame | None = None
    error: str = ""

    def describe(self) -> dict[str, object]:
        """The frame's fields (frame_fields) after its time, or its time, error and octets (a JSON row)."""
        f = self.frame
        if f is None:
            return {"t": round(self.t, 6), "error": self.error, "raw": self.raw.hex(" ")}
        d: dict[str, object] = {"t": round(self.t, 6)}
        d.update(frame_fields(self))
        return d


class _Head:
    """What a frame's fields, line and JSON take from its header alone -- SD, addresses, FC, SAPs and
    whether it carries data -- made once per header (a bus has a few hundred): the fields before
    `raw` and between `raw` and `du` (`mid`), the service, the line's text before the DU and the
    JSON pieces. A frame then costs its octets' hex only (values that change every cycle)."""
    __slots__ = ("sd", "mid", "service", "prefix", "json_mid", "json_end", "has_du")

    def __init__(self, f: F.Frame):
        d = _fields(b"", f)
        self.sd = d["sd"]
        self.has_du = "du" in d
        self.mid = {k: v for k, v in d.items() if k not in ("sd", "raw", "du", "service")}
        self.service = d["service"]
        # the line's text: this prefix, then the DU's hex (_body of the fields with an empty DU)
        self.prefix = _body({**d, "du": ""}) if self.has_du else _body(d)
        # json.dumps(frame_json(describe())) after "raw": the keys between raw and du, du, service
        mid = json.dumps(self.mid)[1:-1]
        self.json_mid = (", " + mid if mid else "") + (', "du": "' if self.has_du else "")
        self.json_end = ('", ' if self.has_du else ", ") + json.dumps({"service": self.service})[1:-1]


#: the heads seen (_Head), by (sd, da, sa, fc, dsap, ssap, carries data); bounded like the caches
_HEADS: dict[tuple[int, int, int, int, int | None, int | None, bool], _Head] = {}


def _head(f: F.Frame) -> _Head:
    key = (f.sd, f.da, f.sa, f.fc, f.dsap, f.ssap, bool(f.data))
    h = _HEADS.get(key)
    if h is None:
        h = _Head(f)
        if acyclic_sap(f) is not None:
            return h        # named by its PDU's first octet too: made each time (rare), never kept
        if len(_HEADS) >= _CACHE_MAX:
            _HEADS.clear()
        _HEADS[key] = h
    return h


#: the DP-V1 acyclic SAPs of a slave (dp/msac1.py) and the name of their telegrams
ACYCLIC_SAPS = {M.SAP_C1: "MSAC_C1", M.SAP_C1_ALARM: "MSAC_C1 alarm", M.SAP_C2: "MSAC_C2"}


def acyclic_sap(f: F.Frame) -> int | None:
    """The slave's DP-V1 acyclic SAP a telegram is for (a request's DSAP) or from (a reply's SSAP):
    51 (MSAC_C1), 50 (its alarm SAP) or 49 (MSAC_C2); None for any other telegram."""
    if f.dsap is None:
        return None
    sap = f.dsap if f.fc & F.FC_REQ else f.ssap
    return sap if sap in ACYCLIC_SAPS else None


def acyclic_service(sap: int, is_request: bool, du: bytes) -> str:
    """A DP-V1 acyclic telegram's service by its PDU's first octet: "MSAC_C1 Read request",
    "MSAC_C1 Write response", "MSAC_C1 Read error response" (the error bit), "MSAC_C1 poll" (a
    request without data: the master fetching the answer), "MSAC_C1 reply" (a reply without data: not
    ready yet), "MSAC_C1 Alarm_Ack request" on SAP 50, "MSAC_C2 Initiate request" on SAP 49."""
    prefix = ACYCLIC_SAPS[sap]
    if not du:
        return prefix + (" poll" if is_request else " reply")
    fn = du[0] & 0x7F
    if fn == M.ALARM_ACK and sap == M.SAP_C1_ALARM:
        prefix = "MSAC_C1"
    name = M.FUNCTIONS.get(fn, f"function 0x{fn:02X}")
    if is_request:
        return f"{prefix} {name} request"
    return f"{prefix} {name} {'error response' if du[0] & M.ERROR_BIT else 'response'}"


def frame_fields(c: Captured) -> FrameFields:
    """describe() of a frame without its time: sd, raw, service, da/sa, SAPs, fc, fc_text, du (kept
    per octets: do not change the dict)."""
    d = _FIELDS.get(c.raw)
    if d is None:
        f = c.frame
        if f is None:
            raise ValueError(f"not a frame: {c.error}")
        if len(_FIELDS) >= _CACHE_MAX:
            _FIELDS.clear()
        h = _head(f)
        d = {"sd": h.sd, "raw": c.raw.hex(" ")}
        d.update(h.mid)                                       # type: ignore[typeddict-item]
        if h.has_du:
            d["du"] = f.data.hex(" ")
        d["service"] = h.service
        _FIELDS[c.raw] = d
    return d


def frame_service(c: Captured) -> tuple[str, bool]:
    """(the frame's service as frame_fields names it, whether its fields carry a `du`)."""
    f = c.frame
    if f is None:
        raise ValueError(f"not a frame: {c.error}")
    h = _head(f)
    return h.service, h.has_du


def frame_json_head(c: Captured) -> str:
    """json.dumps of the frame event of docs/json.md ({"event": "frame", "t_s", then frame_fields})
    without its closing brace: the text json.dumps gives, made from the head's pieces and the
    octets' hex (the caller adds keys and the brace). Frames only (an error: ValueError)."""
    f = c.frame
    if f is None:
        raise ValueError(f"not a frame: {c.error}")
    h = _head(f)
    t = round(c.t, 6)
    ts = float.__repr__(t) if type(t) is float and math.isfinite(t) else json.dumps(t)
    return ('{"event": "frame", "t_s": ' + ts + ', "sd": "' + h.sd + '", "raw": "' + c.raw.hex(" ")
            + '"' + h.json_mid + (f.data.hex(" ") if h.has_du else "") + h.json_end)


def _fields(raw: bytes, f: F.Frame) -> FrameFields:
    d: FrameFields = {"sd": _SD_NAMES[f.sd], "raw": raw.hex(" ")}
    if f.sd == F.SC:
        d["service"] = "short acknowledge"
        return d
    d["da"], d["sa"] = f.da, f.sa
    if f.sd == F.SD4:
        d["service"] = "token"
        return d
    d.update({"dsap": f.dsap, "ssap": f.ssap, "fc": f"0x{f.fc:02X}", "fc_text": F.describe_fc(f.fc),
              "du": f.data.hex(" ")})
    if f.is_request and f.function == F.FDL_STATUS:
        d["service"] = "FDL status"
    elif not f.is_request and f.dsap is None and f.ssap is None and f.fc & 0x0F == F.OK and not f.data:
        d["service"] = "FDL status reply"
    elif (sap := acyclic_sap(f)) is not None:
        d["service"] = acyclic_service(sap, f.is_request, f.data)
    else:
        d["service"] = service_name(f.dsap, f.ssap, f.is_request) + ("" if f.is_request else " reply")
    return d


def format_line(c: Captured, arrow: str = "") -> str:
    """One line per frame, as `pdrive sniff` and the -vv trace print it: time, SD, SA -> DA, SAPs,
    FC in words, service, DU."""
    a = f"{arrow} " if arrow else ""
    t = c.t
    global _T, _T_TEXT
    if t != _T or type(t) is not float or not t and math.copysign(1.0, t) != math.copysign(1.0, _T):
        _T, _T_TEXT = t, f"{round(t, 6):>12.6f}  "
    if c.frame is None:
        return f"{_T_TEXT}{a}!! {c.error}: {c.raw.hex(' ')}"
    body = _BODIES.get(c.raw)
    if body is None:
        if len(_BODIES) >= _CACHE_MAX:
            _BODIES.clear()
        h = _head(c.frame)
        body = _BODIES[c.raw] = h.prefix + c.frame.data.hex(" ") if h.has_du else h.prefix
    return f"{_T_TEXT}{a}{body}"


#: the last time format_line wrote and its text (a capture's telegrams often share one)
_T: float = math.nan
_T_TEXT = ""


def _body(d: FrameFields) -> str:
    """A frame's line after its time column (and arrow)."""
    if d["sd"] == "SC":
        return "SC   short acknowledge"
    if d["sd"] == "SD4":
        return f"SD4  token {d['sa']} -> {d['da']}"
    saps = "" if d["dsap"] is None else f" [{d['ssap']}->{d['dsap']}]"
    return f"{d['sd']}  {d['sa']:>3} -> {d['da']:<3}{saps}  {d['fc_text']}  {d['service']}  {d['du']}"


class Capture:
    """Feed octets with the time they arrived; collect Captured frames and framing errors."""

    def __init__(self) -> None:
        self.rx = F.Receiver()
        self._t = 0.0

    def feed(self, data: bytes, t: float, hold: int = 0) -> list[Captured]:
        """Frames and framing errors completed by `data`. Linear in the input: the buffer is parsed
        by position and its consumed prefix dropped once per call (a 10 MiB capture decodes in
        one pass, not one copy of the rest per frame).

        hold=HOLD leaves what starts in the last HOLD octets for the next call: parse() judges the
        start of a telegram by the octets at hand (three octets of an SD2 header with LE != LEr are
        "LE != LEr", four "LE 5 != LEr 6"), so a file decoded in chunks with hold=HOLD, then a
        last feed(b"", t), gives the entries of one piece (with ErrorMerger for garbage runs)."""
        if not len(self.rx):
            self._t = t
        self.rx.feed(data)
        buf = self.rx.buf
        out: list[Captured] = []
        append = out.append
        pos = 0
        n = len(buf)
        stop = n - hold
        tt = self._t                    # the first entry's time: when its first octets came
        frame = F._frame
        while pos < stop:
            # the common telegram, an SD2 without SAPs, whole and sound: what F.parse gives for it
            # (SD LE LEr SD, 4 <= LE <= 249, FCS, ED; DA and SA without the extension bit)
            if buf[pos] == 0x68 and pos + 7 <= n:
                le = buf[pos + 1]
                end = pos + le + 6
                if (end <= n and buf[pos + 2] == le and buf[pos + 3] == 0x68 and 4 <= le <= 249
                        and buf[end - 1] == 0x16 and not (buf[pos + 4] | buf[pos + 5]) & 0x80
                        and sum(buf[pos + 4:end - 2]) & 0xFF == buf[end - 2]):
                    raw = bytes(buf[pos:end])
                    append(Captured(tt, raw, frame(0x68, raw[4], raw[5], raw[6], raw[7:-2],
                                                   None, None)))
                    pos = end
                    tt = t
                    continue
            r = F.parse(buf, pos)
            if r is None:
                break
            if isinstance(r, F.FrameError):
                used = r.used
                if r.kind == F.FrameError.GARBAGE:
                    # a run of octets that cannot start a telegram is one entry
                    end = pos + used
                    while end < n and buf[end] not in _STARTS:
                        end += 1
                    used = end - pos
                    append(Captured(tt, bytes(buf[pos:end]), None, "garbage"))
                else:
                    append(Captured(tt, bytes(buf[pos:pos + used]), None, f"{r.kind}: {r.detail}"))
            else:
                f, used = r
                append(Captured(tt, bytes(buf[pos:pos + used]), f))
            pos += used
            tt = t
        if out:
            self._t = t
        if pos:
            del buf[:pos]
        return out


def merge_errors(items: list[Captured]) -> list[Captured]:
    """Collapse runs of garbage errors into one entry (readable sniff output). Linear: a run's
    octets are joined once."""
    m = ErrorMerger()
    return m.feed(items) + m.flush()


class ErrorMerger:
    """merge_errors over a stream of chunks: feed() each chunk's items, flush() at the end; a run
    of garbage that goes on in the next chunk stays one entry (a file read in chunks is shown as if
    it had been decoded in one piece)."""

    def __init__(self) -> None:
        self._run: list[Captured] = []

    def feed(self, items: list[Captured]) -> list[Captured]:
        out: list[Captured] = []
        run = self._run
        for c in items:
            if c.frame is None and c.error.startswith("garbage"):
                run.append(c)
            else:
                if run:
                    out += self.flush()
                out.append(c)
        return out

    def flush(self) -> list[Captured]:
        """The pending run of garbage as one entry (nothing if there is none)."""
        run = self._run
        if not run:
            return []
        c = run[0] if len(run) == 1 else Captured(run[0].t, b"".join(c.raw for c in run), None,
                                                  "garbage")
        run.clear()
        return [c]


#: the end of the times a capture packet may carry: 10000-01-01 00:00:00 UTC (Python's dates end with
#: 9999; dp/capfile.py's readers refuse a packet time outside 0 <= t < T_MAX)
T_MAX = 253_402_300_800.0
#: pcap: u32 seconds since 1970 (and a fraction below one second)
PCAP_T_MAX = float(1 << 32)
PCAP_RANGE = "0 to 4294967295.999999 s: 1970-01-01 to 2106-02-07 06:28:15 UTC, u32 seconds"


class TimeRangeError(UsageError):
    """A packet time a capture format cannot hold: "packet N: time T s is out of range for FORMAT
    (its range)"; the caller adds the file (exit 2). `index` is the writer's packet number (from 1)."""

    def __init__(self, index: int, t: float, fmt: str, limits: str):
        self.index, self.t, self.format = index, t, fmt
        super().__init__(f"packet {index}: time {t:.6f} s is out of range for {fmt} ({limits})")


def check_time(index: int, t: float, lo: float, hi: float, fmt: str, limits: str) -> None:
    """TimeRangeError unless lo <= t < hi (a NaN or an infinity is never inside)."""
    if not (math.isfinite(t) and lo <= t < hi):
        raise TimeRangeError(index, t, fmt, limits)


class BinaryWriter(Protocol):
    """Where a PcapWriter writes: a binary file, a fifo, a pipe."""

    def write(self, data: bytes, /) -> object: ...


class PcapWriter:
    """A classic pcap file (microsecond timestamps, little-endian). `start` is the wall-clock time
    (time.time()) of t = 0: write(t, raw) stamps start + t, so a capture timed on a monotonic clock
    from its start carries real dates. The header is written at once (also to a fifo: extcap).
    A time pcap cannot hold (before 1970, from 2106-02-07 06:28:16 UTC on: u32 seconds) is a
    TimeRangeError, and nothing of that packet is written."""

    def __init__(self, fh: BinaryWriter, linktype: int = LINKTYPE_USER0, start: float = 0.0):
        self.fh = fh
        self.start = start
        self.linktype = linktype
        self.count = 0
        fh.write(struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 65535, linktype))

    def write(self, t: float, raw: bytes) -> None:
        self.count += 1
        t = self.start + t
        check_time(self.count, t, 0.0, PCAP_T_MAX, "pcap", PCAP_RANGE)
        sec = int(t)
        usec = int(round((t - sec) * 1e6))
        if usec >= 1000000:
            sec, usec = sec + 1, usec - 1000000
        if sec >= 1 << 32:                       # rounded up into the second after the last
            raise TimeRangeError(self.count, t, "pcap", PCAP_RANGE)
        self.fh.write(struct.pack("<IIII", sec, usec, len(raw), len(raw)) + raw)


def read_pcap(data: bytes) -> tuple[int, list[tuple[float, bytes]]]:
    """(linktype, [(time, packet), ...]) from a classic little-endian pcap file."""
    magic, _, _, _, _, _, linktype = struct.unpack_from("<IHHiIII", data, 0)
    if magic != 0xA1B2C3D4:
        raise ValueError("not a little-endian pcap file")
    pos, pkts = 24, []
    while pos + 16 <= len(data):
        sec, usec, incl, _ = struct.unpack_from("<IIII", data, pos)
        pos += 16
        pkts.append((sec + usec / 1e6, data[pos:pos + incl]))
        pos += incl
    return linktype, pkts


__all__ = ["Capture", "Captured", "ErrorMerger", "HOLD", "PcapWriter", "read_pcap", "merge_errors", "frame_fields",
           "frame_service", "frame_json_head", "ACYCLIC_SAPS", "acyclic_sap", "acyclic_service",
           "LINKTYPE_USER0", "LINKTYPE_PROFIBUS_DL", "LINKTYPES", "TimeRangeError", "check_time", "T_MAX"]
