"""`pdrive sniff --from-file` against a saturated 12 Mbit/s line: every mode's decoding rate as
telegrams/s and as a ratio to the line's telegram rate, and its peak memory at two capture sizes.

    python benchmarks/bench_sniff.py [--seconds 10] [--repeat 4] [--keep FILE] [--against DIR]
                                     [--modes text,json,station,live] [--sc-mib 16]

The capture: the built-in PLC (sim/plc.py, what `pdrive sim --plc` runs) on the default five-drive
plant at 12 Mbit/s with the wire's timing, unpaced (cycle_s 0): bring-up (Set_Prm, Chk_Cfg,
Slave_Diag), then Data_Exchange with every drive while each runs its script through its family's
codec (start, ramp, hold with PKW / MEMOBUS reads of the max frequency, acceleration time and a
read-only parameter, stop, pause), the release at the end; `--seconds` of it (4 700 to 8 400
telegrams per second of real time here, by the machine's load), kept in `--keep FILE` and reused
when that file exists. The small size is that capture, the large one `--repeat` copies of it back
to back (each copy a new start-up).

The line rate (bus reference ../shared/spec/profibus-dp-reference.md): a telegram of k octets
lasts 11·k bit (§1 "character | 11 bits"); a saturated line leaves only the idle times a master and
its slaves must keep (§4.1, row 12M): TID1 = 35 + 2·TSET + TQUI = 35 + 32 + 9 = 76 bit before
every request and token, min TSDR = 11 bit before every reply and short acknowledge. So the capture
lasts sum(11·k + idle) / 12e6 s on the line, and its rate in telegrams/s is its count over that.
E.g. a Data_Exchange with a 12-octet PPO1 area each way (two SD2 telegrams of 15 + 6 = 21 octets):
231 + 11 + 231 + 76 = 549 bit per cycle, 43 700 telegrams/s.

Each mode runs as `python -m profidrive_cli sniff --from-file FILE [mode options] > /dev/null`, in
a process of its own (the CLI's whole path: click, reading, decoding, formatting, writing). Its CPU
time (user + system, from wait4) less that of the same command on an empty file (start-up) gives
the decoding rate; CPU time rather than wall time because the machine is shared (the wall time is
printed too). Peak RSS is the process's VmHWM at its exit (Linux; ru_maxrss would count the pages
it had from this process until its exec). `--against DIR` runs the same commands from
another checkout (e.g. `git archive main | tar -x -C DIR`) for a before/after in one run.
`--sc-mib N` adds the worst case the size limit accepts: a file of N MiB of 0xE5 (one short
acknowledge per octet) in the default text mode (this checkout only: before issue 27 16 MiB took
about 40 minutes).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

HERE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, HERE)

BAUD = 12_000_000
#: bus reference §4.1, row 12M: TID1 = 35 + 2·TSET + TQUI (TSET 16, TQUI 9) and min TSDR, in bit
TID1_BITS = 35 + 2 * 16 + 9
MIN_TSDR_BITS = 11
#: bus reference §1: 1 start, 8 data, 1 parity, 1 stop
CHAR_BITS = 11

STATIONS = ["3=fuji-g1", "4=fuji-pdp3", "5=toyo", "6=moeller", "7=yaskawa"]
_STATION_ARGS = [a for s in STATIONS for a in ("--station", s)]
#: --ring's pcaps go to this directory (made per run); its triggers are the docs' systemd unit's
#: (docs/commands.md), with every drive watched: a station lost, a drive's fault bit
RING_OUT = "{ring_out}"
MODES = {
    "text": [],
    "json": ["--json"],
    "station": _STATION_ARGS,
    "live": ["--live"],
    "ring": ["--ring", "30", "--trigger", "lost(*),fault(*)", *_STATION_ARGS, "--out", RING_OUT],
}

#: where the reference word (request) and the actual-frequency word (response) of each drive of the
#: default plant sit in its Data_Exchange area: (request offset, response offset, byte order).
#: PPO1 (fuji-g1, fuji-pdp3, moeller): PKW 0..7, STW/ZSW 8..9, HSW/HIW 10..11, big-endian
#: (PROFIdrive); Toyo PBUS66-Z PPO1: the same places, little-endian; Yaskawa SI-P1 extended1
#: (../shared/spec/yaskawa-profibus-dp.md §2): out word 1 the reference, in word 5 the output
#: frequency, big-endian
SPEED_WORD = {3: (10, 10, "big"), 4: (10, 10, "big"), 5: (10, 10, "little"), 6: (10, 10, "big"),
              7: (2, 10, "big")}


def record(seconds: float) -> bytes:
    """The PLC's traffic on the five-drive plant at 12 Mbit/s for `seconds` of real time."""
    from profidrive_cli.sim.plant import build_bus
    from profidrive_cli.sim.plc import Plc
    bus = build_bus(f"sim://?timing=wire&baud={BAUD}", now=time.monotonic())
    chunks: list[bytes] = []
    plc = Plc(bus, chunks.append, cycle_s=0.0)
    end = time.monotonic() + seconds
    plc.run(lambda: time.monotonic() > end)
    return b"".join(chunks)


