"""A station's drive model built on its first real use (sim:// start-up: only what is used is loaded).

Building a drive model means loading its profile (YAML) and importing the family's model and codecs:
for the default five-station plant that is most of what `pdrive scan --port sim://` costs. Until a
master asks more of a station than an untouched drive can answer, LazyModel answers for it:

  * `ident` (from the profile index, pdrive's cheap read of each profile's first keys),
  * `ext_diag()` = b"" (an untouched drive has no trip to report) and `max_diag_len`,
  * `c1_server` = None (an unbuilt station has no DP-V1 request pending; sim/slave.py serves SAP 51
    only in data exchange, which the Set_Prm that builds the model comes before),
  * `tick(now)` and `catch_up(times)` (sim/bus.py: the ticks of the bus an unaddressed station
    makes up for): remembered; the model, once built, catches up with the last REPLAY_TICKS of them
    in order, so what it records at standstill (the Toyo card's traceback samples) is what an
    eagerly built model would hold; `next_due` None (an untouched drive has no timer of its own).

Anything else (Set_Prm, Chk_Cfg, Get_Cfg, a trip, reading or setting an attribute) builds the model
and hands over: the owning SimSlave's `model` is replaced by the built one, and this object forwards
everything to it from then on (for whoever kept a reference).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from typing import Any, Protocol

from profidrive_cli import PdriveError
from profidrive_cli.drives.registry import sim_diag_len
from profidrive_cli.sim.model import C1Server, SlaveModel, ticks_always



class ModelHolder(Protocol):
    """The station that holds a LazyModel (sim/slave.py SimSlave, which imports this module)."""

    model: SlaveModel | LazyModel

#: tick times kept until the model is built (more than any model's standstill history: Toyo keeps 100)
REPLAY_TICKS = 256



class LazyModel:
    """Stands for the model `build()` returns (a SlaveModel whose ident is `ident`) until first use."""

    # its own state, kept in __dict__ (attribute access goes to the built model): declared only
    _build: Callable[[], SlaveModel]
    _real: SlaveModel | None
    _ident: int
    _diag_len: int
    _ticks: deque[float]
    _owner: ModelHolder | None
    _label: str

    def __init__(self, build: Callable[[], SlaveModel], ident: int, family: str, label: str = ""):
        d = self.__dict__
        d["_build"] = build
        d["_real"] = None
        d["_ident"] = ident
        # the family table's Slave_Diag length (drives/registry.py; tests/test_sim_lazy.py checks it
        # against the built models of every shipped profile)
        d["_diag_len"] = sim_diag_len(family)
        d["_ticks"] = deque(maxlen=REPLAY_TICKS)
        d["_owner"] = None
        d["_label"] = label

    def attach(self, slave: ModelHolder) -> None:
        """The SimSlave that holds this model: it gets the built model in its place."""
        self.__dict__["_owner"] = slave

    @property
    def built(self) -> bool:
        return self._real is not None

    def materialize(self) -> SlaveModel:
        """The built model (built now if it was not yet)."""
        real = self._real
        if real is not None:
            return real
        real = self._build()
        if real.ident != self._ident:
            raise PdriveError(f"simulated station {self._label}: the profile index says ident "
                              f"0x{self._ident:04X}, the profile 0x{real.ident:04X}")
        if self._ticks:
            _catch_up(real, list(self._ticks), None)
        self.__dict__["_real"] = real
        self._ticks.clear()
        owner = self._owner
        if owner is not None and owner.model is self:
            owner.model = real
        return real

    # -- what an untouched drive answers without being built -----------------------------------
    @property
    def ident(self) -> int:
        real = self._real
        return self._ident if real is None else real.ident

    @property
    def max_diag_len(self) -> int:
        real = self._real
        return self._diag_len if real is None else real.max_diag_len

    def ext_diag(self) -> bytes:
        real = self._real
        return b"" if real is None else real.ext_diag()

    @property
    def c1_server(self) -> C1Server | None:
        real = self._real
        return None if real is None else real.c1_server

    def tick(self, now: float) -> None:
        real = self._real
        if real is None:
            self._ticks.append(now)
        else:
            real.tick(now)

    def next_due(self, now: float) -> float | None:
        real = self._real
        return None if real is None else real.next_due(now)

    def catch_up(self, times: list[float], then: float | None = None) -> None:
        real = self._real
        if real is None:
            self._ticks.extend(times)
        else:
            _catch_up(real, times, then)

    # -- everything else builds it --------------------------------------------------------------
    def __getattr__(self, name: str) -> Any:      # the built model's attribute, whatever it is
        if name.startswith("__"):
            raise AttributeError(name)
        return getattr(self.materialize(), name)

    def __setattr__(self, name: str, value: object) -> None:
        setattr(self.materialize(), name, value)

    def __repr__(self) -> str:
        real = self._real
        return f"<LazyModel {self._label} {'built: ' + repr(real) if real is not None else 'not built'}>"


def _catch_up(model: SlaveModel, times: list[float], then: float | None) -> None:
    """The built model makes up for the ticks it missed (tick by tick when it predates catch_up)."""
    if ticks_always(model):
        for t in times:
            model.tick(t)
    else:
        model.catch_up(times, then)
