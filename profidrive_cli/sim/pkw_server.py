"""The PKW server of a simulated PROFIdrive drive (sim/profidrive_model.py): one parameter task per
request (read, write, array), the card's error numbers, the response latency in cycles. A mixin of
ProfidriveModel, whose parameter store, profile, config and special PNUs it answers from; the
families' dialects override pkw_answer (sim/fuji.py, sim/moeller.py, sim/toyo.py)."""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.profidrive import PkwFrame

if TYPE_CHECKING:
    from profidrive_cli.drives.profidrive.config import ProfidriveConfig
    from profidrive_cli.drives.profile import ParamDef

#: request AK of a write -> the positive response AK (PROFIdrive V2; Moeller spec 5.3)
WRITE_ACK = {2: 1, 3: 2, 7: 4, 8: 5}


class PkwServer:
    """The PKW channel's server side: _pkw_serve per Data_Exchange, pkw_answer per task."""

    # provided by ProfidriveModel
    cfg: ProfidriveConfig
    # (a Profile there: Any here, as SlaveModel says Profile | None and DriveModel narrows it to Profile)
    profile: Any
    values: dict[str, int]
    edit_rights: int
    pkw_latency: int
    pkw_log: list[tuple[PkwFrame, PkwFrame]]
    pzd_setpoint_map: list[int]
    _pkw_req: tuple[int, ...] | None
    _pkw_resp: PkwFrame
    _pkw_wait: int

    if TYPE_CHECKING:                                   # pragma: no cover  (ProfidriveModel's)
        @property
        def running(self) -> bool: ...

        def read_special(self, pnu: int, sub: int) -> int | None: ...
        def write_special(self, pnu: int, sub: int, raw: int) -> str | None: ...
        def value_allowed(self, p: Any, value: Any) -> bool: ...
        def value_from_wire(self, p: Any, raw: int) -> Any: ...

    def _pkw_serve(self, area_words: Iterable[int], now: float) -> tuple[int, int, int, int]:
        words = tuple(area_words)
        if words != self._pkw_req:
            self._pkw_req = words
            req = PkwFrame.from_words(words)
            if req.ak == 0:
                self._pkw_resp, self._pkw_wait = pd.IDLE, 0
            else:
                self._pkw_resp = self.pkw_answer(req)
                self._pkw_wait = self.pkw_latency
                self.pkw_log.append((req, self._pkw_resp))
                del self.pkw_log[:-50]
        if self._pkw_wait > 0:
            self._pkw_wait -= 1
            return pd.IDLE.words()
        return self._pkw_resp.words()

    def pkw_answer(self, req: PkwFrame) -> PkwFrame:
        """Execute one PKW task and return the response frame."""
        c = self.cfg
        num = c.error_numbers

        def err(role: str, ak: int = 7) -> PkwFrame:
            return PkwFrame(ak, req.pnu, req.subindex, num.get(role, 18))

        supported = c.supported_requests or frozenset({1, 2, 3, 6, 7, 8, 9})
        if req.ak not in supported or req.ak not in (1, 2, 3, 6, 7, 8, 9):
            return err("bad_request")
        write = req.ak in (2, 3, 7, 8)
        array_req = req.ak in (6, 7, 8, 9)
        if not self.edit_rights and req.pnu != pd.PNU_EDIT_RIGHTS:
            return err("no_rights", ak=8)
        p = pd.param_for(self.profile, req.pnu, req.subindex)
        is_array = req.pnu in c.array_pnus or bool(p is not None and p.extra.get("array"))
        special_read = self.read_special(req.pnu, 1)   # probe: does this PNU exist?
        if p is None and special_read is None:
            return err("unknown_pnu")
        if is_array:
            n = self._array_len(req.pnu, p)
            if not array_req:
                return err("bad_subindex")
            if req.ak == 9:
                return PkwFrame(6, req.pnu, req.subindex, n)
            if not 1 <= req.subindex <= n:
                return err("bad_subindex")
        elif array_req:
            return err("not_array")
        size = p.size if p is not None else 16
        # a write is acknowledged in the width asked (WRITE_ACK), a read in the parameter's own width
        ok_ak = WRITE_ACK.get(req.ak) or ((4 if size == 16 else 5) if is_array else (1 if size == 16 else 2))
        if not write:
            v = self.read_special(req.pnu, req.subindex)
            if v is None:
                assert p is not None            # a PNU the profile lacks is answered by read_special
                v = self.values[p.code]
            return PkwFrame(ok_ak, req.pnu, req.subindex, v & 0xFFFFFFFF)
        raw = req.value & (0xFFFF if size == 16 else 0xFFFFFFFF)
        if size == 16 and req.value > 0xFFFF and req.value >> 16 != 0xFFFF:
            return err("out_of_range")
        if p is not None:
            if p.access == "ro":
                return err("read_only")
            if not self.value_allowed(p, self.value_from_wire(p, raw)):
                return err("out_of_range")
            if p.access == "stop" and self.running:
                return err("stop_only")
        res = self.write_special(req.pnu, req.subindex, raw)
        if res:
            return err(res)
        if res is None:
            if p is None:
                return err("unknown_pnu")
            self.values[p.code] = raw
        return PkwFrame(ok_ak, req.pnu, req.subindex, req.value)

    def _array_len(self, pnu: int, p: ParamDef | None) -> int:
        n = None if p is None else p.extra.get("array")
        if isinstance(n, int):
            return n
        if pnu in self.cfg.pzd_map:
            return len(self.pzd_setpoint_map)
        if pnu == self.cfg.fault_memory_pnu:
            return max(self.cfg.fault_subindexes + [1])
        return 1
