"""Replay: a simulated plant whose slaves answer as the captured ones did (`pdrive sim --learn CAPTURE`,
`sim://?learn=PATH`), so a replacement PLC can be tested against "the line as it was".

    plans = load_plans("line.pcapng")           # dp/capfile.py: raw, pcap, pcapng, ptd by extension
    slaves = learned_slaves(plans, make_model, baud=187500)   # drive models or LearnedModels
    bus = build_bus("sim://?learn=line.pcapng")  # sim/plant.py: the plant with the URL's options

learn(packets) pairs each request with its reply as a listener does (bustools/passive_live.py: the reply
answers the last request that expects one; a token, an SDN or the next request ends the wait) and keeps
per answering station a StationPlan:

  ident        the station's own (its Slave_Diag reply, octets 4..5), else the accepted Set_Prm's
  user_prm     the Set_Prm user data (octets 7..) of the last Set_Prm the station accepted; Sync / Freeze
               offered when that Set_Prm requested them
  chk_cfg      the Chk_Cfg the master sent and the station accepted: acknowledged, and not refuted
               by a Cfg_Fault in its next diagnosis (confirmed by a diagnosis without Prm_Req and
               Cfg_Fault, or by an answered Data_Exchange)
  get_cfg      the last Get_Cfg reply
  diag         the last Slave_Diag reply (its Ext_Diag bit and extended octets are replayed; the state
               bits are the simulated station's own)
  exchanges    the answered Data_Exchanges: (time, outputs, inputs)

A Set_Prm is accepted on the same terms (refuted by Prm_Fault or Not_Supported in the next diagnosis).

The stations are built (learned_slaves): a station whose ident a shipped profile carries
(drives/profile.py profile_for_ident) and whose accepted configuration is one of that profile's layouts
(or none was seen) runs the family's drive model (sim/plant.py make_model), with that layout as the one
Get_Cfg reports before a master configures it; any other station runs a LearnedModel.

The inputs a LearnedModel answers (InputReplay), chosen from the capture:
  keyed     where the capture shows the inputs as a function of the outputs -- every outputs value
            that repeats got the same inputs each time, at least one did repeat, and the inputs
            differed between outputs -- the inputs the captured station gave those outputs (an
            echo, a handshake); outputs the capture never saw fall back to the sequence;
  in order  otherwise: the captured inputs in their order, looping, on the capture's own clock (a
            sensor that was on for 2 s is on for 2 s whatever the new master's cycle), or one per
            Data_Exchange when the capture carries no times (raw files: one time for every packet).
Replaying in order keeps what a PLC test most needs, the process as it ran; keying alone would
answer a PLC whose outputs never repeat with nothing the line ever said.

Sans-IO apart from reading the capture file; errors as one line (UsageError, exit 2): a capture that
cannot be read names the file and the octet (dp/capfile.py CaptureFileError), a capture in which no
slave answered says so.
"""

from __future__ import annotations

import os
from bisect import bisect_right
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Iterable

from profidrive_cli import UsageError
from profidrive_cli.dp import services as S
from profidrive_cli.dp.cfg import CfgError, io_sizes
from profidrive_cli.fdl import frames as F
from profidrive_cli.sim.model import SlaveModel
from profidrive_cli.sim.slave import SimSlave

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.drives.profile import Profile

#: sim/plant.py make_model (passed in: plant.py reads sim://?learn= through this module)
MakeModel = Callable[["Profile"], SlaveModel]

#: answered Data_Exchanges kept per station (the first ones; a capture of hours needs no more to replay)
MAX_EXCHANGES = 100_000
_EXPECTS_REPLY = frozenset(F.NEEDS_REPLY)
_DX_FUNCTIONS = frozenset((F.SRD_LOW, F.SRD_HIGH))
_ANSWERED = frozenset((F.DL, F.DH, F.RDL, F.RDH))
_EXT_DIAG = S.ST1["Ext_Diag"]


