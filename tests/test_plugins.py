"""Plug-ins without forking (issue 29, docs/plugins.md): a distribution that names a drive family in the
entry-point group `profidrive_cli.families` and a port kind in `profidrive_cli.links` is seen by
`pdrive scan`, `decode`, `status` and `sim://`; $PDRIVE_PROFILE_PATH adds profile folders; a broken
plug-in does not break pdrive and is named where a family is missing; a command on the shipped families
never reads the installed distributions' entry points; `sniff --station` reads a plug-in station's
areas through the family's Drive hook (normalise_area).

The example plug-in (tests/data/plugin_demo: the family `demo`, a PROFIdrive PPO card with ident 0xDE01,
and the port kind demosim://) is installed by pip into a new virtualenv's site-packages, and pdrive runs with that virtualenv's
python."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PLUGIN = ROOT / "tests" / "data" / "plugin_demo"

# tests/data/plugin_demo/pdrive_demo/profiles/demo-card.yaml
DEMO_IDENT = 0xDE01
DEMO_TITLE = "Demo PROFIdrive card (a pdrive plug-in)"


@pytest.fixture(scope="module")
def plugin_venv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A new virtualenv (without pip of its own) that sees this environment's packages (pdrive and
    its dependencies, through a .pth file) and has the example plug-in installed into its own
    site-packages by pip: its python is what the tests run pdrive with."""
    pytest.importorskip("setuptools", reason="pip builds the example plug-in with setuptools")
    import shutil
    import sysconfig
    venv = tmp_path_factory.mktemp("venv")
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    py = venv / ("Scripts/python.exe" if os.name == "nt" else "bin/python")
    site = Path(subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                               capture_output=True, text=True, check=True, timeout=60).stdout.strip())
    here = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"], str(ROOT)}
    (site / "outer-env.pth").write_text("\n".join(sorted(here)) + "\n")
    src = tmp_path_factory.mktemp("plugin-src") / "plugin_demo"
    shutil.copytree(PLUGIN, src)               # the build writes egg-info beside its source
    proc = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-index",
                           "--no-build-isolation", "--target", str(site), str(src)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert (site / "pdrive_demo" / "profiles" / "demo-card.yaml").is_file()
    return py


def _pdrive(*args: str, path: Path | None = None, python: Path | None = None,
            **env_extra: str) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("PDRIVE_")}
    env["PYTHONNOUSERSITE"] = "1"
    env.pop("PYTHONPATH", None)
    if path is not None:
        env["PYTHONPATH"] = str(path)
    env.update(env_extra)
    return subprocess.run([str(python or sys.executable), "-m", "profidrive_cli", *args],
                          capture_output=True, text=True, env=env, timeout=300)


def test_scan_sees_the_plugin_family_on_sim(plugin_venv: Path) -> None:
    proc = _pdrive("scan", "--port", "sim://?stations=9:demo-card", "--quick", "--json", python=plugin_venv)
    assert proc.returncode == 0, proc.stderr
    (st,) = json.loads(proc.stdout)["stations"]
    assert (st["station"], st["ident"], st["device"]) == (9, DEMO_IDENT, DEMO_TITLE)


def test_decode_knows_the_plugin_profile(plugin_venv: Path) -> None:
    # PPO1 request: 4 PKW words, then CTW 0x047F (PZD1, octets 8-9) and the reference 0x2000
    # (PZD2): 0x2000 / 0x4000 = 50 % of FMAX's default 50 Hz = 25 Hz (PROFIdrive N2 scaling)
    area = ["00"] * 8 + ["04", "7F", "20", "00"]
    proc = _pdrive("decode", "demo", "--ppo", "1", "--request", *area, python=plugin_venv)
    assert proc.returncode == 0, proc.stderr
    assert "CTW (control word) 0x047F" in proc.stdout
    assert "25.00 Hz" in proc.stdout


def test_a_plugin_drive_runs_and_stops(plugin_venv: Path) -> None:
    proc = _pdrive("run", "9", "--hz", "10", "--duration", "1", "--port", "sim://?stations=9:demo",
                   python=plugin_venv)
    assert proc.returncode == 0, proc.stderr
    assert "stop: normal (stopped)" in proc.stderr


