"""The Lua dissector (wireshark/pdrive.lua) under tshark on a saturated 1.5 Mbit/s line: telegrams
per second and the ratio to the line's own telegram rate.

    python benchmarks/bench_dissector.py [--seconds 10] [--repeat 3] [--lua FILE] [--modes summary,fields,verbose]

The capture (a pcap, link type 147 as `pdrive sniff --pcap` writes it) is built with pdrive's own FDL
encoder (fdl/frames.py): the default simulated plant in Data_Exchange, each cycle polling stations
3 fuji-g1, 4 fuji-pdp3, 5 toyo, 6 moeller (PPO1, 12 octets each way) and 7 yaskawa (extended1, 32
octets each way), back to back. The data change as on a running line: a ramping setpoint and the
actual value following it every third cycle (two thirds of the areas repeat the station's previous
one, as measured on real captures in issue 27), a PKW parameter read on one station every 50 cycles.
Each telegram is stamped where it ends on the wire.

The line rate, by hand from ../shared/spec/profibus-dp-reference.md: a character is 11 bits (§1);
at 1.5 Mbit/s a slave answers at the earliest after min TSDR = 11 bit times and the master sends its
next request after TID1 = 37 bit times (§4.1). A PPO1 Data_Exchange is SD2 with 12 DU octets:
4 + 3 + 12 + 2 = 21 octets each way; the yaskawa extended1 one 4 + 3 + 32 + 2 = 41. One cycle of the
five stations (10 telegrams) takes
    4 x (21 + 21) x 11 + (41 + 41) x 11 + 5 x (11 + 37) = 1848 + 902 + 240 = 2990 bit times,
    1 500 000 / 2990 = 501.7 cycles/s = 5017 telegrams/s.
The script computes the same sum over the telegrams it wrote and prints both.

What is timed: `tshark -n -X lua_script:pdrive.lua -r FILE` (the summary line per packet, i.e. the
Info column pdrive.lua fills: what a person watching a live capture reads; output to /dev/null)
against `tshark -n -r FILE` without the dissector on the same file in the same run (the reference:
tshark's own reading and printing). Best of --repeat runs each. Two rates are printed:
  - overall: telegrams / time with the dissector (what keeps up with a line, tshark included);
  - dissector: telegrams / (time with - time without) (the dissector's own cost).
The target (issue 27) is overall >= 1.0x. `--modes` adds `-T fields` (six pdrive fields, the tests'
way) and `-V` (the full tree as text), which build the protocol tree; they are printed for
information. The dissector runs with the station table `pdrive wireshark install --station 3=fuji-g1
... 7=yaskawa` writes (vendor layouts), in a temporary HOME (no personal plugins).
"""

from __future__ import annotations

import argparse
import os
import shutil
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from profidrive_cli.dp.capture import LINKTYPE_USER0, PcapWriter  # noqa: E402
from profidrive_cli.fdl import frames as F  # noqa: E402

BAUD = 1_500_000
CHAR_BITS = 11          # reference §1: 1 start, 8 data, parity, stop
MIN_TSDR = 11           # reference §4.1, 1.5M row
TID1 = 37               # reference §4.1, 1.5M row: 35 + 2 TSET + TQUI
HAND_RATE = 1_500_000 / 2990 * 10          # the docstring's sum: 5017 telegrams/s
MASTER = 2
PLANT = ((3, "fuji-g1", 12), (4, "fuji-pdp3", 12), (5, "toyo", 12), (6, "moeller", 12), (7, "yaskawa", 32))
FIELDS = ("profibus.service", "profibus.sa", "profibus.da", "profibus.fcs.status", "profidrive.layout",
          "profidrive.control.set")


def _area(n: int, word0: int, word1: int, pkw: bytes) -> bytes:
    if n == 12:                                     # PPO1: PKW 8, STW/ZSW, HSW/HIW
        return pkw + struct.pack(">HH", word0, word1)
    body = struct.pack(">HH", word0, word1) + bytes(n - 4)    # yaskawa extended1: command + reference
    return body


