"""YaskawaDrive: the Drive interface (drives/base.py) over a CyclicChannel for the SI-P1 card.

Couples the sans-IO codec and ParamAccess machine with the channel: builds the output image each
cycle, decodes the status, runs parameter requests through the handshake. May touch: drives/base,
drives/values, drives/torque, and this package's codec, paramaccess, config and describe
(drive_object).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Iterable, Iterator, Sequence

from profidrive_cli import UsageError
from profidrive_cli.drives.base import (CyclicChannel, Drive, DriveError, DriveStatus, FaultRecord, ParamError,
                                        ParamInfo, ParamValue, Reaction)
from profidrive_cli.drives.torque import capability_refusal, torque_counts
from profidrive_cli.drives.yaskawa.codec import (COMMAND_BITS, FORMATS, STATUS_BITS, FrequencyScale, _s16,
                                                 decode_status, mfi_bit, pack_words, unpack_words)
from profidrive_cli.drives.yaskawa.config import family_config, parse_register_code, register_name
from profidrive_cli.drives.yaskawa.describe import drive_object
from profidrive_cli.drives.yaskawa.paramaccess import (ParamAccess, ParamRequest, ParamResult, error_text,
                                                       refusal_words)

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import ParamDef, Profile

FAMILY = "yaskawa"

TORQUE_RES = 0.1                   # % per count (spec §2.4 / §2.7: 0.1 %)


#: F6-01, the reaction to a communication error (SI-P1 / drive manuals)
_F601 = {0: ("ramp", "C1-02", "ramp to stop with C1-02, then the BUS fault"),
         1: ("coast", None, "coast to stop and trip BUS"),
         2: ("ramp", "C1-09", "fast stop with C1-09, then the BUS fault"),
         3: ("none", None, "alarm only: BUS is shown and the drive keeps running")}


class YaskawaDrive(Drive):
    family = FAMILY
    supports_jog = False
    area_shape = "memobus"
    #: C1-01 acceleration time 1, C1-02 deceleration time 1 (from 0 to the max frequency)
    ramp_codes = {"accel": "C1-01", "decel": "C1-02"}
    comm_loss_words = ("a BUS fault after the option's communication timeout (the drive stops by its BUS "
                       "fault setting)")

    @classmethod
    def audit_rules(cls, profile: Any) -> list[Any]:
        from profidrive_cli.drives.yaskawa.audit import audit_rules      # cited rules (pdrive audit)
        return audit_rules(profile)

    def jog_refusal(self) -> str:
        return self._no_jog_words(self.profile)

    @staticmethod
    def _no_jog_words(profile: Any) -> str:
        return (f"{profile.name}: the SI-P1 run command word has no jog bit (bit 0 forward run, bit 1 "
                f"reverse run, the others multi-function inputs whose function the drive's own H1 settings "
                f"choose); use run with a low speed instead")

    @classmethod
    def jog_refusal_for(cls, profile: Any, layout: str) -> str | None:
        return cls._no_jog_words(profile)

    @classmethod
    def normalise_area(cls, profile: Any, direction: str, area: dict[str, Any]) -> dict[str, Any]:
        """Run command / status flags, Hz and the MEMOBUS parameter area (describe.drive_object)."""
        return drive_object(profile, direction, area)

    @classmethod
    def status_flag_names(cls, profile: Any, layout: str) -> list[str]:
        return list(STATUS_BITS)              # the status word's bits (spec 2.5), whatever the layout

    def __init__(self, channel: CyclicChannel, profile: Profile, layout: str | None = None):
        super().__init__(channel, profile, layout)
        if self.layout not in profile.layouts or self.layout not in FORMATS:
            raise UsageError(f"{profile.name}: no layout '{self.layout}' (known: {', '.join(profile.layouts)})")
        self.cfg = family_config(profile)
        self.fmt = FORMATS[self.layout]
        self.order = profile.word_order
        # the handshake takes align (1) + settle_cycles + the toggle (1) + the reply (1) exchanges
        # (spec §4.7); a request times out after timeout_s only once twice that many exchanges went,
        # so a slow cycle (several stations at 9.6k) never times out a handshake still under way
        min_exchanges = 2 * (self.cfg.settle_cycles + 3)
        self.params = (ParamAccess(self.fmt, self.cfg.timeout_s, self.cfg.settle_cycles,
                                   min_exchanges=min_exchanges)
                       if self.fmt.has_params else None)
        self._result: ParamResult | None = None
        # command state
        self._run = False
        self._ref_percent = 0.0
        self._ref_raw = 0
        self._base_block = False
        self._fast_stop = False
        self._external_fault = False
        self._mfi: set[int] = set()
        self._pulses: dict[int, int] = {}
        self.torque_reference = 0.0          # % (flux vector only): reference, or limit in speed control
        self.torque_compensation = 0.0       # % (extended1 bytes 6-7, flux vector only)
        self._torque_mode = False            # run --torque (else the word is a limit, or 0)
        # cached drive settings (read through the handshake when there is a parameter channel)
        self._fmax: float | None = None
        self._o1_03: int | None = None
        self.last: DriveStatus | None = None

    # -- cyclic --------------------------------------------------------------------------------
    @property
    def has_param_channel(self) -> bool:
        return self.fmt.has_params

    def command_word(self) -> int:
        w = 0
        if self._run:
            rev = self.torque_reference < 0 if self._torque_mode else self._ref_percent < 0
            w |= 1 << (COMMAND_BITS["reverse_run"] if rev else COMMAND_BITS["forward_run"])
        if self._base_block:
            w |= 1 << COMMAND_BITS["external_base_block"]
        if self._external_fault:
            w |= 1 << COMMAND_BITS["external_fault"]
        for n in self._mfi:
            w |= 1 << mfi_bit(n)
        if self._fast_stop and self.cfg.fast_stop_input:
            w |= 1 << mfi_bit(self.cfg.fast_stop_input)
        for bit, left in self._pulses.items():
            if left > 0:
                w |= 1 << bit
        return w

    def output_image(self) -> bytes:
        vals = {"command": self.command_word(), "reference": self._ref_raw,
                "torque_reference": int(round(self.torque_reference * 10)) & 0xFFFF,
                "torque_compensation": int(round(self.torque_compensation * 10)) & 0xFFFF}
        img = pack_words([vals.get(n, 0) for n in self.fmt.out_words], self.order)
        if self.params is not None and self.fmt.param_offset is not None:     # (both or neither)
            img += bytes(self.fmt.param_offset - len(img)) + self.params.outputs()
        return img

    def cycle(self) -> DriveStatus:
        inputs = self.channel.exchange(self.output_image())
        if len(inputs) != self.fmt.size:
            raise DriveError(f"yaskawa {self.layout}: station answered {len(inputs)} octets, "
                             f"expected {self.fmt.size}")
        for bit in list(self._pulses):
            self._pulses[bit] -= 1
            if self._pulses[bit] <= 0:
                del self._pulses[bit]
        if self.params is not None:
            r = self.params.feed(inputs[self.fmt.param_offset:], self.channel.now())
            if r is not None:
                self._result = r
        self.last = self._decode(inputs)
        return self.last

    def _scale(self) -> FrequencyScale:
        o1 = self._o1_03 if self._o1_03 is not None else self.cfg.o1_03
        fmax = self._fmax if self._fmax is not None else float(self.profile.max_frequency_default)
        return FrequencyScale(o1, fmax, self.cfg.reference_unit_hz, self.cfg.feedback_unit_hz)

    def _decode(self, inputs: bytes) -> DriveStatus:
        names = self.fmt.in_words
        words = dict(zip(names, unpack_words(inputs[:2 * len(names)], self.order)))
        fl = decode_status(words["status"])
        scale = self._scale()
        hz = scale.raw_to_hz(words["speed_feedback"], "feedback")
        if fl["reverse"]:
            hz = -hz
        pct = round(100.0 * hz / scale.max_hz, 3) if scale.max_hz else None
        ref_pct = self._ref_percent
        if "frequency_reference" in words and scale.max_hz:
            ref_hz = scale.raw_to_hz(words["frequency_reference"], "feedback")
            ref_pct = round(100.0 * ref_hz / scale.max_hz * (-1 if self._ref_percent < 0 else 1), 3)
        if fl["fault"]:
            state = "fault"
        elif fl["ope_error"]:
            state = "OPE setting error"
        elif fl["running"]:
            state = "running reverse" if fl["reverse"] else "running forward"
        elif self._base_block:
            state = "base block"
        elif not fl["ready"]:
            state = "not ready"
        else:
            state = "stopped"
        st = DriveStatus(state=state, running=fl["running"], fault=fl["fault"], flags=fl,
                         speed_percent=pct, speed_hz=hz, reference_percent=ref_pct,
                         raw=dict(words))
        if "torque_reference" in words:          # extended1 input bytes 4-5 (spec §2.4), 0.1 % presumed
            st.torque_percent = round(_s16(words["torque_reference"]) * TORQUE_RES, 3)
        if self._torque_mode:
            st.torque_ref_percent = self.torque_reference
        return st

    # -- motion --------------------------------------------------------------------------------
    def _hint_not_remote(self, st: DriveStatus) -> str:
        if st.flags.get("remote"):
            return ""
        return ("; the status word says local: the drive takes its run command from the bus only "
                "when b1-02 = 3 (option card)")

    def start(self, timeout: float = 5.0) -> DriveStatus:
        self._notify_motion()
        st = self.cycle()
        if st.fault:
            raise DriveError("yaskawa: the drive is in fault; reset it first (pdrive reset)")
        self._prepare_reference()
        self._base_block = False
        self._fast_stop = False
        self._run = True
        try:
            st = self.cycles_until(lambda s: s.running or s.fault, timeout, "the drive to run")
        except DriveError as e:
            raise DriveError(f"{e}{self._hint_not_remote(self.last or st)}") from None
        if st.fault:
            self._run = False
            raise DriveError(f"yaskawa: the drive tripped while starting{self._fault_suffix()}")
        return st

    def stop(self, mode: str = "normal", wait: bool = True, timeout: float = 30.0) -> DriveStatus:
        if self._torque_mode:
            self._torque_mode = False       # no torque from the bus; the run bit off stops by b1-03
            self.torque_reference = 0.0
        if mode == "quick":
            if self.cfg.fast_stop_input is None:
                # the words of the profile's capabilities (the same refusal as checklist validate)
                raise DriveError(self.profile.capabilities.refusal("quick_stop", self.layout)
                                 or "yaskawa SI-P1: the command word has no fast-stop bit")
            self._fast_stop = True
        elif mode == "coast":
            self._base_block = True     # external base block: output cut, the motor coasts
        elif mode != "normal":
            raise UsageError(f"stop mode must be normal, quick or coast, got {mode!r}")
        self._run = False               # run bit off: the drive stops by b1-03 (ramp by default)
        if not wait:
            return self.cycle()
        st = self.cycles_until(lambda s: (not s.running and s.flags["zero_speed"]) or s.fault,
                               timeout, "the drive to stop")
        self._fast_stop = False
        return st

    # -- torque (spec §2.4, §2.6: bytes 4-5 torque reference / limit, 6-7 compensation, 0.1 %) -----
    def torque_support(self) -> str | None:
        if "torque_reference" in self.fmt.out_words:
            return None
        return (f"yaskawa: layout {self.layout} has no torque word (the basic and extended1 layouts "
                f"have one)")

    def torque_limit_support(self) -> str | None:
        # basic bytes 4-5 are a torque reference only (yaskawa-profibus-dp.md L412); the limit /
        # compensation words are extended1's (L341-342): the profile's torque_limit capability says where
        return self.torque_support() or capability_refusal(self.profile, "torque_limit", self.layout)

    def torque_resolution(self) -> float:
        return TORQUE_RES

    def _check_flux_vector(self) -> None:
        p = self.profile.param("A1-02")
        if not self.has_param_channel or p is None or p.register is None:
            return
        a102 = int(self.read_param("A1-02").raw)
        if a102 != 3:
            raise DriveError(f"yaskawa: the torque word acts only in flux vector control (A1-02 = 3); "
                             f"the drive has A1-02 = {a102}")

    def set_torque(self, percent: float | None) -> None:
        why = self.torque_support()
        if why:
            raise DriveError(why)
        if percent is None:
            self._torque_mode = False
            self.torque_reference = 0.0
        else:
            counts = torque_counts(percent, TORQUE_RES)
            self._check_flux_vector()
            self._torque_mode = True
            self.torque_reference = round(counts * TORQUE_RES, 1)
        self.cycle()

    def set_torque_limit(self, percent: float | None) -> None:
        why = self.torque_limit_support()
        if why:
            raise DriveError(why)
        if percent is not None and percent <= 0:
            raise UsageError(f"--torque-limit {percent:g} %: must be above 0 %")
        counts = torque_counts(percent, TORQUE_RES, "--torque-limit") if percent is not None else 0
        if percent is not None:
            self._check_flux_vector()
        self._torque_mode = False
        self.torque_reference = round(counts * TORQUE_RES, 1)
        self.cycle()

    def torque_notes(self) -> list[str]:
        notes = ["the SI-P1 torque word is a torque reference in torque control (d5-01 = 1 on the drive) "
                 "and a torque limit in speed control, in flux vector control only (A1-02 = 3); in torque "
                 "control the drive limits the speed as d5-03 says (1 = by the frequency reference: give "
                 "--hz as the speed limit)"]
        if not self.has_param_channel:
            notes.append(f"layout {self.layout} has no parameter channel: A1-02 was not checked")
        return notes

    def set_speed(self, percent: float) -> None:
        if not -100.0 <= percent <= 100.0:
            raise UsageError(f"speed {percent:g} % is outside -100..100 % of the maximum frequency")
        self._ref_percent = float(percent)
        self._prepare_reference()

    def _prepare_reference(self) -> None:
        if self.has_param_channel:
            self._read_units()
        scale = self._scale()
        hz = abs(self._ref_percent) / 100.0 * scale.max_hz
        self._ref_raw = min(scale.hz_to_raw(hz, "reference"), 0xFFFF)

    def _read_units(self) -> None:
        if self._fmax is None:
            self._fmax = self.max_frequency()
        if self._o1_03 is None:
            p = self.profile.param("o1-03")
            self._o1_03 = int(self.read_param("o1-03").raw) if p is not None and p.register is not None \
                else self.cfg.o1_03

    def set_mfi(self, n: int, on: bool) -> None:
        """Multi-function input n (3..12) of the command word (its function is set in the drive)."""
        mfi_bit(n)
        (self._mfi.add if on else self._mfi.discard)(n)

    def external_fault(self, on: bool = True) -> None:
        """Command-word bit 8: the drive trips with EF0 while it is set."""
        self._external_fault = on

    def reset_fault(self, timeout: float = 5.0) -> DriveStatus:
        self._run = False
        self._external_fault = False
        self._pulses[COMMAND_BITS["fault_reset"]] = 2     # a pulse, never left set
        while self._pulses:
            self.cycle()
        try:
            return self.cycles_until(lambda s: not s.fault, timeout, "the fault to clear")
        except DriveError:
            raise DriveError(f"yaskawa: the fault is still present after the reset pulse; remove its "
                             f"cause first{self._fault_suffix()}") from None

    def clear_error_log(self) -> None:
        """Pulse command-word bit 14 (Clear Error Log)."""
        self._pulses[COMMAND_BITS["clear_error_log"]] = 2
        while self._pulses:
            self.cycle()

    def status(self) -> DriveStatus:
        st = self.cycle()
        if st.fault and self.has_param_channel:
            code = self._current_fault_code()
            if code:
                st.fault_code = code
        return st

    def _current_fault_code(self) -> str | None:
        cur = next((c for pos, c in self.cfg.fault_history if pos == "current"), None)
        if cur is None:
            return None
        try:
            raw = self.read_param(cur).raw
        except DriveError:
            return None
        if not raw:
            return None
        al = self.profile.alarms_for(raw)
        return "/".join(a.code for a in al) if al else f"0x{raw:04X}"

    def _fault_suffix(self) -> str:
        if not self.has_param_channel:
            return ""
        code = self._current_fault_code()
        return f" (fault {code})" if code else ""

    # -- parameters ----------------------------------------------------------------------------
    def _no_channel(self) -> DriveError:
        return DriveError("yaskawa basic layout (3 words) has no parameter access; configure "
                          "extended1 (16 words) or extended2 (6 words)")

    def _transact(self, req: ParamRequest) -> ParamResult:
        if self.params is None:
            raise self._no_channel()
        self._result = None
        self.params.submit(req, self.channel.now())
        while self._result is None:
            self.cycle()
        r, self._result = self._result, None
        if r.timeout:
            raise DriveError(f"yaskawa: {r.message}")
        if not r.ok:
            raise ParamError(f"yaskawa: {r.message}", r.error_code)
        return r

    def read_registers(self, start: int, count: int = 1) -> list[int]:
        """Read `count` consecutive MEMOBUS registers (extended1: up to 4 per request)."""
        if self.params is None:
            raise self._no_channel()
        out: list[int] = []
        while count > 0:
            n = min(count, self.fmt.max_registers)
            out += self._transact(ParamRequest.read(start, n)).values
            start, count = start + n, count - n
        return out

    def write_registers(self, start: int, values: Iterable[int]) -> None:
        if self.params is None:
            raise self._no_channel()
        values = list(values)
        while values:
            chunk, values = values[:self.fmt.max_registers], values[self.fmt.max_registers:]
            self._transact(ParamRequest.write(start, chunk))
            start += len(chunk)

    def param_info(self, code: str) -> ParamInfo:
        reg, p = self._resolve(code)          # MEMOBUS register
        if p is None:
            return ParamInfo(f"REG0x{reg:04X}", "MEMOBUS register", "", None, "raw", reg)
        return ParamInfo(p.code, p.name, p.unit, p, p.access, reg)

    @classmethod
    def param_label_for(cls, profile: Any, code: str) -> tuple[str, Any]:
        if profile.param(code) is None:
            reg = parse_register_code(code)
            if reg is not None and 0 <= reg <= 0xFFFF:
                return f"REG0x{reg:04X}", None
        return super().param_label_for(profile, code)

    def params_at(self, info: ParamInfo) -> list[Any]:
        reg = info.ref if isinstance(info.ref, int) else self._resolve(info.code)[0]
        return [q for q in self.profile.parameters.values() if q.register == reg]

    def save_support(self) -> str:
        return "command" if self.cfg.enter_register is not None else "unsupported"

    def input_words(self) -> tuple[str, ...]:
        return tuple(self.fmt.in_words)

    def last_seen(self) -> DriveStatus | None:
        return self.last

    def cycle_words(self, outputs: bytes, inputs: bytes) -> tuple[int | None, int | None,
                                                                   int | None, int | None]:
        fmt, order = self.fmt, self.profile.word_order                # the fast I/O words
        ow = [int.from_bytes(outputs[i:i + 2], order) for i in range(0, 2 * len(fmt.out_words), 2)]
        iw = [int.from_bytes(inputs[i:i + 2], order) for i in range(0, 2 * len(fmt.in_words), 2)]
        o = dict(zip(fmt.out_words, ow))
        n = dict(zip(fmt.in_words, iw))
        return o.get("command"), o.get("reference"), n.get("status"), n.get("speed_feedback")

    def comm_loss_reaction(self) -> Reaction | None:
        """F6-01 (+ C1-02 / C1-09 for the ramp)."""
        if self.profile.param("F6-01") is None:
            return Reaction("BUS fault (the profile has no F6-01: assumed coast)", "trip", alarm="BUS")
        f601 = int(self.read_param("F6-01").raw)
        stop, ramp_code, words = _F601.get(f601, ("coast", None, "outside 0..3: assumed coast"))
        settings: dict[str, float] = {"F6-01": f601}
        decel = None
        if ramp_code:
            decel = float(self.read_param(ramp_code).value)
            settings[ramp_code] = decel
        return Reaction(f"F6-01 = {f601}: {words}", "trip" if stop == "coast" else stop,
                        alarm=None if stop == "none" else "BUS", decel_s=decel, settings=settings)

    def zero_data_reaction(self, head: str) -> Reaction | None:
        if self.can_read("b1-03") and int(self.read_param("b1-03").raw) == 1:
            return Reaction(head + "; b1-03 = 1: coast to stop", "coast", settings={"b1-03": 1})
        return None

    def dumpable(self, p: Any) -> bool:
        return p.register is not None            # MEMOBUS registers, not PNUs

    def _resolve(self, code: str) -> tuple[int, ParamDef | None]:
        reg = parse_register_code(code)
        if reg is not None:
            if reg > 0xFFFF:
                raise UsageError(f"{code}: register numbers are 16 bits")
            return reg, None
        p = self.profile.param(code)
        if p is None:
            raise UsageError(f"{self.profile.name}: unknown parameter {code!r} (use a code from the "
                             f"profile or a raw register such as REG0x0180)")
        if p.register is None:
            raise DriveError(f"{p.code}: the profile gives no MEMOBUS register for it")
        return p.register, p

    def read_param(self, code: str) -> ParamValue:
        if self.params is None:
            raise self._no_channel()
        return self.read_resolved(self.param_info(code))

    def read_resolved(self, info: ParamInfo) -> ParamValue:       # (read_registers: the channel)
        reg, p = (info.ref, info.param) if isinstance(info.ref, int) else self._resolve(info.code)
        return self._value(reg, p, self.read_registers(reg, 1)[0])

    def read_many(self, codes: Sequence[str]) -> Iterator[tuple[str, ParamValue | DriveError | UsageError]]:
        """Runs of codes whose registers follow each other (b1-01, b1-02, b1-03) in one transaction
        of up to fmt.max_registers (16-word format: 4; manual Table 3.5, "1-4 consecutive
        registers"); a run the drive refuses is read again one code at a time, so each refusal is
        the code's own (a run that gets no answer at all is that error for each of its codes)."""
        if self.params is None or self.fmt.max_registers < 2:
            yield from super().read_many(codes)
            return
        items: list[tuple[str, int, ParamDef | None]] = []
        for code in codes:
            try:
                reg, p = self._resolve(code)
            except (DriveError, UsageError) as e:
                yield from self._read_run(items)
                items = []
                yield code, e
                continue
            if items and (reg != items[-1][1] + 1 or len(items) >= self.fmt.max_registers):
                yield from self._read_run(items)
                items = []
            items.append((code, reg, p))
        yield from self._read_run(items)

    def _read_run(self, run: list[tuple[str, int, ParamDef | None]]
                  ) -> Iterator[tuple[str, ParamValue | DriveError | UsageError]]:
        if not run:
            return
        if len(run) > 1:
            try:
                raws = self.read_registers(run[0][1], len(run))
            except ParamError:
                pass                                # each on its own below: whose refusal it is
            except (DriveError, UsageError) as e:   # no answer: none of them was read
                for code, _, _ in run:
                    yield code, e
                return
            else:
                for (code, reg, p), raw in zip(run, raws):
                    yield code, self._value(reg, p, raw)
                return
        for code, reg, p in run:
            try:
                yield code, self._value(reg, p, self.read_registers(reg, 1)[0])
            except (DriveError, UsageError) as e:
                yield code, e

    def _value(self, reg: int, p: ParamDef | None, raw: int) -> ParamValue:
        if p is None:
            n = register_name(self.profile, reg)
            return ParamValue(code=f"REG0x{reg:04X}", name=f"MEMOBUS register{' (' + n + ')' if n else ''}",
                              raw=raw, value=raw)
        return ParamValue(code=p.code, name=p.name, raw=raw, value=p.from_raw(raw), unit=p.unit)

    def write_resolved(self, info: ParamInfo, value: float | int) -> ParamValue:
        if self.params is None:
            raise self._no_channel()
        reg, p = (info.ref, info.param) if isinstance(info.ref, int) else self._resolve(info.code)
        code = info.code
        if p is not None:
            raw = p.to_raw(value)
            if p.signed and raw < 0:
                raw += 0x10000
        else:
            if float(value) != int(value):
                raise UsageError(f"{code}: raw register values are integers, got {value!r}")
            raw = int(value)
        if not 0 <= raw <= 0xFFFF:
            raise UsageError(f"{code}: {value!r} does not fit a 16-bit register")
        # The profile's limits were checked before (Drive.value_problem: exact value, listed codes,
        # min..max, 16 bits); the drive's own limits (they differ between F7, G7, P7 and depend on
        # other settings) may be narrower: its refusal (0x21 / 0x22) is explained below.
        try:
            self.write_registers(reg, [raw])
        except ParamError as e:
            running = self.last is not None and self.last.running
            raise ParamError(refusal_words(code, p, value, e.number, running), e.number) from None
        if p is not None and p.code.upper() in ("E1-04", "O1-03") or reg in self._unit_registers():
            self._fmax = None
            self._o1_03 = None
        return self.read_resolved(info)

    def _unit_registers(self) -> set[int]:
        regs = set()
        for c in ("E1-04", "o1-03"):
            p = self.profile.param(c)
            if p is not None and p.register is not None:
                regs.add(p.register)
        return regs

    def save(self) -> None:
        """Write the ENTER command register (stores the parameters in the drive's EEPROM)."""
        if self.params is None:
            raise self._no_channel()
        if self.cfg.enter_register is None:
            raise DriveError("yaskawa: the profile names no ENTER command register "
                             "(yaskawa.enter_register); the SI-P1 manual does not give one")
        try:
            self.write_registers(self.cfg.enter_register, [0])
        except ParamError as e:
            raise ParamError(f"yaskawa: ENTER (register 0x{self.cfg.enter_register:04X}) refused: "
                             f"{error_text(e.number or 0)}", e.number) from None

    def fault_history(self) -> list[FaultRecord]:
        if self.params is None:
            raise self._no_channel()
        if not self.cfg.fault_history:
            raise DriveError("yaskawa: the profile names no fault registers (yaskawa.fault_history)")
        regs = [(pos, self.profile.param(c).register) for pos, c in self.cfg.fault_history]
        values = self._read_many([r for _, r in regs])
        out = []
        for pos, reg in regs:
            raw = values[reg]
            if not raw:
                continue
            al = self.profile.alarms_for(raw)
            if al:
                out.append(FaultRecord(pos, raw, [a.code for a in al], [a.meaning for a in al]))
            else:
                out.append(FaultRecord(pos, raw, [f"0x{raw:04X}"],
                                       ["not in the profile's fault table (see the drive's MODBUS manual)"]))
        return out

    def _read_many(self, regs: list[int]) -> dict[int, int]:
        """Read a set of registers, grouping consecutive runs up to the format's registers/request."""
        out: dict[int, int] = {}
        todo = sorted(set(regs))
        while todo:
            start = todo[0]
            n = 1
            while n < self.fmt.max_registers and start + n in todo:
                n += 1
            for i, v in enumerate(self.read_registers(start, n)):
                out[start + i] = v
            todo = [r for r in todo if r not in out]
        return out

    def max_frequency(self) -> float:
        if not self.has_param_channel or not self.profile.max_frequency_param:
            return float(self.profile.max_frequency_default)
        if self._fmax is None:
            self._fmax = float(self.read_param(self.profile.max_frequency_param).value)
        return self._fmax


def make_drive(channel: CyclicChannel, profile: Profile, layout: str | None = None) -> YaskawaDrive:
    return YaskawaDrive(channel, profile, layout)
