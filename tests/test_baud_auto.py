"""--baud auto on every bus command (listen first, then probe), a simulator locked to its baud=,
one FDL status per empty address in a scan, and a busy second client of `pdrive sim --listen`."""

import json
import socket

from profidrive_cli.dp import baud as B
from profidrive_cli.dp import scan as scan_mod
from profidrive_cli.fdl import frames as F
from profidrive_cli.sim import server

from conftest import TcpSim


def _run(*args):
    """Through main(), as the shell runs it: exit code, stdout, stderr."""
    import subprocess
    import sys
    p = subprocess.run([sys.executable, "-m", "profidrive_cli", *args], capture_output=True,
                       text=True, stdin=subprocess.DEVNULL, timeout=120)
    return p.returncode, p.stdout, p.stderr


# -- the simulator locked to baud= -------------------------------------------------------------

def test_sim_with_baud_answers_only_at_that_rate():
    code, out, _ = _run("scan", "--json", "--port", "sim://?baud=187500", "--baud", "19200")
    assert code == 1 or json.loads(out)["stations"] == []
    code, out, _ = _run("scan", "--json", "--port", "sim://?baud=187500", "--baud", "187.5k")
    assert code == 0
    assert [s["station"] for s in json.loads(out)["stations"]] == [3, 4, 5, 6, 7]


def test_plain_sim_answers_at_any_rate():
    for rate in ("9600", "1.5M"):
        code, out, _ = _run("scan", "--json", "--port", "sim://?stations=3:fuji-g1", "--baud", rate)
        assert code == 0
        assert [s["station"] for s in json.loads(out)["stations"]] == [3]


# -- --baud auto -----------------------------------------------------------------------------------

def test_scan_baud_auto_finds_187k5_on_a_wire_timed_bus():
    code, out, err = _run("scan", "--json", "--baud", "auto", "--port",
                          "sim://?baud=187500&timing=wire&stations=3:fuji-g1")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["baud"] == 187500
    assert [s["station"] for s in doc["stations"]] == [3]
    assert "187.5k" in err and "station 3 answered" in err


def test_status_baud_auto_uses_the_rate_found():
    code, out, err = _run("status", "3", "--json", "--baud", "auto", "--port",
                          "sim://?baud=500000&stations=3:fuji-g1")
    assert code == 0, err
    assert "baud rate 500k (station 3 answered)" in err
    assert json.loads(out)["station"] == 3


def test_baud_auto_nobody_answers_is_one_line_exit_1():
    code, out, err = _run("diag", "9", "--baud", "auto", "--port", "sim://?baud=187500&stations=3:fuji-g1")
    assert code == 1
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "--baud auto" in lines[0] and "station 9" in lines[0]


class _ListenLink:
    """A line with a running master at 93.75k: at that rate its telegrams decode, at any other rate
    the octets are garbage. Writing is forbidden (listening must never transmit)."""
    instant = False
    is_simulator = False

    def __init__(self, baud, t0):
        self.baud = baud
        self.t = t0
        self.closed = False

    def now(self):
        return self.t

    def read(self, deadline):
        self.t = min(deadline, self.t + 0.005)
        if self.baud == 93750:
            # Slave_Diag request and a data-exchange request of the reference's kind (SD2 and SD1)
            return (F.encode(F.make(3, 2, F.request_fc(F.SRD_HIGH, True, True), b"", 60, 62))
                    + F.encode(F.make(3, 2, F.request_fc(F.FDL_STATUS))))
        return bytes([0x55, 0xAA, 0x10, 0x99, 0x68, 0x07, 0x00]) * 3

    def write(self, data):
        raise AssertionError("listening transmitted")

    def close(self):
        self.closed = True


def test_listening_finds_a_running_master_without_transmitting():
    links = []

    def open_link(b):
        links.append(_ListenLink(b, 0.0))
        return links[-1]

    found, link = B.detect_baud(open_link, lambda link, b: None, probe=False)
    assert found is not None and found.baud == 93750
    assert "heard" in found.how
    assert link is links[-1] and not link.closed
    assert all(lk.closed for lk in links[:-1])
    # the rates were tried in the documented order up to the right one
    assert [lk.baud for lk in links] == list(B.PROBE_ORDER[:B.PROBE_ORDER.index(93750) + 1])


