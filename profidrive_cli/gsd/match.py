"""Which GSD modules give a configuration (Chk_Cfg / Get_Cfg identifier octets): a sans-IO search over
one GSD's modules, for `pdrive gsd match` and the by-module view of a slave's cyclic data
(gsd/slavedata.py).

A modular slave's configuration is its modules' identifier octets one after the other (reference §3.2,
§5: Chk_Cfg = the selected modules' octets verbatim). So a fit is a cut of the octets into pieces, each
piece the exact octets of at least one GSD module; several modules often share their octets (an
ET 200S has dozens of modules with the one identifier 0x10), so each piece (a slot) carries every
module that fits it, in file order. A compact slave (Modular_Station = 0) has one fixed configuration:
the one module whose octets are the whole configuration.

The search is bounded: a backward pass marks the octet positions from which the end can be reached
(so no branch is a dead end), then a depth-first walk from the start takes longer pieces first and
stops after MAX_FITS cuts; `complete` says whether it saw them all. Fits with fewer slots come first,
and fits with more slots than the GSD's Max_Module are left out (kept only when nothing else fits).

When the slave's Set_Prm user data is known (sniff sees it; `gsd match --prm`), each slot's candidates
are narrowed to the modules whose own parameter block (Ext_Module_Prm_Data_Len and its constant
octets, gsd/interp.py module_prm_template) fits the octets at that slot's place.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

from profidrive_cli import UsageError
from profidrive_cli.dp.cfg import CfgError, decode_cfg
from profidrive_cli.gsd.model import Gsd, Module

#: the most cuts the search enumerates (each is a sequence of slots; every slot lists all its modules)
MAX_FITS = 32


@dataclass(frozen=True)
class Slot:
    """One piece of the configuration and the GSD modules whose octets are exactly that piece."""
    offset: int                        # octet offset within the configuration
    cfg: bytes
    candidates: tuple[Module, ...]     # file order; narrowed by Set_Prm when known

    @property
    def name(self) -> str:
        """The module's name, or the first candidate's with how many others share the octets."""
        if not self.candidates:
            return "?"
        first = self.candidates[0].display_name
        n = len(self.candidates) - 1
        return first if n == 0 else f"{first} (or {n} other{'s' if n > 1 else ''} with {self.cfg.hex(' ')})"

    def to_dict(self) -> dict[str, Any]:
        return {"offset": self.offset, "cfg": self.cfg.hex(" "),
                "modules": [{"index": m.index, "name": m.display_name} for m in self.candidates]}


@dataclass(frozen=True)
class Fit:
    """A cut of the configuration into slots, each with its candidate modules."""
    slots: tuple[Slot, ...]

    def names(self) -> list[str]:
        return [s.name for s in self.slots]

    def describe(self) -> str:
        return "; ".join(f"slot {i} {s.name!r} [{s.cfg.hex(' ')}]" for i, s in enumerate(self.slots, 1))


@dataclass
class MatchResult:
    gsd: Gsd
    cfg: bytes
    fits: list[Fit]
    complete: bool = True              # False: the search stopped at MAX_FITS
    unmatched_at: int | None = None    # no fit: the first octet no module sequence gets past
    problem: str | None = None         # the octets are not identifiers, or a compact slave differs
    notes: list[str] = field(default_factory=list)

    @property
    def best(self) -> Fit | None:
        return self.fits[0] if self.fits else None

    def describe(self) -> list[str]:
        """The result in lines: each fit, or why none fits."""
        title = f"{self.gsd.title} (ident {_ident(self.gsd.ident_number)})"
        if self.problem:
            return [f"{title}: {self.problem}"]
        if not self.fits:
            at = self.unmatched_at or 0
            return [f"{title}: no module sequence gives {self.cfg.hex(' ') or '(empty)'}; "
                    f"the octets from offset {at} ({self.cfg[at:].hex(' ')}) match no module"]
        out = [f"{title}: {len(self.fits)} fit{'s' if len(self.fits) != 1 else ''}"
               + ("" if self.complete else f" (the first {MAX_FITS}; the search stops there)")]
        out += [f"  {i}. {f.describe()}" for i, f in enumerate(self.fits, 1)]
        return out + [f"  note: {n}" for n in self.notes]

    def to_dict(self) -> dict[str, Any]:
        return {"cfg": self.cfg.hex(" "), "complete": self.complete, "unmatched_at": self.unmatched_at,
                "problem": self.problem, "notes": list(self.notes),
                "fits": [{"slots": [s.to_dict() for s in f.slots]} for f in self.fits]}


def _ident(v: int | None) -> str:
    return "-" if v is None else f"0x{v:04X}"


def match_cfg(gsd: Gsd, cfg: bytes, user_prm: bytes | None = None) -> MatchResult:
    """The GSD modules that give `cfg` (see the module text); `user_prm` (Set_Prm octets from 7 on)
    narrows each slot's candidates."""
    cfg = bytes(cfg)
    try:
        decode_cfg(cfg)
    except CfgError as e:
        return MatchResult(gsd, cfg, [], problem=f"the configuration is not identifier octets: {e}")
    by_cfg: dict[bytes, list[Module]] = {}
    for m in gsd.modules:
        if m.cfg:
            by_cfg.setdefault(bytes(m.cfg), []).append(m)
    if not gsd.modular_station:
        hits = by_cfg.get(cfg, [])
        if hits:
            res = MatchResult(gsd, cfg, [Fit((Slot(0, cfg, tuple(hits)),))])
        else:
            fixed = ", ".join(f"{m.display_name!r} [{m.cfg.hex(' ')}]" for m in gsd.modules[:8]) or "none"
            res = MatchResult(gsd, cfg, [], problem=f"a compact slave (Modular_Station = 0) with the "
                              f"fixed configuration(s) {fixed}; {cfg.hex(' ') or '(empty)'} is none of them")
        return _narrowed(res, user_prm)
    fits, complete, unmatched = _search(cfg, by_cfg)
    res = MatchResult(gsd, cfg, fits, complete, unmatched)
    mm = gsd.max_module
    if mm is not None and fits:
        within = [f for f in fits if len(f.slots) <= mm]
        if within:
            res.fits = within
        else:
            res.notes.append(f"every fit has more than Max_Module = {mm} modules")
    return _narrowed(res, user_prm)


