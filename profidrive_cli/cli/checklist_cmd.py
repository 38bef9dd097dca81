"""`pdrive checklist run|validate FILE.yaml`: rendering only; the work is in profidrive_cli.checklist."""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, NoReturn, cast

import click
from rich.console import Console
from rich.markup import escape
from rich.progress import (BarColumn, MofNCompleteColumn, Progress, SpinnerColumn, TaskID, TextColumn,
                           TimeElapsedColumn)

from profidrive_cli import PdriveError, UsageError
from profidrive_cli.checklist.spec import Checklist, ChecklistError, load_checklist, parse_var_assignments
from profidrive_cli.cli.common import (BusOptions, bus_options, can_ask, confirm_real_port, emit_json,
                                       is_sim_port, is_tty, make_console)
from profidrive_cli.outfile import check_output_path

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.checklist.runner import Observer    # (_LiveView and _Quiet have its methods)
    from profidrive_cli.checklist.runner import RunResult, StationResult, StepResult

_MARK = {"passed": "[green]✔[/]", "failed": "[red]✘[/]", "error": "[red]✘[/]", "not run": "[dim]–[/]",
         "skipped": "[dim]–[/]", "interrupted": "[yellow]![/]"}
_PLAIN = {"passed": "PASS", "failed": "FAIL", "error": "ERROR", "not run": "not run", "skipped": "skip",
          "interrupted": "INTERRUPTED"}


def _usage(ctx: click.Context, message: str, problems: list[str] | None = None) -> NoReturn:
    """A usage error as one line and exit code 2 (also under click's test runner); under --json also
    the error object on stdout (docs/json.md)."""
    click.echo(f"pdrive: {message}", err=True)
    _json_error(ctx, message, problems)
    ctx.exit(2)


def _json_error(ctx: click.Context, message: str, problems: list[str] | None = None) -> None:
    if ctx.params.get("as_json"):
        from profidrive_cli.cli.jsonout import error_object
        obj = error_object(message, 2, stream=False)
        if problems is not None:
            obj["problems"] = problems
        emit_json(obj)


def _load(ctx: click.Context, path: str, variables: tuple[str, ...]) -> Checklist:
    """The validated checklist, or every problem on stderr (file:line each) and exit code 2."""
    try:
        return load_checklist(path, parse_var_assignments(variables))
    except ChecklistError as e:
        for line in e.lines():
            click.echo(f"pdrive: {line}", err=True)
        n = len(e.errors)
        summary = f"{path}: {n} problem{'s' if n != 1 else ''}; nothing was sent to any drive"
        click.echo(f"pdrive: {summary}", err=True)
        _json_error(ctx, summary, list(e.lines()))
        ctx.exit(2)
    except UsageError as e:
        _usage(ctx, str(e))


@click.group("checklist")
def checklist_group() -> None:
    """Scripted commissioning checklists: validate, rehearse on the simulator, run, report.

    The format is in docs/checklists.md; examples in examples/checklists/.
    """


@checklist_group.command("validate")
@click.argument("file", type=click.Path(dir_okay=False))
@click.option("--var", "variables", multiple=True, metavar="NAME=VALUE",
              help="Set a checklist variable (repeatable); overrides the file's value.")
@click.option("--json", "as_json", is_flag=True, help="Print the plan per station as JSON.")
@click.pass_context
def validate_cmd(ctx: click.Context, file: str, variables: tuple[str, ...], as_json: bool) -> None:
    """Check FILE.yaml without touching a bus: every problem with file:line (exit code 2)."""
    cl = _load(ctx, file, variables)
    if as_json:
        from profidrive_cli.cli.jsonout import station_identity
        emit_json({"checklist": cl.name, "file": str(cl.path), "valid": True, "variables": cl.variables,
                   "stations": [{**station_identity(s.identity()), "steps": [st.to_dict() for st in s.steps],
                                 "snapshot": [t.label for t in s.snapshot]} for s in cl.stations]})
        return
    con = make_console()
    con.print(f"{escape(str(cl.path))}: [bold]{escape(cl.name)}[/] is valid "
              f"({cl.step_count} steps, {len(cl.stations)} station{'s' if len(cl.stations) != 1 else ''})")
    for s in cl.stations:
        idt = s.identity()
        con.print(f"  station {escape(s.name)}: address {s.address}, {s.profile.name} ({escape(s.profile.title)}), "
                  f"ident {idt['ident']}, layout {s.layout}: {len(s.steps)} steps")
        for st in s.steps:
            extra = "  [dim](on_fail: continue)[/]" if st.on_fail == "continue" else ""
            con.print(f"    {st.index:>2}. {escape(st.label)}  [dim]line {st.line}[/]{extra}")