@dataclass
class StationPlan:
    """What the capture showed of one station (see the module doc)."""
    address: int
    ident: int | None = None
    user_prm: bytes | None = None
    sync: bool = False
    freeze: bool = False
    chk_cfg: bytes | None = None
    refused_cfgs: list[bytes] = field(default_factory=list)
    get_cfg: bytes | None = None
    diag: bytes | None = None
    exchanges: list[tuple[float, bytes, bytes]] = field(default_factory=list)
    answers: int = 0
    # candidates waiting for the station's next word on them
    _prm: S.SetPrm | None = None
    _cfg: bytes | None = None

    def as_dict(self) -> dict[str, Any]:
        return {"station": self.address, "ident": self.ident,
                "ident_hex": None if self.ident is None else f"0x{self.ident:04X}",
                "user_prm": None if self.user_prm is None else self.user_prm.hex(" "),
                "chk_cfg": None if self.chk_cfg is None else self.chk_cfg.hex(" "),
                "get_cfg": None if self.get_cfg is None else self.get_cfg.hex(" "),
                "diag": None if self.diag is None else self.diag.hex(" "),
                "exchanges": len(self.exchanges)}


class Learner:
    """feed() each captured telegram (time, frame or None for a framing error); plans() at the end."""

    def __init__(self) -> None:
        self.stations: dict[int, StationPlan] = {}
        self.frames = 0
        self._pending: tuple[float, F.Frame] | None = None

    def feed(self, t: float, f: F.Frame | None) -> None:
        self.frames += 1
        if f is None or f.sd == F.SD4:             # a corrupt reply or a token: nobody answers now
            self._pending = None
            return
        if f.sd == F.SC:
            self._reply(t, None)
            return
        if f.is_request:
            expects = f.function in _EXPECTS_REPLY and f.da != F.BROADCAST
            self._pending = (t, f) if expects else None
            return
        p = self._pending
        if p is not None and p[1].da == f.sa:
            self._reply(t, f)
        else:
            self._pending = None                   # a reply to nobody we heard

    def _station(self, address: int) -> StationPlan:
        st = self.stations.get(address)
        if st is None:
            st = self.stations[address] = StationPlan(address)
        return st

    def _reply(self, t: float, rep: F.Frame | None) -> None:
        """`rep` (None: a short acknowledge) answers the pending request."""
        p = self._pending
        self._pending = None
        if p is None:
            return
        req = p[1]
        st = self._station(req.da)
        st.answers += 1
        status = F.OK if rep is None else rep.fc & 0x0F
        if req.dsap is None and req.ssap is None and req.function in _DX_FUNCTIONS:
            if rep is None or status in _ANSWERED:
                self._commit_cfg(st)
                if len(st.exchanges) < MAX_EXCHANGES:
                    st.exchanges.append((t, bytes(req.data), b"" if rep is None else bytes(rep.data)))
            return
        if req.dsap == S.SAP_SET_PRM and rep is None:
            try:
                prm = S.SetPrm.decode(req.data)
            except S.ServiceError:
                return
            if prm.unlock:                         # a release, not parameters
                return
            st._prm, st._cfg = prm, None
        elif req.dsap == S.SAP_CHK_CFG and rep is None:
            st._cfg = bytes(req.data)
        elif rep is not None and rep.ssap == S.SAP_GET_CFG and status in _ANSWERED:
            st.get_cfg = bytes(rep.data)
        elif rep is not None and rep.ssap == S.SAP_SLAVE_DIAG and status in _ANSWERED \
                and len(rep.data) >= 6:
            self._diag(st, bytes(rep.data))

    def _diag(self, st: StationPlan, data: bytes) -> None:
        st.diag = data
        d = S.SlaveDiag.decode(data)
        st.ident = d.ident
        if st._prm is not None:
            if d.has("Prm_Fault") or d.has("Not_Supported"):
                st._prm = None
            elif not d.has("Prm_Req"):
                self._commit_prm(st)
        if st._cfg is not None:
            if d.has("Cfg_Fault"):
                st.refused_cfgs.append(st._cfg)
                st._cfg = None
            elif not d.has("Prm_Req"):
                self._commit_cfg(st)

    def _commit_prm(self, st: StationPlan) -> None:
        prm = st._prm
        if prm is not None:
            st.user_prm, st.sync, st.freeze = bytes(prm.user_prm), prm.sync, prm.freeze
            if st.ident is None:
                st.ident = prm.ident
            st._prm = None

    def _commit_cfg(self, st: StationPlan) -> None:
        self._commit_prm(st)
        if st._cfg is not None:
            st.chk_cfg, st._cfg = st._cfg, None

    def plans(self) -> dict[int, StationPlan]:
        """Every station that answered, candidates not refuted by the end of the capture taken."""
        for st in self.stations.values():
            self._commit_cfg(st)
        return dict(sorted(self.stations.items()))


