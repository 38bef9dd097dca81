"""Options every bus command accepts after its name, and opening the master from them."""

from __future__ import annotations

import functools
import json
import logging
import os
import sys
from dataclasses import dataclass, field
from types import TracebackType
from typing import TYPE_CHECKING, Any, Callable, Literal, TypeVar, overload

import click
from rich.console import Console

from profidrive_cli import UsageError
from profidrive_cli.fdl.timing import parse_baud

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.api import Bus
    from profidrive_cli.config import Effective, Setting
    from profidrive_cli.dp.baud import BaudFound
    from profidrive_cli.dp.poller import Master
    from profidrive_cli.link.base import Link

R = TypeVar("R")

def baud_from(text: str | int, source: str) -> int:
    """A baud rate a bus command takes, from where it came (`source`: "option --baud", "env
    PDRIVE_BAUD", "FILE:LINE"); UsageError naming that source unless it is the option itself."""
    try:
        return parse_baud(text)
    except ValueError as e:
        raise UsageError(str(e) if source.startswith("option") else f"{source}: baud {e}") from None


NO_PORT_HELP = ("no port given: use --port DEVICE (e.g. /dev/ttyUSB0, COM3, socket://host:port) "
                "or a port name from the config file, or set PDRIVE_PORT; --port sim:// runs the "
                "built-in simulated bus")

#: the width text output gets when it does not go to a terminal (a pipe, a file): wide enough that
#: rich never wraps a line (a table cell with a long file path stays on one line)
PIPE_WIDTH = 4096


def make_console(stderr: bool = False, **kw: Any) -> Console:
    """A rich console for command output: no soft wrapping, and not wrapped at 80 columns when the
    stream is not a terminal (a pipe or a file gets whole lines; $COLUMNS still wins)."""
    stream = sys.stderr if stderr else sys.stdout
    try:
        tty = stream.isatty()
    except (AttributeError, ValueError):
        tty = False
    if not tty and not os.environ.get("COLUMNS") and "width" not in kw:
        kw["width"] = PIPE_WIDTH
    return Console(stderr=stderr, soft_wrap=True, highlight=False, **kw)


out = make_console()
err = make_console(stderr=True)


