"""Drive profiles: profiles/*.yaml loaded and validated with file:line errors.

Common schema (every family):

    profile: fuji-opc-g1-pdp          # the profile's name (= file stem)
    aliases: [fuji-g1]                # short names (sim URLs, --profile)
    family: fuji                      # a row of drives/registry.py (codec, Drive, sim model, config)
    title: Fuji FRENIC-MEGA, OPC-G1-PDP
    identity:
      ident: 0xF0A1                   # PROFIBUS ident number
      ident_placeholder: "why"        # present when the manual gives no ident
      gsd: FUJI_G1.GSD                # library file in gsd/
    word_order: big                   # 16-bit words on the bus: big | little
    layouts:                          # PPO types / message formats
      ppo1: {cfg: "F3 F1", pkw: true, description: "PPO1: 4 PKW + 2 PZD"}
    default_layout: ppo1
    max_frequency: {param: F03, default_hz: 60.0}
    parameters:                       # code, name, unit, scale, min, max, access, default + addressing
      - {code: F03, name: Maximum frequency 1, pnu: 0x103, index: 3, unit: Hz, scale: 0.01,
         min: 25.0, max: 500.0, access: stop, default: 60.0}
    alarms:                           # number on the wire -> names (several where a number is shared)
      - {number: 1, code: OC1, meaning: Overcurrent during acceleration}
    capabilities:                     # what the card can do, per layout (drives/capabilities.py)
      jog: {param: A038}              # a mapping: it can (optionally `layouts:`, `needs:`, `reason:`)
      torque: "no torque reference"   # a text: it cannot, and why
    groups:                           # parameter groups for `param restore --only/--exclude` (one place,
      motor: [P*, A18]                #   not per parameter): code patterns (fnmatch, case-sensitive); a code
      communication: [o*, y98]        #   belongs to the first group that matches it; [] = none listed
    bus_settings: {y98: 3}            # the manual's settings for control over the field bus (a drive
                                      #   holding one is not "changed from the factory" there)
    decisions: [...]                  # what we decided where the manual is ambiguous, and why

Family codecs may read further keys (fault_history, handshake, ...) from Profile.raw; they validate them
with the same ProfileError(file:line).
"""

from __future__ import annotations

import fnmatch
import functools
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, TypeVar

from profidrive_cli.data import profiles_dir, user_profile_dirs
from profidrive_cli.datafile import DataFileError, LineDict, load_yaml, load_yaml_head, read_text
from profidrive_cli.dp.cfg import CfgError, decode_cfg, io_sizes, parse_hex
from profidrive_cli.drives.capabilities import Capabilities, parse_capabilities
from profidrive_cli.drives.formats import FORMATS
from profidrive_cli.drives.registry import unknown_family

if TYPE_CHECKING:
    from profidrive_cli.drives.monitors import MonitorWord

ProfileError = DataFileError

ACCESS = ("rw", "ro", "stop", "wo")  # stop = writable only while the motor is stopped


@dataclass
class Layout:
    name: str
    cfg: bytes
    input_len: int
    output_len: int
    pkw: bool
    description: str = ""
    extra: dict[str, Any] = field(default_factory=dict)   # the YAML node's other keys


@dataclass
class ParamDef:
    code: str
    name: str
    unit: str = ""
    scale: float = 1.0
    min: float | None = None
    max: float | None = None
    access: str = "rw"
    default: float | int | None = None
    pnu: int | None = None
    index: int | None = None
    register: int | None = None
    signed: bool = False
    size: int = 16                    # bits on the wire: 16 or 32
    line: int = 0
    extra: dict[str, Any] = field(default_factory=dict)   # the YAML node's other keys

    @property
    def writable(self) -> bool:
        return self.access in ("rw", "stop", "wo")

    def to_raw(self, value: float) -> int:
        raw = round(value / self.scale) if self.scale else int(value)
        return int(raw)

    def from_raw(self, raw: int) -> float | int:
        if self.signed:
            bits = self.size
            if raw >= 1 << (bits - 1):
                raw -= 1 << bits
        v = raw * self.scale
        if isinstance(self.scale, int) or float(self.scale).is_integer():
            return int(round(v))
        return round(v, 6)

    def check_range(self, value: float) -> str | None:
        """None if value is inside the range, else a message with range and unit."""
        u = f" {self.unit}" if self.unit else ""
        if (self.min is not None and value < self.min) or (self.max is not None and value > self.max):
            return (f"{self.code} ({self.name}): {value:g}{u} is outside "
                    f"{self.min:g}..{self.max:g}{u}")
        return None


