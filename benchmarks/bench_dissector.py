"""The Lua dissector (wireshark/pdrive.lua) under tshark on a saturated 1.5 Mbit/s line: telegrams
per second and the ratio to the line's own telegram rate, on two captures.

    python benchmarks/bench_dissector.py [--seconds 10] [--repeat 3] [--lua FILE]
        [--values changing,realistic] [--modes summary,fields,verbose]

The captures (pcap, link type 147 as `pdrive sniff --pcap` writes them) are built with pdrive's own FDL
encoder (fdl/frames.py): the default simulated plant in Data_Exchange, each cycle polling stations
3 fuji-g1, 4 fuji-pdp3, 5 toyo, 6 moeller (PPO1, 12 octets each way) and 7 yaskawa (extended1, 32
octets each way), back to back, a PKW parameter read on one station every 50 cycles. Each telegram
is stamped where it ends on the wire. The two captures differ in their process data:
  - changing (the worst case: no area repeats): every request and response area differs from the
    station's previous one in every cycle -- the setpoint ramps one step per cycle, the actual value
    follows one cycle behind, the status words move through valid operation states (at setpoint,
    warning, f reached) and the yaskawa's feedback, output frequency and current follow the ramp;
  - realistic (as on a running line, issue 27): a ramping setpoint and the actual value following it
    every third cycle (two thirds of the areas repeat the station's previous one, as measured on real
    captures), status words steady.

The line rate, by hand from ../shared/spec/profibus-dp-reference.md: a character is 11 bits (§1);
at 1.5 Mbit/s a slave answers at the earliest after min TSDR = 11 bit times and the master sends its
next request after TID1 = 37 bit times (§4.1). A PPO1 Data_Exchange is SD2 with 12 DU octets:
4 + 3 + 12 + 2 = 21 octets each way; the yaskawa extended1 one 4 + 3 + 32 + 2 = 41. One cycle of the
five stations (10 telegrams) takes
    4 x (21 + 21) x 11 + (41 + 41) x 11 + 5 x (11 + 37) = 1848 + 902 + 240 = 2990 bit times,
    1 500 000 / 2990 = 501.7 cycles/s = 5017 telegrams/s.
The script computes the same sum over the telegrams it wrote and prints both (both captures have
the same telegram lengths, so the same rate).

What is timed, as CPU time (user + sys of the tshark process; the machine may be shared), best of
--repeat runs each, per capture:
  - the reference: `tshark -n -r FILE` without the dissector (tshark's own reading and printing);
  - summary: `tshark -n -X lua_script:pdrive.lua -r FILE` (the summary line per packet, i.e. the Info
    column pdrive.lua fills: what a person watching a live capture reads, Wireshark's packet list);
  - fields: the same with `-T fields` and six pdrive fields (the tests' way: builds the tree);
  - verbose: the same with `-V` (the full tree as text).
Two rates per mode:
  - overall: telegrams / CPU time with the dissector (what keeps up with a line, tshark included);
  - dissector: telegrams / (time with - reference time) (the dissector's own cost).
The target (issue 38) is overall >= 1.5x the line in every mode on the changing capture. Output goes
to /dev/null. The dissector runs with the station table `pdrive wireshark install --station
3=fuji-g1 ... 7=yaskawa` writes (vendor layouts), in a temporary HOME (no personal plugins).
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
VALUES = ("changing", "realistic")


# the changing capture's status words, valid in operation: PROFIdrive ZSW S4 operation with
# control requested (0x0237), + at setpoint (bit 8), + warning (bit 7), + f reached (bit 10);
# the yaskawa's status: running, ready, remote (0x0421), + frequency agree (bit 4)
ZSW_CHANGING = (0x0237, 0x0337, 0x02B7, 0x0737)
YASKAWA_STATUS = (0x0421, 0x0431)
LITTLE_ENDIAN = ("toyo",)               # the toyo's PPO words are little endian (its profile)


def _area(n: int, word0: int, word1: int, pkw: bytes, order: str = ">") -> bytes:
    if n == 12:                                     # PPO1: PKW 8, STW/ZSW, HSW/HIW
        return pkw + struct.pack(order + "HH", word0, word1)
    body = struct.pack(">HH", word0, word1) + bytes(n - 4)    # yaskawa extended1: command + reference
    return body


def _yaskawa_response(status: int, actual: int, setpoint: int, current: int) -> bytes:
    """extended1 inputs: status, speed feedback, torque reference, PG count, frequency reference,
    output frequency, output current, analog in 1, then 16 octets of parameter access."""
    return struct.pack(">8H", status, actual, 0, 0, setpoint, actual, current, 0) + bytes(16)


def telegrams(seconds: float, values: str = "realistic"):
    """(time the telegram ends on the wire, octets), a saturated 1.5M line for `seconds`; `values`
    "realistic" (areas repeat two cycles in three) or "changing" (every area differs every cycle)."""
    if values not in VALUES:
        raise ValueError(f"values {values!r}: one of {', '.join(VALUES)}")
    changing = values == "changing"
    t_bit = 1.0 / BAUD
    t = 0.0
    cycle = 0
    while t < seconds:
        if changing:
            setpoint = (cycle % 4096) * 4                   # one step per cycle, 0 .. 16380 (~100 %)
            actual = ((cycle + 4095) % 4096) * 4            # the previous cycle's setpoint
            zsw = ZSW_CHANGING[(cycle // 5) % 4]
        else:
            setpoint = actual = ((cycle // 3) % 4096) * 4   # changes every third cycle
            zsw = 0x0237
        for addr, name, n in PLANT:
            # the changing capture writes each drive's words in its own order (toyo: little endian)
            order = "<" if changing and name in LITTLE_ENDIAN else ">"
            pkw_req = pkw_res = bytes(8)
            if n == 12 and cycle % 50 == 0 and addr == 3 + (cycle // 50) % 4:
                pkw_req = struct.pack(order + "HHHH", 0x1000 | 3, 0, 0, 0)      # AK 1: read PNU 3
                pkw_res = struct.pack(order + "HHHH", 0x1000 | 3, 0, 0, 5000)   # AK 1: value 5000
            fcb = 0x20 if cycle % 2 else 0
            if n == 12:
                out = _area(n, 0x047F, setpoint, pkw_req, order)
                inp = _area(n, zsw, actual, pkw_res, order)
            elif changing:
                out = _area(n, 0x0001, setpoint, pkw_req)                     # forward run
                inp = _yaskawa_response(YASKAWA_STATUS[(cycle // 5) % 2], actual, setpoint,
                                        1000 + cycle % 97)
            else:
                out, inp = _area(n, 0x047F, setpoint, pkw_req), _area(n, 0x0237, actual, pkw_res)
            req = F.encode(F.Frame(F.SD2, addr, MASTER, 0x5D | fcb, out))
            res = F.encode(F.Frame(F.SD2, MASTER, addr, 0x08, inp))
            t += (TID1 + len(req) * CHAR_BITS) * t_bit
            yield t, req
            t += (MIN_TSDR + len(res) * CHAR_BITS) * t_bit
            yield t, res
        cycle += 1


def write_capture(path: Path, seconds: float, values: str = "realistic") -> tuple[int, float]:
    """Write the capture; (telegrams, their line time in seconds by the reference's rule)."""
    n, bits = 0, 0
    with open(path, "wb") as fh:
        w = PcapWriter(fh, LINKTYPE_USER0, 1_700_000_000.0)
        for t, raw in telegrams(seconds, values):
            w.write(t, raw)
            n += 1
            is_req = raw[6] & 0x40 if raw[0] == F.SD2 else 0
            bits += len(raw) * CHAR_BITS + (TID1 if is_req else MIN_TSDR)
    return n, bits / BAUD


def _run(cmd: list[str], env: dict[str, str]) -> float:
    """The CPU time (user + sys) of one run of cmd, output to /dev/null."""
    with tempfile.TemporaryFile() as err:
        p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err, env=env)
        _, status, usage = os.wait4(p.pid, 0)
        p.returncode = os.waitstatus_to_exitcode(status)
        err.seek(0)
        text = err.read().decode("utf-8", "replace")
    if p.returncode != 0 or "Lua Error" in text:
        raise SystemExit(f"bench_dissector: {' '.join(cmd)} failed: {text.strip()[:400]}")
    return usage.ru_utime + usage.ru_stime


