"""Dump and compare, for session/parameters.py (Parameters.dump_plan / dump / compare call these with
the Parameters, through its public API: params.ParamView): which parameters of the profile the
connected station has and which of them are settings (restored) or read-only / excluded (read, never
restored); reading them all into a YAML-ready document with the station's identity (dumpfile.py:
format, end marker); comparing a loaded file row by row against the drive (ParamRow). Reads
parameters only; never writes (restore.py does).
"""

from __future__ import annotations

import time
from typing import Any, Callable

from profidrive_cli import BusError, UsageError
from profidrive_cli.drives.base import DriveError
from profidrive_cli.drives.profile import load_profile
from profidrive_cli.session.discovery import family_words
from profidrive_cli.session.dumpfile import DUMP_END, DUMP_FORMAT
from profidrive_cli.datafile import LineDict
from profidrive_cli.session.paramtypes import ParamRow, ParamView

__all__ = ["BUS_SETTING", "CARD_MANUAL", "NO_DEFAULT", "ParamRow", "compare", "default_source", "dump",
           "dump_plan", "factory_diff", "nothing_compared", "same_value"]

#: the reason of a factory-diff row whose parameter has no `default:` in the profile
NO_DEFAULT = "no factory default known"
#: the reason of a factory-diff row that holds the manual's setting for control over the bus
BUS_SETTING = "the manual's setting for control over the field bus (bus_settings)"


def same_value(a: Any, b: Any, scale: float | None) -> bool:
    try:
        fa, fb = float(a), float(b)
    except (TypeError, ValueError):
        return bool(a == b)
    tol = abs(scale) / 2.0 if scale else 1e-9
    return abs(fa - fb) <= max(tol * 0.999, 1e-9)


def dump_plan(params: ParamView) -> list[tuple[str, Any, str]]:
    """(code, ParamDef, kind) for every parameter of the profile that the family can read:
    kind 'setting' (restored), 'readonly', or 'excluded: why' (read, never restored)."""
    out: list[tuple[str, Any, str]] = []
    d = params.need_drive()
    for p in params.profile.parameters.values():
        if p.access == "wo":
            continue
        if not d.dumpable(p):
            continue
        if p.extra.get("traceback"):
            continue                          # Toyo traceback channels: 4 x 100 samples each
        if not d.on_device(p):
            continue
        kind = "setting" if p.writable else "readonly"
        why = d.not_restored(p)
        if why and p.writable:
            kind = f"excluded: {why}"
        arr = p.extra.get("array")
        if isinstance(arr, int) and not isinstance(arr, bool) and arr > 1:
            if p.writable and not why:
                for i in range(1, arr + 1):
                    out.append((f"{p.code}[{i}]", p, kind))
            continue                           # read-only arrays (fault memory): `pdrive faults`
        out.append((p.code, p, kind))
    return out


def not_dumped(params: ParamView) -> dict[str, Any] | None:
    """The profile's settings no dump can hold, because the family has no address to read them by
    (Drive.dumpable), and why (Drive.not_dumpable_why): {"why": ..., "codes": [...]}, or None. A dump
    without them says so, so that `count: 0` is not read as a drive without settings."""
    d = params.need_drive()
    codes = [p.code for p in params.profile.parameters.values()
             if p.writable and p.access != "wo" and not d.dumpable(p)]
    return {"why": d.not_dumpable_why(), "codes": codes} if codes else None


def factory_default(p: Any) -> float | int | None:
    """The factory setting the profile records for a ParamDef (`default:`, from the manual), or None."""
    d = getattr(p, "default", None)
    return d if isinstance(d, (int, float)) and not isinstance(d, bool) else None


#: the source of a factory default the profile gives without `default_source:` (the card's manual)
CARD_MANUAL = "card manual"


def default_source(profile: Any, code: str) -> str | None:
    """Where the factory default of `code` (or CODE[i]) comes from: the profile's `default_source:`
    (e.g. "F7", "FRENIC": the host drive's manual, not the card's), else CARD_MANUAL; None when the
    profile records no default."""
    p = profile.param(code.split("[", 1)[0])
    if p is None or factory_default(p) is None:
        return None
    return str(p.extra.get("default_source") or CARD_MANUAL)


