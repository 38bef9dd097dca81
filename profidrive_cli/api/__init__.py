"""The Python API of pdrive (stable; documented in docs/api.md):

    import profidrive_cli as pdrive

    with pdrive.open_bus("sim://") as bus:          # a device, a URL, sim:// or a config port name
        bus.scan()                                   # -> [Station]
        drive = bus.drive(3)                         # profile from the ident (or profile="fuji-g1")
        drive.status()                               # -> Status
        drive.run(hz=30, wait=True, timeout=20)      # -> Status
        drive.param("F07")                           # -> Param
        bus.read_params([3, 4, 5], ["F07", "F08"])   # several drives at once -> {station: {code: Param}}
        drive.set_param("F07", 5.0)                  # exact value or UsageError; -> Param read back
        drive.faults()                               # -> Faults
        drive.stop()                                 # -> StopResult
    # leaving the block (also by an exception): every drive this bus started is stopped safely

The api layer stands on session/ and bustools/, and checklist/ and cli/ on it (PLAN in
tests/test_layering.py): built on session/ (DriveStation), it never prompts and never prints. It is
pdrive's own front door too: the master is built in one place (make_master), and the CLI's drive
commands and the checklist get their stations from a Bus (Bus.drive, or Bus.session for the session
level; docs/api.md). Errors are the CLI's: UsageError (bad input,
refused writes), BusError / DriveError (the bus or the drive).
"""

from typing import TYPE_CHECKING

from profidrive_cli import BusError, PdriveError, UsageError
from profidrive_cli.api.bus import Bus, make_master, open_bus
from profidrive_cli.api.results import Fault, Faults, Param, ParamsError, Station, Status, StopResult
from profidrive_cli.fdl.master import format_counters

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.api.drive import Drive
    from profidrive_cli.drives.base import DriveError
    from profidrive_cli.session.signals import SessionTerminated

#: loaded on first use (PEP 562): `pdrive scan` builds its master with make_master and never needs the
#: session layer these bring in (benchmarks/bench_startup.py)
_LAZY = {"Drive": "profidrive_cli.api.drive", "DriveError": "profidrive_cli.drives.base",
         "SessionTerminated": "profidrive_cli.session.signals"}


def __getattr__(name: str) -> object:
    if name in _LAZY:
        import importlib
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

__all__ = ["Bus", "BusError", "Drive", "DriveError", "Fault", "Faults", "Param", "ParamsError", "PdriveError",
           "SessionTerminated", "Station", "Status", "StopResult", "UsageError", "format_counters",
           "make_master", "open_bus"]
