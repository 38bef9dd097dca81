"""Windows as a first-class platform (issue 26), as far as a Linux machine can test it.

No POSIX-only module is imported at import time, read from the source as the layering tests read
imports: a module-level import of a standard module Windows does not have (termios, fcntl, pty, tty,
resource, grp, pwd) must sit under a platform test (`if os.name == "posix":`, `sys.platform`) or a
`try: ... except ImportError`; inside a function it is loaded only when that POSIX-only path runs (a
pty, a serial port's parity marking). And the user's config file is where Windows programs keep
theirs (%APPDATA%)."""

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parent.parent / "profidrive_cli"
POSIX_ONLY = {"termios", "fcntl", "pty", "tty", "resource", "grp", "pwd"}


def _guarded(test: ast.expr) -> bool:
    text = ast.unparse(test)
    return "os.name" in text or "sys.platform" in text or "platform.system" in text


def _unguarded_imports(body: list[ast.stmt]) -> list[tuple[int, str]]:
    out: list[tuple[int, str]] = []
    for node in body:
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names if a.name.split(".")[0] in POSIX_ONLY]
        elif isinstance(node, ast.ImportFrom):
            if (node.module or "").split(".")[0] in POSIX_ONLY:
                out.append((node.lineno, node.module or ""))
        elif isinstance(node, ast.If):
            if not _guarded(node.test):
                out += _unguarded_imports(node.body) + _unguarded_imports(node.orelse)
        elif isinstance(node, ast.Try):
            catches = {ast.unparse(h.type) for h in node.handlers if h.type is not None}
            if not catches & {"ImportError", "ModuleNotFoundError"}:
                out += _unguarded_imports(node.body)
        elif isinstance(node, ast.ClassDef):
            out += _unguarded_imports(node.body)        # a class body runs at import time
    return out


def test_no_module_imports_a_posix_only_module_at_import_time():
    bad = []
    for f in sorted(PKG.rglob("*.py")):
        tree = ast.parse(f.read_text(encoding="utf-8"))
        bad += [f"{f.relative_to(PKG.parent).as_posix()}:{line}: import {name}"
                for line, name in _unguarded_imports(tree.body)]
    assert bad == [], "\n".join(bad)


def test_the_check_finds_an_unguarded_import():
    # made-up modules: a bare `import tty` and one inside a class body are found; a guarded one,
    # one under try/except ImportError and one inside a function are not
    src = ("import tty\n"
           "class A:\n    import fcntl\n"
           "if os.name == 'posix':\n    import termios\n"
           "try:\n    import pty\nexcept ImportError:\n    pty = None\n"
           "def f():\n    import resource\n")
    assert _unguarded_imports(ast.parse(src).body) == [(1, "tty"), (3, "fcntl")]


# -- the config file where Windows programs keep theirs ---------------------------------------------

def test_the_user_config_file_on_windows_is_under_appdata():
    from profidrive_cli.config import user_config_path
    appdata = Path("/c/Users/u/AppData/Roaming")             # %APPDATA% (a Linux path stands in)
    assert user_config_path({"APPDATA": str(appdata)}, platform="win32") == appdata / "pdrive" / "config.yaml"
    # no APPDATA: the user profile's AppData\Roaming, as Windows sets APPDATA by default
    assert user_config_path({"USERPROFILE": "/c/Users/u"}, platform="win32") == \
        Path("/c/Users/u") / "AppData" / "Roaming" / "pdrive" / "config.yaml"
    # XDG_CONFIG_HOME, when set, wins everywhere; elsewhere ~/.config as before
    assert user_config_path({"XDG_CONFIG_HOME": "/x", "APPDATA": str(appdata)}, platform="win32") == \
        Path("/x/pdrive/config.yaml")
    assert user_config_path({"HOME": "/home/u", "APPDATA": str(appdata)}, platform="linux") == \
        Path("/home/u/.config/pdrive/config.yaml")


# -- doctor on a COM port: the FTDI latency timer from the registry ---------------------------------

class FakeWinreg:
    """winreg's calls doctor uses, over a dict: key path -> {value name: value} (subkeys by path)."""
    HKEY_LOCAL_MACHINE = "HKLM"

    def __init__(self, keys):
        self.keys = keys

    def OpenKey(self, root, path):
        if path not in self.keys:
            raise OSError(2, "not found")
        return path

    def EnumKey(self, key, i):
        subs = sorted({k[len(key) + 1:].split("\\")[0] for k in self.keys if k.startswith(key + "\\")})
        if i >= len(subs):
            raise OSError(259, "no more data")
        return subs[i]

    def QueryValueEx(self, key, name):
        values = self.keys[key]
        if name not in values:
            raise OSError(2, "no value")
        return values[name], 4


