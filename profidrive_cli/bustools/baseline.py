"""The accepted network and what changed since (issue 27: `pdrive scan --save FILE`, `scan --compare FILE`,
the checklist step `baseline`).

A NetworkRecord is what a scan finds, per station: its FDL type, ident, Get_Cfg, how many requests it
left unanswered before its first answer (warm-up), the bus counters of the measurement and its reply
time. measure() takes one on a master (the only part that talks to the bus); everything else is
sans-IO: to_doc() / from_doc() turn a record into the file's mapping and back (file:line for every
problem), dumps() / load() read and write the file (YAML for .yaml/.yml, JSON otherwise), compare()
says what differs between a baseline and a new record.

Not recorded: the Set_Prm / Chk_Cfg a master sends, as seen on the line when listening (issue 27's
"Prm/Cfg seen on the line"): a scan only asks, and its Get_Cfg is the configuration the station
reports.

Reply time: the shortest of REPLY_READS Slave_Diag round trips (the request handed to the link to
the whole reply read, on the link's clock), taken only from reads answered without a retry: the
shortest is the station's own time plus the adapter's, the longer ones add what else the machine did.

The margins (Margins, decision; the checklist step and docs/commands.md state them):
    counters    retries, no_answer (without the warm-up's unanswered FDL status requests), illegal,
                rs, rr, ue rise during the measurement: a difference when a counter is above the
                baseline's by more than COUNTER_MARGIN = 1 (a scan asks each station a handful of
                times; one spurious retry is noise, two are a pattern)
    reply time  a difference when it is longer than the baseline's by more than REPLY_MARGIN_MS = 5 ms
                and by more than REPLY_MARGIN_RATIO = 50 % of it (5 ms: a USB adapter's latency
                timer set to 1 ms plus scheduling; 50 %: a change of the station's own TSDR or of
                the adapter, not jitter)
Better figures (fewer errors, faster replies) are no difference. The warm-up count is recorded, not
compared: a slave answers late after its power-up only.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from profidrive_cli import BusError
from profidrive_cli.datafile import DataFileError, LineDict, LineList, load_yaml

FORMAT = 1
END = "pdrive_baseline"
#: the counters compared, in this order (keys of fdl.master.StationCounters)
COUNTER_KEYS = ("retries", "no_answer", "illegal", "rs", "rr", "ue")
COUNTER_MARGIN = 1
REPLY_MARGIN_MS = 5.0
REPLY_MARGIN_RATIO = 0.5
REPLY_READS = 3
STATION_KEYS = ("station", "type", "ident", "ident_hex", "cfg", "unanswered_before", "reply_ms",
                "counters")
TOP_KEYS = ("pdrive_baseline", "saved", "port", "baud", "master_address", "first", "last", "count",
            "stations", "end")
#: difference kinds, in the order a station's differences are listed
KINDS = ("missing", "new", "type", "ident", "cfg", "counter", "reply_time")


@dataclass(frozen=True)
class Margins:
    counter: int = COUNTER_MARGIN
    reply_ms: float = REPLY_MARGIN_MS
    reply_ratio: float = REPLY_MARGIN_RATIO

    def as_dict(self) -> dict[str, float]:
        return {"counter": self.counter, "reply_ms": self.reply_ms,
                "reply_percent": round(self.reply_ratio * 100.0, 3)}


@dataclass(frozen=True)
class StationRecord:
    address: int
    station_type: str
    ident: int | None = None
    cfg: bytes | None = None
    unanswered_before: int = 0
    reply_ms: float | None = None
    counters: dict[str, int] = field(default_factory=dict)

    def counter(self, key: str) -> int:
        """A compared counter; no_answer without the warm-up's unanswered requests."""
        n = int(self.counters.get(key, 0))
        if key == "no_answer":
            n = max(0, n - self.unanswered_before)
        return n


@dataclass(frozen=True)
class NetworkRecord:
    port: str
    baud: int
    master_address: int
    first: int
    last: int
    saved: str
    stations: tuple[StationRecord, ...]

    def station(self, address: int) -> StationRecord | None:
        return next((s for s in self.stations if s.address == address), None)


