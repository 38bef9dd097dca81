"""Jog support known before anything runs: the family's Drive says whether its card has a jog
function over the bus (Drive.supports_jog) and, where not, why (Drive.jog_refusal). Asked here from the
profile and layout alone, without a bus, so `pdrive jog` and `checklist validate` refuse a station that
cannot jog with the same words before a telegram is sent.

The profile's `capabilities:` declaration (drives/capabilities.py) is asked first, so the words are
those of `checklist validate` and every other capability refusal; the Drive's own answer stays the
last word for what the declaration does not cover (tests/test_jog.py checks that the two agree).
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
    caps = getattr(profile, "capabilities", None)
    if caps is not None and "jog" in getattr(caps, "decl", {}):
        why = caps.refusal("jog", layout or profile.default_layout)
        if why is not None:
            return why
    from profidrive_cli.drives import make_drive
    d = make_drive(_NoBus(), profile, layout)
    return None if d.supports_jog else d.jog_refusal()