def test_sniff_reads_a_plugin_station_through_its_drive_hook(plugin_venv: Path, tmp_path: Path) -> None:
    # a captured PPO1 exchange with station 9: CTW 0x047F with reference 0x2000 (50 % of FMAX's
    # default 50 Hz = 25 Hz, N2), the answer STW 0x0337 (S4, operation) with actual 0x2000; the demo
    # card's DemoDrive.normalise_area names the card in the state (the core's reading otherwise)
    from profidrive_cli.fdl import frames as F
    out_area = bytes.fromhex("00" * 8 + "04 7F 20 00")
    in_area = bytes.fromhex("00" * 8 + "03 37 20 00")
    raw = tmp_path / "dx.raw"
    raw.write_bytes(F.encode(F.Frame(F.SD2, 9, 2, F.request_fc(F.SRD_HIGH, True, True), out_area))
                    + F.encode(F.Frame(F.SD2, 2, 9, F.DL, in_area)))
    proc = _pdrive("sniff", "--from-file", str(raw), "--station", "9=demo", "--json", python=plugin_venv)
    assert proc.returncode == 0, proc.stderr
    r, a = (json.loads(line)["drive"] for line in proc.stdout.splitlines())
    assert (r["command"], r["reference_hz"]) == ("operate", 25.0)
    assert a["state"] == "demo card: S4 operation" and a["actual_hz"] == 25.0
    assert a["text"] == "demo card: S4 operation, actual 25.00 Hz"


def test_the_plugin_port_kind_opens(plugin_venv: Path) -> None:
    proc = _pdrive("scan", "--port", "demosim://?stations=9:demo", "--quick", "--json", python=plugin_venv)
    assert proc.returncode == 0, proc.stderr
    assert [s["ident"] for s in json.loads(proc.stdout)["stations"]] == [DEMO_IDENT]


def test_without_the_plugin_the_family_is_unknown() -> None:
    proc = _pdrive("decode", "demo", "--ppo", "1", "--request", *(["00"] * 12))
    assert proc.returncode == 2
    assert proc.stderr.startswith("pdrive: unknown profile 'demo'") and "Traceback" not in proc.stderr


GENERIC = textwrap.dedent("""\
    profile: my-card
    family: profidrive
    title: My own PROFIdrive card
    identity: {ident: 0x4321}
    layouts:
      ppo1: {cfg: "F3 F1", pkw: true}
    default_layout: ppo1
    """)


def test_pdrive_profile_path_adds_a_profile_folder(tmp_path: Path) -> None:
    (tmp_path / "my-card.yaml").write_text(GENERIC, encoding="utf-8")
    proc = _pdrive("scan", "--port", "sim://?stations=12:my-card", "--quick", "--json",
                   PDRIVE_PROFILE_PATH=str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    (st,) = json.loads(proc.stdout)["stations"]
    assert (st["station"], st["ident"], st["device"]) == (12, 0x4321, "My own PROFIdrive card")


def _broken_plugin(where: Path) -> None:
    """An installed distribution whose family entry point raises on import (written by hand: a
    dist-info folder is what importlib.metadata reads)."""
    dist = where / "pdrive_broken-0.0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: pdrive-broken\nVersion: 0.0.1\n")
    (dist / "entry_points.txt").write_text("[profidrive_cli.families]\nbroken = pdrive_broken:family\n")
    (where / "pdrive_broken.py").write_text("raise RuntimeError('this plug-in is broken')\n")


def test_a_broken_plugin_breaks_nothing_and_is_named_where_a_family_is_missing(tmp_path: Path) -> None:
    plug = tmp_path / "site"
    plug.mkdir()
    _broken_plugin(plug)
    ok = _pdrive("scan", "--port", "sim://", "--quick", "--json", path=plug)
    assert ok.returncode == 0, ok.stderr
    assert [s["station"] for s in json.loads(ok.stdout)["stations"]] == [3, 4, 5, 6, 7]
    prof = tmp_path / "profiles"
    prof.mkdir()
    (prof / "x.yaml").write_text(GENERIC.replace("family: profidrive", "family: broken"), encoding="utf-8")
    bad = _pdrive("decode", str(prof / "x.yaml"), "--ppo", "1", "--request", *(["00"] * 12), path=plug)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr
    (line,) = bad.stderr.strip().splitlines()
    # line 2 of GENERIC is `family: ...`
    assert line.startswith(f"pdrive: {prof / 'x.yaml'}:2: family 'broken' unknown (known: "), line
    assert "plug-in 'pdrive_broken:family' (entry point 'broken') did not load: RuntimeError: " \
           "this plug-in is broken" in line


def test_commands_on_the_shipped_families_never_read_the_entry_points(capsys, monkeypatch) -> None:
    from profidrive_cli.drives import registry
    from profidrive_cli.drives.profile import clear_cache
    from test_exit_codes import pdrive
    registry.reset_plugins()
    clear_cache()
    code, out, err = pdrive(capsys, monkeypatch, "scan", "--port", "sim://", "--quick")
    assert code == 0, err
    code, out, err = pdrive(capsys, monkeypatch, "status", "3", "--port", "sim://")
    assert code == 0, err
    assert registry._plugins is None          # plugins() was never called