def telegrams(seconds: float):
    """(time the telegram ends on the wire, octets), a saturated 1.5M line for `seconds`."""
    t_bit = 1.0 / BAUD
    t = 0.0
    cycle = 0
    while t < seconds:
        ramp = (cycle // 3) % 4096                  # changes every third cycle
        for addr, _, n in PLANT:
            pkw_req = pkw_res = bytes(8)
            if n == 12 and cycle % 50 == 0 and addr == 3 + (cycle // 50) % 4:
                pkw_req = struct.pack(">HHHH", 0x1000 | 3, 0, 0, 0)           # AK 1: read PNU 3
                pkw_res = struct.pack(">HHHH", 0x1000 | 3, 0, 0, 5000)        # AK 1: value 5000
            fcb = 0x20 if cycle % 2 else 0
            req = F.encode(F.Frame(F.SD2, addr, MASTER, 0x5D | fcb, _area(n, 0x047F, ramp * 4, pkw_req)))
            res = F.encode(F.Frame(F.SD2, MASTER, addr, 0x08, _area(n, 0x0237, ramp * 4, pkw_res)))
            t += (TID1 + len(req) * CHAR_BITS) * t_bit
            yield t, req
            t += (MIN_TSDR + len(res) * CHAR_BITS) * t_bit
            yield t, res
        cycle += 1


def write_capture(path: Path, seconds: float) -> tuple[int, float]:
    """Write the capture; (telegrams, their line time in seconds by the reference's rule)."""
    n, bits = 0, 0
    with open(path, "wb") as fh:
        w = PcapWriter(fh, LINKTYPE_USER0, 1_700_000_000.0)
        for t, raw in telegrams(seconds):
            w.write(t, raw)
            n += 1
            is_req = raw[6] & 0x40 if raw[0] == F.SD2 else 0
            bits += len(raw) * CHAR_BITS + (TID1 if is_req else MIN_TSDR)
    return n, bits / BAUD


def _run(cmd: list[str], env: dict[str, str]) -> float:
    t0 = time.perf_counter()
    p = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)
    dt = time.perf_counter() - t0
    if p.returncode != 0 or "Lua Error" in p.stderr:
        raise SystemExit(f"bench_dissector: {' '.join(cmd)} failed: {p.stderr.strip()[:400]}")
    return dt


def best(cmd: list[str], env: dict[str, str], repeat: int) -> float:
    return min(_run(cmd, env) for _ in range(repeat))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0, help="line time the capture holds")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--lua", default=str(HERE.parent / "wireshark" / "pdrive.lua"),
                    help="the dissector to time (default: the checkout's)")
    ap.add_argument("--modes", default="summary", help="summary, fields, verbose (comma separated)")
    ap.add_argument("--no-table", action="store_true", help="no station table: PPO by length only")
    ap.add_argument("--keep", default=None, metavar="FILE", help="also keep the capture here")
    a = ap.parse_args(argv)
    exe = shutil.which("tshark")
    if exe is None:
        print("bench_dissector: tshark not found", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        tdir = Path(tmp)
        pcap = tdir / "saturated-1.5M.pcap"
        n, line_s = write_capture(pcap, a.seconds)
        if a.keep:
            shutil.copyfile(pcap, a.keep)
        lua = tdir / "pdrive.lua"
        shutil.copyfile(a.lua, lua)
        if not a.no_table:
            from profidrive_cli.bustools.wireshark import STATION_TABLE, parse_station, render_station_table
            specs = [parse_station(f"{addr}={name}") for addr, name, _ in PLANT]
            (tdir / STATION_TABLE).write_text(render_station_table(specs), "utf-8")
        env = {**os.environ, "HOME": tmp}
        rate = n / line_s
        print(f"capture: {n} telegrams = {line_s:.3f} s of a saturated 1.5 Mbit/s line "
              f"(line rate {rate:,.0f} telegrams/s; by hand {HAND_RATE:,.0f}); {pcap.stat().st_size:,} octets")
        ref = best([exe, "-n", "-r", str(pcap)], env, a.repeat)
        print(f"tshark -n -r FILE (no dissector, reference): {ref:.2f} s")
        extra = {"summary": [], "fields": ["-T", "fields"] + [x for f in FIELDS for x in ("-e", f)],
                 "verbose": ["-V"]}
        for mode in a.modes.split(","):
            if mode not in extra:
                print(f"bench_dissector: unknown mode {mode!r} (summary, fields, verbose)", file=sys.stderr)
                return 2
            cmd = [exe, "-n", "-X", f"lua_script:{lua}", "-r", str(pcap), *extra[mode]]
            dt = best(cmd, env, a.repeat)
            own = dt - ref
            print(f"{mode:8s} with pdrive.lua: {dt:.2f} s; overall {n / dt:,.0f} telegrams/s = "
                  f"{n / dt / rate:.2f}x the line; dissector alone {n / own if own > 0 else float('inf'):,.0f} "
                  f"telegrams/s = {(n / own / rate) if own > 0 else float('inf'):.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
