"""Data files pdrive reads: YAML with line numbers, and the one bounded way to read an input file.

Every complaint says file:line in one line. `read_input_file` is the only way pdrive reads a file it is
given (checklists, parameter files, profiles, GSD files, raw captures): a regular file of sane size,
never a device or a FIFO. `load_yaml_text` is the only way it reads YAML: yaml.SafeLoader construction,
with limits (size, nesting depth, digits of a number), aliases refused, and every construction error
(`!!float x`, a bad `!!timestamp`, ...) reported as file:line. Mappings load as LineDict and sequences
as LineList; both remember the line of the node and of each key / item (1-based).

Speed: when PyYAML has libyaml, its C parser (yaml._yaml.CParser) makes the events; a plain document
(no tags, anchors or merge keys) goes straight from the events to the data (`_direct_data`), anything
else through the same Python composer and constructors as the pure loader. The limits, the refusal of
aliases, the data and the line numbers are the same either way (tests/test_yaml_loaders.py checks
every shipped profile and example checklist); the five profiles load in 21 ms instead of 281 ms.
A text libyaml itself refuses (its own nesting limit or syntax check, whose words and limits change
with its version) is parsed again by the pure loader, so the answer is always pdrive's (_LIBYAML_ERRORS).
Without libyaml, or with PDRIVE_PURE_YAML=1 in the environment, the pure-Python parser is used.
`load_yaml_head` reads only the first top-level keys of a file (the profile index).
"""

from __future__ import annotations

import os
import re
import reprlib
import stat
from pathlib import Path
from types import TracebackType
from typing import IO, TYPE_CHECKING, Any, Iterable, Literal

import yaml
from yaml.composer import Composer
from yaml.constructor import SafeConstructor
from yaml.resolver import Resolver

from profidrive_cli import UsageError

try:                                    # libyaml's event parser, when PyYAML was built with it
    from yaml._yaml import CParser as _CParser
except ImportError:                     # pragma: no cover - depends on the PyYAML build
    _CParser = None

# limits for YAML data files (checklists, parameter dumps, profiles): the largest real one is ~30 kB
MAX_YAML_BYTES = 4 * 1024 * 1024
MAX_YAML_DEPTH = 64
MAX_NUMBER_CHARS = 100          # a scalar resolved as a number longer than this is refused
MAX_MESSAGE_CHARS = 400         # a DataFileError message is cut to this, and kept on one line

_short = reprlib.Repr()
_short.maxstring = 80
_short.maxother = 80
_short.maxlong = 40


def short(value: Any) -> str:
    """repr() of a value for an error message: at most about 80 characters."""
    return _short.repr(value)


def _one_line(message: str, limit: int = MAX_MESSAGE_CHARS) -> str:
    m = message.replace("\r", "\\r").replace("\n", "\\n")
    if len(m) > limit:
        m = m[:limit - 25] + f"... ({len(m)} characters)"
    return m


class DataFileError(UsageError):
    def __init__(self, path: str | Path, line: int | None, message: str):
        self.path = str(path)
        self.line = line
        self.message = _one_line(message)
        path_text = _one_line(self.path, 200)
        where = f"{path_text}:{line}" if line else path_text
        super().__init__(f"{where}: {self.message}")


# ------------------------------------------------------------------------------------------------ files


def read_input_file(path: str | Path, what: str = "file", max_bytes: int = MAX_YAML_BYTES) -> bytes:
    """The bytes of a regular file of at most max_bytes. DataFileError (one line: the path, what was
    expected, why not) for a missing or unreadable path, a folder, a device, a FIFO or socket (never
    opened: a FIFO would block), or a file that is too large."""
    p = Path(path)
    with open_input_file(p, what, max_bytes) as fh:
        try:
            data: bytes = fh.read(max_bytes + 1)
        except OSError as e:
            raise DataFileError(p, None, f"cannot read {what}: {e.strerror or e}") from None
    if len(data) > max_bytes:
        raise DataFileError(p, None, f"too large for a {what}: more than {max_bytes} bytes")
    return data


