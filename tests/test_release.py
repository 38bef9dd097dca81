"""A release people can install (issue 29, docs/versioning.md): `python -m build` makes the sdist and,
from it, the wheel; the wheel carries every module, profile, GSD file and the dissector of the source
tree; installed on its own, its `pdrive` runs (--version, a scan of sim://) from the wheel's files and
not from this checkout; CHANGELOG.md's newest version is pyproject's.

The build runs without isolation (`--no-isolation`): the build backend is the one the test
environment has from constraints.txt (setuptools, wheel), so nothing is downloaded while testing.
The source is copied first (the files git tracks), so the build writes nothing into the checkout
and sees no stray file."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

pytest.importorskip("build", reason="the build package (the test extra) makes the sdist and wheel")


def _version() -> str:
    text = (ROOT / "pyproject.toml").read_text()
    m = re.search(r'^version\s*=\s*"([^"]+)"', text, re.M)
    assert m, "pyproject.toml has no version"
    return m.group(1)


def _source_files() -> list[Path]:
    """The files of the checkout as git knows them; without git (an unpacked sdist), every file but
    caches, venvs and build output."""
    try:
        out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True,
                             timeout=60).stdout
        files = [ROOT / p for p in out.decode().split("\0") if p]
        if files:
            return [f for f in files if f.is_file()]
    except (OSError, subprocess.SubprocessError):
        pass
    skip = {".git", ".ci-venv", ".venv", "build", "dist", "__pycache__", ".pytest_cache",
            ".mypy_cache", ".hypothesis"}
    return [p for p in ROOT.rglob("*") if p.is_file()
            and not any(part in skip or part.endswith(".egg-info") for part in p.relative_to(ROOT).parts)]


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    src = tmp_path_factory.mktemp("src")
    for f in _source_files():
        dest = src / f.relative_to(ROOT)
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(f, dest)
    dist = tmp_path_factory.mktemp("dist")
    proc = subprocess.run([sys.executable, "-m", "build", "--no-isolation", "--outdir", str(dist), str(src)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    wheels = list(dist.glob("*.whl"))
    sdists = list(dist.glob("*.tar.gz"))
    assert len(wheels) == 1 and len(sdists) == 1, sorted(p.name for p in dist.iterdir())
    target = tmp_path_factory.mktemp("installed")
    proc = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "--no-index", "--quiet",
                           "--target", str(target), str(wheels[0])],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return {"wheel": wheels[0], "sdist": sdists[0], "target": target}


def test_names_carry_the_version(built: dict[str, Path]) -> None:
    v = _version()
    assert built["wheel"].name == f"profidrive_cli-{v}-py3-none-any.whl"
    assert built["sdist"].name == f"profidrive_cli-{v}.tar.gz"


def test_the_wheel_carries_every_module_and_data_file(built: dict[str, Path]) -> None:
    names = set(zipfile.ZipFile(built["wheel"]).namelist())
    want = {p.relative_to(ROOT).as_posix() for p in (ROOT / "profidrive_cli").rglob("*.py")
            if "__pycache__" not in p.parts}
    # data at the repository root, carried inside the package (pyproject's package-dir)
    for folder, pkg, patterns in (("profiles", "profiles", ("*.yaml",)),
                                  ("gsd", "gsd_files", ("*.gsd", "*.GSD", "*.gse")),
                                  ("wireshark", "wireshark_files", ("*.lua",))):
        for pat in patterns:
            want |= {f"profidrive_cli/{pkg}/{p.name}" for p in (ROOT / folder).glob(pat)}
    want.add("profidrive_cli/py.typed")
    missing = sorted(want - names)
    assert not missing, f"not in the wheel: {missing[:20]}"
    assert any(n.endswith("entry_points.txt") for n in names)


def _run_installed(built: dict[str, Path], *args: str) -> subprocess.CompletedProcess[str]:
    target = built["target"]
    env = dict(os.environ, PYTHONPATH=str(target), PYTHONNOUSERSITE="1")
    env.pop("PDRIVE_PORT", None)
    # the console script pip wrote for the wheel's entry point, run by this interpreter (whose
    # site-packages give the dependencies); PYTHONPATH puts the wheel's package first
    script = target / "bin" / "pdrive"
    assert script.is_file(), sorted(p.name for p in target.iterdir())
    return subprocess.run([sys.executable, str(script), *args], capture_output=True, text=True,
                          env=env, cwd=str(target), timeout=300)


def test_the_installed_wheel_runs(built: dict[str, Path]) -> None:
    proc = _run_installed(built, "--version")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == f"pdrive, version {_version()}"


def test_the_installed_wheel_scans_the_simulator_from_its_own_files(built: dict[str, Path]) -> None:
    import json
    target = built["target"]
    env = dict(os.environ, PYTHONPATH=str(target), PYTHONNOUSERSITE="1")
    where = subprocess.run([sys.executable, "-c", "import profidrive_cli, profidrive_cli.data as d; "
                            "print(profidrive_cli.__file__)"], capture_output=True, text=True, env=env,
                           cwd=str(target), timeout=120)
    assert where.returncode == 0, where.stderr
    assert Path(where.stdout.strip()).is_relative_to(target), where.stdout
    proc = _run_installed(built, "scan", "--port", "sim://", "--quick", "--json")
    assert proc.returncode == 0, proc.stderr
    found = json.loads(proc.stdout)
    # the default plant (docs/architecture.md, "Default sim plant"): 3 fuji-g1, 4 fuji-pdp3, 5 toyo,
    # 6 moeller, 7 yaskawa -- their profiles and GSD files come from the wheel
    assert sorted(s["station"] for s in found["stations"]) == [3, 4, 5, 6, 7]
    # a device name from the shipped GSD library, read out of the wheel
    assert found["stations"][0]["device"].startswith("Fuji Electric")


def test_the_changelog_names_the_version() -> None:
    text = (ROOT / "CHANGELOG.md").read_text()
    versions = re.findall(r"^## (\d+\.\d+\.\d+)\b", text, re.M)
    assert versions, "CHANGELOG.md lists no version"
    assert versions[0] == _version(), "the newest version in CHANGELOG.md is not pyproject's"
