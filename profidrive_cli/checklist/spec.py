"""The checklist format: YAML loaded with line numbers, validated per station before anything runs.

A checklist is a header (name, port defaults, variables, stations with the identity each must have) and a
list of steps. Every step is a mapping with exactly one step-type key (`write: {param: F07, value: 2.0}`)
plus the common keys `name`, `on_fail` and `stations`. Steps run on every station in turn (or only on the
stations a step names). docs/checklists.md is the user's reference; this module decides the file format.

Validation is done per station, after variable substitution, against the station's profile. This module
checks the header, the stations (address, profile, ident, GSD, layout, snapshot), variables and each
step's common keys and step-type key; the step type's own fields (missing, wrong type, unknown parameter,
read-only target, value outside the range, stop-only parameter while running, unknown alarm code or status
flag) are checked by the step type in checklist/steps/. Every problem is collected with file:line;
ChecklistError carries them all. It may import fields.py, steps/, datafile, drives/ (profiles) and gsd/.
"""

from __future__ import annotations

import difflib
import hashlib
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

from profidrive_cli import PdriveError, UsageError
from profidrive_cli.checklist.fields import FieldChecker, ParamTarget, Skip, StepArgs, fmt, line_at, tname
from profidrive_cli.checklist.steps import STEPS
from profidrive_cli.datafile import DataFileError, LineDict, LineList, load_yaml_text, read_text

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.drives.profile import Profile

COMMON_KEYS = ("name", "on_fail", "stations")
ON_FAIL = ("stop", "continue")
HEADER_KEYS = ("name", "description", "port", "baud", "master_address", "on_fail", "variables", "snapshot",
               "stations", "steps")
STATION_KEYS = ("name", "address", "profile", "ident", "gsd", "layout", "variables", "snapshot")

_VAR_RE = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)\}")
_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")

#: a checklist variable's value (`variables:`, --var NAME=VALUE)
VarValue = str | int | float | bool


class ChecklistError(DataFileError):
    """One or more problems in a checklist file; .errors lists every DataFileError (file:line each)."""

    def __init__(self, errors: list[DataFileError]):
        self.errors = errors
        first = errors[0]
        super().__init__(first.path, first.line, first.message + (
            f" (and {len(errors) - 1} more problem{'s' if len(errors) > 2 else ''})" if len(errors) > 1 else ""))

    def lines(self) -> list[str]:
        return [str(e) for e in self.errors]


# =============================================================================================
# the validated model (ParamTarget, a resolved parameter, lives in fields.py)
# =============================================================================================


@dataclass
class Step:
    """One step as it runs on one station (variables substituted, fields typed and checked)."""
    index: int                     # position in the file's steps list, 1-based
    type: str
    line: int
    args: StepArgs                 # typed fields of the step
    title: str                     # what the step does, in words
    name: str | None = None        # the checklist's own name for the step
    on_fail: str = "stop"

    @property
    def label(self) -> str:
        return self.name or self.title

    def to_dict(self) -> dict[str, Any]:
        args = {}
        for k, v in self.args.items():
            if isinstance(v, ParamTarget):
                v = v.label
            args[k] = v
        return {"index": self.index, "type": self.type, "line": self.line, "name": self.name,
                "title": self.title, "on_fail": self.on_fail, "args": args}


@dataclass
class StationSpec:
    name: str
    address: int
    profile: Profile
    ident: int                     # the ident the station must answer with
    ident_source: str              # "checklist" | "gsd" | "profile"
    gsd: str | None                # GSD file name the ident must map to (None: not checked)
    layout: str
    variables: dict[str, VarValue]
    snapshot: list[ParamTarget]
    line: int
    steps: list[Step] = field(default_factory=list)
    flag_names: list[str] = field(default_factory=list)

    def identity(self) -> dict[str, Any]:
        return {"name": self.name, "address": self.address, "profile": self.profile.name,
                "family": self.profile.family, "ident": f"0x{self.ident:04X}",
                "ident_source": self.ident_source, "gsd": self.gsd, "layout": self.layout}


@dataclass
class Checklist:
    name: str
    description: str
    path: Path
    sha256: str
    port: str | None
    baud: str | None
    master_address: int | None
    variables: dict[str, VarValue]  # global values after --var
    stations: list[StationSpec]
    step_count: int                # steps in the file
    on_fail: str = "stop"          # the header's default: also decides whether a station that cannot be
                                   # opened ends the run

    @property
    def has_prompts(self) -> bool:
        return any(s.type == "prompt" for st in self.stations for s in st.steps)

    def first_prompt_line(self) -> int | None:
        lines = [s.line for st in self.stations for s in st.steps if s.type == "prompt"]
        return min(lines) if lines else None

    def station(self, name: str) -> StationSpec:
        for s in self.stations:
            if s.name == name:
                return s
        raise KeyError(name)


