"""Where a drive's speed word sits in its cyclic area, for `pdrive sniff --station`'s fast path
(bustools/passive.py): a family codec's optional `speed_plan(profile, layout, direction, max_hz)`
answers with a SpeedWord (or None). Imports nothing of pdrive: the families import it.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple


class SpeedWord(NamedTuple):
    """Where an area's reference (request) / actual (response) word sits and the drive-object
    fields it gives, computed as the family's decode_area + normalise_area compute them (the same
    arithmetic in the same order: equal floats). A family codec's optional `speed_plan(profile,
    layout, direction, max_hz)` answers it; `sniff --station` then decodes the rest of an area once
    per the rest's octets and this word each time (bustools/passive.py): nothing else in the drive
    object may depend on the word beyond its class (zero, positive, negative as a signed 16-bit
    number), nor on the octets of `ignore` ((offset, size) ranges: words the drive object does not
    read, e.g. a measured current; decoded as zeros). Used while the family's Drive class reads
    areas with a normalise_area of pdrive's families or of the codec's own package (a plug-in's
    own reading of a shipped codec's areas: the slow way). tests/test_sniff_fast.py holds every
    family's to its slow path."""
    offset: int
    order: str                                      # "big" / "little"
    fields: Callable[[int], dict[str, Any]]
    ignore: tuple[tuple[int, int], ...] = ()
    #: the Hz field alone (reference_hz / actual_hz, what a sniff line shows), when it is cheaper
    #: than fields (None: taken from fields)
    hz: Callable[[int], float | None] | None = None
