"""The session layer's place (issue 15), on the one layer plan of tests/test_layering.py (PLAN there;
this file keeps the session-specific checks and reads the same plan and the same import graph):
profidrive_cli/session/ sits on drives/ and under api/ + checklist/ + cli/. From each module's imports
(ast, also inside functions): session/ imports nothing of checklist, cli or sim (nor bustools or
api); drives/ and everything below it (and bustools/, sim/ beside it) import nothing of session/; the
modules of session/ import each other without a cycle (split by concern, never by a line count)."""

from pathlib import Path

from test_layering import ALLOWED, GRAPH, MODULES, layer_of

PKG = Path(__file__).resolve().parent.parent / "profidrive_cli"


def _rel(path: Path) -> str:
    return path.relative_to(PKG.parent).as_posix()


def _session_modules() -> dict[str, Path]:
    return {m: p for m, p in MODULES.items() if m != "profidrive_cli.session" and layer_of(m) == "session"}


def test_session_imports_nothing_above_it():
    files = sorted((PKG / "session").glob("*.py"))
    assert files, "profidrive_cli/session/ is missing"
    # the plan: session stands on drives and below; checklist, cli and sim (and api, bustools) are not
    # under it
    assert not {"checklist", "cli", "sim", "api", "bustools"} & ALLOWED["session"]
    bad = [f"{_rel(MODULES[m])}:{line} imports {t}" for m in MODULES if layer_of(m) == "session"
           for line, t, _ in GRAPH[m] if layer_of(t) not in ALLOWED["session"]]
    assert bad == []


def test_nothing_below_imports_session():
    below = ["link", "fdl", "dp", "drives", "gsd"]
    beside = ["bustools", "sim"]
    assert all("session" not in ALLOWED[d] for d in below + beside)
    bad = [f"{_rel(MODULES[m])}:{line} imports {t}" for m in MODULES if layer_of(m) in below + beside
           for line, t, _ in GRAPH[m] if layer_of(t) == "session"]
    assert bad == []


def test_no_import_cycle_inside_session():
    mods = _session_modules()
    graph = {m: {t for _, t, _ in GRAPH[m] if t in mods and t != m} for m in mods}
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
