"""Checks of a real serial setup for `pdrive doctor` (reference §4.3: PC / USB serial realities).

diagnose(port, ...) -> Report: can we open the port (and why not: permission, the dialout group),
which DP baud rates the adapter accepts, the USB adapter's driver and FTDI latency_timer, kernel
RS-485 support, whether the adapter hears its own transmission (echo), the adapter's turnaround
and request-to-request gap (dp/doctor_timing.py), and what slot time and retries to use. It sends
only FDL status requests (harmless on a live bus), and only when the line was quiet before.

All file-system and ioctl access goes through small functions that take the paths as parameters, so
the tests can point them at a fake sysfs.
"""

from __future__ import annotations

import errno
import os
import struct
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, TypedDict

from profidrive_cli import BusError, UsageError
from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.timing import BAUD_NAMES, BAUD_RATES, BusParams

OK, WARN, FAIL, INFO, SKIP = "ok", "warn", "fail", "info", "skip"

# ioctl numbers (asm-generic: x86, arm, arm64, riscv)
TCGETS2 = 0x802C542A
TIOCGRS485 = 0x542E
SER_RS485_ENABLED = 1
BOTHER = 0o010000
CBAUD = 0o010017

#: slot time a USB adapter needs, ms, as measured by profirust with CH341/FT232R (reference §4.3):
#: 30 ms up to 19.2k, 8 ms above
USB_SLOT_MS = ((19200, 30.0), (12000000, 8.0))
USB_DRIVERS = {"ftdi_sio": "FTDI", "ch341": "CH340/CH341", "ch341-uart": "CH340/CH341",
               "cp210x": "Silicon Labs CP210x", "pl2303": "Prolific PL2303", "cdc_acm": "USB CDC-ACM"}


@dataclass
class Check:
    name: str
    status: str
    detail: str
    data: dict[str, object] = field(default_factory=dict)

    def as_dict(self) -> dict[str, object]:
        return {"name": self.name, "status": self.status, "detail": self.detail, **self.data}


@dataclass
class Report:
    port: str
    kind: str                          # "serial", "url", "simulator"
    checks: list[Check] = field(default_factory=list)
    baud_rates: dict[int, str] = field(default_factory=dict)    # rate -> "ok" / why refused
    recommend: dict[str, object] = field(default_factory=dict)
    #: the line carried traffic before we transmitted (another master): nothing more is sent
    busy: bool = False
    #: the slowest FDL status round trip measured, seconds
    round_trip_s: float | None = None
    #: nothing but (at most) the echo came back to the echo check's request: a free address
    probe_silent: bool = False

    def add(self, name: str, status: str, detail: str, **data: object) -> Check:
        c = Check(name, status, detail, data)
        self.checks.append(c)
        return c

    @property
    def failed(self) -> bool:
        return any(c.status == FAIL for c in self.checks)

    def as_dict(self) -> dict[str, object]:
        return {"port": self.port, "kind": self.kind, "ok": not self.failed,
                "checks": [c.as_dict() for c in self.checks],
                "baud_rates": {str(k): v for k, v in self.baud_rates.items()},
                "recommend": self.recommend}


# -- small probes ------------------------------------------------------------------------------
def tty_name(port: str) -> str:
    return os.path.basename(os.path.realpath(port))


def latency_timer_path(port: str, sysfs: str = "/sys") -> str:
    return os.path.join(sysfs, "bus", "usb-serial", "devices", tty_name(port), "latency_timer")


def read_latency_timer(port: str, sysfs: str = "/sys") -> tuple[str, int | None]:
    """(sysfs path, value in ms or None when the file is absent/unreadable)."""
    path = latency_timer_path(port, sysfs)
    try:
        with open(path) as fh:
            return path, int(fh.read().strip())
    except (OSError, ValueError):
        return path, None


