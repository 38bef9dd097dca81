"""DriveSession: one drive station in Data_Exchange behind the Drive interface, with a safe stop on
every way out. The glue between dp/ (Master, StationChannel) and drives/ (profiles, make_drive).
No click and no rich here: cli/drive_cmds.py and the checklist runner build on this module.

Public API (stable; everything else is internal)
------------------------------------------------

    DriveSession(master, address=None, *, profile=None, layout=None, ppo=None, fmt=None,
                 watchdog_ms=500, cycle_hz=None, stop_timeout=None, close_link=True,
                 handle_signals=True, before_connect=None, on_message=None, log_csv=None,
                 env=None)

        with DriveSession(opts.open_master(), 5, ppo=3) as s:   # identify, Set_Prm/Chk_Cfg, Drive
            s.start(percent=s.percent_for_hz(30.0))
            while ...: sample = s.poll()
        # leaving the block: normal stop (bounded wait), coast if it does not stop, release, close

      master        dp.poller.Master (e.g. BusOptions.open_master()); the session closes its link on exit
                    unless close_link=False
      address       station 0..125; None -> env PDRIVE_STATION, else the only drive station on the bus
                    (FDL status + Slave_Diag scan; UsageError listing the candidates otherwise)
      profile       profile name / alias / path; None -> chosen from the station's ident. A profile of
                    another device than the station's ident is refused (the message names the station's)
      layout | ppo | fmt   layout name, --ppo N (-> "ppoN") or --format NAME; default: the profile's
      watchdog_ms   DP watchdog armed in Set_Prm (always; 10..650000 ms)
      cycle_hz      Data_Exchange rate. None -> the fastest the bus allows for this station (wire time
                    of one exchange at the baud rate), capped at 100 Hz on real ports and 50 Hz on the
                    instant simulator; 0 -> unpaced (parameter work: as fast as the link answers).
                    A rate above the wire limit adds a warning.
      stop_timeout  seconds to wait for the normal stop before coasting; None -> from the drive's
                    deceleration time where it can be read (1.5 x + 3 s, at least 5 s), else 30 s
      before_connect(session)   called after the station is identified and before Set_Prm: the CLI
                    asks for confirmation here (raise to cancel; nothing has been written yet)
      on_message(text)          warnings and what the safe stop did, one line each (also kept in
                    .warnings / .messages)
      log_csv       path: one CSV row per Data_Exchange (time, cycle, control word, reference, status
                    word, actual, output and input octets)
      handle_signals  while the session is open (main thread only), SIGTERM raises
                    SessionTerminated in the main thread; during the safe stop a second SIGINT/SIGTERM
                    escalates to a coast stop instead of interrupting it

    Attributes after open: station (DriveStation), address, ident, profile, layout (name), drive
    (drives.base.Drive), channel (MeteredChannel), cycle_hz (target, 0 = unpaced), wire_hz (the bus
    limit for this station), warnings, messages, link_lost, stop_report (after stop() / close),
    final_status (the last DriveStatus seen); settable: on_sample(Sample), called on every cycle
    while a stop is awaited (also the stop on exit) — live views keep updating through it.

    Motion:   start(percent) / set_reference(percent) / poll() -> Sample / status() -> Sample /
              stop(on_sample=None) -> StopReport (normal, then coast; bounded) / may_run
    Speed:    fmax(override=None) -> (hz, source words);  percent_for_hz(hz, fmax_override=None)
    Bus:      counters -> dict (master.fdl.counters_for(address));  achieved_hz;  cycles
    Params:   param_info(code) -> ParamInfo (UsageError with the closest codes / the station's family);
              parse_value(code, text);  read_param(code);  write_param(code, value, allow_dangerous=False)
              (checks: writable, not dangerous, exact value -- resolution, range, codes, wire width:
              drives/values.py --, stop-only while running; returns the value read back);
              danger_of(info) -> str | None;  save() -> str;  fault_history();  current_fault();  clear_fault()
    Files:    dump(progress=None) -> dict (YAML-ready: station identity + parameters, count, end marker);
              load_dump(path) -> dict (file:line errors; a cut-off format-2 file is refused);
              compare(doc, progress=None) -> [ParamRow];
              restore(doc, dry_run=False, progress=None, allow_dangerous=False) -> [ParamRow]: every row
              checked before the first write (RestoreRefused(.problems), nothing written); only what
              differs is written and read back; RestoreInterrupted(.rows) when a write fails part-way

    Module functions: find_drive_stations(master, first=0, last=125) -> [DriveStation];
    choose_profile(ident, name=None) -> (Profile, warnings); resolve_layout(profile, layout, ppo, fmt);
    wire_limit_hz(baud, out_octets, in_octets); default_cycle_hz(link, wire_hz);
    suggest_codes(profile, code); profiles_with_code(code)
    Exceptions: SessionTerminated(BaseException) .signum;  errors the user sees are UsageError (exit 2)
    or BusError / DriveError (exit 1), one line each.
"""

from __future__ import annotations

import csv
import dataclasses
import difflib
import math
import os
import signal
import threading
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from profidrive_cli import BusError, PdriveError, UsageError
from profidrive_cli.drives.base import DriveError, DriveStatus, FaultRecord, ParamValue
from profidrive_cli.drives.profile import Profile, all_profiles, load_profile, profile_for_ident
from profidrive_cli.drives import restore as _restore
from profidrive_cli.drives.restore import (DUMP_END, DUMP_FORMAT, RestoreInterrupted,  # noqa: F401
                                           RestoreRefused, check_complete)
from profidrive_cli.drives.values import danger, raw_value_problem, value_problem

DEFAULT_WATCHDOG_MS = 500
CAP_REAL_HZ = 100.0          # default cycle-rate cap over real ports
CAP_SIM_HZ = 50.0            # ... and on the instant simulator
COAST_TIMEOUT_S = 10.0
DEFAULT_STOP_TIMEOUT_S = 30.0

#: deceleration-time parameter per family when the profile's `profidrive.ramps` names none
_DECEL_CODES = {"fuji": "F08", "moeller": "F003", "yaskawa": "C1-02"}
#: what the drive does when the master goes silent, per family (when it cannot be read)
_COMM_LOSS_WORDS = {
    "fuji": "its o27/o28 setting (o27 = 3 or 13..15 ignores the loss: the motor keeps running)",
    "moeller": "P002 (0 = trip E70 and coast; 1 = keep running on the last command)",
    "toyo": "protection 18 (COMM): the inverter trips and coasts",
    "yaskawa": "a BUS fault after the option's communication timeout (the drive stops by its BUS "
               "fault setting)",
}


class SessionTerminated(BaseException):
    """SIGTERM arrived while a DriveSession was open (raised in the main thread, like KeyboardInterrupt)."""

    def __init__(self, signum: int = signal.SIGTERM):
        super().__init__(f"terminated by signal {signum}")
        self.signum = signum


# =============================================================================================
# finding the station
# =============================================================================================


