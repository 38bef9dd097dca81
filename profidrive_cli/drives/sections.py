"""One typed reader for a profile's family sections: a declaration -> a frozen dataclass, errors file:line.

A family declares each section it reads as a frozen dataclass whose fields say, through `key(...)`,
the YAML key's kind, default, range and the exact words of its complaint; `read(Decl, path, node)`
checks the mapping against it and returns the instance, or raises datafile.DataFileError naming the
file and the line of the key (of the mapping, for a missing key). A field of kind "section" is a nested
mapping read the same way; `section(...)` reads one from its parent (missing / not a mapping).

    @dataclass(frozen=True)
    class Handshake:
        timeout_s: float = key("number", 1.0, gt=0)
        settle_cycles: int = key("int", 1, lo=1)

Kinds: "number" (int or float, not bool; read as float), "int", "bool", "text", "mapping" (a dict,
kept as is), "list", "texts" (a list of texts), "ints" (a list of integers, each in lo..hi), "section"
(nested declaration), "code" (a parameter code, text or number, kept as text: checked against the
profile's parameters when read() is given `codes`, with `code_msg`), "any" (not checked: kept as it
is); `choices=` narrows a value to a set,
`nonblank=True` a text to a non-blank one. Messages are str.format templates with {key}, {value}
(use {value!r}), {lo}, {hi}, {gt}, {choices}, {where} (the section's dotted path). What the
declaration cannot say key by key, one key against another, is a rule of the declaration: a class attribute
`RULES: ClassVar[tuple[tuple[Callable[[Decl], bool], str], ...]]`, each (holds, message) checked on the
read instance and reported on the section's line. What needs the rest of the profile (a key naming
one of its parameters) stays in the family's builder, which reads the instance and, for its own
complaints, `key_line(instance, name)`; a key that names one parameter is of kind "code".

May touch: datafile. Reads the profile's nodes only.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, TypeVar

from profidrive_cli.datafile import DataFileError, LineDict

T = TypeVar("T")

KINDS = ("number", "int", "bool", "text", "mapping", "list", "texts", "ints", "section", "code", "any")
_KIND_TEXT = {"number": "a number", "int": "an integer", "bool": "true or false", "text": "a text",
              "mapping": "a mapping", "list": "a list", "texts": "a list of texts",
              "ints": "a list of integers", "section": "a mapping", "code": "a parameter code",
              "any": "a value"}
#: read(codes=...): does the profile have this parameter code
Codes = Callable[[str], bool]


@dataclass(frozen=True)
class Key:
    """How one YAML key of a section is read (kept in the dataclass field's metadata)."""
    kind: str
    default: Any = None
    required: bool = False
    nullable: bool = False                  # `key: null` (or a missing key with default None) is None
    lo: float | None = None                 # inclusive range
    hi: float | None = None
    gt: float | None = None                 # strictly greater than
    choices: tuple[Any, ...] = ()           # the value must be one of these (range_msg, {choices})
    nonblank: bool = False                  # kind "text": not empty or only spaces (range_msg)
    type_msg: str = "'{key}' must be {kind_text}, got {value!r}"
    range_msg: str | None = None            # None: type_msg
    missing_msg: str = "missing field '{key}'"
    null_is_missing: bool = False           # a required `key: null` gets missing_msg (else type_msg)
    name: str | None = None                 # the YAML key, when it differs from the field's name
    section: type | None = None             # kind "section": the nested declaration
    unknown_msg: str | None = None          # kind "section": complain about keys it does not declare
    code_msg: str = "{where_dot}{key}: {value} is not a parameter of this profile"   # kind "code"


def key(kind: str, default: Any = None, **rules: Any) -> Any:
    """A dataclass field read from the YAML key of the same name (see Key for the rules)."""
    if kind not in KINDS:
        raise ValueError(f"unknown kind {kind!r}")
    spec = Key(kind, default, **rules)
    if spec.section is not None and default is None and not spec.nullable:
        return dataclasses.field(default_factory=spec.section, metadata={"key": spec})
    if isinstance(default, (dict, list)):
        return dataclasses.field(default_factory=lambda: type(default)(default), metadata={"key": spec})
    return dataclasses.field(default=default, metadata={"key": spec})


def line_dict(value: dict[Any, Any], line: int = 0) -> LineDict:
    """A plain dict (a profile built in code) as a LineDict without lines."""
    if isinstance(value, LineDict):
        return value
    ld = LineDict(value)
    ld.line, ld.key_lines = line, {}
    return ld


def line_of(node: object, name: object) -> int | None:
    if isinstance(node, LineDict):
        return node.line_of(name)
    line = getattr(node, "line", None)
    return line if isinstance(line, int) else None


def key_line(instance: object, name: str) -> int | None:
    """The line of `name` in the mapping `instance` was read from (of the mapping if the key is absent);
    None for an instance made in code or read from a mapping without lines."""
    node = getattr(instance, "_node", None)
    if node is None:
        return None
    return line_of(node, name) or None


def node_line(instance: object) -> int | None:
    """The line of the mapping `instance` was read from (None for one made in code)."""
    node = getattr(instance, "_node", None)
    return getattr(node, "line", None) or None


def section(decl: type[T], path: str | Path, parent: LineDict, name: str, *, required: bool = False,
            missing_msg: str = "missing section '{key}'", mapping_msg: str = "'{key}' must be a mapping",
            unknown_msg: str | None = None, where: str | None = None, codes: Codes | None = None) -> T:
    """The section `name` of `parent` read as `decl`; an absent one is the declaration's defaults
    (or, if required, `missing_msg` at the parent's line; `name: null` counts as absent then). A
    section inside another declaration is a field of kind "section" instead."""
    if name not in parent or (parent[name] is None and required):
        if required:
            raise DataFileError(path, parent.line or None, missing_msg.format(key=name))
        return decl()
    node = parent[name]
    if not isinstance(node, dict):
        raise DataFileError(path, line_of(parent, name), mapping_msg.format(key=name))
    return read(decl, path, line_dict(node), where=where or name, unknown_msg=unknown_msg, codes=codes)


def read(decl: type[T], path: str | Path, node: LineDict, *, where: str = "",
         unknown_msg: str | None = None, codes: Codes | None = None) -> T:
    """`node` read as the frozen dataclass `decl`: every declared key checked, file:line on a fault.
    unknown_msg (with {key}, {known}, {where}): keys `decl` does not declare are refused. codes: the
    profile's parameter codes (a predicate), for the keys of kind "code" (unchecked without it)."""
    fields = [f for f in dataclasses.fields(decl) if "key" in f.metadata]   # type: ignore[arg-type]
    if unknown_msg is not None:
        known = {f.metadata["key"].name or f.name for f in fields}
        for k in node:
            if k not in known:
                raise DataFileError(path, line_of(node, k), unknown_msg.format(
                    key=k, known=", ".join(sorted(known)), where=where))
    values = {f.name: _value(path, node, f.metadata["key"], f.metadata["key"].name or f.name, where, codes)
              for f in fields if (f.metadata["key"].name or f.name) in node or f.metadata["key"].required}
    out = decl(**values)
    object.__setattr__(out, "_node", node)          # for key_line(): the builder's own complaints
    for ok, message in getattr(decl, "RULES", ()):
        if not ok(out):
            raise DataFileError(path, node.line or None, message.format(where=where))
    return out


def _value(path: str | Path, node: LineDict, spec: Key, name: str, where: str, codes: Codes | None) -> Any:
    words = {"key": name, "kind_text": _KIND_TEXT[spec.kind], "lo": spec.lo, "hi": spec.hi,
             "gt": spec.gt, "where": where, "where_dot": f"{where}." if where else "",
             "choices": ", ".join(str(c) for c in spec.choices)}
    if name not in node or (node[name] is None and spec.null_is_missing):
        raise DataFileError(path, node.line or None, spec.missing_msg.format(**words))
    v = node[name]
    line = line_of(node, name)
    if v is None and spec.nullable:
        return None
    if spec.kind == "section":
        if not isinstance(v, dict):
            raise DataFileError(path, line, spec.type_msg.format(value=v, **words))
        assert spec.section is not None
        return read(spec.section, path, line_dict(v, line or 0), where=f"{where}.{name}" if where else name,
                    unknown_msg=spec.unknown_msg, codes=codes)
    if not _is_kind(v, spec.kind):
        raise DataFileError(path, line, spec.type_msg.format(value=v, **words))
    if not _allowed(v, spec):
        raise DataFileError(path, line, (spec.range_msg or spec.type_msg).format(value=v, **words))
    if spec.kind == "code":
        if codes is not None and not codes(str(v)):
            raise DataFileError(path, line, spec.code_msg.format(value=v, **words))
        return str(v)
    return float(v) if spec.kind == "number" else v


def _allowed(v: Any, spec: Key) -> bool:
    """A value of the right kind inside the declared choices, range or non-blankness."""
    if spec.choices and v not in spec.choices:
        return False
    if spec.kind in ("number", "int", "ints"):
        return all(_in_range(x, spec) for x in (v if spec.kind == "ints" else [v]))
    return not (spec.nonblank and not v.strip())


def _in_range(v: float, spec: Key) -> bool:
    return not ((spec.lo is not None and v < spec.lo) or (spec.hi is not None and v > spec.hi)
                or (spec.gt is not None and not v > spec.gt))


def _number(v: object) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _integer(v: object) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


#: kind -> does the YAML value have it ("section" is checked as a mapping before it is read)
_IS_KIND: dict[str, Callable[[object], bool]] = {
    "number": _number,
    "int": _integer,
    "bool": lambda v: isinstance(v, bool),
    "text": lambda v: isinstance(v, str),
    "mapping": lambda v: isinstance(v, dict),
    "list": lambda v: isinstance(v, list),
    "texts": lambda v: isinstance(v, list) and all(isinstance(x, str) for x in v),
    "ints": lambda v: isinstance(v, list) and all(_integer(x) for x in v),
    "code": lambda v: isinstance(v, str) or _integer(v),
    "any": lambda v: True,
}


def _is_kind(v: object, kind: str) -> bool:
    return _IS_KIND[kind](v)
