"""Capture files as streams (issue 27, "interchange"): dp/capfile.py reads and writes raw, pcap, pcapng
(direction, comments) and ProfiTrace .ptd one packet at a time; `pdrive convert IN OUT` between them by
extension.

Expected octets come from the formats' layouts worked by hand: pcap (24-octet header, 16 per record),
pcapng (the blocks of the pcapng specification: SHB 0x0A0D0D0A, IDB 1, EPB 6; epb_flags option 2 with
direction bits 01 inbound / 10 outbound, opt_comment 1), ProfiTrace .ptd from the public
reverse-engineered layout (KU Leuven's MATLAB uart.m, ptdread/ptdwrite: 1000-octet header with the
packet count at octet 32, the baud code at 36, the start date at 65; records 66 66, LEN = size - 13
(LE16), id twice, the time in bit times (LE64) at 13, type at 21 (1 SD1, 2 SD2, 4 SD3, 8 SD4, 16 SC),
SA 23, DA 24, SSAP 25, DSAP 26 (255 255 = none), FC 27, data length 28, data from 31, LEN again,
77 77). The telegrams are the hand-built ones of tests/test_wireshark.py (FCS summed by hand there).
"""

from __future__ import annotations

import calendar
import os
import shutil
import struct
import subprocess
from pathlib import Path

import pytest
from profidrive_cli.dp import capfile
from profidrive_cli.dp.capfile import Packet, open_capture, open_writer
from test_wireshark import CHK_CFG, DX_BAD_FCS, DX_REQ, DX_RES, FDL_STATUS, GC, LUA, SC, SET_PRM, SLAVE_DIAG, TOKEN

T0 = 1_700_000_000.0          # 2023-11-14 22:13:20 UTC
FRAMES = [SET_PRM, SLAVE_DIAG, CHK_CFG, DX_REQ, DX_RES, GC, FDL_STATUS, TOKEN, SC]


from test_wireshark import pd  # noqa: E402,F401  (pdrive in this process: the same fixture)


def _packets():
    """The tests' telegrams 2 ms apart (a multiple of a bit time at 1.5M: 3000 bits), the first two
    with a direction, one with a comment, and a telegram with a bad FCS."""
    out = [Packet(T0 + i * 0.002, raw) for i, raw in enumerate(FRAMES + [DX_BAD_FCS])]
    out[0] = out[0]._replace(direction="out", comment="Set_Prm to 6")
    out[1] = out[1]._replace(direction="in")
    return out


def _write(path, fmt, packets, **kw):
    with open(path, "wb") as fh:
        w = open_writer(fh, fmt, **kw)
        for p in packets:
            w.write(p)
        w.close()
    return path


# -- round trips ----------------------------------------------------------------------------------

@pytest.mark.parametrize("fmt", ["pcap", "pcapng", "ptd"])
def test_every_format_gives_back_the_octets_and_the_times(tmp_path, fmt):
    pk = _packets()
    back = list(open_capture(_write(tmp_path / f"a.{fmt}", fmt, pk)))
    assert [p.raw for p in back] == [p.raw for p in pk]
    # pcap / pcapng: microseconds; ptd: one bit time at 1.5M = 0.67 us
    assert all(abs(a.t - b.t) <= 1e-6 for a, b in zip(back, pk))


def test_pcapng_keeps_direction_and_comments(tmp_path):
    back = list(open_capture(_write(tmp_path / "a.pcapng", "pcapng", _packets())))
    assert [(p.direction, p.comment) for p in back[:3]] == [("out", "Set_Prm to 6"), ("in", None), (None, None)]


def test_raw_keeps_the_octets_and_frames_them_again(tmp_path):
    raw = _write(tmp_path / "a.raw", "raw", _packets())
    assert raw.read_bytes() == b"".join(FRAMES) + DX_BAD_FCS
    os.utime(raw, (T0, T0))
    back = list(open_capture(raw))
    assert [p.raw for p in back[:len(FRAMES)]] == FRAMES
    assert all(p.t == T0 for p in back)                         # no times in raw: the file's mtime
    # the bad FCS: the decoder drops its first octet as an error and reads on (dp.capture)
    assert b"".join(p.raw for p in back[len(FRAMES):]) == DX_BAD_FCS
    assert back[len(FRAMES)].comment and "fcs" in back[len(FRAMES)].comment


# -- the layouts, octet by octet -------------------------------------------------------------------

