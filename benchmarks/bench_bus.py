"""Bus-level figures on the wire-timed simulator (sim://?timing=wire: real wire time on the real
clock) against the wire limit computed from the timing parameters, and the jitter of a 30 Hz cycle
over a pty.

    python benchmarks/bench_bus.py [--only scan|cycle|jitter] [--cycles N] [--jitter-cycles N] [--no-spin]

scan    pdrive's live list 0..126 (one FDL status to every address, then Slave_Diag to the
        five stations found) at 19.2k and 187.5k. Wire limit: every request's octets (11 bit each),
        then either TSDR + reply + TID1, or the slot time for an empty address, per attempt.
cycle   Master.poll() over 1 and 5 stations in data exchange (default plant, default layouts) at
        19.2k, 187.5k and 1.5M. Wire limit per station: request + min TSDR + reply + TID1.
jitter  Master + StationChannel(period 1/30 s) against `pdrive sim --pty` in a subprocess: deviation
        of each cycle's interval from the period (p50 / p99 / max).

--no-spin: plain time.sleep() everywhere (link.base.SPIN_S = 0), to see what the operating system's
wake-up latency (~0.1 ms) alone costs; by default the last 0.2 ms of every wait polls the clock.

The same master on timing=virtual (a simulated clock) meets the wire limit exactly (tests/
test_timed_sim.py); what is left here is Python and the operating system: sleep granularity and
the CPU time of the master and of the simulated stations.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

from profidrive_cli.dp.poller import Master
from profidrive_cli.dp.scan import scan
from profidrive_cli.dp.station import SlaveConfig
from profidrive_cli.fdl.timing import BAUD_NAMES, BusParams
from profidrive_cli.link import open_link
from profidrive_cli.sim.bus import wire_limit


def _master(url: str, baud: int, retries: int = 1) -> Master:
    return Master(open_link(url, baud), BusParams.for_baud(baud, retries=retries))


def bench_scan(baud: int, repeat: int = 3) -> dict:
    best = None
    for _ in range(repeat):
        m = _master(f"sim://?baud={baud}&timing=wire", baud)
        bus = m.link.bus
        bus.log = []
        t0 = time.monotonic()
        found = scan(m, 0, 126)
        took = time.monotonic() - t0
        limit = wire_limit(bus.log, m.params) - m.params.tid1_seconds   # no idle after the last
        assert len(found) == 5 and bus.stats.tsyn_violations == 0 and bus.stats.collisions == 0
        m.link.close()
        r = {"baud": baud, "seconds": took, "limit": limit, "ratio": took / limit}
        if best is None or r["ratio"] < best["ratio"]:
            best = r
    return best


def bench_cycle(baud: int, n_stations: int, cycles: int) -> dict:
    m = _master(f"sim://?baud={baud}&timing=wire", baud)
    bus = m.link.bus
    for a, s in list(sorted(bus.slaves.items()))[:n_stations]:
        m.add_station(a, SlaveConfig(ident=s.model.ident, cfg=s.model.real_cfg()))
        m.bring_up(a)
    for _ in range(10):
        m.poll()
    bus.log = []
    t0 = time.monotonic()
    for _ in range(cycles):
        m.poll()
    took = time.monotonic() - t0
    limit = wire_limit(bus.log, m.params)
    ok = bus.stats.tsyn_violations == 0 and bus.stats.collisions == 0
    ok = ok and all(st.in_data_exchange for st in m.stations.values())
    retries = sum(c.retries for c in m.fdl.counters.values())
    m.link.close()
    return {"baud": baud, "stations": n_stations, "rate": cycles / took, "limit_rate": cycles / limit,
            "ratio": took / limit, "clean": ok, "retries": retries}


def bench_jitter(cycles: int, period: float = 1 / 30) -> dict:
    exe = [sys.executable, "-m", "profidrive_cli"]
    sim = subprocess.Popen(exe + ["sim", "--pty", "--json", "--plant", "sim://?stations=3:fuji-g1"],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        port = json.loads(sim.stdout.readline())["port"]
        m = Master(open_link(port, 19200), BusParams.for_baud(19200, retries=2, link_latency=0.02))
        m.add_station(3, SlaveConfig(ident=0xFD01, cfg=bytes.fromhex("F3F1")))
        m.bring_up(3)
        ch = m.channel(3, period)
        starts = []
        real = m.exchange

        def timed(address, outputs=None):
            starts.append(m.link.now())
            return real(address, outputs)
        m.exchange = timed
        for _ in range(cycles):
            ch.exchange(bytes(12))
        m.release(3)
        m.link.close()
    finally:
        sim.terminate()
        sim.wait(10)
    dev = sorted(abs((b - a) - period) for a, b in zip(starts, starts[1:]))
    q = statistics.quantiles(dev, n=100)
    return {"cycles": cycles, "p50_ms": q[49] * 1000, "p99_ms": q[98] * 1000, "max_ms": dev[-1] * 1000}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--only", choices=("scan", "cycle", "jitter"))
    ap.add_argument("--cycles", type=int, default=0, help="poll() rounds per cycle case (default: ~3 s each)")
    ap.add_argument("--jitter-cycles", type=int, default=600)
    ap.add_argument("--no-spin", action="store_true", help="plain time.sleep (no clock polling)")
    a = ap.parse_args(argv)
    if a.no_spin:
        import profidrive_cli.link.base as base
        base.SPIN_S = 0.0
    print(f"python {sys.version.split()[0]}, {os.cpu_count()} CPUs" + (", no spin" if a.no_spin else ""))
    if a.only in (None, "scan"):
        for baud in (19200, 187500):
            r = bench_scan(baud)
            print(f"scan 0..126 at {BAUD_NAMES[baud]:>6}: {r['seconds'] * 1000:8.1f} ms, wire limit "
                  f"{r['limit'] * 1000:8.1f} ms, {r['ratio']:.3f}x")
    if a.only in (None, "cycle"):
        for baud in (19200, 187500, 1500000):
            for n in (1, 5):
                per_s = {19200: 37, 187500: 360, 1500000: 2900}[baud] / n
                cycles = a.cycles or int(3 * per_s)
                r = bench_cycle(baud, n, cycles)
                print(f"Data_Exchange cycle, {n} station(s) at {BAUD_NAMES[baud]:>6}: {r['rate']:8.1f}/s, "
                      f"wire limit {r['limit_rate']:8.1f}/s, {r['ratio']:.3f}x"
                      + ("" if r["clean"] and not r["retries"] else
                         f"  (TSYN/collision/retry seen: {r['retries']} retries)"))
    if a.only in (None, "jitter"):
        r = bench_jitter(a.jitter_cycles)
        print(f"30 Hz cycle over a pty ({r['cycles']} cycles): deviation from the period "
              f"p50 {r['p50_ms']:.3f} ms, p99 {r['p99_ms']:.3f} ms, max {r['max_ms']:.3f} ms")


if __name__ == "__main__":
    main()
