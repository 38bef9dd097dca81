"""Drive-layer CPU per cycle against the master's own CPU per exchange, in the same run.

DriveSession.poll() unpaced (cycle_hz=0) on the instant in-process simulator (sim://): the time of
each poll is split three ways by wrapping the simulated bus (bus.receive: the slave side, not
pdrive's master) and the station channel under the session's MeteredChannel (the master: dp poller
+ fdl). What is left of a poll is the drive layer: the family's codec (control word, PPO/area
encode and decode, status decode), the session's metering (MeteredChannel, rate) and the Sample.

    python benchmarks/bench_drive_layer.py [--n 20000] [--repeat 5] [--stations 3,5,7]

Printed per station (family): drive-layer µs per cycle, master µs per exchange, their ratio; the best
of --repeat runs (least disturbed by other processes).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from profidrive_cli.cli.common import BusOptions  # noqa: E402
from profidrive_cli.session import DriveSession  # noqa: E402

DEFAULT_STATIONS = "3,4,5,6,7"   # fuji-g1, fuji-pdp3, toyo, moeller, yaskawa (default sim plant)


def measure(address: int, n: int, repeat: int) -> tuple[str, float, float]:
    master = BusOptions("sim://", "19200", 2, None, None, False, False, 0, False).open_master()
    sess = DriveSession(master, address, handle_signals=False, cycle_hz=0)
    sess.open()
    try:
        bus = master.link.bus
        sim = [0.0]
        inner_t = [0.0]
        real_receive = bus.receive

        def timed_receive(data, now):
            t = time.perf_counter()
            r = real_receive(data, now)
            sim[0] += time.perf_counter() - t
            return r

        inner = sess.channel.inner
        real_exchange = inner.exchange

        def timed_exchange(outputs):
            t = time.perf_counter()
            r = real_exchange(outputs)
            inner_t[0] += time.perf_counter() - t
            return r

        bus.receive = timed_receive
        inner.exchange = timed_exchange
        for _ in range(min(n, 2000)):         # warm up (fault reads, caches)
            sess.poll()
        best = None
        for _ in range(repeat):
            sim[0] = inner_t[0] = 0.0
            t = time.perf_counter()
            for _ in range(n):
                sess.poll()
            total = time.perf_counter() - t
            master_s = (inner_t[0] - sim[0]) / n
            drive_s = (total - inner_t[0]) / n
            if best is None or drive_s + master_s < best[0] + best[1]:
                best = (drive_s, master_s)
        return sess.profile.name, best[0], best[1]
    finally:
        sess.close()


def main(argv=None) -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=20000)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--stations", default=DEFAULT_STATIONS)
    a = ap.parse_args(argv)
    for address in (int(x) for x in a.stations.split(",")):
        name, drive_s, master_s = measure(address, a.n, a.repeat)
        print(f"station {address} {name:<20} drive layer {drive_s * 1e6:6.1f} µs per cycle; master "
              f"{master_s * 1e6:5.1f} µs per exchange; ratio {drive_s / master_s:4.1f}×")


if __name__ == "__main__":
    main()
