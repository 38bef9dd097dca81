"""Local echo of 2-wire adapters (issue 26, "Adapters"): `--echo auto`, the default, finds out at the
first transmission whether the adapter hears itself and from then on drops the echo.

At byte level with a fake port whose answer to each write is scripted (no waiting, no timing), and
end to end with an echoing "adapter" on a pty in front of `pdrive sim` (scan without --echo).

Telegrams are the reference's real captures (../shared/spec/profibus-dp-reference.md §2.3 table,
lines 158-167), so no expected value comes from the code under test."""

import json
import os
import select
import subprocess
import threading
import time

import pytest
from click.testing import CliRunner

from conftest import pdrive_cmd
from profidrive_cli import UsageError
from profidrive_cli.link import serial_link
from profidrive_cli.link.serial_link import SerialLink

H = bytes.fromhex
# reference line 158: FDL status request DA 34, SA 2, FC 0x49
FDL_REQ = H("10 22 02 49 6D 16")
# its answer by hand: SD1, DA 2, SA 34, FC 0x00 (slave, OK: reference §2.2 "FDL status reply uses
# FC 0x00 from a slave"), FCS = (2 + 34 + 0) mod 256 = 0x24
FDL_ANS = H("10 02 22 00 24 16")
# reference lines 161/162: Slave_Diag request and response (PPI #33)
DIAG_REQ = H("68 05 05 68 8A 82 6D 3C 3E F3 16")
DIAG_ANS = H("68 0B 0B 68 82 8A 08 3E 3C 06 05 00 FF 0F 84 2B 16")
# reference line 163: Set_Prm and its SC
PRM_REQ = H("68 0C 0C 68 8A 82 5D 3D 3E 80 01 01 00 0F 84 01 FA 16")
SC = H("E5")


class FakePort:
    """A pyserial-like port: every write is answered at once by reply(data) (the octets the adapter
    then has for us); reads never wait (an empty read is the deadline passing)."""

    def __init__(self, reply):
        self.reply = reply
        self.buf = bytearray()
        self.written = []
        self.timeout = 0.0
        self.write_timeout = 2.0
        self.closed = False

    def write(self, data):
        self.written.append(bytes(data))
        self.buf += self.reply(bytes(data))
        return len(data)

    @property
    def in_waiting(self):
        return len(self.buf)

    def read(self, n=1):
        out = bytes(self.buf[:n])
        del self.buf[:n]
        return out

    def reset_input_buffer(self):
        self.buf.clear()

    def close(self):
        self.closed = True


def link_on(monkeypatch, reply, echo="auto"):
    port = FakePort(reply)
    monkeypatch.setattr(serial_link, "open_serial", lambda *a, **k: port)
    return SerialLink("/dev/ttyFAKE0", 19200, echo=echo), port


def read_all(link):
    got = b""
    while True:
        chunk = link.read(time.monotonic())
        if not chunk:
            return got
        got += chunk


def test_an_echoing_adapter_is_found_and_its_echo_dropped_the_answer_kept(monkeypatch):
    # the adapter hears itself; the slave's answer arrives in the same USB packet as the echo
    link, _ = link_on(monkeypatch, lambda d: d + (FDL_ANS if d == FDL_REQ else DIAG_ANS))
    assert link.echo_detected is None and not link.echo          # not known before a transmission
    link.write(FDL_REQ)
    assert link.echo_detected is True and link.echo
    assert read_all(link) == FDL_ANS                              # the echo gone, the answer whole
    link.write(DIAG_REQ)                                          # from then on: always dropped
    assert read_all(link) == DIAG_ANS
    assert link.echo_errors == 0


@pytest.mark.parametrize("req,ans", [(FDL_REQ, FDL_ANS), (DIAG_REQ, DIAG_ANS), (PRM_REQ, SC)],
                         ids=["SD1 FDL status / SD1", "SD2 Slave_Diag / SD2", "SD2 Set_Prm / SC"])
