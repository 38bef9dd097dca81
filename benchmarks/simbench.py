"""Shared by the benchmarks that talk to a `pdrive sim` subprocess over a real byte path: start the
simulator (pty or TCP), open the master in this process (link latency margin 20 ms as for a real
port) and bring station 3 (a Fuji OPC-G1-PDP, PPO1: 12 octets each way) to Data_Exchange."""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

from profidrive_cli.dp.poller import Master  # noqa: E402
from profidrive_cli.dp.station import SlaveConfig  # noqa: E402
from profidrive_cli.fdl.timing import BusParams  # noqa: E402
from profidrive_cli.link import open_link  # noqa: E402

PLANT = "sim://?stations=3:fuji-g1&timing=wire&baud={baud}"


@contextlib.contextmanager
def master_on_sim(baud: int, url: str, where=("--pty",), before_open=None):
    """Yield (master, port) with station 3 in Data_Exchange; the simulator ends on the way out.
    before_open(): called just before the port is opened (a benchmark's switches)."""
    sim = subprocess.Popen([sys.executable, "-m", "profidrive_cli", "sim", "--json", "--baud", str(baud),
                            "--plant", url, *where],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                           cwd=os.path.dirname(HERE))
    try:
        port = json.loads(sim.stdout.readline())["port"]
        if before_open is not None:
            before_open()
        link = open_link(port, baud)
        m = Master(link, BusParams.for_baud(baud, retries=2, link_latency=0.02))
        m.add_station(3, SlaveConfig(ident=0xFD01, cfg=bytes.fromhex("F3F1")))
        m.bring_up(3)
        try:
            yield m, port
        finally:
            link.close()
    finally:
        sim.terminate()
        sim.wait(10)
