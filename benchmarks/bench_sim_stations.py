"""CPU per Data_Exchange against the number of simulated stations (issue 29: a simulator linear in
stations): N Fuji OPC-G1-PDP stations (PPO1, 12 octets each way) on a virtual-clock sim:// bus, all
in Data_Exchange, polled round robin by a dp.poller.Master in this process. The figure is the CPU
time of the whole process (master + simulator) per exchange; a simulator whose stations cost only
when addressed or due gives the same figure for 5 and for 125 stations (every address but the master's).

    python benchmarks/bench_sim_stations.py [--bauds 19200,1500000] [--stations 1,5,16,64,120,125]
                                            [--exchanges 1200] [--repeat 3] [--check 1.3]

Every station's DP watchdog is on (wd_ms, long enough for the slowest round robin: a station that
dropped out would be brought up again inside the timed loop and the figure would be bring-up, not
exchange); the run checks that no watchdog expired and says so. --check R: exit 1 unless the CPU per
exchange at the largest N is within R times the figure at 5 stations, at every rate.
"""

from __future__ import annotations

import argparse
import sys
import time

from profidrive_cli.dp.poller import Master
from profidrive_cli.dp.station import SlaveConfig
from profidrive_cli.fdl.frames import DEFAULT_MASTER
from profidrive_cli.fdl.timing import BusParams
from profidrive_cli.link import open_link

IDENT, CFG = 0xFD01, bytes.fromhex("F3F1")          # fuji-g1, PPO1
#: the watchdog every station gets: longer than bringing up 125 stations at 19.2 kbit/s
WD_MS = 60000.0


def addresses(n: int) -> list[int]:
    """n station addresses: 3, 4, ... while they fit (a sim:// station takes 0..125), else every
    address but the master's (125 stations at most)."""
    if n <= 123:
        return list(range(3, 3 + n))
    return [a for a in range(0, 126) if a != DEFAULT_MASTER][:n]


#: PPO1 outputs: PKW idle, CTW 0x047F (bit 10 + run bits 0-6: the drive runs), MRV 0x2000 (50 %)
RUNNING = bytes(8) + bytes.fromhex("047F2000")


def run(n: int, baud: int, exchanges: int, out: bytes = bytes(12)) -> tuple[float, float, int]:
    """(CPU us per exchange, virtual ms per exchange, watchdog expiries) for n stations."""
    addrs = addresses(n)
    st = ",".join(f"{a}:fuji-g1" for a in addrs)
    link = open_link(f"sim://?stations={st}&timing=virtual&baud={baud}", baud)
    m = Master(link, BusParams.for_baud(baud, retries=1))
    for a in addrs:
        m.add_station(a, SlaveConfig(ident=IDENT, cfg=CFG, wd_ms=WD_MS))
        m.bring_up(a)
    for first in (out[:8] + bytes([out[8], out[9] & 0xFE]) + out[10:], out):
        for a in addrs:               # the outputs in force before the timing starts (running:
            m.exchange(a, first)      # ON = 0 first, S1 -> S2, then ON: S4)
    if out != bytes(12):              # running: on to the set speed before the timing starts
        for i in range(200000):
            if i % n == 0 and all(s.model.at_setpoint() for s in link.bus.slaves.values()):
                break
            m.exchange(addrs[i % n], out)
        for a in addrs:               # (and once more: the motor model settles at that speed)
            m.exchange(a, out)
    t0, v0 = time.process_time(), link.now()
    for i in range(exchanges):
        m.exchange(addrs[i % n], out)
    cpu = time.process_time() - t0
    virt = link.now() - v0
    slaves = link.bus.slaves.values()
    if out != bytes(12):
        assert all(s.model.state.name == "S4" for s in slaves), "the drives do not run"
    expired = sum(s.stats["watchdog_expired"] for s in slaves)
    if not all(m.stations[a].in_data_exchange for a in addrs):
        expired += 1
    link.close()
    return cpu / exchanges * 1e6, virt / exchanges * 1e3, expired


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bauds", default="19200,1500000")
    ap.add_argument("--stations", default="1,5,16,64,120,125")
    ap.add_argument("--exchanges", type=int, default=1200)
    ap.add_argument("--repeat", type=int, default=3, help="best of this many runs per figure")
    ap.add_argument("--check", type=float, default=None, metavar="RATIO")
    ap.add_argument("--running", action="store_true",
                    help="every drive running at 50 %% (brought to that speed before the timing "
                         "starts: a ramping drive is ticked at every tick of the bus, as before)")
    a = ap.parse_args(argv)
    counts = [int(x) for x in a.stations.split(",")]
    ok = True
    for baud in (int(x) for x in a.bauds.split(",")):
        what = "drives running" if a.running else "drives at standstill"
        print(f"{baud} bit/s, {a.exchanges} exchanges round robin, {what}, best of {a.repeat}")
        print(f"  {'stations':>8}  {'CPU us/exchange':>15}  {'virtual ms/exchange':>19}  {'x 5 stations':>12}")
        base = None
        figures = {}
        for n in counts:
            runs = [run(n, baud, a.exchanges, RUNNING if a.running else bytes(12))
                    for _ in range(a.repeat)]
            us = min(r[0] for r in runs)
            virt = runs[0][1]
            expired = sum(r[2] for r in runs)
            figures[n] = us
            if n == 5:
                base = us
            ratio = f"{us / base:12.2f}" if base else f"{'':>12}"
            note = f"  ({expired} watchdog expiries: not a clean run)" if expired else ""
            print(f"  {n:8d}  {us:15.1f}  {virt:19.3f}  {ratio}{note}")
            if expired:
                ok = False
        if a.check is not None and base and figures[counts[-1]] / base > a.check:
            print(f"  {counts[-1]} stations cost {figures[counts[-1]] / base:.2f} x 5 stations: "
                  f"more than {a.check:g} x")
            ok = False
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
