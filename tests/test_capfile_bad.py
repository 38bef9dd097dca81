"""Capture files that must be refused (issue 35): a pcapng block shorter than its fixed part, and times
a format cannot hold, through every reader -- `sniff --from-file`, `convert`, `sim --learn` -- as one
line, exit 2, nothing written; and the edges of each format's time range.

The files are built here by hand from the formats' layouts, not by pdrive's writers:
  pcap    (the pcap draft, draft-ietf-opsawg-pcap) 24-octet header, magic A1B2C3D4 (microseconds) or
          A1B23C4D (nanoseconds), then per packet u32 seconds, u32 fraction (below 10^6 / 10^9), u32
          captured length, u32 original length.
  pcapng  (draft-ietf-opsawg-pcapng) every block: u32 type, u32 total length, body, u32 total length.
          Section Header (0x0A0D0D0A): byte-order magic 1A2B3C4D, version 1.0, s64 section length:
          28 octets without options. Interface Description (1): u16 link type, u16 reserved, u32
          snaplen: 20 octets without options; options 9 if_tsresol (u8: 10^-n, or 2^-n with the top
          bit) and 14 if_tsoffset (s64 seconds added to every timestamp). Enhanced Packet (6): u32
          interface, u32 timestamp high, u32 low, u32 captured length, u32 original length: 32 octets
          without data. Simple Packet (3): u32 original length: 16 octets without data.
  ptd     the public reverse-engineered layout (see tests/test_capfile.py): header date at 65, record
          time in u64 bit times since the header's second.
"""

from __future__ import annotations

import io
import math
import struct

import pytest
from profidrive_cli.dp.capfile import Packet, open_capture, open_writer
from profidrive_cli.dp.capture import PcapWriter, TimeRangeError
from test_wireshark import DX_REQ, SC

from test_wireshark import pd  # noqa: F401  (pdrive in this process: the same fixture)

T0 = 1_700_000_000                     # 2023-11-14 22:13:20 UTC
#: 10000-01-01 00:00:00 UTC: 2 932 897 days after 1970-01-01 (the days of the years 1970..9999:
#: 8030 x 365 + the 1947 leap days among them) x 86 400 s
T_MAX = 2_932_897 * 86_400
assert T_MAX == 253_402_300_800


def _block(btype: int, body: bytes, total: int | None = None) -> bytes:
    total = 12 + len(body) if total is None else total
    return struct.pack("<II", btype, total) + body + struct.pack("<I", total)


def shb() -> bytes:
    return _block(0x0A0D0D0A, struct.pack("<IHHq", 0x1A2B3C4D, 1, 0, -1))


def opt(code: int, value: bytes) -> bytes:
    return struct.pack("<HH", code, len(value)) + value + b"\0" * (-len(value) % 4)


def idb(*options: bytes) -> bytes:
    opts = b"".join(options) + (b"\0\0\0\0" if options else b"")
    return _block(1, struct.pack("<HHI", 147, 0, 0) + opts)


def epb(ticks: int, data: bytes) -> bytes:
    n = len(data)
    return _block(6, struct.pack("<IIIII", 0, ticks >> 32, ticks & 0xFFFFFFFF, n, n) + data + b"\0" * (-n % 4))


def pcapng(*blocks: bytes) -> bytes:
    return shb() + idb() + b"".join(blocks)


SECONDS = opt(9, b"\x00")                  # if_tsresol 10^-0: one tick is one second


def pcap(*records: tuple[int, int, bytes], nano: bool = False) -> bytes:
    magic = 0xA1B23C4D if nano else 0xA1B2C3D4
    head = struct.pack("<IHHiIII", magic, 2, 4, 0, 0, 65535, 147)
    return head + b"".join(struct.pack("<IIII", s, f, len(d), len(d)) + d for s, f, d in records)


# -- every reader refuses the same file the same way ----------------------------------------------

