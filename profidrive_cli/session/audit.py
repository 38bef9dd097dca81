"""`pdrive audit` on one connected drive: the family's rules (Drive.audit_rules, drives/audit.py)
run over a DriveStation, reading through its Parameters; findings with their severity, code, value,
why it matters and the manual's fix. Nothing is written; the drive is not started (a rule may send
one of the card's no-motion control words to read a status bit: drives/toyo/audit.py).

    audit_session(sess, watchdog_s=None, cycle_s=None, max_reaction_s=None) -> AuditReport
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from profidrive_cli import UsageError
from profidrive_cli.drives.audit import SEVERITIES, TOPICS, AuditRule, Finding
from profidrive_cli.dp.services import watchdog_factors
from profidrive_cli.drives.base import DriveError, ParamValue

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.drives.base import Drive
    from profidrive_cli.session.station import DriveStation

__all__ = ["AuditReport", "Skipped", "audit_session"]


@dataclass(frozen=True)
class Skipped:
    """A rule that did not run on this drive: not applicable to the family, or not checked here."""
    rule: str
    topic: str
    reason: str
    manual: str


@dataclass
class AuditReport:
    """What the audit found on one drive."""
    station: int
    profile: str
    layout: str
    ident: int | None
    watchdog_s: float
    cycle_s: float | None
    max_reaction_s: float | None
    findings: list[Finding] = field(default_factory=list)
    not_applicable: list[Skipped] = field(default_factory=list)
    not_checked: list[Skipped] = field(default_factory=list)
    checked: list[str] = field(default_factory=list)

    def count(self, severity: str) -> int:
        return sum(1 for f in self.findings if f.severity == severity)


class _Context:
    """The AuditContext of a connected session (drives/audit.py)."""

    def __init__(self, sess: "DriveStation", watchdog_s: float, cycle_s: float | None,
                 max_reaction_s: float | None) -> None:
        self.sess = sess
        self._watchdog_s = watchdog_s
        self._cycle_s = cycle_s
        self._max_reaction_s = max_reaction_s

    @property
    def drive(self) -> "Drive":
        return self.sess.need_drive()

    @property
    def watchdog_s(self) -> float:
        return self._watchdog_s

    @property
    def cycle_s(self) -> float | None:
        return self._cycle_s

    @property
    def max_reaction_s(self) -> float | None:
        return self._max_reaction_s

    def can_read(self, code: str) -> bool:
        return self.drive.can_read(code)

    def read(self, code: str) -> ParamValue:
        return self.sess.params.read(code)


def watchdog_as_set(ms: float) -> float:
    """The watchdog (s) a Set_Prm asking for `ms` gives the station: WD_Fact_1 x WD_Fact_2 x 10 ms,
    rounded up to what the factors hold (dp/services.py; e.g. 2561 ms -> 129 x 2 x 10 ms = 2580 ms)."""
    try:
        f1, f2 = watchdog_factors(ms)
    except ValueError as e:
        raise UsageError(f"audit: {e}") from None
    return f1 * f2 * 10 / 1000.0


def _order(f: Finding) -> tuple[int, int]:
    topic = f.rule.split(".")[0]
    return (SEVERITIES.index(f.severity) if f.severity in SEVERITIES else len(SEVERITIES),
            TOPICS.index(topic) if topic in TOPICS else len(TOPICS))


def audit_session(sess: "DriveStation", *, watchdog_s: float | None = None,
                  cycle_s: float | None = None, max_reaction_s: float | None = None) -> AuditReport:
    """Run the family's rules on the open session `sess`. watchdog_s: the DP watchdog the master
    sets (default: the session's; either as the Set_Prm's factors give it); cycle_s: the master's bus cycle (default: the session's own
    cycle); max_reaction_s: how long the process allows the drive to run on without its master."""
    for name, v in (("watchdog", watchdog_s), ("cycle", cycle_s), ("max reaction", max_reaction_s)):
        if v is not None and not v > 0:
            raise UsageError(f"audit: {name} {v!r} must be above 0 s")
    d, prof = sess.need_drive(), sess.profile
    assert prof is not None and sess.address is not None      # the session is open
    wd = watchdog_as_set(watchdog_s * 1000.0 if watchdog_s is not None else sess.watchdog_ms)
    if cycle_s is None and sess.cycle_hz:
        cycle_s = 1.0 / float(sess.cycle_hz)
    rep = AuditReport(int(sess.address), prof.name, str(sess.layout), sess.ident, wd, cycle_s,
                      max_reaction_s)
    ctx = _Context(sess, wd, cycle_s, max_reaction_s)
    rules: list[AuditRule] = list(type(d).audit_rules(prof))
    for rule in rules:
        if rule.run is None:
            rep.not_applicable.append(Skipped(rule.id, rule.topic, rule.not_applicable, rule.manual))
            continue
        missing = [c for c in rule.needs if not ctx.can_read(c)]
        if missing:
            why = (f"layout {sess.layout} has no parameter channel (choose one with it, e.g. --ppo 1)"
                   if not d.has_param_channel else
                   f"{', '.join(missing)} cannot be read on this drive")
            rep.not_checked.append(Skipped(rule.id, rule.topic, why, rule.manual))
            continue
        try:
            rep.findings.extend(rule.run(ctx))
        except (DriveError, UsageError, KeyError, ValueError) as e:
            rep.not_checked.append(Skipped(rule.id, rule.topic, f"cannot read: {e}", rule.manual))
            continue
        rep.checked.append(rule.id)
    rep.findings.sort(key=_order)
    return rep
