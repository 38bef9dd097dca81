"""Simulated Fuji FRENIC inverter with an OPC-G1-PDP or OPC-PDP3 card (generic PROFIdrive model + dialect).

    make_model(profile, bus_control=True, o30=None, address=0, baud_code=0, pkw_latency=0,
               defaults=None, card_version=100) -> FujiModel

Dialect on top of sim/profidrive_model.py:
  * run commands from the bus only with CTW bit 10 = 1 and y98 = 2 or 3; the reference only with bit 10
    and y98 = 1 or 3 (bus_control=True seeds y98 = 3, the manual's quick-start setting; the factory
    value 0 leaves the bus without control). STW bit 9 (R/L) shows y98 != 0, whatever bit 10 says
    (manual step 1: CTW 0 answers STW 0x0240).
  * S4 is reached only with CTW bits 4, 5 and 6 = 1 as well (the manual: otherwise no running state)
  * direction = sign of MRV XOR CTW bit 11; STW bit 8 FAR, bit 10 FDT (|f| >= E31)
  * ramps F07 (accel), F08 (decel, also the o27 forced stop), H56 (OFF3); each 0 -> F03
  * PKW errors: 0 unknown code, 1 read-only or PNU927 = 0 (writes only; reads stay allowed), 2 range,
    3 subindex (also PNU947 read without the array request), 4 not an array, 11 stop-only while
    running, 104 busy (while a y97 save runs, or `busy_next` writes for tests), 17 unsupported ID
  * PNU947[1, 9, 17, 25] = the four latest alarms (PROFIdrive codes), M16-M19 = the same as alarm codes
  * monitors M07 torque, M09 frequency, M11 current, M12 voltage follow the motor (sim/motor.py)
  * o30: by default the model accepts any PPO and sets o30 to match; o30=N (or strict_o30) accepts
    only the PPO that o30 selects (a mismatch is the ERR LED: Chk_Cfg refused)
  * communication loss (DP watchdog, after at least one data exchange) per o27/o28 for a drive in
    operation: coast or F08 ramp, at once or after o28, forgotten when the link returns within o28
    where o27 says so, then Er5; none with y98 = 0 (OPC-PDP3 manual L3783-3789) or with H81 != 0
    (er5 a light alarm, manual L6557-6559: which bit is er5's is not in the card manuals, so any);
    loss_lag_s (tests) makes a delayed reaction late
  * OPC-PDP3: y97 (0 EEPROM, 1 RAM, 2 save -> reads 1 when done, 1 s here), o32 all-zero output data
  * y97 and the EEPROM (PDP3 manual 000_59efe766ba1d441f.txt L4325-4333, *6): `eeprom` holds what
    survives `power_cycle()`. A PKW write with y97 = 0 (or on the G1, which has no y97) is stored there
    too; with y97 = 1 it stays in RAM; y97 = 2 copies all RAM data into it and then reads 1. For a write
    of y97 itself the value written decides (a sim choice: the manual does not say).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

from profidrive_cli.drives import fuji as fj
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.profidrive import Ctw, State
from profidrive_cli.sim.motor import Motor, store
from profidrive_cli.sim.profidrive_model import ProfidriveModel

if TYPE_CHECKING:
    from profidrive_cli.drives.fuji.config import FujiConfig
    from profidrive_cli.drives.profile import Alarm, ParamDef, Profile

SAVE_SECONDS = 1.0


class FujiModel(ProfidriveModel):
    family = "fuji"

    def __init__(self, profile: Profile, *, bus_control: bool = True, o30: int | None = None,
                 strict_o30: bool | None = None, card_version: int = 100,
                 **kw: Any):                # ProfidriveModel's keyword arguments
        self.fc: FujiConfig = fj.fuji_config(profile)
        defaults: dict[str, float] = {}
        if bus_control:
            defaults["y98"] = 3
        if o30 is not None:
            defaults[self.fc.ppo_param] = int(o30)
        if profile.param("W90") is not None:
            defaults["W90"] = card_version
        defaults.update(kw.pop("defaults", None) or {})
        super().__init__(profile, defaults=defaults, **kw)
        #: PNU927: 0 = PKW writes refused (error 1) except to PNU927 itself; reads stay allowed
        self.write_permission = int(defaults.get("PNU927", 1))
        self.strict_o30 = (o30 is not None) if strict_o30 is None else bool(strict_o30)
        #: most recent first: (PNU947 code, alarm code) of the last four alarms (current one included)
        self.alarm_log: list[tuple[int, str]] = []
        self._trip_code: str | None = None
        self._now = 0.0
        self.busy_next = 0              # tests: answer the next N writes with error 104
        self._save_until: float | None = None
        self.had_exchange = False
        self.link_up = False
        self.comm_lost_at: float | None = None
        self._loss_action: fj.CommLossAction | None = None
        self._forced_stop = False       # o27 ramp stop in progress: ignore the bus, trip when stopped
        self.last_ctw_in = 0
        #: tests: a card that reacts this much later than o28 says (o27 = 1, 2, 11, 12)
        self.loss_lag_s = 0.0
        m = self.profile.param("M16")
        self._m_pnu = m.pnu if m is not None else None
        self.motor = Motor()
        #: the non-volatile copy of the parameters (power_cycle restores it)
        self.eeprom: dict[str, int] = dict(self.values)

    # -- configuration (o30) ---------------------------------------------------------------------
    def check_cfg(self, cfg: bytes) -> bool:
        want = fj.ppo_for_o30(self.profile, self.values.get(self.fc.ppo_param, 0))
        for name, allowed in self.cfgs.items():
            if bytes(cfg) != allowed:
                continue
            if self.strict_o30 and name != want:
                return False              # ERR LED blinking: the PPO set by o30 differs
            ok = super().check_cfg(cfg)
            if ok and not self.strict_o30:
                v = fj.o30_for_layout(self.profile, name)
                if v is not None and fj.ppo_for_o30(self.profile, self.values[self.fc.ppo_param]) != name:
                    self.values[self.fc.ppo_param] = v
            return ok
        return False

    # -- command source --------------------------------------------------------------------------
    def _y98(self) -> int:
        return self.values.get("y98", 0)

    def commands_from_bus(self, ctw: int) -> bool:
        return bool(ctw & Ctw.CONTROL_BY_PLC) and self._y98() in (2, 3) and not self._forced_stop

    def reference_from_bus(self, ctw: int) -> bool:
        return bool(ctw & Ctw.CONTROL_BY_PLC) and self._y98() in (1, 3) and not self._forced_stop

    def effective_control_word(self, ctw: int) -> int | None:
        if self._forced_stop:
            return None
        if self.commands_from_bus(ctw):
            return ctw
        if ctw & Ctw.CONTROL_BY_PLC and self.state in (State.S3, State.S4, State.S5):
            return self.ctw_eff & ~int(Ctw.ON | Ctw.FAULT_ACK)   # run from elsewhere: ramp stop
        return None                                               # bit 10 = 0: CTW ignored

    def reference_sign(self, ctw: int) -> int:
        return -1 if ctw >> 11 & 1 else 1

    def _transition(self, ctw: int, prev: int, now: float) -> None:
        run = int(pd.RUN_BITS & ~Ctw.ENABLE_OPERATION)      # bits 4, 5, 6
        if self.state in (State.S2, State.S3) and (ctw & run) != run:
            ctw &= ~int(Ctw.ENABLE_OPERATION)                # no S4 without bits 4-6
        super()._transition(ctw, prev, now)

    def status_word(self) -> int:
        w = super().status_word() & ~int(pd.Stw.CONTROL_REQUESTED | pd.Stw.WARNING)
        if self._y98() != 0:
            w |= pd.Stw.CONTROL_REQUESTED            # R/L: the bus is a command source
        return w

    def at_setpoint(self) -> bool:
        return self.state is State.S4 and abs(self.freq - self._target_hz()) < 1e-6 \
            and self.freq != 0.0

    def arrival_reached(self) -> bool:
        p = self.profile.param("E31")
        level = float(self.param_value("E31")) if p is not None else 0.0
        return level > 0 and abs(self.freq) >= level - 1e-9

    # -- alarms ----------------------------------------------------------------------------------
    def _alarm(self, alarm: int | str) -> Alarm:
        """'OC1', 'oc1', '1' / 'M1' (alarm code), '0x2301' (PNU947 code, first candidate)."""
        text = str(alarm).strip()
        a = self.profile.alarm_by_code(text)
        if a is not None:
            return a
        t = text.upper()
        if t.startswith("0X"):
            cands = self.profile.alarms_for(int(t, 16))
            if cands:
                return cands[0]
        elif t.lstrip("M").isdigit():
            by_m: Alarm | None = fj.alarm_by_mcode(self.profile, int(t.lstrip("M")))
            if by_m is not None:
                return by_m
        known = ", ".join(x.code for x in self.profile.alarms[:12])
        raise ValueError(f"unknown alarm '{alarm}' for {self.profile.name} (e.g. {known}, ...)")

    def alarm_number(self, alarm: int | str) -> int:
        if isinstance(alarm, int):
            return alarm
        return self._alarm(alarm).number

    def trip(self, alarm: int | str, now: float = 0.0) -> None:
        a = self._alarm(alarm) if not isinstance(alarm, int) else None
        self._trip_code = a.code if a is not None else None
        super().trip(a.number if a is not None else alarm, now)

    def on_trip(self, number: int, now: float) -> None:
        code = self._trip_code
        if code is None:
            cands = self.profile.alarms_for(number)
            code = cands[0].code if cands else f"0x{number:04X}"
        self.alarm_log.insert(0, (number, code))
        del self.alarm_log[len(self.fc.history):]
        self._trip_code = None
        self._forced_stop = False
        self._loss_action = None
        self.comm_lost_at = None

    def seed_faults(self, alarms: Iterable[int | str]) -> None:
        items = [self._alarm(a) for a in alarms]
        self.alarm_log = [(a.number, a.code) for a in items] + self.alarm_log
        del self.alarm_log[len(self.fc.history):]

    def fault_memory_value(self, subindex: int) -> int:
        for i, (_, ind, _) in enumerate(self.fc.history):
            if ind == subindex:
                return self.alarm_log[i][0] if i < len(self.alarm_log) else 0
        return 0

    def _mcode_value(self, position: int) -> int:
        if position >= len(self.alarm_log):
            return 0
        return fj.mcode_of(self.profile, self.alarm_log[position][1]) or 0

    def _read_special_mcode(self, pnu: int, sub: int) -> int | None:
        if pnu == self._m_pnu:
            for i, (_, _, mparam) in enumerate(self.fc.history):
                p = self.profile.param(mparam) if mparam else None
                if p is not None and p.index == sub:
                    return self._mcode_value(i)
            return None
        return super().read_special(pnu, sub)

    # -- PCD1-4 (PPO2 / PPO4): function codes assigned by o40-o43 / o48-o51 = PNU915/916 ----------
    def _assign_code(self, direction: str, slot: int) -> str:
        first = 40 if direction == "setpoint" else 48
        return f"o{first + slot - 1}"

    def _assigned_param(self, word: int) -> ParamDef | None:
        code = fj.pcd_assignment_code(self.profile, word)
        return self.profile.param(code) if code else None

    def read_special(self, pnu: int, sub: int) -> int | None:
        if pnu == pd.PNU_EDIT_RIGHTS:
            return self.write_permission
        if pnu in self.cfg.pzd_map:
            if not 1 <= sub <= 4:
                return None
            direction = "setpoint" if pnu == self.cfg.pzd_map[0] else "actual"
            return self.values.get(self._assign_code(direction, sub), 0)
        return self._read_special_mcode(pnu, sub)

    def write_special(self, pnu: int, sub: int, raw: int) -> str | None:
        if pnu == pd.PNU_EDIT_RIGHTS:
            if raw not in (0, 1):
                return "out_of_range"
            self.write_permission = raw
            return ""
        if pnu in self.cfg.pzd_map:
            direction = "setpoint" if pnu == self.cfg.pzd_map[0] else "actual"
            self.values[self._assign_code(direction, sub)] = raw & 0xFFFF
            return ""
        return super().write_special(pnu, sub, raw)

    def _pzd_write(self, words: list[int]) -> None:
        seen = set()
        for slot, w in enumerate(words[:4], start=1):
            p = self._assigned_param(self.values.get(self._assign_code("setpoint", slot), 0))
            if p is None or p.code in seen or not p.writable or (p.access == "stop" and self.running):
                continue          # the lowest-numbered o-code wins a code assigned twice
            seen.add(p.code)
            if self.value_allowed(p, self.value_from_wire(p, w)):
                self.values[p.code] = w & 0xFFFF

    def _pzd_read(self, n: int) -> list[int]:
        out = []
        for slot in range(1, n + 1):
            word = self.values.get(self._assign_code("actual", slot), 0)
            p = self._assigned_param(word)
            v = 0
            if p is not None:
                # (every parameter of the shipped Fuji profiles has both: one without reads the store)
                special = (self._read_special_mcode(p.pnu, p.index)
                           if p.pnu is not None and p.index is not None else None)
                v = special if special is not None else self.values.get(p.code, 0)
            out.append(v & 0xFFFF)
        return out

    # -- PKW dialect -----------------------------------------------------------------------------
    def pkw_answer(self, req: pd.PkwFrame) -> pd.PkwFrame:
        write = req.ak in (2, 7)
        err = self.cfg.error_numbers
        if write and not self.write_permission and req.pnu != pd.PNU_EDIT_RIGHTS:
            return pd.PkwFrame(7, req.pnu, req.subindex, err["no_rights"])
        if write and (self.busy_next > 0 or self._saving()):
            if self.busy_next > 0:
                self.busy_next -= 1
            return pd.PkwFrame(7, req.pnu, req.subindex, self.fc.busy_error)
        before = dict(self.values) if write else {}
        resp = super().pkw_answer(req)       # generic edit_rights stays 1: PNU927 blocks writes only
        if write and resp.ak in (1, 4) and self.fc.storage is not None:
            sp = self.profile.param(self.fc.storage["param"])
            if sp is not None and (req.pnu, req.subindex) == (sp.pnu, sp.index):
                if req.value == self.fc.storage["save"]:
                    self._save_until = self._now + SAVE_SECONDS
                    self.saves += 1
                else:
                    self._save_until = None
        if write and resp.ak in (1, 4) and self._stores_writes():
            self.eeprom.update({k: v for k, v in self.values.items() if before.get(k) != v})
        return resp

    def _stores_writes(self) -> bool:
        """A PKW write goes to the EEPROM too: G1 always, PDP3 with y97 = 0 (EEPROM)."""
        s = self.fc.storage
        return s is None or self.values.get(s["param"], s["eeprom"]) == s["eeprom"]

    def power_cycle(self) -> None:
        """Tests: switch the inverter off and on: the parameters are what the EEPROM holds."""
        self.values = dict(self.eeprom)
        self._save_until = None

    def _saving(self) -> bool:
        return self._save_until is not None and self._now < self._save_until

    def tick(self, now: float) -> None:
        due = self._loss_due()
        if due is not None and due < now:
            self._tick_to(due)          # a delayed reaction starts when o28 ends, not at the next tick
        self._tick_to(now)

    def next_due(self, now: float) -> float | None:
        """Moving: every tick (the ramp, the motor, the o27 ramp stop); at standstill the end of a
        y97 save and of the o28 delay of a communication loss, nothing else."""
        if self.moving() or self._forced_stop:
            return now
        due = self._save_until
        if self._loss_action is not None:
            loss = self._loss_due()
            if loss is None:
                return now
            loss -= 1e-6                # _comm_loss_tick allows 1e-9: never a tick too late
            due = loss if due is None or loss < due else due
        return due

    def _loss_due(self) -> float | None:
        act = self._loss_action
        if act is None or not act.delayed or self.comm_lost_at is None or self._forced_stop:
            return None
        return self.comm_lost_at + float(self.param_value(self.fc.comm_loss_timer)) + self.loss_lag_s

    def _tick_to(self, now: float) -> None:
        self._now = now
        if self._save_until is not None and now >= self._save_until and self.fc.storage is not None:
            # "if the value has returned to 1, data saving is complete" (PDP3 manual L4331-4333)
            self.values[self.fc.storage["param"]] = self.fc.storage["saved_reads"]
            self.eeprom = dict(self.values)
            self._save_until = None
        super().tick(now)
        self._comm_loss_tick(now)
        self._monitors(now)

    def _monitors(self, now: float) -> None:
        """M07 torque, M09 frequency, M11 current (% of rated), M12 voltage from the motor."""
        m = self.motor
        m.update(now, self.freq, self.state in (State.S4, State.S5))
        fmax = self.max_frequency()
        for code, v in (("M07", m.torque_pct(fmax)), ("M09", abs(self.freq)),
                        ("M11", 100.0 * m.current_a(fmax) / m.rated_a), ("M12", m.voltage_v(fmax))):
            store(self, code, v)

    # -- cyclic ----------------------------------------------------------------------------------
    def data_exchange(self, outputs: bytes, now: float) -> bytes:
        self._now = now
        self.had_exchange = True
        self.link_up = True
        if self._loss_action is not None and self._loss_action.recover and self.comm_lost_at is not None \
                and not self._forced_stop:
            self._loss_action, self.comm_lost_at = None, None          # link back within o28
        if self.fc.zero_data is not None and not any(outputs):
            self._all_zero(now)
        out = super().data_exchange(outputs, now)
        self.last_ctw_in = self.ctw_in
        return out

    def _all_zero(self, now: float) -> None:
        """OPC-PDP3 o32: all-zero output data (values >= 3 act like 0)."""
        assert self.fc.zero_data is not None            # data_exchange calls this only then
        mode = self.values.get(self.fc.zero_data.get("param", "o32"), 0)
        if mode == 1 or (mode == 2 and self.last_ctw_in & Ctw.CONTROL_BY_PLC):
            if self.state not in (State.FAULT, State.S1):
                self.freq = 0.0
                self.state, self.stop_mode = State.S1, None

    # -- communication loss ----------------------------------------------------------------------
    def on_leave_data_exchange(self, now: float, reason: str) -> None:
        self._pkw_req, self._pkw_resp, self._pkw_wait = None, pd.IDLE, 0
        self.link_up = False
        if reason != "watchdog" or not self.had_exchange:
            return          # Er5 needs a break after at least one good exchange
        if self.state not in (State.S4, State.S5):
            return          # see decisions: the sim applies o27 to a drive in operation only
        if self._y98() == 0 or self.values.get("H81", 0):
            return          # no er5 with y98 = 0; er5 a light alarm (H81, see decisions): keep running
        o27 = self.values.get(self.fc.comm_loss_param, 0)
        act = fj.comm_loss_action(self.profile, o27)
        if act.stop == "none":
            return
        self.comm_lost_at = now
        self._loss_action = act
        if not act.delayed:
            self._react(now)

    def _react(self, now: float) -> None:
        act = self._loss_action
        if act is None:
            return
        if act.stop == "coast":
            self.trip(self.fc.comm_loss_alarm, now)
        else:
            self._forced_stop = True
            if self.state is State.S4:
                self.state, self.stop_mode = State.S5, "off1"

    def _comm_loss_tick(self, now: float) -> None:
        act = self._loss_action
        if act is None:
            return
        if self._forced_stop:
            if self.freq == 0.0:
                self.trip(self.fc.comm_loss_alarm, now)
            return
        if act.delayed and self.comm_lost_at is not None:
            delay = float(self.param_value(self.fc.comm_loss_timer)) + self.loss_lag_s
            if now - self.comm_lost_at >= delay - 1e-9:
                if act.recover and self.link_up:
                    self._loss_action, self.comm_lost_at = None, None
                else:
                    self.comm_lost_at = None
                    self._react(now)


def make_model(profile: Profile, **options: Any) -> FujiModel:     # (the sim:// URL's options)
    if "address" in options:
        options["node_address"] = int(options.pop("address"))
    for k in ("o30", "card_version", "baud_code", "node_address", "pkw_latency"):
        if k in options and options[k] is not None:
            options[k] = int(options[k])
    return FujiModel(profile, **options)
