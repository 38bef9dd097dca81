"""The `pdrive` command group (click + rich). No protocol logic here."""

from __future__ import annotations

# Signals first, before anything slow is imported: SIGINT / SIGTERM at any moment of pdrive's
# start-up end it with one line on stderr, exit code 130 / 143 and, under --json, the error object
# (docs/json.md) -- not a traceback of an import, nor a death by the signal.
import json
import os
import signal
import sys
from typing import TYPE_CHECKING, Any, NoReturn

if TYPE_CHECKING:                                   # (nothing imported at run time)
    from collections.abc import Callable, Sequence
    from types import FrameType

    #: what signal.signal takes: a function, SIG_DFL / SIG_IGN, or None
    _Handler = Callable[[int, FrameType | None], Any] | int | None

#: commands whose --json output is a stream (JSON Lines with an "event" key): their error object
#: carries "event": "error" too
STREAM_COMMANDS = frozenset({"commloss-test", "io", "jog", "run", "sniff"})
#: commands whose --json output is a stream only with one of these options (scan: a document)
STREAM_WITH = {"scan": frozenset({"--watch"})}


def _json_mode(argv: Sequence[str] | None) -> tuple[bool, bool]:
    """(--json given, the command streams), read from the command line itself: known also when the
    error comes before the command body runs (a bad option, a bad --port)."""
    args = list(sys.argv[1:] if argv is None else argv)
    if "--" in args:
        args = args[:args.index("--")]
    stream = bool(args) and (args[0] in STREAM_COMMANDS
                             or bool(STREAM_WITH.get(args[0], frozenset()) & set(args[1:]))
                             or (args[0] == "monitor" and "report" not in args[1:]))
    return "--json" in args, stream


def _signal_words(signum: int) -> str:
    """The one line for a signal, as the commands that handle signals themselves say it."""
    return "interrupted" if signum == signal.SIGINT else f"terminated (signal {signum})"


def _error_json(argv: Sequence[str] | None, message: str, code: int,
                details: dict[str, Any] | None = None) -> None:
    """Under --json, the error object on stdout (docs/json.md; jsonout.error_object)."""
    as_json, stream = _json_mode(argv)
    if as_json:
        from profidrive_cli.cli.jsonout import error_object
        obj = error_object(message, code, stream)
        for k, v in (details or {}).items():
            obj.setdefault(k, v)
        try:
            sys.stdout.write(json.dumps(obj, ensure_ascii=False) + "\n")
            sys.stdout.flush()
        except (BrokenPipeError, OSError, ValueError):
            pass


def _signal_at_start(signum: int, frame: FrameType | None) -> NoReturn:
    """SIGINT / SIGTERM before a command has been loaded: the line, the error object, 128 + N."""
    _set_signals(signal.SIG_IGN)                         # a second signal: no second message
    try:
        sys.stderr.write(f"pdrive: {_signal_words(signum)}\n")
        sys.stderr.flush()
    except (OSError, ValueError):
        pass
    _error_json(None, _signal_words(signum), 128 + signum)
    raise SystemExit(128 + signum)


class _Terminated(BaseException):
    """SIGTERM while a command runs that has no handling of its own (like KeyboardInterrupt)."""

    def __init__(self, signum: int):
        super().__init__(f"terminated by signal {signum}")
        self.signum = signum


def _raise_terminated(signum: int, frame: FrameType | None) -> NoReturn:
    raise _Terminated(signum)


def _set_signals(handler: _Handler, term: _Handler = None) -> bool:
    """SIGINT to `handler`, SIGTERM to `term` (default: `handler`); False off the main thread."""
    try:
        signal.signal(signal.SIGINT, handler)
        signal.signal(signal.SIGTERM, term if term is not None else handler)
        return True
    except (ValueError, OSError):
        return False


def _is_pdrive_process() -> bool:
    """This process is pdrive itself (the console script or `python -m profidrive_cli`), not a
    program that imports the CLI: only then are its signals pdrive's to handle from the start."""
    arg0 = sys.argv[0] if sys.argv else ""
    return (os.path.basename(arg0) in ("pdrive", "pdrive.exe", "pdrive-script.py")
            or arg0.endswith(os.path.join("profidrive_cli", "__main__.py")))


