"""sniff's fast paths give what the plain paths give (issue 38, "sniff with headroom").

- `--station`: each family's speed_plan (drives/speedplan.py SpeedWord) lets bustools/passive.py
  decode the rest of an area once and the speed word each time. For every shipped profile, layout
  and direction, areas of seeded random octets plus the speed word's edge values (0, 1, 0x7FFF,
  0x8000, 0xFFFF) give the same drive object -- the same keys in the same order, the same values --
  as PassiveDecoder(fast=False), which decodes every area through the family's decode_area; also
  with a learnt max frequency; the text line's words (PassiveDecoder.suffix) are frame_suffix's of
  that object. The recorder's triggers (speed=False) fire the same.
- the frame path: a frame's line, its JSON and a Data_Exchange's decoded-by-module JSON, made from
  pieces, equal the line of _body(_fields(...)) and json.dumps of the dicts (docs/json.md), on a
  capture whose values change every telegram, with framing errors, tokens, short acknowledges,
  SAP telegrams and times that repeat, change and are -0.0.
- `--ring --from-file`: a pcap of a line whose station 4 stops answering gives one event and one
  capture on the file's clock.

No timing here: the speed is benchmarks/bench_sniff.py's.
"""

from __future__ import annotations

import json
import random
from pathlib import Path

import pytest

from conftest import run_main
from profidrive_cli.bustools.passive import PassiveDecoder, Watched, frame_suffix
from profidrive_cli.dp.capture import (Capture, Captured, _body, _fields, format_line, frame_fields,
                                       frame_json_head)
from profidrive_cli.drives.profile import all_profiles, load_profile
from profidrive_cli.fdl import frames as F

SHIPPED = [p for p in all_profiles() if p.family in ("fuji", "moeller", "toyo", "yaskawa",
                                                      "profidrive")]
EDGES = (0, 1, 0x7FFF, 0x8000, 0xFFFF, 0x4000, 0xC000)


def _areas(size: int, offset: int | None, order: str, rng: random.Random, n: int) -> list[bytes]:
    """n random areas, then the speed word's edges in an area of each class of the rest."""
    out = [bytes(rng.getrandbits(8) for _ in range(size)) for _ in range(n)]
    if offset is not None:
        for base in out[:6]:
            for w in EDGES:
                a = bytearray(base)
                a[offset:offset + 2] = w.to_bytes(2, order)  # type: ignore[arg-type]
                out.append(bytes(a))
    return out


def _frame(direction: str, station: int, data: bytes) -> Captured:
    f = (F.Frame(F.SD2, station, 2, F.request_fc(F.SRD_HIGH, True, True), data) if direction == "request"
         else F.Frame(F.SD2, 2, station, F.response_fc(F.DL), data))
    raw = F.encode(f, force_sd2=True)
    parsed = F.parse(raw)
    assert isinstance(parsed, tuple)
    return Captured(0.0, raw, parsed[0])


@pytest.mark.parametrize("fmax", [None, 50.0])
@pytest.mark.parametrize("profile", SHIPPED, ids=lambda p: p.name)
def test_the_station_fast_path_gives_the_slow_paths_drive_object(profile, fmax):
    from profidrive_cli.drives import codec_module
    assert hasattr(codec_module(profile), "speed_plan"), f"{profile.family}: no speed_plan"
    rng = random.Random(f"{profile.name}-{fmax}")
    planned = 0
    for layout, lay in profile.layouts.items():
        for direction in ("request", "response"):
            size = lay.output_len if direction == "request" else lay.input_len
            fast = PassiveDecoder({5: Watched(5, profile, layout, fmax=fmax)})
            slow = PassiveDecoder({5: Watched(5, profile, layout, fmax=fmax)}, fast=False)
            lines = PassiveDecoder({5: Watched(5, profile, layout, fmax=fmax)})
            plan = codec_module(profile).speed_plan(profile, layout, direction, None)
            planned += plan is not None
            for data in _areas(size, plan.offset if plan else None, plan.order if plan else "big",
                               rng, 60):
                c = _frame(direction, 5, data)
                a, b = fast.decode(c), slow.decode(c)
                assert a == b and list(a) == list(b), (layout, direction, data.hex(" "))
                assert lines.suffix(c) == frame_suffix(b)         # the text line's words
                assert json.dumps(a) == json.dumps(b)
                # speed=False: everything but the Hz and the text as the slow way's
                r = fast.decode(c, speed=False)
                keep = {k: v for k, v in b.items() if "_hz" not in k and "_percent" not in k
                        and k != "text"}
                assert {k: v for k, v in r.items() if k in keep} == keep
                assert fast.watched[5].fmax == slow.watched[5].fmax
    assert planned                     # every family has a plan for some of its layouts


