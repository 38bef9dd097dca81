"""Data_Exchange rate over socket:// (an RS-485-over-TCP converter: `pdrive sim --listen`) against a
pty (`pdrive sim --pty`), same plant, same master, 19.2k, the simulated station answering octet by
octet at wire time (plant timing=wire) in both cases.

    python benchmarks/bench_socket_vs_pty.py [--seconds S] [--baud RATE] [--repeat N]

Prints one JSON line per transport (exchanges per second, the wire limit for comparison) and the
ratio socket/pty (target >= 0.8). Each transport runs in its own `pdrive sim` subprocess; the
master runs in this process on the real clock (link latency margin 20 ms as for a real port).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

from profidrive_cli.fdl.timing import wire_time_data_exchange  # noqa: E402
from simbench import PLANT, master_on_sim  # noqa: E402


def run(kind: str, baud: int, seconds: float) -> dict:
    where = ["--pty"] if kind == "pty" else ["--listen", "127.0.0.1:0"]
    with master_on_sim(baud, PLANT.format(baud=baud), where) as (m, port):
        for _ in range(5):
            m.exchange(3, bytes(12))
        c = m.fdl.counters[3]
        before = c.data_exchanges
        t0 = time.monotonic()
        while time.monotonic() - t0 < seconds:
            m.exchange(3, bytes(12))
        took = time.monotonic() - t0
        n = c.data_exchanges - before
        m.release(3)
    return {"transport": kind, "port": port, "exchanges": n, "seconds": round(took, 3),
            "rate_hz": round(n / took, 1), "retries": c.retries, "illegal": c.illegal,
            "wire_limit_hz": round(1 / wire_time_data_exchange(baud, 12, 12), 1)}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--baud", type=int, default=19200)
    ap.add_argument("--repeat", type=int, default=1)
    a = ap.parse_args(argv)
    for _ in range(a.repeat):
        pty = run("pty", a.baud, a.seconds)
        sock = run("socket", a.baud, a.seconds)
        print(json.dumps(pty))
        print(json.dumps(sock))
        print(json.dumps({"socket_vs_pty": round(sock["rate_hz"] / pty["rate_hz"], 3)}))


if __name__ == "__main__":
    main()
