"""YAML data files with line numbers, so every complaint can say file:line.

Only yaml.SafeLoader is used. Mappings load as LineDict and sequences as LineList; both remember the
line of the node and of each key / item (1-based).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from profidrive_cli import UsageError


class DataFileError(UsageError):
    def __init__(self, path: str | Path, line: int | None, message: str):
        self.path = str(path)
        self.line = line
        self.message = message
        where = f"{self.path}:{line}" if line else self.path
        super().__init__(f"{where}: {message}")


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


class _Loader(yaml.SafeLoader):
    pass


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
                None, None, f"duplicate key {key!r}", knode.start_mark)
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


def read_text(path: str | Path) -> str:
    """A UTF-8 data file's text; DataFileError (one line, with the path) when it cannot be read."""
    p = Path(path)
    try:
        return p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DataFileError(p, None, "file not found") from None
    except (OSError, UnicodeDecodeError) as e:
        raise DataFileError(p, None, f"cannot read: {e}") from None


def load_yaml(path: str | Path) -> Any:
    return load_yaml_text(read_text(path), Path(path))