@dataclass
class Alarm:
    number: int
    code: str
    meaning: str = ""


@dataclass
class Profile:
    name: str
    family: str
    title: str
    ident: int
    gsd: str | None
    word_order: str
    layouts: dict[str, Layout]
    default_layout: str
    max_frequency_param: str | None
    max_frequency_default: float
    parameters: dict[str, ParamDef]
    alarms: list[Alarm]
    aliases: list[str] = field(default_factory=list)
    ident_placeholder: str | None = None
    path: Path | None = None
    raw: LineDict = field(default_factory=LineDict)
    #: what the card can do (quick_stop, jog, torque, param_channel, monitor_words, ...): drives/capabilities.py
    capabilities: Capabilities | None = None
    #: parameter groups (`groups:`): name -> code patterns, in the file's order
    groups: dict[str, tuple[str, ...]] = field(default_factory=dict)
    #: the manual's settings for control over the field bus (`bus_settings:`): code -> value
    bus_settings: dict[str, float | int] = field(default_factory=dict)

    def group_of(self, code: str) -> str | None:
        """The group a code (or an array element CODE[i]) belongs to: the first whose patterns match."""
        base = code.split("[", 1)[0]
        for name, pats in self.groups.items():
            if any(fnmatch.fnmatchcase(base, pat) for pat in pats):
                return name
        return None

    def alarms_for(self, number: int) -> list[Alarm]:
        return [a for a in self.alarms if a.number == number]

    def alarm_by_code(self, code: str) -> Alarm | None:
        code = code.upper()
        return next((a for a in self.alarms if a.code.upper() == code), None)

    def param(self, code: str) -> ParamDef | None:
        return self.parameters.get(code) or self.parameters.get(code.upper())

    def layout_for_ppo(self, n: int) -> Layout | None:
        return self.layouts.get(f"ppo{n}")


def _err(path: str | Path, node: object, key: str, msg: str) -> DataFileError:
    line = node.line_of(key) if isinstance(node, LineDict) else getattr(node, "line", None)
    return DataFileError(path, line, msg)


#: a YAML type _get checks a value against: one type or a tuple of them
_Types = type | tuple[type, ...]


def _get(path: str | Path, node: LineDict, key: str, types: _Types, required: bool = True,
         default: Any = None) -> Any:   # Any: a parsed YAML value, checked against `types` here
    if key not in node:
        if required:
            raise DataFileError(path, node.line, f"missing field '{key}'")
        return default
    v = node[key]
    if types is float and isinstance(v, int) and not isinstance(v, bool):
        return float(v)
    if not isinstance(v, types) or (isinstance(v, bool) and types in (int, float)):
        tn = types.__name__ if isinstance(types, type) else "/".join(t.__name__ for t in types)
        raise _err(path, node, key, f"'{key}' must be {tn}, got {type(v).__name__} {v!r}")
    return v


#: keys every family accepts in a parameter (kept in ParamDef.extra): `dangerous: true` + `danger:` text
#: (what writing it does, in words) -- written only on an explicit --allow-dangerous (drives/values.py)
#: `default_source:` where the factory `default:` comes from when not from the card's own manual (a
#: short name: "F7", "FRENIC"); `param diff --defaults` shows it beside the value
COMMON_EXTRA_KEYS = {"dangerous", "danger", "default_source"}

_PARAM_KEYS = {"code", "name", "unit", "scale", "min", "max", "access", "default", "pnu", "index",
               "register", "signed", "size"}


