"""CPU per Data_Exchange over a pty at 19.2k against `pdrive sim --pty`, and the exchange rate.

The master runs in this process (dp.poller.Master over link.SerialLink, link latency margin 20 ms as
for a real port); the simulated station answers octet by octet at wire time (plant timing=wire) in a
`pdrive sim` subprocess. The figure is this process's CPU time (time.process_time: user + system)
per exchange, while the exchange rate shows the waiting did not get slower.

    python benchmarks/bench_pty_cpu.py [--seconds S] [--baud RATE] [--repeat N] [--spin] [--pyserial-io]

--spin            spin on the clock for the last 0.2 ms of every wait (link.base.precise_sleep), as
                  pdrive did on every link before it knew which links keep µs timing
--pyserial-io     read and write through pyserial (in_waiting + read: an ioctl and a select() more
                  per read; write: a select() after every write) instead of os.read / os.write
--old             both: what pdrive did before
--compare         alternate runs as now and as --old
--floor           also measure the floor, in the same run: a bare loop of the same system calls on
                  the same pty (write the request octets pdrive sent, one sleep until the reply is
                  due, read it, one sleep for the idle time), no protocol code. What pdrive adds is
                  its CPU minus the floor; the ratio is printed with both.
--plant five      the simulated plant holds five drives (the exchanges still go to station 3);
--timing instant  the simulated stations answer at once (what limits the rate is then the
                  master, the pty and the sim server's loop). One JSON line per run.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

from profidrive_cli.fdl.timing import frame_octets, wire_time_data_exchange  # noqa: E402
from profidrive_cli.link import serial_link  # noqa: E402
from simbench import PLANT, master_on_sim  # noqa: E402
#: --plant five: the default plant's five drives, station 3 the one exchanged with
FIVE = "sim://?stations=3:fuji-g1,4:fuji-pdp3,5:toyo,6:moeller,7:yaskawa&timing={timing}&baud={baud}"


def run(baud: int, seconds: float, spin: bool, pyserial_io: bool, plant: str = PLANT,
        timing: str = "wire") -> dict:
    url = plant.format(baud=baud, timing=timing).replace("timing=wire", f"timing={timing}")

    def switches():
        serial_link.FD_IO = not pyserial_io

    with master_on_sim(baud, url, before_open=switches) as (m, _):
        m.link.us_timing = spin                 # (SerialLink.sleep spins only with us_timing)
        for _ in range(5):
            m.exchange(3, bytes(12))
        c = m.fdl.counters[3]
        before = c.data_exchanges
        cpu0, t0 = time.process_time(), time.monotonic()
        while time.monotonic() - t0 < seconds:
            m.exchange(3, bytes(12))
        took, cpu = time.monotonic() - t0, time.process_time() - cpu0
        n = c.data_exchanges - before
        m.release(3)
    return {"baud": baud, "plant": url, "spin": spin, "pyserial_io": pyserial_io, "exchanges": n,
            "seconds": round(took, 3), "rate_hz": round(n / took, 1),
            "wire_limit_hz": round(1 / wire_time_data_exchange(baud, 12, 12), 1),
            "cpu_us_per_exchange": round(cpu / n * 1e6, 1), "retries": c.retries}


def floor(baud: int, seconds: float) -> dict:
    """The same exchanges as run() as a bare loop: the octets pdrive's master sent for two
    consecutive requests (FCB 0 and 1), written with os.write; one sleep until the reply is due on
    the wire (request + min TSDR + reply, plus the lag the link showed); os.read until the reply's
    octets are in (a select() only when they are not); one sleep for TID1. The least any Python
    master pays per exchange on this pty for the same pace."""
    import select
    with master_on_sim(baud, PLANT.format(baud=baud)) as (m, _):
        link = m.link
        sent = []
        real_write = link.write
        link.write = lambda data: (sent.append(bytes(data)), real_write(data))[1]
        for _ in range(4):
            m.exchange(3, bytes(12))
        link.write = real_write
        reqs = sent[-2:]
        p = m.fdl.params
        reply_len = frame_octets(12)           # SD2 frame with 12 data octets: 21
        due = p.chars(len(reqs[0]) + reply_len) + p.min_tsdr / p.baud + m.reply_lag
        tid1 = p.tid1_seconds
        fd = link.ser.fd
        n = 0
        cpu0, t0 = time.process_time(), time.monotonic()
        while time.monotonic() - t0 < seconds:
            os.write(fd, reqs[n & 1])
            time.sleep(due)
            got = b""
            while len(got) < reply_len:
                chunk = os.read(fd, 512)
                got += chunk
                if len(got) < reply_len:
                    select.select([fd], [], [], 0.05)
            time.sleep(tid1)
            n += 1
        took, cpu = time.monotonic() - t0, time.process_time() - cpu0
    return {"baud": baud, "floor": True, "exchanges": n, "seconds": round(took, 3),
            "rate_hz": round(n / took, 1), "cpu_us_per_exchange": round(cpu / n * 1e6, 1)}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--baud", type=int, default=19200)
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--spin", action="store_true")
    ap.add_argument("--pyserial-io", action="store_true")
    ap.add_argument("--old", action="store_true")
    ap.add_argument("--compare", action="store_true", help="alternate new and --old runs")
    ap.add_argument("--plant", choices=("one", "five"), default="one")
    ap.add_argument("--timing", choices=("wire", "instant"), default="wire")
    ap.add_argument("--floor", action="store_true", help="alternate with the bare loop's floor")
    a = ap.parse_args(argv)
    plant = FIVE if a.plant == "five" else PLANT
    for _ in range(a.repeat):
        if a.floor:
            ours = run(a.baud, a.seconds, False, False, plant, a.timing)
            base = floor(a.baud, a.seconds)
            ours["floor_cpu_us"] = base["cpu_us_per_exchange"]
            ours["floor_rate_hz"] = base["rate_hz"]
            ours["vs_floor"] = round(ours["cpu_us_per_exchange"] / base["cpu_us_per_exchange"], 2)
            print(json.dumps(ours), flush=True)
        elif a.compare:
            print(json.dumps(run(a.baud, a.seconds, False, False, plant, a.timing)), flush=True)
            print(json.dumps(run(a.baud, a.seconds, True, True, plant, a.timing)), flush=True)
        else:
            print(json.dumps(run(a.baud, a.seconds, a.spin or a.old, a.pyserial_io or a.old,
                                 plant, a.timing)), flush=True)


if __name__ == "__main__":
    main()
