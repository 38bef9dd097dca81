"""ProfidriveDrive: the Drive interface (drives/base.py) over a PPO layout, generic PROFIdrive V2.

Couples the sans-IO pieces (ppo, words, scaling, pkw, pnu, params) with a CyclicChannel; the channel
does the waiting, nothing here sleeps. Family drives (Fuji, Moeller, Toyo) subclass it and fill its
hooks. `make_drive` makes `family: profidrive` work.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from profidrive_cli import UsageError
from profidrive_cli.drives.base import (CyclicChannel, Drive, DriveError, DriveStatus, FaultRecord, ParamError,
                                        ParamInfo, ParamValue)
from profidrive_cli.drives.values import raw_value_problem, value_problem
from profidrive_cli.drives.profidrive.config import Dpv1Config, ProfidriveConfig, config
from profidrive_cli.drives.profidrive.describe import ppo_drive_object
from profidrive_cli.drives.profidrive.params import ParamRef, resolve_code
from profidrive_cli.drives.profidrive.pkw import (REQUEST_TEXT, PkwChannel, PkwFrame, PkwResult,
                                                  read_request, write_request)
from profidrive_cli.drives.profidrive.pnu import (PNU_BAUD, PNU_CONTROL_RIGHTS, PNU_CONTROL_WORD,
                                                  PNU_DEVICE_ID, PNU_EDIT_RIGHTS,
                                                  PNU_NODE_ADDRESS, PNU_PROFILE, PNU_STATUS_WORD,
                                                  decode_baud, decode_device_id,
                                                  fault_memory_requests, pzd_map_pnu,
                                                  pzd_map_write, save_requests)
from profidrive_cli.drives.profidrive.ppo import (PpoArea, decode_area_bytes, encode_area,
                                                  ppo_layout)
from profidrive_cli.drives.profidrive.scaling import n2_from_percent, n2_to_percent, to_signed16
from profidrive_cli.drives.profidrive.words import (Ctw, State, Stw, Target, next_control_word,
                                                    state_from_status, target_reached)

if TYPE_CHECKING:
    from profidrive_cli.drives.profidrive.ds47 import ParamRequest, ParamResponse
    from profidrive_cli.drives.profile import Profile

#: a DS47 request that ended in a class-1 timeout is sent once more (the answer may have been lost on
#: the line after the slave handed it out)
DS47_REPEATS = 1


class ProfidriveDrive(Drive):
    """The Drive interface over a PPO layout (drives/base.py), generic PROFIdrive V2.

    Keeps a command (target state, reference, extra control bits, PZD3.. words) and sends it every
    cycle; blocking calls cycle until the drive answers or `timeout` passes.

    Subclass hooks (family codecs override what differs):
      resolve_param(code) -> ParamRef            code -> PNU/subindex/array/size
      raw_to_value(ref, raw) / value_to_raw(ref, value)   wire integer <-> engineering value
      check_value(ref, value) -> str | None      range check before a write (None = ok)
      write_refused_message(ref, value, result) -> str    the one-line error for a refused write
      start_hint(status) -> str                  appended when start() times out
      status_extras(area, status) -> None        add family flags/raw words to a DriveStatus
      control_extra_bits() -> int                bits ORed into every control word
    """

    family = "profidrive"

    def __init__(self, channel: CyclicChannel, profile: Profile, layout: str | None = None,
                 cfg: ProfidriveConfig | None = None):
        super().__init__(channel, profile, layout)
        self.cfg = cfg or config(profile)
        self.ppo = ppo_layout(profile, self.layout)
        self.target: Target | None = None          # None = passive (control word 0, bit 10 = 0)
        self.reference = 0                          # N2 word
        self.extra_bits = self.cfg.held_ctw_bits
        self.pzd_out: list[int] = [0] * max(0, self.ppo.pzd_out - 2)
        self.pkw: PkwChannel | None = None
        if self.ppo.pkw:
            self.pkw = PkwChannel(timeout=self.cfg.pkw_timeout,
                                  zero_after_error=self.cfg.zero_after_error,
                                  zero_between_identical=self.cfg.zero_between_identical,
                                  error_texts=self.cfg.error_texts,
                                  max_zero_cycles=self.cfg.max_zero_cycles)
        self.last_ctw: int | None = None
        self.last_stw: int | None = None
        self.last_area: PpoArea | None = None
        self.last_status: DriveStatus | None = None
        self._pkw_result: PkwResult | None = None
        self._fmax: float | None = None
        #: parameters over DP-V1 DS47 (the profile's `dpv1:`, a channel with class-1 services, a
        #: layout without PKW words or use_dpv1()); None: PKW
        self.ds47: Dpv1Config | None = None
        if self.cfg.dpv1 is not None and self.pkw is None and hasattr(channel, "c1_read"):
            self.ds47 = self.cfg.dpv1
        self._ds47_ref = 0

    # -- hooks -------------------------------------------------------------------------------
    @property
    def has_param_channel(self) -> bool:
        return self.pkw is not None or self.ds47 is not None

    def use_dpv1(self, settings: Dpv1Config | None = None) -> None:
        """Parameters over DP-V1 DS47 from now on (`--dpv1`), with the profile's settings or these."""
        if not hasattr(self.channel, "c1_read"):
            raise DriveError(f"{self.profile.name}: this connection has no DP-V1 class-1 services")
        self.ds47 = settings or self.cfg.dpv1 or Dpv1Config()

    def control_extra_bits(self) -> int:
        return self.extra_bits

    def resolve_param(self, code: str) -> ParamRef:
        return resolve_code(self.profile, code, self.cfg)

    def param_info(self, code: str) -> ParamInfo:
        ref = self.resolve_param(code)
        p = ref.param
        return ParamInfo(ref.code, ref.name, p.unit if p is not None else "", p,
                         p.access if p is not None else "raw", ref)

    def _ref(self, info: ParamInfo) -> ParamRef:
        """The address param_info resolved (resolved again only for a ParamInfo made elsewhere)."""
        return info.ref if isinstance(info.ref, ParamRef) else self.resolve_param(info.code)

    @classmethod
    def set_prm_user_data(cls, profile: Any, user_prm: bytes) -> bytes:
        """A card with `dpv1:` gets DPV1_Enable (DPV1_Status_1 bit 7) in the first of the three
        DPV1_Status octets that open a DP-V1 slave's user parameters (dp/dpv1.py); without a GSD
        that gives them, the three octets 80 00 00."""
        from profidrive_cli.dp.dpv1 import dpv1_status
        if config(profile).dpv1 is None:
            return user_prm
        if dpv1_status(user_prm) is None:
            return bytes((0x80, 0, 0)) + bytes(user_prm)
        return bytes((user_prm[0] | 0x80,)) + bytes(user_prm[1:])

    @classmethod
    def param_label_for(cls, profile: Any, code: str) -> tuple[str, Any]:
        ref = cls.resolve_for(profile, code)
        return ref.code, ref.param

    @classmethod
    def resolve_for(cls, profile: Any, code: str) -> ParamRef:
        """resolve_param() from the profile alone (the profile's own PROFIdrive config)."""
        return resolve_code(profile, code, config(profile))

    def value_problem(self, info: ParamInfo, value: float | int) -> str | None:
        return self.check_value(self._ref(info), value)

    def params_at(self, info: ParamInfo) -> list[Any]:
        ref = self._ref(info)
        return [q for q in self.profile.parameters.values()
                if q.pnu is not None and q.pnu == ref.pnu and (q.index or 0) == (ref.subindex or 0)]

    def save_support(self) -> str:
        return "command" if getattr(self.cfg, "save_pnu", None) is not None else "unsupported"

    def _family_not_restored(self, p: Any) -> str:
        if p.pnu in (927, 928):
            return "access rights, left as they are"
        if p.pnu in (970, 971):
            return "a command, not a setting"
        return ""

    def last_seen(self) -> DriveStatus | None:
        return self.last_status

    def cycle_words(self, outputs: bytes, inputs: bytes) -> tuple[int | None, int | None,
                                                                   int | None, int | None]:
        out = decode_area_bytes(self.ppo, outputs, "request").pzd
        inp = decode_area_bytes(self.ppo, inputs, "response").pzd
        return (out[0] if out else None, out[1] if len(out) > 1 else None,
                inp[0] if inp else None, inp[1] if len(inp) > 1 else None)

    def raw_to_value(self, ref: ParamRef, raw: int) -> float | int:
        p = ref.param
        if p is None:
            return raw
        if p.size == 16:
            raw &= 0xFFFF
        return p.from_raw(raw)

    def value_to_raw(self, ref: ParamRef, value: float | int) -> int:
        p = ref.param
        raw = int(value) if p is None else p.to_raw(value)
        bits = ref.size
        return raw & ((1 << bits) - 1)

    def check_value(self, ref: ParamRef, value: float | int) -> str | None:
        """The exact-value check (drives/values.py): resolution, range, codes, wire width."""
        if ref.param is not None:
            return value_problem(ref.param, value)
        return raw_value_problem(ref.label, value, ref.size)

    def write_refused_message(self, ref: ParamRef, value: float | int, result: PkwResult) -> str:
        stop_only = self.cfg.error_numbers.get("stop_only")
        if result.error is not None and result.error == stop_only:
            return (f"{ref.label} can only be changed while the motor is stopped "
                    f"(drive answered error {result.error}: {result.error_text}); stop it first")
        if result.error is not None and result.error == self.cfg.error_numbers.get("no_rights") \
                or (result.response is not None and result.response.ak == 8):
            return (f"{ref.label}: the drive gives no parameter change rights "
                    f"({result.describe_error()}); set PNU {PNU_EDIT_RIGHTS} = 1")
        return f"{ref.label}: the drive refused the value {value}: {result.describe_error()}"

    def start_hint(self, status: DriveStatus) -> str:
        return ("check that the drive takes commands from the bus (control-word bit 10 is sent "
                "as 1; the drive's command-source parameters)")

    def status_extras(self, area: PpoArea, status: DriveStatus) -> None:
        return None

    # -- one cycle ---------------------------------------------------------------------------
    def _control_word(self) -> int:
        if self.target is None:
            return 0
        stw = self.last_stw if self.last_stw is not None else int(Stw.SWITCHING_ON_INHIBITED)
        moving = None
        if self.last_area is not None and len(self.last_area.pzd) > 1:
            moving = to_signed16(self.last_area.pzd[1]) != 0
        return next_control_word(stw, self.target, self.control_extra_bits(),
                                 previous=self.last_ctw, moving=moving)

    def _exchange_area(self, pzd_words: list[int]) -> PpoArea:
        """One Data_Exchange: this cycle's PKW words + `pzd_words` out, the decoded input area
        back; a PKW answer that completes is kept for the waiting request."""
        pkw_words = self.pkw.outputs() if self.pkw else None
        out = PpoArea(pkw_words, pzd_words)
        inputs = self.channel.exchange(encode_area(self.ppo, out, "request"))
        area = decode_area_bytes(self.ppo, inputs, "response")
        self.last_area = area
        if self.pkw is not None and area.pkw is not None:
            res = self.pkw.feed(area.pkw, self.channel.now())
            if res is not None:
                self._pkw_result = res
        return area

    def cycle(self) -> DriveStatus:
        ctw = self._control_word()
        area = self._exchange_area([ctw, self.reference] + list(self.pzd_out))
        self.last_ctw = ctw
        self.last_stw = area.word1
        st = self._decode_status(area)
        self.last_status = st
        return st

    def _decode_status(self, area: PpoArea) -> DriveStatus:
        stw, mav = area.word1, area.word2
        moving = to_signed16(mav) != 0
        state = state_from_status(stw, moving)
        pct = n2_to_percent(mav)
        fmax = self._fmax if self._fmax is not None else float(self.profile.max_frequency_default)
        names = self.cfg.stw_names
        flags = {names.get(b, f"bit {b}"): bool(stw >> b & 1) for b in range(16) if b in names}
        raw = {"status_word": stw, "actual": mav}
        for i, w in enumerate(area.pzd[2:], start=3):
            raw[f"pzd{i}"] = w
        st = DriveStatus(state=state.value, running=state in (State.S4, State.S5),
                         fault=state is State.FAULT, flags=flags, speed_percent=round(pct, 4),
                         speed_hz=round(pct * fmax / 100.0, 4),
                         reference_percent=round(n2_to_percent(self.reference), 4), raw=raw)
        self.status_extras(area, st)
        return st

    # -- PKW ---------------------------------------------------------------------------------
    def request(self, frame: PkwFrame, timeout: float | None = None) -> PkwResult:
        """Run one PKW request to completion (keeps cyclic data going); on a DP-V1 drive the same
        request as a PROFIdrive parameter request over DS47 (ds47_request)."""
        if self.ds47 is not None:
            return self.ds47_request(frame, timeout)
        if self.pkw is None:
            raise DriveError(f"{self.profile.name}: layout {self.layout} has no parameter channel "
                             f"(use a PPO with PKW: {', '.join(n for n, l in self.profile.layouts.items() if l.pkw) or 'none'})")
        if self.cfg.supported_requests is not None and frame.ak not in self.cfg.supported_requests:
            raise DriveError(f"{self.profile.name}: the card does not support request "
                             f"AK {frame.ak} ({REQUEST_TEXT.get(frame.ak, '?')})")
        self._pkw_result = None
        self.pkw.submit(frame, self.channel.now())
        end = self.channel.now() + (timeout if timeout is not None else self.pkw.timeout) + 1.0
        while self._pkw_result is None:
            self.cycle()
            if self._pkw_result is None and self.channel.now() > end:
                self.pkw.cancel()
                raise DriveError(f"no answer to the parameter request for PNU {frame.pnu}")
        res, self._pkw_result = self._pkw_result, None
        return res

    def ds47_request(self, frame: PkwFrame, timeout: float | None = None) -> PkwResult:
        """A PKW request run as a PROFIdrive parameter request over DP-V1: Write DS47 with the
        request, then Read DS47 until the response comes (a "state conflict" or "resource busy"
        answer means not ready yet, up to the profile's dpv1.timeout_s); the answer as the
        PkwResult the PKW path would give (AK 7 and the error number for a negative one)."""
        from profidrive_cli.drives.profidrive import ds47 as D
        d = self.ds47
        assert d is not None
        ak = frame.ak
        self._ds47_ref = self._ds47_ref % 255 + 1
        addr = D.ParamAddress(frame.pnu, frame.subindex)
        long = ak in (3, 8, 11, 13)
        if ak in (1, 6):
            req = D.read_request(self._ds47_ref, d.axis, [addr])
        elif ak in (2, 3, 7, 8, 11, 12, 13, 14):
            value = frame.value & (0xFFFFFFFF if long else 0xFFFF)
            signed = self._ds47_signed(frame.pnu)
            if signed and value >> (31 if long else 15):
                value -= 1 << (32 if long else 16)
            fmt = (0x04 if signed else 0x07) if long else (0x03 if signed else 0x06)
            req = D.change_request(self._ds47_ref, d.axis, [(addr, D.ParamValues(fmt, (value,)))])
        else:
            raise DriveError(f"{self.profile.name}: request AK {ak} ({REQUEST_TEXT.get(ak, '?')}) "
                             "has no DS47 counterpart here")
        what = f"PNU {frame.pnu}" + (f"[{frame.subindex}]" if frame.subindex else "")
        res = self._ds47_exchange(req, what, timeout)
        item = res.items[0] if res.items else None
        if isinstance(item, D.ParamFault):
            return PkwResult(frame, PkwFrame(7, frame.pnu, frame.subindex, item.number),
                             error=item.number, error_text=D.error_text(item.number))
        if not res.ok:
            return PkwResult(frame, PkwFrame(7, frame.pnu, frame.subindex), error=-1,
                             error_text=f"negative DS47 response 0x{res.response_id:02X}")
        if ak in (1, 6):
            if not isinstance(item, D.ParamValues) or isinstance(item.values, bytes) \
                    or not item.values:
                raise DriveError(f"{what}: DS47 read answered without a numeric value")
            v = int(item.values[0])
            is_long = item.format in (0x04, 0x07, 0x08, 0x43)
            return PkwResult(frame, PkwFrame(2 if is_long else 1, frame.pnu, frame.subindex,
                                             v & (0xFFFFFFFF if is_long else 0xFFFF)))
        return PkwResult(frame, PkwFrame(2 if long else 1, frame.pnu, frame.subindex, frame.value))

    def _ds47_exchange(self, req: ParamRequest, what: str,
                       timeout: float | None = None) -> ParamResponse:
        """Write DS47 with `req` (a ds47.ParamRequest), then Read DS47 until its response (busy
        answers polled up to the profile's dpv1.timeout_s); the decoded ds47.ParamResponse."""
        from profidrive_cli.dp.acyclic import C1Error, C1Timeout
        from profidrive_cli.drives.profidrive import ds47 as D
        d = self.ds47
        assert d is not None
        chan: Any = self.channel
        limit = timeout if timeout is not None else d.timeout_s
        for attempt in range(1 + DS47_REPEATS):
            try:
                chan.c1_write(d.slot, D.INDEX, req.encode(), d.c1_timeout_s)
                end = self.channel.now() + limit
                while True:
                    try:
                        data = chan.c1_read(d.slot, D.INDEX, 240, d.c1_timeout_s)
                        break
                    except C1Error as e:
                        if not e.busy or self.channel.now() > end:
                            raise
                        self.cycle()
                break
            except C1Timeout as e:
                # an answer lost on the line (its telegram and the FDL retry both spoilt) is gone
                # for good: the slave has handed it out. The whole request once more (a read, or
                # the same change again: both come to the same); a slave that stays silent fails
                if attempt < DS47_REPEATS:
                    continue
                raise DriveError(f"{what}: {e}; a DP-V1 slave leaves data exchange on a class-1 "
                                 "timeout: the station is parameterised again (its outputs at "
                                 "their safe state until then)") from None
            except C1Error as e:
                raise DriveError(f"{what}: {e}") from None
        try:
            res = D.ParamResponse.decode(data)
        except D.Ds47Error as e:
            raise DriveError(f"{what}: the drive's DS47 response is malformed: {e}") from None
        if res.reference != req.reference:
            raise DriveError(f"{what}: DS47 response to request {res.reference}, not "
                             f"{req.reference}")
        return res

    def ds47_read_array(self, pnu: int, count: int, subindex: int = 0) -> list[int]:
        """`count` elements of an array parameter from `subindex` on, in one DS47 request (a
        `dpv1:` card only); ParamError with the drive's error number when it refuses."""
        from profidrive_cli.drives.profidrive import ds47 as D
        d = self.ds47
        if d is None:
            raise DriveError(f"{self.profile.name}: PNU {pnu} as a whole array needs DS47 (dpv1:)")
        self._ds47_ref = self._ds47_ref % 255 + 1
        req = D.read_request(self._ds47_ref, d.axis, [D.ParamAddress(pnu, subindex, count)])
        res = self._ds47_exchange(req, f"PNU {pnu}[{subindex}..{subindex + count - 1}]")
        item = res.items[0] if res.items else None
        if isinstance(item, D.ParamFault):
            raise ParamError(f"PNU {pnu}: the drive refused the read: "
                             f"{D.error_text(item.number)}", item.number)
        if not isinstance(item, D.ParamValues) or isinstance(item.values, bytes) \
                or not res.ok:
            raise DriveError(f"PNU {pnu}: DS47 read answered without numeric values")
        return [int(v) for v in item.values]

    def _ds47_signed(self, pnu: int) -> bool:
        """A change request's format: signed when the profile's parameter at this PNU can be < 0."""
        for p in self.profile.parameters.values():
            if p.pnu == pnu and p.min is not None and p.min < 0:
                return True
        return False

    def read_raw(self, pnu: int, subindex: int = 0, array: bool | None = None) -> int:
        if array is None:
            array = pnu in self.cfg.array_pnus
        res = self.request(read_request(pnu, subindex, array))
        if not res.ok:
            raise ParamError(f"PNU {pnu}" + (f"[{subindex}]" if subindex else "")
                             + f": {res.describe_error()}", res.error)
        return res.value

    def write_raw(self, pnu: int, value: int, subindex: int = 0, array: bool | None = None,
                  long: bool = False) -> int:
        if array is None:
            array = pnu in self.cfg.array_pnus
        res = self.request(write_request(pnu, value, subindex, array, long))
        if not res.ok:
            raise ParamError(f"PNU {pnu}" + (f"[{subindex}]" if subindex else "")
                             + f": {res.describe_error()}", res.error)
        return res.value

    def read_param(self, code: str) -> ParamValue:
        return self._read(self.resolve_param(code))

    def read_resolved(self, info: ParamInfo) -> ParamValue:
        return self._read(self._ref(info))

    def _read(self, ref: ParamRef) -> ParamValue:
        if self.ds47 is not None and ref.pnu == PNU_DEVICE_ID and ref.subindex == 0:
            return self._device_identification(ref)
        res = self.request(read_request(ref.pnu, ref.subindex, ref.array))
        if not res.ok:
            raise ParamError(f"{ref.label}: the drive refused the read: {res.describe_error()}",
                             res.error)
        return self._param_value(ref, res.value)

    def _device_identification(self, ref: ParamRef) -> ParamValue:
        """PNU 964 over DS47 read as the whole array (one request, subindex 0 on): the value is
        subindex 0 (the manufacturer id), the text the identification in words."""
        from profidrive_cli.drives.profidrive import ds47 as D
        count = int(ref.param.extra.get("array", 6)) if ref.param is not None else 6
        values = self.ds47_read_array(ref.pnu, max(5, min(count, 6)))
        try:
            ident = D.device_identification(values)
        except D.Ds47Error as e:
            raise DriveError(f"{ref.label}: {e}") from None
        date = ident["firmware_date"] or f"{ident['firmware_year']} {values[4]:04d}"
        text = (f"manufacturer {values[0]}, drive unit type 0x{values[1]:04X}, firmware "
                f"{ident['firmware_version']} of {date}")
        if ident["drive_objects"] is not None:
            n = ident["drive_objects"]
            text += f", {n} drive object" + ("" if n == 1 else "s")
        pv = self._param_value(ref, values[0])
        pv.text = text
        return pv

    def _param_value(self, ref: ParamRef, wire: int) -> ParamValue:
        raw = wire & 0xFFFF if ref.size == 16 else wire & 0xFFFFFFFF
        value = self.raw_to_value(ref, raw)
        unit = ref.param.unit if ref.param is not None else ""
        return ParamValue(ref.code, ref.name, raw, value, unit)

    def write_refusal(self, info: ParamInfo, kind: str, message: str) -> Exception:
        """A write refused before sending, numbered as the card numbers it (pkw.error_numbers:
        read_only, out_of_range)."""
        return ParamError(message, self.cfg.error_numbers.get(kind))

    def write_resolved(self, info: ParamInfo, value: float | int) -> ParamValue:
        return self._write(self._ref(info), value)

    def _write(self, ref: ParamRef, value: float | int) -> ParamValue:
        """Write a checked value to `ref`, then read it back."""
        p = ref.param
        raw = self.value_to_raw(ref, value)
        res = self.request(write_request(ref.pnu, raw, ref.subindex, ref.array, ref.size == 32))
        if not res.ok:
            raise ParamError(self.write_refused_message(ref, value, res), res.error)
        if self.profile.max_frequency_param and ref.param is not None \
                and ref.code == self.profile.max_frequency_param:
            self._fmax = None
        if p is not None and p.access == "wo":
            return self._param_value(ref, raw)
        return self._read(ref)

    def save(self) -> None:
        if self.cfg.save_pnu is None:
            raise DriveError(f"{self.profile.name}: this card has no separate save command")
        for frame in save_requests(self.cfg.save_pnu):
            res = self.request(frame)
            if not res.ok:
                raise ParamError(f"save (PNU {self.cfg.save_pnu} 0 -> 1): {res.describe_error()}",
                                 res.error)

    def alarm_record(self, position: str, raw: int) -> FaultRecord:
        if raw == 0:
            return FaultRecord(position, 0, [], ["no fault"])
        alarms = self.profile.alarms_for(raw)
        if not alarms:
            return FaultRecord(position, raw, [f"?{raw}"], [f"unknown fault number {raw}"])
        return FaultRecord(position, raw, [a.code for a in alarms], [a.meaning for a in alarms])

    def fault_history(self) -> list[FaultRecord]:
        out = []
        for pos, frame in fault_memory_requests(self.cfg):
            res = self.request(frame)
            if not res.ok:
                raise ParamError(f"fault memory PNU {frame.pnu}[{frame.subindex}]: "
                                 f"{res.describe_error()}", res.error)
            rec = self.alarm_record(pos, res.value & 0xFFFF)
            if not rec.empty:            # 0 = no fault in the slot (Moeller manual Table 8, L735)
                out.append(rec)
        return out

    def max_frequency(self) -> float:
        if self._fmax is None:
            if self.has_param_channel and self.profile.max_frequency_param:
                self._fmax = float(self.read_param(self.profile.max_frequency_param).value)
            else:
                self._fmax = float(self.profile.max_frequency_default)
        return self._fmax

    def card_info(self) -> dict[str, object]:
        """PNU 918 address, 963 baud, 964 device, 965 profile, 927/928 rights, 967/968 last words.
        Entries the card does not support are None."""
        out: dict[str, object] = {}
        for key, pnu in (("node_address", PNU_NODE_ADDRESS), ("baud", PNU_BAUD),
                         ("device", PNU_DEVICE_ID), ("profile_version", PNU_PROFILE),
                         ("edit_rights", PNU_EDIT_RIGHTS), ("control_rights", PNU_CONTROL_RIGHTS),
                         ("control_word", PNU_CONTROL_WORD), ("status_word", PNU_STATUS_WORD)):
            try:
                v = self.read_raw(pnu) & 0xFFFF
            except ParamError:
                out[key] = None
                continue
            if key == "baud" and self.cfg.baud_codes:
                out[key] = decode_baud(v, self.cfg)
            elif key == "device" and self.cfg.device_ids:
                out[key] = f"0x{v:04X} ({decode_device_id(v, self.cfg)})"
            elif key in ("control_word", "status_word", "device"):
                out[key] = f"0x{v:04X}"
            else:
                out[key] = v
        return out

    # -- PZD3.. ------------------------------------------------------------------------------
    def set_pzd(self, n: int, raw: int) -> None:
        """Set output word PZDn (n >= 3) to a raw value."""
        if not 3 <= n < 3 + len(self.pzd_out):
            raise DriveError(f"layout {self.layout} has no output PZD{n}")
        self.pzd_out[n - 3] = raw & 0xFFFF

    def pzd_mapping(self, direction: str) -> list[int]:
        n = (self.ppo.pzd_out if direction == "setpoint" else self.ppo.pzd_in) - 2
        pnu = pzd_map_pnu(direction, self.cfg)
        return [self.read_raw(pnu, i, array=True) & 0xFFFF for i in range(1, n + 1)]

    def map_pzd(self, direction: str, slot: int, pnu: int) -> None:
        res = self.request(pzd_map_write(direction, slot, pnu, self.cfg))
        if not res.ok:
            raise ParamError(f"PZD{slot + 2} mapping: {res.describe_error()}", res.error)

    def pzd_input_count(self) -> int:
        return int(self.ppo.pzd_in)

    def last_pzd(self) -> list[int] | None:
        return self.last_area.pzd if self.last_area is not None else None

    def param_from_word(self, code: str, raw: int) -> ParamValue:
        return self._param_value(self.resolve_param(code), raw)

    # -- motion ------------------------------------------------------------------------------
    def _ensure_fmax(self) -> None:
        """Learn the drive's max frequency once (PKW or DS47), else fall back to the profile
        default (a card that refuses or does not answer the read)."""
        if self.has_param_channel and self._fmax is None:
            try:
                self.max_frequency()
            except DriveError as e:
                self._fmax = float(self.profile.max_frequency_default)
                self.fmax_unread = str(e)
            else:
                self.fmax_unread = None          # read now (again, after a write of it)

    def status(self) -> DriveStatus:
        self._ensure_fmax()
        st = self.cycle()
        if st.fault and self.has_param_channel:
            try:
                rec = self.alarm_record("current", self.read_raw(
                    self.cfg.fault_memory_pnu, self.cfg.fault_subindexes[0], array=True) & 0xFFFF)
                st.fault_code = "/".join(rec.codes) or None
            except DriveError:
                pass
        return st

    def set_speed(self, percent: float) -> None:
        self.reference = n2_from_percent(percent)
        self.cycle()

    @property
    def supports_jog(self) -> bool:        # type: ignore[override]
        return self.cfg.jog_reference is not None

    def jog_refusal(self) -> str:
        return self._no_jog_words(self.profile)

    @staticmethod
    def _no_jog_words(profile: Any) -> str:
        return (f"{profile.name}: the profile names no jog function (profidrive: jog_reference), so "
                f"pdrive does not set CTW bit 8")

    @classmethod
    def jog_refusal_for(cls, profile: Any, layout: str) -> str | None:
        return None if config(profile).jog_reference is not None else cls._no_jog_words(profile)

    @classmethod
    def status_flag_names(cls, profile: Any, layout: str) -> list[str]:
        """The status word's named bits (profidrive stw names), then the family's extras."""
        names = config(profile).stw_names
        return [names[b] for b in sorted(names)] + cls.extra_flag_names(profile, layout)

    @classmethod
    def normalise_area(cls, profile: Any, direction: str, area: dict[str, Any]) -> dict[str, Any]:
        """CTW/STW, N2 reference / actual in Hz and the PKW channel (describe.ppo_drive_object)."""
        return ppo_drive_object(direction, area)

    @classmethod
    def extra_flag_names(cls, profile: Any, layout: str) -> list[str]:
        """Flags status_extras() adds (none in the plain PROFIdrive core)."""
        return []

    def jog_reference(self) -> str | None:
        return self.cfg.jog_reference

    def ramp_param(self, role: str) -> str | None:
        """The profile's `profidrive.ramps` code for `role`, else the card's own (ramp_codes)."""
        return self.cfg.ramps.get(role) or self.ramp_codes.get(role)

    def jog(self, on: bool = True, reverse: bool = False) -> None:
        """Jog 1 (CTW bit 8) from the operation state with a zero reference; a card without a jog
        reference (or without jog) refuses (supports_jog, jog_refusal)."""
        if not self.supports_jog:
            raise DriveError(self.jog_refusal())
        if reverse:
            raise DriveError(f"{self.family}: this card has no reverse jog")
        if on:
            self._notify_motion()
            self.reference = 0
            self.extra_bits |= int(Ctw.JOG1)
            self.target = Target.OPERATE
        else:
            self.extra_bits &= ~int(Ctw.JOG1 | Ctw.JOG2)
        self.cycle()

    def _go(self, target: Target, timeout: float, what: str, hint: bool = False) -> DriveStatus:
        self.target = target
        try:
            return self.cycles_until(
                lambda st: target_reached(st.raw["status_word"], target,
                                          moving=abs(st.speed_percent or 0) > 0), timeout, what)
        except DriveError as e:
            if hint and self.last_status is not None:
                raise DriveError(f"{e}; {self.start_hint(self.last_status)}") from None
            raise

    def start(self, timeout: float = 5.0) -> DriveStatus:
        self._notify_motion()
        st = self.cycle()
        if st.fault:
            raise DriveError("the drive is in fault: acknowledge it first (reset)")
        if self.has_param_channel and self._fmax is None:
            self.max_frequency()
        return self._go(Target.OPERATE, timeout, "operation", hint=True)

    def stop(self, mode: str = "normal", wait: bool = True, timeout: float = 30.0) -> DriveStatus:
        target = {"normal": Target.OFF1, "ramp": Target.OFF1, "off1": Target.OFF1,
                  "quick": Target.OFF3, "off3": Target.OFF3,
                  "coast": Target.OFF2, "off2": Target.OFF2}.get(mode)
        if target is None:
            raise UsageError(f"stop mode must be normal, quick or coast, got {mode!r}")
        self.extra_bits &= ~int(Ctw.JOG1 | Ctw.JOG2)       # a stop ends a jog too
        self.target = target
        st = self.cycle()
        if not wait:
            return st
        return self.cycles_until(
            lambda s: s.fault or (s.stopped and target_reached(
                s.raw["status_word"], target, moving=abs(s.speed_percent or 0) > 0)),
            timeout, f"the drive to stop ({mode})")

    def reset_fault(self, timeout: float = 5.0) -> DriveStatus:
        st = self.cycle()
        if not st.fault:
            return st
        self.target = Target.ACK
        return self.cycles_until(lambda s: not s.fault, timeout,
                                 "the fault to clear (is its cause still present?)")


def make_drive(channel: CyclicChannel, profile: Profile, layout: str | None = None) -> ProfidriveDrive:
    """Family `profidrive`: a plain PROFIdrive V2 drive configured only by its profile."""
    return ProfidriveDrive(channel, profile, layout)
