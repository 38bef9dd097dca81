"""GSD text stage (reference §5): bytes -> text -> logical lines -> tokens of one value.

decode() picks UTF-8 when the bytes are valid UTF-8, else Latin-1; logical_lines() cuts `;` comments
(not inside strings) and joins `\\` continuations (also inside number lists and strings) into logical
lines that remember the physical line they started on; Toks splits one value into strings, numbers,
words and punctuation. Knows no keyword (that is parser.py) and touches only datafile.DataFileError.
"""

from __future__ import annotations

import builtins
import re
from collections.abc import Iterator
from typing import Any

from profidrive_cli.datafile import DataFileError

SPLIT = re.compile(r"\r\n|\r|\n")
HEAD = re.compile(r"\s*([^\s=(]+)\s*(?:\(([^)]*)\))?\s*(=)?\s*(.*)\Z", re.S)
TOK = re.compile(r'"([^"]*)"|([-,@])|([^\s,"@-]+)')
NUM = re.compile(r"0[xX][0-9a-fA-F]+\Z|[0-9]+\Z")

# input limits: the largest real GSD file we know is ~190 kB; a GSD number never needs more than 32 bits
MAX_GSD_BYTES = 4 * 1024 * 1024
MAX_NUMBER_CHARS = 24


def decode(data: bytes) -> tuple[str, str]:
    """(text, encoding): UTF-8 when the bytes are valid UTF-8 (ascii when plain), else Latin-1; a BOM
    is dropped."""
    try:
        text = data.decode("utf-8")
        enc = "ascii" if text.isascii() else "utf-8"
    except UnicodeDecodeError:
        text = data.decode("latin-1")
        enc = "latin-1"
    if text.startswith("\ufeff"):
        text = text[1:]
    return text, enc


def strip_comment(raw: str, in_str: bool) -> tuple[str, bool]:
    """Cut a `;` comment that is outside strings; return (kept text, inside-a-string at the end)."""
    if '"' not in raw:
        if in_str:
            return raw, True
        j = raw.find(";")
        return (raw if j < 0 else raw[:j]), False
    parts = raw.split('"')
    out: list[str] = []
    state = in_str
    for k, p in enumerate(parts):
        if k:
            out.append('"')
            state = not state
        if not state:
            j = p.find(";")
            if j >= 0:
                out.append(p[:j])
                return "".join(out), False
        out.append(p)
    return "".join(out), state


class Toks:
    """Tokens of one value: ('s', text) strings, ('n', int) numbers, ('-'|','|'@', None), ('w', text)."""

    __slots__ = ("t", "i", "path", "line", "what")

    def __init__(self, text: str, path: str, line: int, what: str):
        t: list[tuple[str, str | builtins.int | None]] = []
        for m in TOK.finditer(text):
            s, punct, word = m.groups()
            if s is not None:
                t.append(("s", s))
            elif punct is not None:
                t.append((punct, None))
            else:
                if NUM.match(word):
                    if len(word) > MAX_NUMBER_CHARS:
                        raise DataFileError(path, line, f"{what}: number too long ({len(word)} "
                                                        f"characters: {word[:12]}...)")
                    t.append(("n", int(word[2:], 16) if word[1:2] in ("x", "X") else int(word)))
                else:
                    t.append(("w", word))
        self.t = t
        self.i = 0
        self.path = path
        self.line = line
        self.what = what

    def error(self, msg: str) -> DataFileError:
        return DataFileError(self.path, self.line, f"{self.what}: {msg}")

    def at_end(self) -> bool:
        return self.i >= len(self.t)

    def peek(self) -> str | None:
        return self.t[self.i][0] if self.i < len(self.t) else None

    def _show(self) -> str:
        kind, v = self.t[self.i]
        return {"s": f'"{v}"', "n": str(v), "w": str(v)}.get(kind, kind)

    def int(self, what: str = "number", signed: bool = False) -> int:
        neg = False
        if signed and self.peek() == "-":
            neg = True
            self.i += 1
        if self.at_end():
            raise self.error(f"{what} missing")
        kind, v = self.t[self.i]
        if kind != "n" or not isinstance(v, int):
            raise self.error(f"bad number {self._show()!s} (expected {what})" if kind == "w"
                             else f"expected {what}, found {self._show()}")
        self.i += 1
        return -v if neg else v

    def string(self, what: str = "string") -> str:
        if self.at_end():
            raise self.error(f"{what} missing")
        kind, v = self.t[self.i]
        if kind != "s" or not isinstance(v, str):
            raise self.error(f'expected a "quoted" {what}, found {self._show()}')
        self.i += 1
        return v

    def skip(self, punct: str) -> bool:
        if self.peek() == punct:
            self.i += 1
            return True
        return False

    def int_list(self, what: str, lo: builtins.int | None = None, hi: builtins.int | None = None,
                 signed: bool = False) -> list[builtins.int]:      # (builtins: Toks.int is a method)
        out: list[builtins.int] = []
        while not self.at_end():
            v = self.int(what, signed=signed)
            if (lo is not None and v < lo) or (hi is not None and v > hi):
                raise self.error(f"{what} {v} out of range {lo}..{hi}")
            out.append(v)
            if not self.skip(","):
                if not self.at_end() and self.peek() not in ("n", "-"):
                    raise self.error(f"unexpected {self._show()}")
        return out

    def end(self) -> None:
        if not self.at_end():
            raise self.error(f"unexpected {self._show()} after the value")


def logical_lines(path: str, lines: list[str], start: int) -> Iterator[tuple[int, str]]:
    """(first physical line, text) of each logical line from lines[start:]: `;` comments cut outside
    strings, `\\` continuations joined; an unterminated string raises DataFileError at the line it
    opened."""
    buf: list[str] = []
    first = 0
    in_str = False
    str_line = 0
    for i in range(start, len(lines)):
        lineno = i + 1
        was_in_str = in_str
        part, in_str = strip_comment(lines[i], in_str)
        if in_str and not was_in_str:
            str_line = lineno          # the string still open at the end started on this line
        stripped = part.rstrip()
        if stripped.endswith("\\"):
            if not buf:
                first = lineno
                buf.append(stripped[:-1])
            else:
                buf.append(stripped[:-1] if was_in_str else " " + stripped[:-1].lstrip())
            continue
        if in_str:
            raise DataFileError(path, str_line, "unterminated string (closing \" missing)")
        if buf:
            buf.append(part if was_in_str else " " + part.lstrip())
            text = "".join(buf)
            buf = []
            yield first, text
        else:
            yield lineno, part
    if in_str:
        raise DataFileError(path, str_line, "unterminated string (closing \" missing)")
    if buf:
        yield first, "".join(buf)