@dataclass
class BusOptions:
    port: str | None
    baud: str
    master_address: int
    slot_time: int | None
    retries: int | None
    rs485: bool
    #: --echo: "auto" (found at the first transmission), True (on) or False (off)
    echo: bool | str
    verbose: int
    json: bool
    #: --trace FILE.pcap: every telegram the command sends and receives
    trace: str | None = None
    #: the rate --baud auto found (set by the first open_master/open_link)
    found_baud: int | None = None
    _recorder: TraceFile | None = None
    #: config.Effective: the settings with their sources (config file, env, option, default)
    settings: Effective | None = None
    #: the settings of a project file named (or to be named) on stderr (BusOptions._announce)
    _announced: set[str | tuple[str, int | None, str]] = field(default_factory=set)
    #: those lines before the port is opened: printed then (_notices_now), after the checks of
    #: the options, so that bad input stays one line
    _pending: list[str] | None = field(default_factory=list)

    def source_of(self, name: str) -> str:
        """Where the port / baud / master_address came from ("option --baud", "FILE:LINE", ...)."""
        s = getattr(self.settings, name, None)
        return getattr(s, "source", "option")

    def port_or(self, fallback: str | None) -> str | None:
        """The port for a command whose input file names one (a checklist's `port:`): --port or
        PDRIVE_PORT when given, else `fallback` (a config port name in it resolved), else the config
        file's default port."""
        src = self.source_of("port")
        if not fallback or (self.port and src.startswith(("option", "env"))):
            if self.port:
                self._announce("port")
                self._notices_now()
            return self.port
        from profidrive_cli.config import load
        named = load().ports.get(fallback)
        if named is not None and named.port.project:      # the checklist's name, a project's device
            self._notice(f"port {named.port.value} (port name {named.name})", named.port.source)
            self._notices_now()
        return named.port.value if named is not None else fallback

    def station_defaults(self, address: int | None) -> _UsedDefaults:
        """{"profile" | "layout" | "fmax": value} the config file gives this station on this port.
        Reading a value from it is using it: one from a project file is named on stderr then. The
        values keep their FILE:LINE (config.FileText / FileHz) for the labels and errors."""
        return _UsedDefaults(self, address, {} if self.settings is None else
                             self.settings.station_defaults(address))

    def _announce(self, *names: str) -> None:
        """Name on stderr, once per setting, each of `names` ("port", "baud", "master_address")
        that a project file set: a pdrive.yaml in the working folder or above changes where and
        how a command drives the bus only visibly (docs/config.md)."""
        for name in names:
            s = getattr(self.settings, name, None)
            if s is not None and s.project and name not in self._announced:
                self._announced.add(name)
                what = {"port": "port", "baud": "baud rate", "master_address": "master address"}[name]
                named = getattr(self.settings, "port_name", None) if name == "port" else None
                value = f"{s.value}" + (f" (port name {named})" if named else "")
                self._notice(f"{what} {value}", s.source)

    def _notice(self, what: str, source: str) -> None:
        line = f"pdrive: using {what} from {source} (project file)"
        if self._pending is None:
            click.echo(line, err=True)
        else:
            self._pending.append(line)

    def _notices_now(self) -> None:
        """The port is about to be opened: the project file's settings in use are named now."""
        for line in self._pending or ():
            click.echo(line, err=True)
        self._pending = None

    def check_station(self, address: int) -> int:
        """A station address a command names: 0..125 and not our own master address (a master that
        polls its own address talks to itself, or to a station it must not share the address with)."""
        station_address(address)
        if address == self.master_address:
            src = self.source_of("master_address")
            where = "--master-address" if src.startswith(("option", "default")) else src
            raise UsageError(f"station {address} is the master's own address ({where} = "
                             f"{self.master_address}): give another --master-address")
        return address

    def require_port(self) -> str:
        if not self.port:
            raise UsageError(NO_PORT_HELP)
        self._announce("port", "baud", "master_address")
        return self.port

    @property
    def auto_baud(self) -> bool:
        return self.baud == "auto" and self.found_baud is None

    def baud_rate(self, default: int = 19200) -> int:
        if self.found_baud is not None:
            return self.found_baud
        src = self.source_of("baud")
        named = self.baud not in (None, "", "auto")
        rate = baud_from(self.baud, src) if named else default
        sim = self._sim_baud()
        if sim is not None and sim != rate:
            if named and not src.startswith("default"):
                from profidrive_cli import BusError
                from profidrive_cli.fdl.timing import BAUD_NAMES
                raise BusError(f"the simulated bus {self.port} runs at {BAUD_NAMES[sim]} (baud=), the master "
                               f"at {BAUD_NAMES[rate]} ({src}): its stations would hear only garbage; give "
                               f"--baud {BAUD_NAMES[sim]}, or a sim:// URL without baud=")
            rate = sim          # pdrive built that bus from the URL: the master follows its baud=
        self._announce("port", "baud", "master_address")
        self._notices_now()
        return rate

    def silence_hint(self, link: Link, baud_auto: bool = False) -> str:
        """What to try when nobody answered, fitting the cause: a forced --echo the port never gave
        back (every write waited for an echo that did not come; link.echo_errors) is that; else,
        with baud_auto, --baud auto (the rate may be wrong) unless it was already given."""
        errors = getattr(link, "echo_errors", None)
        if self.echo is True and errors:
            return " (--echo was forced but the port does not echo: drop --echo, or give --no-echo)"
        return " (try --baud auto)" if baud_auto and self.baud != "auto" else ""

    def _sim_baud(self) -> int | None:
        """The rate of a sim://?baud=R port (its stations answer only at R), else None."""
        if not is_sim_port(self.port):
            return None
        from profidrive_cli.sim.plant import url_baud
        return url_baud(str(self.port))

    def open_link(self, baud: int | None = None) -> Link:
        """The link at `baud`, the given rate, or (--baud auto) the rate heard on the line; with
        -vv or --trace wrapped so that every telegram is logged / recorded."""
        if baud is None and self.auto_baud:
            found, link = self._detect(addresses=None, probe=False)
            return self._traced(link)
        return self._traced(self._raw_link(baud or self.baud_rate()))

    def _raw_link(self, baud: int) -> Link:
        from profidrive_cli.link import open_link
        port = self.require_port()
        self._notices_now()
        return open_link(port, baud, rs485=self.rs485, echo=self.echo)

    def _traced(self, link: Link) -> Link:
        if self.verbose < 2 and not self.trace:
            return link
        from profidrive_cli.dp.trace import TraceLink
        if self.trace and self._recorder is None:
            self._recorder = _open_trace(self.trace)
        return TraceLink(link, self._recorder)

    def _make_master(self, link: Link, baud: int | None) -> Master:
        from profidrive_cli.api.bus import make_master     # the one place the master is built
        return make_master(link, baud or self.baud_rate(), self.master_address,
                           slot_time=self.slot_time, retries=self.retries)

    def open_master(self, baud: int | None = None, address: int | None = None) -> Master:
        """A Master at `baud`, the given rate, or (--baud auto) the rate found by listening and
        then probing `address` (every address when None)."""
        if address is not None:
            self.check_station(address)
        if baud is None and self.auto_baud:
            found, master = self._detect(addresses=None if address is None else [address],
                                         probe=True)
            return master
        return self._make_master(self.open_link(baud), baud)

    def open_bus(self, address: int | None = None, *, handle_signals: bool = False,
                 on_message: Callable[[str], None] | None = None) -> Bus:
        """The drive commands' front door: an api.Bus on open_master(address) (--trace / -vv,
        --baud auto and its messages as for every bus command) with the settings and their
        sources. Its stations: Bus.drive (the API's drive) or Bus.session (the session level).
        handle_signals False: each session handles SIGTERM itself."""
        from profidrive_cli.api import Bus
        return Bus(self.open_master(address=address), handle_signals=handle_signals,
                   settings=self.settings, on_message=on_message)

    def _make_master_traced(self, link: Link, baud: int | None) -> Master:
        return self._make_master(self._traced(link), baud)

    @overload
    def _detect(self, addresses: list[int] | None, probe: Literal[True]) -> tuple[BaudFound, Master]: ...
    @overload
    def _detect(self, addresses: list[int] | None, probe: Literal[False]) -> tuple[BaudFound, Link]: ...

    def _detect(self, addresses: list[int] | None, probe: bool) -> tuple[BaudFound, Master | Link]:
        from profidrive_cli import BusError
        from profidrive_cli.dp.baud import detect_baud
        from profidrive_cli.link import open_link
        port = self.require_port()
        self._notices_now()
        res = detect_baud(
            lambda b: open_link(port, b, rs485=self.rs485, echo=self.echo),
            self._make_master_traced, addresses, probe=probe)
        if res[0] is None:
            where = "" if addresses is None else f" from station {addresses[0]}"
            how = "heard no running master" + ("" if not probe else
                                                 f" and got no answer{where}")
            raise BusError(f"--baud auto: {how} at any DP baud rate on {port}")
        found, obj = res
        self.found_baud = found.baud
        err.print(f"{found.describe()}")
        return found, obj