@checklist_group.command("run")
@click.argument("file", type=click.Path(dir_okay=False))
@bus_options
@click.option("--report", "reports", multiple=True, metavar="FILE",
              help="Write a report: .json, .md (Markdown), .xml (JUnit) or .html (with plots); repeatable.")
@click.option("--dry-run", is_flag=True,
              help="Validate, then rehearse on a simulated station of each station's profile "
                   "(sim://?stations=ADDR:PROFILE); the plant is not touched.")
@click.option("--yes", "-y", is_flag=True, help="Take every prompt step as confirmed (needed when not on a terminal).")
@click.option("--var", "variables", multiple=True, metavar="NAME=VALUE",
              help="Set a checklist variable (repeatable); overrides the file's value.")
@click.option("--cycle-hz", type=click.FloatRange(min=0), default=None, metavar="RATE",
              help="Data_Exchange rate (default: the fastest the bus allows, capped; 0 = unpaced).")
@click.option("--watchdog-ms", type=click.FloatRange(10, 650000), default=None, metavar="MS",
              help="DP watchdog armed in Set_Prm (default 500 ms).")
@click.pass_context
def run_cmd(ctx: click.Context, opts: BusOptions, file: str, reports: tuple[str, ...], dry_run: bool,
            yes: bool, variables: tuple[str, ...], cycle_hz: float | None,
            watchdog_ms: float | None) -> None:
    """Run FILE.yaml on the drives it names, station by station; exit code 0 only when every step passed.

    A failed step (on_fail: stop, the default), Ctrl-C or SIGTERM stop the drive safely before pdrive
    lets go of the station. Reports are written in every case once the run has started.
    """
    from profidrive_cli.checklist.report import report_format, write_report
    from profidrive_cli.checklist.runner import Runner, dry_run_port, session_opener, signals_as_interrupts

    for r in reports:
        try:
            report_format(r)                      # a bad extension is a usage error before anything runs
            check_output_path(r, "--report")      # so is a report that cannot be written (no mkdir)
        except UsageError as e:
            _usage(ctx, str(e))
    cl = _load(ctx, file, variables)
    interactive = sys.stdin.isatty() and sys.stdout.isatty()
    if cl.has_prompts and not (yes or dry_run or interactive):
        prompt_line = cl.first_prompt_line()
        _usage(ctx, f"{cl.path}:{prompt_line}: the checklist has prompt steps and there is no terminal to "
                    f"answer them: give --yes to take them as confirmed (nothing was sent to any drive)")
    # port: --port / PDRIVE_PORT, else the checklist's; --dry-run: a simulated bus of the same stations
    port: str | None
    if dry_run:
        port = dry_run_port(cl)
        if opts.port:
            click.echo(f"pdrive: --dry-run rehearses on {port}; --port {opts.port} is not used", err=True)
    else:
        port = opts.port_or(cl.port)        # --port / PDRIVE_PORT, the checklist's, the config's
        if not port:
            _usage(ctx, f"no port: give --port (or PDRIVE_PORT), or put `port:` in {cl.path}")
    if not dry_run and not is_sim_port(port):
        # a real port: one question before the first station is opened (--yes answers it)
        if not yes and can_ask():
            for line in _plan_lines(cl):
                click.echo(line, err=True)
        try:
            confirm_real_port(port, yes, f"run checklist {cl.name!r} on {port} "
                                         f"({len(cl.stations)} station{'s' if len(cl.stations) != 1 else ''}"
                                         f"{': it writes settings and runs motors' if _moves(cl) else ''})",
                              cancelled="cancelled: nothing was sent to any drive")
        except UsageError as e:
            _usage(ctx, f"{cl.path}: {e}; nothing was sent to any drive")
    baud = opts.baud
    if cl.baud and _defaulted(ctx, "baud"):
        baud = cl.baud
    master_address = opts.master_address
    if cl.master_address is not None and _defaulted(ctx, "master_address"):
        master_address = cl.master_address
    bus = BusOptions(port, baud, master_address, opts.slot_time, opts.retries, opts.rs485, opts.echo,
                     opts.verbose, opts.json, opts.trace)

    live = is_tty() and not opts.json
    con = make_console(stderr=opts.json)
    view: _LiveView | _Quiet
    ask: Callable[[str], bool] | None = None
    if opts.json:
        view = _Quiet()
    else:
        view = live_view = _LiveView(con, live)
        ask = live_view.ask if interactive else None
    options = {"yes": yes, "cycle_hz": cycle_hz, "watchdog_ms": watchdog_ms, "baud": str(baud),
               "master_address": master_address}
    with signals_as_interrupts():
        try:
            api_bus = bus.open_bus()
        except UsageError as e:
            _usage(ctx, str(e))
        try:
            runner = Runner(cl, session_opener(api_bus, cycle_hz=cycle_hz, watchdog_ms=watchdog_ms,
                                               on_message=view.message, checklist=cl),
                            port=port, yes=yes, ask=ask, dry_run=dry_run, observer=cast("Observer", view), options=options,
                            trace_steps=any(report_format(r) == "html" for r in reports))
            try:
                view.begin(cl, port, dry_run)
                result = runner.run()
            finally:
                view.end()
        finally:
            try:
                api_bus.close()
            except Exception:
                pass
        written, failed = [], []
        for r in reports:
            try:
                written.append(str(write_report(result, r)))
            except PdriveError as e:              # OutputPathError / OutputWriteError: one line each
                failed.append(str(e))
            except OSError as e:
                failed.append(f"--report {r}: {e.strerror or e}")
    if opts.json:
        from profidrive_cli.checklist.report import to_json
        sys.stdout.write(to_json(result))
    else:
        _summary(con, result, written)
    if failed:
        # the last word is that the report is missing, never PASSED
        sys.stdout.flush()
        for line in failed:
            click.echo(f"pdrive: {line}", err=True)
        click.echo(f"pdrive: {len(failed)} report{'s' if len(failed) != 1 else ''} could not be written: "
                   f"the run ({result.status}) is not fully recorded", err=True)
    if result.interrupted:
        ctx.exit(143 if result.interrupted == "SIGTERM" else 130)
    ctx.exit(0 if result.passed and not failed else 1)


