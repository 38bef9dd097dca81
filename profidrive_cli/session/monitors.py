"""Monitor values while a drive runs (`run --monitor`) and the card's trip records (`faults`).

Cyclic words first: a monitor the layout's input words carry anyway (the profile's `monitors.cyclic`:
  Toyo current, torque, DC voltage in PPO2/4/5 and mode 1, output voltage in mode 1) is read from its word
  every cycle, with the parameter's own scaling; where the layout has parameter words in its input
  (PPO2/4/5 beyond STW/MAV),
  * Moeller: a monitor of at most 2 octets is mapped into PZD3..PZD10 with PNU 916 (volatile, spec
    2.4 / manual example 2) for the session; Monitors.restore() writes the old assignment back;
  * Fuji: o48..o51 (= PNU 916) need a power cycle after a change (spec 2.4), so nothing is written:
    a monitor already assigned to a response PCD word is read from it, the others through the PKW.
The rest through the parameter channel, one code per call of `Monitors.poll()`, round robin
between the cycles the run loop makes: each read runs a few Data_Exchanges with the current command, so
the drive keeps its control word and the safe stop is unaffected. A code the drive refuses is dropped
once with a note (e.g. Moeller d012, torque, on a DF6). Trip records are read with the drive's own
read_param on the codes the profile's `trip_records:` names (drives/monitors.py). No click, no rich.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Protocol

from profidrive_cli import UsageError
from profidrive_cli.drives import drive_class
from profidrive_cli.drives.base import Drive, DriveError, ParamError, ParamValue
from profidrive_cli.drives.profile import Profile
from profidrive_cli.session.cycle import MeteredChannel, Sample
from profidrive_cli.session.cyclelog import Extra
from profidrive_cli.drives.monitors import cyclic_monitors, monitor_config, trip_record_config

NO_TRIP_RECORDS = "this card keeps no trip records"


class MonitorHost(Protocol):
    """What the monitors read of their station (session.DriveStation, or a stand-in)."""
    profile: Profile | None
    layout: str | None
    drive: Drive | None
    channel: MeteredChannel | None
    t0: float

    def settle(self, *, log_extra: Extra | None = None) -> None: ...

    @property
    def motion(self) -> "_AfterStop": ...
    @property
    def params(self) -> "_ReadWrite": ...
    def need_drive(self) -> Drive: ...
    def say(self, text: str) -> None: ...


class _AfterStop(Protocol):
    @property
    def after_stop(self) -> list[Callable[[bool], object]]: ...


class _ReadWrite(Protocol):
    """The station's Parameters (the one write path: plan, then execute)."""
    def read(self, code: str) -> ParamValue: ...
    def write(self, code: str, value: str | float | int, *, check_running: bool = True,
              allow_dangerous: bool = False) -> ParamValue: ...


