"""pdrive: a PROFIBUS-DP master and drive-commissioning CLI.

Layers (each knows only the one below it):
    link  -> fdl -> dp -> drives -> cli
plus sim/ (the simulated slave side, built on the same fdl/dp code), gsd/ (GSD parser)
and data (profiles/*.yaml, gsd/*.gsd carried inside the package).
"""

__version__ = "0.1.0"


class PdriveError(Exception):
    """Base of every error pdrive reports to the user as one line (never a traceback)."""


class UsageError(PdriveError):
    """Bad input from the user or a bad data file: exit code 2."""


class BusError(PdriveError):
    """The bus or a station misbehaved: exit code 1."""
