"""What the Python API returns: small frozen dataclasses, plain values (no pdrive internals), names
as in the JSON contract (station, ident + ident_hex, flags as the names that are set, reference_hz /
actual_hz, times in seconds with an _s suffix, counters with the dp layer's keys)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Mapping


def _hex(ident: int | None) -> str | None:
    return None if ident is None else "0x%04X" % ident


@dataclass(frozen=True)
class Station:
    """One station that answered a scan."""
    station: int
    kind: str                        # "slave", "master not ready", "master ready", "master in ring"
    ident: int | None
    profile: str | None              # the pdrive profile whose ident matches (None: not a known drive)
    state: str                       # DP state in words ("waiting for parameters", "data exchange", ...)

    @property
    def ident_hex(self) -> str | None:
        return _hex(self.ident)

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "ident_hex": self.ident_hex}


@dataclass(frozen=True)
class Status:
    """One read of a drive's status."""
    station: int
    profile: str
    state: str                       # in the family's words ("operation", "S1 switching on inhibited")
    running: bool
    stopped: bool
    fault: bool
    fault_code: str | None           # the current fault as the card names it ("OC1", "E05"), if any
    flags: tuple[str, ...]           # the names of the status bits that are set
    actual_hz: float | None
    actual_percent: float | None
    reference_hz: float | None
    reference_percent: float | None
    fmax_hz: float                   # the frequency 100 % stands for
    t_s: float                       # seconds since the drive reached data exchange
    counters: Mapping[str, int]      # retries, no_answer, illegal, reparams, ...

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["flags"] = list(self.flags)
        d["counters"] = dict(self.counters)
        return d


@dataclass(frozen=True)
class Param:
    """A parameter value as read (or read back after a write)."""
    code: str                        # the native code as the profile names it ("F07")
    name: str
    value: float | int               # engineering value
    unit: str
    raw: int                         # the value on the wire
    text: str | None = None          # the value as the card's tables show it, where it has a format

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class Fault:
    """One entry of the fault history."""
    position: str                    # "current", "last", "2nd last", ... or an index
    number: int                      # the code on the wire
    codes: tuple[str, ...]           # alarm names (several where one number means several)
    meanings: tuple[str, ...]


@dataclass(frozen=True)
class Faults:
    """The current fault and the fault history."""
    station: int
    fault: bool
    fault_code: str | None
    state: str
    history: tuple[Fault, ...]

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class StopResult:
    """How a stop went: "normal", "coast", "not needed", "not sent (link lost)" or "failed"."""
    how: str
    stopped: bool
    duration_s: float
    message: str

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
