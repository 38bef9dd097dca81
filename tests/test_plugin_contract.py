"""The plug-in interface under the version promise (drives/plugin.py PLUGIN_INTERFACE; docs/plugins.md,
"The plug-in interface (promised)"; docs/versioning.md):

(a) every promised name exists on its owner (Family, the codec, Drive, CyclicChannel, the result
    types, SlaveModel) with the documented signature, so renaming one, or one of its parameters,
    fails here; Drive's abstract methods are exactly the "must" ones;
(b) the doc's table lists exactly the promised names, each with its signature and need;
(c) the demo plug-in (tests/data/plugin_demo, installed by tests/test_plugins.py) builds on promised
    names only and runs end to end on them (in this process, its Family row given to the registry).
"""

from __future__ import annotations

import ast
import dataclasses
import importlib
import inspect
import re
import sys
from pathlib import Path
from types import ModuleType, SimpleNamespace
from typing import Any

import pytest

from profidrive_cli.drives.base import Drive
from profidrive_cli.drives.plugin import BUILDING_BLOCKS, OWNERS, PENDING, PLUGIN_INTERFACE, promised
from profidrive_cli.drives.registry import FAMILIES, resolve
from profidrive_cli.sim.model import SlaveModel

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "plugins.md"
DEMO = ROOT / "tests" / "data" / "plugin_demo"
SECTION = "## The plug-in interface (promised)"

BY_NAME = {p.name: p for p in PLUGIN_INTERFACE}


# -- rendering a name as the doc writes its signature -----------------------------------------------

def _ann(a: object) -> str:
    return a if isinstance(a, str) else inspect.formatannotation(a)


def _sig(sig: inspect.Signature, returns: bool = True) -> str:
    parts: list[str] = []
    star = False
    for p in sig.parameters.values():
        s = p.name
        if p.kind is p.VAR_POSITIONAL:
            s, star = "*" + s, True
        elif p.kind is p.VAR_KEYWORD:
            s = "**" + s
        elif p.kind is p.KEYWORD_ONLY and not star:
            parts.append("*")
            star = True
        if p.annotation is not p.empty:
            s += f": {_ann(p.annotation)}"
        if p.default is not p.empty:
            s += f" = {p.default!r}"
        parts.append(s)
    out = f"({', '.join(parts)})"
    if returns and sig.return_annotation is not sig.empty:
        out += f" -> {_ann(sig.return_annotation)}"
    return out


def _annotation(cls: type, attr: str) -> str | None:
    for c in cls.__mro__:
        ann = inspect.get_annotations(c)
        if attr in ann:
            return _ann(ann[attr])
    return None


def owner(name: str) -> Any:
    return resolve(OWNERS[name.partition(".")[0]])


def render(name: str) -> str:
    """The signature of a promised name as the code has it, written the way PLUGIN_INTERFACE does."""
    head, _, attr = name.partition(".")
    obj = owner(name)
    if not attr:
        if issubclass(obj, BaseException):
            return f"class {obj.__name__}({obj.__bases__[0].__name__})"
        return _sig(inspect.signature(obj), returns=False)           # a dataclass: its constructor
    if dataclasses.is_dataclass(obj):
        fields = {f.name: f for f in dataclasses.fields(obj)}
        if attr in fields:
            f = fields[attr]
            default = "" if f.default is dataclasses.MISSING else f" = {f.default!r}"
            return f": {_ann(f.type)}{default}"
    if isinstance(obj, ModuleType):
        return _sig(inspect.signature(getattr(obj, attr)))
    try:
        raw = inspect.getattr_static(obj, attr)
    except AttributeError:                                          # annotated, set by __init__
        ann = _annotation(obj, attr)
        if ann is None:
            raise
        return f": {ann}"
    if isinstance(raw, classmethod):
        return _sig(inspect.signature(raw.__func__))
    if isinstance(raw, property):
        return f"@property -> {_ann(inspect.signature(raw.fget).return_annotation)}"
    if inspect.isfunction(raw):
        return _sig(inspect.signature(raw), returns=attr != "__init__" or
                    inspect.signature(raw).return_annotation not in ("None", None))
    return f": {_annotation(obj, attr)} = {raw!r}"


