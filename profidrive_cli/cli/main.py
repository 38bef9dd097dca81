"""The `pdrive` command group (click + rich). No protocol logic here."""

from __future__ import annotations

import sys

import click

from profidrive_cli import BusError, PdriveError, UsageError, __version__


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="pdrive")
def cli():
    """pdrive: PROFIBUS-DP master and drive commissioning.

    Every command works on the built-in simulated bus: add --port sim://
    """


def main(argv=None):
    try:
        cli.main(args=argv, prog_name="pdrive", standalone_mode=False)
    except click.exceptions.Abort:
        click.echo("aborted", err=True)
        sys.exit(130)
    except click.ClickException as e:
        e.show()
        sys.exit(2 if isinstance(e, click.UsageError) or e.exit_code == 2 else e.exit_code)
    except UsageError as e:
        click.echo(f"pdrive: {e}", err=True)
        sys.exit(2)
    except (BusError, PdriveError) as e:
        click.echo(f"pdrive: {e}", err=True)
        sys.exit(1)
    except KeyboardInterrupt:
        click.echo("interrupted", err=True)
        sys.exit(130)
    sys.exit(0)