@dataclass
class DriveStation:
    address: int
    ident: int | None
    profile: Profile | None          # the profile whose ident matches (None: not a known drive)
    state: str = ""                  # DP state in words (from Slave_Diag)

    def describe(self) -> str:
        if self.profile is not None:
            return f"{self.address} ({self.profile.name})"
        return f"{self.address} (ident 0x{self.ident:04X})" if self.ident is not None else str(self.address)


def find_drive_stations(master, first: int = 0, last: int = 125) -> list[DriveStation]:
    """Every slave that answers FDL status and Slave_Diag, with its profile (None when the ident is
    not one of ours). Retries are off during the probe so an empty bus is scanned quickly."""
    from profidrive_cli.dp.scan import scan
    saved = master.fdl.params
    master.fdl.params = dataclasses.replace(saved, retries=0)
    try:
        entries = scan(master, first, last)
    finally:
        master.fdl.params = saved
    out = []
    for e in entries:
        if e.station_type != "slave" or e.diag is None:
            continue
        out.append(DriveStation(e.address, e.ident, profile_for_ident(e.ident),
                                e.diag.state_words(master.address)))
    return out


def _station_from_env(env) -> int | None:
    text = (env or {}).get("PDRIVE_STATION")
    if text in (None, ""):
        return None
    try:
        a = int(str(text).strip(), 0)
    except ValueError:
        raise UsageError(f"PDRIVE_STATION={text!r} is not a station address (0..125)") from None
    if not 0 <= a <= 125:
        raise UsageError(f"PDRIVE_STATION={a} is outside 0..125")
    return a


def _family_words(p: Profile) -> str:
    return f"{p.name} ({p.title}, family {p.family}, ident 0x{p.ident:04X})"


def choose_profile(ident: int | None, name: str | None = None, address: int | None = None
                   ) -> tuple[Profile, list[str]]:
    """The profile for a station: `name` if given (refused when the station's ident belongs to
    another profile), else the one whose ident matches. Returns (profile, warnings)."""
    where = f"station {address}" if address is not None else "the station"
    own = profile_for_ident(ident) if ident is not None else None
    if name:
        prof = load_profile(name)
        if ident is None or prof.ident == ident:
            return prof, []
        if own is not None:
            raise UsageError(f"{where} is {_family_words(own)}, not {prof.name} (family {prof.family}); "
                             f"leave out --profile or use --profile {own.aliases[0] if own.aliases else own.name}")
        return prof, [f"{where} reports ident 0x{ident:04X}, profile {prof.name} expects "
                      f"0x{prof.ident:04X}: using {prof.name} as asked (a vendor GSD with the real "
                      f"ident may replace the placeholder)"]
    if own is None:
        known = ", ".join(f"{p.name} 0x{p.ident:04X}" for p in all_profiles())
        raise UsageError(f"{where} reports ident 0x{ident:04X}, which no drive profile has "
                         f"({known}); name one with --profile")
    return own, []


def resolve_layout(profile: Profile, layout: str | None = None, ppo: int | None = None,
                   fmt: str | None = None) -> str:
    given = [x for x in (layout, ppo, fmt) if x is not None]
    if len(given) > 1:
        raise UsageError("give at most one of --ppo N and --format NAME")
    names = ", ".join(profile.layouts)
    if ppo is not None:
        name = f"ppo{ppo}"
        if name not in profile.layouts:
            ppos = [n[3:] for n in profile.layouts if n.startswith("ppo")]
            if not ppos:
                raise UsageError(f"--ppo {ppo}: {profile.name} has no PPO layouts; use --format "
                                 f"{' | '.join(profile.layouts)}")
            raise UsageError(f"--ppo {ppo}: {profile.name} supports PPO {', '.join(ppos)} "
                             f"(layouts: {names})")
        return name
    name = fmt if fmt is not None else layout
    if name is None:
        return profile.default_layout
    if name not in profile.layouts:
        low = {n.lower(): n for n in profile.layouts}
        if name.lower() in low:
            return low[name.lower()]
        raise UsageError(f"--format {name}: {profile.name} has the layouts {names}")
    return name


# =============================================================================================
# cycle rate
# =============================================================================================


def wire_limit_hz(baud: int, out_octets: int, in_octets: int) -> float:
    """The highest Data_Exchange rate the wire allows for one station (request + TSDR + reply + TID1)."""
    from profidrive_cli.fdl.timing import wire_time_data_exchange
    return 1.0 / wire_time_data_exchange(baud, out_octets, in_octets)


def default_cycle_hz(link, wire_hz: float) -> float:
    cap = CAP_SIM_HZ if getattr(link, "instant", False) else CAP_REAL_HZ
    return min(cap, wire_hz)


class MeteredChannel:
    """drives.base.CyclicChannel around dp.poller.StationChannel: counts exchanges, measures the
    achieved rate over the last two seconds, and calls hooks(t, outputs, inputs) after each one."""

    def __init__(self, inner, window_s: float = 2.0):
        self.inner = inner
        self.window_s = window_s
        self.cycles = 0
        self.hooks: list[Callable[[float, bytes, bytes], None]] = []
        self._times: deque[float] = deque(maxlen=4096)

    def now(self) -> float:
        return self.inner.now()

    def exchange(self, outputs: bytes) -> bytes:
        inputs = self.inner.exchange(outputs)
        t = self.inner.now()
        self.cycles += 1
        self._times.append(t)
        for h in self.hooks:
            h(t, outputs, inputs)
        return inputs

    @property
    def rate(self) -> float:
        """Exchanges per second over the last `window_s` seconds (0 before two exchanges)."""
        if len(self._times) < 2:
            return 0.0
        last = self._times[-1]
        first = None
        n = 0
        for t in reversed(self._times):
            if last - t > self.window_s:
                break
            first = t
            n += 1
        if first is None or n < 2 or last <= first:
            return 0.0
        return (n - 1) / (last - first)


# =============================================================================================
# values handed to the CLI / checklists
# =============================================================================================


@dataclass
class Sample:
    """One decoded cycle with everything a live view shows."""
    t: float                       # seconds since the session reached data exchange
    status: DriveStatus
    fmax_hz: float
    cycle_hz: float                # achieved
    cycles: int
    counters: dict

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

    def to_dict(self) -> dict:
        st = self.status
        return {"t": round(self.t, 3), "state": st.state, "running": st.running, "fault": st.fault,
                "stopped": st.stopped, "fault_code": st.fault_code,
                "flags": [k for k, v in st.flags.items() if v],
                "reference_hz": self.reference_hz, "reference_percent": self.reference_percent,
                "actual_hz": self.actual_hz, "actual_percent": self.actual_percent,
                "cycle_hz": round(self.cycle_hz, 2), "cycles": self.cycles,
                "counters": self.counters, "raw": dict(st.raw)}


@dataclass
class StopReport:
    how: str                       # "normal", "coast", "not needed", "not sent (link lost)", "failed"
    stopped: bool
    seconds: float = 0.0
    message: str = ""
    status: DriveStatus | None = None

    def to_dict(self) -> dict:
        return {"how": self.how, "stopped": self.stopped, "seconds": round(self.seconds, 3),
                "message": self.message,
                "state": self.status.state if self.status is not None else None}