def ftdi(port_name, latency, device="VID_0403+PID_6001+A1B2C3D4A"):
    from profidrive_cli.dp.winports import FTDIBUS
    return {f"{FTDIBUS}\\{device}\\0000\\Device Parameters": {"PortName": port_name, "LatencyTimer": latency}}


def test_ftdi_latency_is_read_for_the_port_asked():
    from profidrive_cli.dp.winports import FTDIBUS, ftdi_latency
    keys = {FTDIBUS: {}, **ftdi("COM3", 16), **ftdi("COM7", 1, "VID_0403+PID_6015+XYZ")}
    reg = FakeWinreg(keys)
    key, ms = ftdi_latency("com3", reg)                       # case-blind, as Windows names ports
    assert ms == 16 and key == f"HKLM\\{FTDIBUS}\\VID_0403+PID_6001+A1B2C3D4A\\0000\\Device Parameters"
    assert ftdi_latency("COM7", reg)[1] == 1
    assert ftdi_latency("COM9", reg) == (None, None)          # not an FTDI port
    assert ftdi_latency("COM3", FakeWinreg({})) == (None, None)    # no FTDI driver installed


def _doctor(monkeypatch, port, keys, ports=("COM1", "COM3")):
    import profidrive_cli.dp.doctor as D
    from profidrive_cli.dp.doctor import diagnose
    monkeypatch.setattr(D, "com_ports", lambda: list(ports))
    rep = diagnose(port, platform="win32", winreg=FakeWinreg(keys), listen_s=0.0)
    return {c.name: c for c in rep.checks}


def test_doctor_names_a_high_latency_timer_and_how_to_lower_it(monkeypatch):
    from profidrive_cli.dp.winports import FTDIBUS
    checks = _doctor(monkeypatch, "COM3", {FTDIBUS: {}, **ftdi("COM3", 16)})
    lt = checks["latency_timer"]
    assert lt.status == "warn" and lt.data["ms"] == 16
    assert "Device Manager > Ports (COM & LPT)" in lt.detail and "Latency Timer (msec): 1" in lt.detail
    assert checks["permission"].status == "skip"


def test_doctor_is_content_with_1_ms_and_says_when_there_is_no_ftdi(monkeypatch):
    from profidrive_cli.dp.winports import FTDIBUS
    assert _doctor(monkeypatch, "COM3", {FTDIBUS: {}, **ftdi("COM3", 1)})["latency_timer"].status == "ok"
    assert _doctor(monkeypatch, "COM3", {})["latency_timer"].status == "skip"


def test_doctor_on_a_com_port_windows_does_not_list(monkeypatch):
    checks = _doctor(monkeypatch, "COM9", {})
    assert checks["port"].status == "fail"
    assert checks["port"].detail == "COM9: no such port (ports here: COM1, COM3)"


def test_doctor_says_whether_the_port_checks_parity():
    # a POSIX serial device marks bad-parity octets (link/parity.py); pyserial on Windows cannot,
    # and doctor says so instead of staying silent
    from types import SimpleNamespace
    from profidrive_cli.dp.doctor import Report, parity_check
    rep = Report("COM3", "serial")
    parity_check(rep, SimpleNamespace())                        # a win32 Serial: no marks_parity
    parity_check(rep, SimpleNamespace(marks_parity=True))        # ParityMarkingSerial on Linux
    assert [(c.name, c.status, c.data["checked"]) for c in rep.checks] == [
        ("parity", "warn", False), ("parity", "ok", True)]
    assert "not checked" in rep.checks[0].detail


# -- Ctrl-Break and closing the console stop the drives as SIGTERM does ----------------------------