def _param(path: str | Path, node: object) -> ParamDef:
    if not isinstance(node, LineDict):
        raise DataFileError(path, getattr(node, "line", None), "a parameter must be a mapping")
    num = (int, float)
    p = ParamDef(
        code=str(_get(path, node, "code", (str, int))),
        name=_get(path, node, "name", str),
        unit=_get(path, node, "unit", str, False, ""),
        scale=_get(path, node, "scale", num, False, 1),
        min=_get(path, node, "min", num, False),
        max=_get(path, node, "max", num, False),
        access=_get(path, node, "access", str, False, "rw"),
        default=_get(path, node, "default", num, False),
        pnu=_get(path, node, "pnu", int, False),
        index=_get(path, node, "index", int, False),
        register=_get(path, node, "register", int, False),
        signed=_get(path, node, "signed", bool, False, False),
        size=_get(path, node, "size", int, False, 16),
        line=node.line,
        extra={k: v for k, v in node.items() if k not in _PARAM_KEYS},
    )
    if p.access not in ACCESS:
        raise _err(path, node, "access", f"access must be one of {', '.join(ACCESS)}, got {p.access!r}")
    if p.size not in (16, 32):
        raise _err(path, node, "size", f"size must be 16 or 32, got {p.size}")
    if p.min is not None and p.max is not None and p.min > p.max:
        raise _err(path, node, "min", f"{p.code}: min {p.min} > max {p.max}")
    if p.scale == 0:
        raise _err(path, node, "scale", f"{p.code}: scale must not be 0")
    if p.default is not None and ((p.min is not None and p.default < p.min)
                                  or (p.max is not None and p.default > p.max)):
        lo, hi = ("" if v is None else f"{v:g}" for v in (p.min, p.max))
        raise _err(path, node, "default", f"{p.code}: the factory default {p.default:g} is outside {lo}..{hi}")
    if "format" in node and node["format"] not in FORMATS:
        raise _err(path, node, "format", f"{p.code}: unknown format {node['format']!r} "
                   f"(known: {', '.join(FORMATS)})")
    if "default_source" in node:
        if not isinstance(node["default_source"], str) or not node["default_source"].strip():
            raise _err(path, node, "default_source", f"{p.code}: 'default_source' must be a text naming "
                       f"where the factory default comes from")
        if p.default is None:
            raise _err(path, node, "default_source", f"{p.code}: 'default_source' needs a 'default:'")
    if "dangerous" in node and not isinstance(node["dangerous"], bool):
        raise _err(path, node, "dangerous", f"{p.code}: 'dangerous' must be true or false")
    if "danger" in node:
        if not isinstance(node["danger"], str) or not node["danger"].strip():
            raise _err(path, node, "danger", f"{p.code}: 'danger' must be a text saying what writing it does")
        if node.get("dangerous") is not True:
            raise _err(path, node, "danger", f"{p.code}: 'danger' needs 'dangerous: true'")
    return p


def load_profile_file(path: str | Path, *, check_sections: bool = True) -> Profile:
    """A profile file, validated (file:line). check_sections=False leaves the family's keys, monitors
    and trip records to be read when they are used (a test of one section reader's own messages);
    every command loads with the check (_check_sections)."""
    path = Path(path)
    doc = load_yaml(path, cached=True)
    if not isinstance(doc, LineDict):
        raise DataFileError(path, 1, "a profile must be a YAML mapping")
    ident_node = _get(path, doc, "identity", LineDict)
    layouts_node = _get(path, doc, "layouts", LineDict)
    layouts: dict[str, Layout] = {}
    for lname, lnode in layouts_node.items():
        if not isinstance(lnode, LineDict):
            raise _err(path, layouts_node, lname, f"layout '{lname}' must be a mapping")
        cfg_text = _get(path, lnode, "cfg", str)
        try:
            cfg = parse_hex(cfg_text)
            decode_cfg(cfg)
        except (ValueError, CfgError) as e:
            raise _err(path, lnode, "cfg", f"layout '{lname}': bad cfg octets: {e}") from None
        if not cfg:
            raise _err(path, lnode, "cfg", f"layout '{lname}': cfg is empty")
        inp, out = io_sizes(cfg)
        layouts[str(lname)] = Layout(
            name=str(lname), cfg=cfg, input_len=inp, output_len=out,
            pkw=_get(path, lnode, "pkw", bool, False, False),
            description=_get(path, lnode, "description", str, False, ""),
            extra={k: v for k, v in lnode.items() if k not in ("cfg", "pkw", "description")})
    if not layouts:
        raise _err(path, doc, "layouts", "no layouts")
    default_layout = _get(path, doc, "default_layout", str)
    if default_layout not in layouts:
        raise _err(path, doc, "default_layout",
                   f"default_layout '{default_layout}' is not one of {', '.join(layouts)}")

    params: dict[str, ParamDef] = {}
    plist = _get(path, doc, "parameters", list, False, [])
    for i, pnode in enumerate(plist):
        p = _param(path, pnode)
        if p.code in params:
            raise DataFileError(path, p.line, f"parameter {p.code} defined twice "
                                f"(first at line {params[p.code].line})")
        params[p.code] = p

    alarms: list[Alarm] = []
    for anode in _get(path, doc, "alarms", list, False, []):
        if not isinstance(anode, LineDict):
            raise DataFileError(path, getattr(anode, "line", None), "an alarm must be a mapping")
        alarms.append(Alarm(number=_get(path, anode, "number", int),
                            code=str(_get(path, anode, "code", (str, int))),
                            meaning=_get(path, anode, "meaning", str, False, "")))

    groups = _groups(path, doc, params)
    mf = _get(path, doc, "max_frequency", LineDict, False, LineDict())
    mf_param = _get(path, mf, "param", str, False) if mf else None
    if mf_param is not None and mf_param not in params:
        raise _err(path, mf, "param", f"max_frequency.param {mf_param} is not in parameters")
    name = _get(path, doc, "profile", str)
    family = _get(path, doc, "family", str)
    unknown = unknown_family(family)
    if unknown is not None:
        raise _err(path, doc, "family", unknown)
    profile = Profile(
        name=name,
        family=family,
        title=_get(path, doc, "title", str),
        ident=_get(path, ident_node, "ident", int),
        ident_placeholder=_get(path, ident_node, "ident_placeholder", str, False),
        gsd=_get(path, ident_node, "gsd", str, False),
        word_order=_word_order(path, doc),
        layouts=layouts,
        default_layout=default_layout,
        max_frequency_param=mf_param,
        max_frequency_default=_get(path, mf, "default_hz", float, False, 50.0) if mf else 50.0,
        parameters=params,
        alarms=alarms,
        aliases=[str(a) for a in _get(path, doc, "aliases", list, False, [])],
        path=path,
        raw=doc,
        capabilities=parse_capabilities(path, doc, name, layouts),
        groups=groups,
        bus_settings=_bus_settings(path, doc, params),
    )
    if check_sections:
        _check_sections(profile, path)
    return profile