#: True while the start-up handlers are pdrive's (until the command's module is loaded)
_STARTING = _is_pdrive_process() and _set_signals(_signal_at_start)

import importlib  # noqa: E402  (after the signal handlers: see above)

import click  # noqa: E402

from profidrive_cli import BusError, PdriveError, UsageError, __version__  # noqa: E402


#: name -> (module, click object, one-line help). A command's module is imported only when that
#: command runs (or `--help` of that command is asked for): `pdrive --version` and `pdrive --help`
#: load neither rich nor yaml nor any protocol code. tests/test_cli_lazy.py checks that each help
#: line here is the command's own.
COMMANDS = {
    "audit": ("profidrive_cli.cli.audit_cmd", "audit_cmd",
              "Lint each drive's safety and commissioning settings, each finding with the manual's fix."),
    "checklist": ("profidrive_cli.cli.checklist_cmd", "checklist_group",
                  "Scripted commissioning checklists: validate, rehearse, run, report."),
    "commloss-test": ("profidrive_cli.cli.commloss_cmd", "commloss_cmd",
                      "Comm-loss acceptance test: break the link, measure the drive's reaction."),
    "config": ("profidrive_cli.cli.config_cmd", "config_group",
               "Config file: the effective settings and where each came from; the files that apply."),
    "convert": ("profidrive_cli.cli.convert_cmd", "convert_cmd", "Convert a capture: raw, pcap, pcapng, ProfiTrace .ptd."),
    "decode": ("profidrive_cli.cli.decode_cmd", "decode_cmd",
               "Decode a captured area of PROFILE's layout into named fields."),
    "diag": ("profidrive_cli.cli.bus_cmds", "diag_cmd",
             "The whole Slave_Diag of one station decoded, and its Get_Cfg."),
    "doctor": ("profidrive_cli.cli.doctor_cmd", "doctor_cmd",
               "Check a serial setup for PROFIBUS: permission, baud rates, echo."),
    "faults": ("profidrive_cli.cli.drive_cmds", "faults_cmd",
               "Fault history with alarm names, and the current fault."),
    "gsd": ("profidrive_cli.cli.gsd_cmd", "gsd_group",
            "GSD device description files: show, list, build Set_Prm."),
    "io": ("profidrive_cli.cli.bus_cmds", "io_cmd",
           "Bring any DP slave to Data_Exchange and show its inputs."),
    "jog": ("profidrive_cli.cli.jog_cmd", "jog_cmd",
            "Jog a drive with the card's own jog function; a safe stop on every exit."),
    "monitor": ("profidrive_cli.cli.monitor_cmd", "monitor_group",
                "A permanent bus monitor: history, web page, metrics, alarms (listens only)."),
    "param": ("profidrive_cli.cli.drive_cmds", "param_group",
              "Read and write drive parameters by their native codes."),
    "run": ("profidrive_cli.cli.run_cmd", "run_cmd",
            "Run a drive at a speed, live; a safe stop on every exit."),
    "scan": ("profidrive_cli.cli.bus_cmds", "scan_cmd",
             "Live list: every station, its type, ident and DP state."),
    "sim": ("profidrive_cli.cli.sim_cmd", "sim_cmd",
            "Serve a simulated PROFIBUS segment for another master."),
    "sim-ctl": ("profidrive_cli.cli.simctl_cmd", "simctl_cmd",
                "Steer a running simulator: trip, clear, unplug, replug, set, faults, state."),
    "sniff": ("profidrive_cli.cli.sniff_cmd", "sniff_cmd",
              "Passive capture: one line per frame, pcap output."),
    "status": ("profidrive_cli.cli.drive_cmds", "status_cmd",
               "One read of a drive's status: state, flags, speed, current fault."),
    "wireshark": ("profidrive_cli.cli.wireshark_cmd", "wireshark_group",
                  "Wireshark: install pdrive's PROFIBUS dissector and the live-capture (extcap) entry."),
}