def test_a_slave_answer_is_never_taken_for_an_echo(monkeypatch, req, ans):
    # no echo, the slave answers at once: the answer differs from the request (FC bit 6: request 1,
    # response 0, reference §2.2; SD1: DA and SA swapped; SC 0xE5 is no request's start delimiter)
    link, _ = link_on(monkeypatch, lambda d: ans)
    link.write(req)
    assert link.echo_detected is False and not link.echo
    assert read_all(link) == ans                                  # delivered, octet for octet


def test_silence_means_no_echo(monkeypatch):
    link, _ = link_on(monkeypatch, lambda d: b"")
    link.write(FDL_REQ)
    assert link.echo_detected is False
    assert read_all(link) == b""


def test_a_matching_beginning_that_stops_short_stays_undecided(monkeypatch):
    # the first 4 octets of an SD2 request and of an SD2 answer of the same length are the same
    # (68 LE LEr 68): 4 octets prove nothing; they are handed on and the next write looks again
    answers = [DIAG_REQ[:4], DIAG_REQ]
    link, _ = link_on(monkeypatch, lambda d: answers.pop(0))
    link.write(DIAG_REQ)
    assert link.echo_detected is None and not link.echo
    assert read_all(link) == DIAG_REQ[:4]
    link.write(DIAG_REQ)
    assert link.echo_detected is True
    assert read_all(link) == b""


def test_forced_on_keeps_an_answer_that_came_with_the_echo(monkeypatch):
    # --echo on: the echo read back, and an answer already behind it kept (it used to be dropped
    # with the echo: the master then saw no answer)
    link, _ = link_on(monkeypatch, lambda d: d + FDL_ANS, echo=True)
    link.write(FDL_REQ)
    assert read_all(link) == FDL_ANS
    assert link.echo_detected is None and link.echo_errors == 0


def test_forced_off_never_looks(monkeypatch):
    link, _ = link_on(monkeypatch, lambda d: d, echo=False)
    link.write(FDL_REQ)
    assert link.echo_detected is None and not link.echo
    assert read_all(link) == FDL_REQ                              # the echo is read as input


def test_flush_drops_what_was_kept(monkeypatch):
    link, _ = link_on(monkeypatch, lambda d: d + FDL_ANS)
    link.write(FDL_REQ)
    link.flush_input()
    assert read_all(link) == b""


def test_reopen_finds_out_again(monkeypatch):
    replies = [lambda d: d, lambda d: b""]
    ports = []

    def opener(*a, **k):
        ports.append(FakePort(replies[len(ports)]))
        return ports[-1]
    monkeypatch.setattr(serial_link, "open_serial", opener)
    link = SerialLink("/dev/ttyFAKE0", 19200)
    link.write(FDL_REQ)
    assert link.echo_detected is True
    link.reopen()                                  # another adapter may be plugged in now
    assert link.echo_detected is None
    link.write(FDL_REQ)
    assert link.echo_detected is False and not link.echo


def test_sim_has_no_echo_and_is_not_asked():
    link = SerialLink("sim://?stations=3:fuji-g1")
    try:
        assert link.echo_detected is False and not link.echo
    finally:
        link.close()


def test_bad_echo_setting_is_one_line():
    with pytest.raises(UsageError, match="give auto, on or off"):
        SerialLink("sim://", echo="maybe")


def test_the_echo_found_is_said_once_with_v(monkeypatch, caplog):
    import logging
    link, _ = link_on(monkeypatch, lambda d: d)
    with caplog.at_level(logging.INFO, logger="profidrive_cli.dp"):
        link.write(FDL_REQ)
        link.write(FDL_REQ)
    said = [r.getMessage() for r in caplog.records if "hears its own transmission" in r.getMessage()]
    assert len(said) == 1 and "10 22 02 49 6d 16" in said[0]