@dataclass
class ParamInfo:
    code: str                      # the code as the family names it
    name: str
    unit: str
    param: Any                     # the profile's ParamDef (None for raw PNU / register access)
    access: str                    # rw / ro / stop / wo / "raw"

    @property
    def writable(self) -> bool:
        return self.access in ("rw", "stop", "wo", "raw")


@dataclass
class ParamRow:
    """One line of restore / diff: result applied | refused | unchanged | would apply | differs |
    missing (in the file, not readable) | skipped."""
    code: str
    name: str
    unit: str
    file_value: Any
    drive_value: Any
    result: str
    reason: str = ""
    new_value: Any = None
    line: int = 0                  # the row's line in the file (0: unknown)
    why: str = ""                  # for 'skipped': unknown | read-only | not restored | dangerous

    def to_dict(self) -> dict:
        return {k: v for k, v in dataclasses.asdict(self).items()}


# =============================================================================================
# parameter codes: suggestions and other families
# =============================================================================================


def suggest_codes(profile: Profile, code: str, n: int = 5) -> list[str]:
    by_lower = {c.lower(): c for c in profile.parameters}
    hits = difflib.get_close_matches(code.strip().lower(), list(by_lower), n=n, cutoff=0.5)
    return [by_lower[h] for h in hits]


def profiles_with_code(code: str) -> list[Profile]:
    c = code.strip().lower()
    return [p for p in all_profiles() if any(k.lower() == c for k in p.parameters)]


def _same_value(a, b, scale: float | None) -> bool:
    try:
        fa, fb = float(a), float(b)
    except (TypeError, ValueError):
        return a == b
    tol = abs(scale) / 2.0 if scale else 1e-9
    return abs(fa - fb) <= max(tol * 0.999, 1e-9)


# =============================================================================================
# the session
# =============================================================================================