def monitor_codes(profile: Profile, layout: str, spec: str) -> list[str]:
    """'default' or 'CODE[,CODE...]' (default may appear among codes) -> the profile's codes, in order.
    Needs only the profile, so it runs before the bus is touched. Raises UsageError (exit 2) for a
    code the profile does not have, a layout without a parameter channel, or no default set."""
    words = monitor_config(profile).words
    lay = profile.layouts.get(layout)
    pkw = lay is None or lay.pkw
    carried = cyclic_monitors(profile, layout) if lay is not None else {}

    def cyclic(c: str) -> bool:
        p = profile.param(c)
        return c in words or (p is not None and p.code in carried)

    codes: list[str] = []
    for part in (p.strip() for p in spec.split(",")):
        if not part:
            continue
        if part.lower() == "default":
            d = monitor_config(profile).default
            if not d:
                raise UsageError(f"--monitor default: profile {profile.name} has no default monitor set")
            # without a parameter channel the default set keeps what the cyclic words carry
            codes.extend(c for c in d if pkw or cyclic(c))
        else:
            codes.append(part)
    here = f" (its input words carry {', '.join(carried)})" if carried else ""
    if not codes:
        raise UsageError("--monitor: give monitor codes (CODE[,CODE...]) or 'default'" if pkw else
                         f"--monitor: layout {layout} of {profile.name} has no parameter channel to read "
                         f"monitors through (choose a layout with one){here}")
    if not pkw:
        bad = [c for c in codes if not cyclic(c)]
        if bad:
            raise UsageError(f"--monitor {bad[0]}: layout {layout} of {profile.name} has no parameter "
                             f"channel to read monitors through and no input word carries it (choose a "
                             f"layout with one){here}")
    out: list[str] = []
    for c in codes:
        if c in words:
            if c not in out:
                out.append(c)
            continue
        p = profile.param(c)
        if p is None:
            from profidrive_cli.session.paramtypes import suggest_codes
            near = suggest_codes(profile, c)
            raise UsageError(f"--monitor {c}: {profile.name} has no parameter {c}"
                             + (f" (closest: {', '.join(near)})" if near else ""))
        if p.code not in out:
            out.append(p.code)
    return out


def setup_monitors(sess: MonitorHost, spec: str) -> "Monitors":
    """--monitor SPEC for a session whose profile and layout are known (before it connects): the
    checked Monitors, its columns added to the --log CSV."""
    assert sess.profile is not None and sess.layout is not None       # identified
    mons = Monitors(sess, monitor_codes(sess.profile, sess.layout, spec))
    sess.settle(log_extra=(mons.columns(), mons.row))
    return mons


@dataclass
class MonitorValue:
    code: str
    name: str
    value: float | int | None = None
    unit: str = ""
    raw: int | None = None
    t: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"value": self.value, "unit": self.unit, "raw": self.raw,
                "t": round(self.t, 3) if self.t is not None else None}


