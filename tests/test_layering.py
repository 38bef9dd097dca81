"""The house rules, read from the source: which layer may import which, no import cycles (modules are
split by concern, never by a line count: there is no line cap). Every import counts, also those inside functions (a lazy import is still a dependency).

The layer plan -- the one version of it: docs/architecture.md, README.md, the packages' docstrings and
tests/test_session_layer.py point here -- is PLAN below, as data: each layer and the layers it stands
on directly. A layer may import its own modules, the top-level modules (profidrive_cli/__init__,
datafile, outfile, data, config, plot) and every layer below it, following PLAN down:

    link -> fdl -> dp -> gsd -> drives -> session -> api -> checklist, cli
                                  |-> bustools   (beside session) -> monitor
                                  '-> sim        (beside the master stack)

    link       nothing of pdrive: bytes in and out of a port (the sim:// handler is named, not imported)
    fdl        link at most; today nothing. Sans-IO frames and bus timing: bytes and times in, bytes and
               deadlines out.
    dp         fdl, link (the poller waits on the link's clock and raises its LinkLost; doctor.py
               sends its FDL probes through a port)
    gsd        dp and below (dp.cfg decodes the module identifiers)
    drives     gsd and below
    session    drives and below: one drive station (profidrive_cli/session/)
    bustools   drives and below, beside session: the bus-level tools without a drive session (listen,
               passive decoding, the live lists, Wireshark); never session, api, checklist, cli, sim
    monitor    bustools and below: `pdrive monitor` (profidrive_cli/monitor/), the listener left on a line
               with its history, web page and exporters; never session, api, checklist, cli, sim
    sim        drives and below, beside the master stack: the slave side (the drive models reuse the
               codecs; sim:// is registered from here) and the built-in PLC of `sim --plc`; never
               session, api, checklist, cli, bustools
    api        session, bustools and below (profidrive_cli/api/: the Python API, the front door)
    checklist  api, sim and below (the dry run drives the simulated models)
    cli        everything (checklist included) but aio; profidrive_cli/__main__ counts as cli
    aio        api and below: the asyncio face of the API (a worker thread per bus on the sync API)
    top-level  (__init__, datafile, outfile, data, config, plot) nothing of any layer -- with one
               exception: profidrive_cli/__init__ may import profidrive_cli.api inside its PEP 562
               module __getattr__ (the lazy `pdrive.open_bus`), and nowhere else; `import
               profidrive_cli` alone then loads no layer (pdrive --version stays light)

Each failure names file:line and the import.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

from profidrive_cli.drives.registry import FAMILIES


ROOT = Path(__file__).resolve().parent.parent
PKG = ROOT / "profidrive_cli"

#: THE layer plan: layer -> the layers it stands on directly (see the module doc)
PLAN: dict[str, tuple[str, ...]] = {
    "link": (),
    "fdl": ("link",),
    "dp": ("fdl",),
    "gsd": ("dp",),
    "drives": ("gsd",),
    "session": ("drives",),
    "bustools": ("drives",),            # beside session
    "sim": ("drives",),                 # beside the master stack
    "monitor": ("bustools",),           # the line monitored (issue 37), beside session and api
    "api": ("session", "bustools"),
    "checklist": ("api", "sim"),
    "cli": ("checklist", "monitor"),
    "aio": ("api",),                    # the asyncio face of the API, beside the CLI (issue 29)
}
TOP = "top"
TOP_MODULES = {"profidrive_cli", "profidrive_cli.datafile", "profidrive_cli.datacache", "profidrive_cli.outfile",
               "profidrive_cli.data",
               "profidrive_cli.config", "profidrive_cli.plot", "profidrive_cli.httprules"}


def _below(layer: str) -> set[str]:
    """Every layer `layer` stands on, directly or through another (PLAN followed down)."""
    out: set[str] = set()
    todo = list(PLAN[layer])
    while todo:
        low = todo.pop()
        if low not in out:
            out.add(low)
            todo += PLAN[low]
    return out


#: layer -> the layers it may import (its own and the top-level modules always)
ALLOWED = {layer: _below(layer) | {layer, TOP} for layer in PLAN}
ALLOWED[TOP] = {TOP}



def _modules() -> dict[str, Path]:
    mods = {}
    for f in sorted(PKG.rglob("*.py")):
        parts = f.relative_to(ROOT).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = f
    return mods


MODULES = _modules()


def layer_of(module: str) -> str:
    parts = module.split(".")
    if module in TOP_MODULES:
        return TOP
    if module == "profidrive_cli.__main__":
        return "cli"
    if len(parts) >= 2 and parts[1] in PLAN:
        return parts[1]
    raise AssertionError(f"{module}: in no layer; add it to PLAN or TOP_MODULES in tests/test_layering.py")


def _resolve(name: str) -> str | None:
    """The pdrive module an imported name loads (the longest existing prefix), or None."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def imports_of(module: str, path: Path) -> list[tuple[int, str, str]]:
    """(line, target module, import text) for every pdrive import in the file, at any depth."""
    is_pkg = path.name == "__init__.py"
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "profidrive_cli":
                    out.append((node.lineno, a.name, f"import {a.name}"))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".") if is_pkg else module.split(".")[:-1]
                base = base[:len(base) - (node.level - 1)]
                src = ".".join(base + ([node.module] if node.module else []))
            else:
                src = node.module or ""
            if src.split(".")[0] != "profidrive_cli":
                continue
            text = f"from {'.' * node.level}{node.module or ''} import {', '.join(a.name for a in node.names)}"
            for a in node.names:
                full = f"{src}.{a.name}"
                out.append((node.lineno, full if full in MODULES else src, text))
    result = []
    for line, target, text in out:
        mod = _resolve(target)
        if mod is not None and mod != module and (line, mod, text) not in result:
            result.append((line, mod, text))
    return result