def test_pcapng_blocks_are_the_specifications(tmp_path):
    """SHB (type 0x0A0D0D0A, byte-order magic 1A2B3C4D, version 1.0), IDB (link type 147), then an
    EPB for SC with direction 'in' and the comment 'x': 12 + 20 + 4 (1 octet padded) + 8 (epb_flags)
    + 8 (comment 'x' padded) + 4 (end of options) = 56 octets."""
    path = _write(tmp_path / "a.pcapng", "pcapng", [Packet(T0 + 0.5, SC, "in", "x")])
    data = path.read_bytes()
    btype, shb_len, bom, major, minor = struct.unpack_from("<IIIHH", data, 0)
    assert (btype, bom, major, minor) == (0x0A0D0D0A, 0x1A2B3C4D, 1, 0)
    idb = shb_len
    btype, idb_len, linktype = struct.unpack_from("<IIH", data, idb)
    assert (btype, linktype) == (1, 147)
    epb = idb + idb_len
    btype, total, iface, hi, lo, cap, orig = struct.unpack_from("<IIIIIII", data, epb)
    assert (btype, total, iface, cap, orig) == (6, 56, 0, 1, 1)
    assert (hi << 32 | lo) == 1_700_000_000_500_000             # microseconds
    assert data[epb + 28:epb + 32] == b"\xE5\0\0\0"
    assert data[epb + 32:epb + 40] == struct.pack("<HHI", 2, 4, 1)          # epb_flags: inbound
    assert data[epb + 40:epb + 48] == struct.pack("<HH", 1, 1) + b"x\0\0\0"  # opt_comment
    assert data[epb + 48:epb + 52] == b"\0\0\0\0"                            # opt_endofopt
    assert struct.unpack_from("<I", data, epb + 52)[0] == 56
    assert len(data) == epb + 56


def _ptd_by_hand(records: list[bytes], baud_code=5) -> bytes:
    head = bytearray(1000)
    head[32:36] = struct.pack("<I", len(records))
    head[36] = baud_code
    head[65], head[66] = 14, 11                                  # 14 November
    head[68:70] = struct.pack("<H", 2023)
    head[70], head[71], head[72] = 22, 13, 20                    # 22:13:20
    return bytes(head) + b"".join(records)


def _ptd_record(n: int, bits: int, kind: int, sa=0, da=0, ssap=255, dsap=255, fc=0, data=b"") -> bytes:
    size = 35 + len(data)
    r = bytearray(size)
    r[0:2] = b"\x66\x66"
    r[2:4] = r[size - 4:size - 2] = struct.pack("<H", size - 13)
    r[4] = 1
    r[5:9] = r[9:13] = struct.pack("<I", n)
    r[13:21] = struct.pack("<Q", bits)
    r[21], r[23], r[24], r[25], r[26], r[27], r[28] = kind, sa, da, ssap, dsap, fc, len(data)
    r[31:31 + len(data)] = data
    r[size - 2:] = b"\x77\x77"
    return bytes(r)


def test_a_ptd_built_by_hand_reads_as_its_telegrams(tmp_path):
    """Records written here from the public layout, not by pdrive: DX request 2 -> 6 (SD2, FC 0x7D,
    12 data octets) 1 s after the start (1 500 000 bit times at code 5 = 1.5 Mbit/s), Set_Prm
    2 -> 6 with SAPs 62 -> 61, a token, an SC."""
    dx_data = DX_REQ[7:-2]
    prm_data = SET_PRM[9:-2]
    path = tmp_path / "hand.ptd"
    path.write_bytes(_ptd_by_hand([
        _ptd_record(1, 1_500_000, 2, sa=2, da=6, fc=0x7D, data=dx_data),
        _ptd_record(2, 1_500_300, 2, sa=2, da=6, ssap=62, dsap=61, fc=0x7D, data=prm_data),
        _ptd_record(3, 1_501_000, 8, sa=2, da=2),
        _ptd_record(4, 1_501_500, 16)]))
    r = open_capture(path)
    assert r.baud == 1_500_000
    back = list(r)
    start = calendar.timegm((2023, 11, 14, 22, 13, 20))
    assert start == T0
    assert [p.raw for p in back] == [DX_REQ, SET_PRM, TOKEN, SC]
    assert back[0].t == pytest.approx(T0 + 1.0, abs=1e-9)
    assert back[1].t == pytest.approx(T0 + 1.0002, abs=1e-9)    # 300 bit times = 200 us


