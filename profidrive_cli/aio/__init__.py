"""The asyncio face of the Python API (docs/api.md, "asyncio"): `async with aio.open_bus(...)` with the
surface of the sync API -- scan, drive, status, run, stop, param, set_param, faults, clear_fault.

Where the work runs: every call of one bus goes to one worker thread of that bus, which calls the sync
API (profidrive_cli.api); the cyclic traffic stays in the sync Bus's keep-alive thread. The event loop
never blocks on the port and the protocol stack stays the one the CLI uses (same checks, same safe
stop), rather than a second, asynchronous implementation of the master: a telegram's timing (a slot
time is 100 us at 1.5 Mbit/s) is kept by a thread that waits on the port, not by a loop that other
tasks share. One thread per bus serialises the calls as the sync Bus's lock would.

Cancellation is a safe stop:
- a cancelled `drive.run(..., wait=True)` ends the wait and stops that drive (the normal stop,
  escalating as the sync stop does), then raises CancelledError;
- any other call runs to its end (a telegram cannot be torn in half), then the CancelledError goes on;
- leaving `async with` -- normally, by an exception or by cancellation (Ctrl-C under asyncio.run
  cancels the main task) -- stops every drive the bus started, together, and closes the port;
- handle_signals=True (the default, POSIX, in the main thread): SIGTERM cancels the task that opened
  the bus, so it ends through the same stop.

A program that runs until it is stopped (a service under systemd) runs its main coroutine with
`aio.run(main())` instead of asyncio.run: SIGTERM and SIGINT (SIGBREAK on Windows) cancel the main
task, so every bus ends through its safe stop; a second signal hurries that stop (coast, as in the
sync API); then the program exits 128 + the signal (143, 130), as the CLI does, with no traceback.
The buses inside leave the signals to it.
"""

from __future__ import annotations

import asyncio
import contextvars
import functools
import signal
import sys
import threading
import weakref
from concurrent.futures import ThreadPoolExecutor
from types import FrameType, TracebackType
from typing import TYPE_CHECKING, Any, Callable, Coroutine, Iterable, Mapping, TypeVar

from profidrive_cli.api import open_bus as _open_bus
from profidrive_cli.api.bus import stop_words

if TYPE_CHECKING:                                       # pragma: no cover
    from profidrive_cli.api import Bus, Drive, Faults, Param, Station, Status, StopResult

__all__ = ["AsyncBus", "AsyncDrive", "open_bus", "run"]

T = TypeVar("T")

#: inside aio.run(): the signals are its own (a bus opened there installs no handler)
_under_run: contextvars.ContextVar[bool] = contextvars.ContextVar("pdrive_aio_run", default=False)
#: every AsyncBus open now (a second signal under aio.run hurries their stops)
_open_buses: "weakref.WeakSet[AsyncBus]" = weakref.WeakSet()


def _stopping_signals() -> tuple[int, ...]:
    brk = getattr(signal, "SIGBREAK", None)
    return (signal.SIGTERM, signal.SIGINT) + (() if brk is None else (brk,))


class _Stop:
    """aio.run's state: the main task, its loop, the first signal."""

    def __init__(self) -> None:
        self.loop: asyncio.AbstractEventLoop | None = None
        self.task: "asyncio.Task[Any] | None" = None
        self.signum: int | None = None

    def on_signal(self, signum: int, frame: FrameType | None) -> None:
        """The first signal cancels the main task; a further one hurries every bus's stop."""
        if self.signum is None:
            self.signum = signum
            if self.loop is not None and self.task is not None and not self.loop.is_closed():
                self.loop.call_soon_threadsafe(self.task.cancel)
            return
        for bus in list(_open_buses):
            bus._hurry()


