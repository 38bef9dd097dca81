"""SIGINT / SIGTERM during pdrive's start-up (cli/main.py): one line on stderr, exit code 130 / 143
(128 + the signal number, as `run`, `jog` and `checklist run` end on them: docs/json.md "Exit
codes"), the error object under --json, no traceback and no death by the signal.

"During start-up" is made certain, not guessed with sleeps: a sitecustomize (run by Python before
pdrive) holds the first import of a module pdrive loads at start-up -- click (imported by cli/main.py
itself) or rich (imported with the command's module) -- and writes a marker file while it holds it.
The test waits for the marker, then sends the signal into that import."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

HOLD = """\
import os, sys, time
class _Hold:
    def find_spec(self, name, path=None, target=None):
        if name == os.environ["PDRIVE_TEST_HOLD"]:
            sys.meta_path.remove(self)
            open(os.environ["PDRIVE_TEST_MARK"], "w").close()
            while True:                         # until the signal ends the process
                time.sleep(0.05)
        return None
sys.meta_path.insert(0, _Hold())
"""


def _entry_points() -> list[list[str]]:
    """`python -m profidrive_cli` and the installed console script (when there is one beside the
    interpreter): both are pdrive's own process."""
    ways = [[sys.executable, "-m", "profidrive_cli"]]
    script = Path(sys.executable).parent / "pdrive"
    if script.is_file():
        ways.append([str(script)])
    return ways


def _started_then_signalled(tmp_path, entry, hold: str, sig, args):
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(HOLD)
    mark = tmp_path / "holding"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), str(ROOT)]),
           "PDRIVE_TEST_HOLD": hold, "PDRIVE_TEST_MARK": str(mark)}
    env.pop("PDRIVE_PORT", None)
    p = subprocess.Popen(entry + args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         stdin=subprocess.DEVNULL, env=env, cwd=tmp_path)
    try:
        deadline = time.monotonic() + 60          # generous: the start of a Python at load 20
        while not mark.exists():
            assert p.poll() is None, p.communicate()
            assert time.monotonic() < deadline, "pdrive never reached the held import"
            time.sleep(0.01)
        p.send_signal(sig)
        out, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    return p.returncode, out, err


@pytest.mark.parametrize("entry", _entry_points(), ids=lambda e: "script" if len(e) == 1 else "-m")
@pytest.mark.parametrize("hold", ["click", "rich"])
@pytest.mark.parametrize("sig,code,words", [(signal.SIGINT, 130, "interrupted"),
                                            (signal.SIGTERM, 143, "terminated (signal 15)")],
                         ids=["SIGINT", "SIGTERM"])
def test_a_signal_during_start_up_is_one_line_and_its_exit_code(tmp_path, entry, hold, sig, code,
                                                                 words):
    rc, out, err = _started_then_signalled(tmp_path, entry, hold, sig,
                                           ["scan", "--port", "sim://", "--json"])
    assert rc == code, (rc, out, err)
    assert err == f"pdrive: {words}\n", err                  # one line, no traceback
    assert json.loads(out) == {"error": words, "exit_code": code}   # docs/json.md: the error object


def test_a_stream_command_gets_the_error_event(tmp_path):
    # run streams JSON Lines: its error object carries "event": "error" (docs/json.md)
    rc, out, err = _started_then_signalled(tmp_path, _entry_points()[0], "rich", signal.SIGTERM,
                                           ["run", "3", "--hz", "5", "--port", "sim://", "--json"])
    assert rc == 143 and "Traceback" not in err
    assert json.loads(out) == {"event": "error", "error": "terminated (signal 15)", "exit_code": 143}


def test_without_json_nothing_on_stdout(tmp_path):
    rc, out, err = _started_then_signalled(tmp_path, _entry_points()[0], "click", signal.SIGINT,
                                           ["--version"])
    assert (rc, out, err) == (130, "", "pdrive: interrupted\n")


def test_a_program_calling_main_keeps_its_own_signal_handlers():
    # main(argv) from another program (the tests, a script): its SIGINT stays KeyboardInterrupt and
    # its SIGTERM its own; only pdrive's own process (main() without argv) handles them from the start
    code = ("import signal\n"
            "from profidrive_cli.cli.main import main\n"
            "try:\n    main(['--version'])\nexcept SystemExit:\n    pass\n"
            "print(signal.getsignal(signal.SIGINT) is signal.default_int_handler,"
            " signal.getsignal(signal.SIGTERM) == signal.SIG_DFL)\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert p.stdout.split()[-2:] == ["True", "True"], p.stdout + p.stderr
