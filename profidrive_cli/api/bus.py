"""open_bus and Bus: one port, its DP master, the drives opened on it, the keep-alive that holds
every opened drive in data exchange between calls, and the safe stop of every drive on close.

Thread model: every public call holds the bus lock for its whole duration; the keep-alive thread
takes the same lock, so the master is only ever used by one thread at a time. While a call talks
to one station, every other opened station still gets a Data_Exchange at least every KEEP_S
seconds (a hook on each drive's channel); while nobody calls, the keep-alive thread sends them
(api/keepalive.py: also what a station it did not hold gives).

The stop on close (bus.close(), leaving the `with`): the stop command of every started drive in one
bus cycle and one bounded wait for all together (session/group.py's Group, as `pdrive run 3,4,5`),
a coast stop for each one not stopped in its time. A bus never closed is closed at interpreter exit
(atexit; also when the script ends with an exception) or when it is garbage collected, with a
ResourceWarning. An exception raised by on_message is recorded and
raised after the call (after the stop, on close), never from inside a cycle or the stop.
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import threading
import os
import warnings
import weakref
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, Callable, Iterable, Iterator, Literal, Mapping, TypeVar, cast

from profidrive_cli import BusError, UsageError
from profidrive_cli.api import keepalive
from profidrive_cli.api.keepalive import API_WATCHDOG_MS, KEEP_S
from profidrive_cli.api.results import Param, ParamsError, Station

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.api.results import AuditResult

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.api.drive import Drive
    from profidrive_cli.dp.poller import Master
    from profidrive_cli.link.base import Link
    from profidrive_cli.session import DriveStation
    from profidrive_cli.session.group import Group
    from profidrive_cli.session.safestop import StopReport
    from profidrive_cli.session.signals import SignalGuard
    from profidrive_cli.session.together import Outcome

T = TypeVar("T")

#: every bus not yet closed (weakly: a closed or dropped bus is not kept alive by this)
_open_buses: "weakref.WeakSet[Bus]" = weakref.WeakSet()
#: the master (so the port) of every bus not yet closed, held strongly: when a dropped bus is
#: collected, its port is not collected with it (closed by its own finalizer first), so the stop
#: can still be sent. id(bus) -> master
_masters: dict[int, Any] = {}


@atexit.register
def _close_at_exit() -> None:
    """At interpreter exit (also after an uncaught exception): every bus still open is closed, so its
    drives are stopped, with a ResourceWarning that the script did not close it."""
    for bus in list(_open_buses):
        bus._close_unclosed("at interpreter exit")


def open_bus(port: str | None = None, *, baud: str | int | None = None,
             master_address: int | None = None, retries: int | None = None,
             slot_time: int | None = None, rs485: bool = False, echo: bool | str = "auto",
             allow_real_port_writes: bool = False, handle_signals: bool = True,
             on_message: Callable[[str], None] | None = None,
             env: Mapping[str, str] | None = None) -> "Bus":
    """Open a bus: a device (/dev/ttyUSB0, COM3), a pyserial URL, sim://, or a port name from the
    config file (config.py). None: PDRIVE_PORT, else the config file's default port. baud and
    master_address as the CLI's --baud / --master-address (default: PDRIVE_BAUD, the config file,
    19200 and 2). The API never asks: on a real port, anything that moves a drive or writes a
    setting needs allow_real_port_writes=True (sim:// is always allowed). Use it as a context
    manager (or call close()): every drive it started is stopped on the way out (a bus never
    closed: at interpreter exit, with a ResourceWarning). on_message(text): warnings and what the
    safe stop did, one line each (also kept in Drive.warnings); what it raises is raised after the
    call (after the stop), never inside it. echo: "auto" (a 2-wire adapter's local echo found at
    the first transmission and dropped), True / False to force it. env: the
    environment read for PDRIVE_PORT, PDRIVE_BAUD, PDRIVE_CONFIG and PDRIVE_STATION (default
    os.environ)."""
    from profidrive_cli.config import resolve
    eff = resolve(port, baud, master_address, env=env)
    if not eff.port.value:
        raise UsageError("open_bus: no port given (a device, sim://, or a port name from the config "
                         "file; or set PDRIVE_PORT)")
    return Bus(_open_master(str(eff.port.value), str(eff.baud.value), eff.baud.source,
                            int(eff.master_address.value), retries, slot_time, rs485, echo),
               allow_real_port_writes=allow_real_port_writes, handle_signals=handle_signals,
               settings=eff, on_message=on_message, env=env)


def _open_master(port: str, baud: str, baud_source: str, address: int, retries: int | None,
                 slot_time: int | None, rs485: bool, echo: bool | str) -> "Master":
    from profidrive_cli.fdl.timing import parse_baud
    from profidrive_cli.link import open_link
    if not 0 <= address <= 125:
        raise UsageError(f"master address {address} outside 0..125")
    if str(baud).strip().lower() == "auto":
        raise UsageError("open_bus: baud 'auto' is not supported by the API; give the rate")
    try:
        rate = parse_baud(baud)
    except ValueError as e:
        where = "" if baud_source.startswith(("option", "default")) else f"{baud_source}: "
        raise UsageError(f"{where}baud {e}") from None
    return make_master(open_link(port, rate, rs485=rs485, echo=echo), rate, address,
                       slot_time=slot_time, retries=retries)


def make_master(link: "Link", baud: int, address: int, *, slot_time: int | None = None,
                retries: int | None = None) -> "Master":
    """The DP master on an open link: the one place pdrive builds it (open_bus, and the CLI's bus
    options with their --trace, --baud auto and -vv links). Bus parameters for `baud`: the standard
    slot time unless slot_time; retries after no reply: 1 on sim://, else 2; the reply timeout
    widened for USB/OS latency except on the instant simulator. A bad parameter (slot time,
    address): UsageError, and the link is closed (also on any other failure)."""
    from profidrive_cli.dp.poller import Master
    from profidrive_cli.fdl.timing import BusParams
    try:
        # over real ports, widen the reply timeout for USB/OS latency (reference §4.3); the
        # instant simulator needs none, a real port measured its own (link/margin.py)
        params = BusParams.for_baud(
            baud, slot_time=slot_time,
            retries=retries if retries is not None else (1 if link.is_simulator else 2),
            link_latency=0.0 if link.instant else getattr(link, "margin", 0.02))
        return Master(link, params, address)
    except ValueError as e:
        link.close()
        raise UsageError(str(e)) from None
    except BaseException:
        link.close()
        raise


class _SharedSignals:
    """A drive session's signal guard that only shares the bus's `hurry` (the bus installs and
    restores the handlers once for all its drives)."""

    def __init__(self, guard: "SignalGuard") -> None:
        self._guard = guard

    @property
    def hurry(self) -> bool:
        return bool(self._guard.hurry)

    @hurry.setter
    def hurry(self, value: bool) -> None:
        self._guard.hurry = value

    def install(self) -> None:
        pass

    def guard(self) -> None:
        pass

    def restore(self) -> None:
        pass


class Bus:
    """An open bus. Made by open_bus(); see there and docs/api.md."""

    def __init__(self, master: "Master", *, allow_real_port_writes: bool = False, handle_signals: bool = True,
                 settings: Any = None, on_message: Callable[[str], None] | None = None,
                 env: Mapping[str, str] | None = None) -> None:
        from profidrive_cli.session.signals import SignalGuard
        self.master = master
        self.port: str = getattr(master.link, "name", "") or ""
        self.allow_real_port_writes = allow_real_port_writes
        self.settings = settings
        self.on_message = on_message
        self.env = os.environ if env is None else env
        self._lock = threading.RLock()
        self._drives: dict[int, "Drive"] = {}
        self._last: dict[int, float] = {}
        self._closed = False
        #: exceptions raised by on_message, raised after the call (after the stop on close)
        self._callback_errors: list[BaseException] = []
        #: the drives' Group: its keep rule; its bus cycle for the stop on close (the keep-alive
        #: hooks stand aside meanwhile)
        self._group: "Group | None" = None
        self._signals = SignalGuard(handle_signals)
        self._signals.install()
        self._stop_keepalive = threading.Event()
        self._keepalive_error: BaseException | None = None
        #: the stations the keep-alive did not hold (each raised by its drive's next call)
        self._missed = keepalive.Missed()
        self._thread: threading.Thread | None = None
        #: a together() run is under way: its rounds hold every station (its jobs' threads must
        #: never reach the master through the channels' hooks)
        self._together = False
        _open_buses.add(self)
        _masters[id(self)] = master

    def __del__(self) -> None:
        if getattr(self, "_closed", True):
            return
        try:
            self._close_unclosed("when it was garbage collected")
        except BaseException:               # noqa: BLE001  (never from __del__)
            pass

    def _close_unclosed(self, when: str) -> None:
        if self._closed:
            return
        started = sorted(a for a, d in self._drives.items() if d._station.motion.may_run)
        warnings.warn(f"pdrive: the bus on {self.port} was never closed; pdrive stops "
                      f"{'the drives it started (' + ', '.join(map(str, started)) + ')' if started else 'it'} {when} "
                      f"(use `with open_bus(...)` or bus.close())", ResourceWarning, source=self)
        self.close()

    # -- callbacks -----------------------------------------------------------------------------
    def _message(self, text: str) -> None:
        """on_message(text); what it raises is kept for after the call (never inside a stop)."""
        if self.on_message is None:
            return
        try:
            self.on_message(text)
        except BaseException as e:          # noqa: BLE001  (reported after the call / the stop)
            self._callback_errors.append(e)

    def _raise_callback_error(self, exc: BaseException | None = None) -> None:
        """The first exception on_message raised: raised now, or, when `exc` already ends the work,
        noted on it."""
        if not self._callback_errors:
            return
        e, self._callback_errors = self._callback_errors[0], []
        if exc is None:
            raise e
        if hasattr(exc, "add_note"):
            exc.add_note(f"on_message raised {type(e).__name__}: {e} (after the stop)")

    @contextlib.contextmanager
    def _call(self) -> Iterator[None]:
        """A public call: the bus lock for its whole duration; an on_message error after it."""
        with self._lock:
            yield
            self._raise_callback_error()

    # -- context manager ------------------------------------------------------------------------
    def __enter__(self) -> "Bus":
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> Literal[False]:
        self.close(exc)
        return False

    @property
    def is_simulator(self) -> bool:
        return self.port.startswith("sim://")

    @property
    def baud(self) -> int:
        return self.master.params.baud

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def simulator(self) -> Any:
        """On sim://, the plant's control (sim/control.py): trip(station, alarm=None), clear,
        unplug, replug, set(station, code, value), faults(spec), state(), each under this bus's
        lock, between two telegrams; None on any other port."""
        sim = getattr(self.master.link, "bus", None)
        return None if sim is None else sim.control(lock=self._lock, clock=self.master.link.now)

    def close(self, exc: BaseException | None = None) -> None:
        """Stop every drive this bus started (the stop command of all in one bus cycle, one
        bounded wait for all together, coast for each one not stopped in its time), release every
        station, close the port. Idempotent. `exc`: the exception that ends the work, if any (the
        line is flushed first). Raises, after all that, the first error of a drive's close or of
        on_message (when `exc` is None)."""
        if self._closed:
            return
        self._closed = True
        _open_buses.discard(self)
        self._stop_keepalive.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)
        self._signals.guard()
        first: BaseException | None = None
        try:
            with self._lock:
                close_exc = exc
                try:
                    close_exc = self._stop_together(exc) or exc
                except BaseException as e:          # noqa: BLE001  (each drive's own stop next)
                    first = e
                while self._drives:
                    # out of the keep-alive before its stop and release (the others stay kept)
                    _, drive = self._drives.popitem()
                    try:
                        drive._close(close_exc)
                    except BaseException as e:      # noqa: BLE001  (the others still need theirs)
                        first = first or e
        finally:
            try:
                self.master.link.close()
            except Exception:
                pass
            _masters.pop(id(self), None)
            self._signals.restore()
        if first is not None and exc is None:
            raise first
        self._raise_callback_error(exc)

    def _stop_together(self, exc: BaseException | None) -> BaseException | None:
        """The stop of every drive that may run, together (see the module doc); each session's
        stop_report is set. Returns the LinkLost that ended it, if one did (the sessions' close
        then says what the watchdog will do); a drive not confirmed stopped here gets its own
        safe stop in its session's close."""
        import time
        from profidrive_cli.link.base import LinkLost
        if isinstance(exc, LinkLost):
            return None
        sessions = [d._station for d in self._drives.values() if d._station.channel is not None]
        running = [s for s in sessions if s.motion.may_run and not s.link_lost and s.drive is not None]
        if not running:
            return None
        if exc is not None:
            # an interrupted request may have left a reply on the line: start clean
            try:
                time.sleep(min(0.05, self.master.params.reply_timeout(64)))
                self.master.link.flush_input()
            except Exception:               # noqa: BLE001
                pass
        group = self._the_group()
        rate = min([group.rate(self.master, [s.wire_hz for s in sessions])[0]]
                   + [s.cycle_hz for s in sessions if s.cycle_hz])
        group.period = 1.0 / rate if rate > 0 else 0.0
        for s in sessions:
            group.join(s)

        def hurry() -> bool:
            h, self._signals.hurry = self._signals.hurry, False
            return h
        try:
            group.stop_all([(_address(s), s, _speed_percent(s)) for s in running], hurry)
            group.finish()
        except LinkLost as e:
            for s in running:
                s.link_lost = True
            return e
        except BusError as e:
            self._message(f"stop: {e}; each drive not yet stopped gets its own stop")
        for s in running:
            r = s.motion.stop_report
            if r is not None and r.stopped:
                s.say(stop_words(_address(s), r))
        return None

    def hurry(self) -> None:
        """A second signal arrived (the asyncio face's aio.run: its signal handler, not this bus's):
        the stop under way, or the next, coasts at once, as on a second signal here."""
        self._signals.hurry = True

    # -- checks ------------------------------------------------------------------------------------
    def _check_open(self, station: int | None = None) -> None:
        """The bus is open and its keep-alive thread did not fail; `station` (a drive's call): the
        keep-alive held it since the drive's last call (DriveError once, when it did not)."""
        if self._closed:
            raise UsageError(f"the bus on {self.port} is closed")
        if self._keepalive_error is not None:
            e, self._keepalive_error = self._keepalive_error, None
            raise BusError(f"{self.port}: keeping the drives in data exchange failed: {e}") from e
        if station is not None:
            self._missed.check(station)

    def _check_write(self, what: str) -> None:
        if self.is_simulator or self.allow_real_port_writes:
            return
        raise UsageError(f"{what}: this writes to a real port ({self.port}); open the bus with "
                         f"open_bus(..., allow_real_port_writes=True)")

    # -- stations ----------------------------------------------------------------------------------
    def scan(self, first: int = 0, last: int = 126) -> list[Station]:
        """Every station that answers FDL status in first..last: its kind, ident, the matching
        pdrive profile and its DP state. Stations opened with drive() keep exchanging data."""
        from profidrive_cli.dp.scan import scan
        from profidrive_cli.drives.profile import profile_for_ident
        if not 0 <= first <= last <= 126:
            raise UsageError(f"scan: range {first}..{last} is not within 0..126")
        with self._call():
            self._check_open()
            out = []
            opened = set(self._drives)
            for a in range(first, last + 1):
                if a in opened:
                    d = self._drives[a]
                    out.append(Station(a, "slave", d.ident, d.profile, "data exchange"))
                    continue
                for e in scan(self.master, a, a):
                    prof = profile_for_ident(e.ident) if e.ident is not None else None
                    out.append(Station(e.address, e.station_type, e.ident,
                                       prof.name if prof is not None else None,
                                       e.diag.state_words(self.master.address) if e.diag else e.error))
                self._keep_others(None)
            return out

    def drive(self, station: int | None = None, *, profile: str | None = None,
              layout: str | None = None, ppo: int | None = None, fmax: float | None = None,
              watchdog_ms: float = API_WATCHDOG_MS,
              cycle_hz: float | None = None, stop_timeout: float | None = None) -> "Drive":
        """The drive at `station` (None: PDRIVE_STATION, else the only drive station on the bus),
        brought to data exchange and kept there until the bus is closed. profile: a profile name or
        alias (default: the config file's for this station, else from the station's ident);
        layout: a layout name (e.g. "ppo3", "toyo") or ppo=N (default: the config file's, else the
        profile's); fmax: the frequency 100 % stands for when the drive's own value cannot be read.
        watchdog_ms: the DP watchdog (default API_WATCHDOG_MS: generous, as only the keep-alive
        thread holds the station between calls). The same station twice: the same Drive."""
        from profidrive_cli.api.drive import Drive
        from profidrive_cli.session import DriveStation
        with self._call():
            self._check_open()
            if station is not None and (isinstance(station, bool) or not isinstance(station, int)
                                        or not 0 <= station <= 125):
                raise UsageError(f"station {station!r} is not a bus address 0..125")
            if station in self._drives:
                return self._drives[station]
            defaults = {}
            if self.settings is not None:
                defaults = {k: s.value for k, s in self.settings.station_defaults(station).items()}
            if layout is None and ppo is None:
                layout = defaults.get("layout")
            sess = DriveStation(self.master, station, profile=profile or defaults.get("profile"),
                                layout=layout, ppo=ppo, watchdog_ms=watchdog_ms,
                                cycle_hz=cycle_hz, stop_timeout=stop_timeout, close_link=False,
                                handle_signals=False, on_message=self._message, env=self.env)
            sess.signals = _SharedSignals(self._signals)
            try:
                sess.open()
            except BaseException as e:
                sess.close(e)
                raise
            if fmax is None:                         # the config's: used where the drive's own is
                fmax = defaults.get("fmax")          # not readable, else checked against it (warning)
            drive = Drive(self, sess, fmax)
            address, channel = sess.address, sess.channel
            assert address is not None and channel is not None      # open() found and connected it
            self._drives[address] = drive
            self._last[address] = self.master.link.now()
            channel.hooks.append(lambda t, o, i: self._exchanged(address, t))
            if self._thread is None:
                self._thread = keepalive.start(self, self._stop_keepalive)
            return drive

    def audit(self, stations: list[int] | None = None, *, profile: str | None = None,
              layout: str | None = None, ppo: int | None = None, watchdog_ms: float = 500,
              cycle_s: float | None = None, max_reaction_s: float | None = None
              ) -> list["AuditResult"]:
        """Drive.audit() of each station (None: every station the scan finds with a known drive
        profile), all at once (one bus cycle carrying a request of each: together()), the results
        lowest station first; a drive this call opened is closed again as soon as its audit is
        done (a drive opened before stays open). BusError when there is no drive station to audit;
        a station's error is raised (the lowest station's) once every audit has ended."""
        from profidrive_cli.api.drive import audit_result
        from profidrive_cli.session.audit import audit_session
        if stations is None:
            found = [s.station for s in self.scan(0, 125) if s.kind == "slave" and s.profile]
            if not found:
                raise BusError(f"audit: no drive station found on {self.port}")
        else:
            found = sorted(set(stations))
        opened = [st for st in found if st not in self._drives]
        try:
            drives = {st: self.drive(st, profile=profile, layout=layout, ppo=ppo,
                                     watchdog_ms=watchdog_ms) for st in found}
            with self._call():
                for st in drives:
                    self._check_open(st)

                def done(st: int, _: object) -> None:
                    if st in opened:
                        drives[st].close()
                out = self.together(
                    {st: d._station for st, d in drives.items()},
                    {st: functools.partial(audit_session, d._station, cycle_s=cycle_s,
                                           max_reaction_s=max_reaction_s)
                     for st, d in drives.items()}, on_done=done)
        finally:
            for st in opened:
                d = self._drives.get(st)
                if d is not None:
                    d.close()
        for st in found:
            if out[st].error is not None:
                raise cast(BaseException, out[st].error)
        return [audit_result(out[st].value) for st in found]

    def read_params(self, stations: "Mapping[int, Iterable[str]] | Iterable[int]",
                    codes: "Iterable[str] | None" = None, *, cancel: threading.Event | None = None
                    ) -> dict[int, dict[str, Param]]:
        """Read parameters of several drives at once: one bus cycle carries a request to each of
        them (session/together.py), so a line reads at the pace of the wire and of its slowest
        drive, not of the sum of them. stations: {station: [codes]}, or stations with `codes` for
        every one (read_params([3, 4, 5], ["F07", "F08"])). A drive not yet opened is opened
        (profile and layout as drive() chooses them) and closed again as soon as it is read.
        Every code of every drive is checked before the first parameter request (UsageError:
        nothing read). cancel: a threading.Event another thread may set: the reads end before the
        next bus round (session.together.Stopped, a BusError). Returns {station: {code:
        Param}}; when a drive could not be read, ParamsError (a BusError) after every other was:
        its .errors {station: why} and .partial (what was read)."""
        if isinstance(stations, Mapping):
            if codes is not None:
                raise UsageError("read_params: give the codes either per station or as codes=, "
                                 "not both")
            given = dict(stations)
        else:
            if codes is None:
                raise UsageError("read_params: which codes? read_params([3, 4], ['F07'])")
            given = {st: codes for st in stations}
        wanted: dict[int, list[str]] = {}
        for st, cs in given.items():
            if isinstance(cs, str) or not all(isinstance(c, str) for c in cs):
                raise UsageError(f"read_params: station {st}: the codes must be a list of strings")
            wanted[st] = list(cs)
        opened = [st for st in wanted if st not in self._drives]
        try:
            drives = {st: self.drive(st) for st in sorted(wanted)}
            with self._call():
                for st in drives:
                    self._check_open(st)
                infos = {st: [drives[st]._station.params.info(c) for c in wanted[st]]
                         for st in drives}

                def job(st: int) -> Callable[[], dict[str, Param]]:
                    params = drives[st]._station.params
                    return lambda: {c: Param.of(params.read_info(i))
                                    for c, i in zip(wanted[st], infos[st])}
                def done(st: int, _: object) -> None:
                    if st in opened:             # opened for this call: released at once
                        drives[st].close()
                out = self.together({st: d._station for st, d in drives.items()},
                                    {st: job(st) for st in drives}, on_done=done, cancel=cancel)
        finally:
            for st in opened:
                d = self._drives.get(st)
                if d is not None:
                    d.close()
        errors = {st: str(o.error) for st, o in out.items() if o.error is not None}
        values = {st: o.value for st, o in out.items() if o.value is not None}
        if errors:
            raise ParamsError(errors, values)
        return values

    def together(self, sessions: "Mapping[int, DriveStation]", jobs: "Mapping[int, Callable[[], T]]",
                 on_done: "Callable[[int, Outcome[T]], None] | None" = None,
                 cancel: threading.Event | None = None) -> "dict[int, Outcome[T]]":
        """The station level: jobs[address]() of every station at once, each talking to its own
        connected session (sessions[address]), one bus cycle carrying a request to each
        (session/together.py: the rounds in this thread, unpaced; every other opened drive of this
        bus held by the keep rule). on_done(address, outcome): in this thread as soon as a job ends
        (write its result, close its session: the rounds stop keeping it). Returns {address:
        Outcome} (.value or .error, per station); raises LinkLost and what this thread gets
        meanwhile (Ctrl-C, SessionTerminated) after every job has ended."""
        from profidrive_cli.session.together import run_together
        with self._call():
            self._check_open()
            channels = {}
            for a in jobs:
                ch = sessions[a].channel
                if ch is None:
                    raise UsageError(f"station {a}: not connected")
                channels[a] = ch
            self._together = True
            try:
                return run_together(self.master, channels, jobs, keep=list(self._drives),
                                    on_done=on_done, cancel=cancel)
            finally:
                self._together = False
                now = self.master.link.now()
                for a in self._drives:
                    self._last[a] = now

    def station(self, station: int | None = None, *, profile: str | None = None,
                layout: str | None = None, ppo: int | None = None, fmt: str | None = None,
                watchdog_ms: float = 500, cycle_hz: float | None = None,
                stop_timeout: float | None = None, handle_signals: bool = True,
                before_connect: Callable[["DriveStation"], None] | None = None,
                on_message: Callable[[str], None] | None = None,
                log_csv: str | Path | None = None,
                own_port: bool = False) -> "DriveStation":
        """The station level, for tools (the CLI's drive commands, the checklist): a DriveStation
        (profidrive_cli.api.station) on this bus's master, not yet opened. Use it as a context manager:
        it finds the station, brings it to data exchange (before_connect(session) runs first, once
        the profile is known: a confirmation) and, on the way out, stops the drive safely and
        releases the station. Beside drive(): progress callbacks, on_message, the --log CSV, the
        checked parameter work, dump / restore; nothing of the config file is applied (the tool
        passes profile and layout), the bus does not keep it alive and its close does not stop it
        (the session's own exit does). The port stays the bus's: close the bus after the session.
        handle_signals: SIGTERM raises session.SessionTerminated while it is open (the CLI's
        sessions; False when the caller handles signals). own_port=True: the session takes the
        port (a tool on one station: the CLI's drive commands): its exit closes it, and this bus is
        done at once (closed; it must not have opened a drive)."""
        from profidrive_cli.session import DriveStation
        with self._call():
            self._check_open()
            if own_port and self._drives:
                raise UsageError(f"the bus on {self.port} has drives open: own_port needs a bus of "
                                 f"its own")
            try:
                if station is not None and (isinstance(station, bool) or not isinstance(station, int)
                                            or not 0 <= station <= 125):
                    raise UsageError(f"station {station!r} is not a bus address 0..125")
                sess = DriveStation(self.master, station, profile=profile, layout=layout, ppo=ppo,
                                    fmt=fmt, watchdog_ms=watchdog_ms, cycle_hz=cycle_hz,
                                    stop_timeout=stop_timeout, close_link=own_port,
                                    handle_signals=handle_signals, before_connect=before_connect,
                                    on_message=on_message, log_csv=log_csv, env=self.env)
            except BaseException:
                if own_port:
                    self.close()
                raise
            if own_port:
                self._hand_over()
            return sess

    def _hand_over(self) -> None:
        """The port now belongs to a session (own_port): this bus is closed without touching it."""
        self._closed = True
        _open_buses.discard(self)
        _masters.pop(id(self), None)
        self._stop_keepalive.set()
        self._signals.restore()

    @property
    def drives(self) -> list["Drive"]:
        """The drives opened on this bus (in data exchange until closed)."""
        return list(self._drives.values())

    # -- keep-alive --------------------------------------------------------------------------------
    def _the_group(self) -> "Group":
        """The Group of this bus's drives: which of them a keep-alive cycles, and the bus cycle of
        the stop on close."""
        if self._group is None:
            from profidrive_cli.session.group import Group
            self._group = Group(self.master)
        return self._group

    def _keep_s(self) -> float:
        wd = min((d._station.watchdog_ms for d in self._drives.values()), default=500.0)
        return min(KEEP_S, wd / 5000.0)

    def _exchanged(self, address: int, t: float) -> None:
        """After a Data_Exchange with `address`: the other opened stations that are due get one."""
        self._last[address] = t
        if self._together or (self._group is not None and self._group.cycling):
            return                          # the rounds exchange every station (in this thread)
        self._keep_others(address)

    def _keep_others(self, busy: int | None) -> None:
        """A Data_Exchange (with its last outputs) for every opened station other than `busy` whose
        last one is KEEP_S old (the Group's keep rule). A station that cannot be kept is left to its
        own next call (which then reports it); a lost link is raised. A station not held (late
        past its watchdog, or brought up again) is reported at once (keepalive.Missed)."""
        for miss in self._the_group().keep_others(list(self._drives), busy, self._last,
                                                  self._keep_s()):
            drive = self._drives.get(miss.address)
            self._missed.note(miss, drive._station.warn if drive is not None else self._message)

    def _keep_once(self) -> float | None:
        """One pass of the keep-alive thread (api/keepalive.py): the seconds to its next pass, None
        when it is done (the bus closed, or keeping failed: said now, raised at the next call)."""
        if not self._lock.acquire(timeout=0.05):
            return KEEP_S / 2                # a call is talking to the bus (and keeps the others)
        try:
            if self._closed:
                return None
            self._keep_others(None)
            return self._keep_s() / 2
        except BaseException as e:          # noqa: BLE001  (said now, raised at the next call)
            self._keepalive_error = e
            keepalive.failed(self.port, e, self._message)
            return None
        finally:
            self._lock.release()

    def __repr__(self) -> str:
        return (f"<Bus {self.port} at {self.baud} bit/s, drives {sorted(self._drives)}"
                f"{' (closed)' if self._closed else ''}>")


def stop_words(address: int, r: "StopReport") -> str:
    """The on_message line of a drive's stop: the stop on close, and a run the asyncio face
    cancelled (aio)."""
    if r.how == "normal":
        return (f"station {address}: stopped (normal stop, {r.seconds:.1f} s)"
                if not (r.status and r.status.fault) else f"station {address}: {r.message}")
    if r.how == "coast":
        return f"station {address}: stopped by a coast stop after {r.seconds:.1f} s ({r.message})"
    return f"station {address}: could not confirm the stop: {r.message}"


def _address(sess: "DriveStation") -> int:
    assert sess.address is not None                 # an opened drive's session found its station
    return int(sess.address)


def _speed_percent(sess: "DriveStation") -> float | None:
    """The speed the drive last reported, in % (sizes its stop time as safestop.stop does)."""
    d = sess.drive
    last = getattr(d, "last_status", None) or getattr(d, "last", None)
    return last.speed_percent if last is not None else None