def run(main: Coroutine[Any, Any, T], *, debug: bool | None = None) -> T:
    """asyncio.run(main) for a program that runs until it is stopped (docs/api.md, "A service"):
    SIGTERM and SIGINT (SIGBREAK on Windows) cancel the main task, so each `async with
    aio.open_bus(...)` ends through its safe stop (a second signal: the stop coasts at once); once
    main has ended, SystemExit(128 + the signal): 143 after SIGTERM, 130 after SIGINT, whether
    main let the CancelledError through or not -- no traceback. Without a signal: main's result,
    or its exception. Outside the main thread the signals cannot be taken: asyncio.run alone."""
    if not asyncio.iscoroutine(main):
        raise TypeError(f"aio.run: a coroutine was expected, got {main!r}")
    stop = _Stop()

    async def serve() -> T:
        stop.loop, stop.task = asyncio.get_running_loop(), asyncio.current_task()
        _under_run.set(True)
        if stop.signum is not None:                  # a signal before the loop ran
            raise asyncio.CancelledError()
        return await main

    before: dict[int, Any] = {}
    if threading.current_thread() is threading.main_thread():
        for s in _stopping_signals():
            try:
                before[s] = signal.signal(s, stop.on_signal)
            except (OSError, ValueError):
                pass
    try:
        result = asyncio.run(serve(), debug=debug)
    except asyncio.CancelledError:
        if stop.signum is None:
            raise
        raise SystemExit(128 + stop.signum) from None
    finally:
        main.close()                                 # never awaited when a signal came first
        for s, h in before.items():
            signal.signal(s, h if h is not None else signal.SIG_DFL)
    if stop.signum is not None:
        raise SystemExit(128 + stop.signum)          # main caught the cancellation itself
    return result


def open_bus(port: str | None = None, *, baud: str | int | None = None,
             master_address: int | None = None, retries: int | None = None,
             slot_time: int | None = None, rs485: bool = False, echo: bool | str = "auto",
             allow_real_port_writes: bool = False, handle_signals: bool = True,
             on_message: Callable[[str], None] | None = None,
             env: Mapping[str, str] | None = None) -> "AsyncBus":
    """The asyncio bus: `async with open_bus("sim://") as bus:` (or `bus = await open_bus(...)` and
    `await bus.close()`). The arguments are the sync open_bus's (docs/api.md); the port is opened on
    entry, in the bus's worker thread. on_message is called in that thread."""
    kwargs: dict[str, Any] = dict(baud=baud, master_address=master_address, retries=retries,
                                  slot_time=slot_time, rs485=rs485, echo=echo,
                                  allow_real_port_writes=allow_real_port_writes,
                                  on_message=on_message, env=env)
    return AsyncBus(port, kwargs, handle_signals)


