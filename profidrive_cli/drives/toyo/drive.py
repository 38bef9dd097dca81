"""ToyoDrive: the PROFIdrive core's drive with the PBUS66-Z dialect. Mode 0 (PPO1-5) runs the core's
state machine; mode 1 (toyo, toyo_plch) the run-command word. Parameters go through the core's PKW
channel with this package's frames and scaling; faults from the history PNU; traceback reads.

May touch: drives/profidrive, drives/base, drives/values, drives/torque, and this package's config, codec,
params, describe (mode1_state).
"""

from __future__ import annotations

from datetime import datetime
from typing import TYPE_CHECKING, Any

from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.base import (CyclicChannel, DriveError, DriveStatus, FaultRecord, ParamError, ParamInfo,
                                        ParamValue, Reaction)
from profidrive_cli.drives.toyo.codec import (bit_names, decode_history_word, speed_percent, speed_word,
                                              traceback_ind)
from profidrive_cli.drives.toyo.config import toyo_config
from profidrive_cli.drives.toyo.describe import mode1_state
from profidrive_cli.drives.toyo.params import (_toyo_frame, effective_scale, frame_for, param_at,
                                               resolve_param, value_from_wire, wire_from_value)
from profidrive_cli.drives.torque import torque_counts
from profidrive_cli.drives.values import value_problem

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import ParamDef, Profile

TORQUE_RES = 100.0 / 5000          # % of rated torque per count (spec §4.2: 5000 = rated torque)
TORQUE_SELECT = 0x0002             # multi-function input 2 bit 1: speed/torque control select (Table 3.8)


def date_words(now: datetime) -> dict[str, int]:
    """The date/time words from a datetime (used by the VF66 when J-14 = 1; spec toyo-vf66-pbus66z.md
    §4.5, manual L1137-1143): month/day = month << 8 | day (low byte day 1-31, high byte month 1-12),
    hour/minute = hour << 8 | minute (low byte minute 0-59, high byte hour 0-23), binary."""
    return {"month_day": now.month << 8 | now.day, "hour_minute": now.hour << 8 | now.minute}


#: Toyo PBUS66-Z manual L612-620 (C-00 factory 0) and Table 3.5 notes 1-2 (L2769-2773)
TOYO_C00_WARNING = ("C-00 (multi-function input source) cannot be read over the bus (Toyo publishes "
                    "no PNU); with C-00 = 0, the factory setting, OFF2 and OFF3 from the bus act as "
                    "a normal stop (manual Table 3.5 notes 1 and 2): a coast or quick stop pdrive "
                    "sends takes the deceleration time; set C-00 = 1 for the full control word")