def test_the_plans_name_the_words_the_manuals_do():
    """Hand-read from the layouts (manuals): PPO1 PKW 0..7, STW/ZSW 8..9, HSW/HIW 10..11 (Fuji,
    Moeller big-endian, Toyo little-endian); Yaskawa extended1 out word 1 the reference, in word 5
    the output frequency."""
    from profidrive_cli.drives import codec_module
    want = {("fuji-opc-g1-pdp", "ppo1"): (10, 10, "big"), ("moeller-de6-net-dp", "ppo3"): (2, 2, "big"),
            ("toyo-pbus66z", "ppo1"): (10, 10, "little"),
            ("yaskawa-si-p1", "extended1"): (2, 10, "big"), ("yaskawa-si-p1", "basic"): (2, 2, "big")}
    for (name, layout), (req, rep, order) in want.items():
        p = load_profile(name)
        mod = codec_module(p)
        a, b = mod.speed_plan(p, layout, "request"), mod.speed_plan(p, layout, "response")
        assert (a.offset, b.offset, a.order, b.order) == (req, rep, order, order)
    # N2 0x2000 = 50 % (0x4000 = 100 %) of a given max frequency of 60 Hz: 30 Hz
    p = load_profile("fuji-opc-g1-pdp")
    f = codec_module(p).speed_plan(p, "ppo1", "request", 60.0).fields(0x2000)
    assert f == {"reference_hz": 30.0, "reference_percent": 50.0}
    # Yaskawa o1-03 = 0: reference 0.01 Hz per count, 3000 = 30.00 Hz
    p = load_profile("yaskawa-si-p1")
    assert codec_module(p).speed_plan(p, "extended1", "request").fields(3000) == {"reference_hz": 30.0}


def _changing_capture(rng: random.Random, cycles: int) -> bytes:
    """A line of the five default drives in PPO1 / extended1 whose reference and actual words
    change every cycle, with tokens, a Set_Prm, a Chk_Cfg, short acknowledges, an FDL status, a
    broken telegram and garbage in between."""
    out = [F.encode(F.Frame(F.SD2, 3, 2, F.request_fc(F.SRD_HIGH, False, True),
                            bytes.fromhex("88 c8 01 0b fd 01 00"), 61, 62)), b"\xE5",
           F.encode(F.Frame(F.SD2, 3, 2, F.request_fc(F.SRD_HIGH, True, True), b"\xf3\xf1", 62, 62)),
           b"\xE5", b"\x00\x13\x37", F.encode(F.token(2, 2))]
    for n in range(cycles):
        for st, size in ((3, 12), (4, 12), (5, 12), (6, 12), (7, 32)):
            req = bytearray(rng.getrandbits(8) for _ in range(size))
            rep = bytearray(rng.getrandbits(8) for _ in range(size))
            req[8:12] = b"\x04\x7f" + (0x2000 + n).to_bytes(2, "big")
            out.append(F.encode(F.Frame(F.SD2, st, 2, F.request_fc(F.SRD_HIGH, n % 2 == 0, True),
                                        bytes(req)), force_sd2=True))
            out.append(F.encode(F.Frame(F.SD2, 2, st, F.response_fc(F.DL), bytes(rep)),
                                force_sd2=True))
        if n % 7 == 0:
            out.append(F.encode(F.token(2, 2)))
            out.append(F.encode(F.Frame(F.SD2, 9, 2, F.request_fc(F.FDL_STATUS))))
            out.append(b"\x68\x05\x06\x68")                    # LE != LEr
    return b"".join(out)


