"""The one Drive interface the CLI uses for every family.

A family = one codec module in drives/ (sans-IO: builds output octets from a command, decodes input
octets into a DriveStatus) + one profile in profiles/ + one sim model in sim/. A Drive couples a codec
with a CyclicChannel (one Data_Exchange per call, provided by dp/) and does the waiting: stepping the
state machine, running the PKW/handshake request until its answer arrives, timeouts.

Everything here speaks engineering units and native codes (F03, A004, E1-04); raw PNU/register access
goes through the same calls with codes like "PNU23", "PNU947[9]" or "REG0x0180" (see the codec).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, Callable, ClassVar, Iterator, Protocol, Sequence, final

from profidrive_cli import BusError, UsageError
from profidrive_cli.drives.torque import no_torque_reason
from profidrive_cli.drives.values import raw_value_problem
from profidrive_cli.drives.values import value_problem as exact_value_problem


class CyclicChannel(Protocol):
    """One station in Data_Exchange. Implemented by dp.poller.StationChannel (and by test doubles)."""

    def exchange(self, outputs: bytes) -> bytes:
        """Send outputs, return the station's inputs (one cycle, waits for the cycle period)."""

    def now(self) -> float:
        """Monotonic time in seconds (the clock the bus runs on)."""


class AcyclicChannel(Protocol):
    """A station's DP-V1 class-1 Read/Write (dp.poller.StationChannel; the session's MeteredChannel
    passes it on). A channel without these methods has no acyclic services."""

    def c1_read(self, slot: int, index: int, length: int, timeout_s: float) -> bytes: ...

    def c1_write(self, slot: int, index: int, data: bytes, timeout_s: float) -> None: ...


class DriveError(BusError):
    """The drive refused or did not answer (parameter error, timeout, not allowed in this state)."""


class ParamError(DriveError):
    """A parameter request was answered with an error; .number is the card's error number."""

    def __init__(self, message: str, number: int | None = None):
        super().__init__(message)
        self.number = number


@dataclass
class DriveStatus:
    state: str                        # "S1 switching on inhibited", "operation", "fault", "stopped", ...
    running: bool
    fault: bool
    flags: dict[str, bool]            # named status bits, in the family's words
    speed_percent: float | None       # actual speed in % of max frequency (signed: negative = reverse)
    speed_hz: float | None            # actual frequency in Hz, when max frequency is known
    reference_percent: float | None = None
    fault_code: str | None = None     # current fault as the family names it ("OC1", "E05", ...)
    raw: dict[str, int] = field(default_factory=dict)   # raw words (status word, actual value, ...)
    torque_ref_percent: float | None = None   # torque reference sent, % of rated (torque runs only)
    torque_percent: float | None = None       # torque the card reports, % of rated (where it has a word)

    @property
    def stopped(self) -> bool:
        return not self.running and (self.speed_percent in (None, 0.0) or abs(self.speed_percent) < 0.05)


def value_text(v: object, unit: str = "") -> str:
    """An engineering value with its unit for messages and tables ("6 Hz", "2.5 s", "-")."""
    if v is None:
        return "-"
    t = f"{v:.6g}" if isinstance(v, float) else str(v)
    return f"{t} {unit}" if unit else t


@dataclass
class ParamValue:
    code: str            # native code as the profile names it ("F03")
    name: str
    raw: int             # value on the wire
    value: float | int   # engineering value (raw * scale)
    unit: str = ""
    text: str | None = None   # the value as the card's tables show it (`format:`, drives/formats.py)

    def __str__(self) -> str:
        return f"{self.code} = {self.value}{(' ' + self.unit) if self.unit else ''}"


@dataclass
class ParamInfo:
    code: str                      # the code as the family names it
    name: str
    unit: str
    param: Any                     # the profile's ParamDef (None for raw PNU / register access)
    access: str                    # rw / ro / stop / wo / "raw"
    #: the codec's own resolved address (PROFIdrive ParamRef, Yaskawa register), so that
    #: value_problem / params_at / read_resolved / write_resolved need not resolve the code again
    ref: Any = field(default=None, repr=False, compare=False)

    @property
    def writable(self) -> bool:
        return self.access in ("rw", "stop", "wo", "raw")