#: offset 48: the SHB's 28 octets and the IDB's 20 before it
BAD = {
    # an EPB of 28 octets (its fixed part is 32): its body has 16 octets, not the 20 of its fields
    "short-epb.pcapng": (pcapng(_block(6, b"\0" * 16)),
                         "not a valid pcapng: enhanced packet block at offset 48 is too short "
                         "(28 octets; its fixed part is 32)"),
    "short-spb.pcapng": (pcapng(_block(3, b"")),
                         "not a valid pcapng: simple packet block at offset 48 is too short "
                         "(12 octets; its fixed part is 16)"),
    "short-idb.pcapng": (shb() + _block(1, b""),
                         "not a valid pcapng: interface description block at offset 28 is too short "
                         "(12 octets; its fixed part is 20)"),
    # the fuzz's case: the first packet at 2^64 - 1 us (year 586 512), the next in 2023: sniff printed
    # a time of -18446742373709.55 s for the second
    "absurd.pcapng": (pcapng(epb(2**64 - 1, SC), epb(T0 * 10**6, SC)),
                      "packet 1: time 18446744073709.55"
                      ),
    # if_tsoffset -10 s on a time of 5 s: 5 s before 1970
    "negative.pcapng": (shb() + idb(SECONDS, opt(14, struct.pack("<q", -10))) + epb(5, SC),
                        "packet 1: time -5.000000 s is out of range"),
    # T_MAX itself (10000-01-01) is the first time out of range
    "year10000.pcapng": (shb() + idb(SECONDS) + epb(T_MAX, SC), "packet 1: time 253402300800.000000 s"),
    # a pcap's fraction must be below one second (10^6 us): 10^6 is "one more second" written wrongly
    "fraction.pcap": (pcap((T0, 999_999, SC), (T0, 1_000_000, SC)),
                      "octet 45: packet 2: time fraction 1000000 is out of range (0 to 999999 us)"),
    "fraction-ns.pcap": (pcap((T0, 10**9, SC), nano=True),
                         "octet 28: packet 1: time fraction 1000000000 is out of range (0 to 999999999 ns)"),
}


def _one_line(code: int, text: str, name: str, words: str) -> None:
    assert code == 2, text
    assert len(text.strip().splitlines()) == 1, text
    assert name in text and words in text, text
    assert "Traceback" not in text


@pytest.mark.parametrize("name", sorted(BAD))
def test_every_reader_refuses_with_one_line_exit_2_and_writes_nothing(tmp_path, monkeypatch, pd, name):
    monkeypatch.chdir(tmp_path)
    data, words = BAD[name]
    (tmp_path / name).write_bytes(data)
    (tmp_path / "old.pcap").write_bytes(b"old")
    # convert: the old target stays
    for out in ("old.pcap", "new.ptd", "new.pcapng"):
        _one_line(*pd("convert", name, out), name, words)
    assert (tmp_path / "old.pcap").read_bytes() == b"old"
    # sniff --from-file, also with a pcap to write
    _one_line(*pd("sniff", "--from-file", name), name, words)
    _one_line(*pd("sniff", "--from-file", name, "--pcap", "old.pcap"), name, words)
    assert (tmp_path / "old.pcap").read_bytes() == b"old"
    # sim --learn: refused before anything is served
    _one_line(*pd("sim", "--learn", name, "--pty"), name, words)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([name, "old.pcap"])


# -- the writers' ranges: a time the output cannot hold ---------------------------------------------

def test_convert_far_future_to_pcap_is_refused_with_the_packet(tmp_path, monkeypatch, pd):
    """pcap holds u32 seconds: 2^32 - 1 s and 999 999 us is its last time (2106-02-07 06:28:15 UTC),
    2^32 s is out. Both are times a pcapng holds (u64 us), so the reader passes them on."""
    monkeypatch.chdir(tmp_path)
    last = (2**32 - 1) * 10**6 + 999_999
    (tmp_path / "edge.pcapng").write_bytes(pcapng(epb(T0 * 10**6, SC), epb(last, SC)))
    assert pd("convert", "edge.pcapng", "edge.pcap")[0] == 0
    data = (tmp_path / "edge.pcap").read_bytes()
    assert struct.unpack_from("<II", data, 24 + 16 + 1) == (0xFFFFFFFF, 999_999)
    (tmp_path / "far.pcapng").write_bytes(pcapng(epb(T0 * 10**6, SC), epb(2**32 * 10**6, SC)))
    (tmp_path / "far.pcap").write_bytes(b"old")
    code, text = pd("convert", "far.pcapng", "far.pcap")
    _one_line(code, text, "far.pcapng", "packet 2: time 4294967296.000000 s is out of range for pcap")
    assert (tmp_path / "far.pcap").read_bytes() == b"old"
    # sniff writes its --pcap with the file's times: the same refusal, nothing written
    code, text = pd("sniff", "--from-file", "far.pcapng", "--pcap", "s.pcap", "--json")
    assert code == 2 and "out of range for pcap" in text.strip().splitlines()[-1], text
    assert not (tmp_path / "s.pcap").exists()