@dataclass
class Monitors:
    """Round-robin reader of `codes` through `sess.params.read`."""
    #: the DriveStation (or a stand-in with its attributes; its profile and drive are set by then)
    sess: MonitorHost
    codes: list[str]
    values: dict[str, MonitorValue] = field(default_factory=dict)
    dropped: dict[str, str] = field(default_factory=dict)
    #: code -> input PZD index (0-based, STW = 0) of the monitors carried in the cyclic words
    cyclic: dict[str, int] = field(default_factory=dict)
    #: parameter code -> the input word carrying it (the profile's monitors.cyclic on this layout)
    carried: dict[str, str] = field(default_factory=dict)
    #: (assignment code, old value) to write back on restore()
    saved_map: list[tuple[str, int]] = field(default_factory=list)
    _i: int = 0

    def __post_init__(self) -> None:
        assert self.sess.profile is not None and self.sess.layout is not None      # identified
        self.profile: Profile = self.sess.profile
        self.layout: str = self.sess.layout
        self.words = monitor_config(self.profile).words
        for c in self.codes:
            w = self.words.get(c)
            if w is not None:
                self.values[c] = MonitorValue(c, w.name, unit=w.unit)
                continue
            p = self.profile.param(c)
            assert p is not None                        # monitor_codes() checked it
            self.values[c] = MonitorValue(c, p.name, unit=p.unit or "")

    @property
    def active(self) -> list[str]:
        return [c for c in self.codes if c not in self.dropped]

    def question_note(self) -> str:
        """What the confirmation before a real-port run adds: the mapping map_cyclic() will write."""
        lay = self.profile.layouts.get(self.layout)
        if drive_class(self.profile).monitor_mapping == "map" and lay is not None and lay.pkw \
                and lay.input_len > 12:
            return " (--monitor maps PNU 916 for the session and restores it after)"
        return ""

    # -- the cyclic words ---------------------------------------------------------------------
    def map_cyclic(self) -> list[str]:
        """Put the monitors into the layout's cyclic input words where the card allows (see the
        module's text). Returns the codes now carried cyclically. Call before the motor starts."""
        sess = self.sess
        drive = sess.need_drive()
        for c, word in cyclic_monitors(self.profile, self.layout).items():
            if c in self.codes:                          # a parameter the input words carry anyway
                self.carried[c] = word
                self.cyclic[c] = -1
        in_words = drive.input_words()
        for c in self.codes:                             # the family's own input words
            w = self.words.get(c)
            if w is None:
                continue
            if w.word in in_words:
                self.cyclic[c] = -1
            else:
                self.dropped[c] = f"layout {sess.layout} has no '{w.word}' input word"
                sess.say(f"--monitor {c}: {self.dropped[c]}; not monitored")
        pzd_in = drive.pzd_input_count()
        if pzd_in <= 2 or not drive.has_param_channel:
            return list(self.cyclic)
        slots = list(range(1, pzd_in - 1))                # PNU 916 subindex n = input word PZD(n+2)
        if drive.monitor_mapping == "read":
            for n in slots:
                assigned = int(sess.params.read(drive.pzd_assignment_param(n)).raw)
                code = drive.pzd_assigned_code(assigned)
                if code in self.codes and code not in self.cyclic:
                    self.cyclic[code] = 1 + n
        elif drive.monitor_mapping == "map":
            free = list(slots)
            for c in self.codes:
                p = self.profile.param(c)
                if not free or p is None or p.pnu is None or p.size != 16 or c in self.cyclic:
                    continue
                n = free.pop(0)
                key = drive.pzd_assignment_param(n)
                old = int(sess.params.read(key).raw)
                try:
                    sess.params.write(key, p.pnu)
                except ParamError as e:
                    sess.say(f"--monitor {c}: not mapped into PZD{n + 2} ({e}); read through the PKW")
                    continue
                if not self.saved_map:
                    sess.motion.after_stop.append(self.restore)
                self.saved_map.append((key, old))
                self.cyclic[c] = 1 + n
        return list(self.cyclic)

    def restore(self, link_ok: bool = True) -> list[str]:
        """Write the PZD assignment back as it was (DriveStation.after_stop calls it after the safe
        stop, on every exit); what could not be restored is said and returned, one line each."""
        if not link_ok:
            failed = [f"{k} not restored to {old} (link lost)" for k, old in self.saved_map]
            self.saved_map.clear()
            for f in failed:
                self.sess.say(f"--monitor: {f}")
            return failed
        failed = []
        while self.saved_map:
            key, old = self.saved_map.pop()
            try:
                self.sess.params.write(key, old)
            except Exception as e:            # noqa: BLE001  (the link may be gone: say what is left)
                failed.append(f"{key} not restored to {old} ({e})")
        for f in failed:
            self.sess.say(f"--monitor: {f}")
        return failed

    def _read_cyclic(self, sample: Sample | None = None) -> None:
        drive = self.sess.need_drive()
        pzd = drive.last_pzd()
        t = self._now()
        for c, i in self.cyclic.items():
            if c in self.carried:
                raw = sample.status.raw.get(self.carried[c]) if sample is not None else None
                if raw is not None:
                    pv = drive.param_from_word(c, raw)
                    mv = self.values[c]
                    mv.value, mv.raw, mv.t = pv.value, pv.raw, t
                continue
            w = self.words.get(c)
            if w is not None:
                raw = sample.status.raw.get(w.word) if sample is not None else None
                if raw is not None:
                    v = raw - 0x10000 if w.signed and raw & 0x8000 else raw
                    mv = self.values[c]
                    mv.value, mv.raw, mv.t = round(v * w.scale, 6), raw, t
                continue
            if pzd is None or i >= len(pzd):
                continue
            pv = drive.param_from_word(c, pzd[i])
            mv = self.values[c]
            mv.value, mv.raw, mv.t = pv.value, pv.raw, t

    def _now(self) -> float:
        """Seconds on the session's clock (connected by now)."""
        assert self.sess.channel is not None
        return self.sess.channel.now() - self.sess.t0

    def poll(self, sample: Sample | None = None) -> MonitorValue | None:
        """Take the cyclic monitors from the last exchange (`sample`: the last Sample, for the
        family's own input words), then read the next other monitor through the parameter channel
        (a few Data_Exchanges); None when none is left. A refused read drops the code (reason in
        .dropped, told once through the session's message hook)."""
        self._read_cyclic(sample)
        act = [c for c in self.active if c not in self.cyclic]
        if not act:
            return None
        code = act[self._i % len(act)]
        self._i += 1
        try:
            pv = self.sess.params.read(code)
        except ParamError as e:              # the drive refused it: it has no such monitor
            self.dropped[code] = str(e)
            self.sess.say(f"--monitor {code}: {e}; not monitored")
            return None
        except DriveError as e:              # no answer in time: keep the last value, try again later
            self.sess.say(f"--monitor {code}: {e}")
            return None
        mv = self.values[code]
        mv.value, mv.raw, mv.t = pv.value, pv.raw, self._now()
        if pv.unit:
            mv.unit = pv.unit
        return mv

    def to_dict(self) -> dict[str, Any]:
        return {c: {**self.values[c].to_dict(), "via": "cyclic" if c in self.cyclic else "parameter channel"}
                for c in self.active}

    def columns(self) -> list[str]:
        """CSV column names: the native code with its unit ('d002 [A]')."""
        return [f"{c} [{self.values[c].unit}]" if self.values[c].unit else c for c in self.codes]

    def row(self) -> list[str]:
        return ["" if self.values[c].value is None else f"{self.values[c].value:g}" for c in self.codes]