def open_input_file(path: str | Path, what: str = "file", max_bytes: int = MAX_YAML_BYTES) -> IO[bytes]:
    """read_input_file's checks, then the file open for reading (binary; the caller closes it):
    for reading a large input in chunks."""
    p = Path(path)
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise DataFileError(p, None, "file not found") from None
    except OSError as e:
        raise DataFileError(p, None, f"cannot read {what}: {e.strerror or e}") from None
    except ValueError as e:        # embedded NUL in the path
        raise DataFileError(repr(str(p)), None, f"bad path: {e}") from None
    if stat.S_ISDIR(st.st_mode):
        raise DataFileError(p, None, f"is a folder, not a {what}")
    if not stat.S_ISREG(st.st_mode):
        kind = ("a FIFO" if stat.S_ISFIFO(st.st_mode) else "a device" if stat.S_ISCHR(st.st_mode)
                or stat.S_ISBLK(st.st_mode) else "a socket" if stat.S_ISSOCK(st.st_mode) else "not a file")
        raise DataFileError(p, None, f"is {kind}, not a regular file ({what} expected)")
    if st.st_size > max_bytes:
        raise DataFileError(p, None, f"too large for a {what}: {st.st_size} bytes (limit {max_bytes})")
    try:
        # O_NONBLOCK: if the path was swapped for a FIFO since the stat, opening must not block
        fd = os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        fh = os.fdopen(fd, "rb")
    except OSError as e:
        raise DataFileError(p, None, f"cannot read {what}: {e.strerror or e}") from None
    try:
        regular = stat.S_ISREG(os.fstat(fh.fileno()).st_mode)
    except OSError:
        regular = False
    if not regular:
        fh.close()
        raise DataFileError(p, None, f"is not a regular file ({what} expected)")
    return fh


def read_text(path: str | Path, what: str = "data file", max_bytes: int = MAX_YAML_BYTES) -> str:
    """A UTF-8 data file's text (read with read_input_file); DataFileError (one line, with the path)
    when it cannot be read or is not UTF-8."""
    data = read_input_file(path, what, max_bytes)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data[:e.start].count(b"\n") + 1
        raise DataFileError(path, line, f"not UTF-8 text (byte 0x{data[e.start]:02X})") from None


# ------------------------------------------------------------------------------------------------ YAML


class LineDict(dict[Any, Any]):
    """A YAML mapping: keys and values are whatever the document holds (validated by the reader)."""
    line: int = 0
    key_lines: dict[Any, int]

    def line_of(self, key: Any) -> int:
        return self.key_lines.get(key, self.line)


class LineList(list[Any]):
    """A YAML sequence: items are whatever the document holds (validated by the reader)."""
    line: int = 0
    item_lines: list[int]

    def line_of(self, i: int) -> int:
        return self.item_lines[i] if i < len(self.item_lines) else self.line


_CONSTRUCT_ERRORS = (ValueError, TypeError, AttributeError, OverflowError, KeyError, IndexError,
                     RecursionError, MemoryError)
_NUMBER_TAGS = frozenset({"tag:yaml.org,2002:int", "tag:yaml.org,2002:float"})


if TYPE_CHECKING:                                   # pragma: no cover
    class _LoaderHost:
        """What _Limits calls of the PyYAML loader classes it is mixed into (their Parser, Composer and
        SafeConstructor), for the type checker only: PyYAML has no type hints, its nodes and events
        are Any here. At run time _Limits stands on object and these come from the loader's MRO."""

        def check_event(self, *choices: Any) -> bool:
            raise NotImplementedError

        def peek_event(self) -> Any: ...

        def compose_node(self, parent: Any, index: Any) -> Any: ...

        def construct_object(self, node: Any, deep: bool = False) -> Any: ...

        def flatten_mapping(self, node: Any) -> None: ...
else:
    _LoaderHost = object


class _Limits(_LoaderHost):
    """Mixed in before a loader's Composer and SafeConstructor: no aliases, bounded depth, bounded
    numbers, construction errors marked. Depth is checked before the composer descends, so a deeply
    nested file never reaches Python's (or C's) recursion limit."""

    _depth = 0

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            ev = self.peek_event()
            raise yaml.composer.ComposerError(
                None, None, f"aliases (*{short(ev.anchor)[1:-1]}) are not supported in pdrive files",
                ev.start_mark)
        ev = self.peek_event()
        self._depth += 1
        try:
            if self._depth > MAX_YAML_DEPTH:
                raise yaml.composer.ComposerError(
                    None, None, f"nested deeper than {MAX_YAML_DEPTH} levels", ev.start_mark)
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_object(self, node: Any, deep: bool = False) -> Any:
        if isinstance(node, yaml.ScalarNode) and node.tag in _NUMBER_TAGS \
                and len(node.value) > MAX_NUMBER_CHARS:
            raise yaml.constructor.ConstructorError(
                None, None, f"number too long ({len(node.value)} characters, limit {MAX_NUMBER_CHARS})",
                node.start_mark)
        try:
            return super().construct_object(node, deep=deep)
        except yaml.YAMLError:
            raise
        except _CONSTRUCT_ERRORS as e:
            tag = node.tag.rsplit(":", 1)[-1] if node.tag.startswith("tag:yaml.org,2002:") else node.tag
            value = short(node.value) if isinstance(node, yaml.ScalarNode) else f"a {node.id}"
            why = f": {short(str(e))[1:-1]}" if isinstance(e, ValueError) and str(e) else ""
            raise yaml.constructor.ConstructorError(
                None, None, f"bad {short(tag)[1:-1]} value {value}{why}", node.start_mark) from None