def test_garbage_is_not_a_running_master():
    found, link = B.detect_baud(lambda b: _ListenLink(b if b != 93750 else 1, 0.0),
                                lambda link, b: None, probe=False)
    assert found is None and link is None


# -- scan: one request per empty address ------------------------------------------------------------

class _StubFdl:
    def __init__(self):
        self.illegal = {}

    def counters_for(self, a):
        class C:
            pass
        c = C()
        c.illegal = self.illegal.get(a, 0)
        return c


class _StubMaster:
    """Counts FDL status requests; address 5 answers garbled the first time."""
    address = 2

    def __init__(self):
        self.fdl = _StubFdl()
        self.calls = []
        import dataclasses

        @dataclasses.dataclass
        class P:
            retries: int = 2
        self.params = P()

    def fdl_status(self, a):
        self.calls.append((a, self.params.retries))
        if a == 5 and len([c for c in self.calls if c[0] == 5]) == 1:
            self.fdl.illegal[5] = self.fdl.illegal.get(5, 0) + 1
            return None
        if a == 5:
            return F.Frame(F.SC, 0, 0)
        return None


def test_scan_sends_one_attempt_per_empty_address_and_retries_only_garbled():
    m = _StubMaster()
    for a in range(0, 8):
        if a != m.address:
            scan_mod.probe(m, a)
    by_addr = {}
    for a, r in m.calls:
        by_addr.setdefault(a, []).append(r)
    assert by_addr[0] == [0] and by_addr[7] == [0]           # empty: one attempt, no retries
    # garbled: a second try with retries; its answer is an SC, which a third probe confirms (an SC
    # carries no address: a lone noise octet 0xE5 reads the same; issue 26, dp/scan.py)
    assert by_addr[5] == [0, 2, 2]
    assert m.params.retries == 2                            # restored


def test_scan_on_sim_one_request_per_empty_address():
    from profidrive_cli.dp.poller import Master
    from profidrive_cli.fdl.timing import BusParams
    from profidrive_cli.link import open_link
    m = Master(open_link("sim://?stations=3:fuji-g1"), BusParams.for_baud(19200, retries=2))
    found = scan_mod.scan(m, 0, 10, quick=True)          # the quick pass alone (issue 26)
    assert [e.address for e in found] == [3]
    c = m.fdl.counters
    for a in (0, 1, 4, 10):
        assert c[a].requests == 1 and c[a].retries == 0, (a, c[a])
    m.link.close()
    # the full scan: the second pass adds one single attempt per silent address (a slave in
    # Baud_Search); it begins after the quick pass's 10 requests (0, 1, 3..10): WAKE_TELEGRAMS
    # (10) went by, no extra pass
    m = Master(open_link("sim://?stations=3:fuji-g1"), BusParams.for_baud(19200, retries=2))
    assert [e.address for e in scan_mod.scan(m, 0, 10)] == [3]
    c = m.fdl.counters
    for a in (0, 1, 4, 10):
        assert c[a].requests == 2 and c[a].retries == 0, (a, c[a])
    m.link.close()


# -- pdrive sim --listen: a second client is told it is busy ------------------------------------------

def test_second_tcp_client_is_told_busy():
    with TcpSim("sim://?stations=3:fuji-g1") as srv:
        first = socket.create_connection(srv.ep.address, timeout=5)
        srv.wait_accepted(1)
        second = socket.create_connection(srv.ep.address, timeout=5)
        got = b""
        while True:
            chunk = second.recv(200)
            if not chunk:
                break
            got += chunk
        assert got == server.BUSY_LINE
        assert b"busy" in got
        assert srv.ep.refused == 1 and srv.ep.accepted == 1
        # the first client is still served: an FDL status to station 3 is answered
        first.sendall(F.encode(F.make(3, 2, F.request_fc(F.FDL_STATUS))))
        first.settimeout(5)
        reply = first.recv(100)
        assert reply and reply[0] in (F.SD1, F.SC)
        first.close()
        second.close()


