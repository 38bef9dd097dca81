"""Simulated Moeller DF6/DV6 inverter with a DE6-NET-DP card (sim/profidrive_model.py + dialect).

    make_model(profile, device="DF6", address=0, baud_code=0, bus_control=True, pkw_latency=0,
               defaults=None) -> MoellerModel

Dialect on top of the generic PROFIdrive model:
  * run commands come from the bus only with STW bit 10 = 1, bit 12 = 0, A002 = 1 and PNU 928 = 1;
    the reference only with bit 10 = 1, bit 13 = 0, A001 = 2 and PNU 928 = 1. Without bus commands a
    running motor ramps to standstill (the terminals are not simulated) and the state machine waits.
  * direction = sign of HSW XOR STW bit 11; ZSW bits 12/13 mirror STW bits 12/13
  * ZSW bit 8 (at set-point) also when stopped (manual example 0x0331); bit 10 when |f| >= C042 > 0
  * parameters as 1/2/4-octet wire values (profile `bytes`), R/WOS refused with error 17 while running
  * communication loss: P002 = 0 trips E70 (only a running drive), 1 keeps running
  * trips count d080 (PNU 352) and fill the trip records d081..d086 (PNU 354, 00..05, points at the
    latest: 00 = record 1)
    with the frequency, current and DC-link voltage at the trip
  * monitors d001 (frequency), d002 (current), d013 (voltage), d012 (torque) follow the motor
    (sim/motor.py: current with load and acceleration, voltage with frequency)
  * PNU 964 = 0x812C (DF6) or 0x012C (DV6)
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from profidrive_cli.drives import moeller as mo
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.profidrive import Ctw, State
from profidrive_cli.sim.motor import Motor, store
from profidrive_cli.sim.profidrive_model import ProfidriveModel

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import ParamDef, Profile

DEVICE_IDS = {"DF6": 0x812C, "DV6": 0x012C}


class MoellerModel(ProfidriveModel):
    family = "moeller"

    def __init__(self, profile: Profile, *, device: str = "DF6", bus_control: bool = True,
                 **kw: Any):                # ProfidriveModel's keyword arguments
        self.mc: mo.MoellerConfig = mo.moeller_config(profile)
        dev = device.upper()
        if dev not in DEVICE_IDS:
            raise ValueError(f"device must be DF6 or DV6, got {device!r}")
        defaults = dict(self.mc.sim_defaults or {})
        if not bus_control:
            defaults[self.mc.frequency_param] = 1
            defaults[self.mc.commands_param] = 2
        defaults.update(kw.pop("defaults", None) or {})
        super().__init__(profile, defaults=defaults, device_id=DEVICE_IDS[dev], **kw)
        self.edit_rights = int(defaults.get("PNU927", 1))
        self.control_rights = int(defaults.get("PNU928", 1))
        self.device = dev
        self.dc_bus_voltage = 560.0 if dev == "DF6" else 540.0
        self.run_seconds = 0.0
        self.records_written = 0        # trip records filled since power-up
        self.motor = Motor(dc_v=self.dc_bus_voltage)

    # -- control source ----------------------------------------------------------------------
    def _raw(self, code: str) -> int:
        return self.values[self.profile.param(code).code]  # type: ignore[union-attr]  # (codes named here)

    def commands_from_bus(self, ctw: int) -> bool:
        mc = self.mc
        return bool(ctw & Ctw.CONTROL_BY_PLC) and not ctw >> mc.commands_invalid_bit & 1 \
            and self._raw(mc.commands_param) == mc.commands_bus_value and bool(self.control_rights)

    def reference_from_bus(self, ctw: int) -> bool:
        mc = self.mc
        return bool(ctw & Ctw.CONTROL_BY_PLC) and not ctw >> mc.reference_invalid_bit & 1 \
            and self._raw(mc.frequency_param) == mc.frequency_bus_value and bool(self.control_rights)

    def effective_control_word(self, ctw: int) -> int | None:
        if self.commands_from_bus(ctw):
            return ctw
        if self.state in (State.S3, State.S4, State.S5):
            return self.ctw_eff & ~int(Ctw.ON | Ctw.FAULT_ACK)     # run command gone: ramp stop
        return None

    def reference_sign(self, ctw: int) -> int:
        if self.commands_from_bus(ctw) and ctw >> self.mc.reverse_bit & 1:
            return -1
        return 1

    def status_extra_bits(self, ctw: int) -> int:
        mask = (1 << self.mc.commands_invalid_bit) | (1 << self.mc.reference_invalid_bit)
        return ctw & mask

    def at_setpoint(self) -> bool:
        # the manual's "ready to switch on" example 0x0331 has bit 8 set: at standstill with no run
        # command the output equals its (zero) set-point; not in S1 (switch-on inhibited)
        if self.state in (State.S2, State.S3):
            return self.freq == 0.0
        return self.state is State.S4 and abs(self.freq - self._target_hz()) < 1e-6

    def arrival_reached(self) -> bool:
        level = float(self.param_value("C042")) if self.profile.param("C042") else 0.0
        return level > 0 and abs(self.freq) >= level

    # -- values ------------------------------------------------------------------------------
    def value_from_wire(self, p: ParamDef, raw: int) -> float:
        v: float = mo.value_from_wire(p, raw)
        return v

    def wire_from_value(self, p: ParamDef, value: float) -> int:
        return mo.wire_from_value(p, value)

    def value_allowed(self, p: ParamDef, value: float) -> bool:
        if not mo.in_ranges(p, value):
            return False
        if self.device == "DF6":
            if p.extra.get("df6") is False:
                return False
            mx = p.extra.get("df6_max")
            if mx is not None and value > mx:
                return False
        return True

    def pkw_answer(self, req: pd.PkwFrame) -> pd.PkwFrame:
        p = pd.param_for(self.profile, req.pnu, req.subindex)
        if p is not None and p.extra.get("df6") is False and self.device == "DF6" and req.ak:
            return pd.PkwFrame(7, req.pnu, req.subindex, self.cfg.error_numbers["unknown_pnu"])
        if req.ak == 7 and req.pnu in (915, 916) and self.device == "DF6":
            q = pd.param_for(self.profile, req.value & 0xFFFF)        # a DV6-only parameter cannot be
            if q is not None and q.extra.get("df6") is False:          # mapped on a DF6 either
                return pd.PkwFrame(7, req.pnu, req.subindex, self.cfg.error_numbers["out_of_range"])
        return super().pkw_answer(req)

    # -- dynamics ----------------------------------------------------------------------------
    def next_due(self, now: float) -> float | None:
        """As the generic drive: the monitors of tick() stand still with the motor; the run-time
        counter is made up by catch_up."""
        return super().next_due(now)

    def catch_up(self, times: list[float], then: float | None = None) -> None:
        """Ticks missed at standstill or at a steady speed: only the run-time counter moves (in
        operation), by each tick's step as tick() adds them."""
        if self.moving() or self._last_tick is None:
            for t in times:
                self.tick(t)
            return
        last = self._last_tick
        running = self.state in (State.S4, State.S5)
        for t in times:
            if t > last:
                if running:
                    self.run_seconds += t - last
                last = t
        self._last_tick = last
        self.motor.update(last, self.freq, running)

    def tick(self, now: float) -> None:
        last = self._last_tick
        super().tick(now)
        if last is not None and now > last and self.state in (State.S4, State.S5):
            self.run_seconds += now - last
        self.motor.update(now, self.freq, self.state in (State.S4, State.S5))
        fmax = self.max_frequency()
        for code, v in (("d001", abs(self.freq)), ("d002", self.motor.current_a(fmax)),
                        ("d013", self.motor.voltage_v(fmax)), ("d012", self.motor.torque_pct(fmax))):
            store(self, code, v)


    def comm_loss_action(self) -> tuple[str, str | None]:
        if self._raw(self.mc.comm_loss_param) == 0:
            return ("trip", self.mc.comm_loss_alarm)
        return ("continue", None)

    def on_trip(self, number: int, now: float) -> None:
        par = self.profile.param
        if par("d080"):
            self.values["d080"] = min(0xFFFF, self.values["d080"] + 1)
        if not par("PNU354"):
            return
        # the pointer runs 00..05 (manual L1116); 00 is taken as trip record 1 (d081), round robin;
        # the first trip goes to record 1
        k = (self.values["PNU354"] + 1) % 6 if self.records_written else 0
        self.records_written += 1
        self.values["PNU354"] = k
        base = 355 + 6 * k
        freq = abs(self.last_trip[1]) if self.last_trip else 0.0
        cur = self.motor.current_a(self.max_frequency())     # the motor as at the last tick
        fields = [number, freq, round(cur, 1), round(self.motor.dc_link_v(), 1), int(self.run_seconds), int(now)]
        for off, v in enumerate(fields):
            p = pd.param_for(self.profile, base + off)
            if p is not None:
                self.values[p.code] = self.wire_from_value(p, min(v, p.max or v))


def make_model(profile: Profile, **options: Any) -> MoellerModel:     # (the sim:// URL's options)
    if "address" in options:
        options["node_address"] = int(options.pop("address"))
    return MoellerModel(profile, **options)
