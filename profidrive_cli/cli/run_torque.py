"""`pdrive run --torque / --torque-limit`: the options' checks and words before the bus is opened.
The card's own check (does this layout carry the word?) runs in session/torque.py once it is known.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Callable

from profidrive_cli import UsageError
from profidrive_cli.drives.torque import NO_TORQUE

if TYPE_CHECKING:
    from profidrive_cli.api.station import DriveStation

    Before = Callable[[DriveStation], None]


def prepare(hz: float | None, percent: float | None, reverse: bool, torque: float | None,
            torque_limit: float | None) -> tuple[float | None, float | None, str]:
    """(torque, percent, what) for run: the torque signed by --reverse, the speed 0 % when a torque
    run gives none, and the words of the confirmation question."""
    if torque is not None and torque_limit is not None:
        raise UsageError("--torque and --torque-limit: give one of them (a torque run has no separate limit)")
    if (hz is not None and percent is not None) or (torque is None and hz is None and percent is None):
        raise UsageError("give the speed with --hz F or --percent P (one of them)")
    if torque is not None and reverse:
        torque = -abs(torque)
    if torque is not None and hz is None and percent is None:
        percent = 0.0                        # a torque run without a speed: speed reference 0
    speed_words = f"{hz:g} Hz" if hz is not None else f"{percent:g} %"
    what = f"run the drive at {speed_words}{' reverse' if reverse else ''}"
    if torque is not None:
        what = f"run the drive in torque control at {torque:g} % of rated torque (speed reference {speed_words})"
    elif torque_limit is not None:
        what += f" with a torque limit of {torque_limit:g} %"
    return torque, percent, what


def header(torque: float | None, torque_limit: float | None) -> dict[str, float]:
    out: dict[str, float] = {}
    if torque is not None:
        out["torque_ref_percent"] = torque
    if torque_limit is not None:
        out["torque_limit_percent"] = torque_limit
    return out


def guard(before: Before | None, torque: float | None, torque_limit: float | None) -> Before | None:
    """The before-connect callback, preceded by the family's refusal (Fuji, Moeller: no torque word)
    so that a real port is not even asked about a run the card cannot do."""
    if torque is None and torque_limit is None:
        return before

    def check_then_before(session: DriveStation) -> None:
        assert session.profile is not None      # identify() chose it before the before-connect call
        fam = session.profile.family
        if fam in NO_TORQUE:
            raise UsageError(f"{'--torque' if torque is not None else '--torque-limit'}: {NO_TORQUE[fam]}")
        if before is not None:
            before(session)
    return check_then_before
