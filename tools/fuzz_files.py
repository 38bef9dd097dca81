"""Fuzz pdrive's file inputs: mutated GSD files through `pdrive gsd show` (table and --json) and
`gsd prm`, mutated checklists through `pdrive checklist validate`, in process through cli.main.main()
(the same code path as the command line, without a process start per case).

A case passes when pdrive exits with 0, 1 or 2, prints no traceback, and finishes within --hang
seconds. Anything else (an exception escaping main(), a traceback, a timeout) is written to
--out DIR as the input file plus a .txt with the error, and counted.

    python tools/fuzz_files.py --gsd 20000 --checklists 4000 --seed 1 --out /tmp/fuzz-out

Not part of CI (tests/test_gsd_fuzz.py and tests/test_yaml_fuzz.py run a small seeded subset of the
same mutators). Needs only the repository: seeds are gsd/*.GSD, ../shared/testdata/gsd (if present)
and examples/checklists/*.yaml.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import random
import signal
import sys
import tempfile
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

# tokens that have broken parsers before: huge numbers, bad tags, aliases, deep nesting, odd bytes
GSD_TOKENS = [
    b"9" * 5000, b"0x" + b"F" * 5000, b"0x", b"-", b",", b"\\", b'"', b";", b"=", b"(", b")", b"\r", b"\n",
    b"#Profibus_DP", b"Module = \"M\" 0xC0, 0x01", b"EndModule", b"ExtUserPrmData = 1 \"x\"", b"Bit(9) 1 0-1",
    b"BitArea(7-0) 1", b"Unsigned32 4294967296 0-1", b"Prm_Text_Ref = 99", b"PrmText = 1", b"EndPrmText",
    b"Ext_User_Prm_Data_Const(236) = 1, 2", b"Ext_User_Prm_Data_Ref(0) = 1", b"Slot(1) = \"s\" 1 1-99999",
    b"Unit_Diag_Area = 0-31", b"Value(4294967295) = \"v\"", b"\xff\xfe", b"\x00", b"\xc3\x28",
    b"Ident_Number = " + b"1" * 4400, b"12M_supp = " + b"1" * 4400, b"Max_Module = -1",
]
YAML_TOKENS = [
    "!!float x", "!!int '12a'", "!!timestamp 2020-13-45", "!!timestamp x", "!!binary '@'", "!!set {a}",
    "!!omap [1]", "!!python/object:os.system x", "&a [1, 2]", "*a", "*nosuch", "<<: *a", "1" * 5000,
    "[" * 3000 + "]" * 3000, "{" * 200, "0x" + "f" * 5000, "1e99999", ".nan", "-.inf", "~", "null", "? [a]",
    "'", '"', "\t", "- ", ": ", "#", "%YAML 1.1\n---", "---", "...", "\x00", "\ufeff", "\u2028", "${x}",
    "${" + "x" * 500 + "}", "yes", "0o17", "0b102", "1_000", "190:20:30", "2001-02-30",
]


def _mutate_bytes(rng: random.Random, data: bytes, tokens: list[bytes]) -> bytes:
    b = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        op = rng.randrange(7)
        pos = rng.randrange(len(b) + 1)
        if op == 0 and b:                                   # flip a byte
            b[min(pos, len(b) - 1)] = rng.randrange(256)
        elif op == 1:                                        # insert a token
            b[pos:pos] = rng.choice(tokens)
        elif op == 2:                                        # delete a run
            del b[pos:pos + rng.randint(1, 200)]
        elif op == 3:                                        # truncate
            del b[pos:]
        elif op == 4:                                        # duplicate a run
            b[pos:pos] = b[pos:pos + rng.randint(1, 400)]
        elif op == 5:                                        # replace a number by a huge one
            i = b.find(b"0x", pos)
            if i >= 0:
                b[i + 2:i + 2] = b"F" * rng.choice((10, 100, 5000))
        else:                                                # swap two lines
            lines = bytes(b).split(b"\n")
            if len(lines) > 2:
                i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
                lines[i], lines[j] = lines[j], lines[i]
                b = bytearray(b"\n".join(lines))
    return bytes(b)


def mutate_gsd(rng: random.Random, data: bytes) -> bytes:
    return _mutate_bytes(rng, data, GSD_TOKENS)


def mutate_yaml(rng: random.Random, text: str) -> bytes:
    data = text.encode("utf-8")
    if rng.random() < 0.6:                                   # textual: a token at a line's value
        lines = text.split("\n")
        for _ in range(rng.randint(1, 3)):
            i = rng.randrange(len(lines))
            tok = rng.choice(YAML_TOKENS)
            ln = lines[i]
            k = ln.find(": ")
            lines[i] = (ln[:k + 2] + tok) if k >= 0 and rng.random() < 0.7 else ln + tok
        data = "\n".join(lines).encode("utf-8", "surrogatepass")
    if rng.random() < 0.5:
        data = _mutate_bytes(rng, data, [t.encode("utf-8") for t in YAML_TOKENS])
    return data


def gsd_seeds() -> list[Path]:
    seeds = sorted((ROOT / "gsd").glob("*.GSD"))
    shared = ROOT.parent / "shared" / "testdata" / "gsd" / "proview"
    if shared.is_dir():
        seeds += sorted(p for p in shared.iterdir() if p.suffix.lower() in (".gsd", ".gse")
                        and p.stat().st_size < 40_000)           # the two large ones make each case slow
    return seeds


def checklist_seeds() -> list[Path]:
    return sorted((ROOT / "examples" / "checklists").glob("*.yaml"))


class Hang(Exception):
    pass


def _alarm(signum, frame):
    raise Hang()


def run_main(argv: list[str], hang_s: float) -> tuple[str, int | None, str]:
    """('ok'|'crash'|'hang', exit code, detail) for one in-process pdrive run."""
    from profidrive_cli.cli.main import main
    from profidrive_cli.gsd.library import clear_cache
    clear_cache()
    out, err = io.StringIO(), io.StringIO()
    signal.setitimer(signal.ITIMER_REAL, hang_s)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            main(argv)
        code = 0
    except SystemExit as e:
        code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
    except Hang:
        return "hang", None, f"no answer within {hang_s} s"
    except BaseException:                                   # noqa: BLE001 - that is the finding
        return "crash", None, traceback.format_exc()
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
    text = err.getvalue()
    if "Traceback" in text or code not in (0, 1, 2):
        return "crash", code, text[-4000:]
    if code in (1, 2) and len(text.strip().splitlines()) == 0:
        return "crash", code, "failed without a message"
    return "ok", code, ""


def fuzz(kind: str, n: int, seed: int, hang_s: float, out_dir: Path | None, tmp: Path) -> dict:
    rng = random.Random(f"{kind}:{seed}")
    seeds = gsd_seeds() if kind == "gsd" else checklist_seeds()
    seed_data = [p.read_bytes() for p in seeds]
    counts = {"cases": 0, "ok": 0, "exit0": 0, "exit1": 0, "exit2": 0, "crash": 0, "hang": 0, "slowest_s": 0.0}
    suffix = ".gsd" if kind == "gsd" else ".yaml"
    path = tmp / f"case{suffix}"
    for i in range(n):
        k = rng.randrange(len(seeds))
        data = (mutate_gsd(rng, seed_data[k]) if kind == "gsd"
                else mutate_yaml(rng, seed_data[k].decode("utf-8")))
        path.write_bytes(data)
        if kind == "gsd":                 # every file as JSON; every 4th also as tables, and Set_Prm
            runs = [["gsd", "show", str(path), "--json"]]
            if i % 4 == 0:
                runs += [["gsd", "show", str(path)], ["gsd", "prm", str(path), "-m", "1", "--json"]]
        else:
            runs = [["checklist", "validate", str(path)]]
        for argv in runs:
            t0 = time.monotonic()
            verdict, code, detail = run_main(argv, hang_s)
            counts["slowest_s"] = max(counts["slowest_s"], round(time.monotonic() - t0, 3))
            counts["cases"] += 1
            counts[verdict if verdict != "ok" else "ok"] += 1
            if verdict == "ok":
                counts[f"exit{code}"] += 1
            elif out_dir is not None:
                out_dir.mkdir(parents=True, exist_ok=True)
                stem = out_dir / f"{kind}-{seed}-{i}"
                stem.with_suffix(suffix).write_bytes(data)
                stem.with_suffix(".txt").write_text(f"{verdict} {argv[:-1]} exit={code}\n{detail}")
            if verdict != "ok":
                print(f"{kind} #{i} ({seeds[k].name}): {verdict}: {detail.strip().splitlines()[-1:]}",
                      file=sys.stderr)
    return counts


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--gsd", type=int, default=20000, help="mutated GSD files")
    ap.add_argument("--checklists", type=int, default=4000, help="mutated checklists")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--hang", type=float, default=5.0, help="seconds after which a case counts as a hang")
    ap.add_argument("--out", type=Path, default=None, help="folder for the inputs that failed")
    a = ap.parse_args(argv)
    os.environ.pop("PDRIVE_GSD_DIR", None)
    signal.signal(signal.SIGALRM, _alarm)
    t0 = time.monotonic()
    bad = 0
    with tempfile.TemporaryDirectory() as tmp:
        for kind, n in (("gsd", a.gsd), ("checklist", a.checklists)):
            if n:
                c = fuzz(kind, n, a.seed, a.hang, a.out, Path(tmp))
                bad += c["crash"] + c["hang"]
                print(f"{kind}: {n} files, {c['cases']} runs: {c['crash']} crashes, {c['hang']} hangs; "
                      f"exit 0/1/2: {c['exit0']}/{c['exit1']}/{c['exit2']}; slowest {c['slowest_s']} s")
    print(f"total {time.monotonic() - t0:.0f} s")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