@dataclass(frozen=True)
class Difference:
    station: int
    kind: str                   # one of KINDS
    item: str                   # the counter for kind "counter", else ""
    baseline: Any               # the baseline's value (None: none)
    now: Any                    # the value now (None: none)
    text: str                   # in words, naming the station

    def as_dict(self) -> dict[str, Any]:
        return {"station": self.station, "kind": self.kind, "item": self.item,
                "baseline": self.baseline, "now": self.now, "text": self.text}


# -- comparing -------------------------------------------------------------------------------------


def _hex4(v: int | None) -> str:
    return "none" if v is None else f"0x{v:04X}"


def _octets(b: bytes | None) -> str | None:
    return None if b is None else b.hex(" ")


def _name(s: StationRecord) -> str:
    return f"station {s.address}" + (f" ({_hex4(s.ident)})" if s.ident is not None else
                                     f" ({s.station_type})")


def reply_worse(base_ms: float, now_ms: float, margins: Margins = Margins()) -> bool:
    """Longer than the baseline's by more than margins.reply_ms and by more than margins.reply_ratio."""
    more = now_ms - base_ms
    return more > margins.reply_ms and more > margins.reply_ratio * base_ms


def compare_station(b: StationRecord, n: StationRecord, margins: Margins = Margins()) -> list[Difference]:
    """What differs between one station's baseline and its record now (same address)."""
    a = b.address
    out: list[Difference] = []
    if b.station_type != n.station_type:
        out.append(Difference(a, "type", "", b.station_type, n.station_type,
                              f"station {a}: type {n.station_type}, baseline {b.station_type}"))
    if b.ident != n.ident:
        out.append(Difference(a, "ident", "", _hex4(b.ident), _hex4(n.ident),
                              f"station {a}: ident {_hex4(n.ident)}, baseline {_hex4(b.ident)}"))
    if b.cfg != n.cfg:
        out.append(Difference(a, "cfg", "", _octets(b.cfg), _octets(n.cfg),
                              f"station {a}: configuration (Get_Cfg) {_octets(n.cfg) or 'not read'}, "
                              f"baseline {_octets(b.cfg) or 'not read'}"))
    for k in COUNTER_KEYS:
        was, now = b.counter(k), n.counter(k)
        if now - was > margins.counter:
            out.append(Difference(a, "counter", k, was, now,
                                  f"station {a}: {k} {now}, baseline {was} (margin {margins.counter})"))
    if b.reply_ms is not None and n.reply_ms is not None and reply_worse(b.reply_ms, n.reply_ms, margins):
        out.append(Difference(a, "reply_time", "", b.reply_ms, n.reply_ms,
                              f"station {a}: reply time {n.reply_ms:.2f} ms, baseline {b.reply_ms:.2f} ms "
                              f"(margin {margins.reply_ms:g} ms and {margins.reply_ratio * 100:g} %)"))
    return out


def compare(base: NetworkRecord, now: NetworkRecord, margins: Margins = Margins()) -> list[Difference]:
    """Every difference, by address: a station missing now, a new one, and per station present in both
    compare_station(). [] when the network is as accepted."""
    out: list[Difference] = []
    addrs = sorted({s.address for s in base.stations} | {s.address for s in now.stations})
    for a in addrs:
        b, n = base.station(a), now.station(a)
        if n is None and b is not None:
            out.append(Difference(a, "missing", "", _hex4(b.ident), None, f"{_name(b)} is missing"))
        elif b is None and n is not None:
            out.append(Difference(a, "new", "", None, _hex4(n.ident), f"{_name(n)} is new"))
        elif b is not None and n is not None:
            out += compare_station(b, n, margins)
    return out


# -- the file --------------------------------------------------------------------------------------


def to_doc(rec: NetworkRecord) -> dict[str, Any]:
    """The file's mapping (the same keys in YAML and JSON; docs/json.md `scan save`)."""
    return {"pdrive_baseline": FORMAT, "saved": rec.saved, "port": rec.port, "baud": rec.baud,
            "master_address": rec.master_address, "first": rec.first, "last": rec.last,
            "count": len(rec.stations),
            "stations": [{"station": s.address, "type": s.station_type, "ident": s.ident,
                          "ident_hex": None if s.ident is None else f"0x{s.ident:04X}",
                          "cfg": _octets(s.cfg), "unanswered_before": s.unanswered_before,
                          "reply_ms": s.reply_ms, "counters": dict(s.counters)}
                         for s in rec.stations],
            "end": END}