def usb_driver(port: str, sysfs: str = "/sys") -> tuple[str | None, bool]:
    """(kernel driver name, sits on USB) from /sys/class/tty/<tty>/device."""
    dev = os.path.join(sysfs, "class", "tty", tty_name(port), "device")
    link = os.path.join(dev, "driver")
    driver = os.path.basename(os.path.realpath(link)) if os.path.exists(link) else None
    real = os.path.realpath(dev) if os.path.exists(dev) else ""
    on_usb = "/usb" in real or driver in USB_DRIVERS
    return driver, on_usb


class Permission(TypedDict):
    """permission(): who may open a device file."""
    path: str
    group: str
    user: str
    root: bool
    access: bool
    in_group_now: bool
    in_group_file: bool
    mode: str


def permission(path: str) -> Permission:
    """Who may open the device: access for us, its group, whether we are in it (now / after login)."""
    import grp
    import pwd
    real = os.path.realpath(path)
    st = os.stat(real)
    try:
        group = grp.getgrgid(st.st_gid).gr_name
        members = grp.getgrgid(st.st_gid).gr_mem
    except KeyError:
        group, members = str(st.st_gid), []
    try:
        user = pwd.getpwuid(os.getuid()).pw_name
    except KeyError:
        user = str(os.getuid())
    in_session = st.st_gid == os.getegid() or st.st_gid in os.getgroups()
    return {"path": real, "group": group, "user": user, "root": os.geteuid() == 0,
            "access": os.access(real, os.R_OK | os.W_OK), "in_group_now": in_session,
            "in_group_file": user in members, "mode": oct(st.st_mode & 0o777)}


def reported_baud(fd: int) -> int | None:
    """The rate the driver reports after setting it (TCGETS2), None when it cannot say."""
    import fcntl
    import termios
    try:
        buf = fcntl.ioctl(fd, TCGETS2, bytes(44))
    except OSError:
        return None
    _i, _o, cflag, _l, _line, _cc, ispeed, ospeed = struct.unpack("=4IB19s2I", buf)
    if cflag & CBAUD == BOTHER:
        rate: int = ospeed           # (struct.unpack's values are Any)
        return rate
    code = cflag & CBAUD
    for name in dir(termios):
        if name.startswith("B") and name[1:].isdigit() and getattr(termios, name) == code:
            return int(name[1:])
    return None


def rs485_state(fd: int) -> tuple[str, int | None]:
    """('enabled'|'available'|'unsupported'|'error: ...', flags) via TIOCGRS485."""
    import fcntl
    try:
        buf = fcntl.ioctl(fd, TIOCGRS485, bytes(32))
    except OSError as e:
        if e.errno in (errno.ENOTTY, errno.EINVAL, errno.EOPNOTSUPP):
            return "unsupported", None
        return f"error: {e.strerror}", None
    flags = struct.unpack("=8I", buf)[0]
    return ("enabled" if flags & SER_RS485_ENABLED else "available"), flags


def usb_slot_bits(baud: int, latency_ms: int | None) -> int:
    ms = next(v for limit, v in USB_SLOT_MS if baud <= limit)
    if latency_ms is not None and latency_ms > 1:
        ms += latency_ms - 1
    p = BusParams.for_baud(baud)
    return max(p.max_tsdr + 15, min(16383, round(ms / 1000.0 * baud)))