def lazy_api_lines(path: Path) -> set[int]:
    """Lines of the imports inside the module-level `def __getattr__` of a file (PEP 562)."""
    lines: set[int] = set()
    for node in ast.parse(path.read_text(encoding="utf-8"), str(path)).body:
        if isinstance(node, ast.FunctionDef) and node.name == "__getattr__":
            lines |= {n.lineno for n in ast.walk(node) if isinstance(n, (ast.Import, ast.ImportFrom))}
    return lines


#: the one allowed way up: profidrive_cli/__init__ imports the api layer in its module __getattr__
LAZY_LINES = lazy_api_lines(PKG / "__init__.py")


def _is_lazy_api_edge(module: str, line: int, target: str) -> bool:
    return module == "profidrive_cli" and line in LAZY_LINES and layer_of(target) == "api"


ALL_EDGES = {m: imports_of(m, p) for m, p in MODULES.items()}
#: the import graph the rules are checked on: every import but the lazy api export (which runs
#: only when pdrive.open_bus & co. are first used, long after the package is loaded)
GRAPH = {m: [e for e in edges if not _is_lazy_api_edge(m, e[0], e[1])] for m, edges in ALL_EDGES.items()}


def _where(path: Path, line: int) -> str:
    return f"{path.relative_to(ROOT)}:{line}"


def test_every_module_is_in_a_layer_and_the_rules_cover_the_package():
    assert {"profidrive_cli.fdl.frames", "profidrive_cli.link.base", "profidrive_cli.dp.poller",
            "profidrive_cli.gsd.parser", "profidrive_cli.cli.main"} <= set(MODULES)
    assert sum(len(v) for v in GRAPH.values()) > 100        # the parser sees the imports at all
    for m in MODULES:
        layer_of(m)


def test_every_package_is_a_layer_of_the_plan():
    # each sub-package of profidrive_cli is one layer of PLAN, and PLAN names no layer that is not
    # there: the plan is the package as built
    packages = {d.name for d in PKG.iterdir() if (d / "__init__.py").is_file()}
    assert packages == set(PLAN)
    for layer, lower in PLAN.items():
        assert set(lower) <= set(PLAN), layer


def test_the_plan_is_one_order():
    # no layer stands on itself through others (a cycle in the plan would allow any import)
    assert all(layer not in _below(layer) for layer in PLAN)