def _entries(raw: bytes) -> list[Captured]:
    cap = Capture()
    items: list[Captured] = []
    for i, chunk in enumerate(raw[j:j + 997] for j in range(0, len(raw), 997)):
        # times that repeat, change, and a negative zero
        items += cap.feed(chunk, -0.0 if i % 5 == 0 else float(i // 3) * 0.000125)
    return items + cap.feed(b"", 1.5)


def test_the_frame_line_and_json_from_pieces_equal_the_dicts():
    from profidrive_cli.cli.sniff_view import frame_json
    items = _entries(_changing_capture(random.Random(7), 40))
    kinds = {c.frame.sd if c.frame is not None else "error" for c in items}
    assert kinds >= {F.SD2, F.SD1, F.SD4, F.SC, "error"}
    for c in items:
        if c.frame is None:
            continue
        want_line = f"{round(c.t, 6):>12.6f}  {_body(_fields(c.raw, c.frame))}"
        assert format_line(c) == want_line
        assert format_line(c, "->") == want_line[:14] + "-> " + want_line[14:]
        assert frame_json_head(c) + "}" == json.dumps(frame_json(c.describe()))
        assert frame_fields(c) == _fields(c.raw, c.frame)
    assert format_line(Captured(-0.0, b"\xE5", F.SC_FRAME)).startswith("   -0.000000  SC")


def _reference_view_lines(items: list[Captured], as_json: bool, stations: list[str]) -> list[str]:
    """The plain path: the lines SniffView wrote before issue 38 (dicts through json.dumps)."""
    from profidrive_cli.bustools.passive import frame_suffix, watch_list
    from profidrive_cli.bustools.slaveview import SlaveView
    from profidrive_cli.cli.sniff_view import DECODED_INDENT, drive_json, frame_json
    from profidrive_cli.dp.du_decode import decode_du
    decoder = PassiveDecoder(watch_list(stations), fast=False) if stations else None
    slaves = SlaveView(None, set(decoder.watched) if decoder else ())
    lines = []
    for c in items:
        d = decoder.decode(c) if decoder is not None else None
        f = c.frame
        fields = frame_fields(c) if f is not None else None
        dec = (decode_du(fields["service"], f.data)
               if f is not None and fields is not None and "du" in fields else None)
        if f is not None:
            dec = slaves.decode(f, dec)
        if as_json:
            obj = frame_json(c.describe())
            if dec is not None:
                obj["decoded"] = dict(dec)
            if d is not None:
                obj["drive"] = drive_json(d)
            lines.append(json.dumps(obj) + "\n")
        else:
            line = format_line(c)
            if d is not None:
                line += frame_suffix(d)
            lines.append(line + "\n")
            if dec is not None:
                lines += [DECODED_INDENT + t + "\n" for t in dec.get("text", [])]
    return lines


@pytest.mark.parametrize("batched", [False, True])
@pytest.mark.parametrize("as_json", [False, True])
@pytest.mark.parametrize("stations", [[], ["3=fuji-g1", "4=fuji-pdp3", "5=toyo", "6=moeller",
                                           "7=yaskawa"]])
def test_the_view_writes_what_the_plain_path_writes(capsys, as_json, stations, batched):
    from profidrive_cli.cli.sniff_view import SniffView
    items = _entries(_changing_capture(random.Random(11), 30))
    view = SniffView(stations, as_json=as_json)
    capsys.readouterr()
    if batched:                         # sniff's way: a chunk's frames at once (SniffView.frames)
        for i in range(0, len(items), 97):
            view.frames(items[i:i + 97])
            view.flush()
    else:
        for c in items:
            view.frame(c)
    view.finish(0.0)
    got = capsys.readouterr().out
    assert got == "".join(_reference_view_lines(items, as_json, stations))
    if not stations:               # the GSD view of station 3: by module on its Data_Exchange
        assert "outputs by module (FUJIFD01.GSD)" in got and "inputs by module" in got
        assert ('"decoded": {"gsd": "FUJIFD01.GSD", "modules": [{' in got) == as_json


EXTERNAL = Path(__file__).resolve().parents[1] / ".." / "shared" / "testdata" / "external"


@pytest.mark.parametrize("as_json", [False, True])
def test_the_view_on_an_external_capture(capsys, as_json):
    """pyprofibus's ET200S start-up (../shared/testdata/external): a modular slave whose Data_Exchange
    the GSD cuts into several modules, also an area shorter than its modules."""
    from profidrive_cli.cli.sniff_view import SniffView
    path = EXTERNAL / "pyprofibus26-et200s-startup.raw"
    if not path.exists():
        pytest.skip("../shared/testdata/external is not here")
    raw = path.read_bytes()
    items = _entries(raw)
    for cut in (raw, raw + raw[:40]):           # (the second: a telegram cut at the end)
        items = _entries(cut)
        view = SniffView(as_json=as_json)
        capsys.readouterr()
        for c in items:
            view.frame(c)
        view.finish(0.0)
        assert capsys.readouterr().out == "".join(_reference_view_lines(items, as_json, []))


def test_the_triggers_fire_the_same_with_the_fast_path():
    from profidrive_cli.bustools.passive import watch_list
    from profidrive_cli.bustools.triggers import TriggerSet, parse
    rng = random.Random(3)
    raw = []
    for n in range(120):
        # drive 3 (Fuji PPO1): operation, faults at cycles 40..59 (STW bit 3), the actual ramps
        stw = 0x0237 | (0x0008 if 40 <= n < 60 else 0)
        raw.append(F.encode(F.Frame(F.SD2, 3, 2, F.request_fc(F.SRD_HIGH, n % 2 == 0, True),
                                    bytes(8) + b"\x04\x7f" + (0x2000 + n).to_bytes(2, "big"))))
        raw.append(F.encode(F.Frame(F.SD2, 2, 3, F.response_fc(F.DL),
                                    bytes(8) + stw.to_bytes(2, "big")
                                    + rng.getrandbits(15).to_bytes(2, "big"))))
    items = _entries(b"".join(raw))
    fired = []
    for fast in (True, False):
        tset = TriggerSet(parse("fault(3),state(3),pkw(3)"), PassiveDecoder(watch_list(["3=fuji-g1"]),
                                                                            fast=fast))
        fired.append([(x.trigger.label, x.station, x.text) for c in items for x in tset.feed(c)])
    assert fired[0] == fired[1]
    assert [k for k, _, _ in fired[0]].count("fault(3)") == 2        # on at 40, cleared at 60


def test_ring_from_a_pcap_file(tmp_path, capsys, monkeypatch):
    """Station 4 answers three rounds, then no more (every 10 ms a round to stations 3 and 4):
    lost(*) fires after LOST_AFTER = 4 unanswered rounds, on the file's clock; one capture."""
    from profidrive_cli.bustools.passive_live import LOST_AFTER
    from profidrive_cli.dp.capture import PcapWriter, read_pcap
    pkts: list[tuple[float, bytes]] = []
    for n in range(12):
        t = 1_700_000_000.0 + n * 0.01
        for st in (3, 4):
            pkts.append((t, F.encode(F.Frame(F.SD2, st, 2, F.request_fc(F.SRD_HIGH, n % 2 == 0, True),
                                             bytes(4)), force_sd2=True)))
            if st == 3 or n < 3:
                pkts.append((t + 0.001, F.encode(F.Frame(F.SD2, 2, st, F.response_fc(F.DL), bytes(4)),
                                                 force_sd2=True)))
    with open(tmp_path / "line.pcap", "wb") as fh:
        w = PcapWriter(fh)
        for t, raw in pkts:
            w.write(t, raw)
    out = tmp_path / "ev"
    out.mkdir()
    r = run_main(capsys, monkeypatch, "sniff", "--from-file", str(tmp_path / "line.pcap"),
                 "--ring", "1", "--after", "0.02", "--trigger", "lost(*)", "--out", str(out))
    assert r.exit_code == 0, r.stderr
    (line,) = r.stdout.splitlines()                        # one event
    assert "lost(*)  station 4 stopped answering: 4 rounds in a row unanswered" in line
    assert "1 event(s), 1 capture(s), 39 telegrams read" in r.stderr
    (cap,) = out.iterdir()
    _, got = read_pcap(cap.read_bytes())
    # the ring before the event (from the file's start) and 0.02 s after it, on the file's clock:
    # the event at the request after the LOST_AFTER-th unanswered one (round 3 + LOST_AFTER)
    t_event = 1_700_000_000.0 + (3 + LOST_AFTER) * 0.01
    assert got[0][0] == pytest.approx(pkts[0][0], abs=1e-6)
    assert all(t <= t_event + 0.02 + 1e-6 for t, _ in got) and len(got) < len(pkts)
    assert [raw for _, raw in got] == [raw for _, raw in pkts[:len(got)]]


def test_ring_from_a_file_refuses_a_pcap_to_write(tmp_path, capsys, monkeypatch):
    (tmp_path / "x.raw").write_bytes(b"\xE5")
    r = run_main(capsys, monkeypatch, "sniff", "--from-file", str(tmp_path / "x.raw"), "--ring", "1",
                 "--trigger", "lost(*)", "--pcap", str(tmp_path / "o.pcap"), "--out", str(tmp_path))
    assert r.exit_code == 2 and "not with --pcap" in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.raw"]


def _reference_feed(cap_buf: bytearray, t_first: float, t: float, hold: int) -> tuple[list[Captured], int]:
    """Capture.feed's loop before its SD2 fast path: F.parse at every position."""
    out, pos, stop = [], 0, len(cap_buf) - hold
    tt = t_first
    while pos < stop:
        r = F.parse(cap_buf, pos)
        if r is None:
            break
        if isinstance(r, F.FrameError):
            used = r.used
            if r.kind == F.FrameError.GARBAGE:
                end = pos + used
                while end < len(cap_buf) and cap_buf[end] not in F.START_DELIMITERS:
                    end += 1
                used = end - pos
                out.append(Captured(tt, bytes(cap_buf[pos:end]), None, "garbage"))
            else:
                out.append(Captured(tt, bytes(cap_buf[pos:pos + used]), None, f"{r.kind}: {r.detail}"))
        else:
            out.append(Captured(tt, bytes(cap_buf[pos:pos + r[1]]), r[0]))
            used = r[1]
        pos += used
        tt = t
    return out, pos


def _odd_sd2(rng: random.Random) -> bytes:
    """An SD2 telegram as the fast path sees it, or one of its near misses: LE 250..255 with a
    right FCS and ED, a SAP bit, a wrong FCS / ED / LEr / second SD, cut short."""
    le = rng.choice((4, 5, 15, 35, 249, 250, 255, 3))
    body = bytes([rng.choice((3, 0x83, 2)), rng.choice((2, 0x82)), 0x7D]) + bytes(
        rng.getrandbits(8) for _ in range(max(0, le - 3)))
    t = bytearray([0x68, le, le, 0x68]) + body[:le] + bytes([sum(body[:le]) & 0xFF, 0x16])
    k = rng.randrange(8)
    if k == 0:
        t[-2] ^= 1
    elif k == 1:
        t[-1] = 0x17
    elif k == 2:
        t[2] ^= 1
    elif k == 3:
        t[3] = 0x69
    elif k == 4:
        t = t[:rng.randrange(1, len(t))]
    return bytes(t)


def test_the_capture_fast_path_parses_as_parse_does():
    from profidrive_cli.dp.capture import HOLD
    rng = random.Random(5)
    for _ in range(300):
        stream = b"".join(rng.choice((_odd_sd2(rng), b"\xE5", b"\xdc\x02\x03", b"\x10\x03\x02\x49\x4e\x16",
                                      bytes([rng.getrandbits(8)]))) for _ in range(20))
        cap = Capture()
        ref_buf = bytearray()
        ref_t = 0.0
        cuts = sorted(rng.sample(range(1, len(stream)), 6)) + [len(stream), len(stream)]
        for i, (j, k) in enumerate(zip([0] + cuts, cuts)):     # (the last chunk empty)
            chunk, t = stream[j:k], float(i)
            hold = rng.choice((0, HOLD)) if k < len(stream) else 0
            got = cap.feed(chunk, t, hold=hold)
            if not ref_buf:
                ref_t = t
            ref_buf += chunk
            want, used = _reference_feed(ref_buf, ref_t, t, hold)
            if want:
                ref_t = t
            del ref_buf[:used]
            assert got == want
        assert bytes(cap.rx.buf) == bytes(ref_buf)
