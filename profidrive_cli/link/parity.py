"""UART parity errors on POSIX serial devices: marked by the kernel, unescaped here.

PROFIBUS gets its Hamming distance of 4 only together with the parity bit of every character
(reference §1: 8E1). pyserial asks for even parity but clears INPCK, so a character that arrives
with a parity error is delivered as a good-looking octet. ParityMarkingSerial turns parity checking
on with marking (termios INPCK + PARMRK, IGNPAR/ISTRIP/BRKINT off): the Linux line discipline then
delivers

    0xFF 0xFF      a real 0xFF octet
    0xFF 0x00 X    octet X arrived with a parity or framing error (a break: 0xFF 0x00 0x00)
    anything else  itself

unmark_parity() undoes that escaping (a pure function; a marker split across two reads is carried
over). The port's read() returns LineOctets: bytes whose .errors lists the positions of the flagged
octets, so the FDL receiver can treat the telegram they belong to as corrupt (fdl/master.py: one
illegal frame, and the attempt is repeated).

Only real serial devices get this: ptys carry no parity (the pty fallback opens them without),
and URLs (socket://, rfc2217://, loop://, sim://) have no termios at all.
"""

from __future__ import annotations

import os

from collections.abc import Iterable
from typing import Any

import serial

MARK = 0xFF


class LineOctets(bytes):
    """Octets from a port, with the positions (indices) of the octets the UART flagged."""

    errors: tuple[int, ...]

    def __new__(cls, data: bytes = b"", errors: Iterable[int] = ()) -> "LineOctets":
        obj = super().__new__(cls, data)
        obj.errors = tuple(errors)
        return obj


def unmark_parity(data: bytes, carry: bytes = b"") -> tuple[bytes, tuple[int, ...], bytes]:
    """PARMRK-escaped input -> (octets, positions of flagged octets, carry for the next read).

    `carry` is what the previous call returned as incomplete (a trailing 0xFF or 0xFF 0x00); pass it
    back with the next octets. A flagged octet stays in the output at its position (its value is not
    to be trusted). An 0xFF followed by anything else (cannot come from the kernel) is taken as is.
    """
    buf = carry + bytes(data)
    out = bytearray()
    errors: list[int] = []
    i, n = 0, len(buf)
    while i < n:
        b = buf[i]
        if b != MARK:
            out.append(b)
            i += 1
            continue
        if i + 1 >= n:
            return bytes(out), tuple(errors), buf[i:]
        nxt = buf[i + 1]
        if nxt == MARK:
            out.append(MARK)
            i += 2
        elif nxt == 0x00:
            if i + 2 >= n:
                return bytes(out), tuple(errors), buf[i:]
            errors.append(len(out))
            out.append(buf[i + 2])
            i += 3
        else:
            out.append(MARK)
            i += 1
    return bytes(out), tuple(errors), b""


if os.name == "posix":
    import termios

    # pyserial has no type hints: serial.Serial is Any, which mypy --strict will not subclass
    class ParityMarkingSerial(serial.Serial):  # type: ignore[misc]
        """serial.Serial (POSIX) with parity checking and error marking on, and unmarked reads."""

        def __init__(self, *args: Any, **kwargs: Any) -> None:   # pyserial's own arguments
            self._carry = b""
            self.marks_parity = False
            #: octets flagged with a parity/framing error since the port was opened
            self.parity_errors = 0
            super().__init__(*args, **kwargs)

        def _reconfigure_port(self, force_update: bool = False) -> None:
            super()._reconfigure_port(force_update)
            attrs = termios.tcgetattr(self.fd)
            if self._parity == serial.PARITY_NONE:
                attrs[0] &= ~(termios.INPCK | termios.PARMRK)
            else:
                attrs[0] |= termios.INPCK | termios.PARMRK
                attrs[0] &= ~(termios.IGNPAR | termios.ISTRIP | termios.BRKINT | termios.IGNBRK)
            termios.tcsetattr(self.fd, termios.TCSANOW, attrs)
            self.marks_parity = bool(termios.tcgetattr(self.fd)[0] & termios.PARMRK)

        def _read_raw(self, size: int) -> bytes:
            raw: bytes = super().read(size)      # pyserial's read (untyped)
            return raw

        def read(self, size: int = 1) -> bytes:
            raw = self._read_raw(size)
            if not self.marks_parity:
                return raw
            data, errors, self._carry = unmark_parity(raw, self._carry)
            self.parity_errors += len(errors)
            return LineOctets(data, errors) if errors else data

        def reset_input_buffer(self) -> None:
            self._carry = b""
            super().reset_input_buffer()
else:                                        # pragma: no cover (Windows: no termios)
    ParityMarkingSerial = None  # type: ignore[assignment, misc]  # (no termios: no such class)
