"""Fuzz pdrive's capture readers and writers: mutated pcap, pcapng, ProfiTrace .ptd and raw files through
dp/capfile.py (open_capture, every writer, sim/learn.py's load_plans) and through the commands that read
them -- `sniff --from-file`, `convert`, `sim --learn` -- in process through cli.main.main() (the same
code path as the command line; `sim --learn` with its serving loop stubbed: a file it learns from ends
the run at once).

Seeds: the ET200S start-up of ../shared/testdata/external (if present) and a start-up built here from
pdrive's own telegram encoder, each written as pcap, pcapng (with directions and comments), .ptd and
raw by pdrive's writers. Mutations: byte flips, truncation, deleted / repeated runs, and -- what
reaches the checks of issue 35 -- a 32-bit field set to an extreme (block and record lengths,
timestamps, fractions, if_tsresol / if_tsoffset values).

A case passes when the library raises nothing but UsageError / DataFileError (the house's one-line
errors; CaptureFileError and TimeRangeError are UsageErrors) and every command exits 0, 1 or 2 with
no traceback and a message when it fails, within --hang seconds. Failures go to --out DIR (the input
and a .txt with the error) and are counted.

    python tools/fuzz_captures.py --files 15000 --seed 1 --out /tmp/fuzz-cap

Not part of CI (tests/test_capture_fuzz.py runs a short seeded subset of the same mutators).
"""

from __future__ import annotations

import argparse
import io
import os
import random
import signal
import struct
import sys
import tempfile
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tools"))

from fuzz_files import Hang, _alarm, run_main  # noqa: E402  (the GSD fuzzer's in-process runner)

ET200S = ROOT.parent / "shared" / "testdata" / "external" / "pyprofibus26-et200s-startup.raw"
T0 = 1_700_000_000.0
FORMATS = ("pcap", "pcapng", "ptd", "raw")
#: values that sit on the edges of lengths, fractions and times
EXTREMES = [0, 1, 3, 4, 8, 11, 12, 13, 15, 16, 19, 20, 27, 28, 31, 32, 35, 999_999, 1_000_000, 10**9,
            0x7FFFFFFF, 0x80000000, 0xFFFFFFFE, 0xFFFFFFFF, 1 << 18, (1 << 18) + 1]


def _startup() -> list[bytes]:
    """A DP start-up of station 6 and two Data_Exchanges, from pdrive's encoder."""
    from profidrive_cli.fdl import frames as F
    sd = lambda da, sa, fc, data=b"", dsap=None, ssap=None: F.encode(F.Frame(F.SD2, da, sa, fc, data, dsap, ssap))
    ident = (0xFD01).to_bytes(2, "big")
    return [F.encode(F.token(2, 2)),
            sd(6, 2, 0x6D, b"", 60, 62), sd(2, 6, 0x08, bytes([0x02, 0x05, 0x00, 0xFF]) + ident, 62, 60),
            sd(6, 2, 0x5D, bytes([0xB8, 0x0D, 0x0F, 0x0B, 0x80]) + ident + b"\x00", 61, 62), b"\xE5",
            sd(6, 2, 0x7D, bytes([0xF3, 0xF1]), 62, 62), b"\xE5",
            sd(6, 2, 0x5D, b"", 60, 62), sd(2, 6, 0x08, bytes([0x00, 0x0C, 0x00, 0x02]) + ident, 62, 60),
            sd(6, 2, 0x7D, bytes(12)), sd(2, 6, 0x08, bytes(range(12))),
            sd(6, 2, 0x5D, bytes(12)), sd(2, 6, 0x08, bytes(range(1, 13)))]


def seeds() -> dict[str, bytes]:
    """name.ext -> octets: each seed telegram list in every format, written by pdrive's writers."""
    from profidrive_cli.dp.capfile import Packet, open_capture, open_writer
    sets = {"startup": [Packet(T0 + i * 0.002, raw, ("out", "in")[i % 2] if i < 3 else None,
                               "first" if i == 0 else None) for i, raw in enumerate(_startup())]}
    if ET200S.is_file():
        sets["et200s"] = [p._replace(t=T0 + i * 0.01) for i, p in enumerate(open_capture(ET200S, "raw"))]
    out = {}
    for name, packets in sets.items():
        for fmt in FORMATS:
            buf = io.BytesIO()
            w = open_writer(buf, fmt, baud=19200 if name == "et200s" else 1_500_000)
            for p in packets:
                w.write(p)
            w.close()
            out[f"{name}.{fmt}"] = buf.getvalue()
    return out


def mutate(rng: random.Random, data: bytes) -> bytes:
    b = bytearray(data)
    for _ in range(rng.randint(1, 3)):
        op = rng.randrange(8)
        pos = rng.randrange(len(b) + 1)
        if op <= 2 and len(b) >= 4:                        # a 32-bit field to an extreme (aligned: pcapng)
            at = min(pos - pos % (4 if op < 2 else 1), len(b) - 4)
            order = "<" if rng.random() < 0.9 else ">"
            b[at:at + 4] = struct.pack(order + "I", rng.choice(EXTREMES) if op < 2 else rng.randrange(1 << 32))
        elif op == 3 and b:                                 # flip a byte
            b[min(pos, len(b) - 1)] = rng.randrange(256)
        elif op == 4:                                       # truncate
            del b[pos:]
        elif op == 5:                                       # delete a run
            del b[pos:pos + rng.randint(1, 40)]
        elif op == 6:                                       # repeat a run
            b[pos:pos] = b[pos:pos + rng.randint(1, 80)]
        else:                                               # a u64 time: the high word of a timestamp
            at = min(pos - pos % 4, max(0, len(b) - 8))
            b[at:at + 8] = struct.pack("<Q", rng.choice([0, 1 << 63, (1 << 64) - 1, 1 << 40, 253402300800 * 10**6]))
    return bytes(b)