def learn(packets: Iterable[Any]) -> dict[int, StationPlan]:
    """Plans per station from captured packets: dp/capfile.py Packets, or (time, octets) pairs of
    one telegram each (octets that are no whole telegram count as a framing error)."""
    lr = Learner()
    for p in packets:
        t, raw = float(p[0]), bytes(p[1])
        r = F.parse(raw, 0)
        lr.feed(t, r[0] if isinstance(r, tuple) and r[1] == len(raw) else None)
    return lr.plans()


def load_plans(path: str | os.PathLike[str]) -> dict[int, StationPlan]:
    """The plans of a capture file (format by extension). UsageError (exit 2) for a file that cannot
    be read (file and octet) and for a capture in which no slave answered."""
    from profidrive_cli.dp.capfile import open_capture
    lr = Learner()
    for p in open_capture(path):
        r = F.parse(p.raw, 0)
        lr.feed(p.t, r[0] if isinstance(r, tuple) and r[1] == len(p.raw) else None)
    every = lr.plans()
    plans = {a: st for a, st in every.items() if st.ident is not None}
    if not plans:
        blind = sorted(every)
        why = (f"; station(s) {', '.join(map(str, blind))} answered, but the capture shows no ident "
               f"(capture the line's start-up: Set_Prm or Slave_Diag)") if blind else ""
        raise UsageError(f"{path}: no slave answers a Slave_Diag or accepts a Set_Prm in its "
                         f"{lr.frames} telegrams: nothing to learn{why}")
    return plans


# -------------------------------------------------------------------------------------------------
# answering

class InputReplay:
    """The inputs a LearnedModel answers (the module doc: keyed, else in order, looping)."""

    def __init__(self, exchanges: list[tuple[float, bytes, bytes]], input_len: int):
        rows = [(t, o, i) for t, o, i in exchanges if len(i) == input_len]
        self.input_len = input_len
        self.sequence = [i for _, _, i in rows]
        t0 = rows[0][0] if rows else 0.0
        self.times = [t - t0 for t, _, _ in rows]
        span = self.times[-1] if rows else 0.0
        #: on the capture's clock (False: one per Data_Exchange; also for times out of order)
        self.timed = span > 0.0 and all(a <= b for a, b in zip(self.times, self.times[1:]))
        self.period = span + span / (len(rows) - 1) if self.timed else 0.0
        self.keyed = _keyed(rows)
        self._count = 0
        self._start: float | None = None

    @property
    def mode(self) -> str:
        return "keyed" if self.keyed else "in order" if self.sequence else "zeros"

    def answer(self, outputs: bytes, now: float) -> bytes:
        if self.keyed is not None:
            hit = self.keyed.get(bytes(outputs))
            if hit is not None:
                return hit
        if not self.sequence:
            return bytes(self.input_len)
        if self.timed:
            if self._start is None:
                self._start = now
            at = (now - self._start) % self.period
            return self.sequence[max(0, bisect_right(self.times, at) - 1)]
        i = self._count % len(self.sequence)
        self._count += 1
        return self.sequence[i]


def _keyed(rows: list[tuple[float, bytes, bytes]]) -> dict[bytes, bytes] | None:
    table: dict[bytes, bytes] = {}
    repeated = False
    for _, o, i in rows:
        seen = table.get(o)
        if seen is None:
            table[o] = i
        elif seen != i:
            return None                  # the same outputs got other inputs: not a function
        else:
            repeated = True
    if not repeated or len(set(table.values())) < 2:
        return None
    return table


