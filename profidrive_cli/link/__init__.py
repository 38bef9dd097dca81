"""link/: bytes in and out. open_link() picks the transport for a --port value."""

from __future__ import annotations

from profidrive_cli.link.base import Link, LinkLost  # noqa: F401


def open_link(port: str, baud: int = 19200, rs485: bool = False,
              echo: bool | str = "auto") -> Link:
    """Device path (/dev/ttyUSB0, COM3), any pyserial URL (socket://, rfc2217://, loop://) or sim://.
    echo: "auto" (found at the first transmission), True / False (forced); link/serial_link.py."""
    from profidrive_cli.link.serial_link import SerialLink
    return SerialLink(port, baud, rs485=rs485, echo=echo)