def dumps(rec: NetworkRecord, path: str | Path) -> str:
    """The file's text: YAML for .yaml / .yml, JSON otherwise."""
    doc = to_doc(rec)
    if Path(path).suffix.lower() in (".yaml", ".yml"):
        import yaml
        text: str = yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=100)
        return "# pdrive scan --save: the accepted network (pdrive scan --compare FILE)\n" + text
    return json.dumps(doc, indent=2) + "\n"


def load(path: str | Path) -> NetworkRecord:
    """Read a baseline file; DataFileError (file:line, one line) for anything that is not one."""
    return from_doc(load_yaml(path, "baseline file"), path)


def _line(node: Any, key: str | None = None) -> int | None:
    if isinstance(node, LineDict):
        return node.line_of(key) if key is not None else node.line
    if isinstance(node, LineList):
        return node.line
    return None


def _int(d: Any, key: str, path: str | Path, lo: int, hi: int, null: bool = False) -> int | None:
    v = d.get(key)
    if v is None and null:
        return None
    if not isinstance(v, int) or isinstance(v, bool) or not lo <= v <= hi:
        raise DataFileError(path, _line(d, key), f"'{key}' must be a whole number {lo}..{hi}"
                            + (" or null" if null else "") + f", got {v!r}")
    return v


def _str(d: Any, key: str, path: str | Path) -> str:
    v = d.get(key)
    if not isinstance(v, str):
        raise DataFileError(path, _line(d, key), f"'{key}' must be text, got {v!r}")
    return v


def _mapping(v: Any, path: str | Path, line: int | None, what: str) -> LineDict:
    if not isinstance(v, LineDict):
        raise DataFileError(path, line, f"{what} must be a mapping, got {type(v).__name__}")
    return v


def _keys(d: LineDict, known: tuple[str, ...], path: str | Path, what: str) -> None:
    for k in d:
        if k not in known:
            raise DataFileError(path, d.line_of(k), f"unknown key {k!r} in {what} "
                                                    f"(known: {', '.join(known)})")


def _station(d: LineDict, path: str | Path) -> StationRecord:
    _keys(d, STATION_KEYS, path, "a station")
    for k in ("station", "type"):
        if k not in d:
            raise DataFileError(path, d.line, f"a station without '{k}'")
    addr = _int(d, "station", path, 0, 126)
    assert addr is not None
    ident = _int(d, "ident", path, 0, 0xFFFF, null=True)
    cfg_text = d.get("cfg")
    cfg: bytes | None = None
    if cfg_text is not None:
        try:
            cfg = bytes.fromhex(str(cfg_text))
        except ValueError:
            raise DataFileError(path, _line(d, "cfg"), f"'cfg' must be octets in hex (e.g. f3 f1) or "
                                                       f"null, got {cfg_text!r}") from None
    reply = d.get("reply_ms")
    if reply is not None and (not isinstance(reply, (int, float)) or isinstance(reply, bool)
                              or not math.isfinite(reply) or reply < 0):
        raise DataFileError(path, _line(d, "reply_ms"), f"'reply_ms' must be a number >= 0 or null, "
                                                        f"got {reply!r}")
    counters_doc = d.get("counters", LineDict())
    counters_map = _mapping(counters_doc, path, _line(d, "counters"), "'counters'")
    counters: dict[str, int] = {}
    for k in counters_map:
        n = _int(counters_map, k, path, 0, 2**63 - 1)
        assert n is not None
        counters[str(k)] = n
    unanswered = _int(d, "unanswered_before", path, 0, 2**31 - 1) if "unanswered_before" in d else 0
    assert unanswered is not None
    return StationRecord(addr, _str(d, "type", path), ident, cfg, unanswered,
                         None if reply is None else float(reply), counters)


