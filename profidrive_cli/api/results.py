"""What the Python API returns: small frozen dataclasses, plain values (no pdrive internals), names
as in the JSON contract (station, ident + ident_hex, flags as the names that are set, reference_hz /
actual_hz, times in seconds with an _s suffix, counters with the dp layer's keys)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Mapping

from profidrive_cli import BusError


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

    @classmethod
    def of(cls, pv: Any) -> "Param":
        """From a drives.base.ParamValue (with its text, where the card's tables give one)."""
        return cls(pv.code, pv.name, pv.value, pv.unit or "", int(pv.raw), getattr(pv, "text", None))


class ParamsError(BusError):
    """Bus.read_params: some drives could not be read (after every other was). errors: {station:
    why}; partial: {station: {code: Param}} of the drives that were."""

    def __init__(self, errors: Mapping[int, str], partial: Mapping[int, Mapping[str, Param]]) -> None:
        self.errors = dict(errors)
        self.partial = {st: dict(v) for st, v in partial.items()}
        super().__init__("; ".join(f"station {st}: {why}" for st, why in sorted(self.errors.items())))


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


@dataclass(frozen=True)
class AuditFinding:
    """One thing `audit` found (drives/audit.py Finding): severity "error" | "warning" | "info"."""
    severity: str
    rule: str                        # the rule's id ("comm_loss.keeps_running")
    code: str                        # the parameter code, or the figure ("watchdog")
    value: str                       # the value as read, with its unit
    why: str                         # why it matters
    fix: str                         # what to do
    manual: str                      # the card manual's line the fix stands on
    check: Mapping[str, Any] | None  # a checklist read step showing it fixed ({"param", "expect"} ...)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["check"] = None if self.check is None else dict(self.check)
        return d


@dataclass(frozen=True)
class AuditSkip:
    """A rule that did not run: not applicable to the family, or not checked on this drive."""
    rule: str
    topic: str
    reason: str
    manual: str

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class AuditResult:
    """The audit of one drive: its findings (worst first), the rules that do not apply to its
    family and those that could not be checked, with the figures the rules used."""
    station: int
    profile: str
    layout: str
    ident: int | None
    watchdog_s: float                # the DP watchdog the master sets
    cycle_s: float | None            # the master's bus cycle the watchdog was checked against
    max_reaction_s: float | None     # the process's limit for a drive without its master
    findings: tuple[AuditFinding, ...]
    not_applicable: tuple[AuditSkip, ...]
    not_checked: tuple[AuditSkip, ...]
    checked: tuple[str, ...]         # the ids of the rules that ran

    @property
    def ident_hex(self) -> str | None:
        return _hex(self.ident)

    @property
    def errors(self) -> int:
        return sum(1 for f in self.findings if f.severity == "error")

    @property
    def warnings(self) -> int:
        return sum(1 for f in self.findings if f.severity == "warning")

    def to_dict(self) -> dict[str, Any]:
        return {"station": self.station, "ident": self.ident, "ident_hex": self.ident_hex,
                "profile": self.profile, "layout": self.layout, "watchdog_s": self.watchdog_s,
                "cycle_s": self.cycle_s, "max_reaction_s": self.max_reaction_s,
                "errors": self.errors, "warnings": self.warnings,
                "findings": [f.to_dict() for f in self.findings],
                "not_applicable": [s.to_dict() for s in self.not_applicable],
                "not_checked": [s.to_dict() for s in self.not_checked],
                "checked": list(self.checked)}
