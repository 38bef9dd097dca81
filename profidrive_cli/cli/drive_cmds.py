"""pdrive run / status / param (get, set, dump, restore, diff) / faults — drive operations from the shell.

All protocol and safety logic lives in session/ (DriveStation); this module parses the
command line, asks for confirmation before writing to a real port, and renders (render_drive.py).
"""

from __future__ import annotations

import contextlib
from typing import TYPE_CHECKING, Any, Callable, Iterator, TypeVar

import click
from rich.markup import escape
from rich.progress import Progress

from profidrive_cli import BusError, UsageError
from profidrive_cli.cli.common import (BusOptions, bus_options, confirm_real_port, emit_json, err, out,
                                       station_address)
from profidrive_cli.cli import render_drive as R
# re-exported (explicitly, for mypy): audit_cmd imports them from here
from profidrive_cli.cli.drive_opts import _terminations as _terminations, drive_options as drive_options
from profidrive_cli.drives.base import DriveError
from profidrive_cli.api.station import (DriveStation, RestoreInterrupted, RestoreRefused,
                                    SessionTerminated)
from profidrive_cli.api.station import CARD_MANUAL, default_source, nothing_compared
from profidrive_cli.api.station import load_dump, not_dumped_words, write_dump
from profidrive_cli.api.station import scope_problem
from profidrive_cli.outfile import check_output_path

if TYPE_CHECKING:
    from profidrive_cli.cli.render_drive import RunView
    from profidrive_cli.api.station import ParamRow

T = TypeVar("T")
#: a before-connect callback (DriveStation's before_connect)
Before = Callable[[DriveStation], None]
#: the progress callback of a parameter pass: (done, total, code)
ProgressFn = Callable[[int, int, str], None]


# =============================================================================================
# shared options and helpers
# =============================================================================================


def _message(text: str) -> None:
    err.print(escape(text))


def _confirmer(opts: BusOptions, yes: bool, what: str) -> Before:
    """before_connect callback: writing to a real port needs --yes or a 'y' on the terminal
    (common.confirm_real_port: the same question io and checklist run ask)."""
    def before(session: DriveStation) -> None:
        assert session.profile is not None      # identify() chose it before the before-connect call
        confirm_real_port(opts.port, yes, f"{what} — station {session.address} "
                                          f"({session.profile.name}) on {opts.port}")
    return before


def _session(opts: BusOptions, address: int | None, profile_name: str | None, ppo: int | None,
             fmt: str | None, watchdog_ms: float, *, cycle_hz: float | None = 0.0,
             before: Before | None = None, log: str | None = None) -> DriveStation:
    """The station at the session level through the API (Bus.session on the bus of these options),
    not yet opened: `with` it opens the station; its exit stops the drive safely, releases the
    station and closes the port (own_port)."""
    if address is not None:
        station_address(address)
    # the config file's defaults for this station on this port (config.py), below the options
    defaults = opts.station_defaults(address)
    profile_name = profile_name or defaults.get("profile")
    layout = defaults.get("layout") if ppo is None and fmt is None else None
    return opts.open_bus(address).station(
        address, profile=profile_name, layout=layout, ppo=ppo, fmt=fmt, watchdog_ms=watchdog_ms,
        cycle_hz=cycle_hz, before_connect=before, on_message=_message, log_csv=log, own_port=True)


@contextlib.contextmanager
def run_ending(session: DriveStation, view: RunView, end: dict[str, Any], started: Callable[[], bool],
               extra: Callable[[], dict[str, Any]] | None = None) -> Iterator[None]:
    """How a run or a jog ends, whatever way it ends: the reason (SIGTERM, Ctrl-C, a bus error), the
    stop report, the final state, counters and warnings in `end`, and the view's last word.
    started() says whether the drive was started (for `stopped` when no stop was needed); extra()
    adds the command's own fields."""
    try:
        yield
    except SessionTerminated:
        end["reason"] = "SIGTERM"
        raise
    except KeyboardInterrupt:
        end["reason"] = "Ctrl-C"
        raise
    except BusError as e:
        end["reason"] = f"error: {e}"
        raise
    finally:
        rep = session.motion.stop_report
        end["stop"] = rep.to_dict() if rep is not None else None
        end["stopped"] = bool(rep.stopped) if rep is not None else not started()
        fs = session.motion.final_status
        if fs is not None:
            end["state"] = fs.state
            end["fault"] = fs.fault
        if extra is not None:
            end.update(extra())
        end["cycles"] = session.cycles
        end["counters"] = session.counters
        end["warnings"] = session.warnings
        if view.header:
            view.finish(end)