@dataclass
class TripRecord:
    position: str
    fields: list[dict[str, Any]]            # {code, name, value, unit, raw}

    def to_dict(self) -> dict[str, Any]:
        return {"position": self.position, "fields": self.fields}


@dataclass
class TripRecords:
    supported: bool
    records: list[TripRecord] = field(default_factory=list)
    latest: int | None = None
    note: str = ""

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"supported": self.supported, "records": [r.to_dict() for r in self.records]}
        if self.latest is not None:
            d["latest"] = self.latest
        if self.note:
            d["note"] = self.note
        return d


def trip_records(sess: MonitorHost) -> TripRecords:
    """The card's trip records as the profile's `trip_records:` describes them; empty records are
    left out (a first field of 0, or a refused first read, as the section's `empty:` says)."""
    assert sess.profile is not None                                  # identified
    cfg = trip_record_config(sess.profile)
    if cfg is None:
        return TripRecords(False, note=NO_TRIP_RECORDS)
    drive = sess.need_drive()
    if not drive.has_param_channel:
        return TripRecords(True, note=f"layout {sess.layout} has no parameter channel: trip records "
                                      f"not readable")
    out = TripRecords(True)
    if cfg.latest:
        out.latest = int(sess.params.read(cfg.latest).raw) - cfg.latest_first + 1
    for spec in cfg.records:
        fields = []
        for j, code in enumerate(spec.fields):
            try:
                pv = sess.params.read(code)
            except ParamError:
                if j == 0 and cfg.empty == "error":
                    return out               # the first empty recording: no older ones
                raise
            fields.append({"code": pv.code, "name": pv.name, "value": pv.value, "unit": pv.unit,
                           "raw": pv.raw})
            if j == 0 and cfg.empty == "zero" and pv.raw == 0:
                break
        if cfg.empty == "zero" and fields and fields[0]["raw"] == 0:
            continue
        out.records.append(TripRecord(spec.position, fields))
    return out


__all__ = ["monitor_codes", "Monitors", "MonitorValue", "trip_records", "TripRecords", "TripRecord",
           "NO_TRIP_RECORDS", "DriveError"]
