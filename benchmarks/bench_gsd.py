"""Parse time of the largest real GSD file (si02806a.gse, Siemens ET 200S, 192 KB, 7300 lines).

    python benchmarks/bench_gsd.py [FILE] [--runs N]

Prints best and median of N parses (no cache: each run reads and parses the file again), measured with
time.perf_counter. The default file is ../shared/testdata/gsd/proview/si02806a.gse next to the checkout.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

from profidrive_cli.gsd.parser import parse_gsd

DEFAULT = Path(__file__).resolve().parents[2] / "shared" / "testdata" / "gsd" / "proview" / "si02806a.gse"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("file", nargs="?", default=str(DEFAULT))
    ap.add_argument("--runs", type=int, default=20)
    a = ap.parse_args(argv)
    path = Path(a.file)
    if not path.is_file():
        print(f"bench_gsd: {path}: no such file", file=sys.stderr)
        return 2
    parse_gsd(path)                       # warm-up (imports, regex compilation, OS file cache)
    times = []
    for _ in range(max(1, a.runs)):
        t0 = time.perf_counter()
        g = parse_gsd(path)
        times.append(time.perf_counter() - t0)
    size = path.stat().st_size
    print(f"{path.name}: {size / 1024:.0f} KiB, {len(g.modules)} modules, "
          f"{len(g.ext_user_prm_data)} ExtUserPrmData, {len(g.warnings)} warnings")
    print(f"parse: best {min(times) * 1000:.1f} ms, median {statistics.median(times) * 1000:.1f} ms "
          f"over {len(times)} runs (Python {sys.version.split()[0]})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
