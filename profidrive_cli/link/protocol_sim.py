"""pyserial URL handler for sim:// — the built-in simulated bus opens like any port.

pyserial finds it because profidrive_cli.link adds itself to serial.protocol_handler_packages.
Writes go to a SimBus (sim/bus.py); replies become readable at the time the bus says they are
complete (immediately for timing=instant; after real wire time for timing=wire).
"""

from __future__ import annotations

import time

from serial.serialutil import PortNotOpenError, SerialBase, SerialTimeoutException  # noqa: F401


class Serial(SerialBase):
    """A pyserial port whose other end is a simulated PROFIBUS segment."""

    BAUDRATES = (9600, 19200, 45450, 93750, 187500, 500000, 1500000, 3000000, 6000000, 12000000)

    def __init__(self, *args, **kwargs):
        self.bus = None
        self._pending: list[tuple[float, bytes]] = []
        self._rxbuf = bytearray()
        self.clock = time.monotonic
        super().__init__(*args, **kwargs)

    def open(self):
        if self._port is None:
            raise ValueError("port must be configured before it can be used")
        from profidrive_cli.sim.plant import build_bus
        self.bus = build_bus(self._port, now=self.clock())
        self.is_open = True

    def close(self):
        self.is_open = False
        self.bus = None

    def _reconfigure_port(self):
        pass

    def from_url(self, url):
        return url

    def _collect(self, now: float) -> None:
        keep = []
        for t, data in self._pending:
            if t <= now:
                self._rxbuf += data
            else:
                keep.append((t, data))
        self._pending = keep

    @property
    def in_waiting(self):
        if not self.is_open:
            raise PortNotOpenError()
        self._collect(self.clock())
        return len(self._rxbuf)

    def read(self, size=1):
        if not self.is_open:
            raise PortNotOpenError()
        deadline = None if self._timeout is None else self.clock() + self._timeout
        while True:
            now = self.clock()
            self._collect(now)
            if len(self._rxbuf) >= size:
                break
            nxt = min((t for t, _ in self._pending), default=None)
            if nxt is None or (deadline is not None and nxt > deadline):
                if deadline is not None and deadline > now and nxt is None:
                    # nothing will ever come (the sim answers synchronously): don't sleep it out
                    # unless the bus runs on wire time, where the caller expects real waiting
                    if self.bus is not None and self.bus.wire:
                        time.sleep(deadline - now)
                break
            time.sleep(max(0.0, nxt - now))
        data = bytes(self._rxbuf[:size])
        del self._rxbuf[:size]
        return data

    def write(self, data):
        if not self.is_open:
            raise PortNotOpenError()
        now = self.clock()
        self.bus.tick(now)
        self._pending.extend(self.bus.receive(bytes(data), now))
        return len(data)

    def reset_input_buffer(self):
        self._rxbuf.clear()
        self._pending.clear()

    def reset_output_buffer(self):
        pass

    @property
    def out_waiting(self):
        return 0

    @property
    def cts(self):
        return True

    @property
    def dsr(self):
        return True

    @property
    def ri(self):
        return False

    @property
    def cd(self):
        return True

    def _update_rts_state(self):
        pass

    def _update_dtr_state(self):
        pass

    def _update_break_state(self):
        pass
