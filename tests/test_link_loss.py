"""The port goes away mid-run: LinkLost with a clear message and the counters; Master.reconnect()
brings every station back; meanwhile the slave's watchdog stops the simulated drive.

Over: the in-process sim (a simulated unplug), pdrive's sim server on TCP in a thread (the bus is
inspected directly), `pdrive sim --listen` behind a TCP proxy that drops and re-accepts, and
`pdrive sim --port` on a socat pty pair whose socat ends and comes back.
"""

import json
import os
import shutil
import signal
import socket
import subprocess
import threading
import time

import pytest

from conftest import TcpSim, pdrive_cmd
from profidrive_cli import BusError
from profidrive_cli.dp.poller import Master
from profidrive_cli.dp.station import SlaveConfig
from profidrive_cli.drives import make_drive
from profidrive_cli.drives.profile import load_profile
from profidrive_cli.fdl.timing import BusParams
from profidrive_cli.link import LinkLost, open_link

FUJI = SlaveConfig(ident=0xFD01, cfg=bytes.fromhex("F3F1"), wd_ms=200)


def _real_params():
    # what the CLI uses on a real port: a latency margin for the OS / converter
    return BusParams.for_baud(19200, retries=2, link_latency=0.05)


def _running_fuji(m):
    """Station 3 in data exchange with its Fuji drive turning."""
    m.add_station(3, FUJI)
    m.bring_up(3)
    prof = load_profile("fuji-g1")
    d = make_drive(m.channel(3), prof, "ppo1")
    d.set_speed_hz(10.0)
    st = d.start()
    assert st.running
    return d


def _until(cond, timeout=5.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.01)
    return False


# -- in-process simulated unplug ------------------------------------------------------------------

def test_unplugged_sim_raises_link_lost_with_counters_and_reconnects():
    link = open_link("sim://?stations=3:fuji-g1,7:yaskawa")
    m = Master(link, BusParams.for_baud(19200))
    m.add_station(3, FUJI)
    m.bring_up(3)
    for _ in range(5):
        m.exchange(3, bytes(12))
    link.ser.unplug()
    with pytest.raises(LinkLost) as ei:
        m.exchange(3, bytes(12))
    e = ei.value
    text = str(e)
    assert text.startswith("link lost: sim://?stations=3:fuji-g1,7:yaskawa: port lost")
    assert "station 3: " in text and " req" in text
    assert e.port == "sim://?stations=3:fuji-g1,7:yaskawa"
    assert e.counters[3]["data_exchanges"] == 5
    assert m.link_losses == 1 and not m.fdl.busy
    with pytest.raises(LinkLost):
        m.poll()                      # still gone
    m.reconnect(timeout=2.0)          # sim:// comes back as a fresh plant
    assert m.reconnects == 1 and m.stations[3].in_data_exchange
    assert m.fdl.counters[3].reparams == 1
    assert link.bus.slave(3).state == "Data_Exch"
    m.exchange(3, bytes(12))


def test_reconnect_gives_up_when_the_port_stays_away(tmp_path):
    if not shutil.which("socat"):
        pytest.skip("socat not installed")
    a, b = str(tmp_path / "A"), str(tmp_path / "B")
    p = _socat(a, b)
    sim = _start(["sim", "--json", "--port", a])
    try:
        m = Master(open_link(b), _real_params())
        m.add_station(7, SlaveConfig(ident=0x00CA, cfg=bytes.fromhex("5F6F"), wd_ms=200))
        m.bring_up(7)
        _stop(p)
        with pytest.raises(LinkLost, match=f"link lost: {b}: port lost"):
            for _ in range(50):
                m.exchange(7, bytes(32))
        t = time.monotonic()
        with pytest.raises(LinkLost, match="did not come back within 0.5 s"):
            m.reconnect(timeout=0.5)
        # it gave up after the 0.5 s asked for, not the default 10 s (Master.reconnect): a bound of
        # half the default says so whatever the load (3 s was a guess a busy machine could miss)
        assert time.monotonic() - t < 10.0 / 2
    finally:
        _stop(sim)


# -- pdrive's sim server over TCP, in a thread: look at the bus directly ----------------------------

def test_tcp_drop_watchdog_stops_drive_and_reconnect_restores():
    with TcpSim("sim://?stations=3:fuji-g1") as srv:
        bus, ep = srv.bus, srv.ep
        m = Master(open_link(srv.url), _real_params())
        d = _running_fuji(m)
        model = bus.slave(3).model
        assert model.running
        ep.request_drop()                                 # the converter loses the connection
        with pytest.raises(LinkLost, match="link lost: socket://"):
            for _ in range(100):
                d.status()
        # nobody talks to station 3 now: its 200 ms watchdog ends data exchange and the Fuji
        # card applies o27 = 0 (coast to stop, Er5)
        assert _until(lambda: bus.slave(3).stats["watchdog_expired"] == 1)
        assert _until(lambda: model.state.name == "FAULT")
        assert model.freq == 0.0 and not model.running
        m.reconnect(timeout=5.0)                          # the server accepts again
        assert ep.accepted == 2
        st = d.status()
        assert st.fault and st.fault_code == "Er5" and not st.running
        c = m.fdl.counters[3]
        assert c.reparams == 1 and m.reconnects == 1 and m.link_losses == 1
        m.release(3)
        m.link.close()