def from_doc(doc: Any, path: str | Path) -> NetworkRecord:
    """A NetworkRecord from a loaded file; DataFileError (file:line) for anything that is not one."""
    top = _mapping(doc, path, 1, "a baseline file (pdrive scan --save)")
    fmt = top.get("pdrive_baseline")
    if fmt != FORMAT or isinstance(fmt, bool):
        raise DataFileError(path, _line(top, "pdrive_baseline") if "pdrive_baseline" in top else 1,
                            f"not a pdrive baseline (format {FORMAT}; written by pdrive scan --save), "
                            f"'pdrive_baseline: {fmt!r}'")
    _keys(top, TOP_KEYS, path, "the baseline")
    keys = list(top.keys())
    if top.get("end") != END or keys[-1] != "end":
        raise DataFileError(path, _line(top, "end") if "end" in top else None,
                            f"the file is incomplete (no final 'end: {END}' line): it was cut off")
    stations_doc = top.get("stations")
    if not isinstance(stations_doc, LineList):
        raise DataFileError(path, _line(top, "stations"), "'stations' must be a list")
    first = _int(top, "first", path, 0, 126)
    last = _int(top, "last", path, 0, 126)
    assert first is not None and last is not None
    if first > last:
        raise DataFileError(path, _line(top, "last"), f"'last' {last} is below 'first' {first}")
    stations: list[StationRecord] = []
    for i, item in enumerate(stations_doc):
        s = _station(_mapping(item, path, stations_doc.line_of(i), "a station"), path)
        if any(x.address == s.address for x in stations):
            raise DataFileError(path, stations_doc.line_of(i), f"station {s.address} listed twice")
        if not first <= s.address <= last:
            raise DataFileError(path, stations_doc.line_of(i),
                                f"station {s.address} outside first..last {first}..{last}")
        stations.append(s)
    count = _int(top, "count", path, 0, 127)
    if count != len(stations):
        raise DataFileError(path, _line(top, "count"), f"the file is incomplete or edited: 'count: "
                                                       f"{count}' but {len(stations)} station(s)")
    baud = _int(top, "baud", path, 1, 12_000_000)
    master = _int(top, "master_address", path, 0, 125)
    assert baud is not None and master is not None
    return NetworkRecord(_str(top, "port", path), baud, master, first, last, _str(top, "saved", path),
                         tuple(stations))


# -- measuring (the bus) ---------------------------------------------------------------------------


def _reply_ms(master: Any, address: int, reads: int) -> float | None:
    """The shortest Slave_Diag round trip of `reads`, answered without a retry (ms); None: none was."""
    from profidrive_cli.dp import services as S
    from profidrive_cli.fdl import frames as F
    from profidrive_cli.fdl.master import REPLY
    best: float | None = None
    for _ in range(reads):
        master.keep_alive(address)      # stations kept in data exchange first: not inside the timing
        t0 = master.link.now()
        out = master.transact(address, F.SRD_HIGH, b"", S.SAP_SLAVE_DIAG, S.SAP_MASTER, 250)
        t = (master.link.now() - t0) * 1000.0
        if out.kind == REPLY and out.frame is not None and not out.retries:
            best = t if best is None else min(best, t)
    return None if best is None else round(best, 3)


def measure(master: Any, first: int = 0, last: int = 126, *, port: str = "", saved: str = "",
            reads: int = REPLY_READS, quick: bool = False) -> NetworkRecord:
    """Scan first..last (dp/scan.py, with Get_Cfg), then time `reads` Slave_Diag of each slave. The
    counters are what rose during this measurement (a master that already talked to a station, e.g.
    the checklist's, counts from here). Stations the master keeps in data exchange stay cycled."""
    from profidrive_cli.dp.scan import scan
    before = {a: c.as_dict() for a, c in master.fdl.counters.items()}
    found = scan(master, first, last, read_cfg=True, quick=quick)
    stations = []
    for e in found:
        reply = None
        if e.station_type == "slave" and e.diag is not None:
            try:
                reply = _reply_ms(master, e.address, reads)
            except BusError:
                reply = None
        now = master.fdl.counters_for(e.address).as_dict()
        was = before.get(e.address, {})
        counters = {k: int(v) - int(was.get(k, 0)) for k, v in now.items() if isinstance(v, int)}
        stations.append(StationRecord(e.address, e.station_type, e.ident, e.cfg, e.unanswered, reply,
                                      counters))
    return NetworkRecord(port, int(master.params.baud), int(master.address), first, last, saved,
                         tuple(stations))


def only(rec: NetworkRecord, addresses: set[int]) -> NetworkRecord:
    """The record with only these stations (the checklist step's scope: station)."""
    return replace(rec, stations=tuple(s for s in rec.stations if s.address in addresses))


__all__ = ["COUNTER_KEYS", "Difference", "KINDS", "Margins", "NetworkRecord", "StationRecord", "compare",
           "compare_station", "dumps", "from_doc", "load", "measure", "only", "reply_worse", "to_doc"]
