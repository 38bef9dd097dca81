"""The Wireshark extcap side of `pdrive sniff`: the interface list, link types and options Wireshark
asks for (plain text lines of the extcap protocol), and the capture itself into Wireshark's fifo.

Wireshark runs the launcher that `pdrive wireshark install` put into its extcap folder:

    pdrive-extcap --extcap-interfaces [--extcap-version=4.0]
    pdrive-extcap --extcap-interface pdrive --extcap-dlts
    pdrive-extcap --extcap-interface pdrive --extcap-config
    pdrive-extcap --extcap-interface pdrive --capture --fifo PATH --port PORT --baud RATE

The capture reuses sniff's reading loop (bustools/listen.py), the capture decoder and the PcapWriter
(dp/capture.py, link type 147 which the shipped dissector binds). It never transmits, and ends when
Wireshark stops it (SIGTERM), closes the fifo, or on Ctrl-C.
"""

from __future__ import annotations

import signal
import threading
import time
from typing import TYPE_CHECKING, Any, BinaryIO, Callable

from profidrive_cli import UsageError, __version__
from profidrive_cli.bustools.listen import listen
from profidrive_cli.dp.capture import LINKTYPE_USER0, Capture, PcapWriter, merge_errors
from profidrive_cli.fdl.timing import BAUD_NAMES, BAUD_RATES

if TYPE_CHECKING:
    from profidrive_cli.link.base import Link

INTERFACE = "pdrive"
DEFAULT_BAUD = 19200
HELP_URL = "https://github.com/pdrive/profidrive-cli/blob/main/docs/commands.md#pdrive-wireshark"


def interfaces_text() -> str:
    return (f"extcap {{version={__version__}}}{{help={HELP_URL}}}\n"
            f"interface {{value={INTERFACE}}}{{display=PROFIBUS (pdrive sniff, listen only)}}\n")


def _check_interface(interface: str | None) -> None:
    if interface != INTERFACE:
        raise UsageError(f"--extcap-interface: unknown interface {interface!r} (pdrive has '{INTERFACE}')")


def dlts_text(interface: str | None) -> str:
    _check_interface(interface)
    return f"dlt {{number={LINKTYPE_USER0}}}{{name=USER0}}{{display=PROFIBUS FDL (pdrive.lua)}}\n"


def config_text(interface: str | None) -> str:
    _check_interface(interface)
    lines = [
        "arg {number=0}{call=--port}{display=Port}{type=string}{required=true}"
        "{tooltip=Serial device (/dev/ttyUSB0, COM3), pyserial URL or the pty of pdrive sim --pty}",
        "arg {number=1}{call=--baud}{display=Baud rate}{type=selector}"
        "{tooltip=The bus baud rate}",
    ]
    for rate in BAUD_RATES:
        default = "{default=true}" if rate == DEFAULT_BAUD else ""
        lines.append(f"value {{arg=1}}{{value={rate}}}{{display={BAUD_NAMES[rate]}bit/s}}{default}")
    lines.append("arg {number=2}{call=--rs485}{display=Kernel RS-485 mode}{type=boolflag}"
                 "{tooltip=RTS direction control by the kernel}")
    return "\n".join(lines) + "\n"


class _Terminated(BaseException):
    """Wireshark stopped the capture with SIGTERM (raised in the main thread, like KeyboardInterrupt)."""


def _raise_terminated(signum: int, frame: Any) -> None:
    raise _Terminated()


class _TermGuard:
    """While the capture runs (main thread only; elsewhere no handler changes): SIGTERM raises
    _Terminated; restore() puts the handler from before back. The capture's own guard: bustools/
    does not stand on session/ (whose SignalGuard does this for a drive session)."""

    def __init__(self) -> None:
        self._old: Any = None
        self._installed = False

    def install(self) -> None:
        if threading.current_thread() is not threading.main_thread():
            return
        try:
            self._old = signal.signal(signal.SIGTERM, _raise_terminated)
            self._installed = True
        except (TypeError, ValueError):
            pass

    def restore(self) -> None:
        if not self._installed:
            return
        self._installed = False
        try:
            signal.signal(signal.SIGTERM, self._old if self._old is not None else signal.SIG_DFL)
        except (TypeError, ValueError):
            pass


class _Fifo:
    """The pcap stream to Wireshark: every write flushed at once (a live view)."""

    def __init__(self, fh: BinaryIO) -> None:
        self.fh = fh

    def write(self, data: bytes) -> None:
        self.fh.write(data)
        self.fh.flush()


def capture(link: Link, fifo_path: str, duration: float | None = None,
            clock: Callable[[], float] = time.monotonic) -> int:
    """Listen on `link` and stream every telegram to the fifo (pcap, DLT_USER0, wall-clock times)
    until SIGTERM, Ctrl-C, a closed fifo or `duration`. Returns the number of frames written; the
    link is closed on every way out."""
    guard = _TermGuard()
    count = 0
    try:
        with open(fifo_path, "wb", buffering=0) as fh:
            writer = PcapWriter(_Fifo(fh), LINKTYPE_USER0, time.time())
            cap = Capture()

            def on_data(data: bytes, t: float) -> None:
                nonlocal count
                for c in merge_errors(cap.feed(data, t)):
                    if c.frame is not None:
                        writer.write(c.t, c.raw)
                        count += 1

            guard.install()
            try:
                writer.start = time.time()
                listen(link, duration, on_data, clock)
            except (KeyboardInterrupt, _Terminated, BrokenPipeError):
                pass                      # Wireshark stopped the capture
    except BrokenPipeError:
        pass
    except OSError as e:
        raise UsageError(f"--fifo {fifo_path}: {e.strerror or e}") from None
    finally:
        guard.restore()
        link.close()
    return count
