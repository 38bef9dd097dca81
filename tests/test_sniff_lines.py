"""`pdrive sniff --from-file FILE --station ...`: the whole output, text and --json, of a hand-built
capture of four drives whose speed words change from telegram to telegram, against lines written
out by hand (issue 38, "sniff with headroom": the fast path must print what the slow one did).

The telegrams (bus reference ../shared/spec/profibus-dp-reference.md §2): SD2 LE LEr SD2 DA SA FC
DU FCS ED, LE = 3 + len(DU), FCS = sum(DA .. DU) mod 256; a Data_Exchange request FC 0x40 (request)
| 0x20 (FCB) | 0x10 (FCV) | 13 (SRD high) = 0x7D (FCB=0: 0x5D), its reply FC 8 (DL data low). A
raw file carries no times: every line is at 0.000000.

The line of a frame (docs/commands.md, "pdrive sniff --station"): time (12.6f), two spaces, SD,
SA (3 wide, right) -> DA (3 wide, left), " [SSAP->DSAP]" if any, FC in words, the service, the
DU in hex, then "  | -> drive N (PROFILE LAYOUT): " and the drive's words. The words and the Hz, by
hand from the specs (../shared/spec):

- Fuji OPC-G1-PDP PPO1 (fuji-opc-g1-pdp.md): CTW 0x047F "operate"; STW 0x0237 S4 ("S4 operation");
  MRV / MAV N2: 0x4000 = 100 % of F03, the profile's 60 Hz until the drive's answer of F03 goes by:
  0x2000 = 30.00 Hz, 0x2001 = 8193 / 16384 x 60 = 30.0037 -> 30.00, 0x2100 = 8448 / 16384 x 60 =
  30.9375 -> 30.94; PKW 11 04 03 .. 01 F4 = F03 = 500 x 0.1 Hz = 50.0 Hz, from then on 0x2000 =
  25.00 Hz, 0xE000 = -8192 / 16384 x 50 = -25.00 Hz (§ chapter 7: "MRV 0xE000 = -30 Hz" at 60),
  0x0000 = 0.00 Hz. The answer's own actual is still at 60 Hz (learnt after its line).
- Toyo PBUS66-Z PPO1 (toyo-vf66-pbus66z.md D20), little-endian words: STW 7F 04 = 0x047F "RUN";
  speed 10 27 = 10000 of 20000 counts = 50 % of 60 Hz = 30.00 Hz, F8 2A = 11000 = 33.00 Hz.
- Moeller DE6 (moeller-de6-net-dp.md): STW 0x047F "operate", ZSW 0x0337 "S4 operation", HSW / HIW
  0x4000 = 100 % of A004 = 50 Hz: 0x2000 = 25.00 Hz, 0x1000 = 12.50 Hz; the layout by the Chk_Cfg
  the master sends once it goes by (reference §, PPO table: F3 F1 = PPO1 12 octets, F3 F5 = PPO2 20).
- Yaskawa SI-P1 extended1 (yaskawa-profibus-dp.md): out word 0 = 0x0001 "forward run", word 1 the
  reference in 0.01 Hz (3000 = 30.00 Hz, 3001 = 30.01 Hz); in word 0 = 0x0001 "running", word 5
  the output frequency in 0.1 Hz (300 = 30.00 Hz).
- Station 4 is not watched: its line has no drive's words. A short acknowledge and a token: their
  lines.
"""

from __future__ import annotations

import json

import pytest

from conftest import run_main

Z8 = "00 00 00 00 00 00 00 00"


def sd2(da: int, sa: int, fc: int, du: bytes, saps: tuple[int, int] | None = None) -> bytes:
    body = bytes([da | (0x80 if saps else 0), sa | (0x80 if saps else 0), fc]) + \
        (bytes(saps) if saps else b"") + du
    return bytes([0x68, len(body), len(body), 0x68]) + body + bytes([sum(body) & 0xFF, 0x16])


def req(da: int, du: str, fcb: bool = True) -> bytes:
    return sd2(da, 2, 0x7D if fcb else 0x5D, bytes.fromhex(du))


def rep(sa: int, du: str) -> bytes:
    return sd2(2, sa, 0x08, bytes.fromhex(du))