def test_ptd_records_pdrive_writes_follow_the_public_layout(tmp_path):
    """The DX request 2 ms after a whole second: 3000 bit times at 1.5M; record size 35 + 12 = 47."""
    path = _write(tmp_path / "a.ptd", "ptd", [Packet(T0 + 0.002, DX_REQ), Packet(T0 + 0.004, SC)])
    data = path.read_bytes()
    assert len(data) == 1000 + 47 + 35
    assert struct.unpack_from("<Q", data, 4)[0] == len(data)                 # file length
    assert struct.unpack_from("<I", data, 32)[0] == 2                        # packets
    assert data[36] == 5                                                     # 1.5 Mbit/s
    assert (data[65], data[66], struct.unpack_from("<H", data, 68)[0]) == (14, 11, 2023)
    assert _ptd_record(1, 3000, 2, sa=2, da=6, fc=0x7D, data=DX_REQ[7:-2]) == data[1000:1047]
    assert _ptd_record(2, 6000, 16, ssap=0, dsap=0) == data[1047:]       # SAPs only in SD2/SD3


def test_a_bad_fcs_is_kept_in_ptd_as_an_illegal_record_with_its_octets(tmp_path):
    path = _write(tmp_path / "a.ptd", "ptd", [Packet(T0, DX_BAD_FCS)])
    data = path.read_bytes()
    assert data[1000 + 21] == 0 and data[1000 + 28] == len(DX_BAD_FCS)
    (p,) = list(open_capture(path))
    assert p.raw == DX_BAD_FCS and p.comment == "illegal telegram"


# -- streaming ------------------------------------------------------------------------------------

def test_reading_is_a_stream_not_the_whole_file(tmp_path):
    """After the first packet of a 4 MiB pcap only its header and first record have been read
    (through the buffered file: at most one buffer more), not the file."""
    n = 4 * 1024 * 1024 // (16 + len(DX_REQ))
    path = _write(tmp_path / "big.pcap", "pcap", (Packet(T0 + i * 1e-3, DX_REQ) for i in range(n)))
    assert path.stat().st_size > 4_000_000
    r = open_capture(path)
    it = iter(r)
    assert next(it).raw == DX_REQ
    assert r._fh.tell() <= 24 + 16 + len(DX_REQ) + 64 * 1024
    assert sum(1 for _ in it) == n - 1


def test_unknown_extension_is_refused_unless_a_default_is_given(tmp_path):
    raw = tmp_path / "capture.bin"
    raw.write_bytes(DX_REQ + SC)
    with pytest.raises(capfile.UsageError, match="unknown capture format '.bin'"):
        open_capture(raw)
    assert [p.raw for p in open_capture(raw, default_format="raw")] == [DX_REQ, SC]


# -- pdrive convert -------------------------------------------------------------------------------

def test_convert_between_every_pair(tmp_path, pd):
    src = _write(tmp_path / "a.pcapng", "pcapng", _packets())
    for a, b in [("pcapng", "ptd"), ("ptd", "pcap"), ("pcap", "raw"), ("raw", "pcapng")]:
        code, text = pd("convert", tmp_path / f"a.{a}", tmp_path / f"a.{b}")
        assert code == 0, text
        assert f"{len(_packets())} packet(s)" in text or a == "raw"
    # pcapng -> ptd -> pcap kept every telegram (the bad FCS as an illegal record) and its time
    assert [(p.raw, round(p.t, 6)) for p in open_capture(tmp_path / "a.pcap")] == \
        [(p.raw, round(p.t, 6)) for p in _packets()]
    # -> raw -> pcapng: the octets, framed again (the bad FCS as the decoder's error pieces)
    assert b"".join(p.raw for p in open_capture(src)) == b"".join(FRAMES) + DX_BAD_FCS


@pytest.mark.parametrize("src, dst, msg", [
    ("a.pcap", "b.txt", "unknown capture format '.txt'"),
    ("a.doc", "b.pcap", "unknown capture format '.doc'"),
    ("missing.pcap", "b.ptd", "missing.pcap: file not found"),
    ("bad.pcap", "b.ptd", "bad.pcap: octet 0: not a pcap file"),
    ("trunc.pcap", "b.ptd", "trunc.pcap: octet 74: file ends inside a packet (3 of 14 octets)"),
    ("a.pcap", "b.ptd --baud 93750", "--baud 93750"),
])
def test_convert_refuses_with_one_line_exit_2_and_leaves_out_alone(tmp_path, monkeypatch, pd, src, dst, msg):
    monkeypatch.chdir(tmp_path)
    _write(tmp_path / "a.pcap", "pcap", _packets())
    (tmp_path / "a.doc").write_bytes(b"")
    (tmp_path / "bad.pcap").write_bytes(b"\0" * 40)
    # 24 header + 16 record header + Set_Prm's 18 octets, then the second record's header (16, at
    # octet 58) promises Slave_Diag's 14 octets, which start at octet 74 and are cut after 3
    whole = (tmp_path / "a.pcap").read_bytes()
    (tmp_path / "trunc.pcap").write_bytes(whole[:24 + 16 + 18 + 16 + 3])
    for out in ("b.txt", "b.pcap", "b.ptd"):
        (tmp_path / out).write_bytes(b"old")
    dst_name, *opts = dst.split()
    code, text = pd("convert", src, dst_name, *opts)
    assert code == 2, text
    assert msg in text and len(text.strip().splitlines()) == 1, text
    assert (tmp_path / dst_name).read_bytes() == b"old"
    assert sorted(x.name for x in tmp_path.iterdir() if x.name.startswith(".")) == []   # no temp file left


