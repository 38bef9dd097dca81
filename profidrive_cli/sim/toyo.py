"""Simulated Toyo VF66 inverter with a PBUS66-Z card (generic PROFIdrive model + the Toyo dialect).

    make_model(profile, mode=None, bus_control=True, voltage_class=None, accel_s=5.0, decel_s=5.0,
               quick_s=1.0, jog_percent=10.0, inverter_mode=0, pkw_latency=0, defaults=None) -> ToyoModel

  * mode: the J-08 setting. None (default) follows the master's Chk_Cfg (PPO1-5 -> mode 0, the Toyo
    frames -> mode 1), a simulator convenience; 0 or 1 accepts only that mode's configurations.
  * little-endian words (profile word_order); speed words 20000 = A-00, signed
  * mode 0: the PROFIdrive state machine (OFF2 > OFF3 > OFF1; bit 10 = 0 keeps the previous command;
    restart after OFF2/OFF3 or a fault acknowledge needs OFF1 first); jog 1/2 with bits 4-6 = 0;
    reverse = negative speed command
  * mode 1: run-command word (bit 0 run, 1 jog, 2 reverse, 5 protection reset on a rising edge; after a
    reset the run bit must go to 0 before the drive runs again); status/fault flag words
  * commands from the network need b-11 = 3 (or b-11 = 0 with b-09 = 2), the speed b-10 = 3 (or 0 with
    b-09 = 2); bus_control=True seeds J-00 = 4, b-10 = b-11 = b-12 = 3, C-00 = 1. Those console codes
    have no published PNU, so set them with `defaults`.
  * torque (sim choices): bus_control also seeds i-07 = 4 (speed/torque switched by multi-function
    input 2 bit 1) and i-08 = 2 (torque command from the option); torque control while running with
    i-08 = 2 and i-07 = 1..3, or i-07 = 4 with that bit on; the axis then follows sim/torque_axis.py
    (torque command 5000 = rated, limited at A-00); the torque word reports the torque produced.
    The sim does not model that i-07/i-08 cannot be set in V/f mode.
  * ramps: Toyo's acceleration/deceleration parameters have no published PNU: accel_s / decel_s /
    quick_s (0 -> A-00) stand in for them; the accel/decel set bits select 1x..4x those times.
  * PKW: tasks 1/2/6, busy = response 0 for pkw_latency cycles, errors 0/1/2/3/101/102; monitors
    677-698 computed from the drive, traceback 700-715 (four recordings of 100 samples, taken at trips),
    fault history 720 (six entries: protection code | inverter mode << 8 | block << 12)
  * multi-function input 2 bits 3-10 (external faults) trip EXT1-4 on a rising edge (C-00 = 1)
  * C-00 = 0 (the manual's factory value; bus_control seeds 1) or the PLC in use: OFF2 and OFF3 act as
    a normal stop (Table 3.5 notes 1 and 2, src L2769-2773)
  * communication loss (DP watchdog) while in operation: protection 18 (COMM), run bits forced off;
    comm_loss="ignore" (sim only, the manual names no setting) keeps it running
  * fan failure (26) is a warning: ZSW bit 7, fault flag 2 bit 9, multi-function output bit 15
  * date/time words (J-14 = 1; spec §4.5, manual L1137-1143: low byte day 1-31, high month 1-12; low
    byte minute 0-59, high hour 0-23): a valid pair is kept as `net_clock` (month, day, hour, minute);
    an invalid one (month 0, day 0, ...) is counted in `bad_clock` and not taken (the manual does not
    say what the inverter does with it)
  * Slave_Diag device block after the first trip: 09 + status flag, fault flags 1/2, multi-function
    output, high byte first
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from itertools import repeat
from typing import TYPE_CHECKING, Any

from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives import toyo as ty
from profidrive_cli.drives.profidrive import Ctw, State
from profidrive_cli.sim import torque_axis
from profidrive_cli.sim.motor import Motor
from profidrive_cli.sim.profidrive_model import ProfidriveModel, _ramp

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import Profile
    from profidrive_cli.drives.toyo.config import ToyoConfig

# protection code -> (fault flag word 1 or 2, bit)
FLAG_OF_CODE = {1: (1, 0), 2: (1, 1), 5: (1, 4), 6: (1, 5), 7: (1, 6), 8: (1, 7), 9: (1, 8), 10: (1, 9),
                11: (1, 10), 12: (1, 11), 13: (1, 12), 14: (1, 13), 15: (1, 14), 16: (1, 15)}
FLAG_OF_CODE.update({17 + i: (2, i) for i in range(16)})
COMM_TIMEOUT = 18
FAN_FAILURE = 26
EXT_FAULTS = (29, 30, 31, 32)
MONITOR_FIRST, MONITOR_LAST = 677, 698
BUS_CONTROL_DEFAULTS = {"J-00": 4, "b-10": 3, "b-11": 3, "b-12": 3, "C-00": 1, "i-07": 4, "i-08": 2}


class ToyoModel(ProfidriveModel):
    alarm_noun = "protection"
    alarm_hint = ", or 1..32"
    family = "toyo"
    #: "trip" (the manual: protection 18) or "ignore" (a sim-only stand-in for an inverter set up
    #: to ride through a lost master: the manual names no setting; make_model(comm_loss="ignore"))
    comm_loss = "trip"

    def __init__(self, profile: Profile, *, mode: int | None = None, bus_control: bool = True,
                 voltage_class: int | None = None, accel_s: float = 5.0, decel_s: float = 5.0,
                 quick_s: float = 1.0, jog_percent: float = 10.0, inverter_mode: int = 0,
                 **kw: Any):                # ProfidriveModel's keyword arguments
        self.tc: ToyoConfig = ty.toyo_config(profile)
        defaults: dict[str, float] = dict(BUS_CONTROL_DEFAULTS) if bus_control else {}
        if mode is not None:
            if mode not in (0, 1):
                raise ValueError("mode (J-08) must be 0 or 1")
            defaults["J-08"] = mode
        defaults.update(kw.pop("defaults", None) or {})
        super().__init__(profile, defaults=defaults, **kw)
        self.max_diag_len = 15
        self.fixed_mode = mode
        self.mode = mode if mode is not None else 0
        self.voltage_class = voltage_class or self.tc.voltage_class
        self.accel_s, self.decel_s, self.quick_s = float(accel_s), float(decel_s), float(quick_s)
        self.jog_percent = float(jog_percent)
        self.inverter_mode = inverter_mode & 3
        self.block = 0
        self.run_cmd = 0
        self.mf_input2 = 0
        self.torque_cmd = 0.0                          # % of rated, from the torque command word
        self.torque_out: float | None = None           # torque produced while torque controlled
        self.fan_failure = False
        self.comm_error = False
        self.net_clock: tuple[int, int, int, int] | None = None     # J-14 = 1: (month, day, hour, minute)
        self.bad_clock = 0
        self.had_exchange = False
        self.trip_log: list[int] = []                  # history words, newest first (max 6)
        self.recordings: list[list[tuple[int, ...]]] = []     # traceback recordings, newest first (max 4)
        self.samples: deque[tuple[int, ...]] = deque(maxlen=self.tc.traceback_points)
        self.first_trip_seen = False
        self._trip_code = 0
        self.motor = Motor(rated_v=200.0 if self.voltage_class == 200 else 400.0)

    # -- configuration -----------------------------------------------------------------------
    def check_cfg(self, cfg: bytes) -> bool:
        for name, allowed in self.cfgs.items():
            if bytes(cfg) != allowed:
                continue
            lmode = self.tc.layouts[name].mode
            if self.fixed_mode is not None and lmode != self.fixed_mode:
                return False        # J-08 selects the other frame family
            ok = super().check_cfg(cfg)
            if ok:
                self.mode = lmode
                self.values["J-08"] = lmode
            return ok
        return False

    def _tl(self) -> ty.ToyoLayout:
        assert self.layout is not None                  # a layout is set by Chk_Cfg before data
        return self.tc.layouts[self.layout]

    def _plch(self) -> bool:
        return self.tc.plch or self._tl().plch

    # -- sources -----------------------------------------------------------------------------
    def _v(self, code: str) -> int:
        return self.values.get(code, 0)

    def _run_from_bus(self) -> bool:
        b11 = self._v("b-11")
        return b11 == 3 or (b11 == 0 and self._v("b-09") == 2)

    def _speed_from_bus(self) -> bool:
        b10 = self._v("b-10")
        return b10 == 3 or (b10 == 0 and self._v("b-09") == 2)

    def commands_from_bus(self, ctw: int) -> bool:
        if self.mode == 1:
            return self._run_from_bus()
        return bool(ctw & Ctw.CONTROL_BY_PLC) and self._run_from_bus()

    def reference_from_bus(self, ctw: int) -> bool:
        if self.mode == 1:
            return self._speed_from_bus()
        return bool(ctw & Ctw.CONTROL_BY_PLC) and self._speed_from_bus()

    def ramp_times(self) -> tuple[float, float, float]:
        mult = 1 + ((self.run_cmd >> 9) & 0x3)          # accel/decel set 1..4
        return self.accel_s * mult, self.decel_s * mult, self.quick_s

    def at_setpoint(self) -> bool:
        return self.state is not State.FAULT            # ZSW bit 8: deviation within range

    def arrival_reached(self) -> bool:
        return self.state is State.S4 and abs(self.freq - self._target_hz()) < 1e-6

    def status_word(self) -> int:
        w = super().status_word()
        if self.fan_failure:
            w |= pd.Stw.WARNING
        return w

    def apply_control(self, ctw: int, ref_word: int, now: float) -> None:
        """As the generic model, with the Toyo speed scale (20000 = A-00)."""
        self.ctw_in = ctw
        if self.reference_from_bus(ctw):
            self.ref_pct = ty.speed_percent(self.profile, ref_word) * self.reference_sign(ctw)
        eff = self.effective_control_word(ctw)
        if eff is None:
            return
        off23 = int(Ctw.NO_OFF2 | Ctw.NO_OFF3)
        if (eff & off23) != off23 and (self._v("C-00") != 1 or self._plch()):
            eff = (eff | off23) & ~int(Ctw.ON)    # C-00 = 0 or PLC: OFF2 / OFF3 = a normal stop
        prev, self.ctw_eff = self.ctw_eff, eff
        self._transition(eff, prev, now)

    def reference_sign(self, ctw: int) -> int:
        return -1 if self.mode == 1 and self.run_cmd & 0x4 else 1

    def actual_word(self) -> int:
        return ty.speed_word(self.profile, 100.0 * self.freq / self.max_frequency())

    # -- jog (bits 4-6 = 0 with bit 8 / 9 in mode 0; run-command bit 1 in mode 1) ---------------
    def _jog_target(self) -> float | None:
        c = self.ctw_eff
        if not c & Ctw.ON or not c & Ctw.NO_OFF2 or not c & Ctw.NO_OFF3:
            return None
        if c & (Ctw.ENABLE_RFG | Ctw.UNFREEZE_RFG | Ctw.ENABLE_SETPOINT):
            return None
        if c & Ctw.JOG1:
            return self.jog_percent * self.max_frequency() / 100.0
        if c & Ctw.JOG2:
            return -self.jog_percent * self.max_frequency() / 100.0
        return None

    def _transition(self, ctw: int, prev: int, now: float) -> None:
        if (self.state is State.S3 and self.freq != 0.0 and not ctw & Ctw.ON
                and ctw & Ctw.NO_OFF2 and ctw & Ctw.NO_OFF3):
            return      # OFF1 after a jog: ramps down on the deceleration time first (tick), then S2
        super()._transition(ctw, prev, now)

    @property
    def jogging(self) -> bool:
        return self.state in (State.S3, State.S4) and (self._jog_target() is not None or
                                                       (self.state is State.S3 and self.freq != 0.0))

    def torque_controlled(self) -> bool:
        """i-08 = 2 and i-07 = 1..3, or 4 with multi-function input 2 bit 1 (spec §10, Table 3.8)."""
        if self._v("i-08") != 2:
            return False
        i07 = self._v("i-07")
        return i07 in (1, 2, 3) or (i07 == 4 and bool(self.mf_input2 & 0x2))

    def moving(self) -> bool:
        st = self.state
        if st is State.S4 and self.torque_controlled():
            return True                          # the axis (sim/torque_axis.py) settles slowly
        if st in (State.S3, State.S4):
            jog = self._jog_target()
            if jog is not None:
                if self.freq != jog:
                    return True                  # the jog ramp (tick)
            elif st is State.S3 and self.freq != 0.0:
                return True                      # the jog's ramp down
        return super().moving()

    def next_due(self, now: float) -> float | None:
        """Every tick while moving (jogging included), else nothing of its own: the traceback
        samples of the ticks in between are made up by catch_up."""
        return super().next_due(now)

    def catch_up(self, times: list[float], then: float | None = None) -> None:
        """Ticks missed at standstill: each would take a traceback sample (the last 100 make the
        next trip's recording), all the same one (nothing moves; the sample holds no time). So: the
        first tick for real, then copies of its sample, and the clocks set to the last."""
        if times and self._last_tick is None:
            self.tick(times[0])                  # a model never ticked: this one takes no sample
            times = times[1:]
        if len(times) < 3 or self.moving() or self._last_tick is None or times[0] <= self._last_tick:
            for t in times:
                self.tick(t)
            return
        self.tick(times[0])
        rest = len(times) - 1
        self.samples.extend(repeat(self.samples[-1], min(rest, self.samples.maxlen or rest)))
        t = times[-1]
        self._last_tick = t
        self.motor.update(t, self.freq, self.state in (State.S4, State.S5) or self.freq != 0.0)

    def tick(self, now: float) -> None:
        last = self._last_tick
        if self.state is State.S4 and self.torque_controlled():
            self._last_tick = now
            if last is not None and now > last:
                self.freq, self.torque_out = torque_axis.step(self.freq, self.torque_cmd,
                                                             self.max_frequency(), now - last)
                self._sample()
            return
        self.torque_out = None
        if self.state is State.S5 and self.torque_controlled():
            self.freq = 0.0              # in torque control OFF1 / OFF3 are coast stops (spec §11)
        if self.state in (State.S3, State.S4) and (self._jog_target() is not None
                                                   or (self.state is State.S3 and self.freq != 0.0)):
            self._last_tick = now
            if last is not None and now > last:
                dt = now - last
                fmax = self.max_frequency()
                acc, dec, _ = self.ramp_times()
                tgt = self._jog_target() or 0.0
                up = abs(tgt) > abs(self.freq)
                self.freq = _ramp(self.freq, tgt, fmax / (acc if up else dec) * dt)
        else:
            super().tick(now)
        self.motor.update(now, self.freq, self.state in (State.S4, State.S5) or self.freq != 0.0)
        if last is not None and now > last:
            self._sample()

    def _sample(self) -> None:
        fmax = self.max_frequency()
        fw = ty.speed_word(self.profile, 100.0 * self.freq / fmax)
        rw = ty.speed_word(self.profile, self.ref_pct)
        i = round(2357 * self.motor.current_a(fmax) / self.motor.rated_a)   # 2357 = 100 % rated
        tq = round(self.motor.torque_pct(fmax) / 0.02)                        # TB07: 0.02 %/count
        ff1, ff2 = self.fault_flags()
        self.samples.append((i, i, i, self._dc_raw(), self._vout_raw(), 0, rw, tq & 0xFFFF, fw, 0, 0, 400, ff1, ff2,
                             self.status_flag() & 0x27FF, self.run_cmd & 0xFF))

    # -- state machine inputs per mode ----------------------------------------------------------
    def data_exchange(self, outputs: bytes, now: float) -> bytes:
        self.had_exchange = True
        self.comm_error = False
        lay = self._ppo()
        tl = self._tl()
        area = pd.decode_area_bytes(lay, outputs, "request")
        self.tick(now)
        resp = self._pkw_serve(area.pkw, now) if area.pkw is not None else None   # (None: no PKW in lay)
        w = dict(zip(tl.words("request", self._plch()), area.pzd))
        if "run_cmd" in w:
            self.run_cmd = w["run_cmd"] if self.mode == 1 else (w["run_cmd"] & ~0x7)
        if "mf_input2" in w:
            self._mf_input2(w["mf_input2"], now)
        if "torque_ref" in w:
            self.torque_cmd = pd.to_signed16(w["torque_ref"]) * 100.0 / 5000
        if "month_day" in w and "hour_minute" in w and self.values.get("J-14", 0) == 1:
            self._clock(w["month_day"], w["hour_minute"])
        speed = w.get("speed_ref", 0)
        if self.mode == 0:
            self.apply_control(w.get("ctw", 0), speed, now)
        else:
            self.apply_control(self._mode1_ctw(), speed, now)
        self.stw = self.status_word()
        words = [self._input_word(n) for n in tl.words("response", self._plch())]
        return pd.encode_area(lay, pd.PpoArea(resp, words), "response")

    def _clock(self, month_day: int, hour_minute: int) -> None:
        month, day, hour, minute = month_day >> 8, month_day & 0xFF, hour_minute >> 8, hour_minute & 0xFF
        if 1 <= month <= 12 and 1 <= day <= 31 and hour <= 23 and minute <= 59:
            self.net_clock = (month, day, hour, minute)
        else:
            self.bad_clock += 1

    def _mode1_ctw(self) -> int:
        rc = self.run_cmd
        base = int(Ctw.NO_OFF2 | Ctw.NO_OFF3 | Ctw.CONTROL_BY_PLC)
        if rc & 0x20:
            base |= int(Ctw.FAULT_ACK)
        if rc & 0x1:
            return base | int(Ctw.ON | pd.RUN_BITS)
        if rc & 0x2:          # jog: switched on with the ramp bits 0 and jog 1 / 2
            return base | int(Ctw.ON) | int(Ctw.JOG2 if rc & 0x4 else Ctw.JOG1)
        return base | int(pd.RUN_BITS)           # OFF1: ramp stop (stays ready)

    def _mf_input2(self, word: int, now: float) -> None:
        prev, self.mf_input2 = self.mf_input2, word
        self.block = (word >> 12) & 1
        if self._v("C-00") != 1:
            return
        rising = word & ~prev
        for i, code in enumerate(EXT_FAULTS):
            if rising >> (3 + i) & 1 or rising >> (7 + i) & 1:
                self.trip(code, now)
                break

    # -- cyclic input words ----------------------------------------------------------------------
    def _dc_raw(self) -> int:
        # 283 V (200 V class, 10 counts/V) or 566 V (400 V class, 5 counts/V): the same count
        return 2830

    def _vout_raw(self) -> int:
        vnom = 200.0 if self.voltage_class == 200 else 400.0
        per_v = 20 if self.voltage_class == 200 else 10
        return round(vnom * min(1.0, abs(self.freq) / self.max_frequency()) * per_v)

    def fault_flags(self) -> tuple[int, int]:
        ff = [0, 0, 0]
        if self.state is State.FAULT and self._trip_code in FLAG_OF_CODE:
            wd, bit = FLAG_OF_CODE[self._trip_code]
            ff[wd] |= 1 << bit
        if self.fan_failure:
            ff[2] |= 1 << FLAG_OF_CODE[FAN_FAILURE][1]
        if self.comm_error:
            ff[2] |= 1 << FLAG_OF_CODE[COMM_TIMEOUT][1]
        return ff[1], ff[2]

    def status_flag(self) -> int:
        w = 0
        on = self.state in (State.S4, State.S5) or self.jogging
        if self.mode == 1:
            if self.run_cmd & 0x1 and self.state is State.S4:
                w |= 1 << 0
            if self.run_cmd & 0x4:
                w |= 1 << 3
        elif self.state is State.S4:
            w |= 1 << 0
            if self.ref_pct < 0:
                w |= 1 << 3
        if self.state in (State.S4, State.S5) and (self.freq != 0.0 or self.state is State.S4):
            w |= 1 << 1
        if self.jogging:
            w |= 1 << 2
        if on:
            w |= (1 << 7) | (1 << 8)
        if self.comm_error:
            w |= 1 << 10
        if self.block:
            w |= 1 << 11
        return w

    def mf_output(self) -> int:
        w = 0
        if self.state is State.S4 and abs(self.freq - self._target_hz()) < 1e-6:
            w |= 1 << 7
        if self.freq < 0:
            w |= 1 << 13
        if self.block:
            w |= 1 << 14
        if self.fan_failure:
            w |= 1 << 15
        return w

    def monitor_raw(self, pnu: int) -> int:
        fmax = self.max_frequency()
        fw = ty.speed_word(self.profile, 100.0 * self.freq / fmax)
        ff1, ff2 = self.fault_flags()
        running = self.freq != 0.0
        cur = self.motor.current_a(fmax)          # sim/motor.py: load + acceleration
        p = self.profile.param("current")
        cur_raw = round(cur / p.scale) if p is not None and p.scale else 0
        tq = self.profile.param("torque")
        tq_raw = round(self.motor.torque_pct(fmax) / tq.scale) if tq is not None and tq.scale else 0
        table = {677: 0x0066, 678: 0x0100, 679: 0x0100, 680: self.status_flag(), 681: ff1, 682: ff2,
                 683: self.mf_output(), 684: fw, 685: fw, 686: cur_raw,
                 687: (self._torque_raw() if self.torque_out is not None       # torque control
                       else max(-32768, min(32767, tq_raw))),                    # the motor model
                 688: self._dc_raw(), 689: self._vout_raw(), 690: fw, 691: 0, 692: 400,
                 693: 1024 if running else 0}
        return table.get(pnu, 0) & 0xFFFF

    def _torque_raw(self) -> int:
        if self.torque_out is not None:
            return round(self.torque_out * 50)                     # 5000 = rated torque
        return round(abs(self.freq) / self.max_frequency() * 1500)

    def _input_word(self, name: str) -> int:
        if name == "zsw":
            return self.stw
        if name in ("motor_speed", "arc_output", "output_frequency"):
            return self.actual_word()
        if name == "status_flag":
            return self.status_flag()
        if name == "fault_flag1":
            return self.fault_flags()[0]
        if name == "fault_flag2":
            return self.fault_flags()[1]
        if name == "mf_output":
            return self.mf_output()
        f = self.tc.fields.get(name)
        if f is not None and f.get("kind") == "param":
            p = self.profile.param(f["param"])
            return self.monitor_raw(p.pnu) if p is not None and p.pnu else 0
        mon = {"torque": 687, "output_voltage": 689, "ol_counter": 691, "motor_temp": 692, "motor_flux": 693}
        if name in mon:
            return self.monitor_raw(mon[name])
        return 0            # PLC registers o000xx, unused words

    # -- PKW server (Toyo tasks and errors) ------------------------------------------------------
    def pkw_answer(self, req: pd.PkwFrame) -> pd.PkwFrame:
        tc = self.tc
        ind = req.ind

        def reply(ak: int, value: int) -> pd.PkwFrame:
            return pd.PkwFrame(ak, req.pnu, req.subindex, value & 0xFFFF, ind_low=req.ind_low)

        def err(n: int) -> pd.PkwFrame:
            return reply(7, n)

        if req.ak not in (1, 2, 6):
            return err(102)
        pnu = req.pnu & ((1 << tc.block_bit) - 1)
        is_tb = tc.traceback_pnu <= pnu < tc.traceback_pnu + tc.traceback_channels
        if pnu == tc.history_pnu or is_tb:
            if req.ak != 6:
                return err(1) if req.ak == 2 else err(102)
            if pnu == tc.history_pnu:
                if ind not in tc.history_indexes:
                    return err(3)
                i = tc.history_indexes.index(ind)
                if i >= len(self.trip_log):
                    return err(tc.empty_error)
                return reply(4, self.trip_log[i])
            rec, pt = ty.decode_traceback_ind(ind)
            if ind >> 10 or pt >= tc.traceback_points:
                return err(3)
            if rec >= len(self.recordings) or pt >= len(self.recordings[rec]):
                return err(tc.empty_error)
            return reply(4, self.recordings[rec][pt][pnu - tc.traceback_pnu])
        if req.ak == 6:
            return err(102)
        if MONITOR_FIRST <= pnu <= MONITOR_LAST:
            if req.ak == 2:
                return err(1)
            return reply(1, self.monitor_raw(pnu))
        p = ty.param_at(self.profile, pnu)
        if p is None:
            return err(0)
        if req.ak == 1:
            return reply(1, self.values[p.code])
        if not p.writable:
            return err(1)
        raw = req.value & 0xFFFF
        if not self.value_allowed(p, ty.value_from_wire(self.profile, p, raw)):
            return err(2)
        if p.access == "stop" and self.running:
            return err(1)
        self.values[p.code] = raw
        return reply(1, raw)            # the value actually written

    # -- faults ------------------------------------------------------------------------------------
    def trip(self, alarm: int | str, now: float = 0.0) -> None:
        code = self.alarm_number(alarm)
        if code == FAN_FAILURE:
            self.fan_failure = True        # a warning: the inverter keeps running
            return
        self._trip_code = code
        super().trip(code, now)

    def on_trip(self, number: int, now: float) -> None:
        self.first_trip_seen = True
        self.trip_log.insert(0, ty.history_word(number, self.inverter_mode, self.block))
        del self.trip_log[len(self.tc.history_indexes):]
        self._sample()
        rec = list(self.samples)
        rec = [(0,) * 16] * (self.tc.traceback_points - len(rec)) + rec     # always 100 points
        self.recordings.insert(0, rec)
        del self.recordings[self.tc.traceback_recordings:]

    def on_acknowledge(self, number: int, now: float) -> None:
        self._trip_code = 0

    def seed_faults(self, alarms: Iterable[int | str]) -> None:
        words = [ty.history_word(self.alarm_number(a), self.inverter_mode, 0) for a in alarms]
        self.trip_log = words + self.trip_log
        del self.trip_log[len(self.tc.history_indexes):]

    def fault_memory_value(self, subindex: int) -> int:
        i = subindex - 1
        return self.trip_log[i] if 0 <= i < len(self.trip_log) else 0

    def ext_diag(self) -> bytes:
        if not self.first_trip_seen:
            return b""
        ff1, ff2 = self.fault_flags()
        words = [self.status_flag(), ff1, ff2, self.mf_output()]
        return bytes([9]) + pd.words_to_bytes(words, self.tc.diag_word_order)

    def on_leave_data_exchange(self, now: float, reason: str) -> None:
        self._pkw_req, self._pkw_resp, self._pkw_wait = None, pd.IDLE, 0
        if reason != "watchdog" or not self.had_exchange or self.comm_loss == "ignore":
            return
        self.comm_error = True
        self.run_cmd &= ~0xF                          # run, jog, reverse, initial excitation forced off
        if self.state in (State.S4, State.S5) or self.jogging:
            self.trip(COMM_TIMEOUT, now)

    def clear_outputs(self, now: float) -> None:
        if self.mode == 1:
            self.run_cmd = 0
            self.apply_control(self._mode1_ctw(), 0, now)
        else:
            self.apply_control(0, 0, now)


def make_model(profile: Profile, **options: Any) -> ToyoModel:     # (the sim:// URL's options)
    comm_loss = options.pop("comm_loss", None)
    for k in ("mode", "voltage_class", "inverter_mode", "pkw_latency"):
        if k in options and options[k] is not None:
            options[k] = int(options[k])
    if "address" in options:
        options["node_address"] = int(options.pop("address"))
    m = ToyoModel(profile, **options)
    if comm_loss is not None:
        if comm_loss not in ("trip", "ignore"):
            raise ValueError(f"toyo sim: comm_loss must be trip or ignore, got {comm_loss!r}")
        m.comm_loss = comm_loss
    return m


__all__ = ["ToyoModel", "make_model", "FLAG_OF_CODE"]