Y_ZERO28 = " 00" * 28
CAPTURE = [
    req(3, f"{Z8} 04 7F 20 00"), rep(3, f"{Z8} 02 37 20 01"),
    req(3, f"{Z8} 04 7F 21 00", fcb=False), rep(3, "11 04 03 00 00 00 01 F4 02 37 20 00"),
    req(3, f"{Z8} 04 7F 20 00"), req(3, f"{Z8} 04 7F E0 00", fcb=False), req(3, f"{Z8} 04 7F 00 00"),
    req(5, f"{Z8} 7F 04 10 27"), req(5, f"{Z8} 7F 04 F8 2A", fcb=False),
    req(6, f"{Z8} 04 7F 20 00"), rep(6, f"{Z8} 03 37 10 00"),
    # Chk_Cfg F3 F5 to station 6 (DSAP 62, SSAP 62): PPO2 from now on (20 octets each way)
    sd2(6, 2, 0x7D, b"\xF3\xF5", (62, 62)), b"\xE5",
    req(6, f"{Z8} 04 7F 20 00 {Z8}", fcb=False),
    req(7, "00 01 0B B8" + Y_ZERO28), rep(7, "00 01" + " 00" * 8 + " 01 2C" + " 00" * 20),
    req(7, "00 01 0B B9" + Y_ZERO28, fcb=False),
    bytes([0xDC, 2, 2]),
    req(4, f"{Z8} 04 7F 20 00"),
]

T = "    0.000000  "
REQ1, REQ0, REP = "SRD high, FCB=1 FCV=1  Data_Exchange", "SRD high, FCB=0 FCV=1  Data_Exchange", \
    "DL data low (slave)  Data_Exchange reply"
Z8L = "00 00 00 00 00 00 00 00"
FUJI, TOYO = "drive 3 (fuji-opc-g1-pdp ppo1)", "drive 5 (toyo-pbus66z ppo1)"
MOE1, MOE2 = "drive 6 (moeller-de6-net-dp ppo1)", "drive 6 (moeller-de6-net-dp ppo2)"
YAS = "drive 7 (yaskawa-si-p1 extended1)"
Y_ZERO28_L = " 00" * 28
#: (the line, the drive's words or None) of each entry, in order; a frame's decoded lines under it
LINES = [
    (f"SD2    2 -> 3    {REQ1}  {Z8L} 04 7f 20 00", f"-> {FUJI}: operate, reference 30.00 Hz"),
    (f"SD2    3 -> 2    {REP}  {Z8L} 02 37 20 01", f"<- {FUJI}: S4 operation, actual 30.00 Hz"),
    (f"SD2    2 -> 3    {REQ0}  {Z8L} 04 7f 21 00", f"-> {FUJI}: operate, reference 30.94 Hz"),
    (f"SD2    3 -> 2    {REP}  11 04 03 00 00 00 01 f4 02 37 20 00",
     f"<- {FUJI}: S4 operation, actual 30.00 Hz; F03 = 50.0 Hz"),
    (f"SD2    2 -> 3    {REQ1}  {Z8L} 04 7f 20 00", f"-> {FUJI}: operate, reference 25.00 Hz"),
    (f"SD2    2 -> 3    {REQ0}  {Z8L} 04 7f e0 00", f"-> {FUJI}: operate, reference -25.00 Hz"),
    (f"SD2    2 -> 3    {REQ1}  {Z8L} 04 7f 00 00", f"-> {FUJI}: operate, reference 0.00 Hz"),
    (f"SD2    2 -> 5    {REQ1}  {Z8L} 7f 04 10 27", f"-> {TOYO}: RUN, reference 30.00 Hz"),
    (f"SD2    2 -> 5    {REQ0}  {Z8L} 7f 04 f8 2a", f"-> {TOYO}: RUN, reference 33.00 Hz"),
    (f"SD2    2 -> 6    {REQ1}  {Z8L} 04 7f 20 00", f"-> {MOE1}: operate, reference 25.00 Hz"),
    (f"SD2    6 -> 2    {REP}  {Z8L} 03 37 10 00", f"<- {MOE1}: S4 operation, actual 12.50 Hz"),
    ("SD2    2 -> 6   [62->62]  SRD high, FCB=1 FCV=1  Chk_Cfg  f3 f5", None),
    ("SC   short acknowledge", None),
    (f"SD2    2 -> 6    {REQ0}  {Z8L} 04 7f 20 00 {Z8L}", f"-> {MOE2}: operate, reference 25.00 Hz"),
    (f"SD2    2 -> 7    {REQ1}  00 01 0b b8{Y_ZERO28_L}", f"-> {YAS}: forward run, reference 30.00 Hz"),
    (f"SD2    7 -> 2    {REP}  00 01{' 00' * 8} 01 2c{' 00' * 20}", f"<- {YAS}: running, actual 30.00 Hz"),
    (f"SD2    2 -> 7    {REQ0}  00 01 0b b9{Y_ZERO28_L}", f"-> {YAS}: forward run, reference 30.01 Hz"),
    ("SD4  token 2 -> 2", None),
    (f"SD2    2 -> 4    {REQ1}  {Z8L} 04 7f 20 00", None),
]
#: under the Chk_Cfg line (reference §: F3 = 4 words in+out, whole consistency; F5 = 6 words)
CHK_CFG_DECODED = " " * 16 + "Chk_Cfg: 4 words in+out, consistent; 6 words in+out, consistent"
STATIONS = ["--station", "3=fuji-g1", "--station", "5=toyo", "--station", "6=moeller",
            "--station", "7=yaskawa"]