class AsyncBus:
    """An open bus for asyncio. Made by open_bus()."""

    def __init__(self, port: str | None, kwargs: dict[str, Any], handle_signals: bool) -> None:
        self._port = port
        self._kwargs = kwargs
        self._handle_signals = handle_signals
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="pdrive-aio")
        self._bus: "Bus | None" = None
        #: the sync bus while close() stops it (a second signal under run() hurries that stop)
        self._closing: "Bus | None" = None
        self._drives: dict[int, AsyncDrive] = {}
        self._sigterm_task: asyncio.Task[Any] | None = None
        #: the SIGTERM handler before ours, put back on close (the loop's removal sets SIG_DFL)
        self._sigterm_before: Any = None
        self._loop: asyncio.AbstractEventLoop | None = None

    # -- opening and closing ------------------------------------------------------------------------
    def __await__(self) -> Any:
        return self._open().__await__()

    async def __aenter__(self) -> "AsyncBus":
        return await self._open()

    async def __aexit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                        tb: TracebackType | None) -> None:
        await self.close(exc)

    async def _open(self) -> "AsyncBus":
        if self._bus is None:
            # signals are the event loop's here (the worker thread cannot take them): see below
            self._bus = await self._run(functools.partial(_open_bus, self._port, handle_signals=False,
                                                          **self._kwargs))
            self._loop = asyncio.get_running_loop()
            _open_buses.add(self)
            self._watch_sigterm()
        return self

    def _watch_sigterm(self) -> None:
        """SIGTERM cancels the task that opened the bus (POSIX, main thread, handle_signals)."""
        task = asyncio.current_task()
        if (not self._handle_signals or task is None or _under_run.get() or sys.platform == "win32"
                or threading.current_thread() is not threading.main_thread()):
            return
        assert self._loop is not None
        before = signal.getsignal(signal.SIGTERM)
        try:
            self._loop.add_signal_handler(signal.SIGTERM, task.cancel)
        except (NotImplementedError, RuntimeError, ValueError):
            return                                   # a loop without signal support
        self._sigterm_task = task
        self._sigterm_before = before

    async def close(self, exc: BaseException | None = None) -> None:
        """Stop every drive this bus started (together), release the stations, close the port. It
        runs to its end even when the awaiting task is cancelled meanwhile (the cancellation goes on
        afterwards). Idempotent."""
        if self._sigterm_task is not None and self._loop is not None:
            self._loop.remove_signal_handler(signal.SIGTERM)
            # the handler from before (the loop's removal would leave SIG_DFL: a SIGTERM after the
            # bus closed would then end a program that handles it itself)
            signal.signal(signal.SIGTERM, self._sigterm_before if self._sigterm_before is not None
                          else signal.SIG_DFL)
            self._sigterm_task = None
        bus, self._bus = self._bus, None
        self._closing = bus
        try:
            if bus is not None:
                await self._run(functools.partial(bus.close, exc))
        finally:
            self._closing = None
            _open_buses.discard(self)
            self._pool.shutdown(wait=False)

    def _hurry(self) -> None:
        """A second signal under run(): the stop under way (or the next) coasts at once."""
        bus = self._bus or self._closing
        if bus is not None:
            bus.hurry()

    @property
    def sync(self) -> "Bus":
        """The sync Bus underneath (its calls block: use them from a thread, not the loop)."""
        if self._bus is None:
            from profidrive_cli import UsageError
            raise UsageError("this bus is not open (use `async with aio.open_bus(...)`)")
        return self._bus

    @property
    def port(self) -> str:
        return self.sync.port

    @property
    def closed(self) -> bool:
        return self._bus is None or self._bus.closed

    # -- the worker thread --------------------------------------------------------------------------
    async def _run(self, fn: Callable[[], T]) -> T:
        """fn() in the bus's worker thread. Cancelled meanwhile: fn runs to its end first (a
        telegram is not torn in half), then CancelledError."""
        fut = asyncio.get_running_loop().run_in_executor(self._pool, fn)
        cancelled = False
        while True:
            try:
                result = await asyncio.shield(fut)
                break
            except asyncio.CancelledError:
                if fut.done():
                    raise
                cancelled = True
        if cancelled:
            raise asyncio.CancelledError()
        return result

    # -- the calls ----------------------------------------------------------------------------------
    async def scan(self, first: int = 0, last: int = 126) -> list["Station"]:
        """Bus.scan: every station that answers in first..last."""
        bus = self.sync
        return await self._run(functools.partial(bus.scan, first, last))

    async def drive(self, station: int | None = None, **kwargs: Any) -> "AsyncDrive":
        """Bus.drive: the station brought to data exchange and kept there (the same arguments:
        profile, layout, ppo, fmax, watchdog_ms, cycle_hz, stop_timeout). The same station twice:
        the same AsyncDrive."""
        bus = self.sync

        def open_it() -> tuple["Drive", float]:
            d = bus.drive(station, **kwargs)
            return d, d.fmax_hz
        d, fmax = await self._run(open_it)
        have = self._drives.get(d.station)
        if have is None or have.sync is not d:
            have = self._drives[d.station] = AsyncDrive(self, d, fmax)
        return have


    async def read_params(self, stations: "Mapping[int, Iterable[str]] | Iterable[int]",
                          codes: "Iterable[str] | None" = None) -> "dict[int, dict[str, Param]]":
        """Bus.read_params: several drives' parameters at once, one bus cycle carrying a request to
        each. Cancelled meanwhile: the reads end before the next bus round (the request of each
        round is not torn in half), the drives it opened are closed, then CancelledError."""
        bus = self.sync
        cancel = threading.Event()
        fut = asyncio.get_running_loop().run_in_executor(
            self._pool, functools.partial(bus.read_params, stations, codes, cancel=cancel))
        cancelled = False
        while not fut.done():
            try:
                await asyncio.shield(fut)
            except asyncio.CancelledError:
                cancel.set()
                cancelled = True
            except BaseException:           # noqa: BLE001  (fut.result() below raises it)
                break
        if cancelled:
            raise asyncio.CancelledError()
        return fut.result()


