"""A torque-controlled axis for the simulated drives (sim/toyo.py, sim/yaskawa.py).

Simulator choices (no manual gives a mechanical load): the load torque opposes the motion and is
LOAD_STATIC % of rated torque plus LOAD_SPEED % at maximum speed, rising linearly with speed; at
standstill the load holds the axis while |torque| <= LOAD_STATIC. The inertia is such that 100 %
net torque (torque minus load) accelerates the axis from 0 to the maximum frequency in INERTIA_S
seconds (torque control bypasses the drive's ramp; time constant INERTIA_S * 100 / LOAD_SPEED = 5 s). The speed is limited to +-fmax (the drive's maximum
frequency): there the drive reduces its torque to the load's. Steady state below the limit:
|speed| / fmax = (|torque| - LOAD_STATIC) / LOAD_SPEED.

Pure arithmetic; imports nothing of pdrive.
"""

from __future__ import annotations

LOAD_STATIC = 10.0       # % of rated torque
LOAD_SPEED = 20.0        # % more at the maximum frequency
INERTIA_S = 1.0          # s from 0 to fmax with 100 % net torque


def load_percent(freq: float, fmax: float) -> float:
    """The load torque magnitude at this speed."""
    return LOAD_STATIC + LOAD_SPEED * min(1.0, abs(freq) / fmax) if fmax > 0 else LOAD_STATIC


def step(freq: float, torque: float, fmax: float, dt: float) -> tuple[float, float]:
    """Advance the axis by dt s under `torque` (% of rated, signed): (new freq in Hz, torque produced)."""
    if dt <= 0 or fmax <= 0:
        return freq, torque if freq != 0.0 or abs(torque) > LOAD_STATIC else 0.0
    if freq == 0.0 and abs(torque) <= LOAD_STATIC:
        return 0.0, torque
    sign = 1.0 if (freq > 0 or (freq == 0.0 and torque > 0)) else -1.0
    net = torque - sign * load_percent(freq, fmax)
    new = freq + net / 100.0 * fmax / INERTIA_S * dt
    if freq != 0.0 and (new > 0) != (freq > 0):      # the load alone cannot reverse the axis
        new = 0.0 if abs(torque) <= LOAD_STATIC or (torque > 0) == (freq > 0) else new
    if abs(new) >= fmax:                              # speed limit: the drive holds max frequency
        new = fmax if new > 0 else -fmax
        return new, (1.0 if new > 0 else -1.0) * load_percent(new, fmax)
    return new, torque
