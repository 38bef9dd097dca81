"""Per-family drive codecs over PPO / vendor layouts, behind one Drive interface (drives/base.py).

Which family module serves a profile (its `family:` key) is the one table in drives/registry.py:
codec module, Drive class, sim model, config reader. Each family codec provides:

    make_drive(channel, profile, layout=None) -> Drive
    decode_area(profile, layout, direction, data) -> dict
        direction is "request" (master -> drive output area) or "response" (drive -> master input
        area); returns named fields, JSON-serialisable, with a "text" list of human-readable lines.

and its sim model (sim/<family>.py) provides:

    make_model(profile, **options) -> SlaveModel

The names below are the registry's, kept here for the layers that import them from drives.
"""

from __future__ import annotations

from profidrive_cli.drives.registry import codec_module, decode_area, drive_class, make_drive

__all__ = ["codec_module", "decode_area", "drive_class", "make_drive"]
