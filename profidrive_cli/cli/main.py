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


def main(argv=None):
    try:
        rc = cli.main(args=argv, prog_name="pdrive", standalone_mode=False)
    except click.exceptions.Abort:
        click.echo("aborted", err=True)
        sys.exit(130)
    except click.ClickException as e:
        e.show()
        sys.exit(2)
    except UsageError as e:
        click.echo(f"pdrive: {e}", err=True)
        sys.exit(2)
    except (BusError, PdriveError) as e:
        click.echo(f"pdrive: {e}", err=True)
        sys.exit(1)
    except KeyboardInterrupt:
        click.echo("interrupted", err=True)
        sys.exit(130)
    except BrokenPipeError:
        sys.exit(1)
    sys.exit(rc if isinstance(rc, int) else 0)