def nothing_compared(rows: list[ParamRow]) -> str | None:
    """Why factory_diff's rows compared no setting with a factory value (None: some were): then no
    verdict is possible, neither "changed" nor "at the factory defaults"."""
    if any(r.result in ("differs", "unchanged", "bus setting") for r in rows):
        return None
    if not rows:
        return "the bus reads none of this drive's settings (the profile gives none a parameter number)"
    unknown = sum(1 for r in rows if r.result == "unknown")
    if unknown:
        return f"no factory default known for any of its {unknown} readable settings"
    return "none of its settings could be read"


def factory_diff(params: ParamView, progress: Callable[[int, int, str], None] | None = None
                 ) -> list[ParamRow]:
    """Each setting of the station (dump_plan's writable rows) against its factory default from the
    profile: 'differs' / 'unchanged', 'bus setting' (differs from the factory default but holds the
    manual's setting for control over the bus, the profile's bus_settings: not counted as changed),
    'unknown' (reason NO_DEFAULT: the profile records none: never counted as changed), 'missing'
    (cannot be read). file_value is the factory default."""
    d = params.need_drive()
    if not d.has_param_channel:
        raise DriveError(no_channel_words(params))
    plan = [(c, p) for c, p, kind in dump_plan(params) if kind != "readonly"]
    rows: list[ParamRow] = []
    reads = d.read_many([code for code, _ in plan])
    for i, (code, p) in enumerate(plan):
        if progress:
            progress(i, len(plan), code)
        want = factory_default(p)
        pv = next(reads)[1]
        if isinstance(pv, (DriveError, UsageError)):
            if isinstance(pv, BusError) and not isinstance(pv, DriveError):
                raise pv
            rows.append(ParamRow(code, p.name, p.unit, want, None, "missing", str(pv)))
            continue
        name, unit = pv.name or p.name, pv.unit or p.unit
        if want is None:
            rows.append(ParamRow(code, name, unit, None, pv.value, "unknown", NO_DEFAULT))
            continue
        if same_value(pv.value, want, p.scale):
            rows.append(ParamRow(code, name, unit, want, pv.value, "unchanged"))
            continue
        bus = params.profile.bus_settings.get(code)
        if bus is not None and same_value(pv.value, bus, p.scale):
            rows.append(ParamRow(code, name, unit, want, pv.value, "bus setting", BUS_SETTING))
            continue
        rows.append(ParamRow(code, name, unit, want, pv.value, "differs"))
    if progress:
        progress(len(plan), len(plan), "")
    return rows


def dump(params: ParamView, progress: Callable[[int, int, str], None] | None = None,
         changed: bool = False) -> dict[str, Any]:
    """Read every readable parameter; a YAML-ready document with the station's identity. changed:
    only the settings whose value differs from the profile's factory default (`changed_only: true`;
    the settings without a known default listed under `no_factory_default`, no read-only values)."""
    d = params.need_drive()
    if not d.has_param_channel:
        raise DriveError(no_channel_words(params))
    plan = dump_plan(params)
    settings: dict[str, Any] = {}
    readonly: dict[str, Any] = {}
    failed: dict[str, str] = {}
    unknown: list[str] = []
    reads = d.read_many([code for code, _, kind in plan if not (changed and kind == "readonly")])
    for i, (code, p, kind) in enumerate(plan):
        if progress:
            progress(i, len(plan), code)
        if changed and kind == "readonly":
            continue                   # a monitor has no factory setting
        pv = next(reads)[1]
        if isinstance(pv, (DriveError, UsageError)):
            failed[code] = str(pv)
            continue
        if changed:
            want = factory_default(p)
            if want is None:
                unknown.append(code)
                continue
            if same_value(pv.value, want, p.scale):
                continue
        entry: dict[str, Any] = {"value": pv.value}
        if pv.unit:
            entry["unit"] = pv.unit
        entry["name"] = pv.name or p.name
        if changed:
            entry["factory"] = factory_default(p)
        if kind == "setting":
            settings[code] = entry
        else:
            if kind.startswith("excluded"):
                entry["not_restored"] = kind.split(": ", 1)[1]
            readonly[code] = entry
    if progress:
        progress(len(plan), len(plan), "")
    prof = params.profile
    doc: dict[str, Any] = {
        "pdrive_dump": DUMP_FORMAT,
        "station": {"address": params.address, "ident": f"0x{params.ident:04X}", "profile": prof.name,
                    "family": prof.family, "title": prof.title, "layout": params.layout,
                    "port": params.port},
        "date": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "count": len(settings),
        "parameters": settings,
        "readonly": readonly,
    }
    if changed:
        doc["changed_only"] = True
        doc["no_factory_default"] = unknown
    if failed:
        doc["unreadable"] = failed
    absent = not_dumped(params)
    if absent:
        doc["not_dumped"] = absent
    doc["end"] = DUMP_END              # the last line: a file cut anywhere lacks it
    return doc


