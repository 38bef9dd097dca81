"""Restoring a parameter dump as validate-all-then-write, for session/parameters.py (Parameters.restore
and restore_problems call these with the Parameters, through its public API: params.ParamView). Each
row to write becomes a WritePlan (Parameters.plan: resolved once, checked once); the writes are the
plans executed (Parameters.execute), each read back; the file itself is loaded by dumpfile.py.

restore(): every row is checked before the first write -- the station's profile and ident against the
file's, the code exists and is readable, writable, the value is one the parameter holds exactly
(drives/values.py), stop-only parameters need the motor stopped; dangerous rows are skipped unless
allow_dangerous. Any problem -> RestoreRefused(.problems, one line each with file:line), nothing
written. Then only what differs is written, each write read back; a failure part-way (link lost, a
refusal) -> RestoreInterrupted(.rows): 'applied' landed, 'unknown' was in flight, 'not written' was not
reached.

Scopes: only / exclude name the profile's parameter groups (`groups:`, drives/profile.py); the rows
outside the scope are marked 'skipped' (why 'out of scope') before any row is planned, so they are
neither checked nor written. An unknown group name is a UsageError listing the profile's groups.
"""

from __future__ import annotations

from typing import Any, Callable

from profidrive_cli import BusError, UsageError
from profidrive_cli.drives.base import DriveError, value_text
from profidrive_cli.drives.profile import Profile, load_profile
from profidrive_cli.session.backup import same_value
from profidrive_cli.session.discovery import family_words
from profidrive_cli.session.paramtypes import ParamRow, ParamView, WritePlan


class RestoreRefused(UsageError):
    """The file has problems; nothing was written. .problems: one line each."""

    def __init__(self, problems: list[str]) -> None:
        more = f" (and {len(problems) - 1} more problem(s))" if len(problems) > 1 else ""
        super().__init__(f"nothing was written: {problems[0]}{more}")
        self.problems = problems


class RestoreInterrupted(BusError):
    """A restore stopped part-way (link lost, a write refused). .rows say what landed."""

    def __init__(self, rows: list[ParamRow], cause: BaseException) -> None:
        landed = sum(r.result == "applied" for r in rows)
        left = sum(r.result in ("not written", "unknown", "refused") for r in rows)
        super().__init__(f"restore interrupted: {cause}; {landed} row(s) written and read back, "
                         f"{left} not (see the table)")
        self.rows = rows
        self.cause = cause


def scope_problem(profile: Profile, only: tuple[str, ...], exclude: tuple[str, ...]) -> str | None:
    """The one line for a group name the profile does not have (--only / --exclude), or None."""
    for name in (*only, *exclude):
        if name not in profile.groups:
            known = ", ".join(profile.groups) or "none"
            return f"unknown parameter group '{name}' for {profile.name} (groups: {known})"
    return None


def apply_scope(profile: Profile, rows: list[ParamRow], only: tuple[str, ...],
                exclude: tuple[str, ...]) -> None:
    """Mark the rows outside the scope 'skipped' (why 'out of scope'): with only, the rows of no
    group named there; every row of an excluded group (exclude wins over only)."""
    if not only and not exclude:
        return
    for r in rows:
        g = profile.group_of(r.code)
        if g is not None and g in exclude:
            r.result, r.why, r.reason = "skipped", "out of scope", f"group {g} excluded (--exclude)"
        elif only and g not in only:
            r.result, r.why = "skipped", "out of scope"
            r.reason = f"group {g} not in --only" if g else "in no group (--only)"


def restore_problems(params: ParamView, doc: dict[str, Any], rows: list[ParamRow],
                     allow_dangerous: bool = False) -> list[str]:
    """Every reason not to write anything, one line each (no bus writes; the rows from compare()).
    Marks dangerous rows 'skipped' unless allow_dangerous."""
    return check_rows(params, doc, rows, allow_dangerous)[0]