# -- the whole check -----------------------------------------------------------------------------
def diagnose(port: str, baud: int = 19200, master_address: int = 2, probe_address: int = 126,
             rs485: bool = False, listen_s: float = 0.3, sysfs: str = "/sys",
             station: int | None = None, platform: str | None = None,
             winreg: Any = None) -> Report:     # the winreg module, or a test's stand-in
    """platform: sys.platform (tests switch it); winreg: the registry module on Windows (a stand-in
    in tests)."""
    if not 0 <= probe_address <= 126 or probe_address == master_address:
        raise UsageError(f"probe address {probe_address} must be 0..126 and not the master's")
    if port.startswith("sim://"):
        return _simulator(port)
    if "://" in port:
        rep = Report(port, "url")
        rep.add("port", INFO, "a pyserial URL (network converter or the like): no device, driver or "
                "latency checks apply")
        ser = _open_check(rep, port, baud, rs485)
        if ser is not None:
            rep.baud_rates[baud] = OK
            _echo(rep, ser, port, baud, master_address, probe_address, listen_s)
            _round_trip(rep, ser, baud, master_address, station)
            _timing(rep, ser, baud, master_address, probe_address)
            ser.close()
        _recommend(rep, baud, usb=False, latency=None, url=True)
        return rep
    if (platform or sys.platform) == "win32":
        return _windows(port, baud, master_address, probe_address, rs485, listen_s, station, winreg)
    rep = Report(port, "serial")
    if not os.path.exists(port):
        return _no_such_port(rep, port, com_ports())
    perm = permission(port)
    if perm["access"]:
        how = "as root" if perm["root"] else f"as {perm['user']}"
        rep.add("permission", OK, f"{perm['path']} can be opened {how} (group {perm['group']}, "
                f"mode {perm['mode']})", **perm)
    elif perm["in_group_file"] and not perm["in_group_now"]:
        rep.add("permission", FAIL, f"{perm['path']} belongs to group {perm['group']}; you are in it "
                f"but not in this login session: log out and in again (or `newgrp {perm['group']}`)", **perm)
    else:
        rep.add("permission", FAIL, f"{perm['path']} belongs to group {perm['group']} and you "
                f"({perm['user']}) are not in it: `sudo usermod -aG {perm['group']} {perm['user']}`, "
                f"then log in again", **perm)
    driver, on_usb = usb_driver(port, sysfs)
    is_pty = perm["path"].startswith(("/dev/pts/", "/dev/pty"))
    if is_pty:
        rep.add("adapter", INFO, "a pseudo-terminal (pty: socat, pdrive sim --pty, a converter's "
                "virtual port): no hardware behind it", driver=None, usb=False, pty=True)
    elif on_usb:
        rep.add("adapter", INFO, f"USB serial adapter, driver {driver or 'unknown'}"
                + (f" ({USB_DRIVERS[driver]})" if driver in USB_DRIVERS else ""),
                driver=driver, usb=True)
    elif driver:
        rep.add("adapter", INFO, f"native serial port, driver {driver}", driver=driver, usb=False)
    else:
        rep.add("adapter", INFO, "no driver information in sysfs (a pty or a virtual device)",
                driver=None, usb=False)
    lt_path, latency = read_latency_timer(port, sysfs)
    if latency is not None:
        _latency_row(rep, latency, lt_path, f"`echo 1 | sudo tee {lt_path}` (a udev rule makes it stick)")
    elif on_usb:
        rep.add("latency_timer", INFO, f"no {lt_path}: this driver has no latency timer to tune",
                path=lt_path, ms=None)
    else:
        rep.add("latency_timer", SKIP, "not a USB serial adapter", path=None, ms=None)
    if not perm["access"]:
        _recommend(rep, baud, on_usb, latency)
        return rep

    def posix_checks(ser: Any) -> None:
        if not is_pty:
            parity_check(rep, ser)
        fd = getattr(ser, "fd", None)
        if fd is not None:
            state, flags = rs485_state(fd)
            if state == "enabled":
                rep.add("rs485", OK, "kernel RS-485 mode is on (the driver switches the transmitter)",
                        state=state, flags=flags)
            elif state == "available":
                rep.add("rs485", INFO, "the driver supports kernel RS-485 mode (RTS direction "
                        "control): add --rs485 if your adapter needs RTS to transmit", state=state,
                        flags=flags)
            elif state == "unsupported":
                rep.add("rs485", INFO, "no kernel RS-485 mode in this driver (fine for adapters "
                        "with automatic direction control, as most USB-RS-485 ones)", state=state)
            else:
                rep.add("rs485", WARN, f"TIOCGRS485: {state}", state=state)
    _on_the_line(rep, port, baud, rs485, master_address, probe_address, listen_s, station, posix_checks)
    _recommend(rep, baud, on_usb, latency)
    return rep