def _is_number(text: str) -> bool:
    try:
        float(text) if not text.lower().lstrip("-").startswith("0x") else int(text, 16)
        return True
    except ValueError:
        return False


def _split_address(args: tuple[str, ...], min_rest: int) -> tuple[int | None, list[str]]:
    """A leading number 0..125 is the station address when at least `min_rest` arguments follow."""
    rest = list(args)
    if len(rest) > min_rest and rest[0].isdigit():
        return station_address(int(rest[0])), rest[1:]
    return None, rest


# =============================================================================================
# pdrive status
# =============================================================================================


@click.command("status")
@click.argument("address", required=False, type=int)
@drive_options
@bus_options
@_terminations
def status_cmd(opts: BusOptions, address: int | None, profile_name: str | None, ppo: int | None,
               fmt: str | None, watchdog_ms: int) -> None:
    """One read of a drive's status: state, flags, speed, current fault."""
    # built on the Python API (api/): the bus, the drive and their ending; rendered from its session
    if address is not None:
        station_address(address)
    with opts.open_bus(address, handle_signals=True, on_message=_message) as bus:
        drive = bus.drive(address, profile=profile_name, layout=fmt, ppo=ppo,
                          watchdog_ms=watchdog_ms, cycle_hz=0.0)
        with drive.held() as s:     # the keep-alive thread keeps off the master meanwhile
            d = R.status_dict(s, s.motion.status())
    if opts.json:
        emit_json(R.status_json(d))
    else:
        R.print_status(d)


# =============================================================================================
# pdrive param get / set / dump / restore / diff
# =============================================================================================


class _ParamGroup(click.Group):
    """The param group; its `fleet` subgroup (cli/fleet_cmd.py) is loaded when it is asked for."""

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name == "fleet":
            from profidrive_cli.cli.fleet_cmd import fleet_group
            return fleet_group
        return super().get_command(ctx, name)

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted([*super().list_commands(ctx), "fleet"])


@click.group("param", cls=_ParamGroup)
def param_group() -> None:
    """Read and write drive parameters by their native codes (F03, A004, C1-01, dc-voltage, PNU23[1],
    REG0x0180); dump, restore and compare whole parameter sets."""


@param_group.command("get")
@click.argument("args", nargs=-1, required=True, metavar="[ADDRESS] CODE...")
@drive_options
@bus_options
@_terminations
def param_get(opts: BusOptions, args: tuple[str, ...], profile_name: str | None, ppo: int | None,
              fmt: str | None, watchdog_ms: int) -> None:
    """Read parameters (engineering value with unit, and the raw wire value)."""
    if len(args) == 1 and args[0].isdigit() and int(args[0]) <= 125:
        # a lone station address: the code is what is missing, not the address
        raise UsageError(f"param get: missing argument CODE after the address {args[0]} "
                         f"(e.g. pdrive param get {args[0]} F07)")
    address, codes = _split_address(args, 1)
    if not codes:
        raise UsageError("param get: give at least one parameter code")
    with _session(opts, address, profile_name, ppo, fmt, watchdog_ms) as s:
        assert s.profile is not None            # the open session has its profile
        infos = [s.params.info(c) for c in codes]     # every code checked before the first read
        values = [s.params.read_info(i) for i in infos]
    if opts.json:
        emit_json({"station": s.address, "profile": s.profile.name,
                   "parameters": [R.param_json(v) for v in values]})
    else:
        out.print(R.param_table(values))


@param_group.command("set", context_settings={"ignore_unknown_options": True})
@click.argument("args", nargs=-1, required=True, metavar="[ADDRESS] CODE VALUE")
@click.option("--save", is_flag=True, help="Store to non-volatile memory afterwards (where the card can).")
@click.option("--yes", is_flag=True, help="Do not ask before writing on a real port.")
@click.option("--allow-dangerous", is_flag=True,
              help="Needed (besides the confirmation) to write a parameter the profile marks dangerous "
                   "(data initialisation, auto-tuning).")
