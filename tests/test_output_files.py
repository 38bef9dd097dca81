"""Files pdrive writes are never lost (issue 12 findings 4 and 5): sniff --pcap/--raw, run --log and
checklist reports go to a temporary file beside the target and replace it only on success; a path
that cannot be written is refused before the bus is opened (exit 2, no directory created); a write
that fails (disk full: /dev/full) exits non-zero; a checklist whose report could not be written does
not end with PASSED and exits 1."""

import json
import os
import subprocess
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from conftest import pdrive_cmd, run_main
from profidrive_cli.cli.main import cli

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples" / "checklists"
FAST = ["--var", "accel_s=1", "--var", "decel_s=1", "--var", "hold_s=0.2"]

needs_dev_full = pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full")


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args], env={"PDRIVE_PORT": ""})


def pdrive(capsys, monkeypatch, *args):
    """pdrive's own entry point in this process: its exit code and its one-line errors."""
    return run_main(capsys, monkeypatch, *args)


# -- sniff ------------------------------------------------------------------------------------


def test_sniff_failure_leaves_an_existing_pcap_as_it_was(tmp_path):
    pcap = tmp_path / "old.pcap"
    pcap.write_bytes(b"an earlier capture")
    r = run("sniff", "--port", str(tmp_path / "no-such-port"), "--duration", "1", "--pcap", pcap)
    assert r.exit_code != 0
    assert pcap.read_bytes() == b"an earlier capture"
    assert [p.name for p in tmp_path.iterdir()] == ["old.pcap"]          # no temporary file left


@needs_dev_full
def test_sniff_pcap_to_a_full_disk_is_one_line_and_exit_1(tmp_path, capsys, monkeypatch):
    raw = tmp_path / "cap.raw"
    raw.write_bytes(bytes.fromhex("10 22 02 49 6D 16"))
    r = pdrive(capsys, monkeypatch, "sniff", "--from-file", raw, "--pcap", "/dev/full")
    assert r.exit_code == 1, r.output
    assert "--pcap /dev/full: write failed: No space left on device" in r.stderr


def test_sniff_pcap_in_a_missing_directory_is_refused_before_listening(tmp_path, capsys, monkeypatch):
    r = pdrive(capsys, monkeypatch, "sniff", "--port", "sim://", "--duration", "0.2", "--pcap", tmp_path / "nodir" / "c.pcap")
    assert r.exit_code == 2
    assert "does not exist" in r.stderr and "sim:// is silent" not in r.output + r.stderr
    assert not (tmp_path / "nodir").exists()


def _wait_until_listening(pid: int, port: str, limit_s: float = 60.0) -> None:
    """Until process `pid` has `port` open and waits in poll/select for its input: sniff flushes the
    port's input once it has opened it, so octets written before then are lost (a fixed sleep was
    too short on a loaded machine). Linux /proc; a hang guard of 60 s, not a timing assertion."""
    real = os.path.realpath(port)
    end = time.monotonic() + limit_s
    while time.monotonic() < end:
        try:
            fds = [os.readlink(f"/proc/{pid}/fd/{n}") for n in os.listdir(f"/proc/{pid}/fd")]
            with open(f"/proc/{pid}/wchan") as f:
                wchan = f.read()
        except OSError:
            fds, wchan = [], ""
        if real in fds and ("poll" in wchan or "select" in wchan):
            return
        time.sleep(0.02)
    pytest.fail(f"sniff did not start listening on {port} within {limit_s:g} s")


