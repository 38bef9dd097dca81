"""Per-family drive codecs over PPO / vendor layouts, behind one Drive interface (drives/base.py).

Each family module drives/<family>.py (the profile's `family:` key) provides:

    make_drive(channel, profile, layout=None) -> Drive
    decode_area(profile, layout, direction, data) -> dict
        direction is "request" (master -> drive output area) or "response" (drive -> master input
        area); returns named fields, JSON-serialisable, with a "text" list of human-readable lines.

and the sim model module sim/<family>.py provides:

    make_model(profile, **options) -> SlaveModel
"""

from __future__ import annotations

import importlib
from types import ModuleType

from profidrive_cli import UsageError


def codec_module(profile) -> ModuleType:
    try:
        return importlib.import_module(f"profidrive_cli.drives.{profile.family}")
    except ModuleNotFoundError as e:
        if e.name == f"profidrive_cli.drives.{profile.family}":
            raise UsageError(f"profile {profile.name}: no codec for family '{profile.family}'") from None
        raise


def make_drive(channel, profile, layout: str | None = None):
    return codec_module(profile).make_drive(channel, profile, layout)


def decode_area(profile, layout: str, direction: str, data: bytes) -> dict:
    return codec_module(profile).decode_area(profile, layout, direction, data)
