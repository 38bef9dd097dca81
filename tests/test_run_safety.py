"""The safe stop of `pdrive run` through a real serial path: `pdrive sim --pty` in one process (the plant
keeps its state between commands), `pdrive run` in another, signalled mid-run; then `pdrive status`
must find the drive stopped. Also: keys on a terminal, link loss, confirmation on a real port."""

import json
import os
import select
import signal
import subprocess
import time

import pytest

from conftest import (SHORT_RAMPS, pdrive_cmd, read_until_turning, short_ramps_pty_sim,
                      start_pty_sim, status_of)

RAMPS = SHORT_RAMPS


def pdrive(*args, timeout=60):
    return subprocess.run(pdrive_cmd() + list(args), capture_output=True, text=True, timeout=timeout,
                          stdin=subprocess.DEVNULL)


@pytest.fixture(scope="module")
def pty_sim(tmp_path_factory):
    with short_ramps_pty_sim(tmp_path_factory) as port:
        yield port


_status = status_of


@pytest.mark.parametrize("address", [3, 4, 5, 6, 7])
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_signal_during_run_leaves_the_drive_stopped(pty_sim, address, sig):
    p = subprocess.Popen(pdrive_cmd() + ["run", str(address), "--hz", "20", "--port", pty_sim, "--yes",
                                         "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         stdin=subprocess.DEVNULL, text=True)
    try:
        read_until_turning(p)
        p.send_signal(sig)
        out, err = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == (143 if sig == signal.SIGTERM else 130), err
    end = json.loads(out.strip().splitlines()[-1])
    assert end["event"] == "end" and end["reason"] == ("SIGTERM" if sig == signal.SIGTERM else "Ctrl-C")
    assert end["stop"]["how"] == "normal" and end["stopped"]
    assert "Traceback" not in err
    st = _status(pty_sim, address)
    assert st["stopped"] and not st["running"] and not st["fault"], st


def test_writing_to_a_real_port_needs_yes(pty_sim):
    r = pdrive("param", "set", "3", "F07", "1", "--port", pty_sim)
    assert r.returncode == 2 and "add --yes" in r.stderr
    r = pdrive("run", "3", "--hz", "5", "--duration", "0.2", "--port", pty_sim)
    assert r.returncode == 2 and "add --yes" in r.stderr
    r = pdrive("param", "get", "3", "F07", "--port", pty_sim, "--json")       # reading needs none
    assert r.returncode == 0 and json.loads(r.stdout)["parameters"][0]["value"] == 0.3


def test_keys_on_a_terminal(tmp_path):
    """up raises the reference by 1 Hz, q stops the drive and ends the run (own in-process sim)."""
    mfd, sfd = os.openpty()
    p = subprocess.Popen(pdrive_cmd() + ["run", "3", "--hz", "10", "--port", "sim://", "--log",
                                         str(tmp_path / "k.csv")],
                         stdin=sfd, stdout=sfd, stderr=sfd, env={**os.environ, "COLUMNS": "120"})
    os.close(sfd)
    buf = b""

    def read_for(seconds):
        nonlocal buf
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            r, _, _ = select.select([mfd], [], [], 0.1)
            if r:
                try:
                    buf += os.read(mfd, 65536)
                except OSError:
                    return
    try:
        end = time.monotonic() + 20
        while b"running" not in buf and time.monotonic() < end:
            read_for(0.2)
        os.write(mfd, b"\x1b[A")
        read_for(1.0)
        os.write(mfd, b"q")
        end = time.monotonic() + 30
        while p.poll() is None and time.monotonic() < end:
            read_for(0.2)                        # keep reading: a full pty would block the writer
        read_for(0.2)
    finally:
        if p.poll() is None:
            p.kill()
        os.close(mfd)
    text = buf.decode(errors="replace")
    assert p.returncode == 0, text[-2000:]
    assert "11.00 Hz" in text                    # the reference after one step up
    assert "q pressed" in text and "stop: normal" in text
    rows = (tmp_path / "k.csv").read_text().splitlines()
    refs = {int(r.split(",")[3]) for r in rows[1:]}
    assert {round(0x4000 * 10 / 60), round(0x4000 * 11 / 60)} <= refs     # N2 words of 10 and 11 Hz


def test_link_loss_during_run_names_the_watchdog():
    sim, port = start_pty_sim()
    p = subprocess.Popen(pdrive_cmd() + ["run", "7", "--hz", "20", "--port", port, "--yes", "--json",
                                         "--watchdog", "400"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True)
    try:
        read_until_turning(p, min_hz=0.5)
        sim.kill()                                   # the port goes away mid-run
        sim.wait()
        out, err = p.communicate(timeout=30)
    finally:
        for x in (p, sim):
            if x.poll() is None:
                x.kill()
    assert p.returncode == 1, err
    assert "pdrive cannot send a stop" in err and "watchdog (400 ms)" in err
    assert "Traceback" not in err
    events = [json.loads(x) for x in out.strip().splitlines()]
    end = next(e for e in reversed(events) if e["event"] == "end")
    assert end["stop"]["how"] == "not sent (link lost)" and not end["stopped"]
    # the stream's last line: the error object (docs/json.md), with the exit code
    assert events[-1]["event"] == "error" and events[-1]["exit_code"] == 1


# =============================================================================================
# pdrive io with outputs that start a drive (issue 12 finding 1): asks on a real port; ends with the
# outputs safe (zero + Global_Control Clear) until the drive has stopped, then releases it
# =============================================================================================

# Moeller PPO1 (Chk_Cfg F3 F1): PKW 8 octets, STW 047F (operate, bus control), HSW 0x2000 = 50 % (25 Hz)
MOELLER_RUN = "0000 0000 0000 0000 047F 2000"


def _moeller_ready(port):
    """Station 6 without a fault and in S2 (ready to switch on), where 047F starts it."""
    r = pdrive("faults", "6", "--clear", "--yes", "--port", port)
    assert r.returncode == 0, r.stderr
    r = pdrive("run", "6", "--hz", "5", "--duration", "0.2", "--yes", "--port", port)
    assert r.returncode == 0, r.stderr
    assert _status(port, 6)["state"].startswith("S2")


def _actual_word(json_line: str) -> int:
    inputs = bytes.fromhex(json.loads(json_line)["inputs"].replace(" ", ""))
    return int.from_bytes(inputs[10:12], "big")


def test_io_outputs_without_a_terminal_and_without_yes_move_nothing(pty_sim):
    _moeller_ready(pty_sim)
    r = pdrive("io", "6", "--cfg", "F3F1", "--out", MOELLER_RUN, "--count", "300", "--port", pty_sim)
    assert r.returncode == 2, r.stdout + r.stderr
    assert "add --yes" in r.stderr and r.stdout == ""
    st = _status(pty_sim, 6)
    assert st["stopped"] and not st["running"] and not st["fault"] and st["actual_hz"] == 0.0, st
    assert st["state"].startswith("S2")                  # not started, not tripped


def test_io_with_yes_ends_with_the_drive_stopped_and_no_fault(pty_sim):
    _moeller_ready(pty_sim)
    r = pdrive("io", "6", "--cfg", "F3F1", "--out", MOELLER_RUN, "--count", "300", "--port", pty_sim,
               "--yes", "--json")
    assert r.returncode == 0, r.stderr
    assert max(_actual_word(x) for x in r.stdout.splitlines()) > 0      # the motor did turn
    st = _status(pty_sim, 6)
    assert st["stopped"] and not st["running"] and not st["fault"] and st["actual_hz"] == 0.0, st
    f = pdrive("faults", "6", "--port", pty_sim, "--json")
    assert f.returncode == 0 and json.loads(f.stdout)["current"]["fault"] is False, f.stdout


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_signal_during_io_leaves_the_drive_stopped_without_a_trip(pty_sim, sig):
    _moeller_ready(pty_sim)
    p = subprocess.Popen(pdrive_cmd() + ["io", "6", "--cfg", "F3F1", "--out", MOELLER_RUN, "--count",
                                         "100000000", "--port", pty_sim, "--yes", "--json"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True)
    try:
        end = time.monotonic() + 20
        while time.monotonic() < end:
            line = p.stdout.readline()
            if not line:
                break
            if _actual_word(line) > 0x0800:              # above 1/8 of the max frequency: turning
                break
        else:
            pytest.fail("io never turned the motor")
        p.send_signal(sig)
        out, err = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == (143 if sig == signal.SIGTERM else 130), err
    assert "Traceback" not in err and "Global_Control Clear" in err
    st = _status(pty_sim, 6)
    assert st["stopped"] and not st["running"] and not st["fault"] and st["actual_hz"] == 0.0, st


def test_the_question_needs_a_terminal_on_stderr_too(pty_sim):
    """stdin a terminal but stderr a pipe: the question would be invisible; refuse instead of waiting."""
    mfd, sfd = os.openpty()
    try:
        p = subprocess.Popen(pdrive_cmd() + ["run", "3", "--hz", "5", "--duration", "0.2", "--port", pty_sim],
                             stdin=sfd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            out, err = p.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            p.kill()
            p.communicate()
            pytest.fail("pdrive waited for an answer to a question nobody can see")
    finally:
        os.close(sfd)
        os.close(mfd)
    assert p.returncode == 2 and "add --yes" in err, err
    assert _status(pty_sim, 3)["actual_hz"] == 0.0
