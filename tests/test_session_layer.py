"""The session layer's place (issue 15): profidrive_cli/session/ sits between drives/ and checklist/ +
cli/. From each module's imports (ast): session/ imports nothing of checklist, cli or sim; drives/ and
everything below it import nothing of session/; no module of session/ exceeds 600 lines; the modules
of session/ import each other without a cycle."""

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parent.parent / "profidrive_cli"


def _imports(path: Path) -> list[str]:
    """Every profidrive_cli module named by an import in `path` (also inside functions)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.append(node.module)
            out += [f"{node.module}.{a.name}" for a in node.names]
    return [m for m in out if m.startswith("profidrive_cli")]


def _rel(path: Path) -> str:
    return path.relative_to(PKG.parent).as_posix()


def test_session_imports_nothing_above_it():
    files = sorted((PKG / "session").glob("*.py"))
    assert files, "profidrive_cli/session/ is missing"
    bad = [f"{_rel(f)} imports {m}" for f in files for m in _imports(f)
           if m.split(".")[1:2] in (["checklist"], ["cli"], ["sim"])]
    assert bad == []


def test_nothing_below_imports_session():
    below = ["link", "fdl", "dp", "drives", "gsd"]
    bad = [f"{_rel(f)} imports {m}" for d in below for f in sorted((PKG / d).rglob("*.py"))
           for m in _imports(f) if m.split(".")[1:2] == ["session"]]
    assert bad == []


def test_session_modules_stay_small():
    files = sorted((PKG / "session").glob("*.py")) + [PKG / "drives" / "session.py"]
    big = [f"{_rel(f)}: {n} lines" for f in files if f.is_file()
           if (n := len(f.read_text(encoding="utf-8").splitlines())) > 600]
    assert big == []


def test_no_import_cycle_inside_session():
    mods = {f"profidrive_cli.session.{f.stem}": f for f in (PKG / "session").glob("*.py")
            if f.stem != "__init__"}
    graph = {m: {i for i in _imports(f) if i in mods and i != m} for m, f in mods.items()}
    seen: dict[str, int] = {}            # 1 = on the current path, 2 = done

    def visit(m, path):
        seen[m] = 1
        for n in sorted(graph[m]):
            if seen.get(n) == 1:
                raise AssertionError("import cycle: " + " -> ".join(path + [m, n]))
            if n not in seen:
                visit(n, path + [m])
        seen[m] = 2
    for m in sorted(graph):
        if m not in seen:
            visit(m, [])
    assert len(mods) >= 10               # the package is split by concern, not one module