class AsyncDrive:
    """A drive station in data exchange on an AsyncBus: the sync Drive's calls as coroutines."""

    def __init__(self, bus: AsyncBus, drive: "Drive", fmax_hz: float) -> None:
        self._bus = bus
        self.sync = drive
        #: the frequency 100 % stands for, as read when the drive was opened
        self.fmax_hz = fmax_hz
        self.station: int = drive.station
        self.profile: str = drive.profile
        self.family: str = drive.family
        self.layout: str = drive.layout
        self.ident: int | None = drive.ident
        self.ident_hex: str | None = drive.ident_hex

    def __repr__(self) -> str:
        return f"<AsyncDrive station {self.station} {self.profile}>"

    @property
    def warnings(self) -> list[str]:
        return self.sync.warnings

    async def status(self) -> "Status":
        return await self._bus._run(self.sync.status)

    async def run(self, hz: float | None = None, *, percent: float | None = None, wait: bool = False,
                  timeout: float | None = None) -> "Status":
        """Drive.run. Cancelled while it waits for the reference (wait=True): the wait ends, the
        drive is stopped (its normal stop, escalating as Drive.stop does), then CancelledError."""
        cancel = threading.Event()
        fut = asyncio.get_running_loop().run_in_executor(
            self._bus._pool, functools.partial(self.sync.run, hz, percent=percent, wait=wait, timeout=timeout,
                                              cancel=cancel))
        try:
            return await asyncio.shield(fut)
        except asyncio.CancelledError:
            cancel.set()
            await self._finish_after_cancel(fut)
            raise

    async def _finish_after_cancel(self, fut: "asyncio.Future[Any]") -> None:
        """After a cancelled run: let the run call return, then stop the drive; neither is cut short
        by a second cancellation."""
        async def settle() -> None:
            try:
                await fut
            except Exception:                        # noqa: BLE001  (the stop below is what matters)
                pass
            await self._bus._run(self._stop_and_say)
        task = asyncio.ensure_future(settle())
        while not task.done():
            try:
                await asyncio.shield(task)
            except asyncio.CancelledError:
                continue
        task.result()

    def _stop_and_say(self) -> None:
        """The stop after a cancelled run, and its line through on_message (the caller gets a
        CancelledError, not the StopResult): the words of the stop on close."""
        self.sync.stop()
        with self.sync.held() as s:
            r = s.motion.stop_report
            if r is not None:
                s.say(stop_words(self.station, r))

    async def stop(self, *, timeout: float | None = None) -> "StopResult":
        return await self._bus._run(functools.partial(self.sync.stop, timeout=timeout))

    async def param(self, code: str) -> "Param":
        return await self._bus._run(functools.partial(self.sync.param, code))

    async def set_param(self, code: str, value: float | int | str, *,
                        allow_dangerous: bool = False) -> "Param":
        return await self._bus._run(functools.partial(self.sync.set_param, code, value,
                                                      allow_dangerous=allow_dangerous))

    async def faults(self) -> "Faults":
        return await self._bus._run(self.sync.faults)

    async def clear_fault(self) -> "Status":
        return await self._bus._run(self.sync.clear_fault)

    async def close(self) -> "StopResult | None":
        return await self._bus._run(self.sync.close)
