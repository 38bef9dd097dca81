"""Torque runs: check that the card and layout carry the torque word asked for (the one-line reason
otherwise, exit 2, before anything moves), warn what the drive's own settings must be, set the torque
reference or limit, then start as a speed run does (motion.start). The stop is the same safe stop
(safestop.py): each codec's stop leaves torque control first.
"""

from __future__ import annotations

from profidrive_cli import UsageError
from profidrive_cli.drives.torque import torque_counts
from profidrive_cli.session import motion
from profidrive_cli.session.cycle import Sample


def check(sess, torque: float | None, limit: float | None) -> None:
    """UsageError with the card's reason when it cannot take this torque reference or limit."""
    d = sess.need_drive()
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


def start(sess, torque: float | None, limit: float | None, percent: float | None = None,
          timeout: float = 5.0) -> Sample:
    """Check, warn, set the torque word, start (with the speed reference `percent` if given)."""
    check(sess, torque, limit)
    d = sess.need_drive()
    for note in d.torque_notes():
        if note not in sess.warnings:
            sess.warn(note)
    if torque is not None:
        d.set_torque(torque)
    if limit is not None:
        d.set_torque_limit(limit)
    return motion.start(sess, percent, timeout)


def set_torque(sess, percent: float) -> None:
    """A new torque reference while running (keys in the live view)."""
    check(sess, percent, None)
    sess.need_drive().set_torque(percent)