@drive_options
@bus_options
@_terminations
def param_set(opts: BusOptions, args: tuple[str, ...], save: bool, yes: bool, allow_dangerous: bool,
              profile_name: str | None, ppo: int | None, fmt: str | None, watchdog_ms: int) -> None:
    """Write one parameter: checked first (a value the parameter cannot hold exactly is refused,
    never rounded), read back after."""
    address, rest = _split_address(args, 2)
    bad = [a for a in rest if a.startswith("--")]
    if bad:
        raise UsageError(f"param set: unknown option {bad[0]}")
    if len(rest) != 2 or (address is None and rest[0].isdigit() and not _is_number(rest[1])):
        raise UsageError("param set: expected [ADDRESS] CODE VALUE")
    code, text = rest

    def before(session: DriveStation) -> None:
        # the profile is known here, the drive is not connected yet: nothing has been written;
        # a dangerous entry or a value it cannot hold is refused before anyone is asked
        what = session.params.preflight(code, text, allow_dangerous=allow_dangerous)
        words = f"write {code} = {text}" + (f" — DANGEROUS: {what}" if what else "")
        _confirmer(opts, yes, words)(session)

    with _session(opts, address, profile_name, ppo, fmt, watchdog_ms, before=before) as s:
        assert s.profile is not None            # the open session has its profile
        params = s.params
        # the code resolved once and every check made once; execute() neither resolves nor checks again
        plan = params.plan(code, text, allow_dangerous=allow_dangerous)
        try:
            old = params.read_info(plan.info) if plan.info.access != "wo" else None
        except DriveError:
            old = None
        new = params.execute(plan)
        saved = params.save() if save else None
        notes = params.notes()
    if opts.json:
        emit_json({"station": s.address, "profile": s.profile.name, "code": new.code,
                   "old": R.param_json(old) if old else None, "new": R.param_json(new),
                   "saved": saved, "notes": notes})
        return
    # the same value text as `param get` (the card's notation where the profile has a `format:`)
    was = f" (was {old.text or R.value_text(old.value, old.unit)})" if old is not None else ""
    out.print(f"{escape(new.code)} ({escape(new.name)}) = {escape(new.text or R.value_text(new.value, new.unit))}"
              f"{escape(was)}")
    if saved:
        out.print(escape(saved))
    for n in notes:
        err.print(escape(f"note: {n}"))


@param_group.command("dump")
@click.argument("address", required=False, type=int)
@click.option("-o", "--output", required=True, metavar="FILE.yaml", help="Where to write the YAML.")
@click.option("--changed", is_flag=True,
              help="Only the settings whose value differs from the factory default (the profile's).")
@drive_options
@bus_options
@_terminations
def param_dump(opts: BusOptions, address: int | None, output: str, changed: bool, profile_name: str | None,
               ppo: int | None, fmt: str | None, watchdog_ms: int) -> None:
    """Read every readable parameter into a YAML file (with the station's identity and profile).
    An existing file is replaced only when the dump is complete."""
    check_output_path(output, "-o")             # before the bus is opened
    with _session(opts, address, profile_name, ppo, fmt, watchdog_ms) as s:
        assert s.profile is not None            # the open session has its profile
        doc = _with_progress(opts, "reading parameters", lambda prog: s.params.dump(prog, changed=changed))
    write_dump(doc, output)                     # through outfile.OutputFile
    n_set, n_ro, n_bad = len(doc["parameters"]), len(doc["readonly"]), len(doc.get("unreadable", {}))
    absent = doc.get("not_dumped")
    if opts.json:
        d: dict[str, Any] = {"file": output, "station": s.address, "profile": s.profile.name, "settings": n_set,
             "readonly": n_ro, "unreadable": n_bad}
        if changed:
            d["no_factory_default"] = len(doc["no_factory_default"])
        if absent:
            d["not_dumped"] = {"count": len(absent["codes"]), "why": absent["why"]}
        emit_json(d)
        return
    if absent:
        err.print(escape(f"note: {not_dumped_words(absent)}"))
    if changed:
        out.print(f"station {s.address} ({escape(s.profile.name)}): {n_set} setting(s) changed from the "
                  f"factory default written to {escape(output)}; {len(doc['no_factory_default'])} with "
                  f"no factory default known (listed under 'no_factory_default')")
    else:
        out.print(f"station {s.address} ({escape(s.profile.name)}): {n_set} settings and {n_ro} read-only "
                  f"values written to {escape(output)}" + (f"; {n_bad} could not be read (listed under "
                                                            f"'unreadable')" if n_bad else ""))


