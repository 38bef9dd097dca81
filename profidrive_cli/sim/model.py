"""The application behind a simulated station's Data_Exchange.

sim/slave.py owns the DP side of a station (states, Set_Prm/Chk_Cfg checks, watchdog, FCB, diag bits);
a SlaveModel owns what the device does with its process data. One drive family = one model module in
sim/ (sim/fuji.py, sim/moeller.py, ...), built from that family's profile.

All methods are sans-IO and take `now` (seconds, monotonic, from whoever drives the bus), so a model can
be run on a simulated clock.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.dp.msac1 import Msac1Pdu
    from profidrive_cli.drives.profile import Profile


class C1Server(Protocol):
    """A DP-V1 slave's class-1 acyclic server (MSAC_C1 Read/Write of data records), sans-IO.

    sim/slave.py owns the wire side: SAP 51, the short acknowledgement, the answer in the reply to a
    poll once it is ready, the one request pending (a new one replaces it), what drops it. The server
    owns the records: it answers each request and says from when the answer may be given."""

    def c1_request(self, pdu: Msac1Pdu, now: float) -> tuple[bytes, float] | None:
        """The answer to a Read or Write request that arrived at `now` (decoded; its function READ
        or WRITE): the answer PDU (msac1.read_response / write_response / error_response octets)
        and the time from which it is ready; None: the request is never answered."""

    def c1_drop(self, now: float) -> None:
        """The class-1 connection ended (a Set_Prm, the watchdog, the station left data exchange):
        forget what is in progress (e.g. a parameter response not yet read)."""


_TICKS_ALWAYS: dict[type, bool] = {}


def ticks_always(model: object) -> bool:
    """Whether the model's class overrides tick() below the class that says next_due() (or has no
    next_due at all): a model written before next_due (a plug-in family's, say), ticked at every
    tick of the bus and tick by tick when it makes up for ticks, as before."""
    cls = type(model)
    v = _TICKS_ALWAYS.get(cls)
    if v is None:
        tick_owner = next((c for c in cls.__mro__ if "tick" in vars(c)), None)
        due_owner = next((c for c in cls.__mro__ if "next_due" in vars(c)), None)
        v = due_owner is None or (tick_owner is not None and tick_owner is not due_owner
                                  and issubclass(tick_owner, due_owner))
        _TICKS_ALWAYS[cls] = v
    return v


class SlaveModel:
    """A plain DP-V0 slave: fixed ident, a set of accepted configurations, zero inputs.

    Drive models subclass it and override data_exchange()/tick()/on_leave_data_exchange().
    """

    #: short family name ("fuji-g1", "plain", ...) shown by the sim
    family: str = "plain"
    #: Sync / Freeze offered (sim/plant.py sets them where the profile's GSD file claims them)
    sync_supported = False
    freeze_supported = False
    #: the drive profile the model was built from (drive models set it); None: a plain DP-V0 slave
    profile: Profile | None = None
    #: the DP-V1 class-1 server of a DP-V1 slave (sim/dpv1_axis.py); None: no MSAC_C1 (SAP 51
    #: answered RS, as a DP-V0 slave does)
    c1_server: C1Server | None = None
    #: the layout chosen by the last accepted Chk_Cfg (None until configured), and its input and
    #: output lengths in octets (data_exchange answers exactly input_len octets)
    layout: str | None
    input_len: int
    output_len: int

    def __init__(self, ident: int, cfgs: dict[str, bytes] | None = None, name: str = "DP-V0 slave",
                 user_prm_len: int | None = None, max_diag_len: int = 6):
        self.ident = ident
        self.name = name
        #: accepted configurations: layout name -> exact Chk_Cfg octets
        self.cfgs = dict(cfgs or {})
        #: Set_Prm user-parameter length the device insists on (None = any)
        self.user_prm_len = user_prm_len
        self.max_diag_len = max_diag_len
        #: the layout chosen by the last accepted Chk_Cfg (None until configured)
        self.layout: str | None = None
        #: what Get_Cfg reports before any configuration (the device's own default)
        self.default_layout: str | None = None
        self.input_len = 0
        self.output_len = 0

    def on_bus(self, address: int, baud: int) -> None:
        """The plant placed this station at `address` on a bus running at `baud` bit/s (PNU 918/963)."""

    # -- DP start-up -------------------------------------------------------------------------
    def check_prm(self, user_prm: bytes) -> bool:
        """Return True when the Set_Prm user-parameter octets are acceptable."""
        return self.user_prm_len is None or len(user_prm) == self.user_prm_len

    def check_cfg(self, cfg: bytes) -> bool:
        """Return True and select the layout when `cfg` equals one accepted configuration exactly."""
        from profidrive_cli.dp.cfg import io_sizes
        for name, allowed in self.cfgs.items():
            if bytes(cfg) == allowed:
                self.layout = name
                self.input_len, self.output_len = io_sizes(allowed)
                return True
        return False

    def real_cfg(self) -> bytes:
        """What Get_Cfg answers: the configured layout, else the first (default) one."""
        if self.layout is not None:
            return self.cfgs[self.layout]
        if self.default_layout in self.cfgs:
            return self.cfgs[self.default_layout]
        return next(iter(self.cfgs.values()), b"")

    # -- cyclic ------------------------------------------------------------------------------
    def data_exchange(self, outputs: bytes, now: float) -> bytes:
        """Outputs from the master in, inputs to the master out (exactly input_len octets)."""
        return bytes(self.input_len)

    def tick(self, now: float) -> None:
        """Advance internal dynamics (ramps, timers) to `now`."""

    def next_due(self, now: float) -> float | None:
        """When the model must next be ticked although its station is not addressed, given that it
        was last ticked at `now` (sim/bus.py ticks a station only when a request addresses it or
        when this time, or its watchdog's expiry, has come; then at the bus's next tick at or after
        it). None: nothing of its own (ticks would change nothing but the time of the last tick);
        `now` or earlier: at every tick of the bus (ramping, running). Drive models override it.

        A class that overrides tick() below the class that defines next_due() (a model written
        before this hook, e.g. a plug-in family's) is ticked at every tick of the bus, as it always
        was (ticks_always above)."""
        return None

    def catch_up(self, times: list[float], then: float | None = None) -> None:
        """The bus ticked at `times` (in order, the latest 256 at most) while this model's station
        was neither addressed nor due: what those ticks would have done. `then`: a tick at that
        time follows at once. Default: one tick at the last of them, none when a tick follows (next_due
        said None: ticks change nothing but the time of the last one, which that tick sets). A model
        that records something at every tick overrides this (sim/toyo.py)."""
        if times and then is None:
            self.tick(times[-1])

    def on_leave_data_exchange(self, now: float, reason: str) -> None:
        """The station left Data_Exchange (watchdog expired, new Set_Prm, power cycle, Clear).

        Outputs go to their safe state; a drive applies its communication-loss reaction here.
        """

    def clear_outputs(self, now: float) -> None:
        """Global_Control Clear_Data: the master is in CLEAR; outputs to safe values."""
        self.on_leave_data_exchange(now, "clear")

    # -- diagnosis ---------------------------------------------------------------------------
    def ext_diag(self) -> bytes:
        """Extended diagnosis octets appended after the 6 standard octets (b'' for none)."""
        return b""

    # -- fault injection / demos -------------------------------------------------------------
    def trip(self, alarm: str, now: float) -> None:
        """Trip the device with a family alarm name (drive models); plain slaves ignore it."""
        raise ValueError(f"{self.family} station cannot trip")

    def seed_faults(self, alarms: list[str]) -> None:
        """Pre-fill the fault history (drive models)."""
        raise ValueError(f"{self.family} station has no fault history")

    # -- steering while a master runs (sim/control.py) ---------------------------------------
    def clear_fault(self, now: float) -> None:
        """Clear the active fault as the drive's keypad reset would (drive models)."""
        raise ValueError(f"{self.family} station has no faults to clear")

    def set_value(self, code: str, value: float) -> None:
        """Change a setting in the drive's memory now (engineering units; drive models)."""
        raise ValueError(f"{self.family} station has no parameters")

    def snapshot(self) -> dict[str, object]:
        """What the plant shows of the device (sim-ctl state): drive models add state, Hz, fault."""
        return {"family": self.family, "layout": self.layout}


class DriveModel(SlaveModel):
    """A drive's model (sim/<family>.py): built from its drive profile, which it keeps in `profile`."""

    profile: Profile