def _check_sections(profile: Profile, path: Path) -> None:
    """The sections read when they are used, read now (a profile that loads is one every command can
    use): the family's own keys (drives/registry.py `config`: ppo_select, comm_loss, ... -- every
    code they name checked against the parameters), `monitors:` and `trip_records:`, whose codes
    must be parameters of the profile (or CODE[i] of one, a raw PNU<n>[i], a monitors.words name,
    or an address form the family's codec declares in ADDRESS_FORMS). DataFileError, file:line."""
    from profidrive_cli.drives.monitors import monitor_config, trip_record_config
    from profidrive_cli.drives.registry import find, resolve
    fam = find(profile.family)
    if fam is not None:
        resolve(fam.config)(profile)
    mon = monitor_config(profile)
    trips = trip_record_config(profile)
    forms = getattr(resolve(fam.codec), "ADDRESS_FORMS", None) if fam is not None else None
    raw = profile.raw
    named: list[tuple[object, str, str, str]] = []        # (node, key, where, code)
    node = raw.get("monitors")
    if isinstance(node, LineDict) and isinstance(node.get("default"), list):
        named += [(node, "default", "monitors.default", c) for c in mon.default]
    node = raw.get("trip_records")
    if trips is not None and isinstance(node, LineDict):
        named += [(node, "latest", "trip_records.latest", trips.latest)] if trips.latest else []
        for rec, spec in zip(node.get("records") or [], trips.records):
            named += [(rec, "fields", "trip_records.records.fields", c) for c in spec.fields]
    for where_node, key_, where, code in named:
        if not _addressable(profile, code, mon.words, forms):
            raise _err(path, where_node, key_, f"{where}: {code} is not a parameter of this profile")


_RAW_PNU = re.compile(r"PNU\s*(0x[0-9a-f]+|\d+)(\s*\[\s*(0x[0-9a-f]+|\d+)\s*\])?", re.I)


def _addressable(profile: Profile, code: str, words: dict[str, MonitorWord], forms: object) -> bool:
    """A code a monitor or trip record may name: see _check_sections."""
    base = code.split("[", 1)[0].strip()
    if profile.param(code) is not None or profile.param(base) is not None or code in words:
        return True
    if any(c.lower() == code.lower() for c in profile.parameters) or _RAW_PNU.fullmatch(code):
        return True
    return isinstance(forms, re.Pattern) and forms.fullmatch(code) is not None


