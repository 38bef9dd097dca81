"""A built-in cyclic master (a "PLC") for `pdrive sim --plc`: it runs against the in-process plant
only, and everything on its bus is mirrored to a tap (an RS-485 tap's view of the line).

    PlantLink      a Link straight onto a SimBus (never a port): what the master writes and what the
                   stations answer also go to `tap(octets)`, at the times they are on the wire
    ImageChannel   drives.base.CyclicChannel over a process image: a Drive posts its outputs and
                   gets the inputs of the bus cycle that carried them (the bus cycle never waits
                   for a drive, so every station keeps its watchdog fed)
    Plc            bring-up of every station (dp.poller.Master: Set_Prm with watchdog, Chk_Cfg), then
                   Data_Exchange cycles; each drive runs MotionScript in a thread of its own through
                   the family's Drive codec (start, ramp, hold, PKW reads, stop, pause, repeat)

The Plc never opens a port: it is given a SimBus, and PlantLink is the only link it uses.

Its place (tests/test_layering.py): sim/, beside the master stack. The PLC is a master of the
simulated plant, built from the master stack's lower rooms -- dp.poller.Master (bring-up, keep,
exchange, release), the families' Drive codecs (drives.make_drive) and the device's GSD (gsd/) --
never from session/ or api/, which sim/ must not import. Reading the plant (SimBus, its stations'
models) it may: that is sim/ itself.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable

from profidrive_cli import BusError, UsageError
from profidrive_cli.link.base import Link, plain_sleep
from profidrive_cli.sim.bus import SimBus

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.drives.base import Drive
    from profidrive_cli.drives.profile import ParamDef, Profile

#: DP watchdog armed in Set_Prm for every station (ms): far above a cycle of five stations at 9.6 kbit/s
WATCHDOG_MS = 2000.0
#: the PLC's cycle: at least this long (s); a slow baud rate makes it longer (the wire sets the pace)
MIN_CYCLE_S = 0.01


class PlcStopped(BaseException):
    """The PLC is shutting down: a drive thread leaves its script (not an error)."""


class PlantLink(Link):
    """A Link onto an in-process SimBus on the real clock; every octet is also handed to `tap`."""

    is_simulator = True
    instant = False
    latency = 0.0
    us_timing = False
    name = "plc"

    TICK_S = 0.005

    def __init__(self, bus: SimBus, tap: Callable[[bytes], object] | None = None,
                 clock: Callable[[], float] = time.monotonic):
        self.bus = bus
        self.tap = tap or (lambda data: None)
        self.now = clock        # type: ignore[method-assign]  # (the plant's clock stands for Link.now)
        self._ticked = float("-inf")

    def _tick(self, now: float) -> None:
        if now - self._ticked >= self.TICK_S:
            self.bus.tick(now)
            self._ticked = now

    def write(self, data: bytes) -> None:
        now = self.now()
        self._tick(now)
        self.tap(bytes(data))
        self.bus.receive(bytes(data), now)

    def read(self, deadline: float) -> bytes:
        bus = self.bus
        while True:
            now = self.now()
            data = bus.take(now)
            if data:
                self.tap(data)
                return data
            nxt = bus.next_time()
            if nxt is None or nxt > deadline:
                if deadline > now:
                    plain_sleep(min(deadline - now, 0.05))
                    if self.now() < deadline and bus.next_time() is None:
                        continue
                    data = bus.take(self.now())
                    if data:
                        self.tap(data)
                    return data
                return b""
            plain_sleep(max(0.0, nxt - now))

    def flush_input(self) -> None:
        self.bus.flush()

    def sleep(self, seconds: float) -> None:
        plain_sleep(seconds)
        self._tick(self.now())


@dataclass
class _Image:
    """One station's process image: outputs posted by its drive, inputs of the last cycle."""
    outputs: bytes
    inputs: bytes = b""
    posted: int = 0          # generation of `outputs`
    done: int = 0            # generation whose exchange completed (its inputs are in `inputs`)


class ImageChannel:
    """drives.base.CyclicChannel on the PLC's process image (see the module doc)."""

    def __init__(self, plc: "Plc", address: int):
        self.plc = plc
        self.address = address

    def now(self) -> float:
        return self.plc.link.now()

    def exchange(self, outputs: bytes) -> bytes:
        plc = self.plc
        with plc.cond:
            img = plc.images[self.address]
            img.outputs = bytes(outputs)
            img.posted += 1
            gen = img.posted
            while img.done < gen:
                if plc.stopping:
                    raise PlcStopped()
                plc.cond.wait(0.5)
            return img.inputs