def _groups_arg(values: tuple[str, ...], option: str) -> tuple[str, ...]:
    """--only a --only b,c -> (a, b, c). An empty name (--only '', --only ',', --only 'a,,b') is bad
    input: read as "no scope" it would restore every group, the opposite of what was asked."""
    out: list[str] = []
    for v in values:
        names = [g.strip() for g in v.split(",")]
        if not all(names):
            raise UsageError(f"{option} {v!r}: an empty group name; give group names such as "
                             f"{option} motor,communication")
        out += names
    return tuple(out)


def _file_args(args: tuple[str, ...], what: str) -> tuple[int | None, str]:
    address, rest = _split_address(args, 1)
    if len(rest) != 1:
        raise UsageError(f"param {what}: expected [ADDRESS] FILE.yaml")
    return address, rest[0]


@param_group.command("restore")
@click.argument("args", nargs=-1, required=True, metavar="[ADDRESS] FILE.yaml")
@click.option("--dry-run", is_flag=True, help="Show what would be written; write nothing.")
@click.option("--yes", is_flag=True, help="Do not ask before writing on a real port.")
@click.option("--allow-dangerous", is_flag=True,
              help="Also write rows the profile marks dangerous (skipped otherwise).")
@click.option("--only", "only", multiple=True, metavar="GROUP",
              help="Restore only these parameter groups (the profile's groups: motor, communication, "
                   "protection, application; repeat or separate with commas).")
@click.option("--exclude", "exclude", multiple=True, metavar="GROUP",
              help="Leave these parameter groups untouched (e.g. --exclude motor,communication).")
@drive_options
@bus_options
@_terminations
def param_restore(opts: BusOptions, args: tuple[str, ...], dry_run: bool, yes: bool, allow_dangerous: bool,
                  only: tuple[str, ...], exclude: tuple[str, ...], profile_name: str | None,
                  ppo: int | None, fmt: str | None, watchdog_ms: int) -> None:
    """Write back what differs from a dump. Every row is checked first (drive identity, code, exact
    value, writability, motor stopped where needed): any problem and nothing is written. Each write
    is read back. Ends with a table. --only / --exclude limit it to parameter groups."""
    address, path = _file_args(args, "restore")
    doc = load_dump(path)
    only_g, excl_g = _groups_arg(only, "--only"), _groups_arg(exclude, "--exclude")
    confirm = None if dry_run else _confirmer(opts, yes, f"restore parameters from {path}")

    def before(session: DriveStation) -> None:
        assert session.profile is not None      # identify() chose it before the before-connect call
        bad = scope_problem(session.profile, only_g, excl_g)   # before anyone is asked
        if bad:
            raise UsageError(bad)
        if confirm is not None:
            confirm(session)
    try:
        with _session(opts, address, profile_name, ppo, fmt, watchdog_ms, before=before) as s:
            rows = _with_progress(opts, "comparing", lambda prog: s.params.restore(
                doc, dry_run=dry_run, progress=prog, allow_dangerous=allow_dangerous, only=only_g,
                exclude=excl_g))
            notes = s.params.notes()
    except RestoreRefused as e:
        if not opts.json:
            for line in e.problems:
                err.print(escape(line))
        refused = UsageError(f"{path}: {len(e.problems)} problem(s); nothing was written")
        # under --json the error object carries them (one document on stdout)
        refused.json_details = {  # type: ignore[attr-defined]  # read by cli/main.py with getattr
            "file": path, "written": 0, "problems": e.problems}
        raise refused from None
    except RestoreInterrupted as e:
        _print_rows(opts, s, e.rows, "restore", False, interrupted=str(e))
        raise
    _print_rows(opts, s, rows, "restore", dry_run)
    for n in notes:
        err.print(escape(f"note: {n}"))
    skipped = [r.code for r in rows if r.why == "dangerous"]
    if skipped and not opts.json:
        err.print(escape(f"skipped (dangerous; --allow-dangerous writes them): {', '.join(skipped)}"))


