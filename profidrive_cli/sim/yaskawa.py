"""Simulated Yaskawa drive behind a PROFIBUS-DP option SI-P1 (spec: ../shared/spec/yaskawa-profibus-dp.md).

Written independently of drives/yaskawa.py (own bit numbers, own scaling) so that the codec's tests
against this model check the codec, not the codec against itself. It reads only the profile.

What it does:
- the three messages (basic / extended1 / extended2) with their exact Chk_Cfg octets;
- run command -> running with a ramp: acceleration E1-04 per C1-01, deceleration E1-04 per C1-02
  (C1-10 selects 0.01 s or 0.1 s), fast stop by C1-09 on a programmed multi-function input;
  b1-03 = 1 coasts, other values ramp; external base block cuts the output at once;
- b1-02 = 3 is needed for the bus run bits, b1-01 = 3 for the bus reference (otherwise d1-01);
- parameter access through the handshake byte: a request is taken only when the command HS bit
  changes; the response HS follows at once with STATUS 00, then 01, then 10 until the processing
  delay (default 12 ms, the manual says 10-15 ms) has passed, then 11 with the reply; the reply area
  keeps its old content until then;
- the manual's error replies: 01 bad function, 02 unknown register, 03 bad data quantity,
  21 out of range, 22 read-only / running (for stop-only parameters) / ENTER while running / while
  storing;
- Global_Control Clear: outputs of zero (no run command: the drive stops by b1-03), no BUS fault;
- BUS fault when the master stops talking (on_leave_data_exchange, or no Data_Exchange for
  comm_timeout s) while b1-01 or b1-02 = 3, stopping per F6-01 (0 ramp with C1-02 and BUS at 0 Hz,
  1 coast and BUS (factory), 2 fast stop with C1-09 and BUS at 0 Hz, 3 alarm only: keeps running on
  the last command; run commands are ignored during the ramp); by default only if the motor was running at that moment
  (bus_fault="running"), so that one pdrive command per process does not leave a fault behind;
  bus_fault="always" is closer to a real drive, "never" disables it; EF0 from command bit 8, trip(code), seed_faults(codes), fault reset on the rising
  edge of bit 9 (with the run bits off and the cause gone), clear error log on the rising edge of bit 14.

Simulator choices (not from the manual):
- b1-01 = b1-02 = 3 by default: the manual gives no factory value, so the sim starts as a drive
  commissioned for the bus; make_model(..., b1_01=1, b1_02=1) gives an uncommissioned one;
- parameter writes take effect at once (RAM); ENTER (profile yaskawa.enter_register) copies them to
  a "stored" set and blocks writes for 50 ms;
- fault numbers in the fault registers are the profile's alarm numbers (the manual has none);
- MF outputs 1/2/3 = during run / zero speed / frequency agree; output current 30 % of rating at
  standstill when running, rising to 80 % at max frequency, +20 % while accelerating;
  register 0x0037 (output power) in 0.1 kW from an assumed 3.7 kW motor;
- forward and reverse together: the drive stops and shows the alarm bit.
- torque (spec §2.4: bytes 4-5 torque reference / limit, 6-7 compensation, 0.1 %, flux vector only;
  manual src L594 "Torque Reference/Limit ... 0.1% Flux Vector mode only"): the option d5_01 stands
  for the drive parameter d5-01 (torque control select; the profile has no register for it),
  default 0 = speed control, the drive's factory setting (issue 34: the sim used to start in torque
  control, so `run --torque-limit 50 --hz 30` ran the motor to 60 Hz). A sim URL sets it as
  set=7:d5-01=1 (SETTINGS below, read by sim/plant.py), `sim-ctl set 7 d5-01 1` while it runs.
  With A1-02 = 3 (flux vector) and d5_01 = 0 a non-zero torque word is a torque limit: the speed
  follows the reference with the ramp and stops rising where the load of sim/torque_axis.py
  reaches the limit. With A1-02 = 3 and d5_01 = 1 a running drive is torque controlled: the axis
  follows sim/torque_axis.py under the torque word, limited at E1-04 (the frequency reference is
  not used as a speed limit). Bytes 4-5 of the input report the torque produced (0.1 %): in torque control the
  reference (or the load at the speed limit), in speed control the load of sim/torque_axis.py plus
  20 % while accelerating. In other control methods the torque words are ignored.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

from profidrive_cli.sim import torque_axis
from profidrive_cli.sim.model import DriveModel

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import Profile

# command word bits (spec §2.2)
FWD, REV, EXT_FAULT, RESET, CLEAR_LOG, BASE_BLOCK = 0, 1, 8, 9, 14, 15
MFI_BITS = {3: 2, 4: 3, 5: 4, 6: 5, 7: 6, 8: 7, 9: 10, 10: 11, 11: 12, 12: 13}
# status word bits (spec §2.3)
S_RUN, S_ZERO, S_REV, S_RESET, S_AGREE, S_READY, S_ALARM, S_FAULT, S_OPE, S_RESTART, S_REMOTE, \
    S_MFO1, S_MFO2, S_MFO3, S_MOTOR2, S_ZSERVO = range(16)

# layout -> (size, fast-I/O input word names, parameter area offset, registers per request)
LAYOUTS = {
    "basic": (6, ("status", "feedback", "current"), None, 0),
    "extended1": (32, ("status", "feedback", "torque", "pg", "fref", "fout", "current", "ain"), 16, 4),
    "extended2": (12, ("status", "feedback"), 4, 1),
}
CFGS = {"basic": b"\x72", "extended1": b"\x5f\x6f", "extended2": b"\x55\x65"}

ERR_FUNCTION, ERR_ADDRESS, ERR_QUANTITY, ERR_RANGE, ERR_WRITE = 0x01, 0x02, 0x03, 0x21, 0x22

#: the model's settings beyond the profile's parameters (code -> the values it takes), for a sim URL's
#: set= (sim/plant.py) and sim-ctl set: d5-01 torque control select, 0 speed control (factory), 1
#: torque control
SETTINGS = {"d5-01": (0, 1)}


def _s16(w: int) -> int:
    return w - 0x10000 if w & 0x8000 else w


class YaskawaModel(DriveModel):
    family = "yaskawa"

    # (the numbers may come as text, from a sim:// URL; **params: E1_04=50.0, ... in engineering units)
    def __init__(self, profile: Profile, b1_01: int | str = 3, b1_02: int | str = 3,
                 processing_ms: float | str = 12.0, comm_timeout: float | str = 1.0,
                 fast_stop_input: int | str | None = None, rated_kw: float | str = 3.7,
                 bus_fault: str = "running", d5_01: int = 0, **params: float | str) -> None:
        super().__init__(profile.ident, {k: CFGS[k] for k in profile.layouts if k in CFGS},
                         name=profile.title, user_prm_len=0, max_diag_len=6)
        self.profile = profile
        self.order = ">" if profile.word_order == "big" else "<"
        y = profile.raw.get("yaskawa", {}) or {}
        self.ref_unit = float(y.get("reference_unit_hz", 0.01))
        self.fb_unit = float(y.get("feedback_unit_hz", 0.1))
        enter = y.get("enter_register") or {}
        self.enter_register = enter.get("register") if isinstance(enter, dict) else None
        self.processing = float(processing_ms) / 1000.0
        self.comm_timeout = float(comm_timeout)
        self.fast_stop_input = int(fast_stop_input) if fast_stop_input not in (None, "", "none") else None
        self.rated_kw = float(rated_kw)
        if d5_01 not in SETTINGS["d5-01"]:
            raise ValueError(f"yaskawa sim: d5-01 must be 0 (speed control) or 1 (torque control), got {d5_01!r}")
        self.d5_01 = int(d5_01)
        if bus_fault not in ("running", "always", "never"):
            raise ValueError(f"yaskawa sim: bus_fault must be running, always or never, got {bus_fault!r}")
        self.bus_fault = bus_fault

        # parameter store: register -> raw value, from the profile's defaults
        self.defs = {p.register: p for p in profile.parameters.values() if p.register is not None}
        self.regs: dict[int, int] = {}
        for reg, p in self.defs.items():
            self.regs[reg] = p.to_raw(p.default) & 0xFFFF if p.default is not None else 0
        self._set("b1-01", int(b1_01))
        self._set("b1-02", int(b1_02))
        for key, value in params.items():       # e.g. E1_04=50.0, C1_01=2.0 (engineering units)
            code = key.replace("_", "-")
            prm = profile.param(code)
            if prm is None or prm.register is None:
                raise ValueError(f"yaskawa sim: unknown option {key!r}")
            self.regs[prm.register] = prm.to_raw(float(value)) & 0xFFFF
        self.stored = dict(self.regs)
        self._storing_until = -1.0

        # drive state
        self.out_hz = 0.0               # signed output frequency
        self.accelerating = False
        self.fault: str | None = None   # active fault code
        self.ope: str | None = None
        self.history: list[int] = []    # fault numbers, most recent first
        self.alarm = False
        self._cmd = 0
        self._ref_raw = 0
        self._torque_raw = 0            # output bytes 4-5, 0.1 % (extended1, basic)
        self.torque_out: float | None = None
        self._prev_cmd = 0
        self._run_latched = False       # running incl. the ramp down after the run bit went off
        self._coasting = False
        self._loss_stop: str | None = None     # F6-01 = 0 / 2: the ramp time of the comm-loss stop
        self._last_tick: float | None = None
        self._comm = False              # in data exchange with a master
        self._last_rx = 0.0
        # handshake / parameter access
        self._cmd_hs = 0                # last command HS bit seen
        self._resp_hs = 0
        self._status = 0                # response STATUS field
        #: the parameter request being processed: (function, start register, quantity, data words)
        self._pending: tuple[int, int, int, list[int]] | None = None
        self._t_toggle = 0.0
        self._answers_since_toggle = 0
        self._reply = bytes(16)         # reply area without the HS byte (16-byte model, cut per layout)

    # -- helpers -----------------------------------------------------------------------------
    def _reg(self, code: str) -> int | None:
        p = self.profile.param(code)
        return None if p is None or p.register is None else p.register

    def _get(self, code: str, default: float) -> float:
        """Engineering value of a parameter from the store."""
        p = self.profile.param(code)
        if p is None or p.register is None:
            return default
        return float(p.from_raw(self.regs.get(p.register, 0)))

    def _set(self, code: str, raw: int) -> None:
        reg = self._reg(code)
        if reg is not None:
            self.regs[reg] = raw

    def param(self, code: str) -> float:
        """Current engineering value of a parameter (tests)."""
        return self._get(code, 0.0)

    @property
    def fmax(self) -> float:
        return self._get("E1-04", float(self.profile.max_frequency_default)) or 60.0

    def _time(self, code: str) -> float:
        raw = self.regs.get(self._reg(code) or -1, 100)
        unit = 0.01 if int(self._get("C1-10", 1)) == 0 else 0.1
        return raw * unit

    def _o1_03(self) -> int:
        return int(self._get("o1-03", 0))

    def _hz_per_count(self, direction: str) -> float:
        o1 = self._o1_03()
        if o1 == 1:
            return self.fmax / 10000.0
        if 2 <= o1 <= 39:
            return o1 / 120.0
        if o1 >= 40 and o1 % 10000:
            return self.fmax / (o1 % 10000)
        return self.ref_unit if direction == "ref" else self.fb_unit

    def _alarm_number(self, code: str) -> int:
        a = self.profile.alarm_by_code(code)
        return a.number if a else 0

    def _alarm_kind(self, code: str) -> str:
        for a in self.profile.raw.get("alarms", []) or []:
            if str(a.get("code", "")).upper() == code.upper():
                return str(a.get("kind", "fault"))
        return "fault"

    # -- DP ------------------------------------------------------------------------------------
    def check_cfg(self, cfg: bytes) -> bool:
        ok = super().check_cfg(cfg)
        if ok:
            self._reply = bytes(16)
        return ok

    def on_leave_data_exchange(self, now: float, reason: str) -> None:
        # communication loss: BUS fault when the bus is the run or reference source; how the drive
        # stops is F6-01 (0 ramp C1-02, 1 coast (factory), 2 fast stop C1-09, 3 alarm only)
        was = self._comm
        running = self._run_latched or self.out_hz != 0.0
        self._comm = False
        bus_source = int(self._get("b1-01", 0)) == 3 or int(self._get("b1-02", 0)) == 3
        react = was and bus_source and (self.bus_fault == "always" or
                                        (self.bus_fault == "running" and running))
        f601 = self._f601()
        if react and f601 == 3:
            return                      # alarm only: the drive keeps running on the last command
        self._cmd = 0
        self._ref_raw = 0
        if not react:
            return
        if f601 in (0, 2) and self.out_hz != 0.0:
            self._loss_stop = "C1-09" if f601 == 2 else "C1-02"    # ramp, BUS once at 0 Hz
        else:
            self.trip("BUS", now)

    def clear_outputs(self, now: float) -> None:
        """Global_Control Clear: the outputs read as zero (Fail_Safe 0, spec: "In the master's CLEAR
        state the slave receives outputs set to 0"): no run command, so the drive stops by b1-03;
        the link stays up, so no BUS fault."""
        self._apply_command(0, now)
        self._ref_raw = 0

    def _f601(self) -> int:
        p = self.profile.param("F6-01")
        return int(self._get("F6-01", 1)) if p is not None and p.register is not None else 1

    # -- dynamics -----------------------------------------------------------------------------
    def next_due(self, now: float) -> float | None:
        """Every tick while running, ramping or about to (a run command waiting for the next tick);
        otherwise the end of comm_timeout without a Data_Exchange (the BUS fault), nothing else."""
        alarm = self.alarm
        target, run = self._target()
        self.alarm = alarm                  # (_target sets it: that is the tick's business)
        if self._loss_stop is not None:
            return now
        if run or self._run_latched or self.out_hz != 0.0:
            lim = self._torque_limit_hz()
            if lim is not None and abs(target) > lim:
                target = lim if target > 0 else -lim
            steady = (run and self._run_latched and not self.torque_controlled()
                      and not self.accelerating and self.out_hz == target)
            if not steady:
                return now                  # ramping, stopping, or about to start
        if self._comm and self.comm_timeout > 0:
            return self._last_rx + self.comm_timeout
        return None

    def tick(self, now: float) -> None:
        if self._last_tick is None:
            self._last_tick = now
        dt = max(0.0, now - self._last_tick)
        self._last_tick = now
        if self._comm and self.comm_timeout > 0 and now - self._last_rx > self.comm_timeout:
            self.on_leave_data_exchange(now, "timeout")
        self._step(dt)
        if self._loss_stop is not None and self.out_hz == 0.0:
            self._loss_stop = None
            self.trip("BUS", now)

    def _bus_run(self) -> bool:
        return int(self._get("b1-02", 0)) == 3

    def _reference_hz(self) -> float:
        """The frequency reference in force: from the bus if b1-01 = 3, else d1-01 (keypad)."""
        if int(self._get("b1-01", 0)) == 3:
            ref = self._ref_raw * self._hz_per_count("ref")
        else:
            ref = self._get("d1-01", 0.0)
        return min(ref, self.fmax)

    def _target(self) -> tuple[float, bool]:
        """(signed target frequency, run active)."""
        fwd, rev = self._cmd >> FWD & 1, self._cmd >> REV & 1
        self.alarm = bool(fwd and rev)
        run = self._bus_run() and (fwd ^ rev) and not self.fault and not self.ope \
            and not self._cmd >> BASE_BLOCK & 1 and not self._fast_stop_active() \
            and self._loss_stop is None
        ref = self._reference_hz()
        return ((-ref if rev else ref) if run else 0.0), bool(run)

    def _fast_stop_active(self) -> bool:
        n = self.fast_stop_input
        return n is not None and bool(self._cmd >> MFI_BITS[n] & 1)

    def torque_controlled(self) -> bool:
        """Flux vector (A1-02 = 3) and d5-01 = 1 (see the module docstring)."""
        return int(self._get("A1-02", 0)) == 3 and self.d5_01 == 1

    def _torque_limit_hz(self) -> float | None:
        """In flux-vector speed control, the speed at which the load reaches the torque limit."""
        if int(self._get("A1-02", 0)) != 3 or self.d5_01 == 1 or self._torque_raw == 0:
            return None
        lim = abs(_s16(self._torque_raw)) / 10.0
        frac = (lim - torque_axis.LOAD_STATIC) / torque_axis.LOAD_SPEED
        return max(0.0, min(1.0, frac)) * self.fmax

    def _step(self, dt: float) -> None:
        target, run = self._target()
        self.torque_out = None
        cut = self.fault is not None or self._cmd >> BASE_BLOCK & 1 or self.ope is not None
        if not run and not cut and self._run_latched and int(self._get("b1-03", 0)) == 1 \
                and self._loss_stop is None:
            cut = True                  # b1-03 = 1: coast to stop
        if cut:
            self.out_hz = 0.0
            self._run_latched = False
            self.accelerating = False
            return
        if run:
            self._run_latched = True
        if not self._run_latched:
            self.out_hz = 0.0
            return
        fmax = self.fmax
        if run and self.torque_controlled():
            torque = _s16(self._torque_raw) / 10.0
            self.out_hz, self.torque_out = torque_axis.step(self.out_hz, torque, fmax, dt)
            self.accelerating = False
            return
        lim = self._torque_limit_hz()
        if lim is not None and abs(target) > lim:
            target = lim if target > 0 else -lim
        t_acc = max(self._time("C1-01"), 1e-3)
        t_dec = max(self._time(self._loss_stop or ("C1-09" if self._fast_stop_active() else "C1-02")),
                    1e-3)
        f = self.out_hz
        if f * target < 0 or abs(target) < abs(f):        # slowing down (or through zero)
            goal = 0.0 if f * target < 0 else target
            step = fmax / t_dec * dt
            f = max(goal, f - step) if f > 0 else min(goal, f + step)
            self.accelerating = False
        else:
            step = fmax / t_acc * dt
            f = min(target, f + step) if target > 0 else max(target, f - step)
            self.accelerating = abs(f) < abs(target)
        self.out_hz = f
        if not run and f == 0.0:
            self._run_latched = False

    # -- cyclic --------------------------------------------------------------------------------
    def data_exchange(self, outputs: bytes, now: float) -> bytes:
        if self.layout is None:
            return bytes(self.input_len)
        size, in_names, poff, maxregs = LAYOUTS[self.layout]
        self._comm = True
        self._last_rx = now
        cmd, ref = struct.unpack_from(self.order + "HH", outputs, 0)
        self._torque_raw = struct.unpack_from(self.order + "H", outputs, 4)[0] if size >= 6 else 0
        self._apply_command(cmd, now)
        self._ref_raw = ref
        self._step(0.0)
        if poff is not None:
            self._param_cycle(outputs[poff:], maxregs, now)
        words = self._inputs(in_names)
        img = b"".join(struct.pack(self.order + "H", w & 0xFFFF) for w in words)
        if poff is not None:
            area_len = size - poff
            wd = int(now / 0.064) & 0x0F            # watchdog counter, about every 64 ms
            hs = self._resp_hs << 7 | self._status << 5 | wd << 1
            # reply area: everything but the HS byte (extended2 has room for one data word)
            img = img.ljust(poff, b"\0") + self._reply[:area_len - 1] + bytes([hs])
        return img.ljust(size, b"\0")[:size]

    def _apply_command(self, cmd: int, now: float) -> None:
        rising = cmd & ~self._prev_cmd
        self._prev_cmd = cmd
        self._cmd = cmd
        if cmd >> EXT_FAULT & 1 and self.fault is None:
            self.trip("EF0", now)
        if rising >> RESET & 1 and self.fault is not None and not cmd & 0b11:
            cause_gone = not (self.fault == "EF0" and cmd >> EXT_FAULT & 1)
            if cause_gone:
                self.fault = None
        if rising >> CLEAR_LOG & 1:
            self.history.clear()

    def _inputs(self, names: Iterable[str]) -> list[int]:
        fmax = self.fmax
        f = abs(self.out_hz)
        running = self._run_latched and self.fault is None
        target, _ = self._target()
        agree = running and abs(abs(target) - f) < 0.05 and f > 0
        st = 0
        bits = {S_RUN: running, S_ZERO: f == 0.0, S_REV: self.out_hz < 0 or (running and target < 0),
                S_RESET: bool(self._cmd >> RESET & 1), S_AGREE: agree,
                S_READY: self.fault is None and self.ope is None and not self._cmd >> BASE_BLOCK & 1,
                S_ALARM: self.alarm, S_FAULT: self.fault is not None, S_OPE: self.ope is not None,
                S_REMOTE: self._bus_run(), S_MFO1: running, S_MFO2: f == 0.0, S_MFO3: agree}
        for b, on in bits.items():
            if on:
                st |= 1 << b
        fb = int(round(f / self._hz_per_count("fb")))
        cur = 0.0
        if running:
            cur = 0.3 + 0.5 * f / fmax + (0.2 if self.accelerating else 0.0)
        if self.torque_out is not None:
            torque = self.torque_out
        else:
            torque = (torque_axis.load_percent(f, fmax) + (20.0 if self.accelerating else 0.0)) \
                * (-1 if self.out_hz < 0 else 1) if running else 0.0
        vals = {"status": st, "feedback": fb, "torque": int(round(torque * 10)) & 0xFFFF,
                "pg": 0, "fref": int(round(self._reference_hz() / self._hz_per_count("fb"))), "fout": fb,
                "current": int(round(cur * 8192)), "ain": 0}
        return [min(vals[n], 0xFFFF) for n in names]

    # -- parameter access --------------------------------------------------------------------
    def _param_cycle(self, area: bytes, maxregs: int, now: float) -> None:
        hs = area[-1] >> 7 & 1
        if hs != self._cmd_hs:
            # a toggle: take the command as it stands now; the response HS follows at once
            self._cmd_hs = hs
            self._resp_hs = hs
            self._status = 0
            self._t_toggle = now
            self._answers_since_toggle = 0
            fc = area[0]
            self._pending = None if fc == 0 else (fc, area[1] << 8 | area[2], area[3],
                                                  [area[4 + 2 * i] << 8 | area[5 + 2 * i]
                                                   for i in range(maxregs)])
            return
        if self._pending is None:
            return
        self._answers_since_toggle += 1
        if self._answers_since_toggle == 1:
            self._status = 1                  # sending to the drive
        elif self._answers_since_toggle == 2 or now - self._t_toggle < self.processing:
            self._status = 2                  # waiting for the drive
        else:
            fc, start, dq, data = self._pending
            self._pending = None
            self._reply = self._execute(fc, start, dq, data, maxregs, now)
            self._status = 3

    def _error(self, fc: int, code: int) -> bytes:
        return bytes([fc | 0x80, 0, 0, 2, 0, code]).ljust(16, b"\0")

    def _execute(self, fc: int, start: int, dq: int, data: list[int], maxregs: int, now: float) -> bytes:
        if fc not in (0x03, 0x10):
            return self._error(fc & 0x7F, ERR_FUNCTION)
        if dq % 2 or not 2 <= dq <= 2 * maxregs:
            return self._error(fc, ERR_QUANTITY)
        n = dq // 2
        regs = range(start, start + n)
        if fc == 0x03:
            vals = []
            for r in regs:
                v = self._read_register(r, now)
                if v is None:
                    return self._error(fc, ERR_ADDRESS)
                vals.append(v)
            body = bytes([fc, start >> 8 & 0xFF, start & 0xFF, dq])
            for v in vals:
                body += bytes([v >> 8 & 0xFF, v & 0xFF])
            return body.ljust(16, b"\0")
        # write: check everything first, then apply
        for i, r in enumerate(regs):
            code = self._check_write(r, data[i], now)
            if code:
                return self._error(fc, code)
        for i, r in enumerate(regs):
            if r == self.enter_register:
                self.stored = dict(self.regs)
                self._storing_until = now + 0.05
            else:
                self.regs[r] = data[i]
        return bytes([fc, start >> 8 & 0xFF, start & 0xFF, dq]).ljust(16, b"\0")

    def _read_register(self, r: int, now: float) -> int | None:
        if r == self.enter_register:
            return None                     # write-only
        p = self.defs.get(r)
        if p is None:
            return None
        if r == 0x0037 and p.access == "ro":
            f = abs(self.out_hz)
            cur = 0.3 + 0.5 * f / self.fmax if self._run_latched else 0.0
            return int(round(self.rated_kw * cur * f / self.fmax * 10))
        fh = self._fault_register(p.code)
        if fh is not None:
            return fh
        return self.regs.get(r, 0)

    def _fault_register(self, code: str) -> int | None:
        code = code.upper()
        if code == "U2-01":
            return self._alarm_number(self.fault) if self.fault else 0
        if code == "U2-02":
            h = self.history[1:] if self.fault else self.history
            return h[0] if h else 0
        if code.startswith("U3-0") and code[-1] in "1234":
            i = int(code[-1]) - 1
            return self.history[i] if i < len(self.history) else 0
        return None

    def _check_write(self, r: int, value: int, now: float) -> int:
        running = self._run_latched or abs(self.out_hz) > 0
        if now < self._storing_until:
            return ERR_WRITE                 # parameters being stored
        if r == self.enter_register:
            return ERR_WRITE if running else 0
        p = self.defs.get(r)
        if p is None:
            return ERR_ADDRESS
        if p.access == "ro":
            return ERR_WRITE
        if p.access == "stop" and running:
            return ERR_WRITE
        v = value - 0x10000 if p.signed and value & 0x8000 else value
        lo = p.to_raw(p.min) if p.min is not None else None
        hi = p.to_raw(p.max) if p.max is not None else None
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            return ERR_RANGE
        return 0

    # -- steering (sim/control.py) -------------------------------------------------------------
    def clear_fault(self, now: float) -> None:
        self.fault = None
        self.ope = None

    def set_value(self, code: str, value: float) -> None:
        from profidrive_cli.drives.values import profile_value_problem
        if code.lower() == "d5-01":
            if value not in SETTINGS["d5-01"]:
                raise ValueError(f"d5-01 must be 0 (speed control) or 1 (torque control), got {value:g}")
            self.d5_01 = int(value)
            return
        p = self.profile.param(code)
        if p is None or p.register is None:
            raise ValueError(f"{code} is not a parameter of {self.profile.name}")
        why = profile_value_problem(self.profile, p, value)
        if why is not None:
            raise ValueError(why)
        self.regs[p.register] = p.to_raw(float(value)) & 0xFFFF

    def snapshot(self) -> dict[str, object]:
        return {**super().snapshot(), "state": "fault" if self.fault else
                ("running" if self.out_hz or self._run_latched else "stopped"),
                "hz": round(self.out_hz, 3), "fault": self.fault or self.ope}

    # -- fault injection -------------------------------------------------------------------------
    def trip(self, alarm: str, now: float) -> None:
        a = self.profile.alarm_by_code(alarm)
        if a is None:
            known = ", ".join(x.code for x in self.profile.alarms)
            raise ValueError(f"yaskawa sim: unknown fault {alarm!r} (known: {known})")
        if self._alarm_kind(a.code) == "ope":
            self.ope = a.code
            return
        if self.fault is None:
            self.fault = a.code
            self.history.insert(0, a.number)
            del self.history[4:]
        self.out_hz = 0.0
        self._run_latched = False
        self._loss_stop = None

    def seed_faults(self, alarms: list[str]) -> None:
        nums = []
        for code in alarms:
            a = self.profile.alarm_by_code(code)
            if a is None:
                raise ValueError(f"yaskawa sim: unknown fault {code!r}")
            nums.append(a.number)
        self.history = (nums + self.history)[:4]


def make_model(profile: Profile, **options: Any) -> YaskawaModel:     # (the sim:// URL's options)
    # `defaults` (code -> value: a sim URL's set=, the preset every family's model takes) become the
    # model's parameter options (E1-04 -> E1_04)
    for code, v in (options.pop("defaults", None) or {}).items():
        options[code.replace("-", "_")] = v
    return YaskawaModel(profile, **options)
