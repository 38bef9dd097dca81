"""A control server that cannot hurt the plant (issue 35; sim/control_http.py, sim/server.py AcceptGuard):
idle, slow and hostile clients of `pdrive sim --control`, a process out of file descriptors, and web
pages in the user's browser must neither stop the simulated bus nor steer the plant.

The simulator runs as `pdrive sim --listen 127.0.0.1:0 --control 127.0.0.1:0` (tools/soak_sim_control.py
Sim), a master asks station 3 for its FDL status on the bus port (the reply from the protocol: SD1,
FC 0x00 "slave, OK")."""

from __future__ import annotations

import errno
import importlib.util
import json
import os
import socket
import sys
import time
from pathlib import Path

import pytest

from profidrive_cli.sim import control_http
from profidrive_cli.sim.control import Controller, QueuedController
from profidrive_cli.sim.server import NO_FDS_LINE, AcceptGuard, Reports, TcpEndpoint

ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc, rlimits")


def _soak():
    spec = importlib.util.spec_from_file_location("soak_sim_control", ROOT / "tools" / "soak_sim_control.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


S = _soak()


def _until(what, deadline_s: float = 120.0, every: float = 0.1):
    """what() until it is truthy (its value), within a generous deadline (load 20 on two cores)."""
    end = time.monotonic() + deadline_s
    while True:
        got = what()
        if got or time.monotonic() > end:
            return got
        time.sleep(every)


def _clean(stderr: str) -> None:
    assert "Traceback" not in stderr and "Error" not in stderr, stderr


# -- descriptors ------------------------------------------------------------------------------------

def test_seventy_idle_control_clients_under_64_descriptors_leave_the_bus_running() -> None:
    """The issue's case: 65+ idle connections to the control under RLIMIT_NOFILE 64 made the control
    spin on EMFILE and the simulator exit when a master then connected to the bus port."""
    sim = S.Sim(nofile=64)
    idle: list[socket.socket] = []
    try:
        for _ in range(70):
            idle.append(socket.create_connection(sim.control, timeout=30))
        assert S.fdl_status(sim.bus) == S.FDL_STATUS_3_REPLY
        assert sim.alive()
        # the control holds clients_for_limit(64) = 12 connections (a quarter of what the process
        # has left after its own 16); the others were answered 503 and closed
        status, answer = S.http(sim.control, "GET", "/state")
        assert status in (200, 503), answer
        if status == 503:
            assert "too many clients" in answer["error"]
        for s in idle:
            s.close()
        idle.clear()
        assert _until(lambda: S.http(sim.control, "GET", "/state")[0] == 200)
        assert S.fdl_status(sim.bus) == S.FDL_STATUS_3_REPLY
        assert sim.alive()
    finally:
        for s in idle:
            s.close()
        stderr = sim.stop()
    _clean(stderr)
    assert stderr.count("clients at once") == 1, stderr           # reported once


def test_out_of_descriptors_on_either_port_refuses_one_client_and_goes_on() -> None:
    """The simulator's descriptor limit squeezed from outside (prlimit) so that accept fails: the bus
    port says why and closes, the control answers 503, the simulator reports it once per port and
    serves again when descriptors are free."""
    import resource
    sim = S.Sim()                                  # (no client yet: its descriptors are settled)
    try:
        soft, hard = resource.prlimit(sim.pid, resource.RLIMIT_NOFILE)
        # the limit at the lowest free descriptor: every one below it is in use, so the next
        # descriptor the process asks for is refused (EMFILE); those above stay valid
        used = {int(fd) for fd in os.listdir(f"/proc/{sim.pid}/fd")}
        lowest_free = min(set(range(max(used) + 2)) - used)
        try:
            resource.prlimit(sim.pid, resource.RLIMIT_NOFILE, (lowest_free, hard))
        except PermissionError:
            pytest.skip("prlimit on another process not permitted here")
        assert _bus_reply_until_closed(sim.bus) in (b"", NO_FDS_LINE)
        with socket.create_connection(sim.control, timeout=30) as c:
            c.settimeout(120)
            refused = c.recv(4096)                # told at once, before any request
        assert refused.startswith(b"HTTP/1.0 503") and b"out of file descriptors" in refused, refused
        assert sim.alive()
        resource.prlimit(sim.pid, resource.RLIMIT_NOFILE, (soft, hard))
        assert _until(lambda: S.fdl_status(sim.bus) == S.FDL_STATUS_3_REPLY)
        assert _until(lambda: S.http(sim.control, "GET", "/state")[0] == 200)
    finally:
        stderr = sim.stop()
    _clean(stderr)
    assert stderr.count("control: out of file descriptors") == 1, stderr
    assert stderr.count("bus port: out of file descriptors") == 1, stderr


def _bus_reply_until_closed(bus: tuple[str, int]) -> bytes:
    """A master's FDL status on the bus port, and what it hears until the server closes (a reset
    counts as nothing heard)."""
    got = b""
    with socket.create_connection(bus, timeout=30) as m:
        try:
            m.sendall(S.FDL_STATUS_3)
            while chunk := m.recv(4096):
                got += chunk
        except OSError:
            pass
    return got


class _FullSocket:
    """A listening socket whose accept fails for want of descriptors until told otherwise."""

    def __init__(self) -> None:
        self.accepts = 0
        self.full = True

    def accept(self):
        self.accepts += 1
        if self.full:
            raise OSError(errno.EMFILE, "Too many open files")
        a, b = socket.socketpair()
        b.close()
        return a, ("127.0.0.1", 1)


class _Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_accept_guard_refuses_backs_off_and_reports_once() -> None:
    clock, lines = _Clock(), []
    guard = AcceptGuard("bus port", lines.append, clock)
    srv = _FullSocket()
    try:
        assert guard.accept(srv, b"x") is None         # type: ignore[arg-type]
        # the spare descriptor was given up for one more try: 2 accepts, one refused client
        assert (srv.accepts, guard.refused) == (2, 1)
        assert not guard.ready()                          # backing off: no look at the socket
        clock.t += AcceptGuard.BACKOFF_S
        assert guard.ready()
        for _ in range(5):
            guard.accept(srv, b"x")                       # type: ignore[arg-type]
            clock.t += AcceptGuard.BACKOFF_S
        assert guard.refused == 6 and len(lines) == 1 and "out of file descriptors" in lines[0]
        srv.full = False
        got = guard.accept(srv, b"x")                     # type: ignore[arg-type]
        assert got is not None
        got[0].close()
        assert len(lines) == 2 and "free again (6 client(s) refused" in lines[1]
    finally:
        guard.close()


def test_a_recurring_report_is_one_line_a_minute_with_a_count() -> None:
    clock, lines = _Clock(), []
    report = Reports(lines.append, 60.0, clock)
    for _ in range(1000):                      # a client churning at a limit, every 10 ms
        report("control: 12 clients at once")
        clock.t += 0.01
    # 10 s of it: the first line only; a minute on, one line that counts the 999 held back
    assert lines == ["control: 12 clients at once"]
    clock.t += 60
    report("control: 12 clients at once")
    assert lines[1] == "control: 12 clients at once (and 999 more like it before)"


def test_the_bus_port_does_not_look_at_its_socket_while_backing_off(monkeypatch) -> None:
    clock, lines = _Clock(), []
    ep = TcpEndpoint("127.0.0.1", 0, log=lines.append, clock=clock)
    real = ep.srv
    full = _FullSocket()
    try:
        monkeypatch.setattr(ep, "srv", full)
        monkeypatch.setattr("profidrive_cli.sim.server.select.select",
                            lambda r, w, x, t: ([full], [], []) if full in r else ([], [], []))
        monkeypatch.setattr("profidrive_cli.sim.server.time.sleep", lambda s: None)
        assert ep.read(0.01) == b""
        before = full.accepts
        for _ in range(100):                              # the back-off's time does not pass
            assert ep.read(0.01) == b""
        assert full.accepts == before and len(lines) == 1
    finally:
        ep.srv = real
        ep.close()


# -- hostile and careless clients -------------------------------------------------------------------

def test_deep_bodies_early_leavers_and_slow_clients_get_answers_not_tracebacks() -> None:
    sim = S.Sim()
    try:
        status, answer = S.http(sim.control, "POST", "/trip", "[" * 60000,
                                {"Content-Type": "application/json"})
        assert status == 400 and "nests deeper" in answer["error"], answer
        status, answer = S.http(sim.control, "POST", "/trip", '{"station": 3}' + " " * 70000)
        assert status == 400 and "request body" in answer["error"], answer
        status, answer = S.http(sim.control, "POST", "/trip", b"\xff[{")
        assert status == 400 and "not JSON" in answer["error"], answer
        for _ in range(20):
            S.leave_early(sim.control, b"POST /state HTTP/1.0\r\nContent-Length: 2\r\n\r\n{}")
            S.leave_early(sim.control, b"GET /state HTTP/1.0\r\n\r\n")
        status, answer = S.http(sim.control, "GET", "/state", headers={"Authorization": "Bearer \xe9"})
        assert status == 200 and [r["station"] for r in answer["stations"]] == [3, 4, 5, 6, 7]
        assert S.fdl_status(sim.bus) == S.FDL_STATUS_3_REPLY and sim.alive()
    finally:
        stderr = sim.stop()
    _clean(stderr)


def test_a_client_that_holds_its_connection_is_cut(monkeypatch) -> None:
    """A client that sends one octet now and then (never timing out a read) is shut down after
    MAX_CONNECTION_S (here 1 s; 30 in use) by the server's own loop."""
    from profidrive_cli.sim.plant import build_bus
    monkeypatch.setattr(control_http, "MAX_CONNECTION_S", 1.0)
    srv = control_http.ControlServer(Controller(build_bus("sim://")), log=lambda line: None).start()
    try:
        with socket.create_connection(("127.0.0.1", srv.port), timeout=30) as s:
            def cut() -> bool:
                try:
                    s.sendall(b"X")
                    s.settimeout(0.2)
                    return s.recv(1) == b""
                except socket.timeout:
                    return False
                except OSError:
                    return True
            assert _until(cut, 120.0, 0.2)
        assert srv.cut >= 1
    finally:
        srv.close()


def test_a_command_the_bus_did_not_take_is_withdrawn(monkeypatch) -> None:
    """A command that timed out waiting for the bus must not be run later (a trip its user was told
    had failed)."""
    from profidrive_cli.sim import control
    from profidrive_cli.sim.control import ControlBusy
    from profidrive_cli.sim.plant import build_bus
    monkeypatch.setattr(control, "TAKE_TIMEOUT_S", 0.01)
    bus = build_bus("sim://")
    with pytest.raises(ControlBusy, match="withdrawn"):
        QueuedController(bus).unplug(5)
    bus.run_pending(0.0)                              # the bus comes round at last
    assert 5 in bus.slaves and 5 not in bus.unplugged


# -- a web page in the user's browser ---------------------------------------------------------------

def test_foreign_origin_host_or_site_is_refused() -> None:
    sim = S.Sim()
    own = f"127.0.0.1:{sim.control[1]}"
    body = json.dumps({"station": 5})
    try:
        for headers, why in (
                ({"Origin": "http://evil.example", "Content-Type": "text/plain"}, "Origin"),
                ({"Origin": "null", "Content-Type": "text/plain"}, "Origin"),
                ({"Origin": f"http://127.0.0.1:{sim.control[1] ^ 1}"}, "Origin"),
                ({"Host": f"rebound.evil.example:{sim.control[1]}"}, "Host"),
                ({"Sec-Fetch-Site": "cross-site"}, "Sec-Fetch-Site")):
            status, answer = S.http(sim.control, "POST", "/unplug", body, headers)
            assert status == 403 and why in answer["error"], (headers, answer)
        status, answer = S.http(sim.control, "GET", "/state")
        assert {r["station"]: r["plugged"] for r in answer["stations"]}[5] is True
        # the server's own page, and a client without Origin (curl, sim-ctl), are obeyed
        status, answer = S.http(sim.control, "POST", "/unplug", body,
                                {"Origin": f"http://{own}", "Sec-Fetch-Site": "same-origin"})
        assert (status, answer) == (200, {"station": 5, "plugged": False})
        status, answer = S.http(sim.control, "POST", "/replug", body, {"Host": f"localhost:{sim.control[1]}"})
        assert status == 200, answer
        # GET does not steer the plant
        status, answer = S.http(sim.control, "GET", "/unplug")
        assert status == 405, answer
    finally:
        stderr = sim.stop()
    _clean(stderr)


# -- the token off loopback -------------------------------------------------------------------------

@pytest.mark.parametrize("host,needs", [("127.0.0.1", False), ("127.3.2.1", False), ("::1", False),
                                        ("localhost", False), ("0.0.0.0", True), ("", True),
                                        ("::", True), ("192.168.1.20", True), ("plc-sim.lan", True)])
def test_which_addresses_need_the_token(host: str, needs: bool) -> None:
    assert control_http.needs_token(host) is needs


@pytest.fixture()
def token_server(monkeypatch):
    """A control bound to 127.0.0.1 that decides, through needs_token, as one off loopback does."""
    from profidrive_cli.sim.plant import build_bus
    monkeypatch.setattr(control_http, "needs_token", lambda host: True)
    srv = control_http.ControlServer(Controller(build_bus("sim://")), "127.0.0.1", 0,
                                     log=lambda line: None).start()
    try:
        yield srv
    finally:
        srv.close()


def test_a_control_that_needs_its_token_takes_only_that_token(token_server) -> None:
    srv = token_server
    assert srv.token and len(srv.token) >= 20
    where = ("127.0.0.1", srv.port)
    for auth in (None, "Bearer wrong", f"Bearer {srv.token}x", f"Bearer {srv.token[:-1]}",
                 f"bearer{srv.token}", srv.token, "Bearer \xe9\xe9"):
        headers = {"Authorization": auth} if auth is not None else {}
        status, answer = S.http(where, "POST", "/unplug", json.dumps({"station": 5}), headers)
        assert status == 401 and "needs its token" in answer["error"], (auth, answer)
    status, answer = S.http(where, "POST", "/unplug", json.dumps({"station": 5}),
                            {"Authorization": f"Bearer {srv.token}"})
    assert (status, answer) == (200, {"station": 5, "plugged": False})


def _pdrive(capsys, *argv: str) -> tuple[int, str, str]:
    from profidrive_cli.cli.main import main
    try:
        main(list(argv))
        code = 0
    except SystemExit as e:
        code = int(e.code or 0)
    got = capsys.readouterr()
    return code, got.out, got.err


def test_sim_ctl_with_a_wrong_or_right_token(token_server, capsys, monkeypatch) -> None:
    monkeypatch.delenv("PDRIVE_SIM_TOKEN", raising=False)
    where = f"127.0.0.1:{token_server.port}"
    code, out, err = _pdrive(capsys, "sim-ctl", "--control", where, "--token", "wrong", "state")
    assert code == 1 and "needs its token" in err and err.count("\n") == 1, err
    code, out, err = _pdrive(capsys, "sim-ctl", "--control", where, "--token", token_server.token,
                             "state", "--json")
    assert code == 0, err
    assert [row["station"] for row in json.loads(out)["stations"]] == [3, 4, 5, 6, 7]


# -- the bus never waits for the control ------------------------------------------------------------

def test_a_hung_control_does_not_stall_the_bus_port() -> None:
    """Every control connection stuck in a command that never ends (a hung control): the bus port
    still answers a master. (A guard: the bus loop shares nothing with the control but the queue of
    commands, which it only empties.)"""
    import threading

    from profidrive_cli.sim import server
    from profidrive_cli.sim.plant import build_bus

    release = threading.Event()

    class Hung(Controller):
        def call(self, command, args=None):
            release.wait(120)
            return {}

    bus = build_bus("sim://")
    ep = TcpEndpoint("127.0.0.1", 0, log=lambda line: None)
    stop = threading.Event()
    loop = threading.Thread(target=server.serve, args=(bus, ep), kwargs={"stop": stop.is_set}, daemon=True)
    ctl = control_http.ControlServer(Hung(bus), log=lambda line: None, max_clients=4).start()
    stuck: list[socket.socket] = []
    try:
        loop.start()
        for _ in range(6):                         # 4 held in the hung command, 2 answered 503
            s = socket.create_connection(("127.0.0.1", ctl.port), timeout=30)
            s.sendall(b"GET /state HTTP/1.0\r\n\r\n")
            stuck.append(s)
        assert _until(lambda: ctl.refused_busy >= 2)
        assert S.fdl_status(ep.address) == S.FDL_STATUS_3_REPLY
    finally:
        release.set()
        for s in stuck:
            s.close()
        ctl.close()
        stop.set()
        loop.join(30)
        ep.close()
