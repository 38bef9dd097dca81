"""The audit's rule objects (issue 28, `pdrive audit`): what a family's Drive.audit_rules() returns.

A rule belongs to one of six topics (TOPICS) and cites the line of the card's manual it stands on.
It either checks (a function of an AuditContext: the connected drive, the master's figures, reads
through the session's Parameters) and returns Findings, or says why the topic does not apply to the
family (`not_applicable`). The rule builders below are shared: each family module (drives/fuji/
audit.py, drives/moeller_audit.py, drives/toyo/audit.py, drives/yaskawa/audit.py) names its own
codes, values and manual lines. session/audit.py runs them; nothing here talks to the bus except
through the context.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable, Mapping, Protocol, Sequence

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.drives.base import Drive, ParamValue

#: the issue's six topics, in report order
TOPICS = ("comm_loss", "watchdog", "source", "ramps", "max_frequency", "save_mode")
#: finding severities, worst first
SEVERITIES = ("error", "warning", "info")

#: a checklist `read` step's fields that show a finding was fixed: {"param": code, "expect": v} or
#: {"param": code, "min": a, "max": b} (docs/checklists.md)
Check = Mapping[str, "float | int | str"]


@dataclass(frozen=True)
class Finding:
    """One thing the audit found on one drive."""
    severity: str                  # error | warning | info
    rule: str                      # the rule's id ("comm_loss.keeps_running")
    code: str                      # the parameter code, or what the figure is ("watchdog")
    value: str                     # the value as read, with its unit
    why: str                       # why it matters
    fix: str                       # what to do, in our words
    manual: str                    # the manual's line the fix stands on
    check: Check | None = None     # a checklist read step that shows it fixed (None: a note)


class AuditContext(Protocol):
    """What a rule may use (session/audit.py provides it for a connected DriveStation)."""

    @property
    def drive(self) -> "Drive": ...

    @property
    def watchdog_s(self) -> float:
        """The DP watchdog the master sets (s)."""

    @property
    def cycle_s(self) -> float | None:
        """The master's bus cycle (s) where known."""

    @property
    def max_reaction_s(self) -> float | None:
        """How long the process allows a drive to go on without its master (s); None: not given."""

    def can_read(self, code: str) -> bool:
        """The profile addresses `code` and the layout has a parameter channel."""

    def read(self, code: str) -> "ParamValue":
        """Read `code` through the session's Parameters (DriveError when the drive refuses)."""


@dataclass(frozen=True)
class AuditRule:
    """One rule of a family: a check, or the reason the topic does not apply."""
    id: str
    topic: str                                       # one of TOPICS
    title: str
    manual: str                                      # the manual line(s) the rule stands on
    run: Callable[[AuditContext], list[Finding]] | None = None
    not_applicable: str = ""                         # why the family has no such rule (run is None)
    needs: tuple[str, ...] = field(default=())       # parameter codes the rule reads

    def __post_init__(self) -> None:
        if self.topic not in TOPICS:
            raise ValueError(f"audit rule {self.id}: topic {self.topic!r} not one of {TOPICS}")
        if (self.run is None) == (not self.not_applicable):
            raise ValueError(f"audit rule {self.id}: give a check or a reason it does not apply")


def not_applicable(topic: str, reason: str, manual: str) -> AuditRule:
    """A topic the family's manual gives no setting for, with the reason."""
    return AuditRule(f"{topic}.not_applicable", topic, f"{topic}: not applicable", manual,
                     not_applicable=reason)


def _num(v: float | int) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def _text(pv: "ParamValue") -> str:
    t = f"{_num(pv.value)}{(' ' + pv.unit) if pv.unit else ''}"
    return f"{t} ({pv.text})" if pv.text and pv.text != _num(pv.value) else t


# -- comm loss --------------------------------------------------------------------------------
#: the fix and citation of a reaction's own warnings (Fuji H81), unless the family names its own
NOTE_FIX = "check the setting named, then run `pdrive commloss-test`"


