"""A generic simulated PROFIdrive V2 drive behind Data_Exchange, seeded from a profile.

What it does (sans-IO, every method takes `now`):
  * the PROFIdrive state machine S1..S5 + fault, driven by the control word (bit-table transitions:
    S1 -> S2 needs ON = 0 with no OFF2/OFF3; S2 -> S3 -> S4 may happen in one telegram; OFF1 ramps
    down to S2, OFF3 ramps down on the quick ramp to S1, OFF2 and "disable operation" coast;
    a 0 -> 1 edge on bit 7 acknowledges a fault -> S1)
  * a linear ramp (acceleration / deceleration / quick-stop times from the profile's
    `profidrive.ramps` parameters, each the time from 0 to the max frequency)
  * a parameter store seeded with the profile's defaults (then the `defaults` argument), holding
    raw wire integers; PZD3.. mapped through PNU 915/916 when PNU 928 = 1
  * a PKW server answering with the card's own error numbers (`profidrive.pkw.error_numbers`): unknown
    PNU, read-only, out of range, wrong subindex, not an array, stop-only while running, no edit
    rights (PNU 927 = 0, answered with AK 8), request ID not supported. A task is executed once; the
    response is repeated while the same request words stay in the output (the master sends AK 0 to
    end a task); `pkw_latency` cycles of AK 0 before each answer simulate a slow card.
  * fault injection: trip(alarm, now) -> fault bit, coast, fault-memory entry (PNU 947);
    seed_faults([...]) pre-fills the acknowledged history (first = most recent)
  * communication loss in on_leave_data_exchange per comm_loss_action()

Hooks for dialects (override in sim/<family>.py; all have generic defaults):
  commands_from_bus(ctw) -> bool          does this control word command the drive? (bit 10)
  reference_from_bus(ctw) -> bool         is the main reference taken from the bus? (bit 10)
  effective_control_word(ctw) -> int|None the word the state machine acts on; None = keep the previous
                                          one (generic: None when commands_from_bus is false)
  reference_sign(ctw) -> int              +1 / -1 applied to the N2 reference (e.g. a reverse bit)
  status_extra_bits(ctw) -> int           bits 11..15 of the status word (e.g. mirrors)
  at_setpoint() -> bool                   status bit 8 (generic: in S4 and at the ramp target)
  arrival_reached() -> bool               status bit 10 (generic: False)
  ramp_times() -> (accel_s, decel_s, quick_s)
  max_frequency() -> float                Hz = 100 % (the profile's max_frequency parameter)
  jog_frequency() -> float | None         the jog-1 reference (cfg.jog_reference), None = no jog
  comm_loss_action() -> (action, alarm)   action: "continue" | "ramp" | "coast" | "trip"
  value_from_wire(param, raw) / wire_from_value(param, value)   raw <-> engineering value
  value_allowed(param, value) -> bool     range check for PKW / PZD writes
  read_special(pnu, sub) -> int | None    PNUs without a ParamDef (9xx); None = not special
  write_special(pnu, sub, raw) -> str | None   "" = done, an error role = refused, None = not special
  fault_memory_value(subindex) -> int     PNU 947 element
  alarm_number(alarm) -> int              "E05" / "5" / 5 -> fault number (ValueError if unknown)
  on_trip(number, now) / on_acknowledge(number, now)   side effects (trip records, counters)
  _transition(ctw, prev, now)             one state-machine step on an effective control word;
                                          override to add card rules and call super()
  pkw_answer(req) -> PkwFrame             one PKW task (override to pre-empt, call super())
  status_word() / actual_word()           the two input words (override to mask or add bits)
Useful state: state, freq (Hz), ref_pct, ctw_in, ctw_eff, fault, history, values (raw store),
fault_cause_active (True keeps the fault through an acknowledgement), pkw_log, status_text().
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING

from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.profidrive import Ctw, PkwFrame, State, Stw
from profidrive_cli.sim.model import DriveModel
from profidrive_cli.sim.pkw_server import WRITE_ACK, PkwServer  # noqa: F401  (WRITE_ACK: re-exported)

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import ParamDef, Profile

STATE_BITS = {
    State.S1: Stw.SWITCHING_ON_INHIBITED,
    State.S2: Stw.READY_TO_SWITCH_ON,
    State.S3: Stw.READY_TO_SWITCH_ON | Stw.READY_TO_OPERATE,
    State.S4: Stw.READY_TO_SWITCH_ON | Stw.READY_TO_OPERATE | Stw.OPERATION_ENABLED,
    State.S5: Stw.READY_TO_SWITCH_ON | Stw.READY_TO_OPERATE,
    State.FAULT: Stw.FAULT,
}


SPECIAL_READ_ONLY = (pd.PNU_NODE_ADDRESS, pd.PNU_BAUD, pd.PNU_DEVICE_ID, pd.PNU_PROFILE,
                     pd.PNU_CONTROL_WORD, pd.PNU_STATUS_WORD, pd.PNU_FAULT_NUMBER)


class ProfidriveModel(PkwServer, DriveModel):
    family = "profidrive"
    #: how the family calls its faults in messages ("alarm", "protection") and extra hint text
    alarm_noun = "alarm"
    alarm_hint = ""
    profile: Profile

    def __init__(self, profile: Profile, *, cfg: pd.ProfidriveConfig | None = None,
                 defaults: Mapping[str, float] | None = None, pkw_latency: int = 0, name: str | None = None,
                 node_address: int = 0, baud_code: int = 0, device_id: int = 0,
                 profile_version: int = 2, pzd_map_len: int = 8):
        cfgs = {}
        for lname, lay in profile.layouts.items():
            try:
                pd.ppo_layout(profile, lname)
            except Exception:
                continue
            cfgs[lname] = lay.cfg
        super().__init__(profile.ident, cfgs, name=name or profile.title)
        self.family = profile.name
        self.default_layout = profile.default_layout
        self.profile = profile
        self.cfg = cfg or pd.config(profile)
        self.pkw_latency = pkw_latency
        self.node_address = node_address
        self.baud_code = baud_code
        self._pinned = {k for k, v in (("address", node_address), ("baud", baud_code)) if v}
        self.device_id = device_id
        self.profile_version = profile_version
        # parameter store: code -> raw wire integer
        self.values: dict[str, int] = {}
        for p in profile.parameters.values():
            v = p.default
            if v is None:
                v = p.min if (p.min is not None and p.min > 0) else 0
                if p.max is not None and v > p.max:
                    v = p.max
            self.values[p.code] = self.wire_from_value(p, v)
        for code, v in (defaults or {}).items():
            dp = profile.param(str(code))
            if dp is None:
                raise ValueError(f"{profile.name}: default for unknown parameter {code}")
            self.values[dp.code] = self.wire_from_value(dp, v)
        self.pzd_setpoint_map = [0] * pzd_map_len
        self.pzd_actual_map = [0] * pzd_map_len
        self.edit_rights = 1
        self.control_rights = 1
        self.saves = 0
        self._save_armed = False
        # drive state
        self.state = State.S1
        self.freq = 0.0                 # output frequency, Hz, signed
        self.ref_pct = 0.0              # reference from the bus, % of max frequency, signed
        self.stop_mode: str | None = None   # in S5: "off1" or "off3"
        self.ctw_in = 0                 # last control word received
        self.ctw_eff = 0                # last control word acted upon
        self.stw = int(STATE_BITS[State.S1])
        self.fault = 0                  # current (unacknowledged) fault number
        self.history: list[int] = []    # acknowledged faults, most recent first
        self.fault_cause_active = False  # True: acknowledging does not clear the fault
        self.last_trip: tuple[int, float] | None = None
        self._last_tick: float | None = None
        self._frozen_target: float | None = None
        # PKW server
        self._pkw_req: tuple[int, ...] | None = None
        self._pkw_resp: PkwFrame = pd.IDLE
        self._pkw_wait = 0
        self.pkw_log: list[tuple[PkwFrame, PkwFrame]] = []

    # =========================================================================================
    # hooks
    # =========================================================================================
    def commands_from_bus(self, ctw: int) -> bool:
        return bool(ctw & Ctw.CONTROL_BY_PLC) and bool(self.control_rights)

    def reference_from_bus(self, ctw: int) -> bool:
        return bool(ctw & Ctw.CONTROL_BY_PLC) and bool(self.control_rights)

    def effective_control_word(self, ctw: int) -> int | None:
        return ctw if self.commands_from_bus(ctw) else None

    def reference_sign(self, ctw: int) -> int:
        return 1

    def status_extra_bits(self, ctw: int) -> int:
        return 0

    def at_setpoint(self) -> bool:
        return self.state is State.S4 and abs(self.freq - self._target_hz()) < 1e-6

    def arrival_reached(self) -> bool:
        return False

    def param_value(self, code: str) -> float:
        p = self.profile.param(code)
        return self.value_from_wire(p, self.values[p.code])  # type: ignore[union-attr, arg-type]  # (config codes)

    def ramp_times(self) -> tuple[float, float, float]:
        def t(role: str, default: float) -> float:
            code = self.cfg.ramps.get(role)
            if code is None:
                return default
            v = float(self.param_value(code))
            return v if v > 0 else default
        acc = t("accel", 5.0)
        dec = t("decel", acc)
        return acc, dec, t("quick_decel", dec)

    def max_frequency(self) -> float:
        code = self.profile.max_frequency_param
        if code:
            v = float(self.param_value(code))
            if v > 0:
                return v
        return float(self.profile.max_frequency_default)

    def jog_frequency(self) -> float | None:
        if self.cfg.jog_reference is None:
            return None
        return float(self.param_value(self.cfg.jog_reference))

    def comm_loss_action(self) -> tuple[str, str | None]:
        return ("ramp", None)

    def value_from_wire(self, p: ParamDef, raw: int) -> float:
        if p.size == 16:
            raw &= 0xFFFF
        return p.from_raw(raw)

    def wire_from_value(self, p: ParamDef, value: float) -> int:
        raw = p.to_raw(value)
        return raw & ((1 << p.size) - 1)

    def value_allowed(self, p: ParamDef, value: float) -> bool:
        return p.check_range(value) is None

    def read_special(self, pnu: int, sub: int) -> int | None:
        c = self.cfg
        if pnu in c.pzd_map:
            m = self.pzd_setpoint_map if pnu == c.pzd_map[0] else self.pzd_actual_map
            return m[sub - 1]
        if pnu == c.fault_memory_pnu:
            return self.fault_memory_value(sub)
        return {pd.PNU_NODE_ADDRESS: self.node_address, pd.PNU_EDIT_RIGHTS: self.edit_rights,
                pd.PNU_CONTROL_RIGHTS: self.control_rights, pd.PNU_BAUD: self.baud_code,
                pd.PNU_DEVICE_ID: self.device_id, pd.PNU_PROFILE: self.profile_version,
                pd.PNU_CONTROL_WORD: self.ctw_in, pd.PNU_STATUS_WORD: self.stw,
                }.get(pnu, 0 if pnu == c.save_pnu else None)

    def write_special(self, pnu: int, sub: int, raw: int) -> str | None:
        c = self.cfg
        if pnu in c.pzd_map:
            q = pd.param_for(self.profile, raw) if raw else None
            if raw and (q is None or q.size != 16):
                return "out_of_range"
            m = self.pzd_setpoint_map if pnu == c.pzd_map[0] else self.pzd_actual_map
            m[sub - 1] = raw
            return ""
        if pnu in (pd.PNU_EDIT_RIGHTS, pd.PNU_CONTROL_RIGHTS):
            if raw not in (0, 1):
                return "out_of_range"
            if pnu == pd.PNU_EDIT_RIGHTS:
                self.edit_rights = raw
            else:
                self.control_rights = raw
            return ""
        if pnu == c.save_pnu and c.save_pnu is not None:
            if raw not in (0, 1):
                return "out_of_range"
            if self.running:
                return "stop_only"
            if raw == 1 and self._save_armed:
                self.saves += 1
            self._save_armed = raw == 0
            return ""
        if pnu in SPECIAL_READ_ONLY:
            return "read_only"
        return None

    def fault_memory_value(self, subindex: int) -> int:
        subs = self.cfg.fault_subindexes
        if subindex not in subs:
            return 0
        i = subs.index(subindex)
        if i == 0:
            return self.fault
        return self.history[i - 1] if i - 1 < len(self.history) else 0

    def alarm_number(self, alarm: int | str) -> int:
        if isinstance(alarm, int):
            return alarm
        text = str(alarm).strip()
        if text.isdigit():
            return int(text)
        a = self.profile.alarm_by_code(text)
        if a is None:
            known = ", ".join(x.code for x in self.profile.alarms[:12])
            raise ValueError(f"unknown {self.alarm_noun} '{alarm}' for {self.profile.name} "
                             f"(e.g. {known}{self.alarm_hint})")
        return a.number

    def on_trip(self, number: int, now: float) -> None:
        pass

    def on_acknowledge(self, number: int, now: float) -> None:
        pass

    # =========================================================================================
    # state
    # =========================================================================================
    @property
    def running(self) -> bool:
        return self.state in (State.S4, State.S5) or abs(self.freq) > 1e-9

    def status_text(self) -> str:
        s = f"{self.state.value}, {self.freq:.2f} Hz"
        if self.state is State.FAULT:
            names = "/".join(a.code for a in self.profile.alarms_for(self.fault)) or str(self.fault)
            s += f", fault {names}"
        return s

    def _ppo(self) -> pd.PpoLayout:
        return pd.ppo_layout(self.profile, self.layout)

    def _target_hz(self) -> float:
        ctw = self.ctw_eff
        fmax = self.max_frequency()
        if ctw & Ctw.JOG1:
            jog = self.jog_frequency()
            if jog is not None:
                return jog * self.reference_sign(ctw)      # Moeller: bit 11 reverses the jog too
        if not ctw & Ctw.ENABLE_RFG:
            return 0.0
        if not ctw & Ctw.UNFREEZE_RFG:
            return self.freq if self._frozen_target is None else self._frozen_target
        if not ctw & Ctw.ENABLE_SETPOINT:
            return 0.0
        hz = self.ref_pct * fmax / 100.0
        return max(-fmax, min(fmax, hz))

    def moving(self) -> bool:
        """Whether a tick changes the drive: stopping (S5), ramping in operation (the output not at
        its target yet), an output frequency left outside operation, or the motor (sim/motor.py)
        not yet settled on the output (its acceleration of the last tick). Otherwise -- standstill,
        or in operation at a steady speed -- ticks change nothing but the time of the last one."""
        st = self.state
        if st is State.S5:
            return True
        if st is State.S4:
            if not self.ctw_eff & Ctw.ENABLE_RFG and not self.ctw_eff & Ctw.JOG1:
                if self.freq != 0.0:
                    return True
            elif self.freq != self._target_hz():
                return True
        elif self.freq != 0.0:
            return True
        m = getattr(self, "motor", None)
        return m is not None and (m.freq != self.freq or m.accel != 0.0
                                  or m.on != (st is State.S4 or self.freq != 0.0))

    def next_due(self, now: float) -> float | None:
        """At every tick of the bus while moving (the ramp, the motor), as before; nothing of its own
        at standstill or at a steady speed (sim/bus.py then ticks it only when addressed)."""
        return now if self.moving() else None

    def tick(self, now: float) -> None:
        last, self._last_tick = self._last_tick, now
        if last is None or now <= last:
            return
        dt = now - last
        fmax = self.max_frequency()
        acc, dec, quick = self.ramp_times()
        if self.state is State.S4:
            if not self.ctw_eff & Ctw.ENABLE_RFG and not self.ctw_eff & Ctw.JOG1:
                self.freq = 0.0                  # ramp generator output forced to 0
                return
            tgt = self._target_hz()
            up = (self.freq >= 0 and tgt > self.freq) or (self.freq <= 0 and tgt < self.freq)
            self.freq = _ramp(self.freq, tgt, (fmax / acc if up else fmax / dec) * dt)
        elif self.state is State.S5:
            t = quick if self.stop_mode == "off3" else dec
            self.freq = _ramp(self.freq, 0.0, fmax / t * dt)
            if self.freq == 0.0:
                self.state = State.S1 if self.stop_mode == "off3" else State.S2
                self.stop_mode = None
        else:
            self.freq = 0.0

    def _transition(self, ctw: int, prev: int, now: float) -> None:
        edge = bool(ctw & Ctw.FAULT_ACK) and not prev & Ctw.FAULT_ACK
        st = self.state
        if st is State.FAULT:
            if edge and not self.fault_cause_active:
                self._acknowledge(now)
            return
        if not ctw & Ctw.NO_OFF2:                  # coast, pulses off
            self.freq = 0.0
            self.state, self.stop_mode = State.S1, None
            return
        if not ctw & Ctw.NO_OFF3:                  # quick stop
            if st in (State.S4, State.S5) and self.freq != 0.0:
                self.state, self.stop_mode = State.S5, "off3"
            elif st is not State.S5:
                self.state, self.stop_mode = State.S1, None
            return
        on = bool(ctw & Ctw.ON)
        enop = bool(ctw & Ctw.ENABLE_OPERATION)
        if st is State.S1:
            if not on:
                self.state = State.S2
            return
        if st is State.S5:
            if self.stop_mode == "off1" and on and enop:
                self.state, self.stop_mode = State.S4, None          # back to operation
            elif not enop:
                self.freq = 0.0
                self.state, self.stop_mode = (State.S3 if on else State.S2), None
            return
        if st is State.S2 and on:
            st = self.state = State.S3
        if st is State.S3:
            if not on:
                self.state = State.S2
                return
            if enop:
                st = self.state = State.S4
                self._frozen_target = None
        if st is State.S4:
            if not on:
                if self.freq != 0.0:
                    self.state, self.stop_mode = State.S5, "off1"
                else:
                    self.state = State.S2
            elif not enop:
                self.freq = 0.0                   # operation disabled: coast
                self.state = State.S3
            elif not ctw & Ctw.ENABLE_RFG and not ctw & Ctw.JOG1:
                self.freq = 0.0                   # ramp-generator output forced to 0 at once
            elif not ctw & Ctw.UNFREEZE_RFG and prev & Ctw.UNFREEZE_RFG:
                self._frozen_target = self.freq
            elif ctw & Ctw.UNFREEZE_RFG:
                self._frozen_target = None

    # -- steering (sim/control.py) -------------------------------------------------------------
    def clear_fault(self, now: float) -> None:
        if self.fault:
            self._acknowledge(now)

    def set_value(self, code: str, value: float) -> None:
        from profidrive_cli.drives.values import profile_value_problem
        p = self.profile.param(code)
        if p is None:
            raise ValueError(f"{code} is not a parameter of {self.profile.name}")
        why = profile_value_problem(self.profile, p, value)
        if why is not None:
            raise ValueError(why)
        self.values[p.code] = self.wire_from_value(p, value)

    def snapshot(self) -> dict[str, object]:
        names = "/".join(a.code for a in self.profile.alarms_for(self.fault)) if self.fault else None
        return {**super().snapshot(), "state": self.state.name, "hz": round(self.freq, 3),
                "fault": (names or str(self.fault)) if self.fault else None}

    def _acknowledge(self, now: float) -> None:
        num = self.fault
        if num:
            self.history.insert(0, num)
            del self.history[max(0, len(self.cfg.fault_subindexes) - 1):]
        self.fault = 0
        self.state, self.stop_mode = State.S1, None
        self.on_acknowledge(num, now)

    def apply_control(self, ctw: int, ref_word: int, now: float) -> None:
        self.ctw_in = ctw
        if self.reference_from_bus(ctw):
            self.ref_pct = pd.n2_to_percent(ref_word) * self.reference_sign(ctw)
        eff = self.effective_control_word(ctw)
        if eff is None:
            return
        prev, self.ctw_eff = self.ctw_eff, eff
        self._transition(eff, prev, now)

    def status_word(self) -> int:
        w = int(STATE_BITS[self.state])
        if self.ctw_eff & Ctw.NO_OFF2:
            w |= Stw.NO_OFF2
        if self.ctw_eff & Ctw.NO_OFF3:
            w |= Stw.NO_OFF3
        if self.state is not State.FAULT and self.at_setpoint():
            w |= Stw.AT_SETPOINT
        if self.commands_from_bus(self.ctw_in) or self.reference_from_bus(self.ctw_in):
            w |= Stw.CONTROL_REQUESTED
        if self.arrival_reached():
            w |= Stw.F_REACHED
        w |= self.status_extra_bits(self.ctw_in) & 0xF800
        return w & 0xFFFF

    def actual_word(self) -> int:
        return pd.n2_from_hz(self.freq, self.max_frequency())

    # =========================================================================================
    # Data_Exchange
    # =========================================================================================
    def data_exchange(self, outputs: bytes, now: float) -> bytes:
        lay = self._ppo()
        area = pd.decode_area_bytes(lay, outputs, "request")
        self.tick(now)
        resp = self._pkw_serve(area.pkw, now) if area.pkw is not None else None   # (None: no PKW in lay)
        self.apply_control(area.word1, area.word2, now)
        self._pzd_write(area.pzd[2:])
        self.stw = self.status_word()
        pzd = [self.stw, self.actual_word()] + self._pzd_read(lay.pzd_in - 2)
        return pd.encode_area(lay, pd.PpoArea(resp, pzd), "response")

    def _pzd_write(self, words: list[int]) -> None:
        if not self.control_rights:
            return
        for pnu, w in zip(self.pzd_setpoint_map, words):
            if not pnu:
                continue
            p = pd.param_for(self.profile, pnu)
            if p is None or not p.writable or (p.access == "stop" and self.running):
                continue          # stop-only parameters wait until the motor is stopped
            if self.value_allowed(p, self.value_from_wire(p, w)):
                self.values[p.code] = w

    def _pzd_read(self, n: int) -> list[int]:
        out = []
        for pnu in self.pzd_actual_map[:n]:
            v = 0
            if pnu:
                p = pd.param_for(self.profile, pnu)
                if p is not None:
                    v = self.values.get(p.code, 0) & 0xFFFF
            out.append(v)
        return out + [0] * (n - len(out))

    def on_bus(self, address: int, baud: int) -> None:
        """PNU 918 = the station address, PNU 963 = the card's own code for the rate (unless given)."""
        if "address" not in self._pinned:
            self.node_address = address
        code = pd.baud_code_for(self.cfg.baud_codes, baud)
        if "baud" not in self._pinned and code is not None:
            self.baud_code = code

    # =========================================================================================
    # faults, communication loss
    # =========================================================================================
    def trip(self, alarm: int | str, now: float = 0.0) -> None:
        number = self.alarm_number(alarm)
        if number <= 0:
            raise ValueError(f"fault number must be > 0, got {number}")
        if self.state is State.FAULT:
            return
        self.last_trip = (number, self.freq)
        self.fault = number
        self.freq = 0.0                 # a trip switches the output off: the motor coasts
        self.state, self.stop_mode = State.FAULT, None
        self.on_trip(number, now)

    def seed_faults(self, alarms: Iterable[int | str]) -> None:
        nums = [self.alarm_number(a) for a in alarms]
        self.history = nums + self.history
        del self.history[max(0, len(self.cfg.fault_subindexes) - 1):]

    def on_leave_data_exchange(self, now: float, reason: str) -> None:
        action, alarm = self.comm_loss_action()
        was_running = self.state in (State.S4, State.S5)
        self._pkw_req, self._pkw_resp, self._pkw_wait = None, pd.IDLE, 0
        if action == "continue" or not was_running:
            return
        if action == "trip":
            assert alarm is not None, "comm_loss_action(): a trip names its alarm"
            self.trip(alarm, now)
        elif action == "coast":
            self.freq = 0.0
            self.state, self.stop_mode = State.S1, None
        else:
            if self.state is State.S4:
                self.state, self.stop_mode = State.S5, "off1"
        self.ctw_eff &= ~int(Ctw.ON)

    def clear_outputs(self, now: float) -> None:
        """Global_Control Clear: the outputs read as zero (control word 0, bit 10 = 0)."""
        self.apply_control(0, 0, now)


def _ramp(cur: float, tgt: float, step: float) -> float:
    if math.isclose(cur, tgt, abs_tol=1e-12) or abs(tgt - cur) <= step:
        return float(tgt)
    return cur + math.copysign(step, tgt - cur)