class DriveSession:
    def __init__(self, master, address: int | None = None, *, profile: str | None = None,
                 layout: str | None = None, ppo: int | None = None, fmt: str | None = None,
                 watchdog_ms: float = DEFAULT_WATCHDOG_MS, cycle_hz: float | None = None,
                 stop_timeout: float | None = None, close_link: bool = True,
                 handle_signals: bool = True,
                 before_connect: Callable[["DriveSession"], None] | None = None,
                 on_message: Callable[[str], None] | None = None,
                 log_csv: str | Path | None = None, env: dict | None = None):
        if address is not None and not 0 <= address <= 125:
            raise UsageError(f"station address {address} outside 0..125")
        if not 10 <= watchdog_ms <= 650000:
            raise UsageError(f"watchdog {watchdog_ms:g} ms outside 10..650000 ms")
        if cycle_hz is not None and cycle_hz < 0:
            raise UsageError(f"cycle rate {cycle_hz:g} Hz must be positive")
        self.master = master
        self.requested_address = address
        self.profile_name = profile
        self._layout_args = (layout, ppo, fmt)
        self.watchdog_ms = float(watchdog_ms)
        self.requested_cycle_hz = cycle_hz
        self.stop_timeout_s = stop_timeout
        self.close_link = close_link
        self.handle_signals = handle_signals
        self.before_connect = before_connect
        self.on_message = on_message
        #: called with each Sample while the session waits for a stop (also the stop on exit)
        self.on_sample: Callable[[Sample], None] | None = None
        self.log_csv = log_csv
        self.env = os.environ if env is None else env

        self.station: DriveStation | None = None
        self.address: int | None = None
        self.ident: int | None = None
        self.profile: Profile | None = None
        self.layout: str | None = None
        self.drive = None
        self.channel: MeteredChannel | None = None
        self.cycle_hz: float = 0.0
        self.wire_hz: float = 0.0
        self.warnings: list[str] = []
        self.messages: list[str] = []
        self.link_lost = False
        self.stop_report: StopReport | None = None
        self.final_status: DriveStatus | None = None
        self.comm_loss_text: str | None = None
        self._may_run = False
        self._t0 = 0.0
        self._decel_s: float | None = None
        self._fmax: tuple[float, str] | None = None
        self._fmax_override: float | None = None
        self._old_handlers: dict[int, Any] = {}
        self._hurry = False
        self._closed = False
        self._log_file = None
        self._log_writer = None
        #: OutputWriteError when the --log file could not be written (raised by close())
        self.log_error = None

    # -- messages ------------------------------------------------------------------------------
    def _warn(self, text: str) -> None:
        self.warnings.append(text)
        if self.on_message:
            self.on_message(f"warning: {text}")

    def _say(self, text: str) -> None:
        self.messages.append(text)
        if self.on_message:
            self.on_message(text)

    # -- context manager -----------------------------------------------------------------------
    def __enter__(self) -> "DriveSession":
        self._install_signals()
        try:
            self.open()
        except BaseException as e:
            self.close(e)
            raise
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        self.close(exc)
        return False

    def open(self) -> "DriveSession":
        if self.station is None:
            self.identify()
        if self.drive is None:
            if self.before_connect is not None:
                self.before_connect(self)
            self.connect()
        return self

    # -- step 1: which station, which profile, which layout ------------------------------------
    def identify(self) -> DriveStation:
        addr = self.requested_address
        if addr is None:
            addr = _station_from_env(self.env)
        port = getattr(self.master.link, "name", "") or "the bus"
        if addr is None:
            found = find_drive_stations(self.master)
            drives = [s for s in found if s.profile is not None]
            if self.profile_name and not drives:
                drives = found
            if len(drives) == 1:
                self.station = drives[0]
            elif not drives:
                others = f" (other slaves: {', '.join(s.describe() for s in found)})" if found else ""
                raise BusError(f"no drive station answers on {port}{others}")
            else:
                raise UsageError(f"{len(drives)} drive stations on {port}: "
                                 f"{', '.join(s.describe() for s in drives)}; give ADDRESS "
                                 f"(or set PDRIVE_STATION)")
        else:
            d = self.master.slave_diag(addr)
            if d is None:
                raise BusError(f"station {addr} does not answer on {port}")
            self.station = DriveStation(addr, d.ident, profile_for_ident(d.ident),
                                        d.state_words(self.master.address))
        self.address = self.station.address
        self.ident = self.station.ident
        self.profile, warns = choose_profile(self.ident, self.profile_name, self.address)
        for w in warns:
            self._warn(w)
        self.layout = resolve_layout(self.profile, *self._layout_args)
        lay = self.profile.layouts[self.layout]
        baud = self.master.params.baud
        self.wire_hz = wire_limit_hz(baud, lay.output_len, lay.input_len)
        if self.requested_cycle_hz is None:
            self.cycle_hz = default_cycle_hz(self.master.link, self.wire_hz)
        else:
            self.cycle_hz = float(self.requested_cycle_hz)
            if self.cycle_hz > self.wire_hz * 1.0001:
                from profidrive_cli.fdl.timing import BAUD_NAMES
                self._warn(f"--cycle-hz {self.cycle_hz:g} is more than {BAUD_NAMES.get(baud, baud)} "
                           f"allows for this station ({self.wire_hz:.1f} Hz: "
                           f"{1000.0 / self.wire_hz:.1f} ms per Data_Exchange of "
                           f"{lay.output_len}/{lay.input_len} octets); on a real bus the wire sets "
                           f"the pace")
        return self.station

    # -- step 2: parameterise, configure, Data_Exchange, Drive ----------------------------------
    def connect(self):
        from profidrive_cli.drives import make_drive
        from profidrive_cli.dp.station import SlaveConfig
        assert self.profile is not None and self.layout is not None
        lay = self.profile.layouts[self.layout]
        sc = SlaveConfig(ident=self.ident, cfg=lay.cfg, user_prm=self._user_prm(),
                         wd_ms=self.watchdog_ms)
        self.master.add_station(self.address, sc)
        try:
            self.master.bring_up(self.address, timeout=3.0, fail_fast=True)
        except BusError as e:
            raise BusError(f"{e} (profile {self.profile.name}, layout {self.layout}: Chk_Cfg "
                           f"{lay.cfg.hex(' ').upper()})") from None
        period = 1.0 / self.cycle_hz if self.cycle_hz else 0.0
        self.channel = MeteredChannel(self.master.channel(self.address, period))
        if self.log_csv:
            self._open_log()
        self._t0 = self.channel.now()
        drive = make_drive(self.channel, self.profile, self.layout)
        self._track_motion(drive)
        self.drive = drive
        return drive

    def _user_prm(self) -> bytes:
        """The device's default User_Prm_Data from its GSD (library or PDRIVE_GSD_DIR), else none."""
        try:
            from profidrive_cli.gsd.interp import device_user_prm
            from profidrive_cli.gsd.library import find_by_ident
            g = find_by_ident(self.ident)
            return device_user_prm(g) if g is not None else b""
        except Exception:       # a broken user GSD must not keep the drive from starting
            return b""

    def _track_motion(self, drive) -> None:
        """Remember when anything may have set the motor turning (start / jog), whoever called it."""
        for name in ("start", "jog"):
            orig = getattr(drive, name, None)
            if orig is None:
                continue

            def wrapped(*a, _orig=orig, **k):
                self._may_run = True
                return _orig(*a, **k)
            setattr(drive, name, wrapped)

    # -- bus figures ----------------------------------------------------------------------------
    @property
    def counters(self) -> dict:
        if self.address is None:
            return {}
        return self.master.fdl.counters_for(self.address).as_dict()

    @property
    def achieved_hz(self) -> float:
        return self.channel.rate if self.channel is not None else 0.0

    @property
    def cycles(self) -> int:
        return self.channel.cycles if self.channel is not None else 0

    @property
    def may_run(self) -> bool:
        return self._may_run

    def _need_drive(self):
        if self.drive is None:
            raise PdriveError("DriveSession: not connected (use it as a context manager or call open())")
        return self.drive

    # -- speed ----------------------------------------------------------------------------------
    def fmax(self, override: float | None = None) -> tuple[float, str]:
        """(max frequency in Hz = 100 %, where it came from). With a parameter channel the drive's own
        value is read; without one `override` (--fmax) or the profile default is used."""
        d = self._need_drive()
        if self._fmax is not None and override == self._fmax_override:
            return self._fmax
        code = self.profile.max_frequency_param
        pdef = self.profile.param(code) if code else None
        readable = pdef is not None and (pdef.pnu is not None or pdef.register is not None)
        if d.has_param_channel and readable:
            hz = float(d.max_frequency())
            src = f"read from the drive ({code})"
            if override is not None and not math.isclose(override, hz, rel_tol=1e-3):
                self._warn(f"--fmax {override:g} Hz ignored: the drive says {code} = {hz:g} Hz")
        elif override is not None:
            if override <= 0:
                raise UsageError(f"--fmax {override:g}: must be above 0 Hz")
            hz = float(override)
            src = "from --fmax"
            self._set_drive_fmax(hz)
        else:
            hz = float(self.profile.max_frequency_default)
            if not d.has_param_channel:
                why = f"layout {self.layout} has no parameter channel"
            elif code:
                why = f"{code} has no published parameter number"
            else:
                why = "the profile names no max-frequency parameter"
            src = (f"the profile default ({why}; {code or 'max frequency'} not read — "
                   f"give --fmax if the drive is set otherwise)")
            self._set_drive_fmax(hz)
        self._fmax, self._fmax_override = (hz, src), override
        return self._fmax

    def _set_drive_fmax(self, hz: float) -> None:
        # the codecs keep the max frequency they scale speed words with in `_fmax`; without a
        # parameter channel they would use the profile default, so keep them consistent with ours
        if hasattr(self.drive, "_fmax"):
            self.drive._fmax = hz

    def percent_for_hz(self, hz: float, fmax_override: float | None = None) -> float:
        fmax, src = self.fmax(fmax_override)
        pct = 100.0 * hz / fmax
        if abs(pct) > 100.0 + 1e-9:
            raise UsageError(f"{hz:g} Hz is above the maximum frequency {fmax:g} Hz ({src})")
        return pct

    # -- motion ---------------------------------------------------------------------------------
    def set_reference(self, percent: float) -> None:
        if not -100.0 <= percent <= 100.0:
            raise UsageError(f"speed {percent:g} % is outside -100..100 % of the maximum frequency")
        self._need_drive().set_speed(percent)

    def start(self, percent: float | None = None, timeout: float = 5.0) -> Sample:
        """Set the reference (if given) and step the drive to operation."""
        d = self._need_drive()
        if self._decel_s is None:
            self._decel_s = self._read_decel()
        if self.comm_loss_text is None:
            self.comm_loss_text = self._read_comm_loss()
        if percent is not None:
            self.set_reference(percent)
        self._may_run = True
        st = d.start(timeout=timeout)
        return self._sample(st)

    def poll(self) -> Sample:
        """One Data_Exchange with the current command, decoded."""
        st = self._need_drive().cycle()
        if st.fault and st.fault_code is None:
            st = self._need_drive().status()
        return self._sample(st)

    def status(self) -> Sample:
        """One read of the status, with the current fault named where the card can say it."""
        d = self._need_drive()
        if d.has_param_channel:
            try:
                self.fmax()
            except DriveError:
                pass
        return self._sample(d.status())

    def _sample(self, st: DriveStatus) -> Sample:
        if self._fmax is not None:
            fmax = self._fmax[0]
        else:
            fmax = getattr(self.drive, "_fmax", None) or float(self.profile.max_frequency_default)
        self.final_status = st
        return Sample(self.channel.now() - self._t0, st, float(fmax), self.achieved_hz,
                      self.cycles, self.counters)

    def _read_decel(self) -> float | None:
        d = self.drive
        if not d.has_param_channel:
            return None
        code = getattr(getattr(d, "cfg", None), "ramps", {}) or {}
        code = code.get("decel") if isinstance(code, dict) else None
        code = code or _DECEL_CODES.get(self.profile.family)
        if not code or self.profile.param(code) is None:
            return None
        try:
            return float(d.read_param(code).value)
        except (DriveError, UsageError, ValueError, TypeError):
            return None

    def _read_comm_loss(self) -> str:
        d = self.drive
        fam = self.profile.family
        try:
            if fam == "fuji" and d.has_param_channel and hasattr(d, "comm_loss_setting"):
                return d.comm_loss_setting()
            if fam == "moeller" and d.has_param_channel and hasattr(d, "comm_loss_setting"):
                vals = d.comm_loss_setting()
                first = next(iter(vals.values()))
                keep = int(first.raw) == 1
                return (f"{first.code} = {first.raw}: " +
                        ("the drive keeps running on the last command" if keep else
                         "the drive trips (E70) and coasts"))
        except (DriveError, UsageError):
            pass
        return _COMM_LOSS_WORDS.get(fam, "its communication-loss setting")

    def stop_timeout(self, percent: float | None = None) -> float:
        if self.stop_timeout_s is not None:
            return float(self.stop_timeout_s)
        if self._decel_s is None:
            return DEFAULT_STOP_TIMEOUT_S
        frac = 1.0
        if percent is not None:
            frac = min(1.0, abs(percent) / 100.0)
        return max(5.0, min(600.0, 1.5 * self._decel_s * frac + 3.0))

    def stop(self, on_sample: Callable[[Sample], None] | None = None,
             timeout: float | None = None) -> StopReport:
        """The family's normal stop; wait (bounded) until the drive reports stopped; coast if it does
        not. A second SIGINT/SIGTERM during the wait (when signals are handled) coasts at once.
        The report is also kept in .stop_report."""
        self.stop_report = self._stop(on_sample or self.on_sample, timeout)
        return self.stop_report

    def _stop(self, on_sample, timeout) -> StopReport:
        d = self._need_drive()
        t_start = self.channel.now()
        last = d.last_status if hasattr(d, "last_status") else None
        last = last or getattr(d, "last", None)
        pct = last.speed_percent if last is not None else None
        limit = timeout if timeout is not None else self.stop_timeout(pct)
        st = None
        why = ""
        try:
            d.stop("normal", wait=False)
            st = self._wait_stopped(limit, on_sample)
            if st is not None:
                self._may_run = False
                how = "normal"
                msg = (f"the drive is in fault{f' ({st.fault_code})' if st.fault_code else ''}: "
                       f"its output is off" if st.fault else "stopped")
                return StopReport(how, True, self.channel.now() - t_start, msg, st)
            why = ("stop hurried by a second signal" if self._hurry else
                   f"not stopped after {limit:g} s")
        except DriveError as e:
            why = f"normal stop failed: {e}"
        # escalate: coast (OFF2 / base block / run bit off)
        self._warn(f"{why}: coasting")
        try:
            d.stop("coast", wait=False)
            self._hurry = False
            st = self._wait_stopped(COAST_TIMEOUT_S, on_sample)
        except DriveError as e:
            return StopReport("failed", False, self.channel.now() - t_start,
                              f"{why}; coast stop not possible: {e}", self.final_status)
        if st is None:
            return StopReport("failed", False, self.channel.now() - t_start,
                              f"{why}; the drive does not report stopped after a coast stop either",
                              self.final_status)
        self._may_run = False
        return StopReport("coast", True, self.channel.now() - t_start, f"{why}; coasted", st)

    def _wait_stopped(self, timeout: float, on_sample) -> DriveStatus | None:
        d = self.drive
        end = self.channel.now() + timeout
        while True:
            st = d.cycle()
            if on_sample is not None:
                on_sample(self._sample(st))
            else:
                self.final_status = st
            if st.fault or st.stopped:
                if st.fault and st.fault_code is None:
                    try:
                        st = d.status()
                    except DriveError:
                        pass
                return st
            if self._hurry or self.channel.now() > end:
                return None

    # -- closing --------------------------------------------------------------------------------
    def close(self, exc: BaseException | None = None) -> None:
        """Safe stop (if the drive may be running), release the station, close the link. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._guard_signals()
        try:
            self._shutdown(exc)
        finally:
            self._close_log()
            if self.close_link:
                try:
                    self.master.link.close()
                except Exception:
                    pass
            self._restore_signals()
        if self.log_error is not None:
            if exc is None:
                raise self.log_error          # the run went well, its log did not: exit 1
            self._say(str(self.log_error))

    def _link_lost_words(self, e: BaseException) -> str:
        fam_text = self.comm_loss_text or _COMM_LOSS_WORDS.get(
            self.profile.family if self.profile else "", "its communication-loss setting")
        return (f"link lost ({e}): pdrive cannot send a stop. The station's DP watchdog "
                f"({self.watchdog_ms:g} ms) takes it out of data exchange within "
                f"{self.watchdog_ms / 1000.0:g} s of the last telegram; the drive then stops by "
                f"{fam_text}")

    def _shutdown(self, exc: BaseException | None) -> None:
        from profidrive_cli.link.base import LinkLost
        if isinstance(exc, LinkLost):
            self.link_lost = True
        if self.drive is None or self.address is None:
            return
        if self.link_lost:
            if self._may_run:
                self.stop_report = StopReport("not sent (link lost)", False, 0.0,
                                              self._link_lost_words(exc))
                self._say(self.stop_report.message)
            return
        if exc is not None:
            # an interrupted request may have left a reply on the line: start clean
            try:
                time.sleep(min(0.05, self.master.params.reply_timeout(64)))
                self.master.link.flush_input()
            except Exception:
                pass
        if self._may_run:
            try:
                r = self.stop()
                if r.how == "normal":
                    self._say(f"stopped (normal stop, {r.seconds:.1f} s)" if not (r.status and r.status.fault)
                              else r.message)
                elif r.how == "coast":
                    self._say(f"stopped by a coast stop after {r.seconds:.1f} s ({r.message})")
                else:
                    self._say(f"could not confirm the stop: {r.message}")
            except LinkLost as e:
                self.link_lost = True
                self.stop_report = StopReport("not sent (link lost)", False, 0.0, self._link_lost_words(e))
                self._say(self.stop_report.message)
                return
            except PdriveError as e:
                self.stop_report = StopReport("failed", False, 0.0, f"stop failed: {e}")
                self._say(f"stop failed: {e}; the station's watchdog ({self.watchdog_ms:g} ms) "
                          f"ends data exchange when pdrive lets go")
        elif self.stop_report is None:
            self.stop_report = StopReport("not needed", True, 0.0, "not started by this session",
                                          self.final_status)
        try:
            self.master.release(self.address)
        except PdriveError:
            pass

    # -- signals --------------------------------------------------------------------------------
    def _main_thread(self) -> bool:
        return threading.current_thread() is threading.main_thread()

    def _install_signals(self) -> None:
        if not self.handle_signals or not self._main_thread():
            return

        def on_term(signum, frame):
            raise SessionTerminated(signum)
        self._old_handlers[signal.SIGTERM] = signal.signal(signal.SIGTERM, on_term)
        self._old_handlers[signal.SIGINT] = signal.getsignal(signal.SIGINT)

    def _guard_signals(self) -> None:
        """While stopping: a further SIGINT/SIGTERM hurries the stop (coast) instead of raising."""
        if not self.handle_signals or not self._main_thread():
            return

        def hurry(signum, frame):
            self._hurry = True
        for s in (signal.SIGTERM, signal.SIGINT):
            if s not in self._old_handlers:
                self._old_handlers[s] = signal.getsignal(s)
            signal.signal(s, hurry)

    def _restore_signals(self) -> None:
        if not self._main_thread():
            return
        for s, h in self._old_handlers.items():
            try:
                signal.signal(s, h if h is not None else signal.SIG_DFL)
            except (TypeError, ValueError):
                pass
        self._old_handlers.clear()

    # -- cycle log ------------------------------------------------------------------------------
    # Written to a temporary file beside the target (outfile.OutputFile) and renamed over it when the
    # session closes, also after Ctrl-C or a trip (the log of such a run is the one wanted). A write
    # that fails mid-run never disturbs the cycle (nor the stop): logging ends, the temporary file is
    # dropped, the old file stays, and close() raises OutputWriteError (exit 1).
    def _open_log(self) -> None:
        from profidrive_cli.outfile import OutputFile
        out = OutputFile(self.log_csv, "w", newline="", what="--log")
        out.open()
        self._log_file = out
        self._log_writer = csv.writer(out.file)
        self.channel.hooks.append(self._log_cycle)
        self._log_row(["time_s", "cycle", "control_word", "reference", "status_word",
                       "actual", "outputs", "inputs"])

    def _log_cycle(self, t: float, outputs: bytes, inputs: bytes) -> None:
        if self._log_file is None:
            return
        ctw, ref, stw, act = cycle_words(self.drive, outputs, inputs)
        self._log_row([f"{t - self._t0:.4f}", self.channel.cycles, _hex4(ctw), _s16(ref), _hex4(stw),
                       _s16(act), outputs.hex(), inputs.hex()])

    def _log_row(self, row: list) -> None:
        try:
            self._log_writer.writerow(row)
        except OSError as e:
            self._log_failed(e)

    def _log_failed(self, e: OSError) -> None:
        from profidrive_cli.outfile import OutputWriteError
        out, self._log_file = self._log_file, None
        kept = out.path.is_file()           # a regular file there: it stays as it was
        out.discard()
        self.log_error = OutputWriteError(f"--log {self.log_csv}: write failed: {e.strerror or e}"
                                          + ("; the previous file is untouched" if kept else ""))
        self._warn(f"{self.log_error}; logging stopped")

    def _close_log(self) -> None:
        from profidrive_cli.outfile import OutputWriteError
        out, self._log_file = self._log_file, None
        if out is None:
            return
        try:
            out.commit()
        except OutputWriteError as e:
            self.log_error = e

    # -- parameters -----------------------------------------------------------------------------
    def param_info(self, code: str) -> ParamInfo:
        """How the station's family addresses `code` (no bus traffic). UsageError with the closest
        codes of the family, or with the family the code belongs to."""
        d = self._need_drive()
        text = code.strip()
        if not text:
            raise UsageError("empty parameter code")
        try:
            if hasattr(d, "resolve_param"):
                ref = d.resolve_param(text)
                p = ref.param
                return ParamInfo(ref.code, ref.name, p.unit if p is not None else "", p,
                                 p.access if p is not None else "raw")
            reg, p = d._resolve(text)          # Yaskawa: MEMOBUS register
            if p is None:
                return ParamInfo(f"REG0x{reg:04X}", "MEMOBUS register", "", None, "raw")
            return ParamInfo(p.code, p.name, p.unit, p, p.access)
        except UsageError as e:
            raise UsageError(self._unknown_code_message(text, str(e))) from None

    def _unknown_code_message(self, code: str, why: str) -> str:
        prof = self.profile
        if any(k.lower() == code.lower() for k in prof.parameters):
            return why                         # ours, but not reachable (e.g. no published PNU)
        where = f"station {self.address} is {prof.name} ({prof.title}, family {prof.family})"
        others = [p for p in profiles_with_code(code) if p.family != prof.family]
        near = suggest_codes(prof, code)
        hint = f"; closest {prof.family} codes: {', '.join(near)}" if near else ""
        if others:
            fams = sorted({p.family for p in others})
            names = ", ".join(p.name for p in others)
            return (f"{code} is a {'/'.join(fams)} code ({names}); {where}{hint}")
        if near:
            return f"unknown parameter '{code}' for {prof.name}{hint}"
        return f"{why}" if why else f"unknown parameter '{code}' for {prof.name}"

    def parse_value(self, code: str, text: str | float | int, info: ParamInfo | None = None):
        """A value typed by the user -> int/float; UsageError saying what was expected."""
        info = info or self.param_info(code)
        if isinstance(text, (int, float)) and not isinstance(text, bool):
            return text
        t = str(text).strip()
        try:
            if t.lower().startswith(("0x", "-0x")):
                return int(t, 16)
            v = float(t)
            if not math.isfinite(v):
                raise ValueError
            return int(v) if v.is_integer() and "." not in t and "e" not in t.lower() else v
        except ValueError:
            p = info.param
            rng = ""
            if p is not None and p.min is not None and p.max is not None:
                rng = f" {p.min:g}..{p.max:g}"
            unit = f" {info.unit}" if info.unit else ""
            kind = "a number" if p is None or (p.scale and not float(p.scale).is_integer()) else "a whole number"
            raise UsageError(f"{info.code}: expected {kind}{rng}{unit}, got {t!r}") from None

    def read_param(self, code: str) -> ParamValue:
        self.param_info(code)                 # unknown codes: the closest ones / the right family
        return self.drive.read_param(code.strip())

    def danger_of(self, info: ParamInfo) -> str | None:
        """What writing this parameter does, in words, when the profile marks it `dangerous: true`
        (also when it is reached by its raw PNU/index or register); None otherwise."""
        if info.param is not None:
            return danger(info.param)
        d = self.drive
        try:
            if hasattr(d, "resolve_param"):
                ref = d.resolve_param(info.code)
                hits = [q for q in self.profile.parameters.values()
                        if q.pnu is not None and q.pnu == ref.pnu and (q.index or 0) == (ref.subindex or 0)]
            else:
                reg, _ = d._resolve(info.code)
                hits = [q for q in self.profile.parameters.values() if q.register == reg]
        except (UsageError, DriveError, AttributeError):
            return None
        return next((danger(q) for q in hits if danger(q)), None)

    def check_dangerous(self, info: ParamInfo, allow_dangerous: bool = False) -> None:
        """UsageError (exit 2) for a dangerous parameter unless allow_dangerous."""
        what = self.danger_of(info)
        if what and not allow_dangerous:
            raise UsageError(f"{info.code} ({info.name}) is dangerous: writing it {what}; nothing was "
                             f"written (add --allow-dangerous to write it)")

    def _check_write(self, info: ParamInfo, value, allow_dangerous: bool = False) -> None:
        """Every check before a write, no bus traffic: writable, dangerous, exact value (resolution,
        range, listed codes, wire width: drives/values.py)."""
        p = info.param
        if p is not None and not p.writable:
            raise UsageError(f"{info.code} ({info.name}) is read-only")
        self.check_dangerous(info, allow_dangerous)
        d = self.drive
        if hasattr(d, "check_value") and hasattr(d, "resolve_param"):
            msg = d.check_value(d.resolve_param(info.code), value)
        elif p is not None:
            msg = value_problem(p, value)
        else:
            msg = raw_value_problem(info.code, value, 16)
        if msg:
            raise UsageError(msg)

    def stopped_for(self, info: ParamInfo) -> str | None:
        """None when the parameter may be written now; else why not (stop-only while running)."""
        if info.access != "stop":
            return None
        st = self.drive.cycle()
        if st.running or not st.stopped:
            hz = Sample(0, st, self._fmax[0] if self._fmax else float(self.profile.max_frequency_default),
                        0, 0, {}).actual_hz
            return (f"{info.code} ({info.name}) can only be changed while the motor is "
                    f"stopped (the drive is {st.state}" + (f", {hz:g} Hz" if hz else "") + "); stop it first")
        return None

    def write_param(self, code: str, value, *, check_running: bool = True,
                    allow_dangerous: bool = False) -> ParamValue:
        """Checked write (writable, not dangerous unless allow_dangerous, exact value, stop-only
        parameters while running); returns the value read back from the drive."""
        info = self.param_info(code)
        if isinstance(value, str):
            value = self.parse_value(code, value, info)
        self._check_write(info, value, allow_dangerous)
        if check_running:
            why = self.stopped_for(info)
            if why:
                raise DriveError(why)
        return self.drive.write_param(code.strip(), value)

    def notes(self) -> list[str]:
        """Remarks the codec collected (e.g. Fuji: 'o30 takes effect after a power cycle'); cleared."""
        n = list(getattr(self.drive, "notes", []) or [])
        if hasattr(self.drive, "notes"):
            self.drive.notes.clear()
        return n

    def save_support(self) -> str:
        """'command' (the card has a save command), 'automatic' (every write is stored), or
        'unsupported'."""
        d = self._need_drive()
        fam = self.profile.family
        if fam == "toyo":
            return "automatic"
        if fam == "fuji":
            return "command" if getattr(d, "fc", None) is not None and d.fc.storage else "automatic"
        if fam == "yaskawa":
            return "command" if getattr(d, "cfg", None) is not None and d.cfg.enter_register is not None \
                else "unsupported"
        cfg = getattr(d, "cfg", None)
        return "command" if cfg is not None and getattr(cfg, "save_pnu", None) is not None else "unsupported"

    def save(self) -> str:
        """Store parameters in non-volatile memory; returns what happened in words."""
        how = self.save_support()
        if how == "automatic":
            return f"{self.profile.name}: every parameter write is stored by the card itself (no separate save)"
        if how == "unsupported":
            raise DriveError(f"{self.profile.name}: this card has no save command; the value is "
                             f"written but may be lost at power-off")
        self.drive.save()
        return "saved to non-volatile memory"

    def current_fault(self) -> Sample:
        return self.status()

    def fault_history(self) -> list[FaultRecord]:
        return self._need_drive().fault_history()

    def clear_fault(self, timeout: float = 5.0) -> Sample:
        """Acknowledge the current fault (the cause must be gone). The history stays."""
        st = self._need_drive().reset_fault(timeout=timeout)
        return self._sample(st)

    # -- dump / compare / restore ---------------------------------------------------------------
    def dump_plan(self) -> list[tuple[str, Any, str]]:
        """(code, ParamDef, kind) for every parameter of the profile that the family can read:
        kind 'setting' (restored), 'readonly', or 'excluded: why' (read, never restored)."""
        out = []
        self._need_drive()
        for p in self.profile.parameters.values():
            if p.access == "wo":
                continue
            if self.profile.family == "yaskawa":
                if p.register is None:
                    continue
            elif p.pnu is None:
                continue
            if p.extra.get("traceback"):
                continue                          # Toyo traceback channels: 4 x 100 samples each
            if not self._exists_on_device(p):
                continue
            kind = "setting" if p.writable else "readonly"
            why = _not_restored(self.profile, p)
            if why and p.writable:
                kind = f"excluded: {why}"
            arr = p.extra.get("array")
            if isinstance(arr, int) and not isinstance(arr, bool) and arr > 1:
                if p.writable and not why:
                    for i in range(1, arr + 1):
                        out.append((f"{p.code}[{i}]", p, kind))
                continue                           # read-only arrays (fault memory): `pdrive faults`
            out.append((p.code, p, kind))
        return out

    def _exists_on_device(self, p) -> bool:
        """False for parameters the connected device variant does not have (Moeller: `df6: false`
        on a DF6) and for fault memories (`pdrive faults` reads those)."""
        fam = self.profile.family
        d = self.drive
        if fam == "toyo" and p.pnu == getattr(getattr(d, "tc", None), "history_pnu", None):
            return False
        if fam == "moeller" and p.extra.get("df6") is False and hasattr(d, "device"):
            try:
                return not d.device().startswith("DF")
            except (DriveError, UsageError):
                return True
        return True

    def dump(self, progress: Callable[[int, int, str], None] | None = None) -> dict:
        """Read every readable parameter; a YAML-ready document with the station's identity."""
        d = self._need_drive()
        if not d.has_param_channel:
            raise DriveError(self._no_channel_words())
        plan = self.dump_plan()
        settings: dict[str, Any] = {}
        readonly: dict[str, Any] = {}
        failed: dict[str, str] = {}
        for i, (code, p, kind) in enumerate(plan):
            if progress:
                progress(i, len(plan), code)
            try:
                pv = d.read_param(code)
            except (DriveError, UsageError) as e:
                failed[code] = str(e)
                continue
            entry = {"value": pv.value}
            if pv.unit:
                entry["unit"] = pv.unit
            entry["name"] = pv.name or p.name
            if kind == "setting":
                settings[code] = entry
            else:
                if kind.startswith("excluded"):
                    entry["not_restored"] = kind.split(": ", 1)[1]
                readonly[code] = entry
        if progress:
            progress(len(plan), len(plan), "")
        prof = self.profile
        doc = {
            "pdrive_dump": DUMP_FORMAT,
            "station": {"address": self.address, "ident": f"0x{self.ident:04X}", "profile": prof.name,
                        "family": prof.family, "title": prof.title, "layout": self.layout,
                        "port": getattr(self.master.link, "name", "")},
            "date": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "count": len(settings),
            "parameters": settings,
            "readonly": readonly,
        }
        if failed:
            doc["unreadable"] = failed
        doc["end"] = DUMP_END              # the last line: a file cut anywhere lacks it
        return doc

    def _no_channel_words(self) -> str:
        with_pkw = [n for n, lay in self.profile.layouts.items() if lay.pkw]
        return (f"{self.profile.name}: layout {self.layout} has no parameter channel"
                + (f" (use --ppo/--format {' | '.join(with_pkw)})" if with_pkw else ""))

    @staticmethod
    def load_dump(path: str | Path) -> dict:
        """Read a dump file; UsageError with file:line for anything that is not one."""
        from profidrive_cli.datafile import DataFileError, LineDict, load_yaml
        doc = load_yaml(path)
        if not isinstance(doc, LineDict) or "parameters" not in doc:
            raise DataFileError(path, getattr(doc, "line", 1),
                                "not a pdrive parameter file (no 'parameters:' mapping; make one with "
                                "`pdrive param dump`)")
        params = doc["parameters"]
        if params is None:
            params = LineDict()
            doc["parameters"] = params
        if not isinstance(params, dict):
            raise DataFileError(path, doc.line_of("parameters"), "'parameters' must be a mapping CODE: VALUE")
        for code, v in params.items():
            val = v.get("value") if isinstance(v, dict) else v
            if isinstance(val, bool) or not isinstance(val, (int, float)):
                line = params.line_of(code) if isinstance(params, LineDict) else None
                raise DataFileError(path, line, f"{code}: the value must be a number, got {val!r}")
        st = doc.get("station")
        if st is not None and not isinstance(st, dict):
            raise DataFileError(path, doc.line_of("station"), "'station' must be a mapping")
        doc["_warnings"] = check_complete(path, doc, params)
        doc["_path"] = str(path)
        return doc

    def _check_identity(self, doc: dict) -> list[str]:
        st = doc.get("station") or {}
        name = st.get("profile")
        notes = []
        if name and name != self.profile.name:
            try:
                other = load_profile(str(name))
            except UsageError:
                other = None
            if other is None or other.name != self.profile.name:
                raise UsageError(f"{doc.get('_path', 'the file')} was dumped from a {name} station "
                                 f"({st.get('title', '')}); station {self.address} is "
                                 f"{_family_words(self.profile)}")
        if st.get("address") is not None and st.get("address") != self.address:
            notes.append(f"the file was dumped from station {st.get('address')}; writing to station "
                         f"{self.address}")
        return notes

    def compare(self, doc: dict, progress: Callable[[int, int, str], None] | None = None,
                allow_dangerous: bool = False, check_identity: bool = True) -> list[ParamRow]:
        """Each parameter of the file against the drive: 'unchanged', 'differs', 'missing' (cannot
        be read), 'skipped' (unknown code / read-only / not restorable / dangerous; .why says which)."""
        d = self._need_drive()
        if not d.has_param_channel:
            raise DriveError(self._no_channel_words())
        if check_identity:
            for n in self._check_identity(doc):
                self._warn(n)
        rows: list[ParamRow] = []
        params = doc["parameters"]
        items = list(params.items())
        for i, (code, v) in enumerate(items):
            if progress:
                progress(i, len(items), str(code))
            want = v.get("value") if isinstance(v, dict) else v
            line = params.line_of(code) if hasattr(params, "line_of") else 0
            code = str(code)
            try:
                info = self.param_info(code)
            except UsageError as e:
                rows.append(ParamRow(code, "", "", want, None, "skipped", str(e), line=line or 0,
                                     why="unknown"))
                continue
            p = info.param
            base = code.split("[", 1)[0]
            pdef = self.profile.param(base) or p
            if pdef is not None:
                why = _not_restored(self.profile, pdef) if pdef.writable else "read-only"
                if why and not (allow_dangerous and why.startswith("dangerous")):
                    kind = ("read-only" if why == "read-only" else
                            "dangerous" if why.startswith("dangerous") else "not restored")
                    rows.append(ParamRow(code, info.name, info.unit, want, None, "skipped", why,
                                         line=line or 0, why=kind))
                    continue
            try:
                pv = d.read_param(code)
            except (DriveError, UsageError) as e:
                if isinstance(e, BusError) and not isinstance(e, DriveError):
                    raise
                rows.append(ParamRow(code, info.name, info.unit, want, None, "missing", str(e),
                                     line=line or 0))
                continue
            same = _same_value(pv.value, want, pdef.scale if pdef is not None else None)
            rows.append(ParamRow(code, pv.name or info.name, pv.unit or info.unit, want, pv.value,
                                 "unchanged" if same else "differs", line=line or 0))
        if progress:
            progress(len(items), len(items), "")
        return rows

    def restore_problems(self, doc: dict, rows: list[ParamRow], allow_dangerous: bool = False
                         ) -> list[str]:
        """Every reason not to write anything, one line each (drives/restore.py)."""
        return _restore.restore_problems(self, doc, rows, allow_dangerous)

    def restore(self, doc: dict, dry_run: bool = False,
                progress: Callable[[int, int, str], None] | None = None,
                allow_dangerous: bool = False) -> list[ParamRow]:
        """Validate every row, then write what differs, reading each write back (drives/restore.py):
        RestoreRefused (nothing written) / RestoreInterrupted (which rows landed)."""
        return _restore.restore(self, doc, dry_run, progress, allow_dangerous)