def comm_loss_rule(manual: str, fix: str, check: Check | None, needs: tuple[str, ...] = (),
                   delay_code: str | None = None, note: tuple[str, str] | None = None) -> AuditRule:
    """The drive's reaction to a lost master, read by its own Drive.comm_loss_reaction (the hook
    the comm-loss test reads): error when it keeps running; the reaction time (the watchdog plus
    the card's delay) against the process's limit (max_reaction_s); the reaction's own warnings
    (Fuji H81), with `note` = (fix, manual line) where the family's warning stands on other lines
    than the reaction (default: NOTE_FIX and `manual`)."""
    note_fix, note_manual = note or (NOTE_FIX, manual)

    def run(ctx: AuditContext) -> list[Finding]:
        r = ctx.drive.comm_loss_reaction()
        if r is None:
            return []
        code = next(iter(r.settings), "comm-loss setting")
        others = ", ".join(f"{k} = {_num(v)}" for k, v in r.settings.items() if k != code)
        value = (_num(r.settings[code]) if code in r.settings else "fixed by the card") + \
            (f" ({others})" if others else "")
        out: list[Finding] = []
        if r.stop == "none":
            out.append(Finding("error", "comm_loss.keeps_running", code, value,
                               f"{r.words}: when the master (PLC) stops or its cable is cut, the drive "
                               f"goes on turning on its last command and nobody can stop it over the bus",
                               fix, manual, check))
        else:
            out.extend(_reaction_time(ctx, r.words, r.delay_s, code, value, fix, manual, delay_code))
        for w in r.warnings:
            out.append(Finding("warning", "comm_loss.note", code, value, w, note_fix, note_manual,
                               None))
        return out
    return AuditRule("comm_loss.reaction", "comm_loss", "reaction to a lost master", manual, run,
                     needs=needs)


def _reaction_time(ctx: AuditContext, words: str, delay_s: float, code: str, value: str, fix: str,
                   manual: str, delay_code: str | None) -> list[Finding]:
    """How long the drive runs on its last command after the master is lost: the DP watchdog the
    master sets (the station notices nothing before it expires) plus the card's own delay; against
    the process's limit (max_reaction_s). A reaction at the watchdog (no delay) is measured too: a
    watchdog alone above the limit is an error as well."""
    wd, limit = ctx.watchdog_s, ctx.max_reaction_s
    total = wd + delay_s
    sums = f"watchdog {wd:g} s + delay {delay_s:g} s" if delay_s > 0 else f"the watchdog {wd:g} s"
    if limit is None:
        if delay_s <= 0:
            return []
        return [Finding("warning", "comm_loss.delay", code, value,
                        f"{words}: the drive runs on its last command for {total:g} s ({sums}) "
                        f"after the master is lost; give --max-reaction to check it against the process",
                        "shorten the delay to what the process allows (0 acts at the watchdog)",
                        manual, None)]
    if total <= limit:
        return []
    why = (f"{words}: the drive runs on its last command for {total:g} s ({sums}), longer than the "
           f"{limit:g} s the process allows")
    if wd >= limit:                 # no delay can help: the master's watchdog alone is too long
        return [Finding("error", "comm_loss.delay", "watchdog", f"{wd * 1000:g} ms ({value})", why,
                        f"set the master's watchdog for this station below {limit:g} s (the process's "
                        f"limit){' and ' + fix if delay_s > 0 else ''}", manual, None)]
    most = max(0.0, limit - wd)
    if delay_code is not None:          # whole steps of the timer, not above the limit
        step = _step(ctx, delay_code)
        most = round(math.floor(most / step + 1e-9) * step, 6)
    return [Finding("error", "comm_loss.delay", code, value, why,
                    f"shorten the delay{f' ({delay_code})' if delay_code else ''} to at most {most:g} s "
                    f"(the process's {limit:g} s less the watchdog)", manual,
                    None if delay_code is None else {"param": delay_code, "max": most})]


def zero_data_rule(code: str, manual: str, fix: str, check: Check | None) -> AuditRule:
    """The drive's reaction to all-zero output data, read by its own Drive.zero_data_reaction (the
    hook `commloss-test --mode clear` reads): some masters send all-zero data to every slave when
    the PLC program stops or fails, and the watchdog never expires; a warning when the drive then
    keeps running (it depends on the master: not every one sends zeros)."""
    def run(ctx: AuditContext) -> list[Finding]:
        r = ctx.drive.zero_data_reaction("all-zero output data from the master")
        if r is None or r.stop != "none":
            return []
        value = _num(r.settings[code]) if code in r.settings else "not read"
        return [Finding("warning", "comm_loss.zero_data", code, value,
                        f"{r.words}: a master that sends all-zero data when its PLC stops (the link "
                        f"stays up, no watchdog expires) leaves the drive turning on its last command",
                        fix, manual, check)]
    return AuditRule("comm_loss.zero_data", "comm_loss", "reaction to all-zero data from a stopped PLC",
                     manual, run, needs=(code,))