class _UsedDefaults(dict[str, Any]):
    """A station's config defaults {key: value}; reading a key that a project file set names that
    file:line on stderr (once per key): only the defaults a command really uses are named."""

    def __init__(self, opts: BusOptions, address: int | None, settings: dict[str, Setting]) -> None:
        super().__init__({k: s.value for k, s in settings.items()})
        self._opts, self._address, self._settings = opts, address, settings

    def _used(self, key: str) -> None:
        s = self._settings.get(key)
        tag: tuple[str, int | None, str] = ("station", self._address, key)
        if s is not None and s.project and tag not in self._opts._announced:
            self._opts._announced.add(tag)
            value = f"{s.value:g} Hz" if key == "fmax" else f"{s.value}"
            self._opts._notice(f"station {self._address} {key} {value}", s.source)

    def __getitem__(self, key: str) -> Any:
        self._used(key)
        return super().__getitem__(key)

    def get(self, key: str, default: Any = None) -> Any:
        if key in self:
            self._used(key)
        return super().get(key, default)

    def peek(self, key: str) -> Any:
        """The value without using it (an fmax only checked against the drive's own): not named."""
        return super().get(key)


class _StderrHandler(logging.Handler):
    """Log lines on whatever sys.stderr is when they are emitted (click's test runner swaps it)."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            sys.stderr.write(self.format(record) + "\n")
            sys.stderr.flush()
        except Exception:
            self.handleError(record)


def configure_logging(verbose: int) -> None:
    """-v: DP service steps (profidrive_cli.dp at INFO); -vv: also every telegram
    (profidrive_cli.trace at DEBUG). On stderr, so that stdout stays the command's output."""
    logger = logging.getLogger("profidrive_cli")
    for h in [h for h in logger.handlers if isinstance(h, _StderrHandler)]:
        logger.removeHandler(h)
    if verbose <= 0:
        return
    h = _StderrHandler()
    h.setFormatter(logging.Formatter("%(message)s"))
    logger.addHandler(h)
    logger.setLevel(logging.DEBUG if verbose >= 2 else logging.INFO)