def test_sniff_raw_and_pcap_over_a_real_byte_path(socat_pair, tmp_path):
    """What arrives on the port is in --raw octet for octet, and --from-file decodes it back."""
    a, b = socat_pair
    raw, pcap = tmp_path / "c.raw", tmp_path / "c.pcap"
    # FDL status request 2 -> 34, its reply, a short acknowledge (reference §2 telegrams)
    sent = bytes.fromhex("10 22 02 49 6D 16") + bytes.fromhex("10 02 22 00 24 16") + b"\xE5"
    p = subprocess.Popen(pdrive_cmd() + ["sniff", "--port", a, "--duration", "2.5", "--raw", str(raw),
                                         "--pcap", str(pcap)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_until_listening(p.pid, a)
        fd = os.open(b, os.O_WRONLY | os.O_NOCTTY)
        os.write(fd, sent)
        os.close(fd)
        out, err = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0, err
    assert raw.read_bytes() == sent
    from profidrive_cli.dp.capture import read_pcap
    _, pkts = read_pcap(pcap.read_bytes())
    assert [x[1] for x in pkts] == [sent[:6], sent[6:12], sent[12:]]
    r = run("sniff", "--from-file", raw)
    assert r.exit_code == 0 and "FDL status" in r.output


# -- run --log --------------------------------------------------------------------------------


@needs_dev_full
def test_run_log_to_a_full_disk_exits_1(tmp_path, capsys, monkeypatch):
    r = pdrive(capsys, monkeypatch, "run", "3", "--hz", "5", "--duration", "0.3", "--port", "sim://", "--log", "/dev/full")
    assert r.exit_code == 1, r.output
    assert "--log /dev/full: write failed: No space left on device" in r.output + r.stderr


def test_run_log_in_a_missing_directory_is_refused_before_the_bus_is_opened(tmp_path, sim, capsys,
                                                                            monkeypatch):
    port = "sim://?stations=3:fuji-g1"
    r = pdrive(capsys, monkeypatch, "run", "3", "--hz", "5", "--duration", "0.3", "--port", port, "--log", tmp_path / "no" / "x.csv")
    assert r.exit_code == 2 and "does not exist" in r.stderr
    assert not (tmp_path / "no").exists()
    assert not sim                                 # the simulated bus was never even opened


def test_run_log_replaces_the_old_file_when_complete(tmp_path):
    log = tmp_path / "run.csv"
    log.write_text("old log\n")
    r = run("run", "3", "--hz", "5", "--duration", "0.3", "--port", "sim://?set=3:F07=0.1", "--log", log)
    assert r.exit_code == 0, r.output          # F07 0.1 s: the 5 Hz are reached within the 0.3 s
    rows = log.read_text().splitlines()
    assert rows[0].startswith("time_s,cycle,control_word") and len(rows) > 5
    assert [p.name for p in tmp_path.iterdir()] == ["run.csv"]


# -- checklist reports ------------------------------------------------------------------------


def test_checklist_report_in_a_missing_directory_is_refused_before_anything_runs(tmp_path, sim):
    missing = tmp_path / "typo" / "r.json"
    r = run("checklist", "run", EX / "moeller.yaml", "--yes", *FAST, "--report", missing)
    assert r.exit_code == 2, r.output
    assert "typo" in r.stderr and "does not exist" in r.stderr
    assert not missing.parent.exists()              # no directory created
    assert not sim                                  # no bus opened, no motor turned


def test_checklist_report_at_the_filesystem_root_is_not_created(sim):
    r = run("checklist", "run", EX / "moeller.yaml", "--yes", *FAST, "--report", "/pdrive-no-such-dir/r.json")
    assert r.exit_code == 2
    assert not os.path.exists("/pdrive-no-such-dir")
    assert not sim


@needs_dev_full
def test_checklist_whose_report_cannot_be_written_exits_1_and_does_not_end_with_passed(tmp_path):
    full = tmp_path / "r.json"
    full.symlink_to("/dev/full")                     # the path is fine; writing it fails (disk full)
    md = tmp_path / "r.md"
    r = run("checklist", "run", EX / "moeller.yaml", "--yes", "--cycle-hz", "200", *FAST,
            "--report", md, "--report", full)
    assert r.exit_code == 1, r.output
    assert "PASSED" in r.stdout                      # the steps did pass ...
    last = (r.stdout + r.stderr).strip().splitlines()[-1]
    assert "PASSED" not in last and "could not be written" in last
    assert "--report" in r.stderr and "No space left on device" in r.stderr
    assert full.is_symlink() and md.read_text().startswith("# Checklist")   # the other report is there


def test_checklist_report_replaces_an_old_one_only_when_written(tmp_path):
    js = tmp_path / "r.json"
    js.write_text("old report")
    r = run("checklist", "run", EX / "moeller.yaml", "--yes", "--cycle-hz", "200", *FAST, "--report", js)
    assert r.exit_code == 0, r.output
    assert json.loads(js.read_text())["status"] == "passed"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json"]
