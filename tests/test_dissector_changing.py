"""The Lua dissector on a line whose drive values change every cycle (issue 38): no area repeats the
station's previous one, so nothing can come from a per-station cache. Every telegram's decoded
values must be the values written, in every mode tshark has: the summary lines (no protocol tree),
-T fields (a tree) and -V (the tree as text).

The captures are built here by hand: SD2 telegrams, FCS = the sum of DA..DU mod 256. Expected values
come from the words written and the manuals' rules, computed here, not by the dissector:
  - PROFIdrive N2: 0x4000 = 100 % (HSW/HIW); the Moeller DE6-NET-DP's 100 % is A004 = 50 Hz by
    default (moeller-de6-net-dp.md, as test_wireshark's vendor-layout test);
  - the PROFIdrive state from the status word: bit 3 fault; bit 6 switching on inhibited (S1); else
    bits 0-2: 111 S4 operation, 011 S3 switched on, 001 S2 ready for switching on;
  - PKW: AK in PKE bits 12-15, PNU in bits 0-10, PWE the last two words (PROFIdrive profile);
  - Yaskawa SI-P1 extended1: reference in 0.01 Hz, run command bit 0 forward run (spec §2.2, §2.7).
"""

from __future__ import annotations

import re
import struct

from test_wireshark import _fields, _pcap, _tshark, run, tshark  # noqa: F401 (fixture)

CYCLES = 24
STW = 0x047F
# status words valid on a running drive and the state each means (bits 0-2, 3 and 6 by hand)
ZSW = ((0x0237, "S4 operation"), (0x0337, "S4 operation"), (0x0233, "S3 switched on"),
       (0x0231, "S2 ready for switching on"), (0x0270, "S1 switching on inhibited"),
       (0x023F, "fault"))


def _dx(da: int, sa: int, fc: int, area: bytes) -> bytes:
    body = bytes([da, sa, fc]) + area
    return bytes([0x68, len(body), len(body), 0x68]) + body + bytes([sum(body) & 0xFF, 0x16])


def _ppo1_cycle(c: int, station: int = 6):
    """One cycle: (request, response) and what each carries. The setpoint climbs 0x0155 per cycle,
    the actual value is the previous cycle's setpoint, the status word walks through ZSW; every
    fourth cycle the master reads PNU 100 + c and the drive answers 1000 + c."""
    hsw = (c + 1) * 0x0155
    hiw = c * 0x0155
    zsw, state = ZSW[c % len(ZSW)]
    pke_req = pke_res = ind = pwe = 0
    if c % 4 == 0:
        pke_req = 0x1000 | (100 + c)                    # AK 1: request parameter value
        pke_res = 0x1000 | (100 + c)                    # AK 1: transfer parameter value (word)
        pwe = 1000 + c
    fcb = 0x20 if c % 2 else 0
    req = _dx(station, 2, 0x5D | fcb, struct.pack(">HHHHHH", pke_req, ind, 0, 0, STW, hsw))
    res = _dx(2, station, 0x08, struct.pack(">HHHHHH", pke_res, ind, 0, pwe, zsw, hiw))
    return req, res, dict(hsw=hsw, hiw=hiw, zsw=zsw, state=state, pke=pke_req, pwe=pwe, fcb=fcb)


def _capture(tmp_path, station=6):
    frames, expect = [], []
    for c in range(CYCLES):
        req, res, e = _ppo1_cycle(c, station)
        frames += [req, res]
        expect.append(e)
    return _pcap(tmp_path / "changing.pcap", frames), expect


def test_every_area_differs_from_the_stations_previous_one():
    """The capture is what it claims: no request and no response area repeats the one before."""
    areas = [_ppo1_cycle(c)[:2] for c in range(CYCLES)]
    for prev, cur in zip(areas, areas[1:]):
        assert prev[0][7:-2] != cur[0][7:-2] and prev[1][7:-2] != cur[1][7:-2]


def test_fields_are_the_values_written_every_cycle(tshark, tmp_path):
    """-T fields (with a tree): per telegram, the setpoint and actual value in % of 0x4000, the
    status word's state, the control word's bits, the PKW's AK, PNU and PWE."""
    pcap, expect = _capture(tmp_path)
    names = ["profidrive.reference_percent", "profidrive.actual_percent", "profidrive.status",
             "profidrive.state", "profidrive.control", "profidrive.pkw.ak", "profidrive.pkw.pnu",
             "profidrive.pkw.pwe", "profibus.fcs.status"]
    rows = _fields(tshark, pcap, names)
    assert len(rows) == 2 * CYCLES
    for c, e in enumerate(expect):
        req, res = rows[2 * c], rows[2 * c + 1]
        assert float(req["profidrive.reference_percent"]) == e["hsw"] * 100 / 16384, c
        assert float(res["profidrive.actual_percent"]) == e["hiw"] * 100 / 16384, c
        assert int(req["profidrive.control"], 16) == STW
        assert int(res["profidrive.status"], 16) == e["zsw"], c
        assert res["profidrive.state"] == e["state"], c
        assert req["profibus.fcs.status"] == res["profibus.fcs.status"] == "good"
        if e["pke"]:
            assert req["profidrive.pkw.ak"] == res["profidrive.pkw.ak"] == "1"
            assert int(req["profidrive.pkw.pnu"]) == int(res["profidrive.pkw.pnu"]) == 100 + c
            assert int(res["profidrive.pkw.pwe"], 0) == 1000 + c
        else:
            assert req["profidrive.pkw.ak"] == "0" and int(res["profidrive.pkw.pwe"], 0) == 0


