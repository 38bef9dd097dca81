"""The README's commands are the ones CI runs and the ones a newcomer types."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PINNED = "PIP_CONSTRAINT=constraints.txt pip install -c constraints.txt '.[test]' && pytest -q"
NEWEST = "pip install --upgrade --upgrade-strategy eager '.[test]' && pytest -q"


def _blocks(text: str) -> list[str]:
    return [b.split("```")[0].strip() for b in text.split("```sh")[1:]]


def test_ci_runs_exactly_the_readme_pinned_test_command():
    readme = (ROOT / "README.md").read_text()
    ci = (ROOT / ".ci" / "run").read_text()
    assert _blocks(readme)[1] == PINNED
    assert any(line.strip() == PINNED for line in ci.splitlines())


def test_the_run_against_the_newest_releases_is_documented_apart():
    """Unpinned: the command that shows whether constraints.txt can be moved on; never CI's, and
    not among the README's commands (a newcomer runs those two: install and scan, the pinned
    tests). docs/dependencies.md has it, with how constraints.txt is updated."""
    readme = (ROOT / "README.md").read_text()
    doc = (ROOT / "docs" / "dependencies.md").read_text()
    assert _blocks(doc)[1] == NEWEST and _blocks(doc)[0] == PINNED
    assert NEWEST not in readme and "docs/dependencies.md" in readme
    assert "constraints" not in NEWEST and NEWEST not in (ROOT / ".ci" / "run").read_text()
    assert "pip freeze --exclude profidrive-cli" in doc        # how constraints.txt is updated


def test_the_readme_has_two_commands_before_its_first_section():
    readme = (ROOT / "README.md").read_text()
    head = readme.split("\n## ", 1)[0]
    assert len(_blocks(head)) == 2


def test_ci_installs_nothing_unpinned():
    """Every pip install in .ci/run is the pinned command: no `pip install --upgrade pip` and such
    that a new release could break."""
    ci = (ROOT / ".ci" / "run").read_text()
    installs = [line.strip() for line in ci.splitlines()
                if re.search(r"\bpip\b.*\binstall\b", line) and not line.lstrip().startswith("#")]
    assert installs == [PINNED]


def test_the_constraints_pin_every_dependency_exactly():
    """constraints.txt pins (==) each runtime and test dependency of pyproject.toml, and the build
    backend (setuptools, wheel) that pip's isolated build would otherwise take at its newest."""
    pins = {}
    for line in (ROOT / "constraints.txt").read_text().splitlines():
        line = line.split("#")[0].strip()
        if line:
            name, sep, version = line.partition("==")
            assert sep and re.fullmatch(r"[0-9][0-9A-Za-z.+!-]*", version), line
            pins[name.lower().replace("_", "-")] = version
    pyproject = (ROOT / "pyproject.toml").read_text()
    deps = re.search(r"(?ms)^dependencies = \[(.*?)\]", pyproject).group(1)
    test = re.search(r"(?ms)^test = \[(.*?)\]", pyproject).group(1)
    backend = re.search(r"(?m)^requires = \[(.*?)\]", pyproject).group(1)
    wanted = {re.match(r"[A-Za-z0-9_.-]+", d).group(0).lower().replace("_", "-")
              for d in re.findall(r'"([^"]+)"', deps + test + backend)}
    assert wanted and wanted <= set(pins), wanted - set(pins)


def test_readme_opens_with_the_main_job():
    readme = (ROOT / "README.md").read_text()
    first_block = readme.split("```sh")[1].split("```")[0].strip()
    assert first_block == "pip install . && pdrive scan --port sim://"