def com_ports() -> list[str]:
    """The serial ports the system lists (pyserial's list_ports: /dev/ttyUSB0, COM3, ...)."""
    import serial.tools.list_ports
    return sorted(p.device for p in serial.tools.list_ports.comports())


def _no_such_port(rep: Report, port: str, found: list[str]) -> Report:
    rep.add("port", FAIL, f"{port}: no such port" + (f" (ports here: {', '.join(found)})" if found
                                                    else " (no serial ports found)"),
            candidates=found)
    return rep


def _latency_row(rep: Report, latency: int, where: str, how: str) -> None:
    """The adapter's latency timer (ms, read at `where`): fine at 1 ms, else how to lower it."""
    if latency <= 1:
        rep.add("latency_timer", OK, f"{latency} ms ({where})", path=where, ms=latency)
    else:
        rep.add("latency_timer", WARN, f"{latency} ms: every reply waits up to that long in the "
                f"adapter; set 1 ms: {how}", path=where, ms=latency)


def _on_the_line(rep: Report, port: str, baud: int, rs485: bool, master: int, probe: int,
                 listen_s: float, station: int | None,
                 platform_checks: Callable[[Any], None]) -> None:
    """The checks that open the port: the DP baud rates, the open at `baud`, the platform's own
    checks of the open port (platform_checks(ser)), the echo and the round trip."""
    _baud_rates(rep, port, rs485)
    ser = _open_check(rep, port, baud, rs485, quiet=True)
    if ser is not None:
        platform_checks(ser)
        _echo(rep, ser, port, baud, master, probe, listen_s)
        _round_trip(rep, ser, baud, master, station)
        _timing(rep, ser, baud, master, probe)
        ser.close()


def _windows(port: str, baud: int, master: int, probe: int, rs485: bool, listen_s: float,
             station: int | None, winreg: Any) -> Report:
    """A COM port: listed by Windows (no device file, no permission bits), the FTDI latency timer
    from the registry (dp/winports.py), then the same open / baud / echo / round-trip checks."""
    from profidrive_cli.dp.winports import HOW_TO_LOWER, ftdi_latency, usb_adapter
    rep = Report(port, "serial")
    found = com_ports()
    if port.strip().upper() not in {p.upper() for p in found}:
        return _no_such_port(rep, port, found)
    rep.add("permission", SKIP, "Windows: no device-file permissions (a port another program holds "
            "fails to open below)", access=True)
    key, latency = ftdi_latency(port, winreg)
    usb = usb_adapter(port, winreg) if latency is None else None
    if latency is not None:
        rep.add("adapter", INFO, "USB serial adapter, driver FTDI (FTDIBUS)", driver="FTDIBUS", usb=True)
        _latency_row(rep, latency, key or "", HOW_TO_LOWER)
    elif usb is not None:
        rep.add("adapter", INFO, f"USB serial adapter {usb.chip} (VID {usb.vid}, PID {usb.pid})",
                driver=None, usb=True)
        rep.add("latency_timer", INFO, f"{usb.chip}: {usb.latency}", path=usb.key, ms=None)
    else:
        rep.add("latency_timer", SKIP, "no USB adapter on this port in the registry (a native "
                "port, or a driver that keeps its ports elsewhere: a latency setting, if it has one, "
                "is in its own Advanced port settings)", path=None, ms=None)
    _on_the_line(rep, port, baud, rs485, master, probe, listen_s, station,
                 lambda ser: parity_check(rep, ser))
    _recommend(rep, baud, latency is not None or usb is not None, latency)
    return rep