def _construct_mapping(loader: _Limits, node: yaml.MappingNode) -> LineDict:
    loader.flatten_mapping(node)
    d = LineDict()
    d.line = node.start_mark.line + 1
    d.key_lines = {}
    for knode, vnode in node.value:
        key = loader.construct_object(knode, deep=True)
        try:
            hash(key)
        except TypeError:
            raise yaml.constructor.ConstructorError(None, None, "unhashable key", knode.start_mark)
        if key in d:
            raise yaml.constructor.ConstructorError(
                None, None, f"duplicate key {short(key)}", knode.start_mark)
        d[key] = loader.construct_object(vnode, deep=True)
        d.key_lines[key] = knode.start_mark.line + 1
    return d


def _construct_sequence(loader: _Limits, node: yaml.SequenceNode) -> LineList:
    lst = LineList(loader.construct_object(n, deep=True) for n in node.value)
    lst.line = node.start_mark.line + 1
    lst.item_lines = [n.start_mark.line + 1 for n in node.value]
    return lst


class _PureLoader(_Limits, yaml.SafeLoader):  # type: ignore[misc]  # PyYAML has no type hints: SafeLoader is Any
    """The pure-Python loader: yaml.SafeLoader (safe construction only) with the limits."""


if _CParser is not None:
    class _CLoader(_Limits, Composer, _CParser, SafeConstructor, Resolver):  # type: ignore[misc]  # (as _PureLoader)
        """libyaml's parser makes the events; PyYAML's Python Composer (ahead of CParser's own C
        composer in the MRO, so the limits above apply node by node), SafeConstructor and Resolver do
        the rest, exactly as in _PureLoader."""

        def __init__(self, stream: str) -> None:
            _CParser.__init__(self, stream)
            SafeConstructor.__init__(self)
            Resolver.__init__(self)
            Composer.__init__(self)
else:                                   # pragma: no cover - depends on the PyYAML build
    _CLoader = None  # type: ignore[assignment, misc]  # (no libyaml: no such class)

for _cls in filter(None, (_PureLoader, _CLoader)):
    _cls.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)
    _cls.add_constructor(yaml.resolver.BaseResolver.DEFAULT_SEQUENCE_TAG, _construct_sequence)


def _loader_class(pure: bool | None, text: str = "") -> type[_PureLoader] | type[_CLoader]:
    if pure is None:
        pure = os.environ.get("PDRIVE_PURE_YAML", "") not in ("", "0")
    if pure or _CLoader is None:
        return _PureLoader
    if not text.isascii():
        try:
            text.encode("utf-8")
        except UnicodeEncodeError:      # a lone surrogate: libyaml cannot take the text; the pure
            return _PureLoader          # reader refuses it with its position, as without libyaml
    return _CLoader


# libyaml's own refusals (CParser raises these; the Python composer and constructors never do). Its
# words, its limits and where it stops depend on its version: libyaml 0.2.6 refuses nesting deeper than
# 1000 levels ("exceeded maximum nesting depth") while scanning ahead, before the composer sees the
# events and so before pdrive's 64-level check. On any of them the text is parsed again by the
# pure-Python loader, which checks pdrive's limits node by node: the answer (data, or pdrive's message
# at its file:line) is the pure loader's whatever libyaml does. Only a file libyaml refuses pays for it.
_LIBYAML_ERRORS = (yaml.reader.ReaderError, yaml.scanner.ScannerError, yaml.parser.ParserError)


