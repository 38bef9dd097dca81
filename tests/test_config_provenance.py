"""Where a config value came from is never lost (docs/config.md "Provenance"):

- a project file (the nearest pdrive.yaml in the working folder or above) is named on stderr, with
  file:line, for every setting of it a command uses: port, baud rate, master address, a station's
  profile / layout / fmax -- before the port is opened;
- a station's fmax from a file is labelled "from FILE:LINE" (live view, text, JSON fmax_source), never
  "from --fmax";
- config mistakes found late (an undefined port name, a station's profile or layout that does not fit,
  a baud rate with no integer, a master address equal to the station's) are exit 2 with file:line.

pdrive runs as its own process here (stdout and stderr apart, the working folder its own)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# F07/F08 = 0.1 s (0 -> F03 60 Hz): every run here reaches its reference within its 0.2-0.3 s (a run
# that does not exits 1); 5 Hz in 8 ms, 60 Hz (PPO3 with fmax 1: 100 %) in 0.1 s
SIM = "sim://?stations=3:fuji-g1&timing=virtual&set=3:F07=0.1,F08=0.1"

# the issue's project file: a parent folder's pdrive.yaml sets the default port (a name) and, for
# station 3, layout PPO3 (no parameter channel: F03 cannot be read) and fmax 1 Hz
PROJECT = f"""\
port: rig
ports:
  rig:
    port: '{SIM}'
    stations:
      3:
        layout: ppo3
        fmax: 1