# =============================================================================================
# loading
# =============================================================================================


def parse_var_assignments(items: list[str] | tuple[str, ...]) -> dict[str, VarValue]:
    """--var NAME=VALUE (VALUE read as a YAML scalar: 0.5 -> float, 10 -> int, text -> str)."""
    out: dict[str, VarValue] = {}
    for item in items or ():
        name, eq, text = item.partition("=")
        name = name.strip()
        if not eq or not _NAME_RE.match(name):
            raise UsageError(f"--var {item!r}: expected NAME=VALUE (NAME: letters, digits, _)")
        try:
            v = load_yaml_text(text, f"--var {name}") if text.strip() else ""
        except DataFileError:
            v = text
        if not isinstance(v, (str, int, float, bool)) or v is None:
            v = text
        out[name] = v
    return out


def load_checklist(path: str | Path, overrides: dict[str, VarValue] | None = None) -> Checklist:
    return load_checklist_text(read_text(path), Path(path), overrides)


def load_checklist_text(text: str, path: str | Path = "<string>",
                        overrides: dict[str, VarValue] | None = None) -> Checklist:
    try:
        doc = load_yaml_text(text, path)
    except ChecklistError:
        raise
    except DataFileError as e:
        raise ChecklistError([e]) from None
    v = _Validator(Path(path), overrides or {})
    cl = v.checklist(doc, hashlib.sha256(text.encode("utf-8")).hexdigest())
    if v.errors:
        raise ChecklistError(sorted(v.errors, key=lambda e: (e.path != str(path), e.line or 0)))
    assert cl is not None                   # None only with errors
    return cl


# =============================================================================================
# validation: the header, stations, variables and the step list; each step's own fields are checked by
# its step type (checklist/steps/), through the FieldChecker this validator is
# =============================================================================================