@dataclass
class MotionScript:
    """What the PLC does with one drive, over and over: start at `speeds_pct[i]` % of the max
    frequency, hold `hold_s` (reading one of `read_codes` on the parameter channel every
    `read_every_s` while it holds), stop with the normal ramp, pause `pause_s`, next speed."""
    speeds_pct: tuple[float, ...] = (50.0, 25.0)
    hold_s: float = 4.0
    pause_s: float = 1.0
    read_every_s: float = 1.0
    read_codes: tuple[str, ...] = ()


def default_script(profile: Profile) -> MotionScript:
    """Reads of the max frequency parameter, the acceleration time and the first read-only
    parameter (where the profile names them; a code the card cannot address is dropped when the
    drive refuses it, e.g. Toyo's parameters without a published PNU)."""
    codes = []
    ro = next((p.code for p in _params(profile) if p.access == "ro"), None)
    for code in (profile.max_frequency_param, _accel_code(profile), ro):
        if code and profile.param(code) is not None and code not in codes:
            codes.append(code)
    return MotionScript(read_codes=tuple(codes))


def _params(profile: Profile) -> list[ParamDef]:
    return list(profile.parameters.values())


def _accel_code(profile: Profile) -> str | None:
    for p in _params(profile):
        if "acceleration time 1" in (p.name or "").lower():
            return p.code
    return None


@dataclass
class StationPlan:
    address: int
    profile: Profile
    layout: str
    script: MotionScript
    drive: Drive | None = None
    thread: threading.Thread | None = None
    errors: list[str] = field(default_factory=list)
    reads: list[str] = field(default_factory=list)
    next_read: int = 0

    def __post_init__(self) -> None:
        self.reads = list(self.script.read_codes)


