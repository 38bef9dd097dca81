"""What a card can do, known before anything runs: the profile's `capabilities:` section.

    capabilities:
      quick_stop: {how: "CTW bit 2 OFF3, ramp with H56"}             # a mapping: the card can, on every layout
      torque: {layouts: [ppo2, ppo4, ppo5, toyo], reason: "..."}      # only on these layouts; `reason` for others
      quick_stop: {needs: yaskawa.fast_stop_input, reason: "..."}     # only when that profile key is set
      jog: "the card has no jog (CTW bits 8/9 not used, spec 4.1)"   # a text: the card cannot, and why

Names (CAPABILITIES): quick_stop, coast_stop, jog, torque, torque_limit, param_channel, monitor_words.
param_channel defaults to the layouts with `pkw: true`. Other keys of a mapping are details for the code
that uses the capability (`how`, `param`, `words`, ...): Capabilities.detail(name).

API (profile.capabilities):
    name in caps / iter(caps) / caps.names   the names the card has on at least one layout
    caps.has(name, layout=None) -> bool      on this layout (None: on any layout)
    caps.why_not(name, layout=None) -> str | None   None when it can, else the one-line reason
    caps.refusal(name, layout=None) -> str | None   the sentence every refusal uses (CLI and checklist)
    caps.require(name, layout=None)          raise UsageError(refusal) (exit 2): for CLI options
    caps.layouts(name) -> tuple[str, ...]    the layouts where it can
    caps.detail(name) -> dict                the declaration's other keys
    caps.for_layout(layout) -> frozenset     the names the card has on that layout
Reads the profile only; no bus.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Mapping, Protocol

from profidrive_cli.datafile import DataFileError, LineDict


class LayoutLike(Protocol):
    """What the section reads of a drives.profile.Layout (profile.py imports this module)."""
    @property
    def pkw(self) -> bool: ...

#: capability name -> what it lets pdrive do (the words of a refusal: "<card> cannot <this>")
CAPABILITIES = {
    "quick_stop": "make a quick stop",
    "coast_stop": "make a coast stop",
    "jog": "jog",
    "torque": "run on a torque reference",
    "torque_limit": "take a torque limit",
    "param_channel": "read or write parameters",
    "monitor_words": "carry parameter words cyclically",
}
_DECL_KEYS = {"layouts", "needs", "reason"}


@dataclass
class Capability:
    name: str
    layouts: tuple[str, ...] | None = None      # None: every layout
    reason: str = ""                            # why not (the card, or the other layouts)
    detail: dict[str, Any] = field(default_factory=dict)   # the declaration's other keys (YAML values)
    capable: bool = True


@dataclass
class Capabilities:
    profile_name: str
    all_layouts: tuple[str, ...]
    decl: dict[str, Capability] = field(default_factory=dict)

    @property
    def names(self) -> frozenset[str]:
        return frozenset(n for n, c in self.decl.items() if c.capable and self.layouts(n))

    def __contains__(self, name: str) -> bool:
        return name in self.names

    def __iter__(self) -> Iterator[str]:
        return iter(sorted(self.names))

    def layouts(self, name: str) -> tuple[str, ...]:
        c = self.decl.get(name)
        if c is None or not c.capable:
            return ()
        return tuple(self.all_layouts if c.layouts is None else c.layouts)

    def has(self, name: str, layout: str | None = None) -> bool:
        return self.why_not(name, layout) is None

    def why_not(self, name: str, layout: str | None = None) -> str | None:
        if name not in CAPABILITIES:
            raise KeyError(f"unknown capability {name!r} (known: {', '.join(CAPABILITIES)})")
        c = self.decl.get(name)
        if c is None:
            return f"the profile declares no '{name}' capability"
        if not c.capable:
            return c.reason
        where = self.layouts(name)
        if layout is None:
            return None if where else c.reason
        if layout in where:
            return None
        return c.reason or f"only with layout {', '.join(where)}"

    def refusal(self, name: str, layout: str | None = None) -> str | None:
        """'<profile> (layout L) cannot <do it>: <reason>' or None when it can."""
        why = self.why_not(name, layout)
        if why is None:
            return None
        on = f" (layout {layout})" if layout else ""
        return f"{self.profile_name}{on} cannot {CAPABILITIES[name]}: {why}"

    def require(self, name: str, layout: str | None = None) -> None:
        """UsageError (exit 2, before anything runs) with the refusal when the card cannot."""
        msg = self.refusal(name, layout)
        if msg is not None:
            from profidrive_cli import UsageError
            raise UsageError(msg)

    def detail(self, name: str) -> dict[str, Any]:
        c = self.decl.get(name)
        return dict(c.detail) if c is not None else {}

    def for_layout(self, layout: str) -> frozenset[str]:
        return frozenset(n for n in self.names if self.has(n, layout))


def _lookup(doc: object, dotted: str) -> Any:   # Any: a parsed YAML value
    node = doc
    for part in dotted.split("."):
        if not isinstance(node, dict) or part not in node:
            return None
        node = node[part]
    return node


def parse_capabilities(path: str | Path, doc: LineDict, name: str, layouts: Mapping[str, LayoutLike]) -> Capabilities:
    """The `capabilities:` section of a profile document, checked with file:line."""
    caps = Capabilities(name, tuple(layouts))
    sec = doc.get("capabilities")
    if sec is not None and not isinstance(sec, LineDict):
        raise DataFileError(path, doc.line_of("capabilities"), "'capabilities' must be a mapping")
    sec = sec or LineDict()
    for key, v in sec.items():
        line = sec.line_of(key)
        if key not in CAPABILITIES:
            raise DataFileError(path, line, f"capabilities: unknown capability {key!r} "
                                f"(known: {', '.join(CAPABILITIES)})")
        if isinstance(v, str):
            if not v.strip():
                raise DataFileError(path, line, f"capabilities.{key}: the reason must not be empty")
            caps.decl[key] = Capability(key, reason=v.strip(), capable=False)
            continue
        if v is None:
            v = LineDict()
        if not isinstance(v, dict):
            raise DataFileError(path, line, f"capabilities.{key}: a mapping (the card can) or a text "
                                "(why it cannot)")
        lay = v.get("layouts")
        if lay is not None:
            if not isinstance(lay, list) or not all(isinstance(x, str) for x in lay):
                raise DataFileError(path, line, f"capabilities.{key}.layouts must be a list of layout names")
            bad = [x for x in lay if x not in layouts]
            if bad:
                raise DataFileError(path, line, f"capabilities.{key}.layouts: {', '.join(bad)} not in "
                                    f"layouts ({', '.join(layouts)})")
            lay = tuple(lay)
        reason = v.get("reason", "")
        if not isinstance(reason, str):
            raise DataFileError(path, line, f"capabilities.{key}.reason must be a text")
        needs = v.get("needs")
        capable = True
        if needs is not None:
            if not isinstance(needs, str):
                raise DataFileError(path, line, f"capabilities.{key}.needs must name a profile key (a.b)")
            if not reason:
                raise DataFileError(path, line, f"capabilities.{key}: 'needs' wants a 'reason' for when "
                                    f"{needs} is not set")
            capable = _lookup(doc, needs) not in (None, "", False)
        if lay is not None and set(lay) != set(layouts) and not reason:
            reason = f"only with layout {', '.join(lay)}"
        caps.decl[key] = Capability(key, layouts=lay, reason=reason, capable=capable,
                                    detail={k: x for k, x in v.items() if k not in _DECL_KEYS})
    if "param_channel" not in caps.decl:
        with_pkw = tuple(n for n, lay in layouts.items() if lay.pkw)
        caps.decl["param_channel"] = Capability(
            "param_channel", layouts=with_pkw, capable=bool(with_pkw),
            reason=(f"no parameter channel in this layout (choose {' | '.join(with_pkw)})" if with_pkw
                    else "no layout has a parameter channel"))
    return caps
