"""Torque runs: check that the card and layout carry the torque word asked for (the one-line reason
otherwise, exit 2, before anything moves) and set the torque reference or limit; Motion
(session/motion.py) warns what the drive's own settings must be and then starts as a speed run does.
The stop is the same safe stop (safestop.py): each codec's stop leaves torque control first.
"""

from __future__ import annotations

from profidrive_cli import UsageError
from profidrive_cli.drives.base import Drive
from profidrive_cli.drives.torque import torque_counts


def check(d: Drive, torque: float | None, limit: float | None) -> None:
    """UsageError with the card's reason when it cannot take this torque reference or limit."""
    if torque is not None:
        why = d.torque_support()
        if why:
            raise UsageError(f"--torque: {why}")
        torque_counts(torque, d.torque_resolution(), "--torque")
    if limit is not None:
        why = d.torque_limit_support()
        if why:
            raise UsageError(f"--torque-limit: {why}")
        if limit <= 0:
            raise UsageError(f"--torque-limit {limit:g} %: must be above 0 %")
        torque_counts(limit, d.torque_resolution(), "--torque-limit")


def set_words(d: Drive, torque: float | None, limit: float | None) -> None:
    """The torque reference and / or limit words (after check)."""
    if torque is not None:
        d.set_torque(torque)
    if limit is not None:
        d.set_torque_limit(limit)