def _simulator(port: str) -> Report:
    """Asked through the opened port: the sim:// handler (sim/protocol_sim.py) describes its segment,
    so link/ needs nothing of sim/."""
    from profidrive_cli.link.serial_link import open_serial
    rep = Report(port, "simulator")
    try:
        ser = open_serial(port, 19200)
    except (UsageError, BusError) as e:
        rep.add("simulator", FAIL, str(e))
        return rep
    try:
        info = ser.simulator_info()
    finally:
        ser.close()
    stations = ", ".join(f"{a} {family}" for a, family in info["stations"].items())
    timing = {"instant": "instant (no wire time)", "wire": "wire time",
              "virtual": "wire time on a simulated clock"}[info["timing"]]
    rep.add("simulator", INFO, f"{port} is pdrive's built-in simulator, not hardware: stations "
            f"{stations}; {BAUD_NAMES[info['baud']]}, {timing}"
            + ("; fault injection on" if info["faults"] else ""),
            stations=dict(info["stations"]), timing=info["timing"], baud=info["baud"])
    rep.add("hardware", SKIP, "nothing to check: give --port with a real device (e.g. /dev/ttyUSB0)")
    rep.baud_rates = {b: OK for b in BAUD_RATES}
    rep.recommend = {"baud": info["baud"], "slot_time": None, "retries": 1,
                     "options": "", "why": "the simulator needs no latency margin"}
    return rep


def _open_check(rep: Report, port: str, baud: int, rs485: bool, quiet: bool = False) -> Any:
    # the open pyserial port or None (pyserial has no type hints: the `ser` of these checks is Any)
    from profidrive_cli.link.serial_link import open_serial
    try:
        ser = open_serial(port, baud, rs485)
    except (BusError, UsageError) as e:
        rep.add("open", FAIL, str(e))
        return None
    if not quiet:
        rep.add("open", OK, f"opened at {BAUD_NAMES.get(baud, baud)}")
    return ser


def parity_check(rep: Report, ser: Any) -> None:
    """Whether the port checks parity: a POSIX serial device marks each octet that arrived with a
    parity or framing error (link/parity.py), which makes its telegram illegal; elsewhere (Windows:
    pyserial cannot mark single octets) a wrong parity bit passes and only the FCS can catch it."""
    if getattr(ser, "marks_parity", False):
        rep.add("parity", OK, "parity and framing errors are checked: an octet that arrives with one "
                "makes its telegram illegal (termios INPCK + PARMRK)", checked=True)
    else:
        rep.add("parity", WARN, "parity errors are not checked on this port: an octet with a wrong "
                "parity bit passes as good, and only the telegram's FCS can catch it (PROFIBUS loses "
                "the Hamming distance 4 it gets from the parity bit)", checked=False)


def _baud_rates(rep: Report, port: str, rs485: bool) -> None:
    from profidrive_cli.link.serial_link import open_serial
    refused, odd = [], []
    for b in BAUD_RATES:
        try:
            ser = open_serial(port, b, rs485)
        except (BusError, UsageError) as e:
            rep.baud_rates[b] = f"refused: {e}"
            refused.append(BAUD_NAMES[b])
            continue
        fd = getattr(ser, "fd", None)
        got = reported_baud(fd) if fd is not None else None
        ser.close()
        if got is not None and got != b and abs(got - b) > b * 0.02:
            rep.baud_rates[b] = f"reports {got}"
            odd.append(f"{BAUD_NAMES[b]} (driver reports {got})")
        else:
            rep.baud_rates[b] = OK
    ok = [BAUD_NAMES[b] for b, v in rep.baud_rates.items() if v == OK]
    if refused or odd:
        rep.add("baud rates", WARN if ok else FAIL,
                f"accepted: {', '.join(ok) or 'none'}"
                + (f"; refused: {', '.join(refused)}" if refused else "")
                + (f"; not exact: {', '.join(odd)}" if odd else ""), accepted=ok)
    else:
        rep.add("baud rates", OK, f"every DP rate opens ({', '.join(ok)})", accepted=ok)


def _read_for(ser: Any, seconds: float) -> bytes:
    from profidrive_cli.link.serial_link import read_available
    end = time.monotonic() + seconds
    got = bytearray()
    while True:
        left = end - time.monotonic()
        if left <= 0:
            return bytes(got)
        got += read_available(ser, left)


