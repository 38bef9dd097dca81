"""The options every drive command takes besides the bus options (cli/common.py): --profile, --ppo,
--format, --watchdog; and its ending on SIGTERM (_terminations). Its own module so that the param
group (drive_cmds.py) and its fleet subcommands (fleet_cmd.py) share them without importing each
other."""

from __future__ import annotations

import functools
import sys
from typing import Any, Callable, ParamSpec, TypeVar

import click

from profidrive_cli.cli.common import err
from profidrive_cli.api.station import SessionTerminated

F = TypeVar("F", bound=Callable[..., Any])
P = ParamSpec("P")
R = TypeVar("R")


def drive_options(f: F) -> F:
    """--profile, --ppo, --format, --watchdog."""
    f = click.option("--watchdog", "watchdog_ms", default=500, show_default=True,
                     type=click.IntRange(10, 650000), help="Slave watchdog in ms (always armed).")(f)
    f = click.option("--format", "fmt", default=None, metavar="NAME",
                     help="Layout by name (e.g. extended1, toyo); default: the profile's.")(f)
    f = click.option("--ppo", type=click.IntRange(1, 5), default=None, help="PPO type N (layout ppoN).")(f)
    f = click.option("--profile", "profile_name", default=None, metavar="NAME",
                     help="Drive profile (default: from the station's ident).")(f)
    return f


def _terminations(f: Callable[P, R]) -> Callable[P, R]:
    """SIGTERM (SessionTerminated) -> one line and exit 143; the session has already stopped the drive."""
    @functools.wraps(f)
    def wrapper(*a: P.args, **kw: P.kwargs) -> R:
        try:
            return f(*a, **kw)
        except SessionTerminated as e:
            err.print(f"terminated (signal {e.signum})")
            sys.exit(128 + int(e.signum))
    return wrapper
