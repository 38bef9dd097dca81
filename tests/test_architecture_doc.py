"""docs/architecture.md names the modules of each layer; every module it names must exist there
(it once listed dp/diag.py and dp/slave.py, which never did)."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "profidrive_cli"


def named_modules():
    """(folder, module file) for every `name.py` in the module list at the top of the doc. A line
    `    name/  ...` opens a folder at its indentation (a deeper one is a sub-package of the folder
    above it); `name.py` on the lines below it are that folder's modules."""
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    block = text.split("## ", 1)[0]
    stack: list[tuple[int, str]] = []          # (indent, folder name)
    for line in block.splitlines():
        m = re.match(r"( +)(\w+)/(\s|$)", line)
        indent = len(line) - len(line.lstrip(" "))
        if m:
            while stack and stack[-1][0] >= indent:
                stack.pop()
            stack.append((indent, m.group(2)))
        elif line.strip():
            while stack and stack[-1][0] >= indent:
                stack.pop()
        if not stack:
            continue
        folder = "/".join(name for _, name in stack)
        for name in re.findall(r"(?<![\w/.])(\w+\.py)\b", line):
            yield folder, name
        for path in re.findall(r"\b(\w+/\w+\.py)\b", line):     # written with its folder: link/x.py
            yield path.split("/")[0], path.split("/")[1]


def test_every_module_the_architecture_doc_names_exists():
    pairs = set(named_modules())
    assert len(pairs) >= 15                      # the parser found the list at all
    missing = sorted(f"{d}/{f}" for d, f in pairs
                     if not (PKG / d / f).is_file() and not (ROOT / d / f).is_file())
    assert missing == []
