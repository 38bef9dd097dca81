"""A slave's cyclic data by module, from its GSD and its configuration (Chk_Cfg / Get_Cfg octets).

layout(gsd, cfg, user_prm) -> SlaveLayout: the configuration cut into modules (gsd/match.py: the
GSD's Module entries whose identifier octets give it; narrowed by the Set_Prm user data when known),
and for each module its name, its offset and length in the output area (master -> slave, the
Data_Exchange request) and in the input area (slave -> master, the response), its direction and unit
(byte / word, consistency: the identifier's, reference §3.2). Outputs and inputs are laid out in
configuration order, each direction on its own (reference §3.2: a module's output octets follow the
previous modules' outputs, its inputs their inputs).

SlaveLayout.split(direction, data) cuts a Data_Exchange request's or response's octets into per-module
values: slicing with offsets computed once, no GSD work per telegram.

What a GSD gives about the data themselves: the real files in ../shared/testdata/gsd say
`DPV1_Data_Types = 0` or nothing, i.e. no data types for the cyclic data; their modules carry only
identifier octets (the unit: byte or word, and consistency) and their parameters (Ext_User_Prm_Data,
which describe Set_Prm, not the cyclic data). A module's `Data_Area_Beg ... Data_Area_End` block (DP-V1,
for slave-to-slave data) is passed on as the file gives it (`data_areas`). So values are hex per
module with the unit (byte or word) the identifier gives; a slave's Set_Prm user data are read
with the GSD's names and texts by gsd/interp.py decode_user_prm (prm_rows below).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from profidrive_cli.dp.cfg import CfgError, CfgModule, decode_cfg
from profidrive_cli.gsd.match import MatchResult, match_cfg
from profidrive_cli.gsd.model import Gsd, Module

OUT, IN = "out", "in"


@dataclass(frozen=True)
class ModuleData:
    """One module of the configuration and where its data sit."""
    slot: int                        # 1-based position in the configuration
    name: str
    cfg: bytes
    out_offset: int
    out_len: int
    in_offset: int
    in_len: int
    unit: str                        # "byte", "word" or "mixed" (special format, per direction)
    consistent: bool
    candidates: tuple[str, ...] = ()     # every GSD module with these octets (after narrowing)
    data_areas: tuple[dict[str, Any], ...] = ()

    @property
    def short(self) -> str:
        """The name without the other modules that share its octets (the first GSD module's)."""
        return self.candidates[0] if self.candidates else self.name

    @property
    def direction(self) -> str:
        if self.out_len and self.in_len:
            return "in/out"
        return "out" if self.out_len else "in" if self.in_len else "none"

    def to_dict(self) -> dict[str, Any]:
        return {"slot": self.slot, "name": self.name, "cfg": self.cfg.hex(" "),
                "direction": self.direction, "out_offset": self.out_offset, "out_len": self.out_len,
                "in_offset": self.in_offset, "in_len": self.in_len, "unit": self.unit,
                "consistent": self.consistent, "candidates": list(self.candidates)}


@dataclass
class SlaveLayout:
    cfg: bytes
    modules: tuple[ModuleData, ...]
    ident: int | None = None
    gsd_path: str | None = None
    title: str | None = None
    user_prm: bytes | None = None
    notes: list[str] = field(default_factory=list)
    gsd: Gsd | None = field(default=None, repr=False)
    gsd_modules: tuple[Module, ...] = field(default=(), repr=False)   # the best fit's first candidates
    _cuts: dict[str, tuple[tuple[ModuleData, int, int], ...]] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        self._cuts[OUT] = tuple((m, m.out_offset, m.out_offset + m.out_len) for m in self.modules if m.out_len)
        self._cuts[IN] = tuple((m, m.in_offset, m.in_offset + m.in_len) for m in self.modules if m.in_len)

    @property
    def output_len(self) -> int:
        return sum(m.out_len for m in self.modules)

    @property
    def input_len(self) -> int:
        return sum(m.in_len for m in self.modules)

    def split(self, direction: str, data: bytes) -> list[tuple[ModuleData, bytes]]:
        """The octets of a Data_Exchange request (direction "out" / "request") or response ("in" /
        "response") per module, in configuration order; a short area gives the modules it reaches."""
        cuts = self._cuts[OUT if direction in (OUT, "request") else IN]
        return [(m, data[a:b]) for m, a, b in cuts if a < len(data)]

    def describe(self) -> list[str]:
        out = []
        for m in self.modules:
            where = []
            for d, off, n in ((OUT, m.out_offset, m.out_len), (IN, m.in_offset, m.in_len)):
                if n:
                    where.append(f"{d} octet {off}" if n == 1 else f"{d} octets {off}-{off + n - 1}")
            unit = f" (unit: {m.unit}" + (", consistent)" if m.consistent else ")") if where else ""
            out.append(f"slot {m.slot} {m.name!r} [{m.cfg.hex(' ')}]: " + (", ".join(where) or "no data") + unit)
        return out + [f"note: {n}" for n in self.notes]

    def to_dict(self) -> dict[str, Any]:
        return {"cfg": self.cfg.hex(" "), "gsd": self.gsd_path, "outputs": self.output_len,
                "inputs": self.input_len, "modules": [m.to_dict() for m in self.modules],
                "notes": list(self.notes)}

    def prm_rows(self) -> tuple[list[dict[str, Any]], list[str]]:
        """The Set_Prm user data read with the GSD's names and texts (empty without GSD or user data)."""
        if self.gsd is None or self.user_prm is None:
            return [], []
        from profidrive_cli.gsd.interp import decode_user_prm
        from profidrive_cli import UsageError
        try:
            return decode_user_prm(self.gsd, list(self.gsd_modules), self.user_prm)
        except UsageError as e:
            return [], [str(e)]


def _unit(ids: list[CfgModule]) -> tuple[str, bool]:
    units: set[str] = set()
    for c in ids:
        if c.special:
            units.update("word" if w else "byte" for w, n in ((c.out_words, c.outputs), (c.in_words, c.inputs))
                         if n and w is not None)
        elif not c.empty:
            units.add("word" if c.words else "byte")
    unit = units.pop() if len(units) == 1 else "mixed" if units else "byte"
    return unit, any(c.consistent for c in ids)


def layout(gsd: Gsd | None, cfg: bytes, user_prm: bytes | None = None) -> SlaveLayout:
    """The slave's cyclic data by module (see the module text). Without a GSD, or when no module
    sequence of the GSD gives `cfg`, each identifier is its own module, named by its octets.
    Raises dp.cfg.CfgError when `cfg` is not identifier octets."""
    cfg = bytes(cfg)
    decode_cfg(cfg)                                         # not identifiers: the caller says so
    notes: list[str] = []
    pieces: list[tuple[bytes, str, tuple[str, ...], tuple[dict[str, Any], ...]]] = []
    chosen: list[Module] = []
    res: MatchResult | None = match_cfg(gsd, cfg, user_prm) if gsd is not None else None
    if res is not None and res.best is not None:
        for s in res.best.slots:
            pieces.append((s.cfg, s.name, tuple(m.display_name for m in s.candidates),
                           tuple(dict(a) for a in s.candidates[0].data_areas) if s.candidates else ()))
            chosen.append(s.candidates[0])
        if len(res.fits) > 1:
            notes.append(f"{len(res.fits)} module sequences give these octets; shown: the one with the "
                         "fewest modules")
    else:
        if res is not None:
            notes += res.describe()
        elif gsd is None:
            notes.append("no GSD: one module per identifier")
        for c in decode_cfg(cfg):
            pieces.append((c.raw, f"identifier {c.raw.hex(' ')}", (), ()))
    mods: list[ModuleData] = []
    o = i = 0
    for n, (raw, name, cands, areas) in enumerate(pieces, 1):
        ids = decode_cfg(raw)
        outs, ins = sum(c.outputs for c in ids), sum(c.inputs for c in ids)
        unit, consistent = _unit(ids)
        mods.append(ModuleData(n, name, raw, o, outs, i, ins, unit, consistent, cands, areas))
        o += outs
        i += ins
    return SlaveLayout(cfg=cfg, modules=tuple(mods), ident=None if gsd is None else gsd.ident_number,
                       gsd_path=None if gsd is None else gsd.path, title=None if gsd is None else gsd.title,
                       user_prm=None if user_prm is None else bytes(user_prm), notes=notes, gsd=gsd,
                       gsd_modules=tuple(chosen))


def values(lay: SlaveLayout, direction: str, data: bytes) -> list[dict[str, Any]]:
    """split() as JSON-ready rows: slot, name, offset, octets (lower-case hex)."""
    d = OUT if direction in (OUT, "request") else IN
    return [{"slot": m.slot, "name": m.short, "offset": m.out_offset if d == OUT else m.in_offset,
             "octets": v.hex(" ")} for m, v in lay.split(d, data)]


__all__ = ["IN", "OUT", "CfgError", "ModuleData", "SlaveLayout", "layout", "values"]