"""


def _pdrive(args, cwd, **env_extra):
    env = {k: v for k, v in os.environ.items()
           if k not in ("PDRIVE_PORT", "PDRIVE_BAUD", "PDRIVE_CONFIG", "PDRIVE_STATION", "COLUMNS")}
    env.update(env_extra)
    env["PYTHONPATH"] = str(ROOT)
    return subprocess.run([sys.executable, "-m", "profidrive_cli", *args], capture_output=True,
                          text=True, timeout=120, cwd=cwd, env=env, stdin=subprocess.DEVNULL)


def _project(tmp_path, text=PROJECT):
    """pdrive.yaml in tmp/proj, the working folder tmp/proj/clone/sub (two folders below it)."""
    (tmp_path / "proj").mkdir()
    f = tmp_path / "proj" / "pdrive.yaml"
    f.write_text(text)
    cwd = tmp_path / "proj" / "clone" / "sub"
    cwd.mkdir(parents=True)
    return f.resolve(), cwd, {"XDG_CONFIG_HOME": str(tmp_path / "no-user-config")}


def test_the_issue_a_parent_folders_fmax_is_named_and_labelled_with_its_line(tmp_path):
    f, cwd, env = _project(tmp_path)
    p = _pdrive(["run", "3", "--hz", "1", "--duration", "0.3", "--json"], cwd, **env)
    assert p.returncode == 0, p.stderr
    start = json.loads(p.stdout.splitlines()[0])
    assert start["event"] == "start" and start["layout"] == "ppo3" and start["fmax_hz"] == 1.0
    # PROJECT line 8 is `fmax: 1`: the value's source is that line, not an option never given
    assert start["fmax_source"] == f"from {f}:8"
    assert "--fmax" not in p.stdout
    # stderr names the project file for each value it set that the run used (lines 1 and 4: the
    # default port `rig` and its device; line 7: the layout; line 8: fmax)
    assert f"pdrive: using port {SIM} (port name rig) from {f}:1 -> {f}:4 (project file)" in p.stderr
    assert f"pdrive: using station 3 layout ppo3 from {f}:7 (project file)" in p.stderr
    assert f"pdrive: using station 3 fmax 1 Hz from {f}:8 (project file)" in p.stderr


def test_the_text_view_labels_the_fmax_with_the_files_line(tmp_path):
    f, cwd, env = _project(tmp_path)
    p = _pdrive(["run", "3", "--hz", "1", "--duration", "0.3"], cwd, **env)
    assert p.returncode == 0, p.stderr
    assert f"max frequency 1 Hz from {f}:8" in p.stdout, p.stdout


def test_a_readable_drive_max_frequency_wins_and_the_files_fmax_is_checked_against_it(tmp_path):
    # --ppo 1 has a parameter channel: F03 is read from the drive (the simulator's 60 Hz, the
    # FRENIC-MEGA factory value) and used, so the speed shown is the drive's own scale; the file's
    # fmax 1 Hz is not used (not named as used) but its disagreement is a warning with both figures
    f, cwd, env = _project(tmp_path)
    p = _pdrive(["run", "3", "--hz", "1", "--duration", "0.3", "--ppo", "1", "--json"], cwd, **env)
    assert p.returncode == 0, p.stderr
    start = json.loads(p.stdout.splitlines()[0])
    assert start["fmax_source"] == "read from the drive (F03)" and start["fmax_hz"] == 60.0
    warning = f"fmax 1 Hz from {f}:8 ignored: the drive says F03 = 60 Hz"
    assert start["warnings"] == [warning]
    assert "using station 3 fmax" not in p.stderr and "layout" not in p.stderr  # --ppo 1 beat it
    assert f"using port {SIM} (port name rig) from {f}:1 -> {f}:4" in p.stderr


def test_the_api_checks_a_config_fmax_against_the_drives_own_too(tmp_path, monkeypatch):
    import profidrive_cli as pdrive
    f = tmp_path / "cfg.yaml"
    f.write_text(f"ports:\n  rig:\n    port: '{SIM}'\n    stations:\n      3: {{layout: ppo1, fmax: 50}}\n")
    monkeypatch.setenv("PDRIVE_CONFIG", str(f))
    with pdrive.open_bus("rig") as bus:
        d = bus.drive(3)
        assert d.fmax_hz == 60.0                                 # F03 read from the drive
        assert f"fmax 50 Hz from {f}:5 ignored: the drive says F03 = 60 Hz" in d._station.warnings


def test_an_option_given_is_not_announced(tmp_path):
    f, cwd, env = _project(tmp_path, "port: sim://\nbaud: 187500\nmaster_address: 1\n")
    p = _pdrive(["scan", "--port", SIM, "--baud", "19200", "--master-address", "2"], cwd, **env)
    assert p.returncode == 0, p.stderr
    assert p.stderr == ""
    p = _pdrive(["scan"], cwd, **env)
    assert p.returncode == 0, p.stderr
    assert p.stderr.splitlines() == [f"pdrive: using port sim:// from {f}:1 (project file)",
                                     f"pdrive: using baud rate 187500 from {f}:2 (project file)",
                                     f"pdrive: using master address 1 from {f}:3 (project file)"]


def test_the_users_own_file_and_pdrive_config_are_not_announced(tmp_path):
    # the user's file and the one PDRIVE_CONFIG names were chosen by the user: no notice
    xdg = tmp_path / "xdg"
    (xdg / "pdrive").mkdir(parents=True)
    (xdg / "pdrive" / "config.yaml").write_text(f"port: '{SIM}'\n")
    p = _pdrive(["scan"], tmp_path, XDG_CONFIG_HOME=str(xdg))
    assert p.returncode == 0 and p.stderr == "", p.stderr
    named = tmp_path / "named.yaml"
    named.write_text(f"port: '{SIM}'\nports:\n  rig:\n    port: '{SIM}'\n    stations:\n"
                     f"      3: {{layout: ppo3, fmax: 50}}\n")
    p = _pdrive(["run", "3", "--hz", "5", "--duration", "0.2", "--port", "rig", "--json"], tmp_path,
                XDG_CONFIG_HOME=str(xdg), PDRIVE_CONFIG=str(named))
    assert p.returncode == 0 and p.stderr == "", p.stderr
    # ... but the fmax label still names the file and line (named.yaml line 6)
    assert json.loads(p.stdout.splitlines()[0])["fmax_source"] == f"from {named}:6"


def test_a_bad_value_is_refused_before_any_notice(tmp_path):
    # a bad input is one line: the project file's notices come only when the port is opened
    f, cwd, env = _project(tmp_path, "port: sim://\nbaud: 'inf'\n")
    p = _pdrive(["scan"], cwd, **env)
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert p.stderr.splitlines() == [f"pdrive: {f}:2: baud 'inf' is not a PROFIBUS-DP baud rate "
                                     f"(9.6k, 19.2k, 45.45k, 93.75k, 187.5k, 500k, 1.5M, 3M, 6M, 12M)"]
    assert p.stdout == ""


# ------------------------------------------------------------------------ late mistakes: file:line


def _named(tmp_path, text):
    f = tmp_path / "cfg.yaml"
    f.write_text(text)
    return f, {"PDRIVE_CONFIG": str(f), "XDG_CONFIG_HOME": str(tmp_path / "none")}


def _one_error(p, code=2):
    assert p.returncode == code, p.stderr
    assert p.stderr.count("\n") == 1 and "Traceback" not in p.stderr, p.stderr
    return p.stderr


def test_an_undefined_default_port_name_is_exit_2_at_its_line(tmp_path):
    f, env = _named(tmp_path, "port: line9\nports:\n  rig: sim://\n")
    err = _one_error(_pdrive(["scan"], tmp_path, **env))
    assert err.startswith(f"pdrive: {f}:1: port 'line9' is not a port name of the config files "
                          f"(names: rig)"), err
    err = _one_error(_pdrive(["scan"], tmp_path, **env, PDRIVE_PORT="lin"))
    assert err.startswith("pdrive: env PDRIVE_PORT: port 'lin' is not a port name"), err
    # a Windows device has the form of a name: not refused here (pyserial says whether it exists)
    f, env = _named(tmp_path, "port: COM3\n")
    p = _pdrive(["scan"], tmp_path, **env)
    assert "is not a port name" not in p.stderr


def test_a_stations_profile_from_the_file_is_blamed_on_its_line(tmp_path):
    f, env = _named(tmp_path, f"port: rig\nports:\n  rig:\n    port: '{SIM}'\n    stations:\n"
                              f"      3: {{profile: moeller}}\n")
    err = _one_error(_pdrive(["run", "3", "--hz", "5", "--duration", "0.2"], tmp_path, **env))
    # station 3 of SIM is a Fuji OPC-G1-PDP (ident 0xFD01); the file's line 6 said moeller
    assert err.startswith(f"pdrive: {f}:6: profile: station 3 is fuji-opc-g1-pdp"), err
    assert "not moeller-de6-net-dp" in err and "correct that line or give --profile fuji-g1" in err
    assert "leave out --profile" not in err
    err = _one_error(_pdrive(["status", "3"], tmp_path, **env))          # the API's path too
    assert err.startswith(f"pdrive: {f}:6: profile: station 3 is fuji-opc-g1-pdp"), err
    f, env = _named(tmp_path, f"port: rig\nports:\n  rig:\n    port: '{SIM}'\n    stations:\n"
                              f"      3: {{profile: nosuch}}\n")
    err = _one_error(_pdrive(["status", "3"], tmp_path, **env))
    assert err.startswith(f"pdrive: {f}:6: profile: unknown profile 'nosuch'"), err


def test_a_stations_layout_from_the_file_is_blamed_on_its_line(tmp_path):
    f, env = _named(tmp_path, f"port: rig\nports:\n  rig:\n    port: '{SIM}'\n    stations:\n"
                              f"      3: {{layout: ppo9}}\n")
    err = _one_error(_pdrive(["run", "3", "--hz", "5", "--duration", "0.2"], tmp_path, **env))
    assert err.startswith(f"pdrive: {f}:6: layout ppo9: fuji-opc-g1-pdp has the layouts"), err
    assert "--format" not in err


def test_a_master_address_equal_to_the_station_is_refused_naming_where_it_came_from(tmp_path):
    f, env = _named(tmp_path, f"port: '{SIM}'\nmaster_address: 3\n")
    for args in (["status", "3"], ["diag", "3"], ["run", "3", "--hz", "5", "--duration", "0.2"],
                 ["param", "get", "3", "F03"], ["io", "3", "--cfg", "F3F1", "--count", "1"]):
        err = _one_error(_pdrive(args, tmp_path, **env))
        assert err == (f"pdrive: station 3 is the master's own address ({f}:2 = 3): give another "
                       f"--master-address\n"), (args, err)
    # the option: named as the option
    err = _one_error(_pdrive(["run", "3,4", "--hz", "5", "--duration", "0.2", "--master-address", "4",
                              "--port", SIM], tmp_path, XDG_CONFIG_HOME=str(tmp_path / "none")))
    assert "station 4 is the master's own address (--master-address = 4)" in err


def test_a_name_given_on_the_command_line_but_redefined_by_a_project_file_is_named(tmp_path):
    # the user's file says line1 is a device; a project file above the working folder redefines
    # line1 (a name defined in both files is taken whole from the project file): --port line1 now
    # goes elsewhere -- said on stderr with the project file's line
    xdg = tmp_path / "xdg"
    (xdg / "pdrive").mkdir(parents=True)
    (xdg / "pdrive" / "config.yaml").write_text("ports:\n  line1: /dev/pdrive-no-such-port\n")
    f, cwd, _ = _project(tmp_path, f"ports:\n  line1: '{SIM}'\n")
    p = _pdrive(["scan", "--port", "line1"], cwd, XDG_CONFIG_HOME=str(xdg))
    assert p.returncode == 0, p.stderr
    assert p.stderr == f"pdrive: using port {SIM} (port name line1) from option --port -> {f}:2 (project file)\n"


def test_a_checklists_port_name_defined_by_a_project_file_is_named(tmp_path):
    f, cwd, env = _project(tmp_path, f"ports:\n  rig: '{SIM}'\n")
    (cwd / "cl.yaml").write_text("name: provenance\nport: rig\nstations:\n  - name: g1\n    address: 3\n"
                                 "    profile: fuji-g1\nsteps:\n  - expect_identity\n")
    p = _pdrive(["checklist", "run", "cl.yaml", "--yes"], cwd, **env)
    assert p.returncode == 0, p.stdout + p.stderr
    assert f"pdrive: using port {SIM} (port name rig) from {f}:2 (project file)" in p.stderr