def _echo(rep: Report, ser: Any, port: str, baud: int, master: int, probe: int, listen_s: float) -> None:
    p = BusParams.for_baud(baud)
    try:
        ser.reset_input_buffer()
        before = _read_for(ser, listen_s)
    except Exception as e:
        rep.add("echo", FAIL, f"reading failed: {e}")
        return
    if before:
        rep.add("line", WARN, f"{len(before)} octets arrived in {listen_s:g} s without a request: "
                "another master is active (or the baud rate / wiring is wrong); not transmitting",
                octets=len(before))
        rep.add("echo", SKIP, "not tested on a busy line")
        rep.busy = True
        return
    rep.add("line", OK, f"quiet for {listen_s:g} s before transmitting")
    req = F.encode(F.Frame(F.SD1, probe, master, F.request_fc(F.FDL_STATUS)))
    try:
        ser.write(req)
        got = _read_for(ser, p.chars(len(req)) + p.slot_seconds + p.chars(6) + 0.1)
    except Exception as e:
        rep.add("echo", FAIL, f"sending an FDL status request failed: {e}")
        return
    echo = got[:len(req)] == req
    rest = got[len(req):] if echo else got
    answer = None
    r = F.parse(rest) if rest else None
    if r is not None and not isinstance(r, F.FrameError):
        f, _ = r
        if f.sd != F.SC and f.sa == probe and f.da == master and not f.is_request:
            answer = f"station {probe} answered ({F.STATION_TYPES[f.station_type]})"
    data = {"sent": req.hex(" "), "received": got.hex(" "), "echo": echo, "probe_address": probe}
    rep.probe_silent = not rest
    if echo:
        rep.add("echo", INFO, f"the adapter hears its own transmission (sent {req.hex(' ')}, read it "
                f"back): bus commands find this at their first transmission and drop the echo "
                f"(--echo auto, the default); use --echo on to skip the check"
                + (f"; {answer}" if answer else ""), **data)
    elif answer:
        rep.add("echo", OK, f"no echo; {answer} to an FDL status request", **data)
    elif got:
        rep.add("echo", WARN, f"no echo, but {len(got)} unexpected octets came back "
                f"({got[:16].hex(' ')}): check the baud rate, parity (8E1) and the A/B wiring", **data)
    else:
        rep.add("echo", OK, f"no echo (an FDL status request to address {probe} brought nothing back)",
                **data)
    rep.recommend["echo"] = echo


#: FDL status round trips measured per doctor run
ROUND_TRIPS = 5


def _exchange(ser: Any, req: bytes, timeout: float, echo: bool) -> tuple[float | None, bytes]:
    """Send `req`, read until one whole telegram came back: (seconds from the end of the write to
    the last octet, what came) or (None, what came) on timeout."""
    ser.reset_input_buffer()
    ser.write(req)
    t0 = time.monotonic()
    from profidrive_cli.link.serial_link import read_available
    got = bytearray()
    skip = len(req) if echo else 0
    while True:
        left = t0 + timeout - time.monotonic()
        if left <= 0:
            return None, bytes(got)
        got += read_available(ser, left)
        body = got[skip:]
        r = F.parse(body) if body else None
        if r is not None and not isinstance(r, F.FrameError):
            return time.monotonic() - t0, bytes(got)


