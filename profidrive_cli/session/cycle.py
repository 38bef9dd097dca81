"""The metered cycle: the Data_Exchange rate (the wire limit for one station at the baud rate, the
default cap, a warning for a rate above the wire), MeteredChannel (counts exchanges, measures the
achieved rate, calls hooks after each one) and Sample, one decoded cycle as a live view shows it.
Reads fdl/timing.py; wraps a dp StationChannel; no bus traffic of its own.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any, Callable, Protocol

from profidrive_cli.drives.base import CyclicChannel, DriveStatus
from profidrive_cli.drives.profile import Profile

CAP_REAL_HZ = 100.0          # default cycle-rate cap over real ports
CAP_SIM_HZ = 50.0            # ... and on the instant simulator


def wire_limit_hz(baud: int, out_octets: int, in_octets: int) -> float:
    """The highest Data_Exchange rate the wire allows for one station (request + TSDR + reply + TID1)."""
    from profidrive_cli.fdl.timing import wire_time_data_exchange
    return 1.0 / wire_time_data_exchange(baud, out_octets, in_octets)


def default_cycle_hz(link: object, wire_hz: float) -> float:
    cap = CAP_SIM_HZ if getattr(link, "instant", False) else CAP_REAL_HZ
    return min(cap, wire_hz)


class MeteredChannel:
    """drives.base.CyclicChannel around dp.poller.StationChannel: counts exchanges, measures the
    achieved rate over the last two seconds (at most the last 4,096 exchanges), and calls
    hooks(t, outputs, inputs) after each one.

    The window is kept up to date as exchanges come in (timestamps older than `window_s` before the
    newest one are dropped on append), so `rate` is O(1): a live view reads it on every cycle."""

    def __init__(self, inner: CyclicChannel, window_s: float = 2.0) -> None:
        self.inner = inner
        self.window_s = window_s
        self.cycles = 0
        self.hooks: list[Callable[[float, bytes, bytes], None]] = []
        self._times: deque[float] = deque(maxlen=4096)

    def now(self) -> float:
        return self.inner.now()

    def c1_read(self, slot: int, index: int, length: int, timeout_s: float) -> bytes:
        """drives.base.AcyclicChannel, when the inner channel has it (AttributeError otherwise)."""
        read: Callable[[int, int, int, float], bytes] = getattr(self.inner, "c1_read")
        return read(slot, index, length, timeout_s)

    def c1_write(self, slot: int, index: int, data: bytes, timeout_s: float) -> None:
        write: Callable[[int, int, bytes, float], None] = getattr(self.inner, "c1_write")
        write(slot, index, data, timeout_s)

    def exchange(self, outputs: bytes) -> bytes:
        inner = self.inner
        inputs = inner.exchange(outputs)
        t = inner.now()
        self.cycles += 1
        times = self._times
        times.append(t)
        window = self.window_s
        while t - times[0] > window:
            times.popleft()
        for h in self.hooks:
            h(t, outputs, inputs)
        return inputs

    @property
    def rate(self) -> float:
        """Exchanges per second over the last `window_s` seconds (0 before two exchanges)."""
        times = self._times
        n = len(times)
        if n < 2:
            return 0.0
        span = times[-1] - times[0]
        if span <= 0:
            return 0.0
        return (n - 1) / span


@dataclass
class Sample:
    """One decoded cycle with everything a live view shows."""
    t: float                       # seconds since the session reached data exchange
    status: DriveStatus
    fmax_hz: float
    cycle_hz: float                # achieved
    cycles: int
    counters: dict[str, Any]

    @property
    def actual_percent(self) -> float | None:
        return self.status.speed_percent

    @property
    def actual_hz(self) -> float | None:
        p = self.status.speed_percent
        return None if p is None else round(p * self.fmax_hz / 100.0, 3)

    @property
    def reference_percent(self) -> float | None:
        return self.status.reference_percent

    @property
    def reference_hz(self) -> float | None:
        p = self.status.reference_percent
        return None if p is None else round(p * self.fmax_hz / 100.0, 3)

    def to_dict(self) -> dict[str, Any]:
        st = self.status
        return {"t": round(self.t, 3), "state": st.state, "running": st.running, "fault": st.fault,
                "stopped": st.stopped, "fault_code": st.fault_code,
                "flags": [k for k, v in st.flags.items() if v],
                "reference_hz": self.reference_hz, "reference_percent": self.reference_percent,
                "actual_hz": self.actual_hz, "actual_percent": self.actual_percent,
                "cycle_hz": round(self.cycle_hz, 2), "cycles": self.cycles,
                "counters": self.counters, "raw": dict(st.raw)}


class _Sampler(Protocol):
    def sample(self, st: DriveStatus) -> Sample: ...


class Sampling(Protocol):
    """A station with a Motion (session.DriveStation)."""
    @property
    def motion(self) -> _Sampler: ...


def choose_rate(baud: int, link: object, output_len: int, input_len: int,
                asked_hz: float | None) -> tuple[float, float, str | None]:
    """(the wire limit for a station of these area lengths, the cycle rate: asked or the default,
    a warning when the asked rate is above the wire limit, else None)."""
    wire_hz = wire_limit_hz(baud, output_len, input_len)
    if asked_hz is None:
        return wire_hz, default_cycle_hz(link, wire_hz), None
    cycle_hz = float(asked_hz)
    if cycle_hz <= wire_hz * 1.0001:
        return wire_hz, cycle_hz, None
    from profidrive_cli.fdl.timing import BAUD_NAMES
    return wire_hz, cycle_hz, (f"--cycle-hz {cycle_hz:g} is more than {BAUD_NAMES.get(baud, baud)} "
                               f"allows for this station ({wire_hz:.1f} Hz: "
                               f"{1000.0 / wire_hz:.1f} ms per Data_Exchange of "
                               f"{output_len}/{input_len} octets); on a real bus the wire sets "
                               f"the pace")


def make_sample(sess: Sampling, st: DriveStatus) -> Sample:
    """A Sample of status `st` on the session's clock (also remembered as its final_status): the
    session's Motion makes it (session/motion.py Motion.sample)."""
    return sess.motion.sample(st)