@param_group.command("diff")
@click.argument("args", nargs=-1, required=False, metavar="[ADDRESS] FILE.yaml | [ADDRESS] --defaults")
@click.option("--defaults", is_flag=True,
              help="Compare with the factory defaults (the profile's; each value's source shown: the "
                   "card manual or the host drive's) instead of a file.")
@drive_options
@bus_options
@_terminations
def param_diff(opts: BusOptions, args: tuple[str, ...], defaults: bool, profile_name: str | None,
               ppo: int | None, fmt: str | None, watchdog_ms: int) -> None:
    """Compare the drive with a dump, or with the factory defaults (--defaults); nothing is written.
    Exit code as diff's: 0 when the drive holds what the file says (--defaults: nothing changed from
    the factory), 1 when a parameter differs or cannot be read (--defaults: or when no setting could
    be compared with a factory value: nothing verified), 2 for bad input."""
    if defaults:
        address, rest = _split_address(tuple(args), 0)
        if rest:
            raise UsageError("param diff --defaults: expected [ADDRESS] only (no file)")
        with _session(opts, address, profile_name, ppo, fmt, watchdog_ms) as s:
            rows = _with_progress(opts, "comparing", lambda prog: s.params.factory_diff(prog))
        _print_rows(opts, s, rows, "defaults", False)
        if any(r.result in ("differs", "missing") for r in rows) or nothing_compared(rows):
            raise SystemExit(1)             # nothing compared: no verdict (docs/commands.md)
        return
    address, path = _file_args(args, "diff")
    doc = load_dump(path)
    with _session(opts, address, profile_name, ppo, fmt, watchdog_ms) as s:
        rows = _with_progress(opts, "comparing", lambda prog: s.params.compare(doc, prog))
    _print_rows(opts, s, rows, "diff", False)
    if any(r.result in ("differs", "missing") for r in rows):
        raise SystemExit(1)             # the table (or the JSON document) is the message


def _print_rows(opts: BusOptions, s: DriveStation, rows: list[ParamRow], what: str, dry_run: bool, interrupted: str | None = None) -> None:
    counts: dict[str, int] = {}
    for r in rows:
        counts[r.result] = counts.get(r.result, 0) + 1
    if opts.json:
        assert s.profile is not None            # the session was opened
        d: dict[str, Any] = {"station": s.address, "profile": s.profile.name, "dry_run": dry_run,
             "counts": counts, "rows": [r.to_dict() for r in rows]}
        if what == "defaults":
            d["compared_with"] = "factory defaults"     # each row's file_value is the factory default
            d["compared"] = sum(counts.get(k, 0) for k in ("differs", "unchanged", "bus setting"))
            d["nothing_compared"] = nothing_compared(rows)
            d["rows"] = [{**r.to_dict(), "default_source": default_source(s.profile, r.code)}
                         for r in rows]
        if interrupted is not None:
            d["interrupted"] = interrupted
            d["landed"] = [r.code for r in rows if r.result == "applied"]
            d["uncertain"] = [r.code for r in rows if r.result == "unknown"]   # sent, not read back
            d["not_landed"] = [r.code for r in rows if r.result in ("not written", "refused")]
        emit_json(d)
        return
    shown = [r for r in rows if r.result not in ("unchanged", "skipped") or opts.verbose
             or r.why == "dangerous"]
    if what == "diff":
        cols: tuple[str, ...] = ("code", "name", "file", "drive", "result", "reason")
        title = f"station {s.address}: {counts.get('differs', 0)} parameter(s) differ from the file"
    elif what == "defaults":
        shown = [r for r in rows if r.result == "differs" or r.result == "missing" or opts.verbose]
        cols = ("code", "name", "factory", "source", "drive", "result", "reason")
        none = nothing_compared(rows)
        title = (f"station {s.address}: nothing compared with the factory defaults: {none}" if none else
                 f"station {s.address}: {counts.get('differs', 0)} setting(s) changed from the factory "
                 f"default")
    else:
        cols = ("code", "name", "file", "drive", "now", "result", "reason")
        title = f"station {s.address}: restore" + (" (dry run: nothing written)" if dry_run else "")
    if shown:
        out.print(R.rows_table(shown, title, cols, {r.code: default_source(s.profile, r.code) or ""
                                                    for r in shown} if what == "defaults" else None))
    else:
        out.print(escape(title))
    order = ("applied", "would apply", "refused", "unknown", "not written", "differs", "unchanged", "missing",
             "skipped")
    if what == "defaults":
        unknown = [r.code for r in rows if r.result == "unknown"]
        words = {"differs": "changed", "unchanged": "at the factory default",
                 "bus setting": "at the manual's setting for the field bus", "missing": "unreadable"}
        if not none:
            out.print(", ".join(f"{counts.get(k, 0)} {w}" for k, w in words.items()
                                if counts.get(k) or k == "differs"))
        elsewhere: dict[str, list[str]] = {}
        for r in rows:
            src = default_source(s.profile, r.code) if r.result != "unknown" else None
            if src and src != CARD_MANUAL:
                elsewhere.setdefault(src, []).append(r.code)
        for src, codes in elsewhere.items():
            out.print(escape(f"factory value not from the card manual ({src}): {', '.join(codes)}"))
        bus = [f"{r.code} = {R.value_text(r.drive_value, r.unit)}" for r in rows if r.result == "bus setting"]
        if bus:
            out.print(escape(f"set for control over the field bus (the manual's commissioning): {', '.join(bus)}"))
        if unknown:
            out.print(escape(f"no factory default known ({len(unknown)}): {', '.join(unknown)}"))
        return
    out.print(", ".join(f"{counts[k]} {k}" for k in order if counts.get(k)) or "nothing in the file")