def best(cmd: list[str], env: dict[str, str], repeat: int) -> float:
    return min(_run(cmd, env) for _ in range(repeat))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0, help="line time each capture holds")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--lua", default=str(HERE.parent / "wireshark" / "pdrive.lua"),
                    help="the dissector to time (default: the checkout's)")
    ap.add_argument("--values", default="changing,realistic",
                    help="the captures: changing, realistic (comma separated)")
    ap.add_argument("--modes", default="summary,fields,verbose",
                    help="summary, fields, verbose (comma separated)")
    ap.add_argument("--no-table", action="store_true", help="no station table: PPO by length only")
    ap.add_argument("--keep", default=None, metavar="DIR", help="also keep the captures in this folder")
    a = ap.parse_args(argv)
    exe = shutil.which("tshark")
    if exe is None:
        print("bench_dissector: tshark not found", file=sys.stderr)
        return 2
    extra = {"summary": [], "fields": ["-T", "fields"] + [x for f in FIELDS for x in ("-e", f)],
             "verbose": ["-V"]}
    modes = a.modes.split(",")
    captures = a.values.split(",")
    for bad in [m for m in modes if m not in extra] + [v for v in captures if v not in VALUES]:
        print(f"bench_dissector: unknown mode or capture {bad!r} (modes: summary, fields, verbose; "
              f"--values: {', '.join(VALUES)})", file=sys.stderr)
        return 2
    print(f"load: {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f} "
          f"(1, 5, 15 min) on {os.cpu_count()} CPUs; times are CPU (user + sys), best of {a.repeat}")
    rows: list[tuple[str, str, float]] = []
    with tempfile.TemporaryDirectory() as tmp:
        tdir = Path(tmp)
        lua = tdir / "pdrive.lua"
        shutil.copyfile(a.lua, lua)
        if not a.no_table:
            from profidrive_cli.bustools.wireshark import STATION_TABLE, parse_station, render_station_table
            specs = [parse_station(f"{addr}={name}") for addr, name, _ in PLANT]
            (tdir / STATION_TABLE).write_text(render_station_table(specs), "utf-8")
        env = {**os.environ, "HOME": tmp}
        for values in captures:
            pcap = tdir / f"saturated-1.5M-{values}.pcap"
            n, line_s = write_capture(pcap, a.seconds, values)
            if a.keep:
                shutil.copyfile(pcap, Path(a.keep) / pcap.name)
            rate = n / line_s
            print(f"\n{values} capture: {n} telegrams = {line_s:.3f} s of a saturated 1.5 Mbit/s line "
                  f"(line rate {rate:,.0f} telegrams/s; by hand {HAND_RATE:,.0f}); {pcap.stat().st_size:,} octets")
            ref = best([exe, "-n", "-r", str(pcap)], env, a.repeat)
            print(f"  tshark -n -r FILE (no dissector, reference): {ref:.2f} s CPU = "
                  f"{n / ref / rate:.2f}x the line")
            for mode in modes:
                cmd = [exe, "-n", "-X", f"lua_script:{lua}", "-r", str(pcap), *extra[mode]]
                dt = best(cmd, env, a.repeat)
                own = dt - ref
                alone = f"{n / own / rate:.2f}x" if own > 0 else "(within the reference's noise)"
                print(f"  {mode:8s} with pdrive.lua: {dt:.2f} s CPU; overall {n / dt:,.0f} telegrams/s = "
                      f"{n / dt / rate:.2f}x the line; dissector alone {alone}")
                rows.append((values, mode, n / dt / rate))
    print("\noverall (tshark included), multiples of a saturated 1.5 Mbit/s line; target >= 1.5x on changing:")
    print("  " + " " * 8 + "".join(f"{v:>12s}" for v in captures))
    for mode in modes:
        print(f"  {mode:8s}" + "".join(f"{r:>11.2f}x" for v, m, r in rows if m == mode))
    return 0


if __name__ == "__main__":
    sys.exit(main())
