"""pdrive's DP master against pyprofibus' DPM1: master CPU per Data_Exchange.

    pip install -e '.[bench]'          # pyprofibus (GPL): for this benchmark only, never imported
                                       # by profidrive_cli
    python benchmarks/bench_vs_pyprofibus.py [--n 20000] [--rounds 7] [--octets 4 12] [--general]

Both masters run in this process on two links:

  canned   after the start-up, every request is answered at once with the same prepared DL reply
           (the same octets for both masters): what is measured is the master alone - building the
           request, taking the reply, its state machine and counters.
  dummy    pyprofibus' own dummy slave (phy_dummy.CpPhyDummySlave, echoing the outputs inverted),
           behind pyprofibus' PHY interface for DPM1 and behind a pdrive Link for pdrive. Its own
           work (parsing the request, building the reply) is timed alone on the same request
           ("dummy slave alone") and taken off both masters' figures for the ratio.

The start-up (Slave_Diag, Set_Prm, Chk_Cfg, Slave_Diag) runs against the dummy slave for both
masters. CPU time is time.process_time() over --n exchanges; the rounds alternate pdrive and
pyprofibus (interleaved, so load on the machine hits both alike); the medians per exchange and
their ratio are printed.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from profidrive_cli.dp.poller import Master  # noqa: E402
from profidrive_cli.dp.station import SlaveConfig  # noqa: E402
from profidrive_cli.fdl import frames as F  # noqa: E402
from profidrive_cli.fdl.timing import BusParams  # noqa: E402
from profidrive_cli.link.base import Link  # noqa: E402

try:
    import pyprofibus
    from pyprofibus.dp_master import DpSlaveDesc, DpSlaveState
    from pyprofibus.phy_dummy import CpPhyDummySlave
except ImportError:                      # the optional `bench` extra is not installed
    pyprofibus = None

MASTER, STATION, BAUD = 2, 8, 1500000
CFG = {4: bytes.fromhex("F1"), 12: bytes.fromhex("F3F1")}     # 4 / 12 octets each way


def canned_reply(n: int) -> bytes:
    """The DL reply both masters get on the canned link: n input octets 0x11, 0x22, ..."""
    data = bytes((0x11 * (i % 15 + 1)) & 0xFF for i in range(n))
    return F.encode(F.Frame(F.SD2, MASTER, STATION, F.response_fc(F.DL), data))


if pyprofibus is not None:
    class BenchPhy(CpPhyDummySlave):
        """pyprofibus' dummy slave; `canned` set: every SRD answered with those octets instead."""

        def __init__(self, *a, **kw):
            super().__init__(*a, **kw)
            self.canned = None
            self.answer = None
            self.sends = 0

        def sendData(self, telegramData, srd):
            self.sends += 1
            if self.canned is not None:
                self.answer = self.canned if srd else None
                return
            super().sendData(telegramData, srd)

        def pollData(self, timeout=0.0):
            if self.canned is not None:
                a, self.answer = self.answer, None
                return a
            return super().pollData(timeout)

    class SlaveConf:
        """What DpSlaveDesc reads from pyprofibus' config file entry."""

        def __init__(self, n: int):
            self.gsd = None
            self.addr = STATION
            self.name = "bench"
            self.index = 0
            self.inputSize = self.outputSize = n
            self.diagPeriod = 0


class DummyLink(Link):
    """A pdrive Link onto a BenchPhy: write = an SRD sent to it, read = what it answered."""

    name = "pyprofibus-dummy"
    instant = True
    latency = 0.0

    def __init__(self, phy):
        self.phy = phy

    def write(self, data: bytes) -> None:
        self.last = data
        # pdrive sends SDN (no reply) only as Global_Control; everything else waits for a reply
        self.phy.sendData(data, srd=(data[0] == F.SC or (data[6 if data[0] == F.SD2 else 3] & 0x0F)
                                     not in (F.SDN_LOW, F.SDN_HIGH)))

    def read(self, deadline: float) -> bytes:
        r = self.phy.pollData(0.0)
        return bytes(r) if r is not None else b""

    def flush_input(self) -> None:
        while self.phy.pollData(0.0) is not None:
            pass

    def now(self) -> float:
        return time.monotonic()


def pdrive_setup(n: int, fast: bool = True):
    phy = BenchPhy(echoDX=True, echoDXSize=n)
    phy.setConfig(baudrate=BAUD)
    m = Master(DummyLink(phy), BusParams.for_baud(BAUD), MASTER)
    m.fast_dx = fast
    m.add_station(STATION, SlaveConfig(ident=0, cfg=CFG[n], wd_ms=None))
    m.bring_up(STATION, timeout=2.0)
    m.exchange(STATION, bytes(n))
    return m, phy


def pdrive_run(state, n_ex: int, out: bytes) -> None:
    m = state[0]
    ex = m.exchange
    for _ in range(n_ex):
        ex(STATION, out)


def pdrive_check(state) -> None:
    c = state[0].fdl.counters[STATION]
    assert state[0].stations[STATION].in_data_exchange, "pdrive left data exchange"
    assert c.retries == c.no_answer == c.illegal == 0, c


