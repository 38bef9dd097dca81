"""Jog support known before anything runs: the family's Drive says whether its card has a jog
function over the bus (Drive.supports_jog) and, where not, why (Drive.jog_refusal). Asked here from the
profile and layout alone, without a bus, so `pdrive jog` and `checklist validate` refuse a station that
cannot jog with the same words before a telegram is sent.

(The profiles' `capabilities:` list, when it comes, answers the same question; this module is the one
place to connect it.)
"""

from __future__ import annotations

from profidrive_cli.drives.base import DriveError


class _NoBus:
    """A CyclicChannel that refuses traffic: constructing a Drive exchanges nothing."""

    def exchange(self, outputs: bytes) -> bytes:
        raise DriveError("no bus: jog support is asked without a station")

    def now(self) -> float:
        return 0.0


def jog_refusal(profile, layout: str | None = None) -> str | None:
    """None when this profile's card can jog in `layout`, else one line saying why not."""
    from profidrive_cli.drives import make_drive
    d = make_drive(_NoBus(), profile, layout)
    return None if d.supports_jog else d.jog_refusal()