@dataclass
class Reaction:
    """The drive's configured reaction to a lost master (or to all-zero outputs), read from the
    drive (Drive.comm_loss_reaction / zero_data_reaction; the comm-loss test checks against it)."""
    words: str                     # e.g. "o27 = 0: coast to a stop at once, then trip Er5"
    stop: str                      # "coast" | "ramp" | "trip" | "none"
    delay_s: float = 0.0           # configured delay after the watchdog
    recover: bool = False          # forgotten when the link returns within the delay
    alarm: str | None = None       # the fault the drive shows
    decel_s: float | None = None   # ramp time from max frequency to 0 (stop == "ramp")
    settings: dict[str, Any] = field(default_factory=dict)   # code -> value read from the drive
    warnings: list[str] = field(default_factory=list)   # what may make the drive act otherwise

    def stop_s(self, hz: float, fmax_hz: float) -> float:
        if self.stop != "ramp" or not self.decel_s or fmax_hz <= 0:
            return 0.0
        return self.decel_s * min(1.0, abs(hz) / fmax_hz)

    @property
    def stop_known(self) -> bool:
        """False: a ramp stop whose time could not be read (the limit counts none)."""
        return self.stop != "ramp" or bool(self.decel_s)


@dataclass
class FaultRecord:
    position: str        # "current", "last", "2nd last", ... or an index
    raw: int             # code on the wire
    codes: list[str]     # alarm names; several when one number maps to several alarms
    meanings: list[str]

    @property
    def empty(self) -> bool:
        """A slot that holds no alarm: code 0 and no alarm named (Fuji PNU947 0000 / M16-M19 0 "no
        alarm", Moeller PNU 947 0 "No fault"); Drive.fault_history leaves such slots out, each
        record keeping its own position."""
        return self.raw == 0 and not self.codes


