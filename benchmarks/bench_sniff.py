"""`pdrive sniff --from-file` against a saturated 12 Mbit/s line: every mode's decoding rate as
telegrams/s and as a ratio to the line's telegram rate, on a capture whose drive values change every
cycle and on the built-in PLC's own, and its peak memory at two capture sizes.

    python benchmarks/bench_sniff.py [--seconds 10] [--repeat 4] [--runs 3] [--keep FILE]
                                     [--against DIR] [--modes text,json,station,live,ring]
                                     [--values changing,realistic] [--sc-mib 16]

The realistic capture: the built-in PLC (sim/plc.py, what `pdrive sim --plc` runs) on the default
five-drive plant at 12 Mbit/s with the wire's timing, unpaced (cycle_s 0): bring-up (Set_Prm,
Chk_Cfg, Slave_Diag), then Data_Exchange with every drive while each runs its script through its
family's codec (start, ramp, hold with PKW / MEMOBUS reads of the max frequency, acceleration time
and a read-only parameter, stop, pause), the release at the end; `--seconds` of it (900 to 8 400
telegrams per second of real time, by the machine's load), kept in `--keep FILE` and reused when
that file exists. Its requests repeat cycle after cycle and its replies change while a drive ramps:
kind to the per-octets caches of the decoders.

The changing capture (changing()): the same telegrams, but in every Data_Exchange request the
drive's reference word and in every reply its actual-frequency word carry the station's count of
Data_Exchange telegrams in that direction added (mod 2^16; SPEED_WORD: where each family's layout
has them), the FCS made anew: every area differs from the station's previous one and none repeats
within 65,536 cycles, while control / status words and the PKW / MEMOBUS parameter areas stay as
the PLC sent them (valid telegrams, fully decoded: `sniff --station` shows a reference and an
actual that move every cycle). The worst case for the caches.

The line rate (bus reference ../shared/spec/profibus-dp-reference.md): a telegram of k octets
lasts 11·k bit (§1 "character | 11 bits"); a saturated line leaves only the idle times a master and
its slaves must keep (§4.1, row 12M): TID1 = 35 + 2·TSET + TQUI = 35 + 32 + 9 = 76 bit before
every request and token, min TSDR = 11 bit before every reply and short acknowledge. So the capture
lasts sum(11·k + idle) / 12e6 s on the line, and its rate in telegrams/s is its count over that.
E.g. a Data_Exchange with a 12-octet PPO1 area each way (two SD2 telegrams of 15 + 6 = 21 octets):
231 + 11 + 231 + 76 = 549 bit per cycle, 43 700 telegrams/s.

Each mode runs as `python -m profidrive_cli sniff --from-file FILE [mode options] > /dev/null`, in
a process of its own (the CLI's whole path: click, reading, decoding, formatting, writing); `ring`
is the black-box recorder (--ring 30) with the triggers of docs/commands.md's systemd unit, lost(*)
and fault(*), over all five drives (--station): they never fire on these captures, so it measures
the recorder's steady path (the live list with its notes, the drives' words, the ring). The rate:
the CPU time (user + system, from wait4) of the large capture (`--repeat` copies back to back, each
a new start-up) less that of the same command on an empty file (start-up), best of `--runs`; CPU
time rather than wall time because the machine is shared. Peak RSS is the process's VmHWM at its
exit (Linux; ru_maxrss would count the pages it had from this process until its exec), for the
capture and for its `--repeat` copies (flat: sniff keeps no telegram; the ring keeps up to 250,000).
`--against DIR` runs the same commands from another checkout (e.g. `git archive main | tar -x -C
DIR`) for a before/after in one run. `--sc-mib N` adds the worst case the size limit accepts: a file
of N MiB of 0xE5 (one short acknowledge per octet) in the default text mode (this checkout only:
before issue 27 16 MiB took about 40 minutes). The machine: the CPU time of `import click` in a
fresh interpreter, measured in the same run.
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
RING_OUT = "{ring_out}"      # (replaced by a directory of the run)
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


def capture_file(d: str, name: str, raw: bytes, repeat: int) -> tuple[str, str, int, float]:
    """(the capture's path, its --repeat copies' path, telegrams, seconds on the line)."""
    small, large = os.path.join(d, name + ".raw"), os.path.join(d, name + f"-x{repeat}.raw")
    with open(small, "wb") as fh:
        fh.write(raw)
    with open(large, "wb") as fh:
        fh.write(raw * repeat)
    n, line_s, kinds = line_figures(raw)
    print(f"{name} capture: {len(raw):,} octets, {n:,} telegrams "
          f"({', '.join(f'{k} {v:,}' for k, v in sorted(kinds.items()))}); on a saturated 12M line "
          f"{line_s:.3f} s = {n / line_s:,.0f} telegrams/s; large: {repeat} copies", flush=True)
    return small, large, n, line_s


def best_cpu(root: str, path: str, extra: list[str], runs: int, out_dir: str) -> tuple[float, int]:
    """(the least CPU time of `runs` runs, the exit code of the last)."""
    best, rc = float("inf"), 0
    for _ in range(runs):
        cpu, _, _, rc = run_one(root, path, _args(extra, out_dir))
        best = min(best, cpu)
        _empty(out_dir)
    return best, rc


def _args(extra: list[str], out_dir: str) -> list[str]:
    return [out_dir if a == RING_OUT else a for a in extra]


def _empty(out_dir: str) -> None:
    for name in os.listdir(out_dir):
        os.unlink(os.path.join(out_dir, name))


def click_cpu(runs: int) -> float:
    """The least CPU time of `python -c "import click"` (the machine's speed, this run)."""
    best = float("inf")
    for _ in range(runs):
        p = subprocess.Popen([sys.executable, "-c", "import click"])
        _, _, ru = os.wait4(p.pid, 0)
        best = min(best, ru.ru_utime + ru.ru_stime)
    return best


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=10.0, help="seconds of PLC traffic to record")
    ap.add_argument("--repeat", type=int, default=4, help="copies in the large capture")
    ap.add_argument("--runs", type=int, default=3, help="runs per figure (the least CPU counts)")
    ap.add_argument("--keep", metavar="FILE", help="the recorded capture (reused if it exists)")
    ap.add_argument("--against", metavar="DIR", help="another checkout, run the same way")
    ap.add_argument("--modes", default=",".join(MODES))
    ap.add_argument("--values", default="changing,realistic",
                    help="the captures: changing (values change every cycle), realistic (the PLC's)")
    ap.add_argument("--sc-mib", type=float, default=0.0,
                    help="also N MiB of 0xE5 octets in text mode (0: not)")
    a = ap.parse_args()
    values = a.values.split(",")
    if not values or set(values) - {"changing", "realistic"}:
        ap.error("--values: changing, realistic or both")
    if a.keep and os.path.exists(a.keep):
        with open(a.keep, "rb") as fh:
            raw = fh.read()
    else:
        print(f"recording {a.seconds:g} s of the PLC at 12 Mbit/s ...", file=sys.stderr)
        raw = record(a.seconds)
        if a.keep:
            with open(a.keep, "wb") as fh:
                fh.write(raw)
    trees = [("", HERE)] + ([(os.path.basename(os.path.abspath(a.against)), os.path.abspath(a.against))]
                            if a.against else [])
    print(f"the machine: `import click` takes {click_cpu(a.runs) * 1000:.0f} ms of CPU; "
          f"load {os.getloadavg()[0]:.2f}", flush=True)
    with tempfile.TemporaryDirectory(prefix="bench_sniff") as d:
        out_dir = os.path.join(d, "ring")
        os.mkdir(out_dir)
        caps = {v: capture_file(d, v, changing(raw) if v == "changing" else raw, a.repeat)
                for v in values}
        empty = os.path.join(d, "empty.raw")
        open(empty, "wb").close()
        head = "".join(f"{v + ' x line':>18}{'tel/s':>10}" for v in values)
        print(f"{'mode':<9}{'tree':<12}{head}{'RSS MB':>8}{'RSS MB x' + str(a.repeat):>12}", flush=True)
        for mode in a.modes.split(","):
            extra = MODES[mode]
            for tag, root in trees:
                base, _ = best_cpu(root, empty, extra, a.runs, out_dir)
                cells, bad = "", ""
                for v in values:
                    small, large, n, line_s = caps[v]
                    cpu, rc = best_cpu(root, large, extra, a.runs, out_dir)
                    rate = n * a.repeat / max(cpu - base, 1e-9)
                    cells += (f"{rate * line_s / n:>18.2f}{rate:>10,.0f}" if rc == 0 else
                              f"{'exit ' + str(rc):>18}{'-':>10}")
                small, large, _, _ = caps[values[0]]
                _, _, rss, rc_s = run_one(root, small, _args(extra, out_dir))
                _empty(out_dir)
                _, _, rss_l, _ = run_one(root, large, _args(extra, out_dir))
                _empty(out_dir)
                bad += "" if rc_s == 0 else f"  exit {rc_s}"
                print(f"{mode:<9}{tag or 'this':<12}{cells}{rss:>8.0f}{rss_l:>12.0f}{bad}", flush=True)
        if a.sc_mib:
            sc = os.path.join(d, "sc.raw")
            with open(sc, "wb") as fh:
                fh.write(b"\xE5" * int(a.sc_mib * 1024 * 1024))
            cpu, wall, rss, rc = run_one(HERE, sc, [])
            print(f"{a.sc_mib:g} MiB of 0xE5, text: cpu {cpu:.1f} s, wall {wall:.1f} s, peak RSS "
                  f"{rss:.0f} MB, exit {rc}", flush=True)
    print(f"load {os.getloadavg()[0]:.2f} at the end", flush=True)


if __name__ == "__main__":
    main()