# -- sniff decoding: garbage runs are one entry; chunked feeding equals one feed ----------------------

def test_capture_garbage_run_is_one_entry_and_frames_after_it_are_found():
    from profidrive_cli.dp.capture import Capture
    req = F.encode(F.make(3, 2, F.request_fc(F.FDL_STATUS)))    # SD1 10 03 02 49 4E 16
    assert req == bytes.fromhex("10 03 02 49 4E 16")
    noise = bytes([0x00, 0x55, 0xAA, 0x99, 0x01])               # none of them can start a telegram
    items = Capture().feed(noise + req + noise, 0.0)
    assert [(c.frame is None, c.raw) for c in items] == [(True, noise), (False, req), (True, noise)]


def test_capture_chunked_feed_equals_one_feed():
    import random
    from profidrive_cli.dp.capture import Capture, merge_errors
    rnd = random.Random(7)
    frames = [F.encode(F.make(a, 2, F.request_fc(F.SRD_HIGH, True, True), bytes([a] * 4), 58, 62))
              for a in range(3, 10)]
    alphabet = [b for b in range(256) if b not in (F.SD1, F.SD2, F.SD3, F.SD4, F.SC)]
    data = b"".join(bytes(rnd.choice(alphabet) for _ in range(rnd.randrange(0, 20))) + f
                    for f in frames)
    whole = merge_errors(Capture().feed(data, 0.0))
    cap = Capture()
    parts = []
    for i in range(0, len(data), 5):
        parts += cap.feed(data[i:i + 5], 0.0)
    chunked = merge_errors(parts)
    assert [c.raw for c in whole if c.frame] == frames
    assert [c.raw for c in chunked if c.frame] == frames
    assert b"".join(c.raw for c in whole) == b"".join(c.raw for c in chunked) == data[:len(b"".join(c.raw for c in whole))]


def test_pdrive_as_second_client_is_told_the_simulator_is_busy():
    import subprocess
    import sys
    with TcpSim("sim://?stations=3:fuji-g1") as srv:
        first = socket.create_connection(srv.ep.address, timeout=5)
        srv.wait_accepted(1)
        p = subprocess.run([sys.executable, "-m", "profidrive_cli", "scan", "--to", "5", "--port",
                            srv.url], capture_output=True, text=True,
                           stdin=subprocess.DEVNULL, timeout=60)
        first.close()
    assert p.returncode == 1
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "busy" in lines[0] and "another client is connected" in lines[0]
    assert "Traceback" not in p.stderr


# -- a line without a baud rate of its own: a pty, TCP, the simulator without baud= ------------------

RATELESS_WORDS = "has no baud rate of its own, so any rate answers; 19.2k is used, the default"


def test_baud_auto_over_tcp_says_the_line_has_no_rate():
    # `pdrive sim --listen` answers whatever rate the master sets (the octets do not carry it), so
    # the first rate tried (1.5M) used to be reported as found. The honest answer names the line and
    # the rate used: 19.2k, the rate the commands use without --baud (`pdrive --help`: --baud 19200).
    with TcpSim("sim://?stations=3:fuji-g1") as srv:
        code, out, err = _run("status", "3", "--json", "--baud", "auto", "--port", srv.url)
    assert code == 0, err
    assert "a TCP connection (socket://) " + RATELESS_WORDS in err
    assert "1.5M" not in err and json.loads(out)["station"] == 3


def test_baud_auto_over_a_pty_says_the_line_has_no_rate():
    from conftest import pty_sim_process
    with pty_sim_process() as port:
        code, out, err = _run("scan", "--json", "--baud", "auto", "--port", port)
    assert code == 0, err
    assert f"a pty ({port}) " + RATELESS_WORDS in err
    doc = json.loads(out)
    assert doc["baud"] == 19200 and 3 in [s["station"] for s in doc["stations"]]


def test_baud_auto_on_the_simulator_without_baud():
    code, out, err = _run("status", "3", "--json", "--baud", "auto", "--port", "sim://?stations=3:fuji-g1")
    assert code == 0, err
    assert "the simulator without baud= " + RATELESS_WORDS in err