@pytest.fixture
def capture_file(tmp_path):
    path = tmp_path / "line.raw"
    path.write_bytes(b"".join(CAPTURE))
    return path


def test_the_text_lines_are_the_hand_written_ones(capture_file, capsys, monkeypatch):
    r = run_main(capsys, monkeypatch, "sniff", "--from-file", capture_file, *STATIONS)
    assert r.exit_code == 0, r.stderr
    want = []
    for line, words in LINES:
        want.append(T + line + (f"  | {words}" if words else ""))
        if "Chk_Cfg" in line:
            want.append(CHK_CFG_DECODED)
    assert r.stdout.splitlines() == want


def test_the_json_lines_carry_the_hand_written_words(capture_file, capsys, monkeypatch):
    r = run_main(capsys, monkeypatch, "sniff", "--from-file", capture_file, "--json", *STATIONS)
    assert r.exit_code == 0, r.stderr
    objs = [json.loads(x) for x in r.stdout.splitlines()]
    assert len(objs) == len(LINES)
    for obj, (line, words) in zip(objs, LINES):
        assert obj["event"] == "frame" and obj["t_s"] == 0.0
        if "du" in obj:
            assert line.endswith("  " + obj["du"])
        if words is None:
            assert "drive" not in obj
            continue
        d = obj["drive"]
        arrow, who, text = words[:2], words[3:words.index(": ")], words[words.index(": ") + 2:]
        assert d["direction"] == ("request" if arrow == "->" else "response")
        assert f"drive {d['station']} ({d['profile']} {d['layout']})" == who
        assert d["text"] == text
        hz = d["reference_hz"] if arrow == "->" else d["actual_hz"]
        assert f"{hz:.2f} Hz" in text.split("; ")[0].split(", ")[-1]
    # by hand: the Fuji answer teaches F03 = 50 Hz; the next reference is 0x2000 = 50 % of it
    assert objs[3]["drive"]["param"]["text"] == "F03 = 50.0 Hz"
    assert [o["drive"]["reference_hz"] for o in objs[4:7]] == [25.0, -25.0, 0.0]


def test_every_lane_cache_stays_bounded():
    """A station whose parameter channel carries a new value every telegram: the rests and their
    lines are kept up to AREA_CACHE_MAX, the Hz texts too."""
    from profidrive_cli.bustools import passive as P
    from profidrive_cli.dp.capture import Capture
    dec = P.PassiveDecoder(P.watch_list(["3=fuji-g1"]))
    n = P.AREA_CACHE_MAX + 300
    cap = Capture()
    for i in range(n):
        # PKW: write F07 = i (AK 2), a reference that changes too
        du = f"21 04 07 00 {i >> 24 & 0xFF:02x} {i >> 16 & 0xFF:02x} {i >> 8 & 0xFF:02x} " \
             f"{i & 0xFF:02x} 04 7F {0x10 + (i >> 8) & 0x3F:02x} {i & 0xFF:02x}"
        (c,) = cap.feed(req(3, du), 0.0)
        assert dec.suffix(c) is not None
    lane = dec._req_lanes[3]
    assert 0 < len(lane.lines) <= P.AREA_CACHE_MAX
    assert 0 < len(lane.hz_texts) <= P.AREA_CACHE_MAX
    assert len(dec._rests) <= P.AREA_CACHE_MAX and len(dec._areas) <= P.AREA_CACHE_MAX