def changing(raw: bytes) -> bytes:
    """The capture with values that change every cycle: in each Data_Exchange request to a drive of
    SPEED_WORD its reference word, in each reply its actual word, plus the number of that station's
    Data_Exchange telegrams so far in that direction (mod 2^16), the FCS made anew; every other
    octet (control and status words, PKW / parameter areas, the other telegrams) as it was. So
    every area differs from the station's previous one and none repeats within 65,536 cycles."""
    from profidrive_cli.bustools.passive import is_data_exchange
    from profidrive_cli.dp.capture import Capture
    from profidrive_cli.fdl import frames as F
    out: list[bytes] = []
    count: dict[tuple[int, bool], int] = {}
    cap = Capture()
    for i in range(0, len(raw), 1 << 16):
        for c in cap.feed(raw[i:i + (1 << 16)], 0.0, hold=3):
            out.append(_changed(c, count, is_data_exchange, F))
    for c in cap.feed(b"", 0.0):
        out.append(_changed(c, count, is_data_exchange, F))
    if len(cap.rx):
        out.append(bytes(cap.rx.buf))
    return b"".join(out)


def _changed(c: Any, count: dict[tuple[int, bool], int], is_dx: Any, F: Any) -> bytes:
    f = c.frame
    if f is None or not is_dx(f) or c.raw[0] != F.SD2:
        return bytes(c.raw)
    station = f.da if f.is_request else f.sa
    where = SPEED_WORD.get(station)
    if where is None:
        return bytes(c.raw)
    off = where[0] if f.is_request else where[1]
    order = where[2]
    key = (station, f.is_request)
    n = count[key] = count.get(key, 0) + 1
    raw = bytearray(c.raw)
    at = 7 + off                             # SD2 LE LEr SD2 DA SA FC, then the area (no SAPs)
    word = (int.from_bytes(raw[at:at + 2], order) + n) & 0xFFFF
    raw[at:at + 2] = word.to_bytes(2, order)
    raw[-2] = F.fcs(raw[4:-2])
    return bytes(raw)


def line_figures(raw: bytes) -> tuple[int, float, dict[str, int]]:
    """(telegrams, seconds on a saturated 12M line, telegrams by kind) of a capture."""
    from profidrive_cli.dp.capture import Capture
    from profidrive_cli.fdl import frames as F
    bits = 0
    n = 0
    kinds: dict[str, int] = {}
    cap = Capture()
    for i in range(0, len(raw), 1 << 16):
        for c in cap.feed(raw[i:i + (1 << 16)], 0.0):
            n += 1
            f = c.frame
            if f is None:
                kind = "error"
            elif f.sd == F.SD4:
                kind = "token"
            elif f.sd == F.SC:
                kind = "short ack"
            elif f.is_request:
                kind = "Data_Exchange request" if f.dsap is None else "SAP request"
            else:
                kind = "Data_Exchange reply" if f.dsap is None and f.data else "other reply"
            kinds[kind] = kinds.get(kind, 0) + 1
            idle = TID1_BITS if kind in ("token", "Data_Exchange request", "SAP request") \
                else MIN_TSDR_BITS
            bits += CHAR_BITS * len(c.raw) + idle
    return n, bits / BAUD, kinds


#: runs `pdrive ARGS` and writes its peak RSS to OUT (benchmarks/peak_rss.py)
PEAK_RSS = str(Path(__file__).resolve().parents[1] / "benchmarks" / "peak_rss.py")


