"""The config file (profidrive_cli/config.py, docs/config.md): user and project files, PDRIVE_CONFIG,
the precedence option > env > project > user > default with the source of each setting (file:line),
named ports accepted by every command that takes --port, per-station defaults, errors as file:line
(exit 2), `pdrive config show / path`, and text output to a pipe not wrapped."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from profidrive_cli import config as C
from profidrive_cli.cli.main import COMMANDS, cli
from profidrive_cli.datafile import DataFileError

ROOT = Path(__file__).resolve().parent.parent
SIM = "sim://?timing=virtual"

USER = """\
baud: 93750
master_address: 1
ports:
  rig: 'sim://?timing=virtual'
  line1:
    port: /dev/ttyUSB9
"""

PROJECT = """\
port: line1
ports:
  line1:
    port: 'sim://?timing=virtual'
    baud: 187500
    stations:
      3: {layout: ppo3, fmax: 50}
      5: {profile: toyo}
"""


@pytest.fixture
def env(tmp_path, monkeypatch):
    """A user file under XDG_CONFIG_HOME and a project file two folders up from the cwd."""
    xdg = tmp_path / "xdg"
    (xdg / "pdrive").mkdir(parents=True)
    (xdg / "pdrive" / "config.yaml").write_text(USER)
    (tmp_path / "proj").mkdir()
    (tmp_path / "proj" / "pdrive.yaml").write_text(PROJECT)
    cwd = tmp_path / "proj" / "a" / "b"
    cwd.mkdir(parents=True)
    monkeypatch.chdir(cwd)
    e = {"XDG_CONFIG_HOME": str(xdg), "HOME": str(tmp_path)}
    for k in ("PDRIVE_PORT", "PDRIVE_BAUD", "PDRIVE_CONFIG", "XDG_CONFIG_HOME"):
        monkeypatch.delenv(k, raising=False)
    monkeypatch.setenv("XDG_CONFIG_HOME", str(xdg))
    return e


def test_the_files_user_then_the_nearest_project_file(env, tmp_path):
    files = C.config_files(env)
    assert [(f.kind, f.path, f.exists) for f in files] == [
        ("user", tmp_path / "xdg" / "pdrive" / "config.yaml", True),
        ("project", (tmp_path / "proj" / "pdrive.yaml").resolve(), True)]
    # without XDG_CONFIG_HOME: ~/.config
    assert C.user_config_path({"HOME": "/home/u"}) == Path("/home/u/.config/pdrive/config.yaml")


def test_precedence_project_over_user_over_default(env, tmp_path):
    eff = C.resolve(env=env)
    proj = (tmp_path / "proj" / "pdrive.yaml").resolve()
    # the project's default port is its own line1 (line 1), which names the device on line 4
    assert eff.port.value == SIM and eff.port_name == "line1"
    assert eff.port.source == f"{proj}:1 -> {proj}:4"
    assert eff.baud == C.Setting("187500", f"{proj}:5")            # the named port's own baud
    user = tmp_path / "xdg" / "pdrive" / "config.yaml"
    assert eff.master_address == C.Setting(1, f"{user}:2")           # only the user file has one
    assert eff.station_defaults(3) == {"layout": C.Setting("ppo3", f"{proj}:7"),
                                       "fmax": C.Setting(50.0, f"{proj}:7")}
    assert eff.station_defaults(4) == {}


def test_env_over_files_and_option_over_env(env, tmp_path):
    e = {**env, "PDRIVE_PORT": "rig", "PDRIVE_BAUD": "45.45k"}
    eff = C.resolve(env=e)
    user = tmp_path / "xdg" / "pdrive" / "config.yaml"
    assert eff.port.value == SIM and eff.port_name == "rig"
    assert eff.port.source == f"env PDRIVE_PORT -> {user}:4"
    assert eff.baud == C.Setting("45.45k", "env PDRIVE_BAUD")
    assert eff.stations == {}                                        # rig has no station defaults
    eff = C.resolve("/dev/ttyS3", "500k", 7, env=e)
    assert eff.port == C.Setting("/dev/ttyS3", "option --port") and eff.port_name is None
    assert eff.baud == C.Setting("500k", "option --baud")
    assert eff.master_address == C.Setting(7, "option --master-address")


def test_nothing_configured_gives_the_built_in_defaults(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    eff = C.resolve(env={"XDG_CONFIG_HOME": str(tmp_path / "none")}, cwd=tmp_path)
    assert eff.port == C.Setting(None, "default")
    assert eff.baud == C.Setting("19200", "default")
    assert eff.master_address == C.Setting(2, "default")


def test_pdrive_config_names_the_file_instead_of_the_search(env, tmp_path):
    other = tmp_path / "other.yaml"
    other.write_text("port: sim://\n")
    eff = C.resolve(env={**env, "PDRIVE_CONFIG": str(other)})
    assert eff.port == C.Setting("sim://", f"{other}:1")
    with pytest.raises(DataFileError, match=r"missing\.yaml: file not found \(named by PDRIVE_CONFIG\)"):
        C.load({**env, "PDRIVE_CONFIG": str(tmp_path / "missing.yaml")})


@pytest.mark.parametrize("text,line,words", [
    ("ports:\n  rig:\n    port: sim://\n    bud: 9600\n", 4, "unknown key 'bud'"),
    ("ports:\n  rig:\n    baud: 9600\n", 2, "`port:` (the device or URL) is missing"),
    ("master_address: 200\n", 1, "not a bus address 0..125"),
    ("ports:\n  rig:\n    port: sim://\n    stations:\n      130: {profile: x}\n", 5, "not a station"),
    ("ports:\n  rig:\n    port: sim://\n    stations:\n      3: {fmax: -5}\n", 5, "not a frequency"),
    ("ports:\n  'a b': sim://\n", 2, "not a port name"),
    ("- port\n", 1, "a config file is a mapping"),
    ("port: [1\n", 1, ""),
])
def test_bad_files_are_refused_with_file_and_line(tmp_path, text, line, words):
    f = tmp_path / "pdrive.yaml"
    f.write_text(text)
    with pytest.raises(DataFileError) as ei:
        C.load({"PDRIVE_CONFIG": str(f), "XDG_CONFIG_HOME": str(tmp_path / "none")})
    assert ei.value.line == line or (words == "" and ei.value.line is not None)
    assert words in str(ei.value)


def _pdrive(args, cwd, env_extra, timeout=60):
    env = {k: v for k, v in os.environ.items()
           if k not in ("PDRIVE_PORT", "PDRIVE_BAUD", "PDRIVE_CONFIG", "COLUMNS")}
    env.update(env_extra)
    env["PYTHONPATH"] = str(ROOT)
    return subprocess.run([sys.executable, "-m", "profidrive_cli", *args], capture_output=True,
                          text=True, timeout=timeout, cwd=cwd, env=env)


def test_a_bad_config_file_is_one_line_exit_2_and_nothing_sent(tmp_path):
    (tmp_path / "pdrive.yaml").write_text("port: sim://\nbaud: [x]\n")
    p = _pdrive(["scan"], tmp_path, {"XDG_CONFIG_HOME": str(tmp_path / "none")})
    assert p.returncode == 2
    assert p.stderr.strip().count("\n") == 0 and "Traceback" not in p.stderr
    assert f"{tmp_path / 'pdrive.yaml'}:2: baud: a baud rate" in p.stderr
    assert p.stdout == ""


def test_a_bad_baud_in_the_file_names_the_file_and_line(tmp_path):
    (tmp_path / "pdrive.yaml").write_text("port: sim://\nbaud: 77\n")
    p = _pdrive(["scan"], tmp_path, {"XDG_CONFIG_HOME": str(tmp_path / "none")})
    assert p.returncode == 2
    assert f"{tmp_path / 'pdrive.yaml'}:2: baud" in p.stderr and "not a PROFIBUS-DP baud rate" in p.stderr


def _port_commands():
    """(path, command) for every command and subcommand that has a --port option."""
    found = []

    def walk(path, cmd):
        if isinstance(cmd, click.Group):
            for name, sub in cmd.commands.items():
                walk(path + [name], sub)
        elif any("--port" in p.opts for p in cmd.params if isinstance(p, click.Option)):
            found.append((" ".join(path), cmd))
    import importlib
    for name, (module, attr, _) in COMMANDS.items():
        walk([name], getattr(importlib.import_module(module), attr))
    return found


def test_every_command_that_takes_a_bus_port_takes_a_port_name():
    cmds = dict(_port_commands())
    assert {"scan", "diag", "io", "status", "run", "jog", "faults", "param get", "param set",
            "doctor", "sniff", "checklist run"} <= set(cmds)
    for path, cmd in cmds.items():
        if path == "sim":
            continue        # sim --port is the device to serve the simulated bus on, not a bus
        opt = next(p for p in cmd.params if "--port" in p.opts)
        assert "port name from the config file" in (opt.help or ""), path
        assert opt.envvar is None, path          # PDRIVE_PORT goes through config.resolve


@pytest.mark.parametrize("args,expect", [
    (["scan"], "sim://?timing=virtual at 187.5k: 5 station(s)"),
    (["status", "3", "--json"], '"layout": "ppo3"'),                # the station default
    (["status", "5", "--json"], '"profile": "toyo-pbus66z"'),
    (["param", "get", "4", "F07"], "F07"),
    (["faults", "4"], "station 4"),
    (["diag", "3"], "3"),
])
def test_a_named_port_works_in_bus_commands(env, args, expect, monkeypatch):
    r = CliRunner().invoke(cli, args + ["--port", "line1"])
    assert r.exit_code == 0, r.output
    assert expect in r.output


def test_run_takes_fmax_from_the_station_defaults(env, tmp_path):
    # layout ppo3 has no parameter channel: F03 cannot be read, the config's fmax 50 Hz applies
    # 20 % of the drive's F03 60 Hz = 12 Hz, F07 6 s for 60 Hz: reached after 1.2 s, within the 2 s
    r = CliRunner().invoke(cli, ["run", "3", "--hz", "10", "--duration", "2", "--json"])
    assert r.exit_code == 0, r.output
    # stdout only: the project file's settings in use are named on stderr (docs/config.md)
    start = json.loads(r.stdout.splitlines()[0])
    assert start["event"] == "start" and start["layout"] == "ppo3"
    assert start["fmax_hz"] == 50.0 and start["reference_percent"] == pytest.approx(20.0)
    proj = (tmp_path / "proj" / "pdrive.yaml").resolve()
    assert start["fmax_source"] == f"from {proj}:7"           # PROJECT line 7, not "from --fmax"


def test_an_option_beats_the_station_default(env):
    r = CliRunner().invoke(cli, ["status", "3", "--ppo", "1", "--json"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["layout"] == "ppo1"         # stderr names the project file's port


def test_config_show_json_says_where_each_setting_came_from(env, tmp_path):
    r = CliRunner().invoke(cli, ["config", "show", "--json", "--baud", "1.5M"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.output)
    proj = str((tmp_path / "proj" / "pdrive.yaml").resolve())
    assert d["port"] == {"value": SIM, "source": f"{proj}:1 -> {proj}:4", "name": "line1"}
    assert d["baud"] == {"value": "1.5M", "source": "option --baud"}
    assert d["master_address"]["value"] == 1
    assert d["stations"][0] == {"station": 3, "layout": {"value": "ppo3", "source": f"{proj}:7"},
                                "fmax": {"value": 50.0, "source": f"{proj}:7"}}
    assert [p["name"] for p in d["ports"]] == ["rig", "line1"]
    assert [f["kind"] for f in d["files"]] == ["user", "project"]


def test_config_show_text_and_path(env, tmp_path, monkeypatch):
    # wide enough for the row with the config file's path whatever tmp_path's length: the command's
    # console is made at import, with the width of that moment (under pytest-xdist the path is
    # longer and an 80-column table cut the words this test reads)
    from profidrive_cli.cli import common
    monkeypatch.setattr(common.out, "width", 1000)
    r = CliRunner().invoke(cli, ["config", "show"])
    assert r.exit_code == 0, r.output
    assert "port name line1" in r.output and "187500" in r.output
    r = CliRunner().invoke(cli, ["config", "path", "--json"])
    assert json.loads(r.output)["files"][0]["path"] == str(tmp_path / "xdg" / "pdrive" / "config.yaml")


def test_text_output_to_a_pipe_is_not_wrapped(tmp_path):
    # a 200-character folder name: through a pipe the table keeps each path on one line
    deep = tmp_path / ("x" * 200)
    p = _pdrive(["config", "path"], tmp_path, {"XDG_CONFIG_HOME": str(deep)})
    assert p.returncode == 0, p.stderr
    want = str(deep / "pdrive" / "config.yaml")
    assert any(want in line for line in p.stdout.splitlines()), p.stdout


def test_gsd_show_through_a_pipe_keeps_a_long_path_whole(tmp_path):
    # gsd_cmd makes its own console (markup off): the same rule as common.make_console; before, a
    # piped table was cut to 80 columns and the path ended in "…"
    import shutil
    deep = tmp_path / ("z" * 150)
    deep.mkdir()
    f = deep / "FUJIFD01.GSD"
    shutil.copy(Path(__file__).resolve().parent.parent / "gsd" / "FUJIFD01.GSD", f)
    p = _pdrive(["gsd", "show", str(f)], tmp_path, {})
    assert p.returncode == 0, p.stderr
    assert str(f) in p.stdout, p.stdout


def test_shell_completion_works_and_completes_port_names(env, tmp_path):
    # click's completion, as the README's `eval "$(_PDRIVE_COMPLETE=bash_source pdrive)"` uses it
    extra = {"XDG_CONFIG_HOME": env["XDG_CONFIG_HOME"]}
    cwd = Path.cwd()
    p = _pdrive([], cwd, {**extra, "_PDRIVE_COMPLETE": "bash_source"})
    assert p.returncode == 0 and "_pdrive_completion()" in p.stdout
    p = _pdrive([], cwd, {**extra, "_PDRIVE_COMPLETE": "bash_complete",
                          "COMP_WORDS": "pdrive conf", "COMP_CWORD": "1"})   # "con": config, convert
    assert p.stdout.split() == ["plain,config"]
    p = _pdrive([], cwd, {**extra, "_PDRIVE_COMPLETE": "bash_complete",
                          "COMP_WORDS": "pdrive status --port ", "COMP_CWORD": "3"})
    # the project's line1 (it wins over the user's) and the user's rig, then sim://
    assert sorted(p.stdout.split()) == ["plain,line1", "plain,rig", "plain,sim://"]


CHECKLIST = """\
name: config precedence
port: {port}
stations:
  - name: g1
    address: 3
    profile: fuji-g1