def documented_params(signature: str) -> list[str]:
    """The parameter names of a documented callable signature ('(self, timeout: float = 5.0) -> X')."""
    code = "def f" + signature.replace("<factory>", "None") + ": ..."
    fn = ast.parse(code).body[0]
    assert isinstance(fn, ast.FunctionDef)
    a = fn.args
    names = [x.arg for x in (*a.posonlyargs, *a.args)]
    names += ["*" + a.vararg.arg] if a.vararg else []
    names += [x.arg for x in a.kwonlyargs]
    names += ["**" + a.kwarg.arg] if a.kwarg else []
    return names


def actual_params(name: str) -> list[str]:
    head, _, attr = name.partition(".")
    obj = owner(name)
    raw = inspect.getattr_static(obj, attr) if attr else obj
    fn = raw.__func__ if isinstance(raw, classmethod) else raw
    out = []
    for p in inspect.signature(fn).parameters.values():
        out.append({p.VAR_POSITIONAL: "*", p.VAR_KEYWORD: "**"}.get(p.kind, "") + p.name)
    return out


# -- (a) the names and their signatures ---------------------------------------------------------------

CHECKED = [p for p in PLUGIN_INTERFACE if not p.name.startswith("codec.")]


@pytest.mark.parametrize("p", CHECKED, ids=[p.name for p in CHECKED])
def test_every_promised_name_exists_with_its_documented_signature(p):
    head, _, attr = p.name.partition(".")
    obj = owner(p.name)
    if attr and not hasattr(obj, attr) and _annotation(obj, attr) is None:
        if p.name in PENDING:
            pytest.skip(f"{p.name}: promised, its code arrives with another branch (PENDING)")
        pytest.fail(f"{p.name} is promised (drives/plugin.py, docs/plugins.md) but {head} has no {attr!r}")
    if p.signature.startswith("("):
        assert actual_params(p.name) == documented_params(p.signature), \
            f"{p.name}: the parameter names changed; they are promised (docs/plugins.md)"
    assert render(p.name) == p.signature, f"{p.name}: its signature changed; it is promised"


def test_the_codec_functions_take_the_documented_parameters_in_every_shipped_codec():
    """registry.make_drive / decode_area call the codec's functions positionally with these
    parameters; a codec may add keyword parameters with defaults (the core's decode_area: max_hz)."""
    codecs = {name: resolve(f.codec) for name, f in FAMILIES.items()}
    codecs["core"] = resolve(OWNERS["codec"])
    for fn_name, p in promised("codec").items():
        want = documented_params(p.signature)
        for fam, mod in codecs.items():
            params = list(inspect.signature(getattr(mod, fn_name)).parameters.values())
            assert [q.name for q in params[:len(want)]] == want, f"{fam}: {fn_name}"
            assert all(q.default is not q.empty for q in params[len(want):]), f"{fam}: {fn_name}"


def test_drives_abstract_methods_are_exactly_the_must_names():
    assert set(Drive.__abstractmethods__) == set(promised("Drive", "must"))


def test_every_may_name_has_a_default_in_the_base():
    for cls_name, cls in (("Drive", Drive), ("SlaveModel", SlaveModel)):
        for attr, p in promised(cls_name, "may").items():
            if p.name in PENDING and not hasattr(cls, attr):
                continue
            assert attr in vars(cls), p.name
            assert not getattr(getattr(cls, attr), "__isabstractmethod__", False), p.name


class _Channel:
    def exchange(self, outputs: bytes) -> bytes:
        return bytes(4)

    def now(self) -> float:
        return 0.0


