"""`pdrive param fleet dump` of a line of five drives against the wire it runs on, and against one
`pdrive status` on the same bus (the price of starting a command and bringing up a station).

    python benchmarks/bench_fleet.py [--baud 1500000,19200] [--repeat 3] [--against DIR]

Each command runs as a process of its own on `sim://?baud=B&timing=wire` (the simulated plant
answers at the times its telegrams would take on a line of that rate, at its slaves' min TSDR),
with `--baud B --trace FILE.pcap` (every telegram the command sent and received, with its time):

    pdrive status 3 ...
    pdrive param fleet dump 3,4,5,6,7 -o DIR ...     (fuji-g1, fuji-pdp3, toyo, moeller, yaskawa)

The wire bound, by hand from ../shared/spec/profibus-dp-reference.md: a character is 11 bit (§1);
a reply may start min TSDR = 11 bit after its request, and the next request TID1 = 37 bit after a
reply (§4.1, rows 9.6k to 1.5M). So a telegram of k octets costs at least 11·k bit plus its idle
time before it, and the traced telegrams' sum over the baud rate is the least time the line needs
for them (telegram count × telegram time; the script prints it with the count). E.g. one PPO1
Data_Exchange (SD2, 12 data octets each way: 21 + 21 octets) is 2·21·11 + 11 + 37 = 510 bit:
0.34 ms at 1.5 Mbit/s, 26.6 ms at 19.2 kbit/s.

Printed per baud rate and tree: the best wall time of --repeat runs of each command, its CPU time
(user + system), the dump's telegrams and their wire bound, the dump's wall time over that bound,
and the dump's wall time less status's (issue 38: at most 0.6 s at 1.5 Mbit/s; within 1.2x of the
bound at 19.2k). `--against DIR` runs the same commands from another checkout (e.g.
`git archive HEAD~3 | tar -x -C DIR`) in the same run.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = str(Path(__file__).resolve().parents[1])
sys.path.insert(0, HERE)

CHAR_BITS = 11          # reference §1: start, 8 data, parity, stop
MIN_TSDR = 11           # reference §4.1, rows 9.6k .. 1.5M
TID1 = 37               # reference §4.1: 35 + 2 TSET + TQUI, TSET 1, TQUI 0
STATIONS = "3,4,5,6,7"


def wire_bound(pcap: str, baud: int) -> tuple[int, float]:
    """(telegrams, least seconds on the line) of a --trace capture."""
    from profidrive_cli.dp.capfile import open_capture
    from profidrive_cli.dp.capture import Capture
    n = 0
    bits = 0
    cap = Capture()
    for p in open_capture(pcap):
        for c in cap.feed(p.raw, p.t):
            n += 1
            request = c.frame is not None and c.frame.is_request
            bits += CHAR_BITS * len(c.raw) + (TID1 if request else MIN_TSDR)
    return n, bits / baud


def run(root: str, args: list[str]) -> tuple[float, float, int]:
    """(wall s, cpu s, exit code) of `python -m profidrive_cli ARGS` from the checkout `root`."""
    env = dict(os.environ)
    env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    t = time.perf_counter()
    p = subprocess.Popen([sys.executable, "-m", "profidrive_cli", *args], cwd=root, env=env,
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, ru = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t
    rc = os.waitstatus_to_exitcode(status)
    if rc:
        assert p.stderr is not None
        sys.stderr.write(p.stderr.read().decode(errors="replace"))
    return wall, ru.ru_utime + ru.ru_stime, rc


def best(root: str, args: list[str], repeat: int) -> tuple[float, float, int]:
    runs = [run(root, args) for _ in range(repeat)]
    wall = min(r[0] for r in runs)
    cpu = min(r[1] for r in runs)
    return wall, cpu, max(r[2] for r in runs)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--baud", default="1500000,19200")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--against", metavar="DIR")
    a = ap.parse_args()
    trees = [("this", HERE)] + ([(os.path.basename(os.path.abspath(a.against)),
                                  os.path.abspath(a.against))] if a.against else [])
    print(f"load {os.getloadavg()[0]:.1f}; best of {a.repeat}")
    print(f"{'baud':>8} {'tree':<10}{'status s':>9}{'cpu':>6}{'dump s':>8}{'cpu':>6}{'telegrams':>10}"
          f"{'wire s':>8}{'x wire':>7}{'dump-status':>12}")
    for baud in (int(b) for b in a.baud.split(",")):
        port = ["--port", f"sim://?baud={baud}&timing=wire", "--baud", str(baud)]
        for tag, root in trees:
            with tempfile.TemporaryDirectory(prefix="bench_fleet") as d:
                st_wall, st_cpu, rc1 = best(root, ["status", "3", *port], a.repeat)
                trace = os.path.join(d, "dump.pcap")
                out = os.path.join(d, "out")
                os.mkdir(out)
                dw, dc, rc2 = best(root, ["param", "fleet", "dump", STATIONS, "-o", out, *port,
                                          "--trace", trace], a.repeat)
                n, wire = wire_bound(trace, baud)
            bad = "" if rc1 == rc2 == 0 else f"  exit {rc1}/{rc2}"
            print(f"{baud:>8} {tag:<10}{st_wall:>9.2f}{st_cpu:>6.2f}{dw:>8.2f}{dc:>6.2f}{n:>10,}"
                  f"{wire:>8.2f}{dw / wire:>7.2f}{dw - st_wall:>12.2f}{bad}", flush=True)


if __name__ == "__main__":
    main()