class ToyoDrive(pd.ProfidriveDrive):
    """Mode 0 (PPO1-5) runs the PROFIdrive state machine; mode 1 (toyo, toyo_plch) the run-command word."""

    family = "toyo"
    comm_loss_words = "protection 18 (COMM): the inverter trips and coasts"

    @classmethod
    def audit_rules(cls, profile: Any) -> list[Any]:
        """The family's `pdrive audit` rules (drives/toyo/audit.py), each citing its manual line."""
        from profidrive_cli.drives.toyo.audit import audit_rules
        return audit_rules(profile)

    def __init__(self, channel: CyclicChannel, profile: Profile, layout: str | None = None):
        self.tc = toyo_config(profile)
        super().__init__(channel, profile, layout)
        self.tl = self.tc.layouts[self.layout]
        self.mode = self.tl.mode
        self.plch = self.tc.plch or self.tl.plch
        self.run_cmd = 0                      # mode 1 run-command / multi-function input 1
        self.mf_input2 = 0
        self.torque_ref = 0
        self.torque_mode = False              # run --torque: torque command word + MFI 2 bit 1
        self.words_out: dict[str, int] = {}
        self.jogging = False
        self._reset_pulse = 0
        #: the host clock for the date/time words (tests replace it)
        self.clock = datetime.now
        self._dated = {"month_day", "hour_minute"} & set(self.tl.words("request", self.plch))

    def save_support(self) -> str:
        return "automatic"               # every write is stored by the card itself

    def cycle_words(self, outputs: bytes, inputs: bytes) -> tuple[int | None, int | None,
                                                                   int | None, int | None]:
        out = pd.decode_area_bytes(self.ppo, outputs, "request").pzd
        inp = pd.decode_area_bytes(self.ppo, inputs, "response").pzd
        o = dict(zip(self.tl.words("request", self.plch), out))      # the layout's named words
        n = dict(zip(self.tl.words("response", self.plch), inp))
        return (o.get("ctw", o.get("run_cmd")), o.get("speed_ref"),
                n.get("zsw", n.get("status_flag")), n.get("motor_speed"))

    comm_loss_reaction_fixed = True           # protection 18: no setting to read

    def comm_loss_reaction(self) -> Reaction | None:
        return Reaction("protection 18 (COMM, communication timeout): trip, run commands forced "
                        "off (fixed: the manual names no setting)", "trip", alarm="COMM",
                        warnings=[TOYO_C00_WARNING])

    def zero_data_reaction(self, head: str) -> Reaction | None:
        if self.layout == "toyo":
            return None
        return Reaction(head + "; control word bit 10 = 0: the card ignores the master's command and "
                        "keeps the previous cycle's (manual Table 3.5) -- the drive keeps running",
                        "none", warnings=[TOYO_C00_WARNING])

    def normal_stop_warnings(self) -> list[str]:
        return [TOYO_C00_WARNING]

    def on_device(self, p: ParamDef) -> bool:
        return p.pnu != self.tc.history_pnu      # the fault history: `pdrive faults` reads it

    def not_dumpable_why(self) -> str:
        # PBUS66-Z manual, note 1 (seed 002 L4201): "ＶＦ６６インバータの設定データ番号については別途お問い
        # 合わせください" -- the VF66 setting-data numbers are to be asked of Toyo
        return ("the PBUS66-Z manual publishes no VF66 setting-data numbers (note 1: ask Toyo for them); "
                "add `pnu:` to the profile to reach a setting")

    # -- addressing ----------------------------------------------------------------------------
    def resolve_param(self, code: str) -> pd.ParamRef:
        """See params.resolve_param: monitor names, console codes, TBnn[r,p], FH[n], PNU<n>[ind]."""
        return resolve_param(self.profile, self.tc, code)

    @classmethod
    def resolve_for(cls, profile: Any, code: str) -> pd.ParamRef:
        return resolve_param(profile, toyo_config(profile), code)

    def raw_to_value(self, ref: pd.ParamRef, raw: int) -> float | int:
        return value_from_wire(self.profile, ref.param, raw) if ref.param is not None else raw & 0xFFFF

    def check_value(self, ref: pd.ParamRef, value: float | int) -> str | None:
        if ref.param is None:
            return super().check_value(ref, value)
        return value_problem(ref.param, value, scale=effective_scale(self.profile, ref.param))

    def value_to_raw(self, ref: pd.ParamRef, value: float | int) -> int:
        return wire_from_value(self.profile, ref.param, value) if ref.param is not None else int(value) & 0xFFFF

    def _read(self, ref: pd.ParamRef) -> ParamValue:
        res = self.request(frame_for(ref))
        if not res.ok:
            raise ParamError(f"{ref.label}: the card refused the read: {res.describe_error()}", res.error)
        return self._param_value(ref, res.value)

    def param_info(self, code: str) -> ParamInfo:
        info = super().param_info(code)
        if isinstance(info.ref, pd.ParamRef) and info.ref.array:
            info.access = "ro"                       # traceback / fault history frames: read only
        return info

    def _write(self, ref: pd.ParamRef, value: float | int) -> ParamValue:
        p = ref.param
        if ref.array:                                # traceback / fault history frames: read only
            raise ParamError(f"{ref.label} is read-only", 1)
        raw = self.value_to_raw(ref, value)
        res = self.request(frame_for(ref, write=True, value=raw))
        if not res.ok:
            if res.error == 1 and p is not None and p.access == "stop":
                raise ParamError(f"{ref.label}: refused (error 1, write-protected); it can only be changed "
                                 f"while the inverter is stopped", 1)
            raise ParamError(f"{ref.label}: the card refused the value {value}: {res.describe_error()}",
                             res.error)
        # the answer carries the value actually written (the card writes to EEPROM)
        return self._param_value(ref, res.value)

    def read_raw(self, pnu: int, subindex: int = 0, array: bool | None = None) -> int:
        if array is None:
            array = pnu in self.cfg.array_pnus
        res = self.request(_toyo_frame(6 if array else 1, pnu, subindex if array else 0))
        if not res.ok:
            raise ParamError(f"PNU {pnu}" + (f"[{subindex}]" if array else "") + f": {res.describe_error()}",
                             res.error)
        return res.value & 0xFFFF

    def save(self) -> None:
        raise DriveError("PBUS66-Z: every parameter write goes straight to the inverter's EEPROM "
                         "(limited write cycles); there is no separate save")

    def max_frequency(self) -> float:
        if self._fmax is None:
            p = self.profile.param(self.profile.max_frequency_param or "")
            if p is not None and p.pnu is not None and self.pkw is not None:
                self._fmax = float(self.read_param(p.code).value)
            else:
                self._fmax = float(self.profile.max_frequency_default)
        return self._fmax

    # -- faults --------------------------------------------------------------------------------
    def fault_history(self) -> list[FaultRecord]:
        """PNU 720, IND 1 (newest) .. 6; stops at the first empty slot (error 101)."""
        out = []
        for i, ind in enumerate(self.tc.history_indexes):
            res = self.request(_toyo_frame(6, self.tc.history_pnu, ind))
            if not res.ok:
                if res.error == self.tc.empty_error:
                    break
                raise ParamError(f"fault history PNU {self.tc.history_pnu}[{ind}]: {res.describe_error()}",
                                 res.error)
            h = decode_history_word(self.profile, res.value & 0xFFFF)
            pos = "newest" if i == 0 else f"{i} back"
            out.append(FaultRecord(pos, h["code"], [h["name"]],
                                   [f"{h['meaning']} (inverter mode {h['mode_text']}, setting block {h['block']})"]))
        return out

    def status(self) -> DriveStatus:
        st = self.cycle()
        if st.fault and self.pkw is not None:
            try:
                res = self.request(_toyo_frame(6, self.tc.history_pnu, self.tc.history_indexes[0]))
                if res.ok:
                    st.fault_code = decode_history_word(self.profile, res.value & 0xFFFF)["name"]
            except DriveError:
                pass
        return st

    # -- one cycle -----------------------------------------------------------------------------
    def _out_words(self, ctw: int) -> list[int]:
        names = self.tl.words("request", self.plch)
        vals = {"ctw": ctw, "speed_ref": self.reference, "torque_ref": self.torque_ref,
                "run_cmd": self.run_cmd | (0x20 if self._reset_pulse else 0), "mf_input2": self.mf_input2}
        if self._dated:
            vals.update(date_words(self.clock()))
        vals.update(self.words_out)
        return [vals.get(n, 0) & 0xFFFF for n in names]

    def cycle(self) -> DriveStatus:
        ctw = self._control_word() if self.mode == 0 else 0
        area = self._exchange_area(self._out_words(ctw))
        if self._reset_pulse:
            self._reset_pulse -= 1
        self.last_ctw = ctw
        if self.mode == 0:
            self.last_stw = area.word1
        st = self._decode_status(area)
        self.last_status = st
        return st

    def _control_word(self) -> int:
        if self.target is None:
            return 0
        stw = self.last_stw if self.last_stw is not None else int(pd.Stw.SWITCHING_ON_INHIBITED)
        moving = None
        if self.last_area is not None and len(self.last_area.pzd) > 1:
            moving = pd.to_signed16(self.last_area.pzd[1]) != 0
        extra = self.control_extra_bits()
        target = self.target
        if self.jogging and target is pd.Target.OPERATE:
            target = pd.Target.SWITCHED_ON       # jog: ON with bits 4-6 = 0 and bit 8 / 9
        return pd.next_control_word(stw, target, extra, previous=self.last_ctw, moving=moving)

    def _decode_status(self, area: pd.PpoArea) -> DriveStatus:
        names = self.tl.words("response", self.plch)
        w = dict(zip(names, area.pzd))
        fmax = self._fmax if self._fmax is not None else float(self.profile.max_frequency_default)
        raw = {n: v for n, v in w.items() if n != "unused"}
        flags: dict[str, bool] = {}
        sf = w.get("status_flag")
        ff1, ff2 = w.get("fault_flag1", 0), w.get("fault_flag2", 0)
        if sf is not None:
            for b, t in self.tc.bits["status_flag"].items():
                flags[t] = bool(sf >> b & 1)
        fan = self._fan_bit()
        fault_flags = bool(ff1) or bool(ff2 & ~fan)
        for table, word in (("fault_flag1", ff1), ("fault_flag2", ff2)):
            if word:
                for b, t in self.tc.bits[table].items():
                    if word >> b & 1:
                        flags[f"fault: {t}"] = True
        speed = w.get("motor_speed")
        pct = speed_percent(self.profile, speed) if speed is not None else None
        ref_pct = speed_percent(self.profile, self.reference)
        state: pd.State | str
        if self.mode == 0:
            zsw = w["zsw"]
            raw["status_word"] = zsw
            moving = pct is not None and abs(pct) > 0
            state = pd.state_from_status(zsw, moving)
            if self.jogging and state is pd.State.S5:
                state = pd.State.S3             # jog runs in the switched-on state (bits 4-6 = 0)
            flags["jogging"] = self.jogging
            for b, t in self.tc.bits["zsw"].items():
                flags[t] = bool(zsw >> b & 1)
            running = state in (pd.State.S4, pd.State.S5) or bool(moving)
            st = DriveStatus(state=state.value, running=running, fault=state is pd.State.FAULT,
                             flags=flags, speed_percent=None if pct is None else round(pct, 4),
                             speed_hz=None if pct is None else round(pct * fmax / 100.0, 4),
                             reference_percent=round(ref_pct, 4), raw=raw)
        else:
            sf = sf or 0
            running = bool(sf & 0x2) or bool(sf & 0x4) or (pct is not None and pct != 0)
            if fault_flags:
                state = "fault"
            elif sf & 0x4:
                state = "jog"
            elif sf & 0x1:
                state = "running"
            elif running:
                state = "stopping"
            else:
                state = "stopped"
            if self.run_cmd & 4 and ref_pct > 0:
                ref_pct = -ref_pct
            st = DriveStatus(state=state, running=running, fault=fault_flags, flags=flags,
                             speed_percent=None if pct is None else round(pct, 4),
                             speed_hz=None if pct is None else round(pct * fmax / 100.0, 4),
                             reference_percent=round(ref_pct, 4), raw=raw)
        if st.fault and (ff1 or ff2):
            st.fault_code = self._flag_fault_code(ff1, ff2)
        if "torque" in w:
            st.torque_percent = round(pd.to_signed16(w["torque"]) * TORQUE_RES, 4)
        if self.torque_mode:
            st.torque_ref_percent = round(pd.to_signed16(self.torque_ref) * TORQUE_RES, 4)
        return st

    def _fan_bit(self) -> int:
        for b, t in self.tc.bits.get("fault_flag2", {}).items():
            if t.startswith("fan"):
                return 1 << b
        return 0

    def _flag_fault_code(self, ff1: int, ff2: int) -> str | None:
        names = bit_names(self.profile, "fault_flag1", ff1) + [
            n for n in bit_names(self.profile, "fault_flag2", ff2) if not n.startswith("fan")]
        return ", ".join(names) or None

    # -- motion --------------------------------------------------------------------------------
    def set_speed(self, percent: float) -> None:
        if self.mode == 1:
            # mode 1: the direction is run-command bit 2 with a positive speed command
            self.reference = speed_word(self.profile, abs(percent))
            self.run_cmd = (self.run_cmd | 0x4) if percent < 0 else (self.run_cmd & ~0x4)
        else:
            self.reference = speed_word(self.profile, percent)    # mode 0: negative = reverse
        self.cycle()

    def start(self, timeout: float = 5.0) -> DriveStatus:
        self._notify_motion()
        if self.mode == 0:
            self.jogging = False
            self.extra_bits &= ~int(pd.Ctw.JOG1 | pd.Ctw.JOG2)
            return super().start(timeout)
        st = self.cycle()
        if st.fault:
            raise DriveError("the drive is in fault: reset it first")
        self.run_cmd = (self.run_cmd | 0x1) & ~0x2
        try:
            return self.cycles_until(lambda s: s.flags.get(self.tc.bits["status_flag"][0], False)
                                     and s.flags.get(self.tc.bits["status_flag"][1], False), timeout,
                                     "the run command to be taken (status flag bits 0 and 1)")
        except DriveError as e:
            raise DriveError(f"{e}; {self.start_hint(self.last_status)}") from None

    def stop(self, mode: str = "normal", wait: bool = True, timeout: float = 30.0) -> DriveStatus:
        if self.torque_mode:
            # in torque control OFF1/OFF3 are coast stops (spec §11): back to speed control first,
            # so the stop ramps
            self.set_torque(None)
        if self.mode == 0:
            self.jogging = False
            self.extra_bits &= ~int(pd.Ctw.JOG1 | pd.Ctw.JOG2)
            return super().stop(mode, wait, timeout)
        if mode not in ("normal", "ramp", "off1"):
            cap = {"quick": "quick_stop", "off3": "quick_stop"}.get(mode, "coast_stop")
            # the words of the profile's capabilities (the same refusal as checklist validate)
            raise DriveError(self.profile.capabilities.refusal(cap, self.layout)
                             or "mode 1 (Toyo original frame) has only the run bit: use a normal stop")
        self.run_cmd &= ~0x3
        st = self.cycle()
        if not wait:
            return st
        return self.cycles_until(lambda s: s.fault or s.stopped, timeout, "the drive to stop")

    @property
    def supports_jog(self) -> bool:        # type: ignore[override]
        return not self.plch

    def jog_refusal(self) -> str:
        return self._no_jog_words(self.profile)

    @staticmethod
    def _no_jog_words(profile: Any) -> str:
        return (f"{profile.name}: with the built-in PLC in use (PLCH) the jog bit goes to PLC contact "
                f"I00021, not to the inverter (spec 3.4); pdrive does not jog through a PLC program")

    @classmethod
    def jog_refusal_for(cls, profile: Any, layout: str) -> str | None:
        tc = toyo_config(profile)
        plch = tc.plch or tc.layouts[layout].plch
        return cls._no_jog_words(profile) if plch else None

    @classmethod
    def normalise_area(cls, profile: Any, direction: str, area: dict[str, Any]) -> dict[str, Any]:
        """The core's PPO reading; a mode 1 response (no status word) says its state by the status
        and fault flags (describe.mode1_state)."""
        return pd.ppo_drive_object(direction, area, state_without_status_word=mode1_state)

    @classmethod
    def status_flag_names(cls, profile: Any, layout: str) -> list[str]:
        """_decode_status's flags: the status-flag word's bits, a name per fault-flag bit
        ("fault: ..."), and in PROFIdrive mode "jogging" and the ZSW's bits."""
        tc = toyo_config(profile)
        tl = tc.layouts[layout]
        words = tl.words("response", tc.plch or tl.plch)
        names: list[str] = []
        if "status_flag" in words:
            names += list(tc.bits["status_flag"].values())
        for table in ("fault_flag1", "fault_flag2"):
            if table in words:
                names += [f"fault: {t}" for t in tc.bits[table].values()]
        if tl.mode == 0:
            names += ["jogging"] + list(tc.bits["zsw"].values())
        return list(dict.fromkeys(names))

    def jog_reference(self) -> str | None:
        return None        # the PBUS66-Z manual names no jog-speed parameter (set on the VF66 itself)

    def jog(self, on: bool = True, reverse: bool = False) -> None:
        """Mode 0: CTW bit 8 (forward) / 9 (reverse) with bits 4-6 = 0 from "switched on" (spec 3.1,
        3.3; manual L2725-2731, L2919). Mode 1: run-command bit 1 (jog) with bit 2 (reverse)."""
        if on:
            self._notify_motion()
        if self.mode == 1:
            self.run_cmd = (self.run_cmd | 0x2) if on else (self.run_cmd & ~0x2)
            if on:
                self.run_cmd = (self.run_cmd | 0x4) if reverse else (self.run_cmd & ~0x4)
            self.cycle()
            return
        bit = int(pd.Ctw.JOG2 if reverse else pd.Ctw.JOG1)
        if on:
            self.jogging = True
            self.extra_bits = (self.extra_bits & ~int(pd.Ctw.JOG1 | pd.Ctw.JOG2)) | bit
            self.target = pd.Target.OPERATE     # sent as SWITCHED_ON + jog bit while jogging
        else:
            self.jogging = False
            self.extra_bits &= ~int(pd.Ctw.JOG1 | pd.Ctw.JOG2)
            self.target = pd.Target.READY
        self.cycle()

    # -- torque (spec §2.4-2.10, §4.2: torque command 5000 = rated; MFI 2 bit 1 speed/torque) ---
    def torque_support(self) -> str | None:
        if "torque_ref" in self.tl.words("request", self.plch):
            return None
        return (f"toyo: layout {self.layout}{' with PLCH on' if self.plch else ''} has no torque command "
                f"word (PPO2, PPO4, PPO5 and the Toyo frame with PLCH off have one)")

    def torque_limit_support(self) -> str | None:
        return ("toyo: the PBUS66-Z has no torque limit word (the VF66 torque limits are inverter "
                "settings); use --torque for torque control")

    def torque_resolution(self) -> float:
        return TORQUE_RES

    def _switches_torque(self) -> bool:
        return "mf_input2" in self.tl.words("request", self.plch)

    def set_torque(self, percent: float | None) -> None:
        why = self.torque_support()
        if why:
            raise DriveError(why)
        if percent is None:
            self.torque_mode = False
            self.torque_ref = 0
            self.mf_input2 &= ~TORQUE_SELECT
        else:
            self.torque_mode = True
            self.torque_ref = torque_counts(percent, TORQUE_RES) & 0xFFFF
            if self._switches_torque():
                self.mf_input2 |= TORQUE_SELECT
        self.cycle()

    def torque_notes(self) -> list[str]:
        how = ("i-07 = 4 (speed/torque switched by multi-function input 2 bit 1, which pdrive sets)"
               if self._switches_torque() else
               f"i-07 = 1, 2 or 3 (layout {self.layout} has no multi-function input 2 to switch it)")
        return [f"the VF66 follows the torque command only in a vector mode with i-08 = 2 (torque from "
                f"the option) and {how}; otherwise it stays speed controlled"]

    def reset_fault(self, timeout: float = 5.0) -> DriveStatus:
        if self.mode == 0:
            return super().reset_fault(timeout)
        st = self.cycle()
        if not st.fault:
            return st
        if self.run_cmd & 0x3:
            raise DriveError("refusing to reset with the run (or jog) bit set: the motor would restart at "
                             "once; stop first")
        self._reset_pulse = 3       # protection reset: bit 5 high for a few cycles (rising edge)
        return self.cycles_until(lambda s: not s.fault and not self._reset_pulse, timeout,
                                 "the protection to clear (is its cause still present?)")

    def start_hint(self, status: DriveStatus | None) -> str:
        return ("the VF66 takes network commands with J-00 = 4, b-11 = 3 (run) and b-10 = 3 (speed) "
                "(or 0 with b-09 = 2), C-00 = 1 for the multi-function inputs, the ST-F terminal on, and "
                + ("control-word bit 10 = 1" if self.mode == 0 else "J-08 = 1 for this frame"))

    # -- traceback -----------------------------------------------------------------------------
    def read_traceback(self, channel: int, recording: int = 0, points: range | None = None) -> list[float]:
        """Samples of one traceback channel (0-15) from one recording (0 newest .. 3 oldest)."""
        p = param_at(self.profile, self.tc.traceback_pnu + channel)
        vals = []
        for pt in points or range(self.tc.traceback_points):
            res = self.request(_toyo_frame(6, self.tc.traceback_pnu + channel, traceback_ind(recording, pt)))
            if not res.ok:
                raise ParamError(f"traceback channel {channel} recording {recording} point {pt}: "
                                 f"{res.describe_error()}", res.error)
            raw = res.value & 0xFFFF
            vals.append(value_from_wire(self.profile, p, raw) if p is not None else raw)
        return vals


def make_drive(channel: CyclicChannel, profile: Profile, layout: str | None = None) -> ToyoDrive:
    toyo_config(profile)
    return ToyoDrive(channel, profile, layout)