def _round_trip(rep: Report, ser: Any, baud: int, master: int, station: int | None) -> None:
    """The round trip of a real exchange against its wire time: FDL status requests to `station`
    (or to the first address that answers one) — a converter or adapter that buffers shows here."""
    if rep.busy:
        rep.add("round trip", SKIP, "not measured on a busy line")
        return
    p = BusParams.for_baud(baud)
    echo = bool(rep.recommend.get("echo"))
    wire = p.chars(6) + p.min_tsdr / baud + p.chars(6)       # SD1 request, TSDR, SD1 reply
    wire_max = p.chars(6) + p.max_tsdr / baud + p.chars(6)
    timeout = max(0.2, 20 * wire_max)
    targets = [station] if station is not None else [a for a in range(0, 127) if a != master]
    found, times = None, []
    try:
        for a in targets:
            req = F.encode(F.Frame(F.SD1, a, master, F.request_fc(F.FDL_STATUS)))
            rt, _ = _exchange(ser, req, min(timeout, 0.05) if station is None else timeout, echo)
            if rt is not None:
                found, times = a, [rt]
                break
        if found is not None:
            req = F.encode(F.Frame(F.SD1, found, master, F.request_fc(F.FDL_STATUS)))
            for _ in range(ROUND_TRIPS - 1):
                rt, _ = _exchange(ser, req, timeout, echo)
                if rt is not None:
                    times.append(rt)
    except Exception as e:
        rep.add("round trip", FAIL, f"FDL status exchange failed: {e}")
        return
    if found is None:
        rep.add("round trip", INFO if station is None else WARN,
                "no station answered an FDL status request: nothing to measure"
                + ("" if station is None else f" (station {station})"))
        return
    worst = max(times)
    data = {"station": found, "round_trips_ms": [round(t * 1000, 3) for t in times],
            "wire_ms": round(wire * 1000, 3), "wire_max_tsdr_ms": round(wire_max * 1000, 3)}
    rep.round_trip_s = worst
    text = (f"station {found}: FDL status round trip {min(times) * 1000:.1f}–{worst * 1000:.1f} ms "
            f"over {len(times)} exchanges; on the wire {wire * 1000:.1f}–{wire_max * 1000:.1f} ms "
            f"at {BAUD_NAMES[baud]}")
    if worst > 2 * wire_max + 0.002:
        extra = worst - wire
        rep.add("round trip", WARN, text + f": the port adds up to {extra * 1000:.1f} ms per "
                "exchange (adapter latency, a buffering converter): cycle rates will be far below "
                "the wire limit; raise --slot-time above that delay", **data)
    elif worst < wire:
        rep.add("round trip", INFO, text + ": faster than the wire, so no real line is behind this "
                "port (a simulator, or a converter that answers from a buffer)", **data)
    else:
        rep.add("round trip", OK, text, **data)


def _timing(rep: Report, ser: Any, baud: int, master: int, probe: int) -> None:
    """The turnaround and request-gap rows (dp/doctor_timing.py) after the echo and round trip."""
    from profidrive_cli.dp.doctor_timing import timing_rows
    rt = next((c.data for c in rep.checks if c.name == "round trip" and "station" in c.data), None)
    for name, status, detail, data in timing_rows(
            ser, baud, master, probe, echo=bool(rep.recommend.get("echo")), busy=rep.busy,
            probe_silent=rep.probe_silent, round_trip=rt):
        rep.add(name, status, detail, **data)


def _recommend(rep: Report, baud: int, usb: bool, latency: int | None, url: bool = False) -> None:
    p = BusParams.for_baud(baud)
    echo = rep.recommend.get("echo", False)
    if usb or url:
        slot = usb_slot_bits(baud, latency)
        retries = 3 if (latency or 0) > 1 else 2
        why = ("USB adapters add latency: slot time as measured for CH341/FT232R adapters "
               f"({slot / baud * 1000:.0f} ms at {BAUD_NAMES[baud]}), retries 2..3 (reference §4.3)")
        if url:
            why = "a network converter adds latency like a USB adapter: " + why
        if latency and latency > 1:
            why += f"; with latency_timer {latency} ms the slot time grows by {latency - 1} ms"
    else:
        slot, retries = p.tsl, 1
        why = (f"a native UART or a pty: the standard slot time ({p.tsl} bit) and 1 retry; pdrive "
               "adds 20 ms for the operating system on real ports")
    rt = rep.round_trip_s
    if rt is not None:
        need = int((rt - p.chars(6)) * baud * 1.5) + 1      # the measured delay with 50 % margin
        if need > slot:
            slot = min(16383, need)
            why += f"; slot time raised to {slot} bit to cover the measured round trip"
    opts = f"--baud {BAUD_NAMES[baud]} --slot-time {slot} --retries {retries}" + (" --echo" if echo else "")
    rep.recommend.update({"baud": baud, "slot_time": slot, "retries": retries, "options": opts,
                          "why": why})