# -- Wireshark opens what pdrive writes ------------------------------------------------------------

def test_tshark_reads_the_pcapng_with_direction_comment_and_the_dissector(tmp_path):
    exe = shutil.which("tshark")
    if exe is None:
        if os.environ.get("CI") == "true":
            pytest.fail("tshark is missing on CI")
        pytest.skip("tshark not installed")
    path = _write(tmp_path / "a.pcapng", "pcapng", _packets())
    p = subprocess.run([exe, "-n", "-X", f"lua_script:{LUA}", "-r", str(path), "-T", "fields", "-E",
                        "separator=\t", "-e", "frame.packet_flags_direction", "-e", "frame.comment",
                        "-e", "profibus.service"], capture_output=True, text=True, timeout=120,
                       env={**os.environ, "HOME": str(tmp_path)})
    assert p.returncode == 0, p.stderr
    rows = [line.split("\t") for line in p.stdout.splitlines()]
    assert len(rows) == len(_packets())
    assert int(rows[0][0], 16) == 2 and rows[0][1] == "Set_Prm to 6" and rows[0][2] == "Set_Prm"
    assert int(rows[1][0], 16) == 1 and rows[1][2] == "Slave_Diag reply"
    assert [r[2] for r in rows[3:5]] == ["Data_Exchange", "Data_Exchange reply"]


def test_packets_of_a_raw_file_decode_as_sniff_decodes_the_whole_file(tmp_path):
    """What `sniff --from-file` will do with open_capture (the call the report names): feeding each
    packet to sniff's decoder gives the frames and errors that decoding the file at once gives --
    garbage, a bad FCS and a truncated telegram at the end included."""
    from profidrive_cli.dp.capture import Capture, merge_errors
    data = b"\x00\x11" + SET_PRM + DX_BAD_FCS + SC + DX_REQ + DX_RES[:5]
    path = tmp_path / "line.bin"
    path.write_bytes(data)
    whole = Capture()
    expect = [(c.raw, c.error) for c in merge_errors(whole.feed(data, 0.0))]
    cap = Capture()
    got = []
    for p in open_capture(path, default_format="raw"):
        got += [(c.raw, c.error) for c in merge_errors(cap.feed(p.raw, 0.0))]
    assert got == expect
    assert bytes(cap.rx.buf) == bytes(whole.rx.buf) == DX_RES[:5]       # the truncated tail, as before


def test_convert_options_linktype_and_baud_carry_over(tmp_path, pd):
    """--linktype 257 is written into the pcapng interface and carried on to a pcap; --baud 12M is
    code 8 in the ptd header (the public layout's table) and carried on from one ptd to the next."""
    _write(tmp_path / "a.pcap", "pcap", _packets())
    assert pd("convert", tmp_path / "a.pcap", tmp_path / "b.pcapng", "--linktype", "257")[0] == 0
    assert pd("convert", tmp_path / "b.pcapng", tmp_path / "c.pcap")[0] == 0
    assert open_capture(tmp_path / "b.pcapng").linktype == 257
    assert open_capture(tmp_path / "c.pcap").linktype == 257
    assert pd("convert", tmp_path / "a.pcap", tmp_path / "d.ptd", "--baud", "12000000")[0] == 0
    assert pd("convert", tmp_path / "d.ptd", tmp_path / "e.ptd")[0] == 0
    assert (tmp_path / "e.ptd").read_bytes()[36] == 8
    # 2 ms at 12 Mbit/s = 24 000 bit times between the first two records, to within the resolution
    # of a time in seconds since 1970 held in a float (2^-22 s = 0.24 us = 2.9 bit times at 12M)
    data = (tmp_path / "e.ptd").read_bytes()
    first = struct.unpack_from("<Q", data, 1000 + 13)[0]
    second_at = 1000 + 35 + len(SET_PRM[9:-2])
    assert abs(struct.unpack_from("<Q", data, second_at + 13)[0] - first - 24_000) <= 3
    assert [p.raw for p in open_capture(tmp_path / "e.ptd")] == [p.raw for p in _packets()]
