"""Jog support known before anything runs: the family's Drive class says, as a class fact from the
profile and layout alone (Drive.jog_refusal_for), whether its card has a jog function over the bus
and, where not, why -- the same words a connected drive's supports_jog / jog_refusal() give. Asked
without a bus, so `pdrive jog` and `checklist validate` refuse a station that cannot jog with the
same words before a telegram is sent.

The profile's `capabilities:` declaration (drives/capabilities.py) is asked first, so the words are
those of `checklist validate` and every other capability refusal; the Drive's own answer stays the
last word for what the declaration does not cover (tests/test_jog.py checks that the two agree).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from profidrive_cli.drives.capabilities import Capabilities
    from profidrive_cli.drives.profile import Profile


def jog_refusal(profile: Profile, layout: str | None = None) -> str | None:
    """None when this profile's card can jog in `layout`, else one line saying why not."""
    caps: Capabilities | None = getattr(profile, "capabilities", None)
    if caps is not None and "jog" in getattr(caps, "decl", {}):
        why = caps.refusal("jog", layout or profile.default_layout)
        if why is not None:
            return why
    from profidrive_cli.drives import drive_class
    refusal: str | None = drive_class(profile).jog_refusal_for(profile, layout or profile.default_layout)
    return refusal