# -- end to end: an echoing adapter on a pty in front of `pdrive sim` ---------------------------------

def _pair(tmp_path, tag):
    a, b = str(tmp_path / f"{tag}A"), str(tmp_path / f"{tag}B")
    p = subprocess.Popen(["socat", f"pty,raw,echo=0,ignoreeof,link={a}",
                          f"pty,raw,echo=0,ignoreeof,link={b}"],
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    for _ in range(500):
        if os.path.exists(a) and os.path.exists(b):
            return p, a, b
        time.sleep(0.01)
    p.kill()
    pytest.fail("socat did not create its ptys")


def _echoing_adapter(master_side, bus_side, stop):
    """What a 2-wire adapter does: every octet the master sends comes back to it (before any
    answer: the slave answers only after the whole request), and goes on to the bus."""
    m = os.open(master_side, os.O_RDWR | os.O_NOCTTY)
    b = os.open(bus_side, os.O_RDWR | os.O_NOCTTY)
    try:
        while not stop:
            r, _, _ = select.select([m, b], [], [], 0.02)
            if m in r:
                data = os.read(m, 4096)
                os.write(m, data)                    # the echo first
                os.write(b, data)
            if b in r:
                os.write(m, os.read(b, 4096))
    finally:
        os.close(m)
        os.close(b)


@pytest.mark.skipif(os.name != "posix", reason="ptys")
def test_scan_through_an_echoing_adapter_needs_no_echo_option(tmp_path):
    import shutil
    if not shutil.which("socat"):
        pytest.skip("socat not installed")
    p1, master_a, master_b = _pair(tmp_path, "m")
    p2, bus_a, bus_b = _pair(tmp_path, "s")
    sim = subprocess.Popen(pdrive_cmd() + ["sim", "--json", "--port", bus_a], stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
    stop = []
    t = threading.Thread(target=_echoing_adapter, args=(master_a, bus_b, stop), daemon=True)
    try:
        assert sim.stdout.readline()
        t.start()
        from profidrive_cli.cli.main import cli
        r = CliRunner().invoke(cli, ["scan", "--port", master_b, "--from", "3", "--to", "7",
                                     "--quick", "--json"])
        assert r.exit_code == 0, r.output
        data = json.loads(r.output)
        # the default plant of `pdrive sim`: stations 3..7 (docs/architecture.md, "Default sim plant")
        assert [s["station"] for s in data["stations"]] == [3, 4, 5, 6, 7], r.output
        # the echo is not read as a telegram: without echo handling every request's echo counted
        # as an illegal frame (a request, not a reply to us)
        assert all(s["counters"]["illegal"] == 0 for s in data["stations"]), r.output
        assert data["echo"] is True                     # and scan says it found the echo
    finally:
        stop.append(1)
        t.join(2)
        sim.terminate()
        sim.wait(10)
        for p in (p1, p2):
            p.terminate()
            p.wait(5)


@pytest.mark.parametrize("args,expect", [((), "auto"), (("--echo",), True), (("--no-echo",), False)])
def test_the_echo_option_reaches_the_link(monkeypatch, args, expect):
    import profidrive_cli.link as L
    from profidrive_cli.cli.main import cli
    seen = []
    real = L.open_link

    def spy(port, baud=19200, rs485=False, echo="auto"):
        seen.append(echo)
        return real(port, baud, rs485=rs485, echo=echo)
    monkeypatch.setattr(L, "open_link", spy)
    r = CliRunner().invoke(cli, ["scan", "--port", "sim://", "--from", "3", "--to", "3", "--quick",
                                 "--json", *args])
    assert seen == [expect], r.output
    assert SerialLink("sim://", echo=expect).echo_mode == expect


def test_the_api_finds_out_by_default():
    import profidrive_cli as pdrive
    with pdrive.open_bus("sim://") as bus:
        link = bus.master.link
        assert link.echo_mode == "auto" and link.echo_detected is False     # sim://: no echo