def _moves(cl: Checklist) -> bool:
    return any(st.type in _MOVES for s in cl.stations for st in s.steps)


_MOVES = ("write", "save", "run", "reset_fault")


def _plan_lines(cl: Checklist) -> list[str]:
    """What the checklist will do that changes something, per station (for the question)."""
    lines = [f"{cl.path}: what it changes, station by station:"]
    for s in cl.stations:
        acts = [st.title for st in s.steps if st.type in _MOVES]
        lines.append(f"  station {s.name} (address {s.address}, {s.profile.name}): "
                     + ("; ".join(acts) if acts else "reads only"))
    return lines


def _defaulted(ctx: click.Context, name: str) -> bool:
    """True when the option was not given (so the checklist's header value applies)."""
    src = ctx.get_parameter_source(name)
    return src is None or src.name in ("DEFAULT", "DEFAULT_MAP")


def _summary(con: Console, result: RunResult, written: list[str]) -> None:
    c = result.counts()
    verdict = {"passed": "[bold green]PASSED[/]", "failed": "[bold red]FAILED[/]",
               "interrupted": "[bold yellow]INTERRUPTED[/]"}[result.status]
    con.print(f"{verdict} {escape(result.checklist.name)}: {c['passed']} passed, {c['failed']} failed, "
              f"{c['error']} errors, {c['not run']} not run" + (" [dim](dry run on the simulator)[/]"
                                                               if result.dry_run else ""))
    ff = result.first_failure()
    if ff is not None:
        sr, r = ff
        if r is not None:
            con.print(f"  first failure: station {escape(sr.spec.name)}, step {r.step.index} "
                      f"({escape(str(result.checklist.path))}:{r.step.line}): {escape(r.message)}")
        elif sr.error:
            con.print(f"  station {escape(sr.spec.name)}: {escape(sr.error)}")
    for sr in result.stations:
        fs = sr.final_status or {}
        if "stopped" in fs:
            con.print(f"  station {escape(sr.spec.name)}: drive left "
                      + ("stopped" if fs.get("stopped") else "[bold red]NOT confirmed stopped[/]")
                      + (f" ({escape(str(fs.get('state')))})" if fs.get("state") else ""))
    for w in written:
        con.print(f"  report: {escape(w)}")


