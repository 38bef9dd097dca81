"""The options every drive command takes besides the bus options (cli/common.py): --profile, --ppo,
--format, --watchdog. Its own module so that the param group (drive_cmds.py) and its fleet
subcommands (fleet_cmd.py) share it without importing each other."""

from __future__ import annotations

import click


def drive_options(f):
    """--profile, --ppo, --format, --watchdog."""
    f = click.option("--watchdog", "watchdog_ms", default=500, show_default=True,
                     type=click.IntRange(10, 650000), help="Slave watchdog in ms (always armed).")(f)
    f = click.option("--format", "fmt", default=None, metavar="NAME",
                     help="Layout by name (e.g. extended1, toyo); default: the profile's.")(f)
    f = click.option("--ppo", type=click.IntRange(1, 5), default=None, help="PPO type N (layout ppoN).")(f)
    f = click.option("--profile", "profile_name", default=None, metavar="NAME",
                     help="Drive profile (default: from the station's ident).")(f)
    return f