def _search(cfg: bytes, by_cfg: dict[bytes, list[Module]]) -> tuple[list[Fit], bool, int | None]:
    n = len(cfg)
    lengths = sorted({len(k) for k in by_cfg}, reverse=True)
    reach = [False] * (n + 1)
    reach[n] = True
    for i in range(n - 1, -1, -1):
        reach[i] = any(i + k <= n and reach[i + k] and cfg[i:i + k] in by_cfg for k in lengths)
    if not reach[0]:
        got = {0}
        for i in range(n + 1):                     # how far a module sequence gets from the start
            if i in got:
                got.update(i + k for k in lengths if i + k <= n and cfg[i:i + k] in by_cfg)
        return [], True, max(got)
    fits: list[Fit] = []
    complete = True
    stack: list[tuple[int, tuple[Slot, ...]]] = [(0, ())]
    while stack:
        i, slots = stack.pop()
        if i == n:
            if len(fits) == MAX_FITS:
                complete = False
                break
            fits.append(Fit(slots))
            continue
        for k in reversed(lengths):                # pushed shortest first: the longest piece pops first
            piece = cfg[i:i + k]
            if i + k <= n and reach[i + k] and piece in by_cfg:
                stack.append((i + k, slots + (Slot(i, piece, tuple(by_cfg[piece])),)))
    fits.sort(key=lambda f: len(f.slots))
    return fits, complete, None