# -- `pdrive sim --listen` behind a proxy that drops the connection -------------------------------

def _start(args):
    p = subprocess.Popen(pdrive_cmd() + args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = p.stdout.readline()
    if not line:
        p.kill()
        pytest.fail("pdrive sim printed nothing: " + p.stderr.read())
    p.info = json.loads(line)
    return p


def _stop(p):
    p.send_signal(signal.SIGINT if p.args[0] != "socat" else signal.SIGTERM)
    try:
        p.wait(timeout=10)
    except subprocess.TimeoutExpired:
        p.kill()
        p.wait()


class Proxy:
    """TCP proxy: client <-> upstream. cut() drops both sides and refuses clients; resume() listens
    again on the same port."""

    def __init__(self, upstream):
        self.upstream = upstream
        self.port = None
        self.pairs = []
        self._listen()

    def _listen(self):
        self.srv = socket.socket()
        self.srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.srv.bind(("127.0.0.1", self.port or 0))
        self.port = self.srv.getsockname()[1]
        self.srv.listen(1)
        self.alive = True
        threading.Thread(target=self._accept, args=(self.srv,), daemon=True).start()

    def _accept(self, srv):
        while self.alive:
            try:
                c, _ = srv.accept()
            except OSError:
                return
            u = socket.create_connection(self.upstream)
            for s in (c, u):
                s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self.pairs.append((c, u))
            threading.Thread(target=self._pump, args=(c, u), daemon=True).start()
            threading.Thread(target=self._pump, args=(u, c), daemon=True).start()

    @staticmethod
    def _pump(a, b):
        try:
            while True:
                data = a.recv(4096)
                if not data:
                    break
                b.sendall(data)
        except OSError:
            pass
        for s in (a, b):
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass

    def cut(self):
        self.alive = False
        try:
            # shutdown first: a close() alone leaves the socket listening while the accept thread
            # is blocked in accept() on it, and the next client would still get through
            self.srv.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self.srv.close()
        for c, u in self.pairs:
            for s in (c, u):
                try:
                    s.shutdown(socket.SHUT_RDWR)
                    s.close()
                except OSError:
                    pass
        self.pairs = []

    def resume(self):
        self._listen()


def test_pdrive_sim_listen_connection_dropped_and_reaccepted():
    sim = _start(["sim", "--json", "--listen", "127.0.0.1:0", "--plant", "sim://?stations=3:fuji-g1"])
    host, port = sim.info["port"].removeprefix("socket://").split(":")
    proxy = Proxy((host, int(port)))
    try:
        m = Master(open_link(f"socket://127.0.0.1:{proxy.port}"), _real_params())
        d = _running_fuji(m)
        proxy.cut()
        with pytest.raises(LinkLost) as ei:
            for _ in range(100):
                d.status()
        assert f"127.0.0.1:{proxy.port}" in str(ei.value) and "station 3:" in str(ei.value)
        assert ei.value.counters[3]["data_exchanges"] > 0
        threading.Timer(0.6, proxy.resume).start()        # the converter comes back later
        m.reconnect(timeout=10.0)
        assert m.stations[3].in_data_exchange
        # the watchdog (200 ms) stopped the drive behind pdrive sim while the link was down
        st = d.status()
        assert st.fault and st.fault_code == "Er5" and not st.running
        m.release(3)
        m.link.close()
    finally:
        proxy.cut()
        _stop(sim)


# -- `pdrive sim --port` on a socat pty pair whose socat goes away and comes back ---------------

def _socat(a, b):
    p = subprocess.Popen(["socat", f"pty,raw,echo=0,ignoreeof,link={a}",
                          f"pty,raw,echo=0,ignoreeof,link={b}"],
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    if not _until(lambda: os.path.exists(a) and os.path.exists(b), 3.0):
        p.kill()
        pytest.fail("socat did not create its ptys")
    return p


def test_pty_pair_goes_away_and_comes_back(tmp_path):
    if not shutil.which("socat"):
        pytest.skip("socat not installed")
    a, b = str(tmp_path / "A"), str(tmp_path / "B")
    pair = _socat(a, b)
    sim = _start(["sim", "--json", "--port", a, "--plant", "sim://?stations=3:fuji-g1"])
    try:
        m = Master(open_link(b), _real_params())
        d = _running_fuji(m)
        _stop(pair)                                       # the "adapter" is pulled
        with pytest.raises(LinkLost, match=f"link lost: {b}"):
            for _ in range(100):
                d.status()
        time.sleep(0.5)
        pair = _socat(a, b)                               # ... and plugged in again
        m.reconnect(timeout=10.0)
        st = d.status()
        assert st.fault and st.fault_code == "Er5" and not st.running
        assert m.fdl.counters[3].reparams == 1
        m.release(3)
        m.link.close()
    finally:
        _stop(pair)
        _stop(sim)


def test_reconnect_names_stations_that_do_not_come_back():
    link = open_link("sim://?stations=3:fuji-g1")
    m = Master(link, BusParams.for_baud(19200))
    m.add_station(3, FUJI)
    m.bring_up(3)
    link.ser.unplug()
    with pytest.raises(LinkLost):
        m.exchange(3, bytes(12))
    link.name = "sim://?stations=4:fuji-pdp3"            # the port comes back with another plant
    with pytest.raises(BusError, match="after reconnecting: station 3 did not reach data exchange"):
        m.reconnect(timeout=0.3)


def test_run_reconnect_resumes_and_leaves_the_drive_stopped():
    """`pdrive run --reconnect`: the converter goes away mid-run; the run says so, waits, resumes
    data exchange when it returns, does not restart the motor, and ends with it stopped."""
    sim = _start(["sim", "--json", "--listen", "127.0.0.1:0", "--plant", "sim://?stations=3:fuji-g1"])
    host, port = sim.info["port"].removeprefix("socket://").split(":")
    proxy = Proxy((host, int(port)))
    url = f"socket://127.0.0.1:{proxy.port}"
    try:
        run = subprocess.Popen(pdrive_cmd() + ["run", "3", "--port", url, "--hz", "20", "--duration", "30",
                                               "--reconnect", "20", "--json", "--watchdog", "200", "--yes"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        events = []
        for line in run.stdout:
            ev = json.loads(line)
            events.append(ev)
            if ev.get("event") == "update" and ev.get("running") and ev.get("actual_hz", 0) > 1.0:
                break
        proxy.cut()
        threading.Timer(1.0, proxy.resume).start()
        rest, errtext = run.communicate(timeout=60)
        events += [json.loads(x) for x in rest.splitlines() if x.strip()]
        phases = [e.get("phase", "") for e in events if e.get("event") == "phase"]
        assert any(p.startswith("link lost") for p in phases), phases
        assert any(p.startswith("link restored") for p in phases), phases
        end = events[-2]
        assert end["event"] == "end" and end["stopped"] and "link lost and restored" in end["reason"]
        # then the error object of the stream (docs/json.md), with the exit code
        assert events[-1]["event"] == "error" and events[-1]["exit_code"] == 1
        assert run.returncode == 1
        st = subprocess.run(pdrive_cmd() + ["status", "3", "--port", url, "--json"],
                            capture_output=True, text=True, timeout=60)
        assert st.returncode == 0, st.stderr
        assert json.loads(st.stdout)["running"] is False
    finally:
        proxy.cut()
        _stop(sim)


# -- a vanished device: every read, write and flush is LinkLost (EIO on a pty) -------------------


@pytest.mark.parametrize("op", ["flush_input", "read", "write"])
def test_a_pty_whose_other_end_closed_is_link_lost_in_every_operation(op):
    """A cable pull on a pty: the other end closes and the kernel answers EIO (tcflush raises
    termios.error, not OSError: flush_input gave a traceback and --reconnect was not tried)."""
    from profidrive_cli.link.serial_link import SerialLink
    m, s = os.openpty()
    link = SerialLink(os.ttyname(s), 19200)
    os.close(s)
    os.close(m)                                          # the other end goes away
    try:
        with pytest.raises(LinkLost) as e:
            if op == "flush_input":
                link.flush_input()
            elif op == "read":
                link.read(link.now() + 0.5)
            else:
                link.write(bytes.fromhex("10 03 02 49 4E 16"))
        assert str(e.value).startswith(f"{link.name}: port lost")
        assert e.value.port == link.name
    finally:
        link.close()


class _VanishedSerial:
    """A pyserial-like port (not a POSIX fd read by os.read) whose device is gone."""

    def __init__(self, exc):
        self.exc = exc
        self.write_timeout = 2.0

    @property
    def in_waiting(self):
        raise self.exc

    def read(self, n=1):
        raise self.exc

    def write(self, data):
        raise self.exc

    def reset_input_buffer(self):
        raise self.exc

    def close(self):
        pass


def _eio_termios():
    import termios
    return termios.error(5, "Input/output error")


@pytest.mark.parametrize("make_exc", [_eio_termios, lambda: OSError(5, "Input/output error")],
                         ids=["termios.error", "OSError"])
@pytest.mark.parametrize("op", ["flush_input", "read", "write"])
def test_eio_from_the_port_object_is_link_lost(make_exc, op):
    from profidrive_cli.link.serial_link import SerialLink
    link = SerialLink.__new__(SerialLink)
    link.name, link.baud, link.echo, link._recent = "/dev/ttyUSB9", 19200, False, b""
    link.ser = _VanishedSerial(make_exc())
    link._posix = link._fd_read = False
    link._clock = link.now = time.monotonic
    with pytest.raises(LinkLost) as e:
        if op == "flush_input":
            link.flush_input()
        elif op == "read":
            link.read(time.monotonic() + 0.1)
        else:
            link.write(b"\xE5")
    assert "port lost" in str(e.value) and "Input/output error" in str(e.value)
    assert "[Errno 5]" in str(e.value)                   # termios.error's tuple put in words
