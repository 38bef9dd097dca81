"""The profile's `monitors:` and `trip_records:` sections: which of the card's parameters are its
monitor values (a default set per family for `run --monitor default`) and where it keeps the records
of its last trips (Moeller d081..d086, the Toyo traceback). Checked with file:line (DataFileError);
no bus traffic. Every code named here must be a code the family's drive can read (a profile
parameter, or a family address form such as Toyo's TB03[0,99]).

    monitors:
      default: [d002, d013, d012]        # codes, in display order
      words:                             # cyclic input words shown as monitors (Yaskawa fast I/O)
        output-current: {word: current, name: Output current, unit: "%", scale: 0.01220703125}
      cyclic:                            # parameters some layouts also carry in an input word (the
        dc-voltage: dc_voltage           # same value and scaling): read from that word there, through
                                         # the parameter channel elsewhere (Toyo PPO2/4/5, mode 1)
    trip_records:
      latest: PNU354                     # optional: which record is the newest
      latest_first: 0                    # optional: the value it shows for record 1 (default 1)
      empty: zero                        # zero: a record whose first field reads 0 is empty;
                                         # error: the first refused read ends the list
      records:                           # one list of codes per record, the first names the trip
        - {position: "1 (d081)", fields: [d081, PNU356, PNU357, PNU358]}
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Protocol

from profidrive_cli.datafile import DataFileError, LineDict, LineList


class _Coded(Protocol):
    @property
    def code(self) -> str: ...


class MonitoredProfile(Protocol):
    """What these readers use of a drives.profile.Profile (which imports this module: named here by
    its shape, not imported)."""
    @property
    def name(self) -> str: ...
    @property
    def family(self) -> str: ...
    @property
    def path(self) -> Path | None: ...
    @property
    def raw(self) -> LineDict: ...
    @property
    def layouts(self) -> Mapping[str, object]: ...
    def param(self, code: str) -> _Coded | None: ...


@dataclass
class MonitorWord:
    code: str
    word: str                     # the family's name of the input word (DriveStatus.raw key)
    name: str
    unit: str = ""
    scale: float = 1.0
    signed: bool = False


@dataclass
class MonitorConfig:
    default: list[str] = field(default_factory=list)
    words: dict[str, MonitorWord] = field(default_factory=dict)
    #: parameter code -> the family's input word that carries the same value (where a layout has it)
    cyclic: dict[str, str] = field(default_factory=dict)


@dataclass
class TripRecordSpec:
    position: str
    fields: list[str]


@dataclass
class TripRecordConfig:
    records: list[TripRecordSpec]
    latest: str | None = None
    empty: str = "zero"
    latest_first: int = 1


def _path(profile: MonitoredProfile) -> str | Path:
    return profile.path or "<profile>"


def _line(node: object, key: str | None = None) -> int | None:
    if key is not None and isinstance(node, LineDict):
        return node.line_of(key)
    return getattr(node, "line", None)


def _codes(profile: MonitoredProfile, node: object, key: str, items: object) -> list[str]:
    if not isinstance(items, list) or not all(isinstance(c, (str, int)) for c in items) or not items:
        raise DataFileError(_path(profile), _line(node, key), f"'{key}' must be a non-empty list of codes")
    return [str(c) for c in items]


def monitor_config(profile: MonitoredProfile) -> MonitorConfig:
    """The `monitors:` section (an empty default set when there is none)."""
    doc = profile.raw.get("monitors")
    if doc is None:
        return MonitorConfig()
    if not isinstance(doc, dict):
        raise DataFileError(_path(profile), _line(profile.raw, "monitors"), "'monitors' must be a mapping")
    for k in doc:
        if k not in ("default", "words", "cyclic"):
            raise DataFileError(_path(profile), _line(doc, k), f"monitors: unknown key '{k}'")
    words: dict[str, MonitorWord] = {}
    for code, w in (doc.get("words") or {}).items():
        if not isinstance(w, dict) or not isinstance(w.get("word"), str) \
                or not isinstance(w.get("scale", 1.0), (int, float)):
            raise DataFileError(_path(profile), _line(doc["words"], code),
                                f"monitors.words.{code}: {{word: NAME, name: TEXT, unit: U, scale: NUMBER}}")
        words[str(code)] = MonitorWord(str(code), w["word"], str(w.get("name", code)), str(w.get("unit", "")),
                                       float(w.get("scale", 1.0)), bool(w.get("signed", False)))
    cyclic: dict[str, str] = {}
    cy = doc.get("cyclic") or {}
    if not isinstance(cy, dict):
        raise DataFileError(_path(profile), _line(doc, "cyclic"), "monitors.cyclic: {CODE: INPUT_WORD, ...}")
    for code, word in cy.items():
        p = profile.param(str(code))
        if p is None or not isinstance(word, str):
            raise DataFileError(_path(profile), _line(cy, code),
                                f"monitors.cyclic.{code}: a parameter code of the profile and the name of "
                                f"the input word carrying it")
        cyclic[p.code] = word
    default = _codes(profile, doc, "default", doc.get("default"))
    return MonitorConfig(default, words, cyclic)


def cyclic_monitors(profile: MonitoredProfile, layout: str) -> dict[str, str]:
    """The `monitors.cyclic` parameters that `layout` carries in its input words: code -> word. The
    family module says which words a layout's input has (`input_words(profile, layout)`); none
    without it. No bus."""
    cyc = monitor_config(profile).cyclic
    if not cyc:
        return {}
    from profidrive_cli import UsageError
    from profidrive_cli.drives import codec_module
    try:
        fn = getattr(codec_module(profile), "input_words", None)
    except UsageError:
        return {}
    have = set(fn(profile, layout)) if fn is not None and layout in profile.layouts else set()
    return {c: w for c, w in cyc.items() if w in have}


def trip_record_config(profile: MonitoredProfile) -> TripRecordConfig | None:
    """The `trip_records:` section, or None: the card keeps no trip records."""
    doc = profile.raw.get("trip_records")
    if doc is None:
        return None
    where = _line(profile.raw, "trip_records")
    if not isinstance(doc, dict):
        raise DataFileError(_path(profile), where, "'trip_records' must be a mapping")
    for k in doc:
        if k not in ("latest", "latest_first", "empty", "records"):
            raise DataFileError(_path(profile), _line(doc, k), f"trip_records: unknown key '{k}'")
    empty = doc.get("empty", "zero")
    if empty not in ("zero", "error"):
        raise DataFileError(_path(profile), _line(doc, "empty"), "trip_records.empty: zero or error")
    recs = doc.get("records")
    if not isinstance(recs, list) or not recs:
        raise DataFileError(_path(profile), _line(doc, "records"), "trip_records.records: a non-empty list")
    out: list[TripRecordSpec] = []
    for i, r in enumerate(recs):
        line = recs.line_of(i) if isinstance(recs, LineList) else where
        if not isinstance(r, dict) or "fields" not in r:
            raise DataFileError(_path(profile), line, "trip record: {position: TEXT, fields: [CODE, ...]}")
        out.append(TripRecordSpec(str(r.get("position", i + 1)), _codes(profile, r, "fields", r["fields"])))
    latest = doc.get("latest")
    first = doc.get("latest_first", 1)
    if first not in (0, 1):
        raise DataFileError(_path(profile), _line(doc, "latest_first"), "trip_records.latest_first: 0 or 1")
    return TripRecordConfig(out, str(latest) if latest is not None else None, empty, first)