def _house() -> tuple[type, ...]:
    from profidrive_cli import UsageError
    from profidrive_cli.datafile import DataFileError
    return (UsageError, DataFileError)


def library_case(path: Path) -> str | None:
    """open_capture, every writer onto memory, load_plans: None, or the traceback of a crash."""
    from profidrive_cli.dp.capfile import open_capture, open_writer
    from profidrive_cli.sim.learn import load_plans
    house = _house()
    try:
        try:
            packets = list(open_capture(path))
        except house:
            return None
        for fmt in FORMATS:
            try:
                w = open_writer(io.BytesIO(), fmt)
                for p in packets:
                    w.write(p)
                w.close()
            except house:
                pass
        try:
            load_plans(path)
        except house:
            pass
    except Hang:
        raise
    except Exception:                                       # noqa: BLE001 - that is the finding
        return traceback.format_exc()
    return None


def _no_serving():
    """sim --learn: the plant is built (the capture read and learnt), then nothing is served."""
    from profidrive_cli.sim import server
    server.serve = lambda *a, **k: None


def cli_runs(path: Path, out_dir: Path, i: int) -> list[list[str]]:
    fmt = ("pcap", "pcapng", "ptd", "raw")[i % 4]
    return [["sniff", "--from-file", str(path), "--json"],
            ["convert", str(path), str(out_dir / f"out.{fmt}")],
            ["sim", "--learn", str(path), "--pty", "--json"]]


def fuzz(n: int, seed: int, hang_s: float, out_dir: Path | None, tmp: Path, cli: bool = True) -> dict:
    rng = random.Random(f"captures:{seed}")
    seed_files = seeds()
    names = sorted(seed_files)
    counts = {"files": 0, "runs": 0, "crash": 0, "hang": 0, "exit0": 0, "exit1": 0, "exit2": 0,
              "lib_refused": 0, "slowest_s": 0.0}
    if cli:
        _no_serving()
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    for i in range(n):
        name = names[rng.randrange(len(names))]
        data = mutate(rng, seed_files[name])
        path = tmp / f"case{i % 2}{Path(name).suffix}"
        path.write_bytes(data)
        counts["files"] += 1
        findings = []
        signal.setitimer(signal.ITIMER_REAL, hang_s)
        try:
            crash = library_case(path)
        except Hang:
            findings.append(("hang", "library", f"no answer within {hang_s} s"))
            crash = None
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
        if crash:
            findings.append(("crash", "library", crash))
        if cli:
            for argv in cli_runs(path, tmp, i):
                t0 = time.monotonic()
                verdict, code, detail = run_main(argv, hang_s)
                for s, h in handlers.items():                # sim sets its own
                    signal.signal(s, h)
                counts["slowest_s"] = max(counts["slowest_s"], round(time.monotonic() - t0, 3))
                counts["runs"] += 1
                if verdict == "ok":
                    counts[f"exit{code}"] += 1
                else:
                    findings.append((verdict, " ".join(argv[:1]), detail))
        if (i + 1) % 1000 == 0:
            print(f"... {i + 1} files: {counts['crash']} crashes, {counts['hang']} hangs", file=sys.stderr, flush=True)
        for verdict, where, detail in findings:
            counts[verdict] += 1
            print(f"#{i} ({name}) {where}: {verdict}: {detail.strip().splitlines()[-1:]}", file=sys.stderr)
            if out_dir is not None:
                out_dir.mkdir(parents=True, exist_ok=True)
                stem = out_dir / f"cap-{seed}-{i}"
                stem.with_suffix(Path(name).suffix).write_bytes(data)
                stem.with_suffix(".txt").write_text(f"{verdict} {where}\n{detail}")
    return counts


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--files", type=int, default=15000, help="mutated capture files")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--hang", type=float, default=5.0, help="seconds after which a run counts as a hang")
    ap.add_argument("--out", type=Path, default=None, help="folder for the inputs that failed")
    ap.add_argument("--library-only", action="store_true", help="no commands: open_capture, writers, learn")
    a = ap.parse_args(argv)
    signal.signal(signal.SIGALRM, _alarm)
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory() as tmp:
        c = fuzz(a.files, a.seed, a.hang, a.out, Path(tmp), cli=not a.library_only)
    print(f"captures: {c['files']} files, {c['runs']} command runs: {c['crash']} crashes, {c['hang']} hangs; "
          f"exit 0/1/2: {c['exit0']}/{c['exit1']}/{c['exit2']}; slowest {c['slowest_s']} s; "
          f"total {time.monotonic() - t0:.0f} s")
    return 1 if c["crash"] or c["hang"] else 0


if __name__ == "__main__":
    sys.exit(main())
