"""The `pdrive` command group (click + rich). No protocol logic here."""

from __future__ import annotations

import importlib
import sys

import click

from profidrive_cli import BusError, PdriveError, UsageError, __version__


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="pdrive")
def cli():
    """pdrive: PROFIBUS-DP master and drive commissioning.

    Every command works on the built-in simulated bus: add --port sim://
    """


# (module, click object) for each command
_COMMANDS = [
    ("profidrive_cli.cli.bus_cmds", "scan_cmd"),
    ("profidrive_cli.cli.bus_cmds", "diag_cmd"),
    ("profidrive_cli.cli.bus_cmds", "io_cmd"),
    ("profidrive_cli.cli.sniff_cmd", "sniff_cmd"),
    ("profidrive_cli.cli.sim_cmd", "sim_cmd"),
    ("profidrive_cli.cli.gsd_cmd", "gsd_group"),
    ("profidrive_cli.cli.decode_cmd", "decode_cmd"),
    ("profidrive_cli.cli.doctor_cmd", "doctor_cmd"),
    ("profidrive_cli.cli.checklist_cmd", "checklist_group"),
    ("profidrive_cli.cli.drive_cmds", "run_cmd"),
    ("profidrive_cli.cli.drive_cmds", "status_cmd"),
    ("profidrive_cli.cli.drive_cmds", "param_group"),
    ("profidrive_cli.cli.drive_cmds", "faults_cmd"),
]
for _mod, _obj in _COMMANDS:
    cli.add_command(getattr(importlib.import_module(_mod), _obj))


MAX_LINE = 400


def _line(text: str) -> str:
    """An error message as one line of at most MAX_LINE characters (a pasted value can be huge)."""
    text = " ".join(str(text).split())
    return text if len(text) <= MAX_LINE else text[:MAX_LINE - 25] + f"... ({len(text)} characters)"


def _os_error_text(e: OSError) -> str:
    """One line: the path(s) and the reason of an OSError."""
    why = e.strerror or str(e) or type(e).__name__
    paths = [str(p) for p in (e.filename, e.filename2) if p is not None]
    return _line(f"{' -> '.join(paths)}: {why}" if paths else why)


def main(argv=None):
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
        click.echo(f"pdrive: {_line(e.format_message())} (see '{cmd} --help')", err=True)
        sys.exit(2)
    except click.ClickException as e:
        click.echo(f"pdrive: {_line(e.format_message())}", err=True)
        sys.exit(2)
    except UsageError as e:
        click.echo(f"pdrive: {_line(e)}", err=True)
        sys.exit(2)
    except (BusError, PdriveError) as e:
        click.echo(f"pdrive: {_line(e)}", err=True)
        sys.exit(1)
    except KeyboardInterrupt:
        click.echo("interrupted", err=True)
        sys.exit(130)
    except BrokenPipeError:
        sys.exit(1)
    except OSError as e:
        # the last line of defence: each known cause has its own message at the place it happens
        click.echo(f"pdrive: {_os_error_text(e)}", err=True)
        sys.exit(1)
    sys.exit(rc if isinstance(rc, int) else 0)
