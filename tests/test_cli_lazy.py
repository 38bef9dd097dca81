"""The command group loads a command's module only when it runs; its help lines stay the commands' own."""

import importlib
import subprocess
import sys

from click.testing import CliRunner

from profidrive_cli.cli.main import COMMANDS, cli


def test_version_and_help_load_no_command_module():
    code = ("import sys; from profidrive_cli.cli.main import main\n"
            "try:\n    main(['--version'])\nexcept SystemExit:\n    pass\n"
            "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "heavy = [m for m in ('rich', 'yaml', 'construct', 'serial', 'profidrive_cli.cli.common',"
            " 'profidrive_cli.fdl.frames', 'profidrive_cli.gsd.parser') if m in sys.modules]\n"
            "print('HEAVY', heavy)\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert "HEAVY []" in p.stdout, p.stdout + p.stderr
    assert "pdrive, version" in p.stdout


def test_every_command_is_listed_and_loads():
    r = CliRunner().invoke(cli, ["--help"])
    assert r.exit_code == 0
    for name in ("scan", "diag", "io", "sniff", "sim", "gsd", "decode", "doctor", "checklist",
                 "run", "status", "param", "faults"):
        assert name in COMMANDS
        assert f"  {name} " in r.output
        module, attr, short = COMMANDS[name]
        cmd = getattr(importlib.import_module(module), attr)
        assert cmd.name == name
        # the table's line starts like the command's own first help line (no drift between them)
        own = (cmd.help or "").split("\n")[0]
        assert own[:12] == short[:12], (name, own, short)


def test_unknown_command_is_a_usage_error():
    r = CliRunner().invoke(cli, ["scna"])
    assert r.exit_code == 2
    assert "No such command" in r.output


def test_a_drive_command_loads_only_the_station_level_it_names():
    # the one door (profidrive_cli.api.station) loads a name's module on first use: the options every
    # drive command shares (drive_opts: SessionTerminated) do not bring in the run loop, the group,
    # the multi-drive run, the monitors or the comm-loss test
    code = ("import sys; import profidrive_cli.cli.drive_opts\n"
            "heavy = [m for m in ('profidrive_cli.session.live', 'profidrive_cli.session.group',"
            " 'profidrive_cli.session.multirun', 'profidrive_cli.session.monitors',"
            " 'profidrive_cli.session.commloss') if m in sys.modules]\n"
            "print('HEAVY', heavy)\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert "HEAVY []" in p.stdout, p.stdout + p.stderr
