"""The checklist format: YAML loaded with line numbers, validated per station before anything runs.

A checklist is a header (name, port defaults, variables, stations with the identity each must have) and a
list of steps. Every step is a mapping with exactly one step-type key (`write: {param: F07, value: 2.0}`)
plus the common keys `name`, `on_fail` and `stations`. Steps run on every station in turn (or only on the
stations a step names). docs/checklists.md is the user's reference; this module is the one that decides.

Validation is done per station, after variable substitution, against the station's profile: unknown step
type, missing field, wrong type, unknown parameter for the family, read-only target, value outside the
parameter's range, stop-only parameter written while the checklist has the motor running, unknown alarm
code, unknown status flag. Every problem is collected with file:line; ChecklistError carries them all.
"""

from __future__ import annotations

import difflib
import hashlib
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from profidrive_cli import PdriveError, UsageError
from profidrive_cli.datafile import DataFileError, LineDict, LineList, load_yaml_text, read_text
from profidrive_cli.drives.values import danger, profile_value_problem

STEP_TYPES = ("expect_identity", "read", "write", "save", "run", "stop", "expect_status", "wait", "faults",
              "reset_fault", "prompt", "note")
COMMON_KEYS = ("name", "on_fail", "stations")
ON_FAIL = ("stop", "continue")
STOP_MODES = ("normal", "quick", "coast")
DIRECTIONS = ("forward", "reverse")
HEADER_KEYS = ("name", "description", "port", "baud", "master_address", "on_fail", "variables", "snapshot",
               "stations", "steps")
STATION_KEYS = ("name", "address", "profile", "ident", "gsd", "layout", "variables", "snapshot")

# generic status names every family answers (DriveStatus fields), besides the family's own flags
GENERIC_FLAGS = ("running", "fault", "stopped")

DEFAULT_RUN_WITHIN_S = 10.0
DEFAULT_TOL_HZ = 0.5
DEFAULT_TOL_PERCENT = 1.0
DEFAULT_STOP_WITHIN_S = 30.0

_VAR_RE = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)\}")
_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


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
# the validated model
# =============================================================================================


@dataclass
class ParamTarget:
    """A parameter a step reads or writes, resolved for one station's profile."""
    code: str                      # as the checklist wrote it (after variables)
    label: str                     # canonical code for the family ("F07", "PNU947[9]", "REG0x0180")
    param: Any = None              # profile ParamDef, None for raw addresses
    unit: str = ""

    @property
    def step_tolerance(self) -> float:
        """Half a wire step: what a read-back may differ by after scaling."""
        if self.param is not None and self.param.scale:
            return abs(float(self.param.scale)) / 2 + 1e-9
        return 1e-9


@dataclass
class Step:
    """One step as it runs on one station (variables substituted, fields typed and checked)."""
    index: int                     # position in the file's steps list, 1-based
    type: str
    line: int
    args: dict                     # typed fields of the step
    title: str                     # what the step does, in words
    name: str | None = None        # the checklist's own name for the step
    on_fail: str = "stop"

    @property
    def label(self) -> str:
        return self.name or self.title

    def to_dict(self) -> dict:
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
    profile: Any                   # drives.profile.Profile
    ident: int                     # the ident the station must answer with
    ident_source: str              # "checklist" | "gsd" | "profile"
    gsd: str | None                # GSD file name the ident must map to (None: not checked)
    layout: str
    variables: dict
    snapshot: list[ParamTarget]
    line: int
    steps: list[Step] = field(default_factory=list)
    flag_names: list[str] = field(default_factory=list)

    def identity(self) -> dict:
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
    variables: dict                # global values after --var
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


def parse_var_assignments(items: list[str] | tuple[str, ...]) -> dict:
    """--var NAME=VALUE (VALUE read as a YAML scalar: 0.5 -> float, 10 -> int, text -> str)."""
    out = {}
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


def load_checklist(path: str | Path, overrides: dict | None = None) -> Checklist:
    return load_checklist_text(read_text(path), Path(path), overrides)