class LearnedModel(SlaveModel):
    """A station answering as the captured one did: its ident, its accepted configuration only, its
    Get_Cfg answer, its extended diagnosis and its inputs (InputReplay)."""

    family = "learned"

    def __init__(self, plan: StationPlan):
        cfgs = {"captured": plan.chk_cfg} if plan.chk_cfg is not None else {}
        diag = plan.diag or b""
        super().__init__(plan.ident or 0, cfgs, name=f"station {plan.address} as captured",
                         user_prm_len=None if plan.user_prm is None else len(plan.user_prm),
                         max_diag_len=max(6, len(diag)))
        self.plan = plan
        self.sync_supported, self.freeze_supported = plan.sync, plan.freeze
        self.io_lens = _io_lens(plan)
        self.replay = InputReplay(plan.exchanges, self.io_lens[0])

    def check_cfg(self, cfg: bytes) -> bool:
        """Exactly the captured configuration (its lengths from the capture when it does not decode)."""
        if self.plan.chk_cfg is None or bytes(cfg) != self.plan.chk_cfg:
            return False
        self.layout = "captured"
        self.input_len, self.output_len = self.io_lens
        return True

    def real_cfg(self) -> bytes:
        """The captured Get_Cfg answer (a modular slave reports its real modules), else the accepted
        configuration."""
        return self.plan.get_cfg if self.plan.get_cfg is not None else super().real_cfg()

    def data_exchange(self, outputs: bytes, now: float) -> bytes:
        return self.replay.answer(outputs, now)

    def ext_diag(self) -> bytes:
        return (self.plan.diag or b"")[6:]

    def snapshot(self) -> dict[str, object]:
        return {**super().snapshot(), "inputs": self.replay.mode, "exchanges": len(self.replay.sequence)}


def _io_lens(plan: StationPlan) -> tuple[int, int]:
    """(input, output) octets of the accepted configuration, else the most frequent in the capture."""
    if plan.chk_cfg is not None:
        try:
            return io_sizes(plan.chk_cfg)
        except (CfgError, ValueError):
            pass
    return _most(len(i) for _, _, i in plan.exchanges), _most(len(o) for _, o, _ in plan.exchanges)


def _most(values: Iterable[int]) -> int:
    lens = list(values)
    return max(set(lens), key=lens.count) if lens else 0


class LearnedSlave(SimSlave):
    """A SimSlave whose Slave_Diag carries the captured Ext_Diag bit (st1 bit 3) with the captured
    extended octets: a device may send extended diagnosis without flagging it (the ET200S of
    pyprofibus #26 did: st1 0x02 with 29 octets of blocks)."""

    def __init__(self, address: int, model: LearnedModel):
        super().__init__(address, model)
        diag = model.plan.diag
        self.ext_flag = bool(diag[0] & _EXT_DIAG) if diag is not None and len(diag) >= 6 else None

    def diag(self) -> S.SlaveDiag:
        d = super().diag()
        if self.ext_flag is None:
            return d
        st1 = (d.st1 & ~_EXT_DIAG) | (_EXT_DIAG if self.ext_flag else 0)
        return S.SlaveDiag(st1, d.st2, d.st3, d.master, d.ident, d.ext)


def _drive_model(plan: StationPlan, baud: int, make_model: MakeModel) -> SlaveModel | None:
    """The family's drive model for a station whose ident a profile carries and whose accepted
    configuration is one of the profile's layouts (or none was seen); None otherwise."""
    from profidrive_cli.drives.profile import profile_for_ident
    if plan.ident is None:
        return None
    prof = profile_for_ident(plan.ident)
    if prof is None:
        return None
    layout = None
    if plan.chk_cfg is not None:
        layout = next((n for n, lay in prof.layouts.items() if lay.cfg == plan.chk_cfg), None)
        if layout is None:
            return None
    model = make_model(prof)
    if layout is not None:
        model.default_layout = layout
    model.on_bus(plan.address, baud)
    return model


def learned_slaves(plans: dict[int, StationPlan], make_model: MakeModel,
                   baud: int = 19200) -> list[SimSlave]:
    """The stations of the plans: `make_model(profile)` (sim/plant.py's) builds a drive model."""
    out: list[SimSlave] = []
    for a, plan in plans.items():
        model = _drive_model(plan, baud, make_model)
        if model is not None:
            out.append(SimSlave(a, model))
        else:
            out.append(LearnedSlave(a, LearnedModel(plan)))
    return out


__all__ = ["StationPlan", "Learner", "learn", "load_plans", "InputReplay", "LearnedModel",
           "LearnedSlave", "learned_slaves"]