def _bus_settings(path: str | Path, doc: LineDict, params: dict[str, ParamDef]) -> dict[str, float | int]:
    """`bus_settings:`: code -> the value the manual's commissioning for the field bus sets."""
    node = _get(path, doc, "bus_settings", LineDict, False, None)
    out: dict[str, float | int] = {}
    for code, v in (node or {}).items():
        if str(code) not in params:
            raise _err(path, node, code, f"bus_settings: {code} is not a parameter of this profile")
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise _err(path, node, code, f"bus_settings: {code} must be a number, got {v!r}")
        out[str(code)] = v
    return out


_GROUP_NAME = re.compile(r"[a-z][a-z0-9_-]*\Z")
_WILD = re.compile(r"[*?\[]")


def _groups(path: str | Path, doc: LineDict, params: dict[str, ParamDef]) -> dict[str, tuple[str, ...]]:
    """`groups:`: a mapping name -> list of code patterns; every pattern must match a parameter."""
    node = _get(path, doc, "groups", LineDict, False, None)
    if node is None:
        return {}
    out: dict[str, tuple[str, ...]] = {}
    for name, pats in node.items():
        if not isinstance(name, str) or not _GROUP_NAME.match(name):
            raise _err(path, node, name, f"groups: {name!r} is not a group name (lower-case letters, "
                       f"digits, - and _)")
        if pats is None:
            pats = []
        if not isinstance(pats, list) or not all(isinstance(x, str) and x.strip() for x in pats):
            raise _err(path, node, name, f"groups.{name} must be a list of parameter codes or patterns")
        for pat in pats:
            if pat in params and not _WILD.search(pat):
                continue                        # a plain code (most of them): no pattern to match
            if not any(fnmatch.fnmatchcase(c, pat) for c in params):
                raise _err(path, node, name, f"groups.{name}: {pat!r} matches no parameter of this profile")
        out[name] = tuple(pats)
    return out


def _word_order(path: str | Path, doc: LineDict) -> str:
    wo: str = _get(path, doc, "word_order", str, False, "big")
    if wo not in ("big", "little"):
        raise _err(path, doc, "word_order", f"word_order must be big or little, got {wo!r}")
    return wo


_C = TypeVar("_C")


def per_profile(build: Callable[[Profile], _C]) -> Callable[[Profile], _C]:
    """Memoise a family codec's config builder per Profile object (profiles are immutable once loaded)."""
    cache: dict[int, tuple[Profile, _C]] = {}

    @functools.wraps(build)
    def get(profile: Profile) -> _C:
        hit = cache.get(id(profile))
        if hit is not None and hit[0] is profile:
            return hit[1]
        c = build(profile)
        cache[id(profile)] = (profile, c)
        return c
    return get


# ------------------------------------------------------------------------------------------------ index
#
# A command needs one profile (decode, run, a sim:// station) or the one with a given ident (naming a
# station): the index reads only each file's first top-level keys (profile, aliases, family, identity;
# datafile.load_yaml_head stops parsing there), and only the file asked for is loaded in full. Both
# the index entries and the loaded profiles are cached per process, keyed by (path, mtime, size).

INDEX_KEYS = ("profile", "aliases", "family", "identity")


@dataclass(frozen=True)
class IndexEntry:
    """What the index knows of one profile file without loading it. name is None when the file's
    first keys could not be read as a profile header: such a file cannot load either, and is loaded
    (raising its file:line error) only when no readable profile answers a lookup."""
    path: Path
    name: str | None = None
    aliases: tuple[str, ...] = ()
    family: str | None = None
    ident: int | None = None

    def answers_to(self, key: str) -> bool:
        return self.name is not None and (self.name == key or key in (a.lower() for a in self.aliases))


_Stamp = tuple[int, int]
_index: dict[Path, tuple[_Stamp | None, IndexEntry]] = {}
_cache: dict[Path, tuple[_Stamp | None, Profile]] = {}


def _stamp(path: Path) -> _Stamp | None:
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_mtime_ns, st.st_size


def clear_cache() -> None:
    _index.clear()
    _cache.clear()


