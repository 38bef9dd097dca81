"""Steering a simulated plant while a master runs (`pdrive sim --control`, `pdrive sim-ctl`, the Python
API's Bus.simulator): trip a drive, clear its fault, unplug and replug a station, change a setting,
inject bus faults, read the plant's state.

Every command runs on the bus's own thread between two telegrams: the in-process controller under
the master's lock (it is that thread), the HTTP server's by queueing it on SimBus.pending, which the
bus runs at its next tick or request (the served bus ticks every 5 ms), and waiting for the result.

The HTTP face (sim/control_http.py: ControlServer) is JSON: `GET /state`;
`POST /<command>` with a JSON object of arguments, e.g. `POST /trip {"station": 3, "alarm": "OC1"}`;
the answer is a JSON object, `{"error": "..."}` with status 400 for a command the plant refuses.
"""

from __future__ import annotations

import contextlib
import re
import time
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeout
from typing import Any, Callable, ContextManager

#: the commands, with their arguments (name -> required?), for the HTTP face and sim-ctl
COMMANDS: dict[str, dict[str, bool]] = {
    "state": {},
    "trip": {"station": True, "alarm": False},
    "clear": {"station": True},
    "unplug": {"station": True},
    "replug": {"station": True},
    "set": {"station": True, "code": True, "value": True},
    "faults": {"spec": True},
}

#: how long an HTTP command waits for the bus's thread to take it (the served bus ticks every 5 ms)
TAKE_TIMEOUT_S = 5.0
#: commands queued for the bus at most (more: 503)
MAX_PENDING = 64


class ControlError(ValueError):
    """A command the plant refuses: one line."""


class Controller:
    """The commands on one SimBus (sim/bus.py, which builds this in SimBus.control: typed Any here,
    for no import cycle). lock: held around each command (the in-process master's);
    clock: the plant's time for the models (default time.monotonic)."""

    def __init__(self, bus: Any, clock: Callable[[], float] | None = None,
                 lock: ContextManager[Any] | None = None) -> None:
        self.bus = bus
        self.clock = clock or time.monotonic
        self.lock: ContextManager[Any] = lock if lock is not None else contextlib.nullcontext()

    # -- one entry for every face -----------------------------------------------------------------
    def call(self, command: str, args: dict[str, Any] | None = None) -> dict[str, Any]:
        """Run `command` with `args` now (this is the bus's thread): its result, or ControlError."""
        fn = self._checked(command, args or {})
        with self.lock:
            return fn(self.clock())

    # -- the same as methods (the Python API: bus.simulator.trip(3, "OC1")) -------------------------
    def state(self) -> dict[str, Any]:
        return self.call("state")

    def trip(self, station: int, alarm: str | None = None) -> dict[str, Any]:
        return self.call("trip", {"station": station, **({"alarm": alarm} if alarm else {})})

    def clear(self, station: int) -> dict[str, Any]:
        return self.call("clear", {"station": station})

    def unplug(self, station: int) -> dict[str, Any]:
        return self.call("unplug", {"station": station})

    def replug(self, station: int) -> dict[str, Any]:
        return self.call("replug", {"station": station})

    def set(self, station: int, code: str, value: float) -> dict[str, Any]:
        return self.call("set", {"station": station, "code": code, "value": value})

    def faults(self, spec: str) -> dict[str, Any]:
        return self.call("faults", {"spec": spec})

    def _checked(self, command: str, args: dict[str, Any]) -> Callable[[float], dict[str, Any]]:
        """The command bound to its checked arguments: fn(now) -> result (ControlError on bad input)."""
        spec = COMMANDS.get(command)
        if spec is None:
            raise ControlError(f"unknown command {command!r} (commands: {', '.join(COMMANDS)})")
        unknown = sorted(set(args) - set(spec))
        if unknown:
            raise ControlError(f"{command}: unknown argument {unknown[0]!r} (takes: "
                               f"{', '.join(spec) or 'nothing'})")
        missing = [k for k, req in spec.items() if req and k not in args]
        if missing:
            raise ControlError(f"{command}: {missing[0]!r} is missing")
        method: Callable[..., dict[str, Any]] = getattr(self, "_" + command)
        return lambda now: method(now, **args)

    # -- the commands (on the bus's thread) --------------------------------------------------------
    def _station(self, station: Any, plugged: bool | None = True) -> Any:
        if isinstance(station, bool) or not isinstance(station, int):
            raise ControlError(f"station {station!r} is not an address")
        if station in self.bus.slaves:
            if plugged is False:
                raise ControlError(f"station {station} is plugged in")
            return self.bus.slaves[station]
        if station in self.bus.unplugged:
            if plugged:
                raise ControlError(f"station {station} is unplugged (replug it first)")
            return self.bus.unplugged[station]
        raise ControlError(f"no station {station} on this plant (stations: "
                           f"{', '.join(map(str, sorted({*self.bus.slaves, *self.bus.unplugged})))})")

    def _state(self, now: float) -> dict[str, Any]:
        rows = []
        for addr in sorted({*self.bus.slaves, *self.bus.unplugged}):
            s = self.bus.slaves.get(addr) or self.bus.unplugged[addr]
            model = s.model
            built = getattr(model, "built", True)
            row: dict[str, Any] = {"station": addr, "plugged": addr in self.bus.slaves,
                                   "dp_state": s.state, "ident": model.ident}
            if built:
                row.update(model.snapshot())
            rows.append(row)
        return {"stations": rows, **faults_answer(self.bus.faults), "requests": self.bus.stats.requests}

    def _trip(self, now: float, station: Any, alarm: Any = None) -> dict[str, Any]:
        s = self._station(station)
        from profidrive_cli.sim.faults import default_trip_code
        try:
            code = str(alarm) if alarm is not None else default_trip_code(s.model)
            s.inject_trip(code, now)
        except ValueError as e:
            raise ControlError(f"trip station {station}: {e}") from None
        return {"station": station, "tripped": code}

    def _clear(self, now: float, station: Any) -> dict[str, Any]:
        s = self._station(station)
        try:
            s.model.clear_fault(now)
        except ValueError as e:
            raise ControlError(f"clear station {station}: {e}") from None
        return {"station": station, "cleared": True}

    def _unplug(self, now: float, station: Any) -> dict[str, Any]:
        s = self._station(station)
        if s.state == "Data_Exch":
            s.model.on_leave_data_exchange(now, "unplugged")
        self.bus.unplugged[station] = self.bus.slaves.pop(station)
        return {"station": station, "plugged": False}

    def _replug(self, now: float, station: Any) -> dict[str, Any]:
        s = self._station(station, plugged=False)
        self.bus.slaves[station] = self.bus.unplugged.pop(station)
        s.power_on(now)                      # a station plugged back in starts as after power-up
        return {"station": station, "plugged": True}

    def _set(self, now: float, station: Any, code: Any, value: Any) -> dict[str, Any]:
        s = self._station(station)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            try:
                value = float(str(value))
            except ValueError:
                raise ControlError(f"set station {station}: {value!r} is not a number") from None
        try:
            s.model.set_value(str(code), float(value))
        except ValueError as e:
            raise ControlError(f"set station {station}: {e}") from None
        return {"station": station, "code": str(code), "value": value}

    def _faults(self, now: float, spec: Any) -> dict[str, Any]:
        """spec: the sim URL's fault options as text ("drop=0.1,noise=0.05"; "" for none)."""
        from urllib.parse import parse_qs

        from profidrive_cli import UsageError
        from profidrive_cli.sim.faults import URL_KEYS, plan_from_query
        # options apart by "&" or by "," before the next name= (only=3,4 keeps its list)
        q = parse_qs("&".join(re.split(r",(?=[a-z_]+=)", str(spec))), keep_blank_values=True)
        bad = sorted(set(q) - set(URL_KEYS))
        if bad:
            raise ControlError(f"faults: unknown option {bad[0]!r} (options: {', '.join(URL_KEYS)})")
        try:
            plan = plan_from_query(q) if q else None
        except UsageError as e:
            raise ControlError(f"faults: {str(e).removeprefix('sim URL: ')}") from None
        self.bus.faults = plan
        return faults_answer(plan)


