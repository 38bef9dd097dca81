"""The README's two commands are the ones CI runs and the ones a newcomer types."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_ci_runs_exactly_the_readme_test_command():
    readme = (ROOT / "README.md").read_text()
    ci = (ROOT / ".ci" / "run").read_text()
    cmd = "pip install '.[test]' && pytest -q"
    assert cmd in readme.split("```sh")[2]
    assert any(line.strip() == cmd for line in ci.splitlines())


def test_readme_opens_with_the_main_job():
    readme = (ROOT / "README.md").read_text()
    first_block = readme.split("```sh")[1].split("```")[0].strip()
    assert first_block == "pip install . && pdrive scan --port sim://"
