"""`pdrive sniff` keeps up with a saturated line (issue 27, "Keeping up"): --from-file is decoded as a
stream (memory flat in the file's length), frame lines are written plainly (not through rich), the
--station decoder decodes an area that repeats its predecessor once and asks inspect.signature once
per codec, not per frame. The words stay those of the line-by-line decoder (tests/test_sniff_passive.py,
tests/test_real_captures.py pin them); the rates are measured by benchmarks/bench_sniff.py."""

import random
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from profidrive_cli.bustools import passive as P
from profidrive_cli.dp.capture import (
    HOLD,
    Capture,
    ErrorMerger,
    format_line,
    merge_errors,
)
from profidrive_cli.fdl import frames as F

ROOT = Path(__file__).resolve().parents[1]
MASTER = 2


def req(da, data, fcb=True):
    return F.encode(F.Frame(F.SD2, da, MASTER, F.request_fc(F.SRD_HIGH, fcb, True), bytes(data)))


def rep(sa, data):
    return F.encode(F.Frame(F.SD2, MASTER, sa, F.DL, bytes(data)))


def _mixed_capture(seed: int) -> bytes:
    """Telegrams of every kind with runs of garbage, broken telegrams and a truncated end."""
    rnd = random.Random(seed)
    parts = [F.encode(F.Frame(F.SC)), F.encode(F.token(2, 2)),
             F.encode(F.Frame(F.SD2, 3, MASTER, F.request_fc(F.SRD_HIGH, True, False),
                              b"\x88\x01\x01\x0b\xfd\x01\x00", 61, 62)),
             req(3, bytes(12)), rep(3, bytes.fromhex("00" * 8 + "03 37 20 00")),
             bytes(rnd.randrange(256) for _ in range(40)), b"\x00" * 25,
             b"\x68\x05\x06\x68", b"\x10\x03\x02\x4d\x00\x16"]       # LE != LEr; FCS wrong
    out = b"".join(rnd.choice(parts) for _ in range(300))
    return out + b"\x68\x20"                                         # truncated at the end


# -- a capture read in chunks is shown as if it had been decoded in one piece ----------------------

@pytest.mark.parametrize("seed", range(4))
def test_chunked_decoding_gives_the_same_entries_as_one_piece(seed):
    raw = _mixed_capture(seed)
    whole = merge_errors(Capture().feed(raw, 0.0))
    rnd = random.Random(seed)
    cap, merger, got = Capture(), ErrorMerger(), []
    pos = 0
    while pos < len(raw):
        n = rnd.randint(1, 9)
        got += merger.feed(cap.feed(raw[pos:pos + n], 0.0, hold=HOLD))
        pos += n
    got += merger.feed(cap.feed(b"", 0.0)) + merger.flush()
    assert [(c.raw, c.error, c.frame) for c in got] == [(c.raw, c.error, c.frame) for c in whole]
    # a run of garbage that crosses chunks is one entry, as in one piece
    assert sum(1 for c in whole if c.error == "garbage") == sum(1 for c in got if c.error == "garbage")


def test_sniff_from_file_in_chunks_prints_what_one_piece_prints(tmp_path, monkeypatch):
    from profidrive_cli.cli import sniff_cmd
    from profidrive_cli.cli.main import cli
    raw = _mixed_capture(7)
    f = tmp_path / "mixed.raw"
    f.write_bytes(raw)
    # what the line-by-line decoder says of the whole file (merge_errors of one feed, then the
    # truncated rest), without the DU lines under Set_Prm
    cap = Capture()
    expected = [format_line(c) for c in merge_errors(cap.feed(raw, 0.0))]
    expected.append(f"    0.000000  !! truncated frame at end of input: {bytes(cap.rx.buf).hex(' ')}")
    monkeypatch.setattr(sniff_cmd, "CHUNK_BYTES", 5)
    r = CliRunner().invoke(cli, ["sniff", "--from-file", str(f)])
    assert r.exit_code == 0, r.output
    from profidrive_cli.cli.sniff_view import DECODED_INDENT
    assert [x for x in r.output.splitlines() if not x.startswith(DECODED_INDENT)] == expected


def test_frame_lines_do_not_go_through_rich(tmp_path, monkeypatch):
    # rich's Console.print was 68 % of `sniff`'s time (issue 27): a frame line is plain text, so it
    # is written as it is; rich stays for the tables and messages
    from profidrive_cli.cli import common
    from profidrive_cli.cli.main import cli
    f = tmp_path / "c.raw"
    f.write_bytes(b"".join([req(3, bytes(12)), rep(3, bytes(12))] * 20))
    calls = []
    real = common.out.print
    monkeypatch.setattr(common.out, "print", lambda *a, **k: (calls.append(a), real(*a, **k)))
    r = CliRunner().invoke(cli, ["sniff", "--from-file", str(f), "--station", "3=fuji-g1"])
    assert r.exit_code == 0, r.output
    assert len(r.output.splitlines()) == 40
    assert calls == []