def faults_answer(plan: Any) -> dict[str, Any]:
    """The injected faults (a sim/faults.py FaultPlan or None) as the control reports them: `faults`
    (the rates), `faults_only` (the stations they are limited to, null: all) and `faults_spec` (the
    whole plan as `sim-ctl faults` takes it, "" for none)."""
    if plan is None:
        return {"faults": {}, "faults_only": None, "faults_spec": ""}
    only = sorted(plan.only) if plan.only is not None else None
    words = [f"{k}={v:g}" for k, v in plan.rates.items()]
    if only is not None:
        words.append("only=" + ",".join(map(str, only)))
    if "late" in plan.rates or plan.late_s != 0.2:
        words.append(f"late_ms={plan.late_s * 1000:g}")
    words += [f"tripcode={a}:{c}" for a, c in sorted(plan.trip_codes.items())]
    words += [f"unplug={a}@{t0:g}" + (f"-{t1:g}" if t1 is not None else "")
              for a, (t0, t1) in sorted(plan.unplugs.items())]
    return {"faults": dict(plan.rates), "faults_only": only, "faults_spec": ",".join(words)}


class ControlBusy(ControlError):
    """The simulator cannot take a command now (HTTP 503): its queue is full, or it did not take it."""


class QueuedController(Controller):
    """For another thread (the HTTP face): a command is queued on the bus and run by its thread.

    A command the bus did not take within TAKE_TIMEOUT_S is withdrawn (the caller is told so, and the
    bus skips it: a plant must not trip later on a command its user was told had failed), and at
    most MAX_PENDING wait at a time."""

    def call(self, command: str, args: dict[str, Any] | None = None) -> dict[str, Any]:
        fn = self._checked(command, args or {})
        done: Future[dict[str, Any]] = Future()

        def run(now: float) -> None:
            if not done.set_running_or_notify_cancel():
                return                               # withdrawn: its caller has been answered
            try:
                done.set_result(fn(now))
            except Exception as e:               # noqa: BLE001  (handed to the asking thread)
                done.set_exception(e)
        if len(self.bus.pending) >= MAX_PENDING:
            raise ControlBusy(f"the simulator has {MAX_PENDING} commands waiting; try again")
        self.bus.pending.append(run)
        try:
            return done.result(timeout=TAKE_TIMEOUT_S)
        except FutureTimeout:
            if done.cancel():
                raise ControlBusy(f"the simulator did not take {command!r} within "
                                  f"{TAKE_TIMEOUT_S:g} s; it was withdrawn") from None
        try:                                         # taken just now: its result
            return done.result(timeout=TAKE_TIMEOUT_S)
        except FutureTimeout:
            raise ControlBusy(f"the simulator took {command!r} but did not finish it within "
                              f"{TAKE_TIMEOUT_S:g} s") from None