# -- watchdog ---------------------------------------------------------------------------------
#: a watchdog shorter than this many master cycles drops the station on one late cycle or retry
WATCHDOG_CYCLES = 3


def watchdog_rule(manual: str) -> AuditRule:
    """The DP watchdog against the master's cycle: it must exceed the worst-case cycle (bus
    reference 4.3: else the slave leaves data exchange and answers RS); error at or below one
    cycle, warning below WATCHDOG_CYCLES cycles."""
    def run(ctx: AuditContext) -> list[Finding]:
        cyc = ctx.cycle_s
        if not cyc or cyc <= 0:
            return []
        wd = ctx.watchdog_s
        value = f"{wd * 1000:g} ms (master cycle {cyc * 1000:.3g} ms)"
        fix = (f"set the master's watchdog for this station to at least {WATCHDOG_CYCLES} cycles "
               f"({WATCHDOG_CYCLES * cyc * 1000:.0f} ms) plus the master's jitter")
        if wd <= cyc:
            return [Finding("error", "watchdog.short", "watchdog", value,
                            "the watchdog expires before the master's next telegram: the drive "
                            "leaves data exchange and trips its comm-loss reaction in normal operation",
                            fix, manual, None)]
        if wd < WATCHDOG_CYCLES * cyc:
            return [Finding("warning", "watchdog.short", "watchdog", value,
                            f"less than {WATCHDOG_CYCLES} master cycles: one late cycle or retry trips "
                            f"the drive's comm-loss reaction", fix, manual, None)]
        return []
    return AuditRule("watchdog.cycle", "watchdog", "DP watchdog against the master's cycle", manual, run)


# -- sources ----------------------------------------------------------------------------------
def source_rule(rule_id: str, code: str, want: Sequence[int], what: str, fix: str, manual: str,
                severity: str = "error", split: Mapping[int, str] | None = None,
                partner: tuple[str, Sequence[int], str] | None = None) -> AuditRule:
    """`code` must hold one of `want` for the bus to give `what` (run command, reference). Split
    control, the bus giving one of the two and another place the other, is a set-up the manuals
    offer: a warning naming the split ("source.split"), not an error. split: values of `code` that
    are such a split, with their words (Fuji y98 = 1, 2); partner: (code, want, what) of the other
    source setting: when it gives the bus its part, `code` not giving its own is a split (Moeller
    A001 / A002, Yaskawa b1-01 / b1-02)."""
    def run(ctx: AuditContext) -> list[Finding]:
        if not ctx.can_read(code):
            return []
        pv = ctx.read(code)
        v = int(pv.raw)
        if v in want:
            return []
        check: Check = ({"param": code, "expect": want[0]} if len(want) == 1 else
                        {"param": code, "min": min(want), "max": max(want)})
        words = split.get(v) if split else None
        if words is None and partner is not None and ctx.can_read(partner[0]):
            pv2 = ctx.read(partner[0])
            if int(pv2.raw) in partner[1]:
                words = (f"{partner[2]} from PROFIBUS ({partner[0]} = {_text(pv2)}), {what} from "
                         f"another place")
        if words is not None:
            return [Finding("warning", "source.split", code, _text(pv),
                            f"split control: {words}. The manual offers it, but the master alone "
                            f"cannot run the drive: check the other place is meant to give it",
                            f"if the bus is to give both: {fix}", manual, None)]
        return [Finding(severity, rule_id, code, _text(pv),
                        f"{what} does not come from PROFIBUS: the master's commands are ignored "
                        f"(or the drive runs from another place)", fix, manual, check)]
    return AuditRule(rule_id, "source", f"{what} from the field bus", manual, run, needs=(code,))