def test_a_drive_implementing_only_the_must_names_is_a_drive_with_what_pdrive_provides():
    must = promised("Drive", "must")
    body = {attr: (lambda self, *a, **k: None) for attr in must}
    Minimal = type("Minimal", (Drive,), body)
    ch = _Channel()
    d = Minimal(ch, SimpleNamespace(default_layout="ppo1"))
    assert (d.channel, d.layout) == (ch, "ppo1") and d.profile.default_layout == "ppo1"
    for attr in promised("Drive", "may"):
        if f"Drive.{attr}" not in PENDING:
            assert hasattr(d, attr)
    m = SlaveModel(0x1234, {"ppo1": b"\xf3\xf1"})
    for attr in promised("SlaveModel", "pdrive"):
        assert hasattr(m, attr), attr
    assert m.check_cfg(b"\xf3\xf1") and (m.layout, m.input_len, m.output_len) == ("ppo1", 12, 12)   # PKW 4 words + PZD 2 words


def test_the_building_blocks_are_there_and_fill_what_they_say():
    from profidrive_cli.drives.profidrive.drive import ProfidriveDrive
    from profidrive_cli.sim.profidrive_model import ProfidriveModel
    for ref, fills in BUILDING_BLOCKS.items():
        obj = resolve(ref)
        assert callable(obj), ref
        assert fills in BY_NAME, ref
    assert issubclass(ProfidriveDrive, Drive) and not ProfidriveDrive.__abstractmethods__
    assert issubclass(ProfidriveModel, SlaveModel)


# -- (b) the doc's table --------------------------------------------------------------------------------