def _open_trace(path: str) -> TraceFile:
    """The --trace recorder: a pcap written beside the target and renamed over it when the command
    ends (whatever way it ends: the trace of a failure is the useful one)."""
    rec = TraceFile(path)
    ctx = click.get_current_context(silent=True)
    if ctx is not None:
        ctx.with_resource(rec)
    return rec


class TraceFile:
    """The --trace pcap file. write(t, raw) never raises: it runs inside every Data_Exchange and
    the safe stop's telegrams. A failed write (disk full, /dev/full) ends the recording and is kept
    in `error`; it is reported when the command's context closes, after the stop and the release:
    one line and exit 1 when the command itself succeeded (a file the user asked for is lost), the
    same line before the command's own error otherwise."""

    def __init__(self, path: str):
        from profidrive_cli.dp.capture import PcapWriter
        from profidrive_cli.outfile import OutputFile
        self.file = OutputFile(path, "wb", what="trace file")
        self.file.open()
        #: OutputWriteError (or any exception of the writer) once recording failed
        self.error: Exception | None = None
        self._pcap = None
        try:
            self._pcap = PcapWriter(self.file)
        except Exception as e:          # noqa: BLE001
            self._failed(e)

    def write(self, t: float, raw: bytes) -> None:
        if self._pcap is None:
            return
        try:
            self._pcap.write(t, raw)
        except Exception as e:          # noqa: BLE001  (never from inside an exchange)
            self._failed(e)

    def _failed(self, e: Exception) -> None:
        from profidrive_cli.outfile import OutputWriteError
        self._pcap = None
        self.file.discard()
        self.error = e if isinstance(e, OutputWriteError) else OutputWriteError(
            f"trace file {self.file.path}: recording failed: {e}")

    def close(self) -> Exception | None:
        """Rename the pcap into place; the error, if recording or the rename failed."""
        from profidrive_cli.outfile import OutputWriteError
        if self._pcap is not None:
            self._pcap = None
            try:
                self.file.commit()
            except OutputWriteError as e:
                self.error = e
        return self.error

    def __enter__(self) -> TraceFile:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> Literal[False]:
        e = self.close()
        if e is None:
            return False
        # a clean end: no exception, or an exit with code 0 (sys.exit / click's ctx.exit)
        code = getattr(exc, "exit_code", getattr(exc, "code", 1)) if exc is not None else 0
        ok = exc_type is None or (issubclass(exc_type, (SystemExit, click.exceptions.Exit))
                                  and code in (0, None))
        if ok:
            raise e                     # the command worked, its trace is lost: exit 1
        sys.stdout.flush()
        click.echo(f"pdrive: {e}", err=True)
        return False


def complete_port(ctx: click.Context, param: click.Parameter, incomplete: str) -> list[str]:
    """Shell completion of --port: the port names from the config files, and sim://."""
    try:
        from profidrive_cli.config import load
        names = list(load().ports)
    except Exception:           # noqa: BLE001  (a broken config file must not break the shell)
        names = []
    return [n for n in [*names, "sim://"] if n.startswith(incomplete)]