def _read_entry(path: Path) -> IndexEntry:
    try:
        head = load_yaml_head(read_text(path, "profile"), INDEX_KEYS, path)
    except DataFileError:
        return IndexEntry(path)
    if head is None:
        return IndexEntry(path)
    name, family, identity = head.get("profile"), head.get("family"), head.get("identity")
    aliases = head.get("aliases", [])
    ident = identity.get("ident") if isinstance(identity, LineDict) else None
    if not (isinstance(name, str) and isinstance(family, str) and isinstance(aliases, list)
            and isinstance(ident, int) and not isinstance(ident, bool)):
        return IndexEntry(path)
    return IndexEntry(path, name, tuple(str(a) for a in aliases), family, ident)


def _profile_files(plugins: bool) -> list[Path]:
    """The shipped profiles/*.yaml sorted by file name, then each $PDRIVE_PROFILE_PATH folder's, then
    (with plugins) each family plug-in's folder's."""
    dirs = [profiles_dir(), *user_profile_dirs()]
    if plugins:
        from profidrive_cli.drives.registry import plugin_profile_dirs
        dirs += plugin_profile_dirs()
    return [p for d in dirs for p in sorted(d.glob("*.yaml"))]


def profile_index(plugins: bool = True) -> list[IndexEntry]:
    """One entry per profile file: the shipped ones sorted by file name, then the user's folders'
    ($PDRIVE_PROFILE_PATH), then (with plugins, the default) the family plug-ins' folders."""
    out = []
    for p in _profile_files(plugins):
        stamp = _stamp(p)
        hit = _index.get(p)
        if hit is None or hit[0] != stamp:
            hit = (stamp, _read_entry(p))
            _index[p] = hit
        out.append(hit[1])
    return out


def index_entry(name: str) -> IndexEntry | None:
    """The index entry of a profile name or alias (the shipped and the user's profiles first, the
    plug-ins' only when none of those answers); None when no readable entry answers."""
    key = name.lower()
    for plugins in (False, True):
        hit = next((e for e in profile_index(plugins) if e.answers_to(key)), None)
        if hit is not None:
            return hit
    return None


def _load_cached(path: Path) -> Profile:
    stamp = _stamp(path)
    hit = _cache.get(path)
    if hit is None or hit[0] != stamp:
        hit = (stamp, load_profile_file(path))
        _cache[path] = hit
    return hit[1]


def all_profiles() -> list[Profile]:
    """Every shipped profile, loaded in full (a broken file raises its file:line error)."""
    return [_load_cached(e.path) for e in profile_index()]


def _lookup(match: Callable[[IndexEntry], bool]) -> Profile | None:
    """The first profile (by file name) whose index entry matches and whose full load confirms it;
    files the index cannot read are loaded only if no readable one matches (raising their error).
    The plug-ins' folders are read only when no shipped or user profile matches."""
    found = _lookup_in(match, profile_index(plugins=False))
    if found is not None:
        return found
    from profidrive_cli.drives.registry import plugins
    return _lookup_in(match, profile_index()) if plugins() else None


def _lookup_in(match: Callable[[IndexEntry], bool], entries: list[IndexEntry]) -> Profile | None:
    for e in entries:
        if match(e):
            p = _load_cached(e.path)
            if match(IndexEntry(e.path, p.name, tuple(p.aliases), p.family, p.ident)):
                return p
    for e in entries:
        if e.name is None:
            p = _load_cached(e.path)        # raises: a file the index cannot read does not load
            if match(IndexEntry(e.path, p.name, tuple(p.aliases), p.family, p.ident)):
                return p
    return None


def load_profile(name: str) -> Profile:
    """By profile name, alias, or a path to a .yaml file. Loads only that profile's file."""
    if name.endswith((".yaml", ".yml")) or "/" in name:
        return load_profile_file(name)
    key = name.lower()
    p = _lookup(lambda e: e.answers_to(key))
    if p is not None:
        return p
    known = ", ".join(sorted(e.name for e in profile_index() if e.name))
    from profidrive_cli import UsageError
    raise UsageError(f"unknown profile '{name}' (known: {known or 'none'})")


def foreign_profiles_with_code(code: str, profile: Profile) -> list[Profile]:
    """The profiles of families other than `profile`'s that have the parameter `code` (case-blind):
    for the message that names the family a code belongs to."""
    c = code.strip().lower()
    return [p for p in all_profiles() if p.family != profile.family
            and any(k.lower() == c for k in p.parameters)]


def profile_for_ident(ident: int) -> Profile | None:
    """The first profile (by file name) with this PROFIBUS ident; None if none has it. Loads only
    that profile's file."""
    return _lookup(lambda e: e.name is not None and e.ident == ident)