# -- ramps ------------------------------------------------------------------------------------
def ramp_rules(accel: str, decel: str, quick: str | None, manual: str, quick_manual: str
               ) -> list[AuditRule]:
    """Acceleration / deceleration 0 s (an abrupt start or stop: overcurrent / overvoltage trips and
    a coasting motor), and a quick stop slower than the normal stop."""
    def zero(code: str, what: str, harm: str) -> AuditRule:
        def run(ctx: AuditContext) -> list[Finding]:
            if not ctx.can_read(code):
                return []
            pv = ctx.read(code)
            if float(pv.value) > 0.0:
                return []
            step = _step(ctx, code)
            return [Finding("error", f"ramps.{what}_zero", code, _text(pv),
                            f"{what} time 0 s: {harm}",
                            f"set {code} to the time the machine needs from 0 to the maximum "
                            f"frequency", manual, {"param": code, "min": step})]
        return AuditRule(f"ramps.{what}_zero", "ramps", f"{what} time not 0 s", manual, run,
                         needs=(code,))

    rules = [zero(accel, "acceleration", "the drive tries to reach speed at once (overcurrent trip, "
                  "mechanical shock)"),
             zero(decel, "deceleration", "the drive tries to stop at once (overvoltage trip, then "
                  "the motor coasts)")]
    if quick is not None:
        q = quick

        def slower(ctx: AuditContext) -> list[Finding]:
            if not (ctx.can_read(q) and ctx.can_read(decel)):
                return []
            qv, dv = ctx.read(q), ctx.read(decel)
            if float(dv.value) <= 0.0 or float(qv.value) <= float(dv.value):
                return []
            return [Finding("warning", "ramps.quick_slower", q,
                            f"{_text(qv)} (normal stop {decel} = {_text(dv)})",
                            "the quick stop takes longer than the normal stop: a quick stop (OFF3) "
                            "from the master is not quick",
                            f"set {q} at or below {decel}", quick_manual,
                            {"param": q, "max": float(dv.value)})]
        rules.append(AuditRule("ramps.quick_slower", "ramps", "quick stop not slower than the "
                               "normal stop", quick_manual, slower, needs=(q, decel)))
    return rules


def _step(ctx: AuditContext, code: str) -> float:
    """The smallest value above 0 the parameter holds (its scale), for a checklist min."""
    p = ctx.drive.profile.param(code)
    scale = getattr(p, "scale", None) if p is not None else None
    return float(scale) if isinstance(scale, (int, float)) and scale > 0 else 0.01


# -- maximum frequency ------------------------------------------------------------------------
def max_frequency_rule(fmax: str, rated: str, manual: str) -> AuditRule:
    """The maximum frequency above the motor's rated (base) frequency: field weakening above the
    nameplate, which the motor and the machine must allow (a warning: it may be meant)."""
    def run(ctx: AuditContext) -> list[Finding]:
        if not (ctx.can_read(fmax) and ctx.can_read(rated)):
            return []
        fv, rv = ctx.read(fmax), ctx.read(rated)
        if float(rv.value) <= 0 or float(fv.value) <= float(rv.value):
            return []
        return [Finding("warning", "max_frequency.above_rating", fmax,
                        f"{_text(fv)} (base frequency {rated} = {_text(rv)})",
                        f"100 % on the bus is {_text(fv)}, above the motor's rated frequency: a full "
                        f"reference drives the motor above its nameplate speed (field weakening, less "
                        f"torque, mechanical limits)",
                        f"check the motor and the machine allow it; else set {fmax} to {rated}",
                        manual, {"param": fmax, "max": float(rv.value)})]
    return AuditRule("max_frequency.above_rating", "max_frequency", "maximum frequency within the "
                     "motor's rating", manual, run, needs=(fmax, rated))


# -- save mode --------------------------------------------------------------------------------
def save_mode_rule(code: str, volatile: Sequence[int], keep: int, why: str, fix: str, manual: str
                   ) -> AuditRule:
    """A storage setting whose `volatile` values lose bus writes at power-off."""
    def run(ctx: AuditContext) -> list[Finding]:
        if not ctx.can_read(code):
            return []
        pv = ctx.read(code)
        if int(pv.raw) not in volatile:
            return []
        return [Finding("warning", "save_mode.volatile", code, _text(pv), why, fix, manual,
                        {"param": code, "expect": keep})]
    return AuditRule("save_mode.volatile", "save_mode", "changes kept at power-off", manual, run,
                     needs=(code,))