class Drive(ABC):
    """Common operations. Every blocking call keeps exchanging cyclic data while it waits."""

    family: str = ""
    #: what __init__ keeps for the codec: the station's cyclic channel, the drive profile (a
    #: drives.profile.Profile) and the layout in use (one of the profile's layouts)
    channel: CyclicChannel
    profile: Any
    layout: str

    def __init__(self, channel: CyclicChannel, profile: Any, layout: str | None = None):
        self.channel = channel
        self.profile = profile
        self.layout = layout or profile.default_layout

    # -- one cycle ---------------------------------------------------------------------------
    @abstractmethod
    def cycle(self) -> DriveStatus:
        """One Data_Exchange with the current command; returns the decoded status."""

    def cycles_until(self, predicate: Callable[[DriveStatus], bool], timeout: float, what: str
                     ) -> DriveStatus:
        """Cycle until predicate(status) is true; DriveError naming `what` after `timeout` s."""
        end = self.channel.now() + timeout
        st = self.cycle()
        while not predicate(st):
            if self.channel.now() > end:
                raise DriveError(f"timed out after {timeout:g} s waiting for {what} (state: {st.state})")
            st = self.cycle()
        return st

    # -- motion ------------------------------------------------------------------------------
    @abstractmethod
    def start(self, timeout: float = 5.0) -> DriveStatus:
        """Step the drive to operation (running) with the current reference."""

    @abstractmethod
    def stop(self, mode: str = "normal", wait: bool = True, timeout: float = 30.0) -> DriveStatus:
        """mode: 'normal' (ramp, OFF1), 'quick' (OFF3), 'coast' (OFF2 / base block)."""

    @abstractmethod
    def set_speed(self, percent: float) -> None:
        """Reference in % of max frequency; negative = reverse (families with a reverse bit use it)."""

    def set_speed_hz(self, hz: float) -> None:
        fmax = self.max_frequency()
        self.set_speed(100.0 * hz / fmax)

    # -- jog (the card's own jog / inching function) -----------------------------------------
    supports_jog: bool = False

    def jog_refusal(self) -> str:
        """Why this card cannot jog over the bus (one line; only asked when supports_jog is False)."""
        return f"{self.family}: jog is not supported by this card"

    @classmethod
    def set_prm_user_data(cls, profile: Any, user_prm: bytes) -> bytes:
        """The User_Prm_Data of the station's Set_Prm, from the GSD's defaults (`user_prm`): a
        family changes what its card needs (the PROFIdrive core: DPV1_Enable for a DS47 card)."""
        return user_prm

    @classmethod
    def jog_refusal_for(cls, profile: Any, layout: str) -> str | None:
        """Class fact, no bus: None when this family's card can jog in `layout`, else one line saying
        why not; the same answer as a connected drive's supports_jog / jog_refusal()."""
        if cls.supports_jog is True:
            return None
        return f"{cls.family}: jog is not supported by this card"

    @classmethod
    def status_flag_names(cls, profile: Any, layout: str) -> list[str]:
        """Class fact, no bus: the names this family's status decode can give DriveStatus.flags in
        `layout` (what a checklist's expect_status may name besides the generic ones)."""
        return []

    @classmethod
    def normalise_area(cls, profile: Any, direction: str, area: dict[str, Any]) -> dict[str, Any]:
        """Class fact, no bus: an area this family's decode_area decoded (direction "request": the
        master's outputs, "response": the drive's inputs) in the common words of `pdrive sniff
        --station` (the `drive` object of docs/json.md): command / control / control_word (request),
        state / status / status_word (response), reference_hz / actual_hz, and `param`, the parameter
        channel's request or answer with its one-line `text`; a field the area does not carry is left
        out. A new dict each call (the caller adds to it). The base knows no area shape: {} (the sniff
        line then names only the station); each family reads its own (area_shape)."""
        return {}

    @classmethod
    def audit_rules(cls, profile: Any) -> list[Any]:
        """Class fact, no bus: this family's rules for `pdrive audit`, drives.audit.AuditRule objects
        (each a check of a connected drive citing its manual line, or a topic the family's manual
        gives no setting for, with the reason; drives/audit.py imports this module, so the type is
        named here in words). session/audit.py runs them; [] = the family has none."""
        return []

    def jog_reference(self) -> str | None:
        """The parameter code holding the jog speed (e.g. Moeller A038), None where the card has none."""
        return None

    def jog(self, on: bool = True, reverse: bool = False) -> None:
        """Jog on (forward or reverse) or off; one cycle. Jog off returns to standstill at the card's
        own braking; the caller then stops the drive the normal way (stop)."""
        raise DriveError(self.jog_refusal())

    # -- torque (drives/torque.py: the family-independent checks) -----------------------------
    def torque_support(self) -> str | None:
        """None when this card and layout carry a torque reference word, else the one-line reason."""
        return no_torque_reason(self.family)

    def torque_limit_support(self) -> str | None:
        """None when this card and layout carry a torque limit word, else the one-line reason."""
        return no_torque_reason(self.family)

    def torque_resolution(self) -> float:
        """Percent of rated torque per count of the torque words."""
        return 1.0

    def set_torque(self, percent: float | None) -> None:
        """Torque control with this reference (% of rated, negative = reverse); None = speed control."""
        raise DriveError(self.torque_support() or f"{self.family}: torque is not supported")

    def set_torque_limit(self, percent: float | None) -> None:
        """Torque limit in % of rated while speed controlled; None = no limit from the bus."""
        raise DriveError(self.torque_limit_support() or f"{self.family}: torque limit is not supported")

    def torque_notes(self) -> list[str]:
        """What the drive's own settings must be for the torque words to act (for warnings)."""
        return []

    @abstractmethod
    def reset_fault(self, timeout: float = 5.0) -> DriveStatus:
        """Acknowledge the current fault (after the cause is gone)."""

    @abstractmethod
    def status(self) -> DriveStatus:
        """One cycle's status, decoded."""

    # -- parameters --------------------------------------------------------------------------
    @property
    def has_param_channel(self) -> bool:
        return True

    @abstractmethod
    def read_param(self, code: str) -> ParamValue: ...

    def read_many(self, codes: Sequence[str]) -> Iterator[tuple[str, ParamValue | DriveError | UsageError]]:
        """Several parameters in order, each as it is read: (code, its value, or the DriveError or
        UsageError that refused it). Here one read_param each; a family whose channel carries
        several parameters in one transaction reads them together (Yaskawa's 16-word format: up to
        4 consecutive MEMOBUS registers), with the same values and the same refusals per code."""
        for code in codes:
            try:
                yield code, self.read_param(code)
            except (DriveError, UsageError) as e:
                yield code, e

    @final
    def write_param(self, code: str, value: float | int) -> ParamValue:
        """The drive's own checked write (no plan; no families' override -- they implement
        write_resolved): `code` resolved by param_info, refused when the parameter is read-only or
        the value fails value_problem (the exact-value check), each refusal raised as the family
        words it (write_refusal); then write_resolved, the one write hook. Returns the value read
        back. A write above drives/ goes through session/parameters.py (Parameters.plan, execute),
        which makes the same checks and reaches the same hook."""
        info = self.param_info(code)
        p = info.param
        if not info.writable or (p is not None and not p.writable):
            label = f"{info.code} ({info.name})" if info.name else info.code
            raise self.write_refusal(info, "read_only", f"{label} is read-only")
        msg = self.value_problem(info, value)
        if msg:
            raise self.write_refusal(info, "out_of_range", msg)
        return self.write_resolved(info, value)

    def write_refusal(self, info: ParamInfo, kind: str, message: str) -> Exception:
        """The error write_param raises for a write it refuses before sending: `kind` is
        "read_only" or "out_of_range"; `message` the one line. Here DriveError for a read-only
        parameter, UsageError for a value the parameter cannot hold; a codec whose card numbers
        these errors answers with its own (PROFIdrive: ParamError with the card's error number)."""
        return DriveError(message) if kind == "read_only" else UsageError(message)

    def save(self) -> None:
        """Store parameters in non-volatile memory where the card supports it."""
        raise DriveError(f"{self.family}: this card has no separate save command")

    # -- family hooks for session/parameters.py (defaults here; each codec answers what differs) ----
    def param_info(self, code: str) -> ParamInfo:
        """How this family addresses `code` (no bus traffic); UsageError when it does not."""
        p = self.profile.param(code)
        if p is None:
            raise UsageError(f"{self.profile.name}: unknown parameter {code!r}")
        return ParamInfo(p.code, p.name, p.unit, p, p.access)

    def param_label(self, code: str) -> tuple[str, Any]:
        """(canonical label, ParamDef or None for a raw address) for a checklist's `code`, without
        a bus; UsageError ("unknown ...") when the family does not address it."""
        return type(self).param_label_for(self.profile, code)

    @classmethod
    def param_label_for(cls, profile: Any, code: str) -> tuple[str, Any]:
        """Class fact, no bus: param_label() from the profile alone (a checklist's validation)."""
        p = profile.param(code)
        if p is not None:
            if p.register is None and p.pnu is None:
                raise UsageError(f"{p.code}: the profile gives no address for it")
            return p.code, p
        raise UsageError(f"unknown parameter '{code}' in profile {profile.name}")

    def value_problem(self, info: ParamInfo, value: float | int) -> str | None:
        """The exact-value check before a write (drives/values.py): None when `value` may be
        written to `info`, else the one-line reason."""
        if info.param is not None:
            return exact_value_problem(info.param, value)
        return raw_value_problem(info.code, value, 16)

    def params_at(self, info: ParamInfo) -> list[Any]:
        """The profile's entries at the address `info` reaches (its raw PNU/index or register),
        for the `dangerous:` marks of a parameter written by its raw address."""
        return []

    def read_resolved(self, info: ParamInfo) -> ParamValue:
        """Read the parameter `info` (from param_info) without resolving its code again."""
        return self.read_param(info.code)

    @abstractmethod
    def write_resolved(self, info: ParamInfo, value: float | int) -> ParamValue:
        """THE family hook for writing a parameter; every write reaches it (Parameters.execute
        after Parameters.plan, and write_param). Write `value`, already checked (plan or
        write_param: writable, value_problem; plan also: not dangerous unless allowed), to the
        parameter `info` (from param_info) without resolving or checking it again (the codecs
        write `info.ref`), then read it back; returns the value read back. What only the family
        knows -- a frame its card cannot write, its refusal in words -- is checked here."""

    # -- family hooks for session/backup.py (dump, compare, restore) --------------------------
    def dumpable(self, p: Any) -> bool:
        """The profile entry `p` has an address this family reads parameters by (PNU here)."""
        return p.pnu is not None

    def not_dumpable_why(self) -> str:
        """Why the profile's settings without such an address (dumpable() False) are not in a dump:
        one line for the dump file's header, stderr and --json (session/backup.py)."""
        return "the profile gives them no address this family reads parameters by"

    def on_device(self, p: Any) -> bool:
        """False for entries the connected device variant does not have, and for fault memories
        (`pdrive faults` reads those)."""
        return True

    def not_restored(self, p: Any) -> str:
        """Why a writable profile entry `p` is never written back by `restore` ('' = it is)."""
        if p.extra.get("dangerous"):
            return "dangerous (initialisation / auto-tuning)"
        if p.access == "wo":
            return "a command, not a setting"
        return self._family_not_restored(p)

    def _family_not_restored(self, p: Any) -> str:
        """The family's own exclusions after the shared ones of not_restored ('' = none)."""
        return ""

    def take_notes(self) -> list[str]:
        """Remarks for the user the codec collected since the last call (then cleared)."""
        return []

    def save_support(self) -> str:
        """'command' (the card has a save command), 'automatic' (every write is stored), or
        'unsupported'."""
        return "unsupported"

    @abstractmethod
    def fault_history(self) -> list[FaultRecord]: ...

    def max_frequency(self) -> float:
        """Max frequency in Hz: read from the drive when a parameter channel exists, else the profile."""
        return float(self.profile.max_frequency_default)

    def comm_loss_summary(self) -> str | None:
        """What the drive does when the master goes silent, read from its settings in one line
        (needs the parameter channel); None when the family has no such reading."""
        return None

    #: the shape of the codec's decode_area (drives.decode_area): "ppo" control/status words, N2 or
    #: the family's speed words and the PKW channel; "memobus" Yaskawa's run command / status words
    #: and the MEMOBUS parameter area (the family's normalise_area reads its own)
    area_shape: str = "ppo"

    def start_hint(self, status: DriveStatus) -> str | None:
        """What to check when the drive does not start from the bus (appended to the timeout's
        line); None when the family names nothing."""
        return None

    def last_seen(self) -> DriveStatus | None:
        """The status decoded from the last exchange (None before the first)."""
        return None

    def cycle_words(self, outputs: bytes, inputs: bytes) -> tuple[int | None, int | None,
                                                                   int | None, int | None]:
        """(control word, reference, status word, actual) of one exchange's output and input
        octets, in the family's words (the cycle log's columns); None where it has no such word."""
        return None, None, None, None

    # -- family hooks for session/monitors.py (run --monitor) ----------------------------------
    #: how --monitor uses the layout's parameter input words (PZD3..): "" not at all; "read" the
    #: card's own assignment is read and used, nothing written; "map" monitors are assigned for the
    #: session (pzd_assignment_param) and the old assignment written back after
    monitor_mapping: str = ""

    def pzd_assignment_param(self, slot: int) -> str:
        """The parameter that assigns input word PZD(slot + 2) (PROFIdrive PNU 916[slot])."""
        return f"PNU916[{slot}]"

    def pzd_assigned_code(self, raw: int) -> str | None:
        """The profile code an assignment value read from pzd_assignment_param names (None: none)."""
        return None

    def input_words(self) -> tuple[str, ...]:
        """The names of the layout's own input words where they are not PPO words (Yaskawa's
        fast I/O: 'status', 'speed_feedback', ...); () for a PPO layout."""
        return ()

    def pzd_input_count(self) -> int:
        """How many PZD words the layout's input has (STW and MAV included; PZD3.. are the
        parameter words pzd_assignment_param assigns); 0 where the layout has no PPO."""
        return 0

    def last_pzd(self) -> list[int] | None:
        """The input PZD words of the last exchange (PZD1 first); None before the first, or where
        the layout has no PPO."""
        return None

    def param_from_word(self, code: str, raw: int) -> ParamValue:
        """The value of parameter `code` carried in a cyclic input word `raw`, scaled as the
        parameter channel reads it (run --monitor)."""
        p = self.profile.param(code)
        if p is None:
            raise UsageError(f"{self.profile.name}: unknown parameter {code!r}")
        return ParamValue(p.code, p.name, raw, p.from_raw(raw), p.unit)

    # -- family hooks for session/commloss_reaction.py (the comm-loss test) -------------------
    #: True when the reaction to a lost master is fixed by the card (read without a parameter
    #: channel: Toyo protection 18); False when it is a setting read from the drive
    comm_loss_reaction_fixed: bool = False

    def can_read(self, code: str) -> bool:
        """The profile has `code` with an address and this layout has a parameter channel."""
        p = self.profile.param(code)
        return (p is not None and (p.pnu is not None or p.register is not None)
                and self.has_param_channel)

    def comm_loss_reaction(self) -> Reaction | None:
        """What the drive is set to do when its master goes away, read from it (the card
        manuals' rules); None when the family knows no such reaction. DriveError, KeyError,
        ValueError when a setting cannot be read."""
        return None

    def zero_data_reaction(self, head: str) -> Reaction | None:
        """What the drive does with all-zero outputs (Global_Control Clear_Data), when the family
        says more than "its normal stop" (None); `head` starts the words. DriveError when a
        setting cannot be read."""
        return None

    def normal_stop_warnings(self) -> list[str]:
        """What may make the normal stop act otherwise when its deceleration time is unknown."""
        return []

    def bus_run_refusal(self) -> str | None:
        """Why the bus cannot run this drive at the speed it asks (read from the drive; None: it
        can). DriveError when the setting cannot be read."""
        return None

    #: the max frequency (Hz = 100 %) the codec scales speed words with; None = not known yet
    _fmax: float | None = None
    #: why the drive's own max frequency could not be read, when the codec fell back to the
    #: profile default (None: read, or never tried); session/motion.py says it instead of "read"
    fmax_unread: str | None = None

    def use_max_frequency(self, hz: float) -> None:
        """Scale speed words with `hz` as 100 % (the --fmax / config / profile value the session
        settled on when the drive's own max frequency cannot be read)."""
        self._fmax = hz

    def speed_scale_hz(self) -> float | None:
        """The max frequency (Hz = 100 %) the codec scales speed words with now; None when it has
        not settled on one yet (a Sample then shows the profile default)."""
        return self._fmax

    # -- family hooks for session/motion.py and session/safestop.py (the run and the safe stop) --
    #: the card's own ramp-time parameters by role ("accel", "decel": seconds from 0 to the max
    #: frequency), asked when the profile's `profidrive.ramps` names none
    ramp_codes: ClassVar[dict[str, str]] = {}

    def ramp_param(self, role: str) -> str | None:
        """The parameter code holding the ramp time `role` ("accel" / "decel"), None where the card
        names none (no bus traffic; the caller checks the profile can address it)."""
        return self.ramp_codes.get(role)

    #: what the drive does when its master goes silent, in words, for when its setting cannot be
    #: read (comm_loss_summary reads it)
    comm_loss_words: ClassVar[str] = "its communication-loss setting"

    #: called when a command may set the motor turning (on_motion)
    _motion_listeners: tuple[Callable[[], None], ...] = ()

    def on_motion(self, listener: Callable[[], None]) -> None:
        """Call `listener` whenever this Drive is told to turn the motor (start, jog on), whoever
        tells it (session/motion.py: the safe stop on every way out then covers it)."""
        self._motion_listeners = (*self._motion_listeners, listener)

    def _notify_motion(self) -> None:
        """Each codec's start() and jog(on) call this first, before anything is sent."""
        for listener in self._motion_listeners:
            listener()