def doc_rows() -> list[list[str]]:
    """The table rows of the doc's section whose first cell is a `name` (the cells unescaped)."""
    text = DOC.read_text(encoding="utf-8")
    assert SECTION in text, f"docs/plugins.md has no section {SECTION!r}"
    section = text.split(SECTION, 1)[1].split("\n## ", 1)[0]
    rows = []
    for line in section.splitlines():
        if not line.startswith("| `"):
            continue
        cells = [c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", line)[1:-1]]
        rows.append(cells)
    return rows


def _code(cell: str) -> str:
    m = re.fullmatch(r"`([^`]+)`", cell)
    assert m, f"not one `code` span: {cell!r}"
    return m.group(1)


def test_the_doc_table_lists_exactly_the_promised_names():
    rows = doc_rows()
    names = [_code(r[0]) for r in rows]
    assert len(names) == len(set(names)), "a name twice in the doc's table"
    assert set(names) == set(BY_NAME), (f"in the doc only: {sorted(set(names) - set(BY_NAME))}; "
                                        f"promised but not in the doc: {sorted(set(BY_NAME) - set(names))}")
    for r in rows:
        p = BY_NAME[_code(r[0])]
        assert len(r) == 4, r
        assert _code(r[1]) == p.signature, f"{p.name}: the doc's signature differs from PLUGIN_INTERFACE"
        assert r[2] == p.need, f"{p.name}: the doc says {r[2]!r}, PLUGIN_INTERFACE {p.need!r}"
        assert ("Pending" in r[3]) == (p.name in PENDING), f"{p.name}: mark it Pending exactly when PENDING"


def test_the_doc_names_the_building_blocks_and_the_owners_import_paths():
    section = DOC.read_text(encoding="utf-8").split(SECTION, 1)[1].split("\n## ", 1)[0]
    for ref in (*BUILDING_BLOCKS, *(v for k, v in OWNERS.items() if k != "codec")):
        assert f"`{ref}`" in section, ref


# -- (c) the demo plug-in is the contract ----------------------------------------------------------------

def _demo_imports() -> list[tuple[str, str]]:
    """(module, name) of every `from profidrive_cli... import name` in the demo's family modules (its
    port kind, protocol_demosim.py, builds on pyserial's SerialBase: not this interface)."""
    out = []
    for f in ("__init__.py", "codec.py", "sim.py"):
        tree = ast.parse((DEMO / "pdrive_demo" / f).read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("profidrive_cli"):
                out += [(node.module or "", a.name) for a in node.names]
            elif isinstance(node, ast.Import):
                assert not any(a.name.startswith("profidrive_cli") for a in node.names), f
    return out


@pytest.fixture
def demo(monkeypatch):
    """The demo plug-in importable and its Family row given to the registry as an entry point would."""
    from profidrive_cli.drives import registry
    from profidrive_cli.drives.profile import clear_cache
    monkeypatch.syspath_prepend(str(DEMO))
    pkg = importlib.import_module("pdrive_demo")
    row = pkg.family()
    registry.reset_plugins()
    clear_cache()
    monkeypatch.setattr(registry, "_plugins", {row.name: row})
    yield row
    clear_cache()
    for mod in [m for m in sys.modules if m == "pdrive_demo" or m.startswith("pdrive_demo.")]:
        del sys.modules[mod]


def test_the_demo_imports_only_promised_names_of_pdrive(demo):
    allowed = {tuple(v.split(":")) for v in OWNERS.values() if ":" in v}
    allowed |= {(ref.split(":")[0], ref.split(":")[1].split(".")[0]) for ref in BUILDING_BLOCKS}
    imports = _demo_imports()
    assert imports
    for mod, name in imports:
        assert (mod, name) in allowed, f"the demo imports {mod}.{name}: not promised"
    for f in dataclasses.fields(demo):
        v = getattr(demo, f.name)
        if isinstance(v, str) and v.startswith("profidrive_cli"):
            assert v in BUILDING_BLOCKS, f"Family.{f.name} = {v!r}: not a promised building block"


def _plugin_classes(cls: type) -> list[type]:
    return [c for c in cls.__mro__ if not c.__module__.startswith(("profidrive_cli", "builtins", "abc"))]


ALLOWED_DUNDERS = {"__module__", "__qualname__", "__doc__", "__dict__", "__weakref__", "__init__",
                   "__abstractmethods__", "_abc_impl", "__annotations__", "__firstlineno__",
                   "__static_attributes__", "__parameters__", "__orig_bases__"}


def test_the_demo_overrides_only_promised_names(demo):
    codec = resolve(demo.codec)
    drive_cls = resolve(demo.drive_class)
    assert issubclass(drive_cls, Drive)
    for fn_name, p in promised("codec").items():
        params = [q.name for q in inspect.signature(getattr(codec, fn_name)).parameters.values()]
        assert params[:len(documented_params(p.signature))] == documented_params(p.signature)
    may_or_must = {a for a, p in promised("Drive").items() if p.need != "pdrive"}
    own = _plugin_classes(drive_cls)
    assert own, "the demo's Drive class is its own"
    for c in own:
        extra = set(vars(c)) - may_or_must - ALLOWED_DUNDERS
        assert not extra, f"{c.__name__} overrides {sorted(extra)}: not promised"
    from profidrive_cli.drives.profile import load_profile
    model = resolve(demo.sim_model)(load_profile("demo"))
    assert isinstance(model, SlaveModel)
    model_names = {a for a, p in promised("SlaveModel").items() if p.need != "pdrive"}
    for c in _plugin_classes(type(model)):
        extra = set(vars(c)) - model_names - ALLOWED_DUNDERS
        assert not extra, f"{c.__name__} overrides {sorted(extra)}: not promised"


@pytest.mark.usefixtures("no_config_at_all")
def test_the_demo_runs_end_to_end_on_the_promise(demo):
    import profidrive_cli as pdrive
    from profidrive_cli.drives import registry
    from profidrive_cli.drives.profile import load_profile
    prof = load_profile("demo")
    assert prof.family == "demo" and registry.family_of(prof) is demo
    # the codec: a PPO1 request, CTW 0x047F and 50 % of 50 Hz (as tests/test_plugins.py decodes it)
    area = registry.decode_area(prof, "ppo1", "request", bytes(8) + bytes([0x04, 0x7F, 0x20, 0x00]))
    assert area
    with pdrive.open_bus("sim://?timing=virtual&stations=9:demo") as bus:
        (st,) = bus.scan()
        assert (st.station, st.ident, st.profile) == (9, 0xDE01, "demo-card")
        d = bus.drive(9)
        assert not d.status().running
        assert d.param("FMAX").value == pytest.approx(50.0)
        s = d.run(hz=10, wait=True, timeout=30)
        assert s.running and s.actual_hz == pytest.approx(10.0, abs=0.2)
        r = d.stop()
        assert r.how == "normal" and r.stopped
        d.faults()