# -- --station: an area decoded once, inspect.signature once per codec -----------------------------

F03_50 = "11 04 03 00 00 00 01 F4"        # fuji-opc-g1-pdp.md: F03 = 500 x 0.1 Hz = 50.0 Hz
F03_60 = "11 04 03 00 00 00 02 58"        # 600 x 0.1 Hz = 60.0 Hz
RUN = "00" * 8 + "04 7F 20 00"            # CTW 0x047F, MRV 0x2000 = 50 % of F03


def test_a_repeated_area_is_decoded_once(monkeypatch):
    calls = []
    real = P._decode
    monkeypatch.setattr(P, "_decode", lambda *a: (calls.append(a), real(*a))[1])
    dec = P.PassiveDecoder(P.watch_list(["3=fuji-g1"]))
    out = [dec.decode(c) for c in Capture().feed(
        b"".join([req(3, bytes.fromhex(RUN)), rep(3, bytes.fromhex("00" * 8 + "03 37 20 00"))] * 3), 0.0)]
    assert len(out) == 6 and len(calls) == 2        # the request and the answer, once each
    assert out[0] == out[2] == out[4] and out[0]["reference_hz"] == 30.0   # 50 % of the default 60 Hz
    assert out[1] == out[3] == out[5] and out[1]["state"].startswith("S4")


def test_a_cached_answer_still_teaches_the_max_frequency():
    # F03 answers 60, 50, 60, 50 Hz: the last is the same octets decoded with the same learnt
    # max frequency (60) as the second; it must set F03 = 50 Hz again, so that MRV 0x2000 (50 %)
    # is 25 Hz (50 % of 50 Hz), not 30 Hz
    dec = P.PassiveDecoder(P.watch_list(["3=fuji-g1"]))
    seq = [rep(3, bytes.fromhex(x + "03 37 20 00")) for x in (F03_60, F03_50, F03_60, F03_50)]
    got = [dec.decode(c) for c in Capture().feed(b"".join(seq) + req(3, bytes.fromhex(RUN)), 0.0)]
    assert [g["param"]["text"] for g in got[:4]] == ["F03 = 60.0 Hz", "F03 = 50.0 Hz"] * 2
    assert got[4]["reference_hz"] == 25.0


def test_inspect_signature_once_per_codec_not_per_frame(monkeypatch):
    import inspect
    calls = []
    real = inspect.signature
    monkeypatch.setattr(P.inspect, "signature", lambda fn: (calls.append(fn), real(fn))[1])
    dec = P.PassiveDecoder(P.watch_list(["3=fuji-g1", "4=fuji-pdp3"]))
    tgs = [rep(a, bytes.fromhex(F03_50 + "03 37 20 00")) for a in (3, 4)]
    tgs += [req(a, bytes(8) + bytes([0x04, 0x7F, 0x20, i])) for i in range(10) for a in (3, 4)]
    got = [dec.decode(c) for c in Capture().feed(b"".join(tgs), 0.0)]
    assert all("error" not in g for g in got)
    assert len(calls) <= 2                          # both profiles share the fuji codec


# -- memory flat in the capture's length ------------------------------------------------------------

#: runs `pdrive ARGS` and writes its peak RSS to OUT (benchmarks/peak_rss.py)
PEAK_RSS = str(Path(__file__).resolve().parents[1] / "benchmarks" / "peak_rss.py")


def _peak_rss_kib(path: Path, tmp_path: Path) -> int:
    out = tmp_path / "peak"
    r = subprocess.run([sys.executable, PEAK_RSS, str(out), "sniff", "--from-file",
                        str(path)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, cwd=ROOT,
                       timeout=600)
    assert r.returncode == 0, r.stderr
    return int(out.read_text())


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc/self/status: Linux")
def test_memory_does_not_grow_with_the_capture(tmp_path):
    # a file of 0xE5 octets is one short acknowledge per octet, the most frames per octet the size
    # limit lets through (issue 27: 16 MiB took 3 GB). A decoder that keeps every frame keeps at least
    # one object of >= 56 octets per frame (a slotted 4-field instance), so 3 x 128 Ki more frames
    # would take >= 21 MiB more; streamed, the two runs peak alike. Allowed: a quarter of that.
    n = 128 * 1024
    small, large = tmp_path / "small.raw", tmp_path / "large.raw"
    small.write_bytes(b"\xE5" * n)
    large.write_bytes(b"\xE5" * (4 * n))
    grown = _peak_rss_kib(large, tmp_path) - _peak_rss_kib(small, tmp_path)
    assert grown < 3 * n * 56 / 4 / 1024, f"peak RSS grew by {grown} KiB"
