"""Torque references and limits, family-independent: the range and exactness check every torque
path uses, and the one-line reasons for cards without torque words.

Facts (spec lines in the codecs): Toyo PBUS66-Z torque command 5000 = rated torque (0.02 % a count,
toyo-vf66-pbus66z.md §4.2), in PPO2/PPO4/PPO5 and the Toyo frame with PLCH off; Yaskawa SI-P1
torque reference / limit and compensation 0.1 % (yaskawa-profibus-dp.md §2.4, §2.6), in the basic
and extended1 layouts. Fuji OPC-G1-PDP / OPC-PDP3 and Moeller DE6-NET-DP carry no torque word in
their cyclic data (their specs: speed setpoint plus parameter words only).

Decision: a torque reference or limit is accepted in -200..200 % of rated torque (the VF66 trips
on overtorque above 150 % for a minute; no card names a larger useful value) and only when the
card's word holds it exactly (a multiple of the word's resolution): refused, never rounded.

May touch: nothing of drives (base imports this module). Imports no layer above drives.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from profidrive_cli import UsageError

if TYPE_CHECKING:
    from profidrive_cli.drives.capabilities import Capabilities
    from profidrive_cli.drives.profile import Profile

TORQUE_MAX_PERCENT = 200.0

NO_TORQUE = {
    "fuji": ("fuji: the OPC-G1-PDP / OPC-PDP3 cyclic data has no torque word (speed setpoint and "
             "PCD parameter words only): torque runs are not possible on this card"),
    "moeller": ("moeller: the DE6-NET-DP cyclic data has no torque word (PZD2 is the frequency; the "
                "torque limits b041-b044 are parameters): torque runs are not possible on this card"),
}


def no_torque_reason(family: str) -> str:
    return NO_TORQUE.get(family, f"{family}: this card has no torque word in its cyclic data")


def capability_refusal(profile: Profile, name: str, layout: str | None) -> str | None:
    """The profile's `capabilities:` refusal for `name` ('torque' or 'torque_limit') on `layout`, None
    when it is declared possible there or not declared at all (the Drive's own answer then decides).
    Bus-free, so run, checklist and API refuse with the same words before anything moves."""
    caps: Capabilities | None = getattr(profile, "capabilities", None)
    if caps is None or name not in getattr(caps, "decl", {}):
        return None
    return caps.refusal(name, layout or profile.default_layout)


def torque_counts(percent: float, resolution: float, what: str = "--torque") -> int:
    """Percent of rated torque -> signed word counts; UsageError when out of range or not exact."""
    if not math.isfinite(percent):
        raise UsageError(f"{what}: not a number")
    if abs(percent) > TORQUE_MAX_PERCENT:
        raise UsageError(f"{what} {percent:g} % is outside -{TORQUE_MAX_PERCENT:g}..{TORQUE_MAX_PERCENT:g} % "
                         f"of rated torque")
    counts = round(percent / resolution)
    if not math.isclose(counts * resolution, percent, rel_tol=0, abs_tol=1e-9):
        raise UsageError(f"{what} {percent:g} %: the card's torque word has steps of {resolution:g} %; "
                         f"{percent:g} is not a multiple (nearest {counts * resolution:.6g} %); give an "
                         f"exact value")
    return counts