class LazyGroup(click.Group):
    """A group that imports a command's module when the command is looked up."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(COMMANDS)

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        entry = COMMANDS.get(name)
        if entry is None:
            return None
        module, attr, _ = entry
        cmd: click.Command = getattr(importlib.import_module(module), attr)   # (COMMANDS names commands)
        _command_loaded()
        return cmd

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = [(name, COMMANDS[name][2]) for name in self.list_commands(ctx)]
        with formatter.section("Commands"):
            formatter.write_dl(rows)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="pdrive", package_name="profidrive-cli")
def cli() -> None:
    """pdrive: PROFIBUS-DP master and drive commissioning.

    Every command works on the built-in simulated bus: add --port sim://
    """


MAX_LINE = 400


def _line(text: object) -> str:
    """An error message as one line of at most MAX_LINE characters (a pasted value can be huge)."""
    text = " ".join(str(text).split())
    return text if len(text) <= MAX_LINE else text[:MAX_LINE - 25] + f"... ({len(text)} characters)"


def _os_error_text(e: OSError) -> str:
    """One line: the path(s) and the reason of an OSError."""
    why = e.strerror or str(e) or type(e).__name__
    paths = [str(p) for p in (e.filename, e.filename2) if p is not None]
    return _line(f"{' -> '.join(paths)}: {why}" if paths else why)


def _fail(argv: Sequence[str] | None, message: str, code: int,
          details: dict[str, Any] | None = None) -> NoReturn:
    """The one line on stderr and, under --json, the error object on stdout (docs/json.md); exit."""
    click.echo(f"pdrive: {message}", err=True)
    _error_json(argv, message, code, details)
    sys.exit(code)


def _command_loaded() -> None:
    """The command's module is loaded (the slow part of start-up is over): from here Ctrl-C is
    KeyboardInterrupt again (each command stops what it started), and SIGTERM raises _Terminated
    where the command installs no handling of its own (sessions, checklists, sim do)."""
    global _STARTING
    if _STARTING:
        _STARTING = False
        _set_signals(signal.default_int_handler, _raise_terminated)


def main(argv: list[str] | None = None) -> None:
    """`pdrive` (argv None: the process is pdrive and its signals are handled from the start; a
    list: called from a program, whose signal handlers are left alone)."""
    global _STARTING
    owner = argv is None
    if owner and not _STARTING:
        _STARTING = _set_signals(_signal_at_start)
    try:
        _main(argv)
    finally:
        if owner:
            _STARTING = False
            _set_signals(signal.SIG_IGN)       # the command has ended: a late signal changes nothing


def _main(argv: Sequence[str] | None) -> NoReturn:
    try:
        rc = cli.main(args=argv, prog_name="pdrive", standalone_mode=False)
    except click.exceptions.Abort:
        click.echo("aborted", err=True)
        sys.exit(130)
    except click.exceptions.NoArgsIsHelpError as e:
        e.show()                     # `pdrive gsd` alone: the group's help, as click shows it
        sys.exit(2)
    except click.exceptions.UsageError as e:
        # bad option / argument: one line (click's own form is four), with where to look
        cmd = e.ctx.command_path if e.ctx is not None else "pdrive"
        _fail(argv, f"{_line(e.format_message())} (see '{cmd} --help')", 2)
    except click.ClickException as e:
        _fail(argv, _line(e.format_message()), 2)
    except UsageError as e:
        _fail(argv, _line(e), 2, getattr(e, "json_details", None))
    except (BusError, PdriveError) as e:
        _fail(argv, _line(e), 1, getattr(e, "json_details", None))
    except KeyboardInterrupt:
        click.echo("interrupted", err=True)
        sys.exit(130)
    except _Terminated as e:
        _fail(argv, _signal_words(e.signum), 128 + e.signum)
    except BrokenPipeError:
        sys.exit(1)
    except OSError as e:
        # the last line of defence: each known cause has its own message at the place it happens
        _fail(argv, _os_error_text(e), 1)
    sys.exit(rc if isinstance(rc, int) else 0)
