"""A line of drives (`pdrive param fleet dump / diff`): the settings of several stations side by side.

Each station's settings come from a parameter dump (backup.dump through Parameters.dump, read live or
loaded from the files `param fleet dump` wrote, dumpfile.py); only the settings (`parameters:`) take
part, never the read-only values. compare() builds the matrix station x code:

* the odd values: per profile and code, the value a strict majority of that profile's stations holds
  is the majority; a station holding another value is odd. Without a strict majority (2 against 2)
  the code is `split` and no cell is odd;
* the golden file (optional, load_golden): the values every drive of the line must hold, with
  per-drive exceptions. A station whose value differs from the golden one (or that lacks the code)
  outside its exceptions is a violation; `pdrive param fleet diff` exits 1 on any.

Golden file (YAML, file:line errors):

    pdrive_golden: 1                 # optional marker
    profile: fuji-g1                 # optional: only stations of this profile are held to it
    parameters:                      # code: value, or code: {value: V} as in a dump
      F07: 5.0
      F08: {value: 6.0}
    except:                          # station: [codes] that station may hold otherwise
      9: [F07]

Two values are the same within half a step of the parameter's scale (backup.same_value). Reads
nothing from the bus itself: the CLI hands in the dumps (live or from files); no writes.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from profidrive_cli import UsageError
from profidrive_cli.datafile import DataFileError, LineDict, load_yaml
from profidrive_cli.drives.profile import Profile, load_profile
from profidrive_cli.session.backup import same_value
from profidrive_cli.session.dumpfile import load_dump
from profidrive_cli.session.paramtypes import suggest_codes

__all__ = ["Cell", "FleetDiff", "Golden", "StationSettings", "Violation", "compare", "dump_file_name",
           "from_dump", "load_dir", "load_golden", "parse_stations"]

Number = float | int


def parse_stations(text: str) -> list[int]:
    """'3-7,9' -> [3, 4, 5, 6, 7, 9] (bus addresses 0..125, each once); UsageError in one line."""
    out: list[int] = []
    for part in text.split(","):
        part = part.strip()
        m = re.fullmatch(r"(\d+)(?:\s*-\s*(\d+))?", part)
        if not m:
            raise UsageError(f"stations {text!r}: {part!r} is not an address or a range A-B "
                             f"(e.g. 3-7,9)")
        lo = int(m.group(1))
        hi = int(m.group(2)) if m.group(2) is not None else lo
        if hi < lo or hi > 125:
            raise UsageError(f"stations {text!r}: {part} is not a range of bus addresses 0..125")
        for a in range(lo, hi + 1):
            if a in out:
                raise UsageError(f"stations {text!r}: station {a} given twice")
            out.append(a)
    return out


def dump_file_name(station: int) -> str:
    """The file `param fleet dump` writes for a station in its directory."""
    return f"station-{station:03d}.yaml"


@dataclass(frozen=True)
class StationSettings:
    """One station's settings: code -> value (the dump's `parameters:`), with units and names."""
    station: int
    profile: str
    values: dict[str, Number]
    units: dict[str, str] = field(default_factory=dict)
    names: dict[str, str] = field(default_factory=dict)
    source: str = ""                   # the file, or '' for a live reading


def from_dump(doc: Mapping[str, Any], source: str = "") -> StationSettings:
    """A dump document (loaded or from Parameters.dump) -> StationSettings."""
    st = doc.get("station") or {}
    addr = st.get("address") if isinstance(st, Mapping) else None
    if isinstance(addr, bool) or not isinstance(addr, int):
        line = doc.line_of("station") if isinstance(doc, LineDict) else None
        raise DataFileError(source or "the dump", line, "the dump names no station address "
                            "('station: {address: N}'); dump it with `pdrive param fleet dump`")
    values: dict[str, Number] = {}
    units: dict[str, str] = {}
    names: dict[str, str] = {}
    for code, v in (doc.get("parameters") or {}).items():
        val = v.get("value") if isinstance(v, Mapping) else v
        if isinstance(val, bool) or not isinstance(val, (int, float)):
            continue                       # load_dump refuses these; a live dump has none
        values[str(code)] = val
        if isinstance(v, Mapping):
            units[str(code)] = str(v.get("unit", ""))
            names[str(code)] = str(v.get("name", ""))
    return StationSettings(addr, str(st.get("profile", "")), values, units, names, source)


def load_dir(directory: str | Path) -> list[StationSettings]:
    """Every *.yaml dump in `directory` (dumpfile.load_dump: file:line errors), sorted by station."""
    d = Path(directory)
    if not d.is_dir():
        raise UsageError(f"{d}: not a directory (give the directory `param fleet dump -o` wrote, or "
                         f"station addresses such as 3-7)")
    files = sorted(d.glob("*.yaml"))
    if not files:
        raise UsageError(f"{d}: no dump files (*.yaml); write them with `pdrive param fleet dump`")
    out: dict[int, StationSettings] = {}
    for f in files:
        s = from_dump(load_dump(f), str(f))
        if s.station in out:
            raise UsageError(f"{f}: station {s.station} again (also in {out[s.station].source}); keep "
                             f"one dump per station in {d}")
        out[s.station] = s
    return [out[a] for a in sorted(out)]


@dataclass(frozen=True)
class Golden:
    """The golden file: code -> value every drive must hold; station -> codes it may hold otherwise."""
    path: str
    values: dict[str, Number]
    exceptions: dict[int, frozenset[str]]
    profile: str | None = None
    #: code -> its line in the file (for the file:line of a code no profile of the line knows)
    lines: dict[str, int] = field(default_factory=dict)

    def check_codes(self, profile: Profile, held: str) -> None:
        """DataFileError (file:line) for a code `profile` has no setting of (unknown, or a read-only
        value, which a dump keeps outside `parameters:`): held to it, every station would show it
        'missing' and the line fail for a typing slip in the file. held: which stations, in words."""
        for code in self.values:
            p = profile.param(code.split("[", 1)[0])
            if p is not None and p.writable:
                continue
            if p is None:
                near = suggest_codes(profile, code)
                why = (f"{code}: {profile.name} has no parameter {code}"
                       + (f" (closest: {', '.join(near)})" if near else ""))
            else:
                why = f"{code} ({p.name}) is a read-only value of {profile.name}, not a setting"
            raise DataFileError(self.path, self.lines.get(code), f"{why}; the golden file holds {held} "
                                f"to it (fix the code, or name the profile with 'profile:')")


def _num(path: str, node: LineDict, key: Any) -> Number:
    v = node[key]
    val = v.get("value") if isinstance(v, Mapping) else v
    if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(val):
        raise DataFileError(path, node.line_of(key), f"{key}: the value must be a number, got {val!r}")
    return val


def load_golden(path: str | Path) -> Golden:
    """Read a golden file (module doc); DataFileError (file:line) for anything else."""
    p = str(path)
    doc = load_yaml(path, "golden file")
    if not isinstance(doc, LineDict) or not isinstance(doc.get("parameters"), LineDict):
        line = doc.line_of("parameters") if isinstance(doc, LineDict) else 1
        raise DataFileError(p, line, "not a golden file: it needs 'parameters:' as a mapping CODE: VALUE")
    known = {"pdrive_golden", "profile", "parameters", "except"}
    for k in doc:
        if k not in known:
            raise DataFileError(p, doc.line_of(k), f"unknown key '{k}' (known: {', '.join(sorted(known))})")
    params: LineDict = doc["parameters"]
    values = {str(code): _num(p, params, code) for code in params}
    prof = doc.get("profile")
    profile: str | None = None
    if prof is not None:
        if not isinstance(prof, str):
            raise DataFileError(p, doc.line_of("profile"), "'profile' must be a profile name")
        try:
            profile = load_profile(prof).name
        except UsageError as e:
            raise DataFileError(p, doc.line_of("profile"), str(e)) from None
    exc: dict[int, frozenset[str]] = {}
    node = doc.get("except")
    if node is not None:
        if not isinstance(node, LineDict):
            raise DataFileError(p, doc.line_of("except"), "'except' must be a mapping STATION: [CODES]")
        for st, codes in node.items():
            line = node.line_of(st)
            if isinstance(st, bool) or not isinstance(st, int) or not 0 <= st <= 125:
                raise DataFileError(p, line, f"except: {st!r} is not a station address 0..125")
            if isinstance(codes, str):
                codes = [codes]
            if not isinstance(codes, list) or not all(isinstance(c, str) for c in codes):
                raise DataFileError(p, line, f"except: station {st}: give a list of codes")
            exc[st] = frozenset(codes)
    gold = Golden(p, values, exc, profile, {str(c): params.line_of(c) for c in params})
    if profile is not None:
        gold.check_codes(load_profile(profile), f"every {profile} station")
    return gold


@dataclass
class Cell:
    """One station's value of one code; odd: it differs from its profile's majority."""
    value: Number | None               # None: the station has no such setting (or could not read it)
    odd: bool = False
    golden: Number | None = None       # the golden value where the golden file holds one for it
    violation: str = ""                # '', 'differs from the golden file', 'missing'
    excepted: bool = False             # differs from the golden value, listed under except:


@dataclass(frozen=True)
class Violation:
    station: int
    code: str
    value: Number | None
    golden: Number
    why: str


@dataclass
class FleetDiff:
    """The matrix station x code (cells[code][station]) with the odd values and the golden check."""
    stations: list[StationSettings]
    codes: list[str]
    cells: dict[str, dict[int, Cell]]
    majority: dict[str, dict[str, Number]]          # profile -> code -> the majority value
    split: list[tuple[str, str]]                     # (profile, code) without a strict majority
    violations: list[Violation]
    golden: Golden | None = None

    @property
    def odd(self) -> list[tuple[int, str]]:
        """(station, code) of every odd value, by code then station."""
        return [(a, c) for c in self.codes for a, cell in self.cells[c].items() if cell.odd]

    def to_dict(self) -> dict[str, Any]:
        return {
            "stations": [{"station": s.station, "profile": s.profile, "source": s.source}
                         for s in self.stations],
            "codes": self.codes,
            "matrix": {c: {str(a): {"value": cell.value, "odd": cell.odd,
                                    **({"golden": cell.golden} if cell.golden is not None else {}),
                                    **({"violation": cell.violation} if cell.violation else {}),
                                    **({"excepted": True} if cell.excepted else {})}
                           for a, cell in self.cells[c].items()} for c in self.codes},
            "majority": self.majority,
            "odd": [{"station": a, "code": c} for a, c in self.odd],
            "split": [{"profile": p, "code": c} for p, c in self.split],
            "golden": self.golden.path if self.golden else None,
            "violations": [{"station": v.station, "code": v.code, "value": v.value, "golden": v.golden,
                            "why": v.why} for v in self.violations],
        }


def _scale_of(profiles: dict[str, Profile | None], name: str, code: str) -> float | None:
    prof = profiles.get(name)
    if prof is None:
        return None
    p = prof.param(code.split("[", 1)[0])
    return float(p.scale) if p is not None else None


def _profile(name: str) -> Profile | None:
    try:
        return load_profile(name) if name else None
    except UsageError:
        return None


def compare(sets: list[StationSettings], golden: Golden | None = None) -> FleetDiff:
    """The matrix of `sets` (one per station), its odd values per profile, the golden check."""
    profiles = {s.profile: _profile(s.profile) for s in sets}
    codes: list[str] = []
    for s in sets:
        codes += [c for c in s.values if c not in codes]
    if golden is not None:
        codes += [c for c in golden.values if c not in codes]
    cells: dict[str, dict[int, Cell]] = {c: {s.station: Cell(s.values.get(c)) for s in sets} for c in codes}
    majority: dict[str, dict[str, Number]] = {}
    split: list[tuple[str, str]] = []
    for name in profiles:
        members = [s for s in sets if s.profile == name]
        for c in codes:
            held = [(s.station, s.values[c]) for s in members if c in s.values]
            if len(held) < 2:
                continue
            scale = _scale_of(profiles, name, c)
            groups: list[list[tuple[int, Number]]] = []
            for a, v in held:
                g = next((g for g in groups if same_value(g[0][1], v, scale)), None)
                if g is None:
                    groups.append([(a, v)])
                else:
                    g.append((a, v))
            best = max(groups, key=len)
            if len(groups) == 1:
                majority.setdefault(name, {})[c] = best[0][1]
            elif 2 * len(best) > len(held):
                majority.setdefault(name, {})[c] = best[0][1]
                for a, _ in held:
                    if all(a != b for b, _ in best):
                        cells[c][a].odd = True
            else:
                split.append((name, c))
    violations: list[Violation] = []
    if golden is not None and golden.profile is None:
        for name, prof in profiles.items():
            if prof is not None:
                who = ", ".join(str(s.station) for s in sets if s.profile == name)
                golden.check_codes(prof, f"station(s) {who} ({prof.name})")
    if golden is not None:
        gname = golden.profile
        for s in sets:
            prof = profiles.get(s.profile)
            if gname is not None and (prof is None or prof.name != gname):
                continue
            allowed = golden.exceptions.get(s.station, frozenset())
            for c, want in golden.values.items():
                cell = cells[c][s.station]
                cell.golden = want
                if cell.value is not None and same_value(cell.value, want, _scale_of(profiles, s.profile, c)):
                    continue
                why = "missing" if cell.value is None else "differs from the golden file"
                if c in allowed:
                    cell.excepted = True
                    continue
                cell.violation = why
                violations.append(Violation(s.station, c, cell.value, want, why))
    return FleetDiff(sets, codes, cells, majority, split, violations, golden)