def _with_progress(opts: BusOptions, label: str, fn: Callable[[ProgressFn | None], T]) -> T:
    if opts.json or not err.is_terminal:
        return fn(None)
    with Progress(console=err, transient=True) as prog:
        task = prog.add_task(label, total=None)

        def cb(i: int, n: int, code: str) -> None:
            prog.update(task, total=n, completed=i, description=f"{label} {code}")
        return fn(cb)


# =============================================================================================
# pdrive faults
# =============================================================================================


@click.command("faults")
@click.argument("address", required=False, type=int)
@click.option("--clear", is_flag=True, help="Acknowledge the current fault (the history stays).")
@click.option("--yes", is_flag=True, help="Do not ask before acknowledging on a real port.")
@drive_options
@bus_options
@_terminations
def faults_cmd(opts: BusOptions, address: int | None, clear: bool, yes: bool, profile_name: str | None,
               ppo: int | None, fmt: str | None, watchdog_ms: int) -> None:
    """Fault history (all candidate alarms where one number means several) and the current fault."""
    before = _confirmer(opts, yes, "acknowledge the current fault") if clear else None
    cleared: dict[str, Any] | None = None
    with _session(opts, address, profile_name, ppo, fmt, watchdog_ms, before=before) as s:
        assert s.profile is not None            # the open session has its profile
        cur = s.motion.status()
        history = s.fault_history()
        trips = s.trip_records()
        if clear:
            if cur.status.fault:
                after = s.clear_fault()
                cleared = {"was": cur.status.fault_code, "state": after.status.state,
                           "fault": after.status.fault}
            else:
                cleared = {"was": None, "state": cur.status.state, "fault": False}
    st = cur.status
    if opts.json:
        emit_json({"station": s.address, "profile": s.profile.name,
                   "current": {"fault": st.fault, "code": st.fault_code, "state": st.state},
                   "history": [R.fault_json(r) for r in history], "trip_records": trips.to_dict(),
                   "cleared": cleared})
        return
    out.print(f"[bold]station {s.address}[/bold]: {escape(s.profile.name)} — current: "
              + (f"[red]fault {escape(st.fault_code or '(code not readable)')}[/red]" if st.fault
                 else f"no fault ({escape(st.state)})"))
    if history:
        out.print(R.faults_table(history, "fault history"))
    else:
        out.print("fault history: empty")
    R.print_trip_records(trips)
    if cleared is not None:
        if cleared["was"] is None and not st.fault:
            out.print("--clear: there was no fault to acknowledge")
        else:
            out.print(f"--clear: acknowledged; the drive is now {escape(cleared['state'])}")
