"""What a checklist step type is, and the small measuring helpers their execution shares.

A step type is one StepType subclass in its own module under checklist/steps/, registered by name in
steps/__init__.py. It holds its schema and its execution together:

    validate(check, st, rs, body, state) -> (args, title)
        check: the FieldChecker collecting file:line problems (fields, num, code_field, need_param_channel,
        err, fail); st: the StationSpec; rs: the raw step (index, type, line, body_line); body: the
        step's mapping or scalar after variable substitution; state: what earlier steps leave behind
        on this station ({"running": bool}). Returns the typed args and the title in words, or raises
        fields.Skip after recording the problem.
    execute(run, sr, r, d, h) -> str
        run: the Runner (dry_run, yes, ask, progress(sr, r, text), cycle_for(sr, r, d, seconds, text));
        sr / r: the StationResult and this step's StepResult (fill r.expected and r.measured); d: the
        Drive; h: the StationHandle (h.session: the station's session, from api.Bus.session). Returns the message of a
        pass; raises StepFailed for an unmet expectation (PdriveError: the step is an error).

The runner does the rest once for every type: timing, the observer, on_fail, the safe stop, the report.
This module imports nothing of the checklist but may be imported by all of it.
"""

from __future__ import annotations

import math


class StepFailed(Exception):
    """An expectation was not met: the step fails with this message (measured values already recorded)."""


class StepType:
    """One step type: its name (the YAML key), its schema check and its execution."""

    name: str = ""

    def validate(self, check, st, rs, body, state) -> tuple[dict, str]:
        raise NotImplementedError

    def execute(self, run, sr, r, d, h) -> str:
        raise NotImplementedError


def hex4(v) -> str | None:
    return f"0x{v:04X}" if isinstance(v, int) else v


def close_to(a, b, tol) -> bool:
    try:
        return abs(float(a) - float(b)) <= float(tol) + 1e-9
    except (TypeError, ValueError):
        return a == b


def rnd(v):
    if v is None or not isinstance(v, float):
        return v
    return round(v, 3) if math.isfinite(v) else v


def status_dict(st) -> dict:
    if st is None:
        return {}
    return {"state": st.state, "running": st.running, "stopped": st.stopped, "fault": st.fault,
            "fault_code": st.fault_code, "speed_hz": rnd(st.speed_hz), "speed_percent": rnd(st.speed_percent),
            "flags": {k: v for k, v in st.flags.items() if v}}
