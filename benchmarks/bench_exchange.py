"""Master <-> in-process simulated slave: Data_Exchange round trips per second, and the master's own
CPU time per exchange (total minus the time spent inside the simulated bus), against the wire time
of the same exchange at 1.5 and 12 Mbit/s.

    python benchmarks/bench_exchange.py [--n 20000]
"""

from __future__ import annotations

import argparse
import time

from profidrive_cli.dp.poller import Master
from profidrive_cli.dp.station import SlaveConfig
from profidrive_cli.fdl.timing import BusParams, wire_time_data_exchange
from profidrive_cli.link import open_link
from profidrive_cli.sim.model import SlaveModel
from profidrive_cli.sim.slave import SimSlave

CASES = {4: bytes.fromhex("F1"), 12: bytes.fromhex("F3F1")}


def run(octets: int, n: int) -> tuple[float, float]:
    link = open_link("sim://?stations=9:fuji-g1")     # replaced below by a plain slave
    bus = link.bus
    cfg = CASES[octets]
    bus.slaves = {9: SimSlave(9, SlaveModel(0x4711, {"x": cfg}))}
    inside = [0.0]
    real_receive = bus.receive

    def timed_receive(data, now):
        t = time.perf_counter()
        r = real_receive(data, now)
        inside[0] += time.perf_counter() - t
        return r

    bus.receive = timed_receive
    m = Master(link, BusParams.for_baud(1500000))
    m.add_station(9, SlaveConfig(ident=0x4711, cfg=cfg))
    m.bring_up(9)
    out = bytes(octets)
    best_total = best_master = None
    for _ in range(5):
        inside[0] = 0.0
        t = time.perf_counter()
        for _ in range(n):
            m.exchange(9, out)
        total = time.perf_counter() - t
        master_only = total - inside[0]
        if best_total is None or total < best_total:
            best_total, best_master = total, master_only
    link.close()
    return n / best_total, best_master / n


def main(argv=None) -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=20000)
    a = ap.parse_args(argv)
    for octets in (4, 12):
        rate, master_s = run(octets, a.n)
        w15 = wire_time_data_exchange(1500000, octets, octets)
        w12 = wire_time_data_exchange(12000000, octets, octets)
        print(f"{octets:>2} octets each way: {rate:,.0f} round trips/s; master CPU "
              f"{master_s * 1e6:.1f} µs per exchange; wire time {w15 * 1e6:.0f} µs at 1.5M, "
              f"{w12 * 1e6:.1f} µs at 12M")


if __name__ == "__main__":
    main()
