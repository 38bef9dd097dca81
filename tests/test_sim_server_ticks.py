"""The sim server (sim/server.py serve) runs every station's timers on a timer, not on every pass of
its loop (issue 16): a busy master must not pay for ticking stations it does not address. Checked on
a fake clock by counting ticks, and on a real plant: an unaddressed station's watchdog still
expires while the master talks to another one."""

from profidrive_cli.sim import server
from profidrive_cli.sim.plant import build_bus
from profidrive_cli.sim.slave import DATA_EXCH


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


class CountingBus:
    def __init__(self):
        self.ticks = []
        self.received = []

    def tick(self, now):
        self.ticks.append(now)

    def next_time(self):
        return None

    def receive(self, data, now):
        self.received.append((data, now))
        return []

    def take(self, now):
        return b""


class BusyEndpoint:
    """Octets arrive every 0.1 ms (a master that keeps the bus busy): each read returns at once."""

    def __init__(self, clock, until):
        self.clock = clock
        self.until = until
        self.timeouts = []

    def read(self, timeout):
        self.timeouts.append(timeout)
        self.clock.t += 0.0001
        return b"\x10"

    def write(self, data):
        pass


def test_stations_tick_on_a_timer_not_per_read():
    clock = Clock()
    bus = CountingBus()
    ep = BusyEndpoint(clock, 0.1)
    server.serve(bus, ep, stop=lambda: clock.t >= 0.1, clock=clock, tick_s=0.005)
    assert len(bus.received) >= 999                    # 1000 reads in 0.1 s
    # a tick at 0, then one every 5 ms: 20 or 21 in 0.1 s (the old loop ticked on every read)
    assert 20 <= len(bus.ticks) <= 21
    gaps = [b - a for a, b in zip(bus.ticks, bus.ticks[1:])]
    assert all(0.005 - 1e-9 <= g < 0.0052 for g in gaps)


class IdleEndpoint:
    """Nothing arrives: a read waits its whole timeout."""

    def __init__(self, clock):
        self.clock = clock
        self.timeouts = []

    def read(self, timeout):
        self.timeouts.append(timeout)
        self.clock.t += timeout
        return b""

    def write(self, data):
        pass


def test_an_idle_bus_still_ticks_every_period():
    clock = Clock()
    bus = CountingBus()
    ep = IdleEndpoint(clock)
    server.serve(bus, ep, stop=lambda: clock.t >= 0.05 - 1e-9, poll=0.02, clock=clock,
                 tick_s=0.005)
    assert all(t <= 0.005 + 1e-9 for t in ep.timeouts)   # the wait ends at the next tick
    assert len(bus.ticks) >= 10


class MasterEndpoint:
    """Feeds a scripted list of (time, octets) to the server; collects what it writes."""

    def __init__(self, clock, script):
        self.clock = clock
        self.script = list(script)
        self.written = bytearray()

    def read(self, timeout):
        if self.script and self.script[0][0] <= self.clock.t + timeout:
            t, data = self.script.pop(0)
            self.clock.t = max(self.clock.t, t)
            return data
        self.clock.t += timeout
        return b""

    def write(self, data):
        self.written += data


def test_unaddressed_watchdog_still_expires():
    """Station 3 in Data_Exchange with a 100 ms watchdog; the master then talks only to station 4
    (FDL status requests every 1 ms): station 3 leaves Data_Exchange within a tick of 100 ms."""
    from profidrive_cli.fdl import frames as F
    clock = Clock()
    bus = build_bus("sim://?stations=3:fuji-g1,4:fuji-pdp3", 0.0)
    s3 = bus.slaves[3]
    # put station 3 into Data_Exchange with a watchdog, as its state machine records it
    s3.state, s3.wd_s, s3.last_seen, s3.master = DATA_EXCH, 0.1, 0.0, 2
    status = F.encode(F.Frame(F.SD1, 4, 2, F.request_fc(F.FDL_STATUS)))
    script = [(0.001 * i, status) for i in range(1, 200)]
    ep = MasterEndpoint(clock, script)
    server.serve(bus, ep, stop=lambda: clock.t >= 0.2, clock=clock, tick_s=0.005)
    assert len(ep.written) > 100                        # station 4 answered its requests
    assert s3.stats["watchdog_expired"] == 1
    assert s3.state != DATA_EXCH