class Plc:
    """The built-in cyclic master over a PlantLink. run(stop) until stop() is true."""

    def __init__(self, bus: object, tap: Callable[[bytes], object] | None = None,
                 log: Callable[[str], object] | None = None, cycle_s: float = MIN_CYCLE_S,
                 scripts: dict[int, MotionScript] | None = None):
        from profidrive_cli.dp.poller import Master
        from profidrive_cli.fdl.timing import BusParams
        if not isinstance(bus, SimBus):
            raise TypeError("the built-in PLC runs only on an in-process simulated bus (SimBus)")
        self.bus = bus
        self.link = PlantLink(bus, tap)
        self.master = Master(self.link, BusParams.for_baud(bus.params.baud, retries=1,
                                                           link_latency=0.0))
        self.log = log or (lambda line: None)
        self.cycle_s = cycle_s
        self.cond = threading.Condition()
        self.stopping = False
        self.images: dict[int, _Image] = {}
        self.plans: dict[int, StationPlan] = {}
        self.cycles = 0
        for a, s in sorted(bus.slaves.items()):
            prof = s.model.profile
            if prof is None:
                continue                      # a plain DP-V0 slave: no drive to script
            layout = s.model.default_layout or prof.default_layout
            script = (scripts or {}).get(a) or default_script(prof)
            self.plans[a] = StationPlan(a, prof, layout, script)

    # -- bring-up --------------------------------------------------------------------------------
    def bring_up(self) -> None:
        from profidrive_cli.dp.station import SlaveConfig
        for a, plan in self.plans.items():
            lay = plan.profile.layouts[plan.layout]
            self.master.add_station(a, SlaveConfig(ident=plan.profile.ident, cfg=lay.cfg,
                                                   user_prm=_user_prm(plan.profile.ident),
                                                   wd_ms=WATCHDOG_MS))
            self.images[a] = _Image(bytes(lay.output_len))
        for a in list(self.plans):
            try:
                self.master.bring_up(a, timeout=3.0)
            except BusError as e:              # the others run on; this one stays out
                self.log(f"plc: {e}")
                del self.plans[a]
                continue
            # kept in the cycle while the next station is brought up (dp/poller.py Master.keep),
            # as a PLC does: its watchdog never waits for the others' start-up
            self.master.keep(a)

    # -- the cycle -------------------------------------------------------------------------------
    def cycle(self) -> None:
        """One PLC cycle: a Data_Exchange with every station, its drive's latest outputs."""
        for a in self.plans:
            with self.cond:
                img = self.images[a]
                outputs, gen = img.outputs, img.posted
            try:
                inputs = self.master.exchange(a, outputs)
            except BusError as e:
                self.log(f"plc: station {a}: {e}")
                continue
            with self.cond:
                img.inputs = inputs
                img.done = max(img.done, gen)
                self.cond.notify_all()
        self.cycles += 1

    def run(self, stop: Callable[[], bool] = lambda: False) -> None:
        self.bring_up()
        for plan in self.plans.values():
            plan.thread = threading.Thread(target=self._drive_thread, args=(plan,), daemon=True,
                                           name=f"plc-station-{plan.address}")
            plan.thread.start()
        try:
            while not stop():
                t0 = self.link.now()
                self.cycle()
                left = self.cycle_s - (self.link.now() - t0)
                if left > 0:
                    self.link.sleep(left)
        finally:
            self.shutdown()

    def shutdown(self) -> None:
        """Drive threads leave their scripts; every station is released (Set_Prm with Unlock_Req:
        its outputs go to their safe state and the drive stops on its communication loss)."""
        with self.cond:
            self.stopping = True
            self.cond.notify_all()
        for plan in self.plans.values():
            if plan.thread is not None:
                plan.thread.join(timeout=2.0)
        for a in self.plans:
            if a in self.master.stations:
                self.master.release(a)

    # -- one drive's script (in its own thread) --------------------------------------------------
    def _drive_thread(self, plan: StationPlan) -> None:
        from profidrive_cli.drives import make_drive
        try:
            drive = make_drive(ImageChannel(self, plan.address), plan.profile, plan.layout)
            plan.drive = drive
            i = 0
            while not self.stopping:
                try:
                    self._one_run(drive, plan, plan.script.speeds_pct[i % len(plan.script.speeds_pct)])
                except BusError as e:          # DriveError included: say so, try again
                    plan.errors.append(str(e))
                    self.log(f"plc: station {plan.address}: {e}")
                    self._hold(drive, 1.0)
                    try:
                        drive.stop(mode="normal", wait=False)
                        if drive.status().fault:
                            drive.reset_fault()
                    except BusError:
                        pass
                i += 1
        except PlcStopped:
            pass
        except Exception as e:                 # a codec bug must not leave the drive turning
            self.log(f"plc: station {plan.address}: script ended: {type(e).__name__}: {e}")
            plan.errors.append(str(e))
            self._stop_quietly(plan)

    def _stop_quietly(self, plan: StationPlan) -> None:
        """After an unexpected error: a normal stop, then idle cycles until the PLC ends."""
        try:
            if plan.drive is not None:
                plan.drive.stop(mode="normal", wait=False)
                while not self.stopping:
                    plan.drive.status()
        except (PlcStopped, Exception):
            pass

    def _one_run(self, drive: Drive, plan: StationPlan, pct: float) -> None:
        s = plan.script
        drive.set_speed(pct)
        drive.start(timeout=5.0)
        now = drive.channel.now
        end = now() + s.hold_s
        while now() < end:
            t_read = now()
            self._read_one(drive, plan)
            self._hold(drive, min(end, t_read + s.read_every_s) - now())
        drive.stop(mode="normal", wait=True, timeout=30.0)
        self._hold(drive, s.pause_s)

    def _read_one(self, drive: Drive, plan: StationPlan) -> None:
        """The next of the plan's parameter reads (round robin); a code the card cannot address
        (UsageError, e.g. no published PNU) is dropped from the plan."""
        while drive.has_param_channel and plan.reads:
            code = plan.reads[plan.next_read % len(plan.reads)]
            try:
                drive.read_param(code)
                plan.next_read += 1
                return
            except UsageError:
                plan.reads.remove(code)

    def _hold(self, drive: Drive, seconds: float) -> None:
        end = drive.channel.now() + seconds
        while drive.channel.now() < end:
            drive.status()


def _user_prm(ident: int) -> bytes:
    """The device's default User_Prm_Data from its GSD (library or PDRIVE_GSD_DIR), else none: what
    a drive session sends (session/bringup.py user_prm)."""
    try:
        from profidrive_cli.gsd.interp import device_user_prm
        from profidrive_cli.gsd.library import find_by_ident
        g = find_by_ident(ident)
        return device_user_prm(g) if g is not None else b""
    except Exception:       # a broken user GSD must not keep the PLC from starting
        return b""