def run_one(root: str, path: str, extra: list[str]) -> tuple[float, float, float, int]:
    """(cpu s, wall s, peak RSS MB, exit code) of `pdrive sniff --from-file path extra` from `root`."""
    env = dict(os.environ)
    env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    with tempfile.NamedTemporaryFile("r", suffix=".peak") as peak:
        cmd = [sys.executable, PEAK_RSS, peak.name, "sniff", "--from-file", path, *extra]
        t = time.perf_counter()
        p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env,
                             cwd=root)
        _, status, ru = os.wait4(p.pid, 0)
        wall = time.perf_counter() - t
        p.returncode = os.waitstatus_to_exitcode(status)
        kib = peak.read().strip()
    return ru.ru_utime + ru.ru_stime, wall, int(kib or 0) / 1024, p.returncode


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=10.0, help="seconds of PLC traffic to record")
    ap.add_argument("--repeat", type=int, default=4, help="copies in the large capture")
    ap.add_argument("--keep", metavar="FILE", help="the recorded capture (reused if it exists)")
    ap.add_argument("--against", metavar="DIR", help="another checkout, run the same way")
    ap.add_argument("--modes", default=",".join(MODES))
    ap.add_argument("--sc-mib", type=float, default=0.0,
                    help="also N MiB of 0xE5 octets in text mode (0: not)")
    a = ap.parse_args()
    if a.keep and os.path.exists(a.keep):
        with open(a.keep, "rb") as fh:
            raw = fh.read()
    else:
        print(f"recording {a.seconds:g} s of the PLC at 12 Mbit/s ...", file=sys.stderr)
        raw = record(a.seconds)
        if a.keep:
            with open(a.keep, "wb") as fh:
                fh.write(raw)
    n, line_s, kinds = line_figures(raw)
    line_rate = n / line_s
    print(f"capture: {len(raw):,} octets, {n:,} telegrams "
          f"({', '.join(f'{k} {v:,}' for k, v in sorted(kinds.items()))}); on a saturated 12M line "
          f"{line_s:.3f} s = {line_rate:,.0f} telegrams/s; large: {a.repeat} copies")
    trees = [("", HERE)] + ([(os.path.basename(os.path.abspath(a.against)), os.path.abspath(a.against))]
                            if a.against else [])
    with tempfile.TemporaryDirectory(prefix="bench_sniff") as d:
        small, large, empty = (os.path.join(d, x) for x in ("small.raw", "large.raw", "empty.raw"))
        with open(small, "wb") as fh:
            fh.write(raw)
        with open(large, "wb") as fh:
            fh.write(raw * a.repeat)
        open(empty, "wb").close()
        print(f"{'mode':<9}{'tree':<12}{'telegrams/s':>13}{'x line':>8}{'cpu s':>8}{'wall s':>8}"
              f"{'RSS MB':>8}{'RSS MB x' + str(a.repeat):>12}")
        for mode in a.modes.split(","):
            extra = MODES[mode]
            for tag, root in trees:
                base, _, _, _ = run_one(root, empty, extra)
                cpu, wall, rss, rc = run_one(root, small, extra)
                _, _, rss_l, rc_l = run_one(root, large, extra)
                rate = n / max(cpu - base, 1e-9)
                bad = "" if rc == rc_l == 0 else f"  exit {rc}/{rc_l}"
                print(f"{mode:<9}{tag or 'this':<12}{rate:>13,.0f}{rate / line_rate:>8.2f}"
                      f"{cpu:>8.2f}{wall:>8.2f}{rss:>8.0f}{rss_l:>12.0f}{bad}", flush=True)
        if a.sc_mib:
            sc = os.path.join(d, "sc.raw")
            with open(sc, "wb") as fh:
                fh.write(b"\xE5" * int(a.sc_mib * 1024 * 1024))
            cpu, wall, rss, rc = run_one(HERE, sc, [])
            print(f"{a.sc_mib:g} MiB of 0xE5, text: cpu {cpu:.1f} s, wall {wall:.1f} s, peak RSS "
                  f"{rss:.0f} MB, exit {rc}", flush=True)


if __name__ == "__main__":
    main()
