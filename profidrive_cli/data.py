"""Where the shipped data lives: profiles/*.yaml, gsd/*.gsd and wireshark/pdrive.lua.

Installed, they are package data (profidrive_cli/profiles, profidrive_cli/gsd_files,
profidrive_cli/wireshark_files); in a source checkout they are the top-level profiles/, gsd/ and
wireshark/ folders.
"""

from __future__ import annotations

import os
from pathlib import Path

_PKG = Path(__file__).resolve().parent


def _first_existing(*candidates: Path) -> Path:
    for c in candidates:
        if c.is_dir():
            return c
    return candidates[0]


def profiles_dir() -> Path:
    return _first_existing(_PKG / "profiles", _PKG.parent / "profiles")


def gsd_dir() -> Path:
    return _first_existing(_PKG / "gsd_files", _PKG.parent / "gsd")


def wireshark_dir() -> Path:
    return _first_existing(_PKG / "wireshark_files", _PKG.parent / "wireshark")


def user_gsd_dirs(extra: str | None = None) -> list[Path]:
    """User GSD folders (--gsd-dir, then $PDRIVE_GSD_DIR); they win over the library."""
    dirs = []
    if extra:
        dirs.append(Path(extra))
    env = os.environ.get("PDRIVE_GSD_DIR")
    if env:
        dirs.extend(Path(p) for p in env.split(os.pathsep) if p)
    return dirs


def user_profile_dirs() -> list[Path]:
    """Profile folders of the user's ($PDRIVE_PROFILE_PATH, os.pathsep-separated), searched after the
    shipped profiles/ (a name there wins) and before the plug-ins' folders."""
    env = os.environ.get("PDRIVE_PROFILE_PATH")
    return [Path(p) for p in env.split(os.pathsep) if p] if env else []
