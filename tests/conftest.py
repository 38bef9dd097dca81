import contextlib
import os
import shutil
import subprocess
import sys
import tempfile
import time

import pytest

SHARED = os.path.join(os.path.dirname(__file__), "..", "..", "shared")

# The cache of parsed profiles (profidrive_cli/datacache.py) is off for the tests and every process
# they start: nothing is written to the developer's ~/.cache, and no test reads what another left
# there (tests/test_datacache.py turns it on in a folder of its own).
os.environ["PDRIVE_CACHE_DIR"] = "off"


def pdrive_cmd() -> list[str]:
    """How to start pdrive as a separate process (the installed console script if there is one)."""
    exe = shutil.which("pdrive")
    return [exe] if exe else [sys.executable, "-m", "profidrive_cli"]


@pytest.fixture
def socat_pair(tmp_path):
    """Two linked ptys from socat: (a, b). Skips when socat is absent (CI installs it)."""
    if not shutil.which("socat"):
        pytest.skip("socat not installed")
    a, b = str(tmp_path / "ttyA"), str(tmp_path / "ttyB")
    p = subprocess.Popen(["socat", f"pty,raw,echo=0,ignoreeof,link={a}",
                          f"pty,raw,echo=0,ignoreeof,link={b}"],
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    for _ in range(200):
        if os.path.exists(a) and os.path.exists(b):
            break
        time.sleep(0.01)
    else:
        p.kill()
        pytest.fail("socat did not create its ptys")
    yield a, b
    p.terminate()
    p.wait(timeout=5)


@pytest.fixture
def sim(monkeypatch):
    """sim:// whose plant survives closing the port (like `pdrive sim`), one bus per URL."""
    from profidrive_cli.sim import plant
    real = plant.build_bus
    buses = {}

    def cached(url, now=0.0, **kw):
        if url not in buses:
            buses[url] = real(url, now, **kw)
        return buses[url]
    monkeypatch.setattr(plant, "build_bus", cached)
    return buses


def drive_on_bus(master, address, profile, layout, wd_ms=500):
    """A Drive for `profile`/`layout` on a station of `master`, brought to Data_Exchange."""
    from profidrive_cli.dp.poller import StationChannel
    from profidrive_cli.dp.station import SlaveConfig
    from profidrive_cli.drives import make_drive
    master.add_station(address, SlaveConfig(ident=profile.ident, cfg=profile.layouts[layout].cfg,
                                            wd_ms=wd_ms))
    master.bring_up(address)
    return make_drive(StationChannel(master, address), profile, layout)


class TcpSim:
    """`pdrive sim --listen` in a thread of the test process, so a test can look at the bus directly.

        with TcpSim("sim://?stations=3:fuji-g1") as srv:
            srv.url        socket://127.0.0.1:PORT
            srv.bus        the SimBus behind it
            srv.ep         the TcpEndpoint (accepted, refused, request_drop())

    `endpoint` makes the endpoint (a subclass to model a slow converter, say)."""

    def __init__(self, plant: str, endpoint=None):
        import threading

        from profidrive_cli.sim import server
        from profidrive_cli.sim.plant import build_bus
        self.bus = build_bus(plant)
        self.ep = (endpoint or server.TcpEndpoint)("127.0.0.1", 0)
        self.url = f"socket://127.0.0.1:{self.ep.address[1]}"
        self._stop = []
        self._th = threading.Thread(target=server.serve,
                                    args=(self.bus, self.ep, lambda: bool(self._stop)), daemon=True)
        self._th.start()

    def wait_accepted(self, n: int = 1, timeout: float = 5.0) -> None:
        end = time.monotonic() + timeout
        while self.ep.accepted < n and time.monotonic() < end:
            time.sleep(0.01)

    def close(self) -> None:
        self._stop.append(1)
        self._th.join(timeout=5)
        self.ep.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def like_hardware():
    """preexec_fn of a simulator process: the simulated slaves answer as hardware does, within their
    TSDR and with their own watchdog clock whatever the load of the machine the master runs on: the
    simulator process is scheduled before ordinary busy processes (nice -10; as root, as CI runs;
    elsewhere it runs as it is). At load 8 without it, `pdrive scan` missed stations (their replies
    came after slot time + retries: the simulator had not run), which says nothing about the master."""
    try:
        os.nice(-10)
    except OSError:
        pass


#: the control URL of every `pdrive sim --pty` a test started and has not stopped yet (by process)
_LIVE_SIMS: dict = {}


def start_pty_sim(*extra: str):
    """`pdrive sim --pty --json [extra…]` in a subprocess: (the process, the pty path). Its plant
    persists between commands, like a real bus; it runs like hardware (like_hardware). It also
    serves its control on loopback, through which a drive left in fault by one test is cleared
    before the next (_no_fault_reaches_the_next_test)."""
    import json
    if "--control" not in extra:
        extra = (*extra, "--control", "127.0.0.1:0")
    p = subprocess.Popen(pdrive_cmd() + ["sim", "--pty", "--json", *extra], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, preexec_fn=like_hardware)
    line = p.stdout.readline()
    if not line:
        p.kill()
        pytest.fail("pdrive sim printed nothing: " + p.stderr.read())
    first = json.loads(line)
    if first.get("control") and not first.get("token"):
        _LIVE_SIMS[p] = first["control"]
    return p, first["port"]


def _clear_faults(control: str) -> list:
    """Every drive of a running simulator that holds a fault, cleared as a keypad reset would
    (sim-ctl clear): the stations cleared. A simulator that does not answer is left alone."""
    import json
    import urllib.request
    cleared = []
    try:
        with urllib.request.urlopen(control + "/state", timeout=30) as r:
            rows = json.loads(r.read())["stations"]
    except (OSError, ValueError, KeyError):
        return cleared
    for row in rows:
        if not (row.get("plugged") and row.get("fault")):
            continue
        req = urllib.request.Request(control + "/clear", method="POST",
                                     data=json.dumps({"station": row["station"]}).encode(),
                                     headers={"Content-Type": "application/json"})
        try:                  # (a setting error, Yaskawa's OPE, is no fault to clear: refused)
            with urllib.request.urlopen(req, timeout=30):
                cleared.append(row["station"])
        except OSError:
            pass
    return cleared


@pytest.fixture(autouse=True)
def _no_fault_reaches_the_next_test():
    """A simulator shared by the tests of a module (a module-scoped `pdrive sim --pty`) carries its
    drives from one test to the next, like a real bus. A test that ends with a drive in fault (its
    master stalled past the watchdog at load, say: E70, Er5) has had its say in its own assertions;
    the next test starts with that fault cleared, as an engineer would reset the drive."""
    yield
    for p, control in list(_LIVE_SIMS.items()):
        if p.poll() is None:
            _clear_faults(control)


def stop_pty_sim(p) -> None:
    """SIGINT ends `pdrive sim` cleanly; killed if it does not end within 10 s."""
    import signal
    _LIVE_SIMS.pop(p, None)
    p.send_signal(signal.SIGINT)
    try:
        p.wait(timeout=10)
    except subprocess.TimeoutExpired:
        p.kill()
        p.wait()


@contextlib.contextmanager
def pty_sim_process(*extra: str):
    """start_pty_sim() for a with-block: yields the pty path, ends the simulator afterwards."""
    p, port = start_pty_sim(*extra)
    try:
        yield port
    finally:
        stop_pty_sim(p)


def read_until_turning(p, phase: str = "running", deadline_s: float = 20.0, min_hz: float = 1.0):
    """Read a run's or jog's JSON stream (`p`, a Popen with text stdout) until an update in `phase`
    shows the motor turning (|actual| above min_hz); return the events so far. Fails the test (and
    kills the process) when it does not turn within deadline_s."""
    import json
    import select
    events = []
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        r, _, _ = select.select([p.stdout], [], [], 0.5)
        if not r:
            continue
        line = p.stdout.readline()
        if not line:
            break
        ev = json.loads(line)
        events.append(ev)
        if ev["event"] == "update" and ev["phase"] == phase and abs(ev["actual_hz"] or 0) > min_hz:
            return events
    p.kill()
    pytest.fail(f"the motor never turned ({phase}): {events[-3:]} {p.stderr.read()}")


@pytest.fixture(autouse=True)
def _no_user_config(tmp_path_factory, monkeypatch):
    """A developer's own ~/.config/pdrive/config.yaml must not change what the tests see: the user
    config folder is an empty one for every test (tests of the config file set their own)."""
    home = tmp_path_factory.getbasetemp() / "xdg-config-home"
    home.mkdir(exist_ok=True)
    monkeypatch.setenv("XDG_CONFIG_HOME", str(home))
    monkeypatch.delenv("PDRIVE_CONFIG", raising=False)


@pytest.fixture
def no_config_at_all(monkeypatch, tmp_path):
    """No config file and no PDRIVE_* setting at all: an empty PDRIVE_CONFIG file (so no pdrive.yaml
    above the checkout counts either) and the environment variables cleared."""
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    (tmp_path / "empty.yaml").write_text("")
    monkeypatch.setenv("PDRIVE_CONFIG", str(tmp_path / "empty.yaml"))
    for name in ("PDRIVE_PORT", "PDRIVE_BAUD", "PDRIVE_STATION"):
        monkeypatch.delenv(name, raising=False)


#: the ramp parameters of the default plant's stations that `short_ramps_pty_sim` sets to 0.3 s (Toyo's
#: ramps are fixed: 5 s to 60 Hz)
SHORT_RAMPS = {3: ("F07", "F08"), 4: ("F07", "F08"), 6: ("F002", "F003"), 7: ("C1-01", "C1-02")}


def run_pdrive(*args, timeout=60):
    """pdrive as a separate process without a terminal (stdin from /dev/null)."""
    return subprocess.run(pdrive_cmd() + [str(a) for a in args], capture_output=True, text=True,
                          timeout=timeout, stdin=subprocess.DEVNULL)


@contextlib.contextmanager
def short_ramps_pty_sim(tmp_path_factory):
    """`pdrive sim --pty` with the default plant, every station's ramps set to 0.3 s by one
    `param restore` each (quick tests of runs and stops over a real byte path); yields the pty."""
    with pty_sim_process() as port:
        for addr, codes in SHORT_RAMPS.items():
            f = tmp_path_factory.mktemp("ramps") / f"{addr}.yaml"
            f.write_text("parameters:\n" + "".join(f"  {c}: 0.3\n" for c in codes))
            r = run_pdrive("param", "restore", addr, f, "--port", port, "--yes")
            assert r.returncode == 0 and "2 applied" in r.stdout, r.stdout + r.stderr
        yield port


def status_of(port, address) -> dict:
    """`pdrive status ADDRESS --json` over `port`, parsed."""
    import json
    r = run_pdrive("status", address, "--port", port, "--json")
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


class MainResult:
    """What pdrive's own entry point did in this process: exit code, stdout, stderr (and both)."""

    def __init__(self, code, out, err):
        self.exit_code, self.stdout, self.stderr = code, out, err
        self.output = out + err


def run_main(capsys, monkeypatch, *args) -> MainResult:
    """pdrive's own entry point (cli.main.main) in this process, PDRIVE_PORT unset."""
    from profidrive_cli.cli.main import main
    monkeypatch.delenv("PDRIVE_PORT", raising=False)
    capsys.readouterr()
    with pytest.raises(SystemExit) as e:
        main([str(a) for a in args])
    got = capsys.readouterr()
    return MainResult(e.value.code, got.out, got.err)


# -- ptys are POSIX-only ---------------------------------------------------------------------------

#: what in a test module says it needs a pty (pdrive sim --pty, socat's ptys, os.openpty)
PTY_MARKERS = ("--pty", "openpty", "socat_pair", "start_pty_sim", "pty_sim_process", "short_ramps_pty_sim")


def needs_pty(source: str) -> bool:
    """The test module uses a pseudo-terminal (see PTY_MARKERS)."""
    return any(m in source for m in PTY_MARKERS)


def pytest_collection_modifyitems(config, items):
    """Where there are no ptys (Windows), the tests that need one are skipped with the reason,
    instead of failing: `pdrive sim --listen` + socket:// covers the same paths there."""
    if os.name == "posix":
        return
    skip = pytest.mark.skip(reason="ptys are POSIX-only (on Windows: pdrive sim --listen and socket://)")
    seen: dict = {}
    for item in items:
        path = str(item.fspath)
        if path not in seen:
            try:
                with open(path, encoding="utf-8") as f:
                    seen[path] = needs_pty(f.read())
            except OSError:
                seen[path] = False
        if seen[path]:
            item.add_marker(skip)


#: Debian's headless browser (CI installs it): the monitor's page is checked as a browser renders it
CHROMIUM = shutil.which("chromium") or ("/usr/bin/chromium" if os.path.exists("/usr/bin/chromium")
                                        else None)


def chromium(url: str, *extra: str) -> str:
    """What headless Chromium prints for `url` (e.g. with --dump-dom: the DOM after the scripts ran,
    10 s of the page's virtual time); killed after 120 s."""
    with tempfile.TemporaryDirectory() as profile:
        p = subprocess.Popen(
            [CHROMIUM or "chromium", "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
             "--no-first-run", "--disable-background-networking", "--disable-component-update",
             "--disable-sync", f"--user-data-dir={profile}", "--virtual-time-budget=10000",
             *extra, url],
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        try:
            out, _ = p.communicate(timeout=120)
        finally:
            if p.poll() is None:
                p.kill()
                p.wait()
        return out
