"""Start-up time of pdrive commands against `python -c "import click"`, measured in the same run.

    python benchmarks/bench_startup.py [--rounds N] [--against DIR]

--against DIR  also run the pdrive commands from another checkout (e.g. `git worktree add` or
               `git archive` of an older commit), in the same rounds: before/after in one run

Each round runs every command once, in turn (interleaved, so machine load hits all alike); the
figure per command is the median wall time over the rounds, and its ratio to the median of
`python -c "import click"` in the same rounds; then the same for the CPU time (user + system) of the
command's process, which another process's load on the machine disturbs much less than the wall time. Run from the repository root (or with pdrive
installed): the commands are started as `python -m profidrive_cli …`. PYTHONDONTWRITEBYTECODE is
removed from the commands' environment and one round is run first and not counted, so the figures are
those of an installation with its .pyc files (without them every run compiles pdrive's modules anew).
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

CASES = [
    ("import click", [sys.executable, "-c", "import click"]),
    ("pdrive --version", [sys.executable, "-m", "profidrive_cli", "--version"]),
    ("pdrive --help", [sys.executable, "-m", "profidrive_cli", "--help"]),
    ("pdrive decode moeller --ppo 1 --request …",
     [sys.executable, "-m", "profidrive_cli", "decode", "moeller", "--ppo", "1", "--request",
      "3017 0000 0000 0190 047F 2000"]),
    ("pdrive scan --port sim://", [sys.executable, "-m", "profidrive_cli", "scan", "--port", "sim://"]),
    ("pdrive scan --port 'sim://?stations=3:fuji-g1'",
     [sys.executable, "-m", "profidrive_cli", "scan", "--port", "sim://?stations=3:fuji-g1"]),
]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--against", metavar="DIR", help="another checkout, run in the same rounds")
    a = ap.parse_args()
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    base = env.get("PYTHONPATH", "")
    trees = [("", HERE)] + ([(" [" + os.path.basename(os.path.abspath(a.against)) + "]",
                              os.path.abspath(a.against))] if a.against else [])
    cases = [(name, cmd, HERE) for name, cmd in CASES[:1]]
    for tag, root in trees:
        cases += [(name + tag, cmd, root) for name, cmd in CASES[1:]]
    times: dict[str, list[float]] = {name: [] for name, _, _ in cases}
    cpu: dict[str, list[float]] = {name: [] for name, _, _ in cases}
    for r in range(a.rounds + 1):
        for name, cmd, root in cases:
            env["PYTHONPATH"] = root + os.pathsep + base
            t = time.perf_counter()
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            subprocess.run(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                           stdin=subprocess.DEVNULL, check=True, cwd=root)
            wall = time.perf_counter() - t
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            if r:                   # round 0 writes the .pyc files
                times[name].append(wall)
                cpu[name].append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    ref = statistics.median(times["import click"])
    cref = statistics.median(cpu["import click"])
    print(f"python {sys.version.split()[0]}, {os.cpu_count()} CPUs, {a.rounds} interleaved rounds"
          f" (load average {os.getloadavg()[0]:.1f})")
    print(f"{'':<60} {'wall':>9}  {'ratio':>6}   {'CPU':>9}  {'ratio':>6}")
    for name, _, _ in cases:
        med, cmed = statistics.median(times[name]), statistics.median(cpu[name])
        print(f"{name:<60} {med * 1000:6.1f} ms  {med / ref:5.2f}x   {cmed * 1000:6.1f} ms  {cmed / cref:5.2f}x")


if __name__ == "__main__":
    main()
