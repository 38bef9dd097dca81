"""Windows side of `pdrive doctor`: COM ports and the FTDI driver's latency timer, read from the
registry (where the FTDI VCP driver keeps it: HKLM\\SYSTEM\\CurrentControlSet\\Enum\\FTDIBUS\\<device>\\
0000\\Device Parameters, values PortName and LatencyTimer, in ms; 16 by default).

`winreg` is a parameter (None: the real one, imported here only on Windows), so the tests run these
functions on Linux with a stand-in. Nothing here writes to the registry: doctor says how to lower the
timer in Device Manager."""

from __future__ import annotations

from typing import Any

FTDIBUS = r"SYSTEM\CurrentControlSet\Enum\FTDIBUS"

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

