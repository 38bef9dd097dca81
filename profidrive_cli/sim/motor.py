"""The simulated motor behind a drive model: the monitor values a card reports (output current,
output voltage, DC-link voltage, torque) from the output frequency, its rate of change and the load.
Pure arithmetic on the model's virtual clock; the family models store the results in their own
monitor registers and trip records.

    current  = rated_a * sqrt(magnetising^2 + (torque/100)^2)   while the output is on, else 0
    torque   = load_pct + inertia_s * 100 * (df/dt) / fmax     (% of rated; load only while turning)
    voltage  = rated_v * min(1, |f| / base_hz)                  (V/f line)
    dc_link  = dc_v * (1 + 0.01 * sin(2 pi 300 t))               (6-pulse rectifier ripple, 1 %)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from profidrive_cli.sim.profidrive_model import ProfidriveModel


@dataclass
class Motor:
    rated_a: float = 10.0           # motor rated current, A
    rated_v: float = 400.0          # output voltage at base frequency, V
    dc_v: float = 560.0             # DC-link voltage, V
    load_pct: float = 30.0          # load torque while turning, % of rated
    inertia_s: float = 2.0          # seconds of rated torque to reach fmax from standstill
    magnetising: float = 0.3        # no-load current, share of rated
    ripple: float = 0.01            # DC-link ripple, share of dc_v
    # state
    freq: float = 0.0               # last output frequency, Hz (signed)
    accel: float = 0.0              # last df/dt, Hz/s
    on: bool = False                # output switched on (running or ramping)
    t: float = 0.0                  # last update, s

    def update(self, now: float, freq: float, on: bool) -> None:
        dt = now - self.t
        if dt > 0:
            self.accel = (abs(freq) - abs(self.freq)) / dt
        self.freq, self.on, self.t = freq, on, now

    def torque_pct(self, fmax: float) -> float:
        if not self.on:
            return 0.0
        load = self.load_pct if self.freq != 0.0 else 0.0
        return load + self.inertia_s * 100.0 * self.accel / max(fmax, 1e-9)

    def current_a(self, fmax: float) -> float:
        if not self.on:
            return 0.0
        return self.rated_a * math.hypot(self.magnetising, self.torque_pct(fmax) / 100.0)

    def voltage_v(self, base_hz: float) -> float:
        if not self.on:
            return 0.0
        return self.rated_v * min(1.0, abs(self.freq) / max(base_hz, 1e-9))

    def dc_link_v(self) -> float:
        return self.dc_v * (1.0 + self.ripple * math.sin(2.0 * math.pi * 300.0 * self.t))


def store(model: ProfidriveModel, code: str, value: float) -> None:
    """Put an engineering value into a model's parameter store as its wire value: clamped to the
    parameter's range, rounded to its step. Nothing when the profile has no such code."""
    p = model.profile.param(code)
    if p is None:
        return
    lo = p.min if p.min is not None else value
    hi = p.max if p.max is not None else value
    v = min(max(value, lo), hi)
    model.values[p.code] = model.wire_from_value(p, round(v / p.scale) * p.scale if p.scale else round(v))
