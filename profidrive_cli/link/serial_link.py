"""SerialLink: the Link over any pyserial port — device paths, pyserial URLs and sim://.

8 data bits, even parity, 1 stop bit. Optional kernel RS-485 mode (pyserial RS485Settings).

Local echo: a 2-wire RS-485 adapter may hear its own transmission (its receiver stays on while it
sends). echo="auto" (the default) finds this out at the first transmission: when the octets read
back start with exactly the octets written, the adapter echoes and from then on every write reads
its echo back before it returns (so the master's reply timeout starts when the line is free); when
they differ, or nothing comes back, it does not. A slave's answer is never taken for an echo: an
answer never equals the request (reference §2.2: a request's FC has bit 6 set, a response's has
it clear, and the FC octet lies inside the first 4 (SD1/SD3) or 7 (SD2) octets compared; an SC
0xE5 is no start delimiter of a request; an SD1 answer swaps DA and SA, and DA != SA). Octets read
after the echo (a fast answer in the same USB packet) are kept for the next read(). echo=True /
False force it on / off (True still counts echoes that do not match: echo_errors). sim:// has no
echo (decided without asking).

Parity errors: on a POSIX serial device the port checks parity and marks each character that
arrived with a parity or framing error (termios INPCK + PARMRK, link/parity.py); read() returns it
as LineOctets whose .errors name the flagged positions, and the FDL master takes the telegram as
corrupt (one illegal frame, the attempt repeated). Without this a character with a wrong parity bit
would pass as a good octet and PROFIBUS would lose the Hamming distance 4 it gets from the parity
bit. Ptys carry no parity (opened without when they refuse it, and never marked); URL ports
(socket://, rfc2217://, loop://, sim://) are untouched.
"""

from __future__ import annotations

import errno
import logging
import os
import select
import time
from typing import Any, Literal, Union

import serial
import serial.rs485

from profidrive_cli import BusError, UsageError
from profidrive_cli.link.base import Link, LinkLost, plain_sleep, precise_sleep
from profidrive_cli.link.margin import measure as measure_margin
from profidrive_cli.link.parity import ParityMarkingSerial

try:
    from serial.urlhandler.protocol_socket import Serial as _SocketSerial
except ImportError:                          # pragma: no cover
    class _SocketSerial:  # type: ignore[no-redef]  # (no socket:// in this pyserial: a stand-in)
        pass

try:
    from termios import error as _TermiosError
except ImportError:                          # pragma: no cover (Windows: no termios)
    class _TermiosError(Exception):  # type: ignore[no-redef]  # (no termios: a stand-in)
        pass

#: what a read, write or flush raises when the device vanished (USB pulled, the pty's other end
#: closed: EIO): pyserial's exceptions, OSError from os.read / os.write / select / ioctl, and
#: termios.error (not an OSError) from tcflush / tcsetattr. Each is LinkLost to the master.
_GONE = (serial.SerialException, OSError, _TermiosError)

#: the most one read takes from a socket:// port (more than any telegram)
_SOCKET_CHUNK = 4096

log = logging.getLogger("profidrive_cli.dp")

#: what SerialLink(echo=...) takes: True (the adapter echoes), False (it does not), "auto" (find out)
Echo = Union[bool, Literal["auto"]]

#: how long after a write its echo may take to come back, beyond the octets' own wire time: a USB
#: adapter holds received octets up to its latency timer (FTDI: 16 ms by default, reference §4.3),
#: a TCP converter a few ms more
ECHO_WAIT_S = 0.05

# sim:// is registered by name: pyserial imports profidrive_cli.sim.protocol_sim only when a sim://
# URL is opened, so link/ never imports sim/ (the handler lives with the plant it builds)
if "profidrive_cli.sim" not in serial.protocol_handler_packages:
    serial.protocol_handler_packages.append("profidrive_cli.sim")


#: the entry-point group of port-kind plug-ins (docs/plugins.md): the entry point's name is the URL
#: scheme, its value the package that holds pyserial's handler module `protocol_<scheme>`
LINK_ENTRY_POINTS = "profidrive_cli.links"
#: the schemes pyserial and pdrive bring themselves (no plug-in lookup for these)
_OWN_SCHEMES = {"loop", "socket", "rfc2217", "hwgrep", "spy", "alt", "cp2110", "sim"}


