"""Naming stations: ident -> device name from the GSD library (user folders first), else a profile."""

from __future__ import annotations

from profidrive_cli.drives.profile import profile_for_ident
from profidrive_cli.gsd.library import station_name


def device_name(ident: int, gsd_dir: str | None = None) -> str:
    name = station_name(ident, gsd_dir)     # None when unknown or the user's file does not parse
    if name:
        return name
    p = profile_for_ident(ident)
    return p.title if p else ""
