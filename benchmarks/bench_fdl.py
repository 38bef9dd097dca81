"""FDL encode + decode of SD2 frames with a 12-octet DU: frames per second.

    python benchmarks/bench_fdl.py [--n 200000]
"""

from __future__ import annotations

import argparse
import time

from profidrive_cli.fdl import frames as F


def main(argv=None) -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=200000)
    a = ap.parse_args(argv)
    frame = F.Frame(F.SD2, 3, 2, 0x7D, bytes(range(12)))
    best = None
    for _ in range(5):
        t = time.perf_counter()
        for _ in range(a.n):
            raw = F.encode(frame)
            F.parse(raw)
        dt = time.perf_counter() - t
        best = dt if best is None or dt < best else best
    print(f"SD2 with 12-octet DU, encode+decode: {a.n / best:,.0f} frames/s "
          f"({best / a.n * 1e6:.2f} µs per frame; best of 5 x {a.n})")


if __name__ == "__main__":
    main()