class _errors_as_data_file_error:
    """Every YAML or construction error raised inside as one DataFileError with file:line."""

    def __init__(self, path: str | Path) -> None:
        self.path = path

    def __enter__(self) -> _errors_as_data_file_error:
        return self

    def __exit__(self, typ: type[BaseException] | None, e: BaseException | None,
                 tb: TracebackType | None) -> Literal[False]:
        if e is None or isinstance(e, DataFileError):
            return False
        path = self.path
        if isinstance(e, yaml.MarkedYAMLError):
            mark = e.problem_mark or e.context_mark
            line = mark.line + 1 if mark else None
            msg = e.problem or str(e)
            if e.context:
                msg = f"{e.context}: {msg}"
            raise DataFileError(path, line, f"YAML error: {msg}") from None
        if isinstance(e, yaml.YAMLError):
            raise DataFileError(path, None, f"YAML error: {e}") from None
        if isinstance(e, _CONSTRUCT_ERRORS):    # from a constructor run after construct_object returned
            raise DataFileError(path, None, f"YAML error: {short(str(e))[1:-1]}") from None
        return False


def load_yaml_text(text: str, path: str | Path = "<string>", *, pure: bool | None = None) -> Any:
    """The one YAML loader of pdrive. Raises DataFileError (file:line, one line) for anything that is
    not a bounded, alias-free YAML document of plain safe types. pure=True: PyYAML's pure-Python parser
    even when libyaml is there (None: libyaml unless PDRIVE_PURE_YAML is set)."""
    if len(text) > MAX_YAML_BYTES:
        raise DataFileError(path, None, f"too large: {len(text)} characters (limit {MAX_YAML_BYTES})")
    cls = _loader_class(pure, text)
    if cls is _CLoader:
        loader = cls(text)
        try:
            return _direct_data(loader)
        except _LibyamlRefused:
            cls = _PureLoader
        except _Fallback:
            pass
        finally:
            loader.dispose()
    with _errors_as_data_file_error(path):
        if cls is _CLoader:
            try:
                return _node_data(cls, text)
            except _LIBYAML_ERRORS:
                cls = _PureLoader
        return _node_data(cls, text)


def _node_data(cls: type[_PureLoader] | type[_CLoader], text: str) -> Any:
    loader = cls(text)
    try:
        return loader.get_single_data()
    finally:
        loader.dispose()


# The direct path: data straight from libyaml's events, without the node tree. It takes only plain
# documents (no tags, anchors, aliases, merge keys; keys are plain scalars, no duplicates, within the
# limits) and builds exactly what the composer and constructors above build from them, with the same
# line numbers; on anything else, or any error, it gives up (_Fallback) and the node path above parses
# the text again and gives the answer or the file:line error. Three times faster for the profiles.

class _Fallback(Exception):
    """The direct path met something it leaves to the node path."""


class _LibyamlRefused(_Fallback):
    """libyaml itself refused the text: the pure loader decides (see _LIBYAML_ERRORS)."""


_STR_TAG = "tag:yaml.org,2002:str"
_DIRECT_TAGS = frozenset({"tag:yaml.org,2002:int", "tag:yaml.org,2002:float", "tag:yaml.org,2002:bool",
                          "tag:yaml.org,2002:null", "tag:yaml.org,2002:timestamp"})


def _direct_data(loader: _CLoader) -> Any:
    try:
        loader.get_event()                                  # StreamStart
        if not loader.check_event(yaml.DocumentStartEvent):
            raise _Fallback                                 # an empty stream: None, by the node path
        loader.get_event()
        data = _direct_node(loader, loader.get_event(), 1, _implicit_table(type(loader)))
        loader.get_event()                                  # DocumentEnd
        if not loader.check_event(yaml.StreamEndEvent):
            raise _Fallback                                 # a second document: an error, by the node path
        return data
    except _Fallback:
        raise
    except _LIBYAML_ERRORS:
        raise _LibyamlRefused from None
    except Exception:
        raise _Fallback from None


#: first character of a plain scalar (None: any) -> [(tag, regexp)]
_ImplicitTable = dict[str | None, list[tuple[str, re.Pattern[str]]]]
_implicit_tables: dict[type[_CLoader], _ImplicitTable] = {}


def _implicit_table(cls: type[_CLoader]) -> _ImplicitTable:
    """Resolver.resolve for plain scalars as a table: first character -> [(tag, regexp)], the
    class's implicit resolvers for that character followed by the wildcard ones (what resolve tries)."""
    table = _implicit_tables.get(cls)
    if table is None:
        res = cls.yaml_implicit_resolvers
        wild = list(res.get(None, []))
        table = {ch: list(rs) + wild for ch, rs in res.items() if ch is not None}
        table[None] = wild
        _implicit_tables[cls] = table
    return table