class _Quiet:
    """--json: no live output (the result goes to stdout as one JSON document)."""

    def __getattr__(self, name: str) -> Callable[..., None]:
        return lambda *a, **k: None


class _LiveView:
    """Progress on the terminal: a live bar per station with the running step and its measurement; one
    line per finished step. Without a terminal: the lines only."""

    def __init__(self, con: Console, live: bool) -> None:
        self.con = con
        self.live = live
        self.progress: Progress | None = None
        self.task: TaskID | None = None

    # -- setup -----------------------------------------------------------------------------------
    def begin(self, cl: Checklist, port: str, dry_run: bool) -> None:
        head = f"[bold]{escape(cl.name)}[/] on {escape(port)}" + (" [yellow](dry run: simulator)[/]" if dry_run else "")
        self.con.print(head)
        if self.live:
            self.progress = Progress(SpinnerColumn(), TextColumn("{task.description}"), BarColumn(),
                                     MofNCompleteColumn(), TimeElapsedColumn(), console=self.con,
                                     transient=True)
            self.progress.start()

    def end(self) -> None:
        if self.progress is not None:
            self.progress.stop()
            self.progress = None

    def _print(self, text: str) -> None:
        (self.progress.console if self.progress is not None else self.con).print(text)

    def message(self, text: str) -> None:
        self._print(f"    [dim]session: {escape(text)}[/]")

    # -- observer ----------------------------------------------------------------------------------
    def run_started(self, run: RunResult) -> None:
        pass

    def station_started(self, sr: StationResult) -> None:
        s = sr.spec
        self._print(f"station [bold]{escape(s.name)}[/] (address {s.address}, {s.profile.name}, layout {s.layout})")
        if self.progress is not None:
            self.task = self.progress.add_task(escape(s.name), total=len(sr.steps))

    def station_opened(self, sr: StationResult) -> None:
        idt = sr.identity
        self._print(f"    [dim]found ident {idt.get('ident')}, profile {idt.get('profile')}, "
                    f"GSD {escape(str(idt.get('gsd')))}[/]")

    def step_started(self, sr: StationResult, r: StepResult) -> None:
        if self.progress is not None and self.task is not None:
            self.progress.update(self.task, description=f"{r.step.index}. {escape(r.step.label)}")

    def step_progress(self, sr: StationResult, r: StepResult, text: str) -> None:
        if self.progress is not None and self.task is not None:
            self.progress.update(self.task, description=f"{r.step.index}. {escape(r.step.label)}: {escape(text)}")

    def step_finished(self, sr: StationResult, r: StepResult) -> None:
        mark = _MARK.get(r.status, r.status) if self.live else _PLAIN.get(r.status, r.status)
        msg = f" — {escape(r.message)}" if r.message else ""
        self._print(f"  {mark} {r.step.index:>2}. {escape(r.step.label)}{msg}")
        if self.progress is not None and self.task is not None:
            self.progress.advance(self.task)

    def station_finished(self, sr: StationResult) -> None:
        if self.progress is not None and self.task is not None:
            self.progress.remove_task(self.task)
            self.task = None
        if sr.error:
            self._print(f"  [red]{escape(sr.error)}[/]" if self.live else f"  {escape(sr.error)}")
        skipped = [r for r in sr.steps if r.status == "not run"]
        if skipped:
            self._print(f"  [dim]{len(skipped)} step{'s' if len(skipped) != 1 else ''} not run "
                        f"({escape(skipped[0].message)})[/]")

    def run_finished(self, run: RunResult) -> None:
        pass

    # -- operator prompts (called from the runner's prompt thread while it keeps the bus cycling) ----
    def ask(self, text: str) -> bool:
        prog = self.progress
        if prog is not None:
            prog.stop()
        try:
            return click.confirm(f"  ? {text}", default=False)
        finally:
            if prog is not None:
                prog.start()