def test_the_plan_is_the_documented_one():
    # the plan drawn at the top of docs/architecture.md (issue 25):
    #   link -> fdl -> dp -> gsd -> drives -> session -> api -> checklist, cli;
    #   bustools beside session (link/fdl/dp/gsd/drives, not session/api/cli); sim beside the master stack
    chain = ["link", "fdl", "dp", "gsd", "drives", "session", "api", "checklist", "cli"]
    for i, layer in enumerate(chain):
        assert ALLOWED[layer] & set(chain) == set(chain[:i + 1]), layer
    stack = {"link", "fdl", "dp", "gsd", "drives"}
    assert ALLOWED["bustools"] == stack | {"bustools", TOP}
    assert ALLOWED["sim"] == stack | {"sim", TOP}
    assert not {"bustools", "sim"} & ALLOWED["session"]         # beside: neither way
    assert "session" not in ALLOWED["bustools"] and "session" not in ALLOWED["sim"]
    assert "sim" not in ALLOWED["api"] and "sim" not in ALLOWED["bustools"]
    assert {"bustools", "sim", "api", "session"} <= ALLOWED["checklist"]
    # the CLI stands on everything but the asyncio face, which stands on the API only (issue 29)
    assert ALLOWED["cli"] == set(PLAN) - {"aio"} | {TOP}
    assert ALLOWED["aio"] == ALLOWED["api"] | {"aio"}
    assert ALLOWED[TOP] == {TOP}


def _against_the_plan(graph: dict[str, list[tuple[int, str, str]]]) -> list[str]:
    """One line per import of `graph` that PLAN does not allow: file:line (or module:line), the import
    and the two layers."""
    bad = []
    for m, edges in graph.items():
        src = layer_of(m)
        for line, target, text in edges:
            dst = layer_of(target)
            if dst not in ALLOWED[src]:
                where = _where(MODULES[m], line) if m in MODULES else f"{m}:{line}"
                bad.append(f"{where}: {text} ({src} must not import {dst})")
    return bad


def test_the_check_finds_an_import_against_the_plan():
    # made-up imports: a bus tool reaching into session/, the sim into the api, session into the sim
    # and the api into the checklist are refused, each with its place; the same layers' allowed ways
    # (cli -> bustools, checklist -> sim, bustools -> dp) pass
    graph = {
        "profidrive_cli.bustools.x": [(3, "profidrive_cli.session.signals", "import s"),
                                      (4, "profidrive_cli.dp.poller", "import p")],
        "profidrive_cli.sim.x": [(5, "profidrive_cli.api.bus", "import b")],
        "profidrive_cli.session.x": [(6, "profidrive_cli.sim.plant", "import q")],
        "profidrive_cli.api.x": [(7, "profidrive_cli.checklist.spec", "import c")],
        "profidrive_cli.checklist.x": [(8, "profidrive_cli.sim.direct", "import d")],
        "profidrive_cli.cli.x": [(9, "profidrive_cli.bustools.passive", "import e")],
    }
    assert _against_the_plan(graph) == [
        "profidrive_cli.bustools.x:3: import s (bustools must not import session)",
        "profidrive_cli.sim.x:5: import b (sim must not import api)",
        "profidrive_cli.session.x:6: import q (session must not import sim)",
        "profidrive_cli.api.x:7: import c (api must not import checklist)",
    ]


def test_imports_follow_the_layer_order():
    bad = _against_the_plan(GRAPH)
    assert not bad, "imports against the layer order:\n" + "\n".join(bad)


def _cycles(graph: dict[str, list[tuple[int, str, str]]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []
    counter = 0
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted({t for _, t, _ in graph[root]})))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted({t for _, t, _ in graph[w]}))))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        found.append(sorted(comp))
    return found


def test_cycle_finder_finds_a_cycle():
    # the finder itself, on graphs made up here: a -> b -> c -> a is one cycle, d (reached from c)
    # none; e <-> f a second one
    graph = {"a": [(1, "b", "")], "b": [(1, "c", "")], "c": [(1, "a", ""), (2, "d", "")], "d": []}
    assert _cycles(graph) == [["a", "b", "c"]]
    graph.update({"d": [(1, "e", "")], "e": [(1, "f", "")], "f": [(1, "e", "")]})
    assert sorted(_cycles(graph)) == [["a", "b", "c"], ["e", "f"]]
    assert _cycles({"a": [(1, "b", "")], "b": []}) == []