def _not_restored(profile: Profile, p) -> str:
    """Why a writable parameter is never written back by `restore` ('' = it is)."""
    if p.extra.get("dangerous"):
        return "dangerous (initialisation / auto-tuning)"
    if p.access == "wo":
        return "a command, not a setting"
    if profile.family == "fuji" and p.code[:1].upper() == "S" and p.code[1:].isdigit():
        return "command data (S codes), not a setting"
    if p.pnu in (927, 928) and profile.family != "yaskawa":
        return "access rights, left as they are"
    if p.pnu in (970, 971) and profile.family != "yaskawa":
        return "a command, not a setting"
    return ""


# =============================================================================================
# cycle words for the CSV log
# =============================================================================================


def _hex4(v) -> str:
    return "" if v is None else f"0x{v & 0xFFFF:04X}"


def _s16(v) -> str:
    if v is None:
        return ""
    v &= 0xFFFF
    return str(v - 0x10000 if v & 0x8000 else v)


def cycle_words(drive, outputs: bytes, inputs: bytes) -> tuple[int | None, int | None, int | None, int | None]:
    """(control word, reference, status word, actual) of one exchange, whatever the family."""
    try:
        fmt = getattr(drive, "fmt", None)
        if fmt is not None and hasattr(fmt, "out_words"):           # Yaskawa fast I/O words
            order = drive.profile.word_order
            ow = [int.from_bytes(outputs[i:i + 2], order) for i in range(0, 2 * len(fmt.out_words), 2)]
            iw = [int.from_bytes(inputs[i:i + 2], order) for i in range(0, 2 * len(fmt.in_words), 2)]
            o = dict(zip(fmt.out_words, ow))
            n = dict(zip(fmt.in_words, iw))
            return o.get("command"), o.get("reference"), n.get("status"), n.get("speed_feedback")
        ppo = getattr(drive, "ppo", None)
        if ppo is not None:
            from profidrive_cli.drives import profidrive as pd
            out = pd.decode_area_bytes(ppo, outputs, "request").pzd
            inp = pd.decode_area_bytes(ppo, inputs, "response").pzd
            tl = getattr(drive, "tl", None)
            if tl is not None:                                      # Toyo: named words
                plch = getattr(drive, "plch", False)
                o = dict(zip(tl.words("request", plch), out))
                n = dict(zip(tl.words("response", plch), inp))
                return (o.get("ctw", o.get("run_cmd")), o.get("speed_ref"),
                        n.get("zsw", n.get("status_flag")), n.get("motor_speed"))
            return (out[0] if out else None, out[1] if len(out) > 1 else None,
                    inp[0] if inp else None, inp[1] if len(inp) > 1 else None)
    except Exception:
        pass
    return None, None, None, None