def check_rows(params: ParamView, doc: dict[str, Any], rows: list[ParamRow],
               allow_dangerous: bool) -> tuple[list[str], list[tuple[ParamRow, WritePlan]]]:
    """restore_problems(), and the plan of each row to write (Parameters.plan: its value parsed,
    writable, exact), for restore() to execute."""
    problems: list[str] = []
    plans: list[tuple[ParamRow, WritePlan]] = []
    path = doc.get("_path", "the file")
    st = doc.get("station") or {}
    name = st.get("profile")
    if name and name != params.profile.name:
        try:
            other: str | None = load_profile(str(name)).name
        except UsageError:
            other = None
        if other != params.profile.name:
            problems.append(f"{path}: dumped from a {name} station ({st.get('title', '')}); station "
                            f"{params.address} is {family_words(params.profile)}")
    ident = st.get("ident")
    if ident is not None:
        try:
            fid: int | None = int(str(ident), 0)
        except ValueError:
            fid = None
        if fid != params.ident:
            problems.append(f"{path}: dumped from a station with ident {ident}; station {params.address} "
                            f"reports 0x{params.ident:04X}")
    running = None
    for r in rows:
        where = f"{path}:{r.line}" if r.line else path
        if r.result == "missing":
            problems.append(f"{where}: {r.code}: cannot be read from the drive: {r.reason}")
            continue
        if r.result == "skipped" and r.why == "unknown":
            problems.append(f"{where}: {r.code}: {r.reason}")
            continue
        if r.result == "skipped" and r.why == "dangerous":
            r.reason = (f"dangerous: writing it {params.danger_of(params.info(r.code)) or r.reason} "
                        f"(--allow-dangerous writes it)")
            continue
        if r.result == "skipped" and r.why == "read-only":
            problems.append(f"{where}: {r.code} ({r.name}) is read-only")
            continue
        if r.result not in ("differs", "unchanged"):
            continue
        info = params.info(r.code)
        what = params.danger_of(info)
        if what and not allow_dangerous:
            r.result, r.reason, r.why = ("skipped", f"dangerous: writing it {what} "
                                         f"(--allow-dangerous writes it)", "dangerous")
            continue
        try:
            plan = params.plan(info, r.file_value, allow_dangerous=True)
        except UsageError as e:
            problems.append(f"{where}: {e}")
            continue
        if r.result == "differs" and info.access == "stop":
            if running is None:
                stc = params.need_drive().cycle()
                running = stc.running or not stc.stopped
            if running:
                problems.append(f"{where}: {r.code} ({r.name}) can only be changed while the motor is "
                                f"stopped, and the drive is running; stop it first")
        if r.result == "differs":
            plans.append((r, plan))
    return problems, plans


def restore(params: ParamView, doc: dict[str, Any], dry_run: bool = False,
            progress: Callable[[int, int, str], None] | None = None,
            allow_dangerous: bool = False, only: tuple[str, ...] = (),
            exclude: tuple[str, ...] = ()) -> list[ParamRow]:
    """Validate every row first (identity, existence, exact value, writability, dangerous, drive
    stopped where needed): any problem -> RestoreRefused listing them all, nothing written. Then
    write what differs (each row's plan), reading each write back. Rows: applied / unchanged /
    skipped / would apply (dry run). A write that fails, or a link lost mid-way ->
    RestoreInterrupted with the rows: 'applied' landed, 'unknown' was being written, 'not written'
    were not reached. only / exclude: parameter groups (apply_scope, before any row is planned)."""
    bad = scope_problem(params.profile, tuple(only), tuple(exclude))
    if bad:
        raise UsageError(bad)
    for w in doc.get("_warnings", []):
        params.warn(w)
    rows = params.compare(doc, progress, allow_dangerous=allow_dangerous, check_identity=False)
    apply_scope(params.profile, rows, tuple(only), tuple(exclude))
    problems, todo = check_rows(params, doc, rows, allow_dangerous)
    if problems:
        raise RestoreRefused(problems)
    if dry_run:
        for r, _ in todo:
            r.result = "would apply"
        return rows
    for r, _ in todo:
        r.result = "not written"
    for r, plan in todo:
        r.result = "unknown"
        try:
            # the row was checked with the drive stopped (check_rows): no second look per row
            params.execute(plan, check_running=False)
            back = params.need_drive().read_resolved(plan.info)
        except BusError as e:
            r.reason = f"the write or its read-back did not complete: {e}"
            raise RestoreInterrupted(rows, e) from e
        except UsageError as e:
            r.result, r.reason = "refused", str(e)
            raise RestoreInterrupted(rows, e) from e
        r.new_value = back.value
        pdef = params.profile.param(r.code.split("[", 1)[0])
        if same_value(back.value, r.file_value, pdef.scale if pdef is not None else None):
            r.result = "applied"
        else:
            r.result, r.reason = "refused", f"the drive kept {value_text(back.value, back.unit)}"
            raise RestoreInterrupted(rows, DriveError(f"{r.code}: {r.reason}"))
    return rows
