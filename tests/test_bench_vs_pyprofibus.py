"""pyprofibus (GPL) stays a benchmark-only dependency: never imported by profidrive_cli/, only in the
optional `bench` extra; the benchmark runs with it and says it skipped without it."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
BENCH = ROOT / "benchmarks" / "bench_vs_pyprofibus.py"


def test_no_module_of_profidrive_cli_imports_pyprofibus():
    hits = []
    for path in (ROOT / "profidrive_cli").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            hits += [f"{path.relative_to(ROOT)}:{node.lineno}" for n in names
                     if n.split(".")[0] == "pyprofibus"]
    assert hits == []


@pytest.mark.skipif(sys.version_info < (3, 11), reason="tomllib")
def test_pyprofibus_is_only_in_the_bench_extra():
    import tomllib
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert not any("pyprofibus" in d for d in conf["dependencies"])
    extras = {k: v for k, v in conf["optional-dependencies"].items()
              if any("pyprofibus" in d for d in v)}
    assert list(extras) == ["bench"]


def test_benchmark_says_it_skipped_without_pyprofibus():
    code = ("import sys, runpy; sys.modules['pyprofibus'] = None; sys.argv = ['b', '--n', '10'];"
            f"runpy.run_path({str(BENCH)!r}, run_name='__main__')")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("skipped: pyprofibus is not installed")


def test_benchmark_runs_both_masters_on_both_links():
    pytest.importorskip("pyprofibus")
    r = subprocess.run([sys.executable, str(BENCH), "--n", "200", "--rounds", "2", "--octets", "4"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    for link in ("canned", "dummy"):
        rows = [ln for ln in lines if ln.split()[:1] == [link]]
        assert any("pdrive " in ln and "µs" in ln for ln in rows), r.stdout
        assert any("pyprofibus DPM1" in ln and "µs" in ln for ln in rows), r.stdout
        assert any("pyprofibus / pdrive =" in ln for ln in rows), r.stdout
