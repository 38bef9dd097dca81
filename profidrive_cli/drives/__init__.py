"""Per-family drive codecs over PPO / vendor layouts, behind one Drive interface (drives/base.py).

Each family module drives/<family>.py (the profile's `family:` key) provides:

    make_drive(channel, profile, layout=None) -> Drive
    DRIVE_CLASS: the Drive subclass make_drive returns (drive_class(profile): its class-level facts)
    decode_area(profile, layout, direction, data) -> dict
        direction is "request" (master -> drive output area) or "response" (drive -> master input
        area); returns named fields, JSON-serialisable, with a "text" list of human-readable lines.

and the sim model module sim/<family>.py provides:

    make_model(profile, **options) -> SlaveModel
"""

from __future__ import annotations

import importlib
from types import ModuleType
from typing import Any

from profidrive_cli import UsageError


def codec_module(profile) -> ModuleType:
    try:
        return importlib.import_module(f"profidrive_cli.drives.{profile.family}")
    except ModuleNotFoundError as e:
        if e.name == f"profidrive_cli.drives.{profile.family}":
            raise UsageError(f"profile {profile.name}: no codec for family '{profile.family}'") from None
        raise


def drive_class(profile) -> Any:
    """The family's Drive class (a drives.base.Drive subclass; not imported here: drives.base ->
    drives.values -> drives would be a cycle): its class-level facts (supports_jog,
    monitor_mapping, ...) are readable before a station is connected."""
    return codec_module(profile).DRIVE_CLASS


def make_drive(channel, profile, layout: str | None = None):
    return codec_module(profile).make_drive(channel, profile, layout)


def decode_area(profile, layout: str, direction: str, data: bytes) -> dict:
    return codec_module(profile).decode_area(profile, layout, direction, data)