class _Validator(FieldChecker):
    def __init__(self, path: Path, overrides: dict[str, VarValue]) -> None:
        super().__init__(path)
        self.overrides = overrides

    # -- header --------------------------------------------------------------------------------
    def checklist(self, doc: Any, sha: str) -> Checklist | None:      # doc: the YAML as loaded
        if not isinstance(doc, LineDict):
            self.err(line_at(doc, default=1), "a checklist must be a YAML mapping with name, stations and steps")
            return None
        for k in doc:
            if k not in HEADER_KEYS:
                self.err(doc.line_of(k), self.unknown_key(k, HEADER_KEYS, "header key"))
        name = self.opt(doc, "name", str, required=True, default="")
        if "name" in doc and name == "":
            self.err(doc.line_of("name"), "'name' must not be empty")
        description = self.opt(doc, "description", str, default="")
        port = self.opt(doc, "port", str)
        baud = self.opt(doc, "baud", (str, int))
        master_address = self.opt(doc, "master_address", int)
        if master_address is not None and not 0 <= master_address <= 125:
            self.err(doc.line_of("master_address"), f"master_address {master_address} outside 0..125")
        default_on_fail = self.opt(doc, "on_fail", str, default="stop")
        if default_on_fail not in ON_FAIL:
            self.err(doc.line_of("on_fail"), f"on_fail must be stop or continue, got {default_on_fail!r}")
            default_on_fail = "stop"
        variables = self.variables(doc, "variables")
        for k in self.overrides:
            if k not in variables and not self._station_declares(doc, k):
                close = difflib.get_close_matches(k, list(variables), 1)
                self.errors.append(DataFileError(
                    "--var", None, f"{k}: the checklist declares no variable of that name"
                    + (f" (did you mean {close[0]}?)" if close else
                       f" (declared: {', '.join(variables) or 'none'})")))
        variables.update(self.overrides)
        snapshot_node = self.opt(doc, "snapshot", list, default=LineList())
        stations_node = self.opt(doc, "stations", list, required=True)
        steps_node = self.opt(doc, "steps", list, required=True)
        if stations_node is not None and not stations_node:
            self.err(doc.line_of("stations"), "stations: at least one station is needed")
        if steps_node is not None and not steps_node:
            self.err(doc.line_of("steps"), "steps: the checklist has no steps")
        raw_steps = self.raw_steps(steps_node or [], default_on_fail)
        stations: list[StationSpec] = []
        for i, snode in enumerate(stations_node or []):
            try:
                st = self.station(stations_node, i, snode, variables, snapshot_node)
            except Skip:
                continue
            if any(s.name == st.name for s in stations):
                self.err(st.line, f"station name {st.name!r} used twice (give each station its own `name`)")
                continue
            if any(s.address == st.address for s in stations):
                self.err(st.line, f"station address {st.address} used twice")
                continue
            stations.append(st)
        names = [s.name for s in stations]
        for rs in raw_steps:
            for nm, ln in rs.stations or []:
                if nm not in names and stations_node and len(stations) == len(stations_node):
                    close = difflib.get_close_matches(nm, names, 1)
                    self.err(ln, f"step {rs.index}: no station named {nm!r}"
                             + (f" (did you mean {close[0]}?)" if close else f" (stations: {', '.join(names)})"))
        for st in stations:
            st.steps = self.plan(st, raw_steps)
        if not name:
            return None
        return Checklist(name=name, description=description, path=self.path, sha256=sha, port=port,
                         baud=str(baud) if baud is not None else None, master_address=master_address,
                         variables=variables, stations=stations, step_count=len(raw_steps),
                         on_fail=default_on_fail)

    def _station_declares(self, doc: LineDict, key: str) -> bool:
        for s in doc.get("stations") or []:
            if isinstance(s, LineDict) and isinstance(s.get("variables"), dict) and key in s["variables"]:
                return True
        return False

    def opt(self, node: LineDict, key: str, types: type | tuple[type, ...], required: bool = False,
            default: Any = None, what: str = "") -> Any:
        """node[key] when it is of `types` (Any: the caller's `types` says which), else `default`."""
        if key not in node:
            if required:
                self.err(line_at(node), f"{what}missing field '{key}'")
            return default
        v = node[key]
        ok = isinstance(v, types) and not (isinstance(v, bool) and bool not in (
            types if isinstance(types, tuple) else (types,)))
        if not ok:
            want = {str: "text", int: "an integer", float: "a number", list: "a list", dict: "a mapping",
                    LineDict: "a mapping", bool: "true or false"}
            tn = " or ".join(want.get(t, t.__name__) for t in (types if isinstance(types, tuple) else (types,)))
            self.err(node.line_of(key), f"{what}'{key}' must be {tn}, got {tname(v)} {v!r}")
            return default
        return v

    def variables(self, node: LineDict, key: str) -> dict[str, VarValue]:
        vs = self.opt(node, key, dict, default=None)
        out: dict[str, VarValue] = {}
        if not vs:
            return out
        for k, v in vs.items():
            ln = vs.line_of(k) if isinstance(vs, LineDict) else line_at(node, key)
            if not isinstance(k, str) or not _NAME_RE.match(k):
                self.err(ln, f"variable name {k!r}: use letters, digits and _ (not starting with a digit)")
                continue
            if not isinstance(v, (str, int, float, bool)):
                self.err(ln, f"variable {k}: a value must be a number or text, got {tname(v)}")
                continue
            out[k] = v
        return out

    # -- variables -----------------------------------------------------------------------------
    def subst(self, value: Any, variables: Mapping[str, VarValue], line: int, where: str) -> Any:
        """value (YAML as loaded) with ${NAME} replaced."""
        if isinstance(value, str):
            m = _VAR_RE.fullmatch(value.strip())
            if m:
                name = m.group(1)
                if name not in variables:
                    self.fail(line, self._undefined(name, variables, where))
                return variables[name]

            def rep(mm: re.Match[str]) -> str:
                name = mm.group(1)
                if name not in variables:
                    self.fail(line, self._undefined(name, variables, where))
                return fmt(variables[name])
            return _VAR_RE.sub(rep, value)
        if isinstance(value, LineDict):
            out = LineDict()
            out.line, out.key_lines = value.line, dict(value.key_lines)
            for k, v in value.items():
                out[k] = self.subst(v, variables, value.line_of(k), where)
            return out
        if isinstance(value, LineList):
            lst = LineList(self.subst(v, variables, value.line_of(i), where) for i, v in enumerate(value))
            lst.line, lst.item_lines = value.line, list(value.item_lines)
            return lst
        return value

    def _undefined(self, name: str, variables: Mapping[str, VarValue], where: str) -> str:
        close = difflib.get_close_matches(name, list(variables), 1)
        return f"{where}: variable ${{{name}}} is not defined" + (
            f" (did you mean {close[0]}?)" if close else
            f" (defined: {', '.join(sorted(variables)) or 'none'}; add it under `variables:` or give --var)")

    # -- stations ------------------------------------------------------------------------------
    def station(self, lst: LineList, i: int, node: Any, global_vars: dict[str, VarValue],
                snapshot_node: Any) -> StationSpec:
        from profidrive_cli.drives.profile import load_profile
        ln = lst.line_of(i)
        if not isinstance(node, LineDict):
            self.fail(ln, f"station {i + 1}: must be a mapping with address and profile, got {tname(node)}")
        for k in node:
            if k not in STATION_KEYS:
                self.err(node.line_of(k), self.unknown_key(k, STATION_KEYS, "station key"))
        own = self.variables(node, "variables")
        variables = {**global_vars, **{k: v for k, v in own.items() if k not in self.overrides}}
        w = f"station {i + 1}"
        resolved = LineDict()
        resolved.line, resolved.key_lines = node.line, dict(node.key_lines)
        for k, v in node.items():
            resolved[k] = v if k == "variables" else self.subst(v, variables, node.line_of(k), w)
        node = resolved
        address = self.opt(node, "address", int, required=True, what=f"{w}: ")
        if address is None:
            raise Skip()
        if not 0 <= address <= 125:
            self.fail(node.line_of("address"), f"{w}: address {address} outside 0..125")
        name = self.opt(node, "name", (str, int), default=None)
        name = str(name) if name is not None else f"station {address}"
        w = f"station {name!r}"
        pname = self.opt(node, "profile", str, required=True, what=f"{w}: ")
        if pname is None:
            raise Skip()
        try:
            profile = load_profile(pname)
        except PdriveError as e:
            self.fail(node.line_of("profile"), f"{w}: {e}")
        ident = self.opt(node, "ident", int)
        ident_source = "checklist" if ident is not None else "profile"
        if ident is not None and not 0 <= ident <= 0xFFFF:
            self.fail(node.line_of("ident"), f"{w}: ident {ident} outside 0..0xFFFF")
        gsd = self.opt(node, "gsd", str)
        if gsd is not None:
            gident = self._gsd_ident(node.line_of("gsd"), w, gsd)
            if gident is not None:
                if ident is not None and ident != gident:
                    self.err(node.line_of("gsd"), f"{w}: {gsd} has ident 0x{gident:04X} but the station "
                             f"says ident 0x{ident:04X}")
                elif ident is None:
                    ident, ident_source = gident, "gsd"
        if ident is None:
            ident = profile.ident
        else:
            from profidrive_cli.drives.profile import profile_for_ident
            other = profile_for_ident(ident)
            if other is not None and other.name != profile.name:
                key = "ident" if ident_source == "checklist" else "gsd"
                self.fail(node.line_of(key), f"{w}: ident 0x{ident:04X}"
                          + (f" (from {gsd})" if key == "gsd" else "")
                          + f" is {other.name} ({other.title}), not {profile.name}")
        layout = self.opt(node, "layout", str, default=profile.default_layout)
        if layout not in profile.layouts:
            self.err(node.line_of("layout"), f"{w}: profile {profile.name} has no layout {layout!r} "
                     f"(layouts: {', '.join(profile.layouts)})")
            layout = profile.default_layout
        st = StationSpec(name=name, address=address, profile=profile, ident=ident, ident_source=ident_source,
                         gsd=gsd, layout=layout, variables=variables, snapshot=[], line=ln)
        st.flag_names = _flag_names(profile, layout)
        # parameter snapshot: the header's list and the station's own
        codes: list[tuple[Any, int]] = []
        for src, where in ((snapshot_node, "snapshot"), (node.get("snapshot"), f"{w}: snapshot")):
            if src is None:
                continue
            if not isinstance(src, list):
                self.err(node.line_of("snapshot"), f"{where} must be a list of parameter codes")
                continue
            for j, c in enumerate(src):
                cl = src.line_of(j) if isinstance(src, LineList) else ln
                try:
                    c = self.subst(c, variables, cl, where)
                except Skip:
                    continue
                codes.append((c, cl))
        for c, cl in codes:
            if not isinstance(c, (str, int)) or isinstance(c, bool):
                self.err(cl, f"snapshot: a parameter code must be text, got {tname(c)}")
                continue
            try:
                t = self.param(st, str(c), cl, "snapshot")
            except Skip:
                continue
            if all(t.label != s.label for s in st.snapshot):
                st.snapshot.append(t)
        return st

    def _gsd_ident(self, line: int, w: str, gsd: str) -> int | None:
        from profidrive_cli.gsd import library
        p = Path(gsd)
        found = p if (("/" in gsd or "\\" in gsd) and p.is_file()) else None
        if found is None:
            for folder, _src in library.search_dirs():
                for f in library.gsd_files(folder):
                    if f.name.lower() == p.name.lower() or f.stem.lower() == p.name.lower():
                        found = f
                        break
                if found:
                    break
        if found is None:
            self.err(line, f"{w}: GSD file {gsd!r} is not in the GSD library (pdrive gsd list; "
                     f"--gsd-dir or PDRIVE_GSD_DIR add folders)")
            return None
        ident = library.quick_ident(found)
        if ident is None:
            self.err(line, f"{w}: {found.name} has no Ident_Number")
        return ident

    # -- parameters ----------------------------------------------------------------------------
    # -- steps: structure (same for every station) ---------------------------------------------
    def raw_steps(self, lst: list[Any], default_on_fail: str) -> list[_RawStep]:
        out = []
        for i, node in enumerate(lst):
            ln = lst.line_of(i) if isinstance(lst, LineList) else 0
            try:
                out.append(self.raw_step(i + 1, ln, node, default_on_fail))
            except Skip:
                continue
        return out

    def raw_step(self, index: int, ln: int, node: Any, default_on_fail: str) -> _RawStep:
        step_types = tuple(STEPS)                    # the registry: checklist/steps/
        if isinstance(node, str):                     # bare step: "- save", "- stop", "- reset_fault"
            key = node.strip()
            if key not in step_types:
                self.fail(ln, f"step {index}: {self.unknown_key(key, step_types, 'step type')}")
            return _RawStep(index, key, ln, None, ln, None, default_on_fail, None)
        if not isinstance(node, LineDict):
            self.fail(ln, f"step {index}: a step must be a mapping such as `- write: {{param: F07, value: 2}}`, "
                      f"got {tname(node)}")
        types = [k for k in node if k in step_types]
        others = [k for k in node if k not in step_types and k not in COMMON_KEYS]
        for k in others:
            self.err(node.line_of(k), f"step {index}: " + self.unknown_key(k, step_types + COMMON_KEYS,
                                                                           "step type or key"))
        if not types:
            if not others:
                self.fail(ln, f"step {index}: no step type (one of {', '.join(step_types)})")
            raise Skip()
        if len(types) > 1:
            self.fail(node.line_of(types[1]), f"step {index}: one step type per step, found "
                      f"{' and '.join(types)} (make them two steps)")
        if others:
            raise Skip()
        t = types[0]
        name = self.opt(node, "name", (str, int), what=f"step {index}: ")
        on_fail = self.opt(node, "on_fail", str, default=default_on_fail, what=f"step {index}: ")
        if on_fail not in ON_FAIL:
            self.err(node.line_of("on_fail"), f"step {index}: on_fail must be stop or continue, got {on_fail!r}")
            on_fail = default_on_fail
        stations = None
        if "stations" in node:
            sv = node["stations"]
            sl = node.line_of("stations")
            if isinstance(sv, (str, int)) and not isinstance(sv, bool):
                stations = [(str(sv), sl)]
            elif isinstance(sv, list) and sv and all(isinstance(x, (str, int)) and not isinstance(x, bool)
                                                     for x in sv):
                stations = [(str(x), sv.line_of(j) if isinstance(sv, LineList) else sl) for j, x in enumerate(sv)]
            else:
                self.fail(sl, f"step {index}: 'stations' must be a station name or a list of names")
        return _RawStep(index, t, ln, node[t], node.line_of(t), str(name) if name is not None else None,
                        on_fail, stations)

    # -- steps: per station --------------------------------------------------------------------
    def plan(self, st: StationSpec, raw_steps: list[_RawStep]) -> list[Step]:
        out = []
        state = {"running": False}
        for rs in raw_steps:
            if rs.stations is not None and st.name not in [n for n, _ in rs.stations]:
                continue
            try:
                body = self.subst(rs.body, st.variables, rs.body_line, f"step {rs.index} ({rs.type})")
                args, title = STEPS[rs.type].validate(self, st, rs, body, state)
            except Skip:
                continue
            out.append(Step(index=rs.index, type=rs.type, line=rs.line, args=args, title=title, name=rs.name,
                            on_fail=rs.on_fail))
        return out


@dataclass
class _RawStep:
    index: int
    type: str
    line: int
    body: Any
    body_line: int
    name: str | None
    on_fail: str
    stations: list[tuple[str, int]] | None


# =============================================================================================
# status flag names of a profile (from a simulated drive, no bus)
# =============================================================================================


_flag_cache: dict[tuple[str, str], list[str]] = {}


def _flag_names(profile: Profile, layout: str) -> list[str]:
    """The family's status flag names in this layout: a class fact of its Drive (no bus, no simulator)."""
    key = (profile.name, layout)
    if key not in _flag_cache:
        from profidrive_cli.drives import drive_class
        _flag_cache[key] = drive_class(profile).status_flag_names(profile, layout)
    return _flag_cache[key]
