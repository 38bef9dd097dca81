"""Data files pdrive reads: YAML with line numbers, and the one bounded way to read an input file.

Every complaint says file:line in one line. `read_input_file` is the only way pdrive reads a file it is
given (checklists, parameter files, profiles, GSD files, raw captures): a regular file of sane size,
never a device or a FIFO. `load_yaml_text` is the only way it reads YAML: yaml.SafeLoader construction,
with limits (size, nesting depth, digits of a number), aliases refused, and every construction error
(`!!float x`, a bad `!!timestamp`, ...) reported as file:line. Mappings load as LineDict and sequences
as LineList; both remember the line of the node and of each key / item (1-based).
"""

from __future__ import annotations

import os
import reprlib
import stat
from pathlib import Path
from typing import Any

import yaml

from profidrive_cli import UsageError

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
        with os.fdopen(fd, "rb") as fh:
            if not stat.S_ISREG(os.fstat(fh.fileno()).st_mode):
                raise DataFileError(p, None, f"is not a regular file ({what} expected)")
            data = fh.read(max_bytes + 1)
    except OSError as e:
        raise DataFileError(p, None, f"cannot read {what}: {e.strerror or e}") from None
    if len(data) > max_bytes:
        raise DataFileError(p, None, f"too large for a {what}: more than {max_bytes} bytes")
    return data


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


class LineDict(dict):
    line: int = 0
    key_lines: dict

    def line_of(self, key: str) -> int:
        return self.key_lines.get(key, self.line)


class LineList(list):
    line: int = 0
    item_lines: list

    def line_of(self, i: int) -> int:
        return self.item_lines[i] if i < len(self.item_lines) else self.line


_CONSTRUCT_ERRORS = (ValueError, TypeError, AttributeError, OverflowError, KeyError, IndexError,
                     RecursionError, MemoryError)
_NUMBER_TAGS = frozenset({"tag:yaml.org,2002:int", "tag:yaml.org,2002:float"})


class _Loader(yaml.SafeLoader):
    """SafeLoader with limits: no aliases, bounded depth, bounded numbers, construction errors marked."""

    def __init__(self, stream):
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent, index):
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

    def construct_object(self, node, deep=False):
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


def _construct_mapping(loader: _Loader, node: yaml.MappingNode) -> LineDict:
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


def _construct_sequence(loader: _Loader, node: yaml.SequenceNode) -> LineList:
    lst = LineList(loader.construct_object(n, deep=True) for n in node.value)
    lst.line = node.start_mark.line + 1
    lst.item_lines = [n.start_mark.line + 1 for n in node.value]
    return lst


_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)
_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_SEQUENCE_TAG, _construct_sequence)


def load_yaml_text(text: str, path: str | Path = "<string>") -> Any:
    """The one YAML loader of pdrive. Raises DataFileError (file:line, one line) for anything that is
    not a bounded, alias-free YAML document of plain safe types."""
    if len(text) > MAX_YAML_BYTES:
        raise DataFileError(path, None, f"too large: {len(text)} characters (limit {MAX_YAML_BYTES})")
    try:
        loader = _Loader(text)  # a yaml.SafeLoader subclass: safe construction only
        try:
            return loader.get_single_data()
        finally:
            loader.dispose()
    except yaml.MarkedYAMLError as e:
        mark = e.problem_mark or e.context_mark
        line = mark.line + 1 if mark else None
        msg = e.problem or str(e)
        if e.context:
            msg = f"{e.context}: {msg}"
        raise DataFileError(path, line, f"YAML error: {msg}") from None
    except yaml.YAMLError as e:
        raise DataFileError(path, None, f"YAML error: {e}") from None
    except _CONSTRUCT_ERRORS as e:      # from a constructor run after construct_object returned
        raise DataFileError(path, None, f"YAML error: {short(str(e))[1:-1]}") from None


def load_yaml(path: str | Path, what: str = "data file") -> Any:
    return load_yaml_text(read_text(path, what), Path(path))
