"""Windows side of `pdrive doctor`: COM ports and the FTDI driver's latency timer, read from the
registry (where the FTDI VCP driver keeps it: HKLM\\SYSTEM\\CurrentControlSet\\Enum\\FTDIBUS\\<device>\\
0000\\Device Parameters, values PortName and LatencyTimer, in ms; 16 by default).

Other USB adapters (CH340/CH341, Prolific PL2303, Silicon Labs CP210x, CDC-ACM): their COM port is
found under HKLM\\SYSTEM\\CurrentControlSet\\Enum\\USB\\VID_xxxx&PID_yyyy\\<instance>\\Device
Parameters (PortName), the chip named by its USB vendor ID. None of their drivers is known to offer a
latency setting (not verified on each driver version): doctor says "no latency setting; USB
full-speed polling 1 ms" (these chips are USB full-speed devices: the host polls them once a 1 ms
frame, so a reply waits up to about 1 ms beyond its wire time).

`winreg` is a parameter (None: the real one, imported here only on Windows), so the tests run these
functions on Linux with a stand-in. Nothing here writes to the registry: doctor says how to lower the
timer in Device Manager."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

FTDIBUS = r"SYSTEM\CurrentControlSet\Enum\FTDIBUS"
USB = r"SYSTEM\CurrentControlSet\Enum\USB"

#: USB vendor IDs of the usual serial-adapter chips (as in the Linux drivers' id tables: ch341.c,
#: pl2303.h, cp210x.c, ftdi_sio_ids.h)
USB_VENDORS = {"1A86": "CH340/CH341 (WCH)", "067B": "Prolific PL2303",
               "10C4": "Silicon Labs CP210x", "0403": "FTDI"}

#: what doctor says for an adapter whose driver has no latency setting
NO_LATENCY_SETTING = "no latency setting; USB full-speed polling 1 ms"

#: where Windows users change it (the FTDI VCP driver's own property page)
HOW_TO_LOWER = ("Device Manager > Ports (COM & LPT) > the port > Properties > Port Settings > "
                "Advanced > Latency Timer (msec): 1, then unplug and plug the adapter")


def _winreg(winreg: Any) -> Any:
    if winreg is not None:
        return winreg
    try:
        import winreg as real                       # Windows only
    except ImportError:
        return None
    return real


def ftdi_latency(port: str, winreg: Any = None) -> tuple[str | None, int | None]:
    """(the registry key, LatencyTimer in ms) of the FTDI adapter whose PortName is `port` ("COM3",
    case-blind); (None, None) when no FTDI adapter has that port (another driver, or no registry)."""
    reg = _winreg(winreg)
    if reg is None:
        return None, None
    try:
        root = reg.OpenKey(reg.HKEY_LOCAL_MACHINE, FTDIBUS)
    except OSError:
        return None, None
    i = 0
    while True:
        try:
            sub = reg.EnumKey(root, i)
        except OSError:
            return None, None                       # no more devices
        i += 1
        path = f"{FTDIBUS}\\{sub}\\0000\\Device Parameters"
        try:
            key = reg.OpenKey(reg.HKEY_LOCAL_MACHINE, path)
            name = reg.QueryValueEx(key, "PortName")[0]
            if str(name).strip().upper() != port.strip().upper():
                continue
            return "HKLM\\" + path, int(reg.QueryValueEx(key, "LatencyTimer")[0])
        except (OSError, ValueError, TypeError):
            continue


@dataclass(frozen=True)
class UsbAdapter:
    """The USB device behind a COM port, from the registry."""
    key: str                    # HKLM\\...\\Device Parameters
    vid: str                    # "1A86"
    pid: str                    # "7523"

    @property
    def chip(self) -> str:
        return USB_VENDORS.get(self.vid, f"USB VID {self.vid}")

    @property
    def latency(self) -> str:
        """What its driver offers for latency, in words."""
        if self.vid == "0403":
            return ("FTDI chip without the FTDI driver's LatencyTimer (another driver): "
                    + NO_LATENCY_SETTING)
        return NO_LATENCY_SETTING


def _vid_pid(name: str) -> tuple[str, str] | None:
    """"VID_1A86&PID_7523" (any case; "&MI_00" after it) -> ("1A86", "7523")."""
    parts: dict[str, str] = {}
    for part in name.upper().split("&"):
        k, _, v = part.partition("_")
        parts[k] = v
    if "VID" not in parts or "PID" not in parts:
        return None
    return parts["VID"], parts["PID"]


def usb_adapter(port: str, winreg: Any = None) -> UsbAdapter | None:
    """The USB device whose Device Parameters name `port` ("COM4", case-blind) under Enum\\USB;
    None when none does (a native port, a driver that keeps it elsewhere, or no registry)."""
    reg = _winreg(winreg)
    if reg is None:
        return None
    want = port.strip().upper()
    for dev in _subkeys(reg, USB):
        ids = _vid_pid(dev)
        if ids is None:
            continue
        for inst in _subkeys(reg, f"{USB}\\{dev}"):
            path = f"{USB}\\{dev}\\{inst}\\Device Parameters"
            try:
                key = reg.OpenKey(reg.HKEY_LOCAL_MACHINE, path)
                name = reg.QueryValueEx(key, "PortName")[0]
            except OSError:
                continue
            if str(name).strip().upper() == want:
                return UsbAdapter("HKLM\\" + path, ids[0], ids[1])
    return None


def _subkeys(reg: Any, path: str) -> list[str]:
    try:
        key = reg.OpenKey(reg.HKEY_LOCAL_MACHINE, path)
    except OSError:
        return []
    out, i = [], 0
    while True:
        try:
            out.append(str(reg.EnumKey(key, i)))
        except OSError:
            return out
        i += 1
