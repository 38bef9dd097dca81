"""`python benchmarks/peak_rss.py OUT ARGS...`: run `pdrive ARGS` in this process and, at exit, write
its peak RSS (VmHWM, KiB; Linux /proc) to OUT. The process's own peak: ru_maxrss of a child also
counts the pages its parent had until the exec. Used by benchmarks/bench_sniff.py and
tests/test_sniff_streaming.py."""

import atexit
import sys

out = sys.argv[1]
sys.argv = ["pdrive"] + sys.argv[2:]


def peak() -> None:
    with open("/proc/self/status") as fh:
        kib = next(line.split()[1] for line in fh if line.startswith("VmHWM:"))
    with open(out, "w") as fh:
        fh.write(kib)


atexit.register(peak)
from profidrive_cli.cli.main import main

main()