def _plug_in_scheme(port: str) -> None:
    """A URL of a scheme nobody built in: the package of the installed plug-in that names it joins
    pyserial's protocol_handler_packages (the way sim:// is registered), before the port is opened."""
    scheme, sep, _ = port.partition("://")
    if not sep or scheme in _OWN_SCHEMES or not scheme.isidentifier():
        return
    from importlib.metadata import entry_points
    for ep in entry_points(group=LINK_ENTRY_POINTS, name=scheme):
        if ep.value not in serial.protocol_handler_packages:
            serial.protocol_handler_packages.append(ep.value)


def _is_pty(port: str) -> bool:
    return "://" not in port and os.path.realpath(port).startswith(("/dev/pts/", "/dev/pty"))


def _marks_parity(port: str) -> bool:
    """A POSIX serial device (not a pty, not a URL): parity errors are checked and marked."""
    return (ParityMarkingSerial is not None and "://" not in port
            and not port.upper().startswith("COM") and not _is_pty(port))


def open_serial(port: str, baud: int, rs485: bool = False, timeout: float = 0.0,
                _retry: bool = False) -> serial.SerialBase:
    """Open a pyserial port for PROFIBUS; one-line errors for missing / busy / forbidden ports."""
    try:
        if not _retry and _marks_parity(port):
            ser = ParityMarkingSerial()          # not opened until .open()
            ser.port = port
        else:
            _plug_in_scheme(port)
            ser = serial.serial_for_url(port, do_not_open=True)
        ser.baudrate = baud
        ser.bytesize = serial.EIGHTBITS
        ser.parity = serial.PARITY_NONE if _retry else serial.PARITY_EVEN
        ser.stopbits = serial.STOPBITS_ONE
        ser.timeout = timeout
        ser.write_timeout = 2.0
        ser.xonxoff = ser.rtscts = ser.dsrdtr = False
        if "://" not in port and not port.upper().startswith("COM"):
            ser.exclusive = True
        if rs485:
            ser.rs485_mode = serial.rs485.RS485Settings()
        ser.open()
        return ser
    except ValueError as e:
        if "baud" in str(e).lower():
            raise BusError(f"{port}: the port refuses {_rate_text(baud)} baud ({e})") from None
        raise UsageError(f"{port}: {e}") from None
    except serial.SerialException as e:
        raise BusError(_explain_open_error(port, e)) from None
    except OSError as e:
        raise BusError(_explain_open_error(port, e)) from None
    except Exception as e:  # termios.error (not an OSError) from tcsetattr on odd devices
        if type(e).__name__ == "error" and type(e).__module__ == "termios":
            if _is_pty(port) and not _retry:
                # Linux ptys carry no parity bits, and a reopened pty may refuse PARENB with
                # EINVAL: parity means nothing there, so open it without
                return open_serial(port, baud, rs485, timeout, _retry=True)
            raise BusError(f"{port}: the device refuses the serial settings "
                           f"(8E1 at {_rate_text(baud)}): {e.args[-1]}") from None
        raise


def _explain_open_error(port: str, e: Exception) -> str:
    err = getattr(e, "errno", None)
    text = str(e)
    if err == errno.ENOENT or "No such file" in text or "could not open port" in text and "2]" in text:
        return f"{port}: no such port (list ports with `python -m serial.tools.list_ports`, or use --port sim://)"
    if err in (errno.EACCES, errno.EPERM) or "Permission denied" in text:
        return (f"{port}: permission denied — add yourself to the port's group "
                f"(e.g. `sudo usermod -aG dialout $USER`, then log in again)")
    if err == errno.EBUSY or "busy" in text.lower() or "exclusively lock" in text:
        return f"{port}: port is busy (another program has it open)"
    if "Connection refused" in text:
        return f"{port}: connection refused"
    return f"{port}: cannot open: {text}"


def read_available(ser: serial.SerialBase, timeout: float) -> bytes:
    """Whatever has arrived, waiting up to `timeout` s for the first octet.

    On a POSIX device the wait is a select() on its fd: changing pyserial's timeout would call
    tcsetattr on every read (slow, and refused by some ptys). URL ports (socket://, sim://) take
    the timeout directly (no termios there). Every kind returns all octets already there: serial
    devices and most URLs by in_waiting, socket:// (whose in_waiting says only 0 or 1) by one
    non-blocking read of up to _SOCKET_CHUNK octets.
    """
    if isinstance(ser, _SocketSerial):
        return _read_socket(ser, timeout)
    if FD_IO and type(ser) is serial.Serial and os.name == "posix":
        return _read_fd(ser, timeout)
    n = ser.in_waiting
    if n:
        got: bytes = ser.read(n)            # pyserial (untyped); LineOctets from a parity-marking port
        return got
    if timeout <= 0:
        return b""
    fd = None
    if isinstance(ser, serial.Serial) and hasattr(ser, "fd"):
        fd = ser.fd
    if fd is not None:
        r, _, _ = select.select([fd], [], [], timeout)
        if not r:
            return b""
        n = ser.in_waiting
        if not n:
            # readable but nothing to read: the other end went away (EOF on a pty/USB unplug)
            raise serial.SerialException("device reports readiness to read but returned no data")
        got = ser.read(n)
        return got
    ser.timeout = timeout
    first: bytes = ser.read(1)
    if not first:
        return b""
    n = ser.in_waiting
    rest: bytes = ser.read(n) if n else b""
    return first + rest


