"""pyserial URL handler for sim:// — the built-in simulated bus opens like any port.

It lives in sim/ (it builds the plant) and may touch sim/ and link.base; link/ only names this package
in serial.protocol_handler_packages (a string, so importing link/ does not import the plant) and
pyserial imports this module the first time a sim:// URL is opened.
Writes go to a SimBus (sim/bus.py); reply octets become readable at the time the bus says each one is
complete on the wire: at once for timing=instant, after real wire time for timing=wire (the reader
sleeps like a real port), and on a simulated clock for timing=virtual (reads advance the clock
instead of sleeping; the port's `clock` is then the time base of everything that uses it).

unplug() makes every later call fail like a pulled USB adapter (tests of LinkLost).
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any, TypedDict
from urllib.parse import parse_qs, urlsplit

from serial.serialutil import PortNotOpenError, SerialBase, SerialException, SerialTimeoutException  # noqa: F401


class VirtualClock:
    """Seconds on a simulated clock; sleep() advances it."""

    def __init__(self, start: float = 0.0):
        self.t = start

    def now(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            self.t += seconds


if TYPE_CHECKING:
    from profidrive_cli.sim.bus import SimBus


class SimulatorInfo(TypedDict):
    """Serial.simulator_info(): the simulated segment behind an open sim:// port."""
    stations: dict[int, str]
    timing: str
    baud: int
    faults: bool


# pyserial has no type hints: SerialBase is Any, which mypy --strict will not subclass
class Serial(SerialBase):  # type: ignore[misc]
    """A pyserial port whose other end is a simulated PROFIBUS segment."""

    BAUDRATES = (9600, 19200, 45450, 93750, 187500, 500000, 1500000, 3000000, 6000000, 12000000)

    def __init__(self, *args: Any, **kwargs: Any) -> None:      # pyserial's own arguments
        self.bus: SimBus | None = None
        self._rxbuf = bytearray()
        self.clock = time.monotonic
        self.virtual: VirtualClock | None = None
        self._unplugged = False
        self._ticked = float("-inf")
        self.locked_baud: int | None = None
        super().__init__(*args, **kwargs)

    def open(self) -> None:
        if self._port is None:
            raise ValueError("port must be configured before it can be used")
        from profidrive_cli.sim.plant import build_bus
        timing = parse_qs(urlsplit(self._port).query).get("timing", ["instant"])[-1]
        if timing == "virtual":
            self.virtual = VirtualClock()
            self.clock = self.virtual.now
        q = parse_qs(urlsplit(self._port).query)
        # sim://?baud=R: the stations are locked to R like slaves on a running bus and hear a
        # master at any other rate as garbage; without baud= they answer at any rate (a slave
        # still searching the rate), and a wire-timed bus takes the port's rate
        self.bus = build_bus(self._port, now=self.clock(), default_baud=int(self._baudrate or 19200))
        if "baud" in q:
            self.locked_baud = self.bus.params.baud
        self._unplugged = False
        self.is_open = True

    def simulator_info(self) -> SimulatorInfo:
        """What `pdrive doctor` reports about the simulated segment behind this open port: the
        stations {address: family}, the timing, the baud rate and whether faults are injected."""
        bus = self.bus
        assert bus is not None, "simulator_info() of a closed port"
        return {"stations": {a: s.model.family for a, s in sorted(bus.slaves.items())},
                "timing": bus.timing, "baud": bus.params.baud, "faults": bus.faults is not None}

    def close(self) -> None:
        self.is_open = False
        self.bus = None

    def unplug(self) -> None:
        """From now on the port behaves like a USB adapter that was pulled out."""
        self._unplugged = True

    def _check(self) -> None:
        if not self.is_open:
            raise PortNotOpenError()
        if self._unplugged:
            raise SerialException("device disconnected (simulated unplug)")

    def sim_sleep(self, seconds: float) -> None:
        """Wait on this port's clock (real sleep, or advance the virtual clock)."""
        if seconds <= 0:
            return
        if self.virtual is not None:
            self.virtual.sleep(seconds)
        else:
            from profidrive_cli.link.base import precise_sleep
            precise_sleep(seconds)

    def _reconfigure_port(self) -> None:
        pass

    def from_url(self, url: str) -> str:
        return url

    def _collect(self, now: float) -> None:
        if self.bus is not None:
            self._rxbuf += self.bus.take(now)

    @property
    def in_waiting(self) -> int:
        if self._unplugged or not self.is_open:
            self._check()
        assert self.bus is not None            # (an open port has its bus)
        self._rxbuf += self.bus.take(self.clock())
        return len(self._rxbuf)

    def read(self, size: int = 1) -> bytes:
        if self._unplugged or not self.is_open:
            self._check()
        assert self.bus is not None            # (an open port has its bus)
        deadline = None if self._timeout is None else self.clock() + self._timeout
        while True:
            now = self.clock()
            self._collect(now)
            if len(self._rxbuf) >= size:
                break
            nxt = self.bus.next_time()
            if nxt is None or (deadline is not None and nxt > deadline):
                # nothing (more) arrives in time. The instant simulator answers synchronously, so
                # the caller need not sleep it out; a wire-timed bus waits like a real port.
                if self.bus.wire and deadline is not None and deadline > now:
                    self.sim_sleep(deadline - now)
                    self._collect(self.clock())
                break
            self.sim_sleep(max(0.0, nxt - now))
        data = bytes(self._rxbuf[:size])
        del self._rxbuf[:size]
        return data

    #: the bus's clock ticks at least this often: the stations due then run their clocks (watchdog,
    #: drive ramps; sim/bus.py), the others make up for it when next run; the addressed one always
    #: runs up to the request first
    TICK_S = 0.01

    def write(self, data: bytes) -> int:
        if self._unplugged or not self.is_open:
            self._check()
        assert self.bus is not None            # (an open port has its bus)
        now = self.clock()
        if now - self._ticked >= self.TICK_S:
            self.bus.tick(now)
            self._ticked = now
        if self.locked_baud is not None and int(self._baudrate) != self.locked_baud:
            return len(data)    # wrong rate: the stations see framing errors and stay silent
        self.bus.receive(bytes(data), now)
        return len(data)

    def reset_input_buffer(self) -> None:
        self._check()
        assert self.bus is not None            # (an open port has its bus)
        self._rxbuf.clear()
        self.bus.flush()

    def reset_output_buffer(self) -> None:
        pass

    @property
    def out_waiting(self) -> int:
        return 0

    @property
    def cts(self) -> bool:
        return True

    @property
    def dsr(self) -> bool:
        return True

    @property
    def ri(self) -> bool:
        return False

    @property
    def cd(self) -> bool:
        return True

    def _update_rts_state(self) -> None:
        pass

    def _update_dtr_state(self) -> None:
        pass

    def _update_break_state(self) -> None:
        pass