def test_sigbreak_ends_an_open_session_as_sigterm_does(monkeypatch):
    # Windows' SIGBREAK (Ctrl-Break; the C runtime also delivers the console window's close as
    # SIGBREAK) stands in as SIGUSR1 here: with a guard open it raises SessionTerminated, so the
    # session's close runs its safe stop; without one the handler from before is back
    import os
    import signal
    from profidrive_cli.session.signals import SessionTerminated, SignalGuard
    monkeypatch.setattr(signal, "SIGBREAK", signal.SIGUSR1, raising=False)
    seen = []
    previous = signal.signal(signal.SIGUSR1, lambda *a: seen.append(a[0]))   # without a guard: this
    before = signal.getsignal(signal.SIGUSR1)
    g = SignalGuard()
    g.install()
    try:
        try:
            os.kill(os.getpid(), signal.SIGUSR1)
            for _ in range(1000):                 # delivered at the next bytecode boundary
                pass
        except SessionTerminated as e:
            assert e.signum == signal.SIGUSR1
        else:
            raise AssertionError("SIGBREAK did not end the session")
        # during the safe stop a second one hurries the stop instead of interrupting it
        g.guard()
        os.kill(os.getpid(), signal.SIGUSR1)
        for _ in range(1000):
            pass
        assert g.hurry is True
    finally:
        g.restore()
        restored = signal.getsignal(signal.SIGUSR1)
        signal.signal(signal.SIGUSR1, previous)
    assert restored == before and seen == []


def test_the_pty_tests_are_the_ones_skipped_where_there_are_no_ptys():
    # conftest.pytest_collection_modifyitems skips a module's tests on Windows when needs_pty()
    from conftest import needs_pty
    here = Path(__file__).resolve().parent
    assert needs_pty((here / "test_pty_bus.py").read_text(encoding="utf-8"))
    assert needs_pty((here / "test_run_safety.py").read_text(encoding="utf-8"))
    assert not needs_pty((here / "test_fdl_frames.py").read_text(encoding="utf-8"))
    assert not needs_pty((here / "test_config.py").read_text(encoding="utf-8"))


# -- adapters other than FTDI: the chip from the registry's Enum\USB, and what its driver offers ----

def usb_port(port_name, vid, pid, instance="5&1a2b3c&0&2"):
    """The registry keys of a USB serial adapter's COM port (Enum\\USB\\VID_x&PID_y\\<instance>\\
    Device Parameters, PortName), with the parent keys the walk opens."""
    from profidrive_cli.dp.winports import USB
    dev = f"{USB}\\VID_{vid}&PID_{pid}"
    return {USB: {}, dev: {}, f"{dev}\\{instance}": {},
            f"{dev}\\{instance}\\Device Parameters": {"PortName": port_name}}


@pytest.mark.parametrize("vid,pid,chip", [
    # vendor IDs as in the Linux drivers' id tables (ch341.c 0x1a86/0x7523, pl2303.h 0x067b/0x2303,
    # cp210x.c 0x10c4/0xea60)
    ("1A86", "7523", "CH340/CH341 (WCH)"),
    ("067B", "2303", "Prolific PL2303"),
    ("10C4", "EA60", "Silicon Labs CP210x"),
])
def test_a_non_ftdi_adapter_is_named_and_has_no_latency_setting(monkeypatch, vid, pid, chip):
    from profidrive_cli.dp.winports import USB, usb_adapter
    keys = {**usb_port("COM4", vid, pid), **usb_port("COM5", "2341", "0043", "other")}
    found = usb_adapter("com4", FakeWinreg(keys))
    assert (found.vid, found.pid, found.chip) == (vid, pid, chip)
    assert found.key == f"HKLM\\{USB}\\VID_{vid}&PID_{pid}\\5&1a2b3c&0&2\\Device Parameters"
    checks = _doctor(monkeypatch, "COM4", keys, ports=("COM4",))
    assert checks["adapter"].data == {"driver": None, "usb": True}
    assert chip in checks["adapter"].detail
    lt = checks["latency_timer"]
    assert lt.status == "info" and lt.data["ms"] is None
    assert lt.detail == f"{chip}: no latency setting; USB full-speed polling 1 ms"


def test_an_unknown_usb_vendor_and_a_native_port():
    from profidrive_cli.dp.winports import usb_adapter
    keys = usb_port("COM5", "2341", "0043")
    assert usb_adapter("COM5", FakeWinreg(keys)).chip == "USB VID 2341"
    assert usb_adapter("COM1", FakeWinreg(keys)) is None          # not on USB (a native UART)
    assert usb_adapter("COM5", FakeWinreg({})) is None             # nothing in the registry


def test_a_usb_adapter_gets_the_usb_slot_time(monkeypatch):
    # reference §4.3: slot times as measured for CH341/FT232R adapters, not the standard TSL
    import profidrive_cli.dp.doctor as D
    monkeypatch.setattr(D, "com_ports", lambda: ["COM4"])
    rep = D.diagnose("COM4", 19200, platform="win32", winreg=FakeWinreg(usb_port("COM4", "1A86", "7523")),
                     listen_s=0.0)
    assert rep.recommend["slot_time"] == 576          # 30 ms at 19.2k (reference §4.3: 576 bit)
