"""Parameters: the parameter services of one station (a session.DriveStation builds one as
`self.params`). A write is planned, then executed: plan(code, value) resolves the code once
(Drive.param_info, the closest codes or the code's family when the station's family does not address
it) and makes every check once -- writable, not dangerous unless allowed, the typed value parsed, the
exact-value check (Drive.value_problem: resolution, range, listed codes, wire width) -- into a
WritePlan; execute(plan) refuses a stop-only parameter while the motor turns, writes the resolved
parameter (Drive.write_resolved: no second resolve, no second check) and returns the value read back.
Also reading, the danger words, the codec's notes, saving to non-volatile memory; dump and compare
(backup.py), restore on plans (restore.py), the dump file (dumpfile.py). Reads only the station's
public attributes (params.Host); talks to the card only through drives.base.Drive.
"""

from __future__ import annotations

from typing import Any, Callable

from profidrive_cli import PdriveError, UsageError
from profidrive_cli.drives.base import Drive, DriveError, ParamInfo, ParamValue
from profidrive_cli.drives.profile import Profile
from profidrive_cli.drives.values import danger, profile_value_problem
import profidrive_cli.session.backup as backup
import profidrive_cli.session.dumpfile as dumpfile
import profidrive_cli.session.restore as restore
from profidrive_cli.session.cycle import Sample
from profidrive_cli.session.paramtypes import (Host, ParamRow, WritePlan, dangerous_words, parse_text,
                                           unknown_code_message, with_text)

__all__ = ["Parameters", "ParamRow", "WritePlan"]

Progress = Callable[[int, int, str], None]