def bus_options(f: Callable[..., R]) -> Callable[..., R]:
    """--port, --baud, --master-address, --slot-time, --retries, --rs485, --echo, -v, --trace, --json."""
    @click.option("--port", default=None, metavar="PORT", shell_complete=complete_port,
                  help="Serial device, pyserial URL, sim://, or a port name from the config file "
                       "(env PDRIVE_PORT; `pdrive config show`).")
    @click.option("--baud", default=None, metavar="RATE",
                  help="Bus baud rate (9.6k … 12M; env PDRIVE_BAUD, else the config file's, else 19200).")
    @click.option("--master-address", default=None, type=click.IntRange(0, 125),
                  help="Our bus address (default: the config file's, else 2).")
    @click.option("--slot-time", default=None, type=int, metavar="BITS",
                  help="Reply timeout in bit times (default: the standard TSL for the baud rate).")
    @click.option("--retries", default=None, type=click.IntRange(0, 15),
                  help="Retries after no reply (default 2 on real ports, 1 on sim://).")
    @click.option("--rs485", is_flag=True, help="Kernel RS-485 mode (RTS direction control).")
    @click.option("--echo/--no-echo", default=None,
                  help="Local echo of a 2-wire adapter: by default found at the first transmission "
                       "and dropped; --echo / --no-echo force it on / off.")
    @click.option("-v", "--verbose", count=True,
                  help="-v: DP service steps (start-up, diagnosis, retries); -vv: every telegram. "
                       "On stderr.")
    @click.option("--trace", "trace", default=None, metavar="FILE.pcap",
                  help="Record every telegram this command sends and receives (pcap).")
    @click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
    @functools.wraps(f)
    def wrapper(port: str | None, baud: str | None, master_address: int | None, slot_time: int | None,
                retries: int | None, rs485: bool, echo: bool | None, verbose: int, trace: str | None,
                as_json: bool, **kw: Any) -> R:
        configure_logging(verbose)
        if trace:
            from profidrive_cli.outfile import check_output_path
            check_output_path(trace, "trace file")
        from profidrive_cli.config import resolve
        eff = resolve(port, baud, master_address)
        opts = BusOptions(eff.port.value, str(eff.baud.value), eff.master_address.value, slot_time,
                          retries, rs485, "auto" if echo is None else echo,
                          verbose, as_json, trace, settings=eff)
        return f(opts, **kw)
    return wrapper


def emit_json(obj: Any) -> None:  # Any: whatever json.dumps takes (a command's JSON object)
    sys.stdout.write(json.dumps(obj, indent=None, sort_keys=False) + "\n")
    sys.stdout.flush()


def station_address(value: int) -> int:
    if not 0 <= value <= 125:
        raise UsageError(f"station address {value} outside 0..125")
    return value


def hex_option(text: str | None, what: str) -> bytes | None:
    if text is None:
        return None
    from profidrive_cli.dp.cfg import parse_hex
    try:
        return parse_hex(text)
    except ValueError as e:
        raise UsageError(f"{what}: {e}") from None


def is_tty() -> bool:
    return sys.stdout.isatty() and os.environ.get("CI") is None


def is_sim_port(port: str | None) -> bool:
    """The built-in simulated bus: nothing real can move, so nothing asks."""
    return (port or "").startswith("sim://")


def can_ask() -> bool:
    """A person can answer: the answer is read from stdin and the question shown on stderr."""
    return sys.stdin.isatty() and sys.stderr.isatty()


def confirm_real_port(port: str | None, yes: bool, text: str,
                      cancelled: str = "cancelled: nothing was written") -> None:
    """Before anything moves a drive or changes a setting on a real port: --yes, or 'y' on a terminal.

    sim:// never asks. Without a terminal to ask (stdin or stderr not a terminal) and without --yes:
    UsageError (exit 2) before anything is sent. 'n' (or end of input) on the terminal: exit 1.
    """
    if yes or is_sim_port(port):
        return
    if not can_ask():
        raise UsageError(f"{text}: this writes to a real port; add --yes to confirm "
                         f"(no terminal to ask)")
    try:
        ok = click.confirm(f"{text}. Continue?", default=False, err=True)
    except click.exceptions.Abort:
        ok = False
        err.print()
    if not ok:
        err.print(cancelled)
        raise SystemExit(1)