def load_checklist_text(text: str, path: str | Path = "<string>", overrides: dict | None = None) -> Checklist:
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
    return cl


# =============================================================================================
# validation
# =============================================================================================


def _tname(v) -> str:
    if isinstance(v, bool):
        return "true/false"
    if isinstance(v, (int, float)):
        return "a number"
    if isinstance(v, str):
        return "text"
    if isinstance(v, list):
        return "a list"
    if isinstance(v, dict):
        return "a mapping"
    if v is None:
        return "nothing"
    return type(v).__name__


def _is_num(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _fmt(v) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def _line(node, key=None, default=0) -> int:
    if key is not None and isinstance(node, LineDict):
        return node.line_of(key)
    if key is not None and isinstance(node, LineList) and isinstance(key, int):
        return node.line_of(key)
    return getattr(node, "line", default) or default


class _Skip(Exception):
    """Abandon the current item (its error is already recorded)."""


class _Validator:
    def __init__(self, path: Path, overrides: dict):
        self.path = path
        self.overrides = overrides
        self.errors: list[DataFileError] = []
        self._seen: set[tuple[int | None, str]] = set()

    # -- errors --------------------------------------------------------------------------------
    def err(self, line: int | None, msg: str) -> None:
        key = (line, msg)
        if key not in self._seen:           # the same problem found for several stations: once
            self._seen.add(key)
            self.errors.append(DataFileError(self.path, line, msg))

    def fail(self, line: int | None, msg: str):
        self.err(line, msg)
        raise _Skip()

    # -- header --------------------------------------------------------------------------------
    def checklist(self, doc, sha: str) -> Checklist | None:
        if not isinstance(doc, LineDict):
            self.err(_line(doc, default=1), "a checklist must be a YAML mapping with name, stations and steps")
            return None
        for k in doc:
            if k not in HEADER_KEYS:
                self.err(doc.line_of(k), self._unknown_key(k, HEADER_KEYS, "header key"))
        name = self.opt(doc, "name", str, required=True, default="")
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
            except _Skip:
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

    def _station_declares(self, doc, key) -> bool:
        for s in doc.get("stations") or []:
            if isinstance(s, LineDict) and isinstance(s.get("variables"), dict) and key in s["variables"]:
                return True
        return False

    def _unknown_key(self, k, known, what) -> str:
        close = difflib.get_close_matches(str(k), list(known), 1)
        return f"unknown {what} {k!r}" + (f" (did you mean {close[0]}?)" if close else
                                          f" (known: {', '.join(known)})")

    def opt(self, node: LineDict, key: str, types, required=False, default=None, what: str = ""):
        if key not in node:
            if required:
                self.err(_line(node), f"{what}missing field '{key}'")
            return default
        v = node[key]
        ok = isinstance(v, types) and not (isinstance(v, bool) and bool not in (
            types if isinstance(types, tuple) else (types,)))
        if not ok:
            want = {str: "text", int: "an integer", float: "a number", list: "a list", dict: "a mapping",
                    LineDict: "a mapping", bool: "true or false"}
            tn = " or ".join(want.get(t, t.__name__) for t in (types if isinstance(types, tuple) else (types,)))
            self.err(node.line_of(key), f"{what}'{key}' must be {tn}, got {_tname(v)} {v!r}")
            return default
        return v

    def variables(self, node: LineDict, key: str) -> dict:
        vs = self.opt(node, key, dict, default=None)
        out = {}
        if not vs:
            return out
        for k, v in vs.items():
            ln = vs.line_of(k) if isinstance(vs, LineDict) else _line(node, key)
            if not isinstance(k, str) or not _NAME_RE.match(k):
                self.err(ln, f"variable name {k!r}: use letters, digits and _ (not starting with a digit)")
                continue
            if not isinstance(v, (str, int, float, bool)):
                self.err(ln, f"variable {k}: a value must be a number or text, got {_tname(v)}")
                continue
            out[k] = v
        return out

    # -- variables -----------------------------------------------------------------------------
    def subst(self, value, variables: dict, line: int, where: str):
        if isinstance(value, str):
            m = _VAR_RE.fullmatch(value.strip())
            if m:
                name = m.group(1)
                if name not in variables:
                    self.fail(line, self._undefined(name, variables, where))
                return variables[name]

            def rep(mm):
                name = mm.group(1)
                if name not in variables:
                    self.fail(line, self._undefined(name, variables, where))
                return _fmt(variables[name])
            return _VAR_RE.sub(rep, value)
        if isinstance(value, LineDict):
            out = LineDict()
            out.line, out.key_lines = value.line, dict(value.key_lines)
            for k, v in value.items():
                out[k] = self.subst(v, variables, value.line_of(k), where)
            return out
        if isinstance(value, LineList):
            out = LineList(self.subst(v, variables, value.line_of(i), where) for i, v in enumerate(value))
            out.line, out.item_lines = value.line, list(value.item_lines)
            return out
        return value

    def _undefined(self, name, variables, where) -> str:
        close = difflib.get_close_matches(name, list(variables), 1)
        return f"{where}: variable ${{{name}}} is not defined" + (
            f" (did you mean {close[0]}?)" if close else
            f" (defined: {', '.join(sorted(variables)) or 'none'}; add it under `variables:` or give --var)")

    # -- stations ------------------------------------------------------------------------------
    def station(self, lst: LineList, i: int, node, global_vars: dict, snapshot_node) -> StationSpec:
        from profidrive_cli.drives.profile import load_profile
        ln = lst.line_of(i)
        if not isinstance(node, LineDict):
            self.fail(ln, f"station {i + 1}: must be a mapping with address and profile, got {_tname(node)}")
        for k in node:
            if k not in STATION_KEYS:
                self.err(node.line_of(k), self._unknown_key(k, STATION_KEYS, "station key"))
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
            raise _Skip()
        if not 0 <= address <= 125:
            self.fail(node.line_of("address"), f"{w}: address {address} outside 0..125")
        name = self.opt(node, "name", (str, int), default=None)
        name = str(name) if name is not None else f"station {address}"
        w = f"station {name!r}"
        pname = self.opt(node, "profile", str, required=True, what=f"{w}: ")
        if pname is None:
            raise _Skip()
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
                except _Skip:
                    continue
                codes.append((c, cl))
        for c, cl in codes:
            if not isinstance(c, (str, int)) or isinstance(c, bool):
                self.err(cl, f"snapshot: a parameter code must be text, got {_tname(c)}")
                continue
            try:
                t = self.param(st, str(c), cl, "snapshot")
            except _Skip:
                continue
            if all(t.label != s.label for s in st.snapshot):
                st.snapshot.append(t)
        return st

    def _gsd_ident(self, line, w, gsd) -> int | None:
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
    def param(self, st: StationSpec, code: str, line: int, where: str) -> ParamTarget:
        try:
            label, p = resolve_param(st.profile, code, st.layout)
        except PdriveError as e:
            self.fail(line, f"{where}: {e} (station {st.name!r})")
        return ParamTarget(code=code, label=label, param=p, unit=(p.unit if p is not None else ""))

    # -- steps: structure (same for every station) ---------------------------------------------
    def raw_steps(self, lst, default_on_fail) -> list["_RawStep"]:
        out = []
        for i, node in enumerate(lst):
            ln = lst.line_of(i) if isinstance(lst, LineList) else 0
            try:
                out.append(self.raw_step(i + 1, ln, node, default_on_fail))
            except _Skip:
                continue
        return out

    def raw_step(self, index, ln, node, default_on_fail) -> "_RawStep":
        if isinstance(node, str):                     # bare step: "- save", "- stop", "- reset_fault"
            key = node.strip()
            if key not in STEP_TYPES:
                self.fail(ln, f"step {index}: {self._unknown_key(key, STEP_TYPES, 'step type')}")
            return _RawStep(index, key, ln, None, ln, None, default_on_fail, None)
        if not isinstance(node, LineDict):
            self.fail(ln, f"step {index}: a step must be a mapping such as `- write: {{param: F07, value: 2}}`, "
                      f"got {_tname(node)}")
        types = [k for k in node if k in STEP_TYPES]
        others = [k for k in node if k not in STEP_TYPES and k not in COMMON_KEYS]
        for k in others:
            self.err(node.line_of(k), f"step {index}: " + self._unknown_key(k, STEP_TYPES + COMMON_KEYS,
                                                                            "step type or key"))
        if not types:
            if not others:
                self.fail(ln, f"step {index}: no step type (one of {', '.join(STEP_TYPES)})")
            raise _Skip()
        if len(types) > 1:
            self.fail(node.line_of(types[1]), f"step {index}: one step type per step, found "
                      f"{' and '.join(types)} (make them two steps)")
        if others:
            raise _Skip()
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
    def plan(self, st: StationSpec, raw_steps: list["_RawStep"]) -> list[Step]:
        out = []
        state = {"running": False}
        for rs in raw_steps:
            if rs.stations is not None and st.name not in [n for n, _ in rs.stations]:
                continue
            try:
                body = self.subst(rs.body, st.variables, rs.body_line, f"step {rs.index} ({rs.type})")
                args, title = getattr(self, f"step_{rs.type}")(st, rs, body, state)
            except _Skip:
                continue
            out.append(Step(index=rs.index, type=rs.type, line=rs.line, args=args, title=title, name=rs.name,
                            on_fail=rs.on_fail))
        return out

    def fields(self, rs, body, allowed: tuple, shorthand: str | None = None, required: tuple = ()) -> LineDict:
        """The step's mapping (or its shorthand scalar as `shorthand: value`), unknown keys rejected."""
        w = f"step {rs.index} ({rs.type})"
        if body is None:
            d = LineDict()
            d.line, d.key_lines = rs.body_line, {}
        elif isinstance(body, LineDict):
            d = body
        elif shorthand is not None and not isinstance(body, (list, dict)):
            d = LineDict({shorthand: body})
            d.line, d.key_lines = rs.body_line, {shorthand: rs.body_line}
        else:
            self.fail(rs.body_line, f"{w}: expected a mapping with {', '.join(allowed) or 'no fields'}, "
                      f"got {_tname(body)}")
        bad = False
        for k in d:
            if k not in allowed:
                self.err(d.line_of(k), f"{w}: " + self._unknown_key(k, allowed, "field") if allowed else
                         f"{w}: takes no fields, got {k!r}")
                bad = True
        for k in required:
            if k not in d:
                self.err(rs.body_line, f"{w}: missing field '{k}'")
                bad = True
        if bad:
            raise _Skip()
        return d

    def num(self, rs, d: LineDict, key, default=None, minimum=None, positive=False, required=False):
        w = f"step {rs.index} ({rs.type})"
        if key not in d:
            if required:
                self.fail(d.line or rs.body_line, f"{w}: missing field '{key}'")
            return default
        v = d[key]
        if not _is_num(v):
            self.fail(d.line_of(key), f"{w}: '{key}' must be a number, got {_tname(v)} {v!r}")
        if minimum is not None and v < minimum:
            self.fail(d.line_of(key), f"{w}: '{key}' must be at least {_fmt(minimum)}, got {_fmt(v)}")
        if positive and v <= 0:
            self.fail(d.line_of(key), f"{w}: '{key}' must be above 0, got {_fmt(v)}")
        return v

    def code_field(self, st, rs, d, key="param") -> ParamTarget:
        v = d[key]
        if not isinstance(v, (str, int)) or isinstance(v, bool):
            self.fail(d.line_of(key), f"step {rs.index} ({rs.type}): '{key}' must be a parameter code, "
                      f"got {_tname(v)}")
        return self.param(st, str(v), d.line_of(key), f"step {rs.index} ({rs.type})")

    def _no_channel(self, st, rs):
        if not _layout_has_params(st.profile, st.layout):
            self.fail(rs.line, f"step {rs.index} ({rs.type}): station {st.name!r} uses layout {st.layout}, "
                      f"which has no parameter channel (choose a layout with one, e.g. "
                      f"{_param_layouts(st.profile)})")

    # one method per step type: (station, raw step, substituted body, static state) -> (args, title)
    def step_expect_identity(self, st, rs, body, state):
        d = self.fields(rs, body, ("ident", "profile", "gsd"))
        ident = st.ident
        if "ident" in d:
            ident = d["ident"]
            if not isinstance(ident, int) or isinstance(ident, bool) or not 0 <= ident <= 0xFFFF:
                self.fail(d.line_of("ident"), f"step {rs.index} (expect_identity): 'ident' must be 0..0xFFFF")
        profile = st.profile.name
        if "profile" in d:
            from profidrive_cli.drives.profile import load_profile
            try:
                profile = load_profile(str(d["profile"])).name
            except PdriveError as e:
                self.fail(d.line_of("profile"), f"step {rs.index} (expect_identity): {e}")
        gsd = d.get("gsd", st.gsd)
        args = {"ident": ident, "profile": profile, "gsd": gsd}
        return args, f"identity: ident 0x{ident:04X}, profile {profile}" + (f", GSD {gsd}" if gsd else "")

    def step_read(self, st, rs, body, state):
        d = self.fields(rs, body, ("param", "expect", "tolerance", "min", "max", "range"), "param", ("param",))
        w = f"step {rs.index} (read)"
        self._no_channel(st, rs)
        t = self.code_field(st, rs, d)
        expect = self.num(rs, d, "expect")
        tol = self.num(rs, d, "tolerance", minimum=0)
        lo, hi = self.num(rs, d, "min"), self.num(rs, d, "max")
        if "range" in d:
            r = d["range"]
            if not (isinstance(r, list) and len(r) == 2 and all(_is_num(x) for x in r) and r[0] <= r[1]):
                self.fail(d.line_of("range"), f"{w}: 'range' must be [low, high] with low <= high, got {r!r}")
            if lo is not None or hi is not None:
                self.fail(d.line_of("range"), f"{w}: give either range or min/max, not both")
            lo, hi = r
        if expect is not None and (lo is not None or hi is not None):
            self.fail(d.line_of("expect"), f"{w}: give either expect (with tolerance) or a range, not both")
        if tol is not None and expect is None:
            self.fail(d.line_of("tolerance"), f"{w}: tolerance needs expect")
        if lo is not None and hi is not None and lo > hi:
            self.fail(d.line_of("min"), f"{w}: min {_fmt(lo)} is above max {_fmt(hi)}")
        u = f" {t.unit}" if t.unit else ""
        if expect is not None:
            if t.param is not None:
                msg = _range_problem(t.param, expect)
                if msg:
                    self.err(d.line_of("expect"), f"{w}: expected value can never be read: {msg}")
            title = f"read {t.label}, expect {_fmt(expect)}{u}" + (f" ± {_fmt(tol)}" if tol else "")
        elif lo is not None or hi is not None:
            title = f"read {t.label}, expect " + (
                f"{_fmt(lo)}..{_fmt(hi)}{u}" if lo is not None and hi is not None else
                f">= {_fmt(lo)}{u}" if lo is not None else f"<= {_fmt(hi)}{u}")
        else:
            title = f"read {t.label}"
        return {"param": t, "expect": expect, "tolerance": tol, "min": lo, "max": hi}, title

    def step_write(self, st, rs, body, state):
        d = self.fields(rs, body, ("param", "value", "allow_dangerous"), None, ("param", "value"))
        w = f"step {rs.index} (write)"
        self._no_channel(st, rs)
        t = self.code_field(st, rs, d)
        value = self.num(rs, d, "value", required=True)
        allow = d.get("allow_dangerous", False)
        if not isinstance(allow, bool):
            self.fail(d.line_of("allow_dangerous"), f"{w}: 'allow_dangerous' must be true or false, got {allow!r}")
        p = t.param
        if p is not None:
            if not p.writable:
                self.fail(d.line_of("param"), f"{w}: {t.label} ({p.name}) is read-only")
            msg = profile_value_problem(st.profile, p, value)
            if msg:
                self.fail(d.line_of("value"), f"{w}: {msg} (station {st.name!r})")
            if p.access == "stop" and state["running"]:
                self.fail(rs.line, f"{w}: {t.label} can only be changed while the motor is stopped, and an "
                          f"earlier run step leaves it running; put a stop step before it")
            what = danger(p)
            if what and not allow:
                self.err(d.line_of("param"), f"{w}: {t.label} ({p.name}) is dangerous: writing it {what}; "
                         f"add 'allow_dangerous: true' to the step to write it")
        u = f" {t.unit}" if t.unit else ""
        return ({"param": t, "value": value, "allow_dangerous": allow},
                f"write {t.label} = {_fmt(value)}{u}" + (" (dangerous, allowed)" if allow and p is not None
                                                         and danger(p) else ""))

    def step_save(self, st, rs, body, state):
        self.fields(rs, body, ())
        self._no_channel(st, rs)
        return {}, "save parameters to non-volatile memory"

    def step_run(self, st, rs, body, state):
        d = self.fields(rs, body, ("hz", "percent", "direction", "duration", "tolerance", "within"))
        w = f"step {rs.index} (run)"
        if ("hz" in d) == ("percent" in d):
            self.fail(rs.body_line, f"{w}: give the speed as either hz or percent")
        unit = "hz" if "hz" in d else "percent"
        speed = self.num(rs, d, unit, positive=True)
        direction = d.get("direction", "forward")
        if direction not in DIRECTIONS:
            self.fail(d.line_of("direction"), f"{w}: direction must be forward or reverse, got {direction!r}")
        if unit == "percent" and speed > 100:
            self.fail(d.line_of("percent"), f"{w}: percent {_fmt(speed)} is above 100 (the max frequency)")
        if unit == "hz":
            fp = st.profile.param(st.profile.max_frequency_param or "")
            top = fp.max if fp is not None and fp.max is not None else None
            if top is not None and speed > top:
                self.fail(d.line_of("hz"), f"{w}: {_fmt(speed)} Hz is above what {st.profile.name} can run "
                          f"({fp.code} max {_fmt(top)} Hz)")
        duration = self.num(rs, d, "duration", default=0.0, minimum=0)
        tol = self.num(rs, d, "tolerance", default=DEFAULT_TOL_HZ if unit == "hz" else DEFAULT_TOL_PERCENT,
                       positive=True)
        within = self.num(rs, d, "within", default=DEFAULT_RUN_WITHIN_S, positive=True)
        state["running"] = True
        u = " Hz" if unit == "hz" else " %"
        title = (f"run {direction} at {_fmt(speed)}{u} (± {_fmt(tol)}{u} within {_fmt(within)} s)"
                 + (f", hold {_fmt(duration)} s" if duration else ""))
        return {"unit": unit, "speed": speed, "direction": direction, "duration": duration, "tolerance": tol,
                "within": within}, title

    def step_stop(self, st, rs, body, state):
        d = self.fields(rs, body, ("mode", "within"), "mode")
        mode = d.get("mode", "normal")
        if mode not in STOP_MODES:
            self.fail(d.line_of("mode"), f"step {rs.index} (stop): mode must be normal, quick or coast, "
                      f"got {mode!r}")
        within = self.num(rs, d, "within", default=DEFAULT_STOP_WITHIN_S, positive=True)
        state["running"] = False
        return {"mode": mode, "within": within}, f"stop ({mode}), stopped within {_fmt(within)} s"

    def step_expect_status(self, st, rs, body, state):
        w = f"step {rs.index} (expect_status)"
        if not isinstance(body, LineDict) or not body:
            self.fail(rs.body_line, f"{w}: expected a mapping of status flags to true/false, e.g. "
                      f"{{running: false, fault: false}}")
        flags = {}
        state_text = None
        within = 0.0
        known = list(dict.fromkeys(list(GENERIC_FLAGS) + st.flag_names))
        n_errors = len(self.errors)
        lower = {k.lower(): k for k in known}
        for k, v in body.items():
            ln = body.line_of(k)
            if k == "state":
                if not isinstance(v, str):
                    self.err(ln, f"{w}: 'state' must be text (part of the state name), got {_tname(v)}")
                state_text = str(v)
                continue
            if k == "within":
                if not _is_num(v) or v < 0:
                    self.err(ln, f"{w}: 'within' must be a number of seconds >= 0, got {v!r}")
                else:
                    within = float(v)
                continue
            if not isinstance(v, bool):
                self.err(ln, f"{w}: flag {k!r} must be true or false, got {_tname(v)} {v!r}")
                continue
            name = lower.get(str(k).lower())
            if name is None and not str(k).lower().startswith("fault: "):
                close = difflib.get_close_matches(str(k), known, 3, 0.5)
                self.err(ln, f"{w}: {st.profile.name} has no status flag {k!r}"
                         + (f" (did you mean {', '.join(repr(c) for c in close)}?)" if close else
                            f" (flags: {', '.join(known)})"))
                continue
            flags[name or str(k)] = v
        if len(self.errors) > n_errors:
            raise _Skip()
        if not flags and state_text is None:
            self.fail(rs.body_line, f"{w}: nothing to check (name flags, or state)")
        parts = [f"{k} = {'yes' if v else 'no'}" for k, v in flags.items()]
        if state_text:
            parts.insert(0, f"state ~ {state_text!r}")
        return {"flags": flags, "state": state_text, "within": within}, "status: " + ", ".join(parts)

    def step_wait(self, st, rs, body, state):
        d = self.fields(rs, body, ("seconds",), "seconds", ("seconds",))
        s = self.num(rs, d, "seconds", minimum=0)
        return {"seconds": s}, f"wait {_fmt(s)} s"

    def step_faults(self, st, rs, body, state):
        d = self.fields(rs, body, ("expect", "history"), "expect")
        w = f"step {rs.index} (faults)"
        expect = d.get("expect", "none")
        if expect is None:
            expect = "none"
        if not isinstance(expect, (str, int)) or isinstance(expect, bool):
            self.fail(d.line_of("expect"), f"{w}: 'expect' must be none or an alarm code, got {_tname(expect)}")
        expect = str(expect)
        history = d.get("history", False)
        if not isinstance(history, bool):
            self.fail(d.line_of("history"), f"{w}: 'history' must be true or false, got {history!r}")
        if expect.lower() != "none":
            a = st.profile.alarm_by_code(expect)
            if a is None:
                codes = [x.code for x in st.profile.alarms]
                close = difflib.get_close_matches(expect, codes, 3, 0.5)
                self.fail(d.line_of("expect"), f"{w}: {st.profile.name} has no alarm {expect!r}"
                          + (f" (did you mean {', '.join(close)}?)" if close else ""))
            expect = a.code
        if (history or expect != "none") and not _layout_has_params(st.profile, st.layout):
            self.fail(rs.line, f"{w}: reading the fault history needs a parameter channel; layout "
                      f"{st.layout} has none")
        if expect == "none":
            title = "no active fault" + (" and an empty fault history" if history else "")
        else:
            title = f"fault {expect} " + ("in the fault history" if history else "is the current fault")
        return {"expect": expect, "history": history}, title

    def step_reset_fault(self, st, rs, body, state):
        self.fields(rs, body, ("within",))
        return {}, "reset (acknowledge) the fault"

    def step_prompt(self, st, rs, body, state):
        d = self.fields(rs, body, ("text",), "text", ("text",))
        if not isinstance(d["text"], str) or not d["text"].strip():
            self.fail(d.line_of("text"), f"step {rs.index} (prompt): 'text' must be the question for the operator")
        return {"text": d["text"].strip()}, f"operator: {d['text'].strip()}"

    def step_note(self, st, rs, body, state):
        d = self.fields(rs, body, ("text",), "text", ("text",))
        if not isinstance(d["text"], (str, int, float)):
            self.fail(d.line_of("text"), f"step {rs.index} (note): 'text' must be text")
        return {"text": str(d["text"]).strip()}, f"note: {str(d['text']).strip()}"


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
# profile helpers (no bus)
# =============================================================================================


class _NoChannel:
    """A CyclicChannel that refuses traffic: builds a family's Drive only to resolve codes."""

    def exchange(self, outputs: bytes) -> bytes:
        raise UsageError("internal: validation tried to talk to a drive")

    def now(self) -> float:
        return 0.0


def resolve_param(profile, code: str, layout: str | None = None) -> tuple[str, Any]:
    """(canonical label, ParamDef or None for a raw address) for `code` in this profile's family, the way
    the family's Drive resolves it; UsageError naming the closest codes when it is unknown."""
    from profidrive_cli.drives import make_drive
    drive = make_drive(_NoChannel(), profile, layout or profile.default_layout)
    text = str(code).strip()
    try:
        if hasattr(drive, "resolve_param"):
            ref = drive.resolve_param(text)
            return ref.code, ref.param
        p = profile.param(text)
        if p is not None:
            if p.register is None and p.pnu is None:
                raise UsageError(f"{p.code}: the profile gives no address for it")
            return p.code, p
        from profidrive_cli.drives import codec_module
        parse = getattr(codec_module(profile), "parse_register_code", None)
        reg = parse(text) if parse else None
        if reg is not None and 0 <= reg <= 0xFFFF:
            return f"REG0x{reg:04X}", None
        raise UsageError(f"unknown parameter '{code}' in profile {profile.name}")
    except UsageError as e:
        msg = str(e)
        if "unknown" in msg.lower():
            from profidrive_cli.session import profiles_with_code, suggest_codes
            others = sorted({p.family for p in profiles_with_code(text) if p.family != profile.family})
            near = suggest_codes(profile, text, 3)
            msg = f"unknown parameter '{text}' for {profile.name}"
            if others:
                msg += f" ({text} is a {'/'.join(others)} code; this station is family {profile.family})"
            if near:
                msg += f"; closest {profile.family} codes: {', '.join(near)}"
        raise UsageError(msg) from None


def _range_problem(p, value) -> str | None:
    """The profile's limits for a value (Moeller-style `ranges` lists first), None when inside."""
    rg = p.extra.get("ranges")
    u = f" {p.unit}" if p.unit else ""
    if rg:
        if any(lo - 1e-9 <= value <= hi + 1e-9 for lo, hi in rg):
            return None
        allowed = ", ".join(f"{lo:g}..{hi:g}" if lo != hi else f"{lo:g}" for lo, hi in rg)
        return f"{p.code} ({p.name}): {value:g}{u} is outside {allowed}{u}"
    lo = p.min - 1e-9 if p.min is not None else None
    hi = p.max + 1e-9 if p.max is not None else None
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        return (f"{p.code} ({p.name}): {value:g}{u} is outside "
                f"{'-inf' if p.min is None else f'{p.min:g}'}..{'inf' if p.max is None else f'{p.max:g}'}{u}")
    return None


def _layout_has_params(profile, layout: str) -> bool:
    return bool(profile.layouts[layout].pkw)


def _param_layouts(profile) -> str:
    return ", ".join(n for n, l in profile.layouts.items() if l.pkw) or "none"


_flag_cache: dict[tuple[str, str], list[str]] = {}


def _flag_names(profile, layout: str) -> list[str]:
    """The family's status flag names, taken from one status decode on a simulated drive of this profile."""
    key = (profile.name, layout)
    if key not in _flag_cache:
        names: list[str] = []
        try:
            from profidrive_cli.drives import make_drive
            from profidrive_cli.sim.direct import DirectChannel
            from profidrive_cli.sim.plant import make_model
            model = make_model(profile)
            drive = make_drive(DirectChannel(model, profile.layouts[layout].cfg), profile, layout)
            names = list(drive.cycle().flags)
        except Exception:             # noqa: BLE001 - no sim model: only the generic names are known
            names = []
        _flag_cache[key] = names
    return _flag_cache[key]