def test_no_import_cycles_between_modules():
    bad = []
    for comp in _cycles(GRAPH):
        members = set(comp)
        edges = [f"  {_where(MODULES[m], line)}: {text}"
                 for m in comp for line, t, text in GRAPH[m] if t in members]
        bad.append("cycle " + " <-> ".join(comp) + ":\n" + "\n".join(edges))
    assert not bad, "import cycles:\n" + "\n".join(bad)


def test_the_package_imports_the_api_only_lazily():
    # the exception for __init__ is exactly the api layer, exactly in __getattr__: every other
    # import of __init__ (there is none today) follows the top-level rule
    lazy = [e for e in ALL_EDGES["profidrive_cli"] if _is_lazy_api_edge("profidrive_cli", e[0], e[1])]
    assert lazy, "profidrive_cli/__init__.py: the lazy api export (__getattr__) is gone"
    code = ("import sys, profidrive_cli\n"
            "print('LOADED', sorted(m for m in sys.modules if m.startswith('profidrive_cli.')))\n"
            "f = profidrive_cli.open_bus\n"
            "print('API', 'profidrive_cli.api' in sys.modules, f.__module__)\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert "LOADED []" in p.stdout, p.stdout + p.stderr
    assert "API True profidrive_cli.api.bus" in p.stdout, p.stdout + p.stderr


def test_a_lazy_import_elsewhere_is_not_excused(tmp_path):
    # the exception is tied to __init__'s __getattr__: the same import at module level is not
    f = tmp_path / "x.py"
    f.write_text("import os\nfrom profidrive_cli.api import open_bus\n"
                 "def __getattr__(name):\n    from profidrive_cli.api import Bus\n    return Bus\n")
    assert lazy_api_lines(f) == {4}
    assert not _is_lazy_api_edge("profidrive_cli.datafile", 4, "profidrive_cli.api")


def test_importing_link_loads_nothing_of_sim_and_sim_urls_still_open():
    # sim:// is registered by name (pyserial's protocol_handler_packages): the handler lives in sim/
    # and is imported only when a sim:// URL is opened
    code = ("import sys\n"
            "import profidrive_cli.link, profidrive_cli.link.serial_link, profidrive_cli.dp.doctor\n"
            "print('BEFORE', sorted(m for m in sys.modules if m.startswith('profidrive_cli.sim')))\n"
            "from profidrive_cli.link import open_link\n"
            "link = open_link('sim://')\n"
            "print('HANDLER', type(link.ser).__module__)\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert "BEFORE []" in p.stdout, p.stdout + p.stderr
    assert "HANDLER profidrive_cli.sim.protocol_sim" in p.stdout, p.stdout + p.stderr


# -- issue 25 step 7: the API is the front door ------------------------------------------------------

#: the CLI's drive commands and their rendering: they get their drives through the API (an api.Bus from
#: cli/common.py BusOptions.open_bus; Bus.drive, Bus.session), so they import nothing of fdl / link / dp
#: and build no DriveStation and no Master themselves. Bus-level commands (scan, sniff, bus_cmds, doctor,
#: wireshark, sim, decode) and cli/common.py (the port, --trace, --baud auto) may keep the lower imports.
DRIVE_COMMANDS = ("drive_cmds", "commloss_cmd", "checklist_cmd", "config_cmd", "render_drive",
                  "audit_cmd", "render_multi", "run_plot", "run_torque", "jsonout", "names", "run_cmd", "jog_cmd",
                  "run_multi", "fleet_cmd")
LOWER = ("fdl", "link", "dp")
BUILT_BELOW = ("DriveStation", "Master")


def _constructions(path: Path, names: tuple[str, ...]) -> list[tuple[int, str]]:
    """(line, name) of every call `Name(...)` or `x.Name(...)` of one of `names` in the file."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Call):
            f = node.func
            name = f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else None
            if name in names:
                out.append((node.lineno, name))
    return out


def test_the_cli_drive_commands_stand_on_the_api():
    bad = []
    for name in DRIVE_COMMANDS:
        m = f"profidrive_cli.cli.{name}"
        assert m in MODULES, f"{m}: listed in DRIVE_COMMANDS but not in the package"
        for line, target, text in ALL_EDGES[m]:
            if layer_of(target) in LOWER:
                bad.append(f"{_where(MODULES[m], line)}: {text} (a drive command reaches its drives "
                           f"through profidrive_cli.api)")
        for line, what in _constructions(MODULES[m], BUILT_BELOW):
            bad.append(f"{_where(MODULES[m], line)}: builds a {what} (use api.Bus: BusOptions.open_bus, "
                       f"Bus.drive or Bus.session)")
    assert not bad, "drive commands below the API:\n" + "\n".join(bad)


def test_the_checklist_stands_on_the_sessions_the_front_door_opens():
    # every station handle has its session (api.Bus.session in pdrive): no `session is None` branch,
    # no getattr(h, "session", None), and no DriveStation or Master built in checklist/
    bad = []
    for m, path in MODULES.items():
        if layer_of(m) != "checklist":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.Compare) and any(isinstance(op, (ast.Is, ast.IsNot)) for op in node.ops):
                sides = [node.left, *node.comparators]
                names = [s.attr if isinstance(s, ast.Attribute) else s.id if isinstance(s, ast.Name) else None
                         for s in sides]
                if "session" in names and any(isinstance(s, ast.Constant) and s.value is None for s in sides):
                    bad.append(f"{_where(path, node.lineno)}: a branch on a missing session")
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "getattr"
                    and len(node.args) >= 2 and isinstance(node.args[1], ast.Constant)
                    and node.args[1].value == "session"):
                bad.append(f"{_where(path, node.lineno)}: getattr(..., 'session'): the handle always has one")
        for line, what in _constructions(path, BUILT_BELOW):
            bad.append(f"{_where(path, line)}: builds a {what} (the opener's bus does: Bus.session)")
    assert not bad, "the checklist beside the front door:\n" + "\n".join(bad)


#: the one door (issue 36): these layers reach the station layer only through profidrive_cli.api
ONE_DOOR = ("cli", "checklist", "aio")


def test_the_cli_the_checklist_and_aio_pass_through_the_one_door():
    bad = []
    for m, path in MODULES.items():
        if m == "profidrive_cli.__main__" or layer_of(m) not in ONE_DOOR:
            continue
        for line, target, text in ALL_EDGES[m]:
            if layer_of(target) == "session":
                bad.append(f"{_where(path, line)}: {text} (the station level is "
                           f"profidrive_cli.api.station)")
    assert not bad, "past the one door:\n" + "\n".join(bad)


def test_the_one_door_check_finds_a_session_import(tmp_path):
    f = tmp_path / "cmd.py"
    f.write_text("def f():\n    from profidrive_cli.session.live import Reach\n", encoding="utf-8")
    found = [t for _, t, _ in imports_of("profidrive_cli.cli.cmd", f)]
    assert "profidrive_cli.session.live" in found and layer_of(found[0]) == "session"

# -- "One station, one door": families only in drives/ -----------------------------------------------

#: the family packages: each row's codec in drives/registry.py FAMILIES (a package, or a module such as
#: drives/moeller.py with its siblings moeller_*.py) and the PROFIdrive core the families build on
FAMILY_PACKAGES: dict[str, str] = {name: row.codec for name, row in FAMILIES.items()}
FAMILY_PACKAGES.setdefault("profidrive", "profidrive_cli.drives.profidrive")
CORE = FAMILY_PACKAGES["profidrive"]
#: the one way in from outside drives/: a family's own simulator model (its registry row's sim_model)
#: may import its family and the core; the core's model (sim/profidrive_model.py) and its PKW server
#: mixin (sim/pkw_server.py) the core
SIM_MODELS: dict[str, set[str]] = {row.sim_model.partition(":")[0]: {row.codec, CORE}
                                   for row in FAMILIES.values() if row.sim_model is not None}
SIM_MODELS.update({"profidrive_cli.sim.profidrive_model": {CORE}, "profidrive_cli.sim.pkw_server": {CORE}})


def family_of_module(module: str) -> str | None:
    """The family whose package (or module family's siblings) `module` is part of, or None."""
    for name, pkg in FAMILY_PACKAGES.items():
        if module == pkg or module.startswith((pkg + ".", pkg + "_")):
            return name
    return None


def _family_imports_outside_drives(graph: dict[str, list[tuple[int, str, str]]]) -> list[str]:
    """One line per import, by a module outside profidrive_cli/drives/, of a family package (other than
    a sim model's own): file:line (or module:line), the import and the family."""
    bad = []
    for m, edges in graph.items():
        if m == "profidrive_cli.drives" or m.startswith("profidrive_cli.drives."):
            continue
        allowed = SIM_MODELS.get(m, set())
        for line, target, text in edges:
            fam = family_of_module(target)
            if fam is None or FAMILY_PACKAGES[fam] in allowed:
                continue
            where = _where(MODULES[m], line) if m in MODULES else f"{m}:{line}"
            bad.append(f"{where}: {text} (family {fam} outside drives/: ask drive_class(profile) or a "
                       f"Drive hook)")
    return bad


def test_the_family_packages_are_the_registrys():
    assert {"fuji", "moeller", "profidrive", "toyo", "yaskawa"} <= set(FAMILY_PACKAGES)
    assert all(p in MODULES for p in FAMILY_PACKAGES.values())
    assert family_of_module("profidrive_cli.drives.moeller_audit") == "moeller"
    assert family_of_module("profidrive_cli.drives.yaskawa.codec") == "yaskawa"
    assert family_of_module("profidrive_cli.drives.profile") is None
    assert family_of_module("profidrive_cli.drives") is None
    assert set(SIM_MODELS) == {"profidrive_cli.sim.fuji", "profidrive_cli.sim.moeller", "profidrive_cli.sim.toyo",
                               "profidrive_cli.sim.yaskawa", "profidrive_cli.sim.dpv1_axis",
                               "profidrive_cli.sim.profidrive_model", "profidrive_cli.sim.pkw_server"}
    assert all(m in MODULES for m in SIM_MODELS)


def test_the_family_check_finds_every_import_form(tmp_path):
    # made up: a bus tool importing families absolutely, as a package attribute, relatively and inside a
    # function is refused at each line; drives' own names (drive_class, base, registry) pass, and so
    # do a sim model's imports of its family and the core -- not of another family
    f = tmp_path / "x.py"
    f.write_text("from profidrive_cli.drives import yaskawa\n"
                 "import profidrive_cli.drives.toyo.codec\n"
                 "from ..drives.fuji import codes\n"
                 "def f():\n    from profidrive_cli.drives.profidrive.pkw import PkwFrame\n"
                 "from profidrive_cli.drives import moeller as mo, drive_class\n"
                 "from ..drives import base, registry\n"
                 "from profidrive_cli.drives.moeller_audit import audit_rules\n")
    graph = {"profidrive_cli.bustools.x": imports_of("profidrive_cli.bustools.x", f),
             "profidrive_cli.sim.fuji": [(1, "profidrive_cli.drives.fuji.config", "import a"),
                                         (2, "profidrive_cli.drives.profidrive", "import b"),
                                         (3, "profidrive_cli.drives.toyo", "import c")],
             "profidrive_cli.drives.x": [(4, "profidrive_cli.drives.yaskawa.codec", "import d")]}
    why = "outside drives/: ask drive_class(profile) or a Drive hook)"
    assert sorted(_family_imports_outside_drives(graph)) == sorted([
        f"profidrive_cli.bustools.x:1: from profidrive_cli.drives import yaskawa (family yaskawa {why}",
        f"profidrive_cli.bustools.x:2: import profidrive_cli.drives.toyo.codec (family toyo {why}",
        f"profidrive_cli.bustools.x:3: from ..drives.fuji import codes (family fuji {why}",
        f"profidrive_cli.bustools.x:5: from profidrive_cli.drives.profidrive.pkw import PkwFrame "
        f"(family profidrive {why}",
        f"profidrive_cli.bustools.x:6: from profidrive_cli.drives import moeller, drive_class "
        f"(family moeller {why}",
        f"profidrive_cli.bustools.x:8: from profidrive_cli.drives.moeller_audit import audit_rules "
        f"(family moeller {why}",
        f"profidrive_cli/sim/fuji.py:3: import c (family toyo {why}",
    ])


def test_no_family_package_is_imported_outside_drives():
    # a family answers through its Drive class (drives.drive_class(profile): the hooks and class facts,
    # normalise_area for sniff --station) and the registry's lazy references; only the simulator
    # models stand on their family's codec
    bad = _family_imports_outside_drives(ALL_EDGES)
    assert not bad, "family packages imported outside drives/:\n" + "\n".join(bad)
