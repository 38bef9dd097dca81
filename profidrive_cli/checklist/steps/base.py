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
This module imports nothing of the checklist (for the type checker only, fields.py's types) but may be
imported by all of it. What a step type gets of runner.py is said here as Protocols (StepRun, StepRecord,
Handle, ...), what it gets of spec.py in fields.py (StationFacts, RawStepFacts): those modules import the
registry, so a step type cannot import them; runner.Runner, spec.StationSpec and the rest satisfy them.
"""

from __future__ import annotations

import math
from contextlib import AbstractContextManager
from typing import TYPE_CHECKING, Any, Callable, Protocol, Sequence, TypeVar

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.checklist.fields import FieldChecker, RawStepFacts, StationFacts, StepArgs, StepFacts
    from profidrive_cli.drives.base import Drive, DriveStatus
    from profidrive_cli.api.station import DriveStation

class ChecklistFacts(Protocol):
    """spec.Checklist: its stations."""
    @property
    def stations(self) -> Sequence[StationFacts]: ...


class StepRecord(Protocol):
    """runner.StepResult: what a step fills in (expected, measured)."""
    @property
    def step(self) -> StepFacts: ...
    expected: dict[str, Any]
    measured: dict[str, Any]


class StationRecord(Protocol):
    """runner.StationResult: the station's results."""
    @property
    def spec(self) -> StationFacts: ...


class Handle(Protocol):
    """runner.StationHandle: the open station."""
    @property
    def drive(self) -> Drive: ...
    @property
    def identity(self) -> dict[str, Any]: ...
    @property
    def session(self) -> DriveStation: ...


#: the run's own result types (runner.StationResult, runner.StepResult), handed back to it by a step
SR = TypeVar("SR", bound=StationRecord)
R = TypeVar("R", bound=StepRecord)
_SRc = TypeVar("_SRc", bound=StationRecord, contravariant=True)
_Rc = TypeVar("_Rc", bound=StepRecord, contravariant=True)


class StepRun(Protocol[_SRc, _Rc]):
    """runner.Runner: what a step type uses of the run (progress and cycle_for take back the
    station's and the step's results the run gave the step)."""
    @property
    def cl(self) -> ChecklistFacts: ...
    @property
    def dry_run(self) -> bool: ...
    @property
    def yes(self) -> bool: ...
    @property
    def ask(self) -> Callable[[str], bool] | None: ...
    @property
    def open_station(self) -> Callable[[StationFacts], AbstractContextManager[Handle]]: ...

    def progress(self, sr: _SRc, r: _Rc, text: str, force: bool = False) -> None: ...

    def cycle_for(self, sr: _SRc, r: _Rc, drive: Drive, seconds: float,
                  text: str = "") -> DriveStatus: ...


class StepFailed(Exception):
    """An expectation was not met: the step fails with this message (measured values already recorded)."""


class StepType:
    """One step type: its name (the YAML key), its schema check and its execution."""

    name: str = ""

    def validate(self, check: FieldChecker, st: StationFacts, rs: RawStepFacts, body: Any,
                 state: dict[str, bool]) -> tuple[StepArgs, str]:
        """body: the step's YAML after substitution (LineDict, scalar or None), checked here."""
        raise NotImplementedError

    def execute(self, run: StepRun[SR, R], sr: SR, r: R, d: Drive, h: Handle) -> str:
        raise NotImplementedError


def hex4(v: int | str | None) -> str | None:
    return f"0x{v:04X}" if isinstance(v, int) else v


def close_to(a: float, b: float, tol: float) -> bool:
    try:
        return abs(float(a) - float(b)) <= float(tol) + 1e-9
    except (TypeError, ValueError):
        return a == b


def rnd(v: float | None) -> float | None:
    if v is None or not isinstance(v, float):
        return v
    return round(v, 3) if math.isfinite(v) else v


def status_dict(st: DriveStatus | None) -> dict[str, Any]:
    if st is None:
        return {}
    return {"state": st.state, "running": st.running, "stopped": st.stopped, "fault": st.fault,
            "fault_code": st.fault_code, "speed_hz": rnd(st.speed_hz), "speed_percent": rnd(st.speed_percent),
            "flags": {k: v for k, v in st.flags.items() if v}}