steps:
  - expect_identity
"""


@pytest.mark.parametrize("cl_port", ["'sim://?timing=virtual'", "rig"])
def test_a_checklists_own_port_beats_the_configs_default_port(tmp_path, cl_port):
    # the config's default port is nowhere; the checklist names its own (a device or a config name)
    (tmp_path / "pdrive.yaml").write_text("port: /dev/pdrive-no-such-port\n"
                                          "ports:\n  rig: 'sim://?timing=virtual'\n")
    (tmp_path / "cl.yaml").write_text(CHECKLIST.format(port=cl_port))
    p = _pdrive(["checklist", "run", "cl.yaml", "--yes"], tmp_path,
                {"XDG_CONFIG_HOME": str(tmp_path / "none")})
    assert p.returncode == 0, p.stdout + p.stderr
    assert "PASSED config precedence" in p.stdout
    # --port still beats the checklist's
    p = _pdrive(["checklist", "run", "cl.yaml", "--yes", "--port", "/dev/pdrive-no-such-port"],
                tmp_path, {"XDG_CONFIG_HOME": str(tmp_path / "none")})
    assert p.returncode != 0 and "/dev/pdrive-no-such-port" in p.stderr


def test_config_show_refuses_a_baud_rate_no_bus_command_takes(monkeypatch):
    from click.testing import CliRunner

    from profidrive_cli import UsageError
    from profidrive_cli.cli.main import cli
    r = CliRunner().invoke(cli, ["config", "show", "--baud", "bogus"])
    # the same words a bus command says for the same value (cli.common.baud_from)
    assert isinstance(r.exception, UsageError) and \
        str(r.exception).startswith("'bogus' is not a PROFIBUS-DP baud rate")
    monkeypatch.setenv("PDRIVE_BAUD", "12345")
    r = CliRunner().invoke(cli, ["config", "show"])
    assert isinstance(r.exception, UsageError) and \
        str(r.exception).startswith("env PDRIVE_BAUD: baud '12345' is not a PROFIBUS-DP baud rate")
    r = CliRunner().invoke(cli, ["config", "show", "--baud", "187500"])
    assert r.exit_code == 0 and "187500" in r.output