# ---------------------------------------------------------------- narrowing by Set_Prm
def _narrowed(res: MatchResult, user_prm: bytes | None) -> MatchResult:
    if user_prm is None or not res.fits:
        return res
    from profidrive_cli.gsd.interp import module_prm_template
    cache: dict[int, tuple[bytes, bytes] | None] = {}

    def template(m: Module) -> tuple[bytes, bytes] | None:
        if m.index not in cache:
            cache[m.index] = module_prm_template(res.gsd, m)
        return cache[m.index]

    try:
        from profidrive_cli.gsd.interp import device_user_prm
        start: int | None = len(device_user_prm(res.gsd))
    except UsageError:
        start = None
    res.fits = [_narrow_fit(f, bytes(user_prm), template, start) for f in res.fits]
    return res


def _fits_at(prm: bytes, pos: int, t: tuple[bytes, bytes]) -> bool:
    data, mask = t
    got = prm[pos:pos + len(data)]
    return len(got) == len(data) and all((a ^ b) & k == 0 for a, b, k in zip(got, data, mask))


def _narrow_fit(fit: Fit, prm: bytes, template: Any, start: int | None) -> Fit:
    """Module parameter blocks follow the device block in slot order and end with the user data. A
    forward pass over the octet positions (from the GSD's device block length; when no module
    sequence fits from there, from any position) keeps each slot's candidates whose block (length and
    constant octets) lies on a path to the end; a fit no path crosses is left as it was."""
    n = len(prm)
    for firsts in ([start] if start is not None and start <= n else [], list(range(n + 1))):
        if not firsts:
            continue
        layer = set(firsts)
        edges: list[list[tuple[int, Module, int]]] = []
        for s in fit.slots:
            e = []
            for pos in layer:
                for m in s.candidates:
                    t = template(m)
                    if t is not None and _fits_at(prm, pos, t):
                        e.append((pos, m, pos + len(t[0])))
            edges.append(e)
            layer = {q for _, _, q in e}
        if n not in layer:
            continue
        good = {n}
        kept: list[set[int]] = []
        for e in reversed(edges):
            on = [(p, m, q) for p, m, q in e if q in good]
            good = {p for p, _, _ in on}
            kept.append({m.index for _, m, _ in on})
        kept.reverse()
        return Fit(tuple(replace(s, candidates=tuple(m for m in s.candidates if m.index in k))
                         for s, k in zip(fit.slots, kept)))
    return fit


# ---------------------------------------------------------------- a refused configuration
def explain_refusal(gsd: Gsd, real_cfg: bytes, configured: bytes, user_prm: bytes | None = None
                    ) -> list[str]:
    """"The slave has these modules; you configured those": both configurations by module and the
    first slot where they part."""
    have = match_cfg(gsd, real_cfg, user_prm)
    want = match_cfg(gsd, configured)

    def words(r: MatchResult) -> str:
        f = r.best
        if f is None:
            try:
                ids = "; ".join(f"{c.raw.hex(' ')} = {c.describe()}" for c in decode_cfg(r.cfg))
            except CfgError as e:
                ids = str(e)
            return f"{r.cfg.hex(' ') or '(empty)'} (no module sequence of the GSD gives it: {ids or 'empty'})"
        return ", ".join(f"{s.name} [{s.cfg.hex(' ')}]" for s in f.slots)

    out = [f"the slave has these modules: {words(have)}",
           f"you configured those: {words(want)}"]
    if bytes(real_cfg) == bytes(configured):
        out.append("the two are the same octets: the slave's own configuration was sent")
        return out
    a, b = have.best, want.best
    if a is not None and b is not None:
        for i, (x, y) in enumerate(zip(a.slots, b.slots), 1):
            if x.cfg != y.cfg:
                out.append(f"they part at slot {i}: the slave has {x.name!r} [{x.cfg.hex(' ')}], "
                           f"the configuration says {y.name!r} [{y.cfg.hex(' ')}]")
                break
        else:
            more, fewer = (a, "the slave has") if len(a.slots) > len(b.slots) else (b, "you configured")
            extra = more.slots[min(len(a.slots), len(b.slots)):]
            out.append(f"{fewer} {len(extra)} more module(s): "
                       + ", ".join(f"{s.name!r} [{s.cfg.hex(' ')}]" for s in extra))
    return out


__all__ = ["MAX_FITS", "Fit", "MatchResult", "Slot", "explain_refusal", "match_cfg"]