def test_summary_lines_name_the_values_written_every_cycle(tshark, tmp_path):
    """tshark's summary lines (no protocol tree: the packet list): each Info column is the telegram
    in words with this cycle's words, by hand: "SD2  2 -> 6  Data_Exchange  SRD high, FCB=f FCV=1
    PKW ...; STW 0x047F; HSW 0x...."; the reply "ZSW 0x.... <state>; HIW 0x....". And it is the
    Info column the full dissection (-T fields, with a tree) writes, row by row."""
    pcap, expect = _capture(tmp_path)
    summary = _tshark(tshark, pcap, "-o", "gui.column.format:\"Info\",\"%i\"")
    lines = [line.strip() for line in summary.splitlines()]
    assert len(lines) == 2 * CYCLES
    for c, e in enumerate(expect):
        fcb = 1 if e["fcb"] else 0
        pkw_req = f"PKW AK 1 request parameter value, PNU {100 + c}" if e["pke"] else "PKW no task"
        pkw_res = (f"PKW AK 1 transfer parameter value (word), PNU {100 + c}, PWE {1000 + c}" if e["pke"]
                   else "PKW no response")
        assert lines[2 * c] == (f"SD2  2 -> 6  Data_Exchange  SRD high, FCB={fcb} FCV=1  "
                                f"{pkw_req}; STW 0x{STW:04X}; HSW 0x{e['hsw']:04X}"), c
        assert lines[2 * c + 1] == (f"SD2  6 -> 2  Data_Exchange reply  DL data low (slave)  "
                                    f"{pkw_res}; ZSW 0x{e['zsw']:04X} {e['state']}; HIW 0x{e['hiw']:04X}"), c
    with_tree = _tshark(tshark, pcap, "-T", "fields", "-e", "_ws.col.Info").splitlines()
    assert with_tree == lines


def test_the_tree_shows_the_values_written_every_cycle(tshark, tmp_path):
    """-V: each telegram's PROFIdrive item carries its own cycle's words (the reference in % of
    0x4000 with four decimals at most, as the dissector writes numbers)."""
    pcap, expect = _capture(tmp_path)
    text = _tshark(tshark, pcap, "-V")
    blocks = re.split(r"^Frame \d+: ", text, flags=re.M)[1:]
    assert len(blocks) == 2 * CYCLES
    for c, e in enumerate(expect):
        pct = f"{e['hsw'] * 100 / 16384:.4f}".rstrip("0").rstrip(".")
        assert f"HSW (main setpoint) 0x{e['hsw']:04X}: {pct} %" in blocks[2 * c], c
        assert f"ZSW (status word) 0x{e['zsw']:04X}: " in blocks[2 * c + 1], c
        assert f" -> {e['state']}" in blocks[2 * c + 1], c


def test_vendor_layouts_decode_the_values_written_every_cycle(tshark, tmp_path):
    """With the station table (pdrive wireshark install): station 6 Moeller (100 % = A004 = 50 Hz)
    and station 7 Yaskawa extended1 (reference in 0.01 Hz, command bit 0 forward run), both ramping
    every cycle, read with -T fields."""
    r = run("wireshark", "install", "--dir", tmp_path, "--station", "6=moeller:ppo1", "--station", "7=yaskawa")
    assert r.exit_code == 0, r.output
    frames, expect = [], []
    for c in range(CYCLES):
        req, res, e = _ppo1_cycle(c, 6)
        ref = 100 * c + 7                              # 0.07 Hz, 1.07 Hz, ... in 0.01 Hz
        yreq = _dx(7, 2, 0x5D, struct.pack(">HH", 0x0001, ref) + bytes(28))
        frames += [req, res, yreq]
        expect.append((e, ref))
    pcap = _pcap(tmp_path / "vendor.pcap", frames)
    rows = _fields(tshark, pcap, ["profidrive.layout", "profidrive.reference_hz", "profidrive.actual_hz",
                                  "profidrive.control.set"], lua=tmp_path / "pdrive.lua")
    assert len(rows) == 3 * CYCLES
    for c, (e, ref) in enumerate(expect):
        req, res, y = rows[3 * c: 3 * c + 3]
        assert req["profidrive.layout"] == "moeller-de6-net-dp ppo1"
        assert abs(float(req["profidrive.reference_hz"]) - e["hsw"] * 50 / 16384) < 1e-9, c
        assert abs(float(res["profidrive.actual_hz"]) - e["hiw"] * 50 / 16384) < 1e-9, c
        assert y["profidrive.layout"] == "yaskawa-si-p1 extended1"
        assert abs(float(y["profidrive.reference_hz"]) - ref / 100) < 1e-9, c
        assert y["profidrive.control.set"] == "forward run"