#: the most one read takes from a POSIX fd (more than any telegram)
_FD_CHUNK = 4096


def _read_fd(ser: serial.Serial, timeout: float) -> bytes:
    """A plain POSIX device or pty (pyserial opens it non-blocking, VMIN = VTIME = 0): os.read of
    what is there; when nothing is, one select() for at most `timeout` s and os.read again.
    pyserial's in_waiting + read would add an ioctl and a select() of its own to every read
    (parity-marking ports keep pyserial's read: it unescapes the marks)."""
    fd = ser.fd
    if fd is None:
        raise serial.SerialException("port not open")
    try:
        data = os.read(fd, _FD_CHUNK)       # b"" = nothing there (VMIN = 0), not end of file
    except BlockingIOError:
        data = b""
    if data or timeout <= 0:
        return data
    r, _, _ = select.select([fd], [], [], timeout)
    if not r:
        return b""
    try:
        data = os.read(fd, _FD_CHUNK)
    except BlockingIOError:
        return b""
    if not data:
        # readable but nothing to read: the other end went away (EOF on a pty/USB unplug)
        raise serial.SerialException("device reports readiness to read but returned no data")
    return data


def _read_socket(ser: _SocketSerial, timeout: float) -> bytes:
    """socket:// reports only whether data waits (in_waiting 0 or 1): take everything that is
    there with one recv once the socket is readable (one select, one recv) instead of an octet at a
    time. pyserial's own read would drop what it had gathered when the peer closes right after
    sending (a converter's last words); here those octets are returned first, and the next read
    reports the closed connection."""
    sock = getattr(ser, "_socket", None)
    if sock is None:
        raise serial.SerialException("socket not open")
    r, _, _ = select.select([sock], [], [], max(0.0, timeout))
    if not r:
        return b""
    try:
        data: bytes = sock.recv(_SOCKET_CHUNK)     # pyserial's private socket (reached untyped)
    except BlockingIOError:
        return b""
    if not data:
        raise serial.SerialException("socket disconnected")
    return data


#: reads and writes on POSIX devices and ptys with os.read / os.write on the fd (False: through
#: pyserial, for comparison in benchmarks/bench_pty_cpu.py)
FD_IO = True


def posix_fd(ser: serial.SerialBase) -> int | None:
    """The file descriptor of a POSIX serial device or pty that pyserial opened (None for URL
    ports, Windows ports and closed ports, and with FD_IO off)."""
    if not FD_IO or os.name != "posix" or not isinstance(ser, serial.Serial):
        return None
    fd = getattr(ser, "fd", None)
    return fd if isinstance(fd, int) else None


def write_fd(fd: int, data: bytes, timeout: float) -> None:
    """All of `data` to a (non-blocking) POSIX fd with os.write.

    pyserial's Serial.write does the same and then a select() after every write, even when the
    kernel took everything at once (about a quarter of the CPU of an exchange over a pty). Here
    select() is called only when the kernel's buffer is full, to wait at most `timeout` s in all for
    room; serial.SerialTimeoutException when none comes (the adapter stopped sending)."""
    try:
        n = os.write(fd, data)
    except BlockingIOError:
        n = 0
    if n == len(data):
        return                                  # the usual case: the kernel took it all at once
    _write_rest(fd, memoryview(data)[n:], timeout)


def _write_rest(fd: int, view: memoryview, timeout: float) -> None:
    deadline = None
    while view:
        try:
            n = os.write(fd, view)
        except BlockingIOError:
            n = 0
        view = view[n:]
        if not view:
            return
        now = time.monotonic()
        if deadline is None:
            deadline = now + timeout
        if now >= deadline:
            raise serial.SerialTimeoutException("Write timeout")
        select.select([], [fd], [], deadline - now)