class Parameters:
    """The parameters of the station `host` (a DriveStation: its profile, address, Drive, ...)."""

    #: read a dump file (file:line errors; a cut-off format-2 file is refused): dumpfile.load_dump
    load_dump = staticmethod(dumpfile.load_dump)

    def __init__(self, host: Host) -> None:
        self.host = host

    # -- the station ------------------------------------------------------------------------------
    @property
    def profile(self) -> Profile:
        prof = self.host.profile
        if prof is None:
            raise PdriveError("Parameters: the station is not identified yet")
        return prof

    @property
    def address(self) -> int | None:
        return self.host.address

    @property
    def ident(self) -> int | None:
        return self.host.ident

    @property
    def layout(self) -> str | None:
        return self.host.layout

    @property
    def port(self) -> str:
        """The port's name ('' where the link has none)."""
        return str(getattr(self.host.master.link, "name", ""))

    def need_drive(self) -> Drive:
        return self.host.need_drive()

    def warn(self, text: str) -> None:
        self.host.warn(text)

    # -- one parameter ----------------------------------------------------------------------------
    def info(self, code: str) -> ParamInfo:
        """How the station's family addresses `code` (no bus traffic). UsageError with the closest
        codes of the family, or with the family the code belongs to."""
        d = self.need_drive()
        text = code.strip()
        if not text:
            raise UsageError("empty parameter code")
        try:
            return d.param_info(text)
        except UsageError as e:
            raise UsageError(unknown_code_message(self.profile, self.address, text, str(e))) from None

    def parse(self, code: str | ParamInfo, text: str | float | int) -> float | int:
        """A value typed by the user -> int/float (the card's notation where the profile has a
        `format:`); UsageError saying what was expected."""
        info = code if isinstance(code, ParamInfo) else self.info(code)
        return parse_text(self.profile, info, text)

    def read(self, code: str) -> ParamValue:
        """Read `code` (an unknown code: the closest ones / the right family), with its text."""
        return self.read_info(self.info(code))

    def read_info(self, info: ParamInfo) -> ParamValue:
        """Read the parameter `info` (from info()) without resolving it again, with its text."""
        return with_text(self.profile, self.need_drive().read_resolved(info))

    def danger_of(self, info: ParamInfo) -> str | None:
        """What writing this parameter does, in words, when the profile marks it `dangerous: true`
        (also when it is reached by its raw PNU/index or register); None otherwise."""
        if info.param is not None:
            return danger(info.param)
        d = self.host.drive
        if d is None:
            return None
        try:
            hits = d.params_at(info)
        except (UsageError, DriveError):
            return None
        return next((danger(q) for q in hits if danger(q)), None)

    def check_dangerous(self, info: ParamInfo, allow_dangerous: bool = False) -> None:
        """UsageError (exit 2) for a dangerous parameter unless allow_dangerous."""
        what = self.danger_of(info)
        if what and not allow_dangerous:
            raise UsageError(dangerous_words(info, what))

    def stopped_for(self, info: ParamInfo) -> str | None:
        """None when the parameter may be written now; else why not (stop-only while running)."""
        if info.access != "stop":
            return None
        st = self.need_drive().cycle()
        if st.running or not st.stopped:
            hz = Sample(0, st, self.host.motion.fmax_hz, 0, 0, {}).actual_hz
            return (f"{info.code} ({info.name}) can only be changed while the motor is "
                    f"stopped (the drive is {st.state}" + (f", {hz:g} Hz" if hz else "") + "); stop it first")
        return None

    # -- the checked write: preflight, plan, then execute -----------------------------------------
    def entry_of(self, code: str) -> Any:
        """The profile entry `code` reaches, from the profile alone (no drive): its own code, or the
        raw address of a listed entry the way the family resolves one (Fuji PNU264[3] is H03); None
        for an address no entry has or a code the family does not address."""
        p = self.profile.param(code)
        if p is not None:
            return p
        from profidrive_cli.drives import drive_class
        try:
            return drive_class(self.profile).param_label_for(self.profile, code)[1]
        except UsageError:
            return None

    def preflight(self, code: str, text: str, *, allow_dangerous: bool = False) -> str | None:
        """The checks the profile alone allows, before the drive is connected (a question before a
        write on a real port comes after them, and nothing is written yet): a dangerous entry
        without allow_dangerous, a number the entry cannot hold (drives.values.profile_value_problem).
        Returns what writing it does when it is dangerous (for the question), else None."""
        p = self.entry_of(code.strip())
        what = danger(p)
        if what and not allow_dangerous:
            raise UsageError(f"{code} is dangerous: writing it {what}; nothing was written "
                             f"(add --allow-dangerous, and confirm, to write it)")
        if p is not None:
            try:                               # a number as `pdrive param set` reads one
                float(text) if not text.lower().lstrip("-").startswith("0x") else int(text, 16)
            except ValueError:
                return what                    # not a number: plan() parses it (the card's notation)
            hexa = text.strip().lower().lstrip("-").startswith("0x")
            v: float | int = int(text, 16) if hexa else float(text)
            msg = profile_value_problem(self.profile, p, v)
            if msg:
                raise UsageError(msg)
        return what

    def plan(self, code: str | ParamInfo, value: str | float | int, *,
             allow_dangerous: bool = False) -> WritePlan:
        """Resolve `code` once (or take the ParamInfo given) and check the write once, no bus
        traffic: the value parsed when typed, writable, not dangerous unless allow_dangerous, the
        exact-value check (Drive.value_problem). UsageError (exit 2) for the first problem."""
        info = code if isinstance(code, ParamInfo) else self.info(code)
        v = parse_text(self.profile, info, value) if isinstance(value, str) else value
        p = info.param
        if p is not None and not p.writable:
            raise UsageError(f"{info.code} ({info.name}) is read-only")
        what = self.danger_of(info)
        if what and not allow_dangerous:
            raise UsageError(dangerous_words(info, what))
        msg = self.need_drive().value_problem(info, v)
        if msg:
            raise UsageError(msg)
        return WritePlan(code=info.code if isinstance(code, ParamInfo) else code.strip(), info=info,
                         value=v, text=str(value).strip(), danger=what or None,
                         allowed=allow_dangerous, stop_only=info.access == "stop")

    def execute(self, plan: WritePlan, *, check_running: bool = True) -> ParamValue:
        """Write a plan: a stop-only parameter is refused while the motor turns (DriveError; one
        cycle to see it, unless check_running=False); then the resolved parameter is written,
        without resolving or checking it again, and the value read back is returned."""
        if check_running and plan.stop_only:
            why = self.stopped_for(plan.info)
            if why:
                raise DriveError(why)
        return with_text(self.profile, self.need_drive().write_resolved(plan.info, plan.value))

    def write(self, code: str, value: str | float | int, *, check_running: bool = True,
              allow_dangerous: bool = False) -> ParamValue:
        """plan() then execute(): the checked write, returning the value read back."""
        return self.execute(self.plan(code, value, allow_dangerous=allow_dangerous),
                            check_running=check_running)

    # -- notes and saving -------------------------------------------------------------------------
    def notes(self) -> list[str]:
        """Remarks the codec collected (e.g. Fuji: 'o30 takes effect after a power cycle'); cleared."""
        d = self.host.drive
        return d.take_notes() if d is not None else []

    def save_support(self) -> str:
        """'command' (the card has a save command), 'automatic' (every write is stored), or
        'unsupported'."""
        return self.need_drive().save_support()

    def save(self) -> str:
        """Store parameters in non-volatile memory; returns what happened in words."""
        how = self.save_support()
        if how == "automatic":
            return f"{self.profile.name}: every parameter write is stored by the card itself (no separate save)"
        if how == "unsupported":
            raise DriveError(f"{self.profile.name}: this card has no save command; the value is "
                             f"written but may be lost at power-off")
        self.need_drive().save()
        return "saved to non-volatile memory"

    # -- dump / compare / restore (backup.py, restore.py) -----------------------------------------
    def dump_plan(self) -> list[tuple[str, Any, str]]:
        """(code, ParamDef, kind) for every parameter of the profile the family can read."""
        return backup.dump_plan(self)

    def dump(self, progress: Progress | None = None, changed: bool = False) -> dict[str, Any]:
        """Read every readable parameter; a YAML-ready document with the station's identity
        (changed: only the settings that differ from the profile's factory defaults)."""
        return backup.dump(self, progress, changed)

    def factory_diff(self, progress: Progress | None = None) -> list[ParamRow]:
        """Each setting against the profile's factory default (backup.factory_diff; nothing written)."""
        return backup.factory_diff(self, progress)

    def compare(self, doc: dict[str, Any], progress: Progress | None = None,
                allow_dangerous: bool = False, check_identity: bool = True) -> list[ParamRow]:
        """Each parameter of a loaded dump against the drive (ParamRow; nothing is written)."""
        return backup.compare(self, doc, progress, allow_dangerous, check_identity)

    def restore_problems(self, doc: dict[str, Any], rows: list[ParamRow],
                         allow_dangerous: bool = False) -> list[str]:
        """Every reason not to write anything, one line each (restore.py)."""
        return restore.restore_problems(self, doc, rows, allow_dangerous)

    def restore(self, doc: dict[str, Any], dry_run: bool = False, progress: Progress | None = None,
                allow_dangerous: bool = False, only: tuple[str, ...] = (),
                exclude: tuple[str, ...] = ()) -> list[ParamRow]:
        """Validate every row into a plan, then write what differs, reading each write back
        (restore.py): RestoreRefused (nothing written) / RestoreInterrupted (which rows landed).
        only / exclude: the profile's parameter groups the restore is limited to / leaves alone."""
        return restore.restore(self, doc, dry_run, progress, allow_dangerous, only, exclude)
