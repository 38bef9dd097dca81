"""Every ```python example in docs/api.md runs: each block on its own (a fresh namespace), against the
built-in simulator on its virtual clock (sim:// -> sim://?timing=virtual: the same plant and code, no
real waiting); a block that defines pytest fixtures and tests is run by pytest. A block that raises
fails the test, with the block's line in docs/api.md."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "api.md"


def python_blocks() -> list[tuple[int, str]]:
    """(line of the opening fence, code) for every ```python block."""
    text = DOC.read_text(encoding="utf-8")
    out = []
    for m in re.finditer(r"^```python\n(.*?)^```", text, flags=re.S | re.M):
        out.append((text.count("\n", 0, m.start()) + 1, m.group(1)))
    return out


BLOCKS = python_blocks()


def _virtual(code: str) -> str:
    return code.replace('"sim://"', '"sim://?timing=virtual"')


def test_the_doc_has_examples_of_every_call():
    code = "\n".join(c for _, c in BLOCKS)
    assert len(BLOCKS) >= 7
    for call in ("open_bus(", ".scan()", ".drive(", ".status()", ".run(", ".stop()", ".param(",
                 ".set_param(", ".faults()", "wait=True"):
        assert call in code, call


#: the tests must not see the developer's own config files or PDRIVE_* settings
pytestmark = pytest.mark.usefixtures("no_config_at_all")


@pytest.mark.parametrize("line,code", BLOCKS, ids=[f"api.md:{n}" for n, _ in BLOCKS])
def test_example_runs(line, code, tmp_path, capsys):
    code = _virtual(code)
    if "@pytest.fixture" in code:
        f = tmp_path / "test_doc_example.py"
        f.write_text(code)
        p = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(f)],
                           capture_output=True, text=True, timeout=120, cwd=tmp_path,
                           env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})
        assert p.returncode == 0 and " passed" in p.stdout, f"docs/api.md:{line}\n{p.stdout}{p.stderr}"
        return
    try:
        exec(compile(code, f"docs/api.md:{line}", "exec"), {"__name__": "__doc_example__"})
    except Exception as e:
        pytest.fail(f"docs/api.md:{line}: the example raised {type(e).__name__}: {e}")


def test_the_examples_print_what_the_comments_say(capsys):
    # the first example's comment names the profile and ident the simulator's station 3 reports
    line, code = BLOCKS[0]
    exec(compile(_virtual(code), f"docs/api.md:{line}", "exec"), {})
    out = capsys.readouterr().out
    assert "fuji-opc-g1-pdp 0xFD01" in out
    m = re.search(r"^(-?\d+\.\d) Hz, S4 operation$", out, re.M)
    assert m and abs(float(m.group(1)) - 30.0) <= 0.3, out       # within 1 % of 30 Hz


def test_the_failing_callback_example_stops_both_drives(capsys):
    # the example's comments: the callback's error comes out after the stop, both drives stopped
    [(line, code)] = [(n, c) for n, c in BLOCKS if "the display is gone" in c]
    exec(compile(_virtual(code), f"docs/api.md:{line}", "exec"), {})
    assert capsys.readouterr().out == "the display is gone\nTrue True\n"