def _why(e: BaseException) -> str:
    """The reason of a lost port in words: termios.error(5, 'Input/output error') has no str() of
    its own beyond the tuple."""
    if isinstance(e, _TermiosError) and not isinstance(e, OSError) and len(e.args) == 2:
        return f"[Errno {e.args[0]}] {e.args[1]}"
    return str(e)


def _rate_text(baud: int) -> str:
    """19200 -> '19.2k', 1500000 -> '1.5M' (the DP rates' usual names)."""
    return f"{baud / 1e6:g}M" if baud >= 1000000 else f"{baud / 1e3:g}k" if baud >= 1000 else str(baud)


def echo_setting(value: object) -> Echo:
    """"auto" / "on" / "off" (any case; also True / False) -> "auto" / True / False; ValueError else."""
    if value is True or value is False:
        return value
    text = str(value).strip().lower()
    if text == "auto":
        return "auto"
    if text in ("on", "yes", "true", "1"):
        return True
    if text in ("off", "no", "false", "0"):
        return False
    raise ValueError(f"echo {value!r}: give auto, on or off")


class SerialLink(Link):
    #: the adapter's echo is read back after every write (True: on, or found by echo="auto")
    echo: bool = False
    #: what echo="auto" found at the first transmission: True (the adapter hears itself), False
    #: (it does not), None (not known yet, or the echo was forced on / off)
    echo_detected: bool | None = None
    #: echo="auto" and not decided yet: the next write looks at what comes back
    _echo_unknown: bool = False
    #: octets read while looking for the echo that belong to the next read() (an answer)
    _pending: bytes = b""
    echo_errors: int = 0

    def __init__(self, port: str, baud: int = 19200, rs485: bool = False,
                 echo: bool | str = "auto"):
        #: the last octets read (for the message when the other end closes the connection)
        self._recent = b""
        self.name = port
        self.baud = baud
        self.rs485 = rs485
        #: the setting asked for: "auto", True or False
        try:
            self.echo_mode: Echo = echo_setting(echo)
        except ValueError as e:
            raise UsageError(f"{port}: {e}") from None
        self.echo = self.echo_mode is True
        self.echo_errors = 0
        self.ser: Any = None                # a pyserial port (pyserial has no type hints)
        self._open()

    def _open(self) -> None:
        self.ser = open_serial(self.name, self.baud, self.rs485)
        self.is_simulator = self.name.startswith("sim://")
        #: the simulated bus behind sim:// (for tests and fault injection), else None
        self.bus = getattr(self.ser, "bus", None)
        self.instant = self.bus is not None and not self.bus.wire
        # the simulator adds no latency of its own; a real port's is unknown
        self.latency = 0.0 if self.bus is not None else None
        #: seconds a master adds to every reply timeout for this port's OS and adapter delays,
        #: measured at open (link/margin.py); none on the simulator
        self.margin = 0.0 if self.bus is not None else measure_margin(self.ser, self.name)
        # only the simulator keeps µs timing: ptys, USB adapters and TCP converters add a
        # millisecond or more of their own, so waits there sleep instead of spinning
        self.us_timing = self.bus is not None
        #: writes go straight to the fd with os.write on POSIX devices and ptys (write_fd)
        self._posix = posix_fd(self.ser) is not None
        self._sim_sleep = getattr(self.ser, "sim_sleep", None) if self.bus is not None else None
        self._clock = getattr(self.ser, "clock", time.monotonic) if self.bus is not None \
            else time.monotonic
        # (hot path: the clock itself, no method call around it)
        self.now = self._clock  # type: ignore[method-assign]  # (on purpose: see the line above)
        # a POSIX device or pty read with os.read (read_available's _read_fd): its own read,
        # without the dispatch on the kind of port for every read
        self._fd_read = (FD_IO and type(self.ser) is serial.Serial and os.name == "posix"
                         and not isinstance(self.ser, _SocketSerial))
        self._pending = b""
        if self.echo_mode == "auto":
            # found out again after a reopen (another adapter may be behind the port now); the
            # simulator's handler has no echo
            self.echo = False
            self.echo_detected = False if self.is_simulator else None
            self._echo_unknown = not self.is_simulator

    def now(self) -> float:
        return self._clock()

    def sleep(self, seconds: float) -> None:
        if seconds <= 0:
            return
        if self._sim_sleep is not None:
            self._sim_sleep(seconds)
        elif self.us_timing:
            precise_sleep(seconds)
        else:
            plain_sleep(seconds)

    def reopen(self) -> None:
        """Close and open the same port again (after LinkLost). BusError while it is not back.
        sim:// comes back as a new simulated plant (its stations start in Wait_Prm)."""
        self.close()
        self._open()

    def write(self, data: bytes) -> None:
        try:
            if self._posix:
                fd = self.ser.fd                  # None once closed: the port is gone
                if fd is None:
                    raise LinkLost(f"{self.name}: port closed", self.name)
                write_fd(fd, data, self.ser.write_timeout or 2.0)
            else:
                self.ser.write(data)
            if self.echo:
                self._swallow_echo(data)
            elif self._echo_unknown:
                self._detect_echo(data)
        except serial.SerialTimeoutException:
            raise LinkLost(f"{self.name}: write timed out (adapter gone?)", self.name) from None
        except _GONE as e:
            raise LinkLost(f"{self.name}: port lost while writing: {_why(e)}", self.name) from None

    def _echo_deadline(self, data: bytes) -> float:
        return self.now() + ECHO_WAIT_S + len(data) * 11 / self.baud

    def _swallow_echo(self, data: bytes) -> None:
        """Read the echo of `data` back; octets after it (an answer already there) are kept."""
        deadline = self._echo_deadline(data)
        got = bytearray()
        while len(got) < len(data):
            chunk = self._read_port(deadline)
            if not chunk:
                break
            got += chunk
        if bytes(got[:len(data)]) != data:
            self.echo_errors += 1
        self._pending += bytes(got[len(data):])

    def _detect_echo(self, data: bytes) -> None:
        """echo="auto", the first transmission: read until what came back either is the whole of
        `data` (an echo: dropped) or differs from it in an octet (an answer or noise: kept for
        read()), or until the echo's time is up. Nothing at all by then: no echo. A matching
        beginning that stops short stays undecided (kept for read(); the next write looks again)."""
        deadline = self._echo_deadline(data)
        got = b""
        while True:
            n = min(len(got), len(data))
            if got[:n] != data[:n]:
                self._echo_found(False, data, got)
                self._pending += got
                return
            if len(got) >= len(data):
                self._echo_found(True, data, got)
                self._pending += got[len(data):]
                return
            chunk = self._read_port(deadline)
            if not chunk:
                if not got:
                    self._echo_found(False, data, got)
                self._pending += got
                return
            got += chunk

    def _echo_found(self, echo: bool, data: bytes, got: bytes) -> None:
        self._echo_unknown = False
        self.echo = self.echo_detected = echo
        if echo:
            log.info("%s: the adapter hears its own transmission (local echo of a 2-wire adapter: "
                     "sent %s, read it back): dropping the echo of every telegram", self.name,
                     data.hex(" "))
        else:
            log.info("%s: no local echo (sent %s, read back %s)", self.name, data.hex(" "),
                     got.hex(" ") or "nothing")

    def read(self, deadline: float) -> bytes:
        if self._pending:
            data, self._pending = self._pending, b""
            return data
        return self._read_port(deadline)

    def _read_port(self, deadline: float) -> bytes:
        try:
            if self._fd_read:
                data = _read_fd(self.ser, deadline - self._clock())
            else:
                data = read_available(self.ser, deadline - self.now())
        except _GONE as e:
            raise LinkLost(f"{self.name}: port lost while reading: {_why(e)}{self._last_words()}",
                           self.name) from None
        except TypeError:
            # pyserial raises TypeError from os.read on a closed fd in some versions
            raise LinkLost(f"{self.name}: port closed", self.name) from None
        if data:
            self._recent = (self._recent + data)[-160:]
        return data

    def _last_words(self) -> str:
        """A converter or `pdrive sim --listen` that refuses a client says why in a text line
        before it closes the connection: quote it."""
        tail = getattr(self, "_recent", b"")
        line = tail.rstrip(b"\r\n").rsplit(b"\n", 1)[-1]
        if len(line) >= 8 and all(32 <= c < 127 for c in line):
            return f" (the other end said: {line.decode('ascii')!r})"
        return ""

    def flush_input(self) -> None:
        self._pending = b""
        try:
            if isinstance(self.ser, _SocketSerial):
                # drop what is there, but remember it: a converter's last words may be in it
                while True:
                    data = _read_socket(self.ser, 0.0)
                    if not data:
                        break
                    self._recent = (self._recent + data)[-160:]
            else:
                self.ser.reset_input_buffer()
        except _GONE as e:
            raise LinkLost(f"{self.name}: port lost: {_why(e)}{self._last_words()}",
                           self.name) from None

    def close(self) -> None:
        try:
            self.ser.close()
        except Exception:
            pass