def _direct_node(loader: _CLoader, ev: Any, depth: int, table: _ImplicitTable) -> Any:
    if depth > MAX_YAML_DEPTH:
        raise _Fallback
    kind = type(ev)
    if kind is yaml.AliasEvent or ev.anchor is not None or ev.tag not in (None, "!"):
        raise _Fallback
    if kind is yaml.ScalarEvent:
        value = ev.value
        tag = _STR_TAG
        if ev.implicit[0]:                                  # as Resolver.resolve does (tag None or "!")
            for t, regexp in table.get(value[:1], table[None]):
                if regexp.match(value):
                    tag = t
                    break
        if tag == _STR_TAG:
            return value
        if tag not in _DIRECT_TAGS or (tag in _NUMBER_TAGS and len(value) > MAX_NUMBER_CHARS):
            raise _Fallback
        node = yaml.ScalarNode(tag, value, ev.start_mark, ev.end_mark, ev.style)
        return loader.yaml_constructors[tag](loader, node)
    get_event = loader.get_event
    if kind is yaml.SequenceStartEvent:
        lst = LineList()
        lst.line = ev.start_mark.line + 1
        lst.item_lines = lines = []
        while True:
            item = get_event()
            if type(item) is yaml.SequenceEndEvent:
                return lst
            lines.append(item.start_mark.line + 1)
            lst.append(_direct_node(loader, item, depth + 1, table))
    if kind is yaml.MappingStartEvent:
        d = LineDict()
        d.line = ev.start_mark.line + 1
        d.key_lines = key_lines = {}
        while True:
            kev = get_event()
            kkind = type(kev)
            if kkind is yaml.MappingEndEvent:
                return d
            if kkind is not yaml.ScalarEvent:
                raise _Fallback
            key = _direct_node(loader, kev, depth + 1, table)
            if key in d:
                raise _Fallback                             # a duplicate key: an error, by the node path
            key_lines[key] = kev.start_mark.line + 1
            d[key] = _direct_node(loader, get_event(), depth + 1, table)
    raise _Fallback


def load_yaml_head(text: str, keys: Iterable[str], path: str | Path = "<string>", *,
                   pure: bool | None = None) -> LineDict | None:
    """The top-level keys `keys` of a YAML mapping document, read only as far as needed: parsing
    stops once all of them were seen, so a file whose first lines hold them is read only that far.
    Values (and line numbers) are what load_yaml_text gives for those keys; None if the document is
    not a mapping. Errors and limits as load_yaml_text, for the part read (what follows is not
    checked: load the whole file before trusting it)."""
    if len(text) > MAX_YAML_BYTES:
        raise DataFileError(path, None, f"too large: {len(text)} characters (limit {MAX_YAML_BYTES})")
    cls = _loader_class(pure, text)
    with _errors_as_data_file_error(path):
        if cls is _CLoader:
            try:
                return _head_data(cls, text, set(keys))
            except _LIBYAML_ERRORS:             # libyaml's own refusal: the pure loader decides
                cls = _PureLoader
        return _head_data(cls, text, set(keys))


def _head_data(cls: type[_PureLoader] | type[_CLoader], text: str, want: set[str]) -> LineDict | None:
    loader = cls(text)
    try:
        loader.get_event()                              # StreamStart
        if not loader.check_event(yaml.DocumentStartEvent):
            return None
        loader.get_event()
        if not loader.check_event(yaml.MappingStartEvent):
            return None
        start = loader.get_event()
        out = LineDict()
        out.line = start.start_mark.line + 1
        out.key_lines = {}
        loader._depth = 1                               # the root mapping's children, as in a full load
        while want and not loader.check_event(yaml.MappingEndEvent):
            knode = loader.compose_node(None, None)
            vnode = loader.compose_node(None, None)
            if not isinstance(knode, yaml.ScalarNode):
                continue
            key = loader.construct_object(knode, deep=True)
            if not isinstance(key, str) or key not in want:
                continue
            want.discard(key)
            out[key] = loader.construct_object(vnode, deep=True)
            out.key_lines[key] = knode.start_mark.line + 1
        return out
    finally:
        loader.dispose()


def load_yaml(path: str | Path, what: str = "data file", *, cached: bool = False) -> Any:
    """load_yaml_text of a file. cached=True: the parse is kept in (and read back from) the cache of
    parsed data files (datacache.py: keyed by the text itself; the profiles use it)."""
    text = read_text(path, what)
    if not cached:
        return load_yaml_text(text, Path(path))
    from profidrive_cli import datacache
    loader = _loader_class(None, text).__name__
    data = datacache.get(text, loader)
    if data is datacache.MISS:
        data = load_yaml_text(text, Path(path))
        datacache.put(text, loader, data)
    return data