def no_channel_words(params: ParamView) -> str:
    with_pkw = [n for n, lay in params.profile.layouts.items() if lay.pkw]
    return (f"{params.profile.name}: layout {params.layout} has no parameter channel"
            + (f" (use --ppo/--format {' | '.join(with_pkw)})" if with_pkw else ""))


def identity_notes(params: ParamView, doc: dict[str, Any]) -> list[str]:
    st = doc.get("station") or {}
    name = st.get("profile")
    notes = []
    if name and name != params.profile.name:
        try:
            other = load_profile(str(name))
        except UsageError:
            other = None
        if other is None or other.name != params.profile.name:
            raise UsageError(f"{doc.get('_path', 'the file')} was dumped from a {name} station "
                             f"({st.get('title', '')}); station {params.address} is "
                             f"{family_words(params.profile)}")
    if st.get("address") is not None and st.get("address") != params.address:
        notes.append(f"the file was dumped from station {st.get('address')}; writing to station "
                     f"{params.address}")
    return notes


def compare(params: ParamView, doc: dict[str, Any],
            progress: Callable[[int, int, str], None] | None = None,
            allow_dangerous: bool = False, check_identity: bool = True) -> list[ParamRow]:
    """Each parameter of the file against the drive: 'unchanged', 'differs', 'missing' (cannot
    be read), 'skipped' (unknown code / read-only / not restorable / dangerous; .why says which)."""
    d = params.need_drive()
    if not d.has_param_channel:
        raise DriveError(no_channel_words(params))
    if check_identity:
        for n in identity_notes(params, doc):
            params.warn(n)
    rows: list[ParamRow] = []
    entries = doc["parameters"]
    items = list(entries.items())
    for i, (code, v) in enumerate(items):
        if progress:
            progress(i, len(items), str(code))
        want = v.get("value") if isinstance(v, dict) else v
        # a loaded file knows each row's line (datafile.LineDict); a dict built in Python does not
        line = entries.line_of(code) if isinstance(entries, LineDict) else 0
        code = str(code)
        try:
            info = params.info(code)
        except UsageError as e:
            rows.append(ParamRow(code, "", "", want, None, "skipped", str(e), line=line or 0,
                                 why="unknown"))
            continue
        p = info.param
        base = code.split("[", 1)[0]
        pdef = params.profile.param(base) or p
        if pdef is not None:
            why = d.not_restored(pdef) if pdef.writable else "read-only"
            if why and not (allow_dangerous and why.startswith("dangerous")):
                kind = ("read-only" if why == "read-only" else
                        "dangerous" if why.startswith("dangerous") else "not restored")
                rows.append(ParamRow(code, info.name, info.unit, want, None, "skipped", why,
                                     line=line or 0, why=kind))
                continue
        try:
            pv = d.read_resolved(info)
        except (DriveError, UsageError) as e:
            if isinstance(e, BusError) and not isinstance(e, DriveError):
                raise
            rows.append(ParamRow(code, info.name, info.unit, want, None, "missing", str(e),
                                 line=line or 0))
            continue
        same = same_value(pv.value, want, pdef.scale if pdef is not None else None)
        rows.append(ParamRow(code, pv.name or info.name, pv.unit or info.unit, want, pv.value,
                             "unchanged" if same else "differs", line=line or 0))
    if progress:
        progress(len(items), len(items), "")
    return rows
