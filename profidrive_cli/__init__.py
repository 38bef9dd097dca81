"""pdrive: a PROFIBUS-DP master and drive-commissioning CLI, and a Python API.

Layers (each knows only the one below it):
    link  -> fdl -> dp -> drives -> session -> checklist -> api -> cli
plus sim/ (the simulated slave side, built on the same fdl/dp code), gsd/ (GSD parser)
and data (profiles/*.yaml, gsd/*.gsd carried inside the package).

The Python API (docs/api.md) is exported here lazily (PEP 562): `import profidrive_cli as pdrive`
loads nothing more; `pdrive.open_bus(...)` imports profidrive_cli.api on first use.
"""

from typing import Any

__version__ = "0.1.0"


class PdriveError(Exception):
    """Base of every error pdrive reports to the user as one line (never a traceback)."""


class UsageError(PdriveError):
    """Bad input from the user or a bad data file: exit code 2."""


class BusError(PdriveError):
    """The bus or a station misbehaved: exit code 1."""


#: names exported from profidrive_cli.api on first use (the only import of a layer from here)
_API_NAMES = frozenset({"open_bus", "Bus", "Drive", "DriveError", "Fault", "Faults", "Param",
                        "SessionTerminated", "Station", "Status", "StopResult"})


def __getattr__(name: str) -> Any:     # whatever profidrive_cli.api exports under that name
    if name in _API_NAMES:
        import profidrive_cli.api as api
        value = getattr(api, name)
        globals()[name] = value
        return value
    if name == "aio":                   # the asyncio face, a sub-package: `pdrive.aio.open_bus`
        import importlib
        return importlib.import_module("profidrive_cli.aio")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | _API_NAMES | {"aio"})
