"""Mutated capture files never crash a reader (issue 35): the seeded subset of tools/fuzz_captures.py --
pcap, pcapng, .ptd and raw seeds written by pdrive's writers (and the ET200S start-up of
../shared/testdata/external when present), mutated, through open_capture, every writer and learn, and
through `sniff --from-file`, `convert` and `sim --learn` in process. Only the house's one-line errors
(UsageError, DataFileError: exit 2) may come out."""

from __future__ import annotations

import importlib.util
import signal
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _tool():
    spec = importlib.util.spec_from_file_location("fuzz_captures", ROOT / "tools" / "fuzz_captures.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_mutated_captures_give_exit_0_or_2_never_a_crash(tmp_path, monkeypatch):
    fz = _tool()
    from profidrive_cli.sim import server
    monkeypatch.setattr(server, "serve", server.serve)          # the tool stubs it: restored after
    old = signal.signal(signal.SIGALRM, fz._alarm)
    try:
        c = fz.fuzz(120, seed=35, hang_s=20.0, out_dir=None, tmp=tmp_path)
    finally:
        signal.signal(signal.SIGALRM, old)
    assert (c["crash"], c["hang"]) == (0, 0), c
    assert c["exit1"] == 0 and c["exit0"] > 0 and c["exit2"] > 0, c      # both outcomes exercised


def test_the_seeds_read_back_whole(tmp_path):
    """The seeds are valid files: every format gives back the start-up's telegrams."""
    from profidrive_cli.dp.capfile import open_capture
    fz = _tool()
    want = fz._startup()
    for name, data in fz.seeds().items():
        if name.startswith("startup."):
            f = tmp_path / name
            f.write_bytes(data)
            assert [p.raw for p in open_capture(f)] == want, name