def test_convert_to_ptd_refuses_a_packet_before_the_first_ones_second(tmp_path, monkeypatch, pd):
    """A .ptd counts u64 bit times from the whole second of its first packet: a packet 0.5 s into that
    second and one 1 s before it -- the second cannot be held (before, it was moved to bit time 0)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "back.pcapng").write_bytes(pcapng(epb(T0 * 10**6 + 500_000, SC), epb((T0 - 1) * 10**6, SC)))
    (tmp_path / "back.ptd").write_bytes(b"old")
    code, text = pd("convert", "back.pcapng", "back.ptd")
    _one_line(code, text, "back.pcapng", "packet 2: time 1699999999.000000 s is out of range for ptd")
    assert (tmp_path / "back.ptd").read_bytes() == b"old"
    # pcap and pcapng hold it
    assert pd("convert", "back.pcapng", "back.pcap")[0] == 0


def test_convert_the_last_date_to_ptd_and_back(tmp_path, monkeypatch, pd):
    """9999-12-31 23:59:59 UTC (T_MAX - 1 s) is in range for a .ptd: its header says 31.12.9999."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "last.pcapng").write_bytes(shb() + idb(SECONDS) + epb(T_MAX - 1, SC))
    assert pd("convert", "last.pcapng", "last.ptd")[0] == 0
    head = (tmp_path / "last.ptd").read_bytes()[:1000]
    assert (head[65], head[66], struct.unpack_from("<H", head, 68)[0], head[70], head[71], head[72]) == \
        (31, 12, 9999, 23, 59, 59)
    assert [p.t for p in open_capture(tmp_path / "last.ptd")] == [T_MAX - 1]


@pytest.mark.parametrize("t, ok", [(0.0, True), (-1e-6, False), (2**32 - 1e-6, True), (2.0**32, False),
                                   (math.nan, False), (math.inf, False)])
def test_pcap_writer_range_edges(t, ok):
    w = PcapWriter(io.BytesIO(), start=0.0)
    if ok:
        w.write(t, SC)
        return
    with pytest.raises(TimeRangeError, match="packet 1: time .* out of range for pcap"):
        w.write(t, SC)


@pytest.mark.parametrize("fmt, t, ok", [
    # pcapng: u64 microseconds; 2^64 us = 18 446 744 073 709.551616 s
    ("pcapng", 18_446_744_073_709.5, True), ("pcapng", 18_446_744_073_709.6, False), ("pcapng", -1.0, False),
    # ptd: a date up to 9999-12-31 23:59:59 (the header's date)
    ("ptd", T_MAX - 1.0, True), ("ptd", float(T_MAX), False), ("ptd", -0.5, False),
])
def test_capfile_writer_range_edges(fmt, t, ok):
    w = open_writer(io.BytesIO(), fmt)
    if ok:
        w.write(Packet(t, SC))
        return
    with pytest.raises(TimeRangeError, match=f"packet 1: time .* out of range for {fmt}"):
        w.write(Packet(t, SC))


# -- the readers' ranges and if_tsoffset ---------------------------------------------------------------

def test_reader_edges_and_if_tsoffset(tmp_path):
    """The last time in range reads back; if_tsoffset (s64 seconds) is added to every timestamp; a
    pcap fraction of 999 999 us is the last in range."""
    f = tmp_path / "a.pcapng"
    f.write_bytes(shb() + idb(SECONDS) + epb(T_MAX - 1, SC))
    assert [p.t for p in open_capture(f)] == [T_MAX - 1]
    f.write_bytes(shb() + idb(opt(14, struct.pack("<q", T0))) + epb(500_000, DX_REQ))
    assert [(p.t, p.raw) for p in open_capture(f)] == [(T0 + 0.5, DX_REQ)]
    g = tmp_path / "a.pcap"
    g.write_bytes(pcap((T0, 999_999, SC)))
    assert [p.t for p in open_capture(g)] == [pytest.approx(T0 + 0.999999, abs=1e-6)]