def pyp_setup(n: int):
    # DPM1 starts a station over when it has had no reply for 0.5 s in Data_Exchange; while the
    # other masters' rounds run (up to 0.5 s each on a loaded machine) it gets none, and would
    # then measure its start-up (or, on the canned link, never get back): the limit is lifted
    DpSlaveState.stateTimeLimits[DpSlaveState.STATE_DX] = 3600.0
    phy = BenchPhy(echoDX=True, echoDXSize=n)
    phy.setConfig(baudrate=BAUD)
    dpm = pyprofibus.DPM1(phy=phy, masterAddr=MASTER, debug=False)
    desc = DpSlaveDesc(SlaveConf(n))
    desc.setWatchdog(0)
    dpm.addSlave(desc)
    dpm.initialize()
    end = time.monotonic() + 2.0
    while not desc.isConnected():
        if time.monotonic() > end:
            raise SystemExit("pyprofibus DPM1 did not reach Data_Exchange with its dummy slave")
        dpm.run()
    pyp_run((dpm, desc, phy), 10, bytes(n))
    return dpm, desc, phy


def pyp_run(state, n_ex: int, out: bytes) -> None:
    dpm, desc, _ = state
    run, get, put = dpm.run, desc.getMasterInData, desc.setMasterOutData
    for _ in range(n_ex):
        put(out)
        for _ in range(100):
            run()
            if get() is not None:
                break
        else:
            raise SystemExit("pyprofibus DPM1 got no inputs in 100 run() calls: it left Data_Exchange")


def pyp_check(state) -> None:
    assert state[1].isConnected(), "pyprofibus left data exchange"


def slave_setup(n: int):
    """The dummy slave alone, given the Data_Exchange request pdrive sends (the same telegram as
    pyprofibus', FCB aside): what both masters' figures on the dummy link contain of its work."""
    m, phy = pdrive_setup(n)
    return m.link.last, phy


def slave_run(state, n_ex: int, out: bytes) -> None:
    req, phy = state
    send, poll = phy.sendData, phy.pollData
    for _ in range(n_ex):
        send(req, True)
        poll(0.0)


def measure(run, state, n_ex: int, out: bytes) -> float:
    """CPU seconds per exchange; exactly one request per exchange (no retry, no start-up)."""
    phy = state[-1]
    sends = phy.sends
    t = time.process_time()
    run(state, n_ex, out)
    cpu = time.process_time() - t
    if phy.sends - sends != n_ex:
        raise SystemExit(f"{phy.sends - sends} requests for {n_ex} exchanges: not a clean round")
    return cpu / n_ex


PDRIVE, GENERAL, PYP, SLAVE = ("pdrive", "pdrive general path", "pyprofibus DPM1",
                               "dummy slave alone")


def bench(n: int, link: str, n_ex: int, rounds: int, general: bool) -> dict:
    who = {PDRIVE: (pdrive_setup, pdrive_run, pdrive_check),
           PYP: (pyp_setup, pyp_run, pyp_check)}
    if general:
        who[GENERAL] = (lambda n: pdrive_setup(n, fast=False), pdrive_run, pdrive_check)
    if link == "dummy":
        who[SLAVE] = (slave_setup, slave_run, lambda state: None)
    states = {}
    for name, (setup, _, _) in who.items():
        states[name] = setup(n)
        if link == "canned":
            states[name][-1].canned = canned_reply(n)
    out = bytes(range(1, n + 1))
    res = {name: [] for name in who}
    for r in range(rounds):
        order = list(who) if r % 2 == 0 else list(reversed(who))   # interleaved, both directions
        for name in order:
            _, run, check = who[name]
            res[name].append(measure(run, states[name], n_ex, out))
            check(states[name])
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=20000, help="exchanges per round (default 20000)")
    ap.add_argument("--rounds", type=int, default=7, help="rounds per master (default 7)")
    ap.add_argument("--octets", type=int, nargs="+", default=[4, 12], choices=sorted(CFG))
    ap.add_argument("--link", nargs="+", default=["canned", "dummy"], choices=["canned", "dummy"])
    ap.add_argument("--general", action="store_true",
                    help="also pdrive with the fast path off (Master.fast_dx = False)")
    a = ap.parse_args(argv)
    if pyprofibus is None:
        print("skipped: pyprofibus is not installed (pip install -e '.[bench]'; it is GPL, an "
              "optional benchmark dependency only)")
        return 0
    from importlib.metadata import version
    print(f"pyprofibus {version('pyprofibus')}, Python {sys.version.split()[0]}; "
          f"{a.rounds} interleaved rounds of {a.n} Data_Exchanges per master; CPU per exchange "
          f"(time.process_time), median [min-max] of the rounds")
    for link in a.link:
        for n in a.octets:
            res = bench(n, link, a.n, a.rounds, a.general)
            med = {name: statistics.median(rows) * 1e6 for name, rows in res.items()}
            for name, rows in res.items():
                print(f"  {link:6} {n:2} octets  {name:20} {med[name]:6.2f} µs "
                      f"[{min(rows) * 1e6:.2f}-{max(rows) * 1e6:.2f}]")
            slave = med.get(SLAVE, 0.0)
            ratio = (med[PYP] - slave) / (med[PDRIVE] - slave)
            print(f"  {link:6} {n:2} octets  pyprofibus / pdrive = {ratio:.1f}x"
                  + (" (master CPU: the dummy slave's own work taken off both)" if slave else ""))
            if GENERAL in med:
                print(f"  {link:6} {n:2} octets  pdrive general path / fast path = "
                      f"{(med[GENERAL] - slave) / (med[PDRIVE] - slave):.1f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
