"""Moeller DE6-NET-DP (DF6/DV6 inverters): the PROFIdrive core plus the card's dialect.

Dialect (profile profiles/moeller-de6-net-dp.yaml, sections `profidrive:` and `moeller:`):
  * parameters by PROFIBUS PNU 1..418 from the cross-reference list (native codes F002, A004, ...),
    1, 2 or 4 octets on the wire (`bytes`), right-aligned in PWE; AK 3 for 4-octet writes, AK 2 else
  * control source: A001 = 2 (operator) lets the bus give the reference, A002 = 1 (terminal) the run
    commands; with those set, STW bit 12 = 1 takes the commands away, bit 13 = 1 the reference,
    bit 10 = 0 both; bit 11 = reverse (direction = sign of HSW XOR bit 11)
  * P002 (slot 2; P001 for slot 1): communication-loss reaction, 0 = trip E7x, 1 = keep running
  * PNU 947 subindexes 1, 9, 17, ..., 49; PNU 964 = 0x812C (DF6) or 0x012C (DV6); PNU 971 0 -> 1 saves
  * DF6 limits: rows marked df6: false are not on a DF6; df6_max lowers the maximum

Module API: make_drive(channel, profile, layout=None), decode_area(profile, layout, direction, data),
speed_plan(profile, layout, direction, max_hz),
param_value(profile, param, raw), moeller_config(profile), source_selection(ctw),
device_name(word), baud_text(code, profile), fault_text(profile, number),
address_from_switches(right, left), value_from_wire(param, raw), wire_from_value(param, value).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from profidrive_cli import UsageError

from profidrive_cli.datafile import DataFileError, LineDict
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.values import value_problem
from profidrive_cli.drives.base import CyclicChannel, DriveError, DriveStatus, ParamError, ParamValue, Reaction
from profidrive_cli.drives.profile import COMMON_EXTRA_KEYS, per_profile
from profidrive_cli.drives.sections import key, key_line, section

if TYPE_CHECKING:
    from profidrive_cli.drives.formats import Formatter
    from profidrive_cli.drives.profile import ParamDef, Profile
    from profidrive_cli.drives.speedplan import SpeedWord

FAMILY_PARAM_KEYS = {"bytes", "format", "ranges", "df6", "df6_max", "note", "array"}
FORMATS = ("code", "hex", "bits", "baud", "alarm947")
_STW_CONTROL_REQUESTED = int(pd.Stw.CONTROL_REQUESTED)


# =============================================================================================
# profile section `moeller:`
# =============================================================================================


@dataclass
class MoellerConfig:
    frequency_param: str = "A001"
    frequency_bus_value: int = 2
    commands_param: str = "A002"
    commands_bus_value: int = 1
    commands_invalid_bit: int = 12
    reference_invalid_bit: int = 13
    reverse_bit: int = 11
    comm_loss_param: str = "P002"
    comm_loss_other_param: str | None = "P001"
    comm_loss_alarm: str = "E70"
    df6_device_id: int = 0x812C
    sim_defaults: dict[Any, Any] | None = None     # code -> number, checked (YAML keys)


def _err(profile: Profile, node: object, key: str, msg: str) -> DataFileError:
    line = node.line_of(key) if isinstance(node, LineDict) else getattr(node, "line", None)
    return DataFileError(profile.path or "<profile>", line, msg)


def _validate_params(profile: Profile) -> None:
    path = profile.path or "<profile>"
    for p in profile.parameters.values():
        b = p.extra.get("bytes")
        if b is None:
            if not p.code.startswith("PNU"):
                raise DataFileError(path, p.line, f"{p.code}: missing 'bytes' (1, 2 or 4)")
        elif b not in (1, 2, 4):
            raise DataFileError(path, p.line, f"{p.code}: bytes must be 1, 2 or 4, got {b!r}")
        elif (b == 4) != (p.size == 32):
            raise DataFileError(path, p.line, f"{p.code}: bytes {b} needs size "
                                f"{32 if b == 4 else 16}, got {p.size}")
        fmt = p.extra.get("format")
        if fmt is not None and fmt not in FORMATS:
            raise DataFileError(path, p.line, f"{p.code}: format must be one of "
                                f"{', '.join(FORMATS)}, got {fmt!r}")
        rg = p.extra.get("ranges")
        if rg is not None and not (isinstance(rg, list) and rg and all(
                isinstance(r, list) and len(r) == 2 and all(isinstance(x, (int, float)) for x in r)
                and r[0] <= r[1] for r in rg)):
            raise DataFileError(path, p.line, f"{p.code}: ranges must be a list of [min, max]")
        if "df6" in p.extra and not isinstance(p.extra["df6"], bool):
            raise DataFileError(path, p.line, f"{p.code}: df6 must be true or false")
        if "df6_max" in p.extra and not isinstance(p.extra["df6_max"], (int, float)):
            raise DataFileError(path, p.line, f"{p.code}: df6_max must be a number")
        unknown = set(p.extra) - FAMILY_PARAM_KEYS - COMMON_EXTRA_KEYS
        if unknown:
            raise DataFileError(path, p.line, f"{p.code}: unknown key(s) {', '.join(sorted(unknown))}"
                                f" (Moeller keys: {', '.join(sorted(FAMILY_PARAM_KEYS))})")


_INT = "'{key}' must be an integer {lo}..{hi}, got {value!r}"
_PARAM = "{where}.{key}: {value} is not a parameter of this profile"


@dataclass(frozen=True)
class SourceKeys:
    """moeller.control_source.frequency / .commands: the parameter that gives the bus the role, and
    the value that does (None: the role's default)."""
    param: str | None = key("text", None, type_msg=_PARAM)
    bus_value: int | None = key("int", None, lo=0, hi=255, type_msg=_INT)


@dataclass(frozen=True)
class ControlSourceKeys:
    frequency: SourceKeys | None = key("section", None, nullable=True, section=SourceKeys,
                                       type_msg="control_source.{key} must be {{param, bus_value}}")
    commands: SourceKeys | None = key("section", None, nullable=True, section=SourceKeys,
                                      type_msg="control_source.{key} must be {{param, bus_value}}")


@dataclass(frozen=True)
class CommLossKeys:
    param: str | None = key("text", None, type_msg=_PARAM)
    other_param: str | None = key("text", None, type_msg=_PARAM)
    alarm: str | None = key("text", None, type_msg="comm_loss.alarm {value!r} is not in alarms")


@dataclass(frozen=True)
class MoellerKeys:
    """The profile's `moeller:` section (read by drives/sections.py)."""
    control_source: ControlSourceKeys = key("section", section=ControlSourceKeys,
                                            type_msg="control_source must be a mapping")
    ctw_commands_invalid_bit: int = key("int", 12, lo=11, hi=15, type_msg=_INT)
    ctw_reference_invalid_bit: int = key("int", 13, lo=11, hi=15, type_msg=_INT)
    ctw_reverse_bit: int = key("int", 11, lo=11, hi=15, type_msg=_INT)
    comm_loss: CommLossKeys = key("section", section=CommLossKeys, type_msg="comm_loss must be a mapping")
    df6_device_id: int = key("int", 0x812C, lo=0, hi=0xFFFF, type_msg=_INT)
    sim_defaults: dict[Any, Any] = key("mapping", {}, type_msg="sim_defaults must be a mapping code: value")


def _param_of(profile: Profile, keys: object, name: str, default: str, where: str) -> str:
    """keys.<name> (or the default), which must be a parameter of the profile."""
    v: str | None = getattr(keys, name)
    v = default if v is None else v
    if profile.param(v) is None:
        raise DataFileError(profile.path or "<profile>", key_line(keys, name),
                            _PARAM.format(where=where, key=name, value=v))
    return v


def _build_config(profile: Profile) -> MoellerConfig:
    _validate_params(profile)
    doc = profile.raw if isinstance(profile.raw, LineDict) else LineDict()
    path = profile.path or "<profile>"
    sec = section(MoellerKeys, path, doc, "moeller", required=True, where="moeller",
                  unknown_msg="moeller: unknown key '{key}' (known: {known})")
    c = MoellerConfig(commands_invalid_bit=sec.ctw_commands_invalid_bit,
                      reference_invalid_bit=sec.ctw_reference_invalid_bit, reverse_bit=sec.ctw_reverse_bit,
                      df6_device_id=sec.df6_device_id)
    for role in ("frequency", "commands"):
        src = getattr(sec.control_source, role)
        if src is None:
            continue
        where = f"moeller.control_source.{role}"
        setattr(c, f"{role}_param", _param_of(profile, src, "param", getattr(c, f"{role}_param"), where))
        if src.bus_value is not None:
            setattr(c, f"{role}_bus_value", src.bus_value)
    cl = sec.comm_loss
    if doc["moeller"].get("comm_loss"):             # a comm_loss: with any key names both slots itself
        c.comm_loss_param = _param_of(profile, cl, "param", c.comm_loss_param, "moeller.comm_loss")
        c.comm_loss_other_param = None if cl.other_param is None else \
            _param_of(profile, cl, "other_param", "", "moeller.comm_loss")
        alarm = c.comm_loss_alarm if cl.alarm is None else cl.alarm
        if profile.alarm_by_code(alarm) is None:
            raise DataFileError(path, key_line(cl, "alarm"), f"comm_loss.alarm {alarm!r} is not in alarms")
        c.comm_loss_alarm = alarm
    sd = sec.sim_defaults
    for k, v in sd.items():
        if profile.param(str(k)) is None:
            raise _err(profile, sd, k, f"sim_defaults: {k} is not a parameter of this profile")
        if not isinstance(v, (int, float)) or isinstance(v, bool):
            raise _err(profile, sd, k, f"sim_defaults: {k} must be a number")
    c.sim_defaults = dict(sd)
    return c


moeller_config = per_profile(_build_config)   # -> MoellerConfig, built once per profile


# =============================================================================================
# values on the wire
# =============================================================================================


def value_from_wire(param: ParamDef, raw: int) -> float | int:
    """PWE (right-aligned) -> engineering value: the low `bytes` octets, sign-extended if signed."""
    nbytes = param.extra.get("bytes", param.size // 8)
    bits = 8 * nbytes
    raw &= (1 << bits) - 1
    if param.signed and raw >= 1 << (bits - 1):
        raw -= 1 << bits
    v = raw * param.scale
    if float(param.scale).is_integer():
        return int(round(v))
    return round(v, 6)


def wire_from_value(param: ParamDef, value: float) -> int:
    """Engineering value -> PWE integer in the parameter's own width (two's complement if < 0)."""
    nbytes: int = param.extra.get("bytes", param.size // 8)     # checked: 1, 2 or 4
    raw = int(round(value / param.scale)) if param.scale else int(value)
    return raw & ((1 << (8 * nbytes)) - 1)


def param_value(profile: Profile, param: ParamDef, raw: int) -> float | int:
    """Hook used by the core decoder."""
    return value_from_wire(param, raw)


def in_ranges(param: ParamDef, value: float) -> bool:
    rg = param.extra.get("ranges")
    if rg:
        return any(lo - 1e-9 <= value <= hi + 1e-9 for lo, hi in rg)
    return (param.min is None or value >= param.min - 1e-9) and \
        (param.max is None or value <= param.max + 1e-9)


# =============================================================================================
# small decoders (test vectors TV-9 .. TV-14)
# =============================================================================================


def device_name(word: int) -> str:
    """PNU 964: bit 15 = family (1 DF, 0 DV), bits 14..0 = model number (300 = '6' series)."""
    fam = "DF" if word & 0x8000 else "DV"
    model = word & 0x7FFF
    return f"{fam}6" if model == 0x12C else f"{fam} model {model}"


def baud_text(code: int, profile: Profile) -> str:
    return pd.config(profile).baud_codes.get(code, f"invalid baud-rate code {code}")


def _baud_format(profile: Profile, param: ParamDef, raw: int, value: object) -> str:
    """PNU 963 (`format: baud`): the card's own code and its rate (spec 6.3, src L716-728: 0 = 12 Mbit/s)."""
    return f"{raw} ({baud_text(raw, profile)})"


def _fault_format(profile: Profile, param: ParamDef, raw: int, value: object) -> str:
    """PNU 947 (`format: alarm947`): the fault number and its name (spec 6.4, src L730-759, Table 8)."""
    return f"{raw} ({fault_text(profile, raw)})"


#: value texts by `format:` (drives/formats.py); code, hex and bits are the generic ones
FORMATTERS: dict[str, Formatter] = {"baud": _baud_format, "alarm947": _fault_format}


def fault_text(profile: Profile, number: int) -> str:
    if number == 0:
        return "no fault"
    alarms = profile.alarms_for(number)
    if not alarms:
        return f"unknown ({number})"
    return " / ".join(f"{a.code} {a.meaning}" for a in alarms)


def address_from_switches(right: int, left: int) -> int:
    """Node address from the two rotary switches: the right one is the tens digit."""
    if not (0 <= right <= 9 and 0 <= left <= 9):
        raise ValueError("switch positions are 0..9")
    return right * 10 + left


def source_selection(ctw: int, mc: MoellerConfig | None = None) -> str:
    """What the bus controls (with A001 = 2, A002 = 1), from STW bits 10, 12, 13."""
    mc = mc or MoellerConfig()
    if not ctw & pd.Ctw.CONTROL_BY_PLC:
        return "nothing (data invalid)"
    cmd = not ctw >> mc.commands_invalid_bit & 1
    ref = not ctw >> mc.reference_invalid_bit & 1
    return {(True, True): "frequency and commands", (False, True): "frequency only",
            (True, False): "commands only", (False, False): "nothing"}[(cmd, ref)]


def direction_text(ctw: int, hsw: int, mc: MoellerConfig | None = None) -> str:
    mc = mc or MoellerConfig()
    neg = pd.to_signed16(hsw) < 0
    rev = bool(ctw >> mc.reverse_bit & 1)
    if pd.to_signed16(hsw) == 0:
        return "reverse" if rev else "forward"
    return "reverse" if neg != rev else "forward"


# =============================================================================================
# the Drive
# =============================================================================================


class MoellerDrive(pd.ProfidriveDrive):
    family = "moeller"
    #: F002 acceleration time, F003 deceleration time (when the profile's ramps name none)
    ramp_codes = {"accel": "F002", "decel": "F003"}
    comm_loss_words = "P002 (0 = trip E70 and coast; 1 = keep running on the last command)"

    @classmethod
    def audit_rules(cls, profile: Any) -> list[Any]:
        """The family's `pdrive audit` rules (drives/moeller_audit.py), each citing its manual line."""
        from profidrive_cli.drives.moeller_audit import audit_rules
        return audit_rules(profile)

    def __init__(self, channel: CyclicChannel, profile: Profile, layout: str | None = None):
        super().__init__(channel, profile, layout)
        self.mc = moeller_config(profile)
        self._device: str | None = None

    def raw_to_value(self, ref: pd.ParamRef, raw: int) -> float | int:
        if ref.param is None:
            return raw
        return value_from_wire(ref.param, raw)

    def value_to_raw(self, ref: pd.ParamRef, value: float | int) -> int:
        if ref.param is None:
            return int(value) & ((1 << ref.size) - 1)
        return wire_from_value(ref.param, value)

    def device(self) -> str:
        """'DF6' or 'DV6' from PNU 964 (read once)."""
        if self._device is None:
            self._device = device_name(self.read_raw(pd.PNU_DEVICE_ID) & 0xFFFF)
        return self._device

    def check_value(self, ref: pd.ParamRef, value: float | int) -> str | None:
        p = ref.param
        if p is None:
            return super().check_value(ref, value)
        u = f" {p.unit}" if p.unit else ""
        msg = value_problem(p, value)            # resolution, ranges, byte width (drives/values.py)
        if msg:
            return msg
        if ("df6" in p.extra or "df6_max" in p.extra) and self.pkw is not None:
            dev = self.device()
            if dev.startswith("DF"):
                if p.extra.get("df6") is False:
                    return f"{p.code} ({p.name}) does not exist on a DF6"
                mx = p.extra.get("df6_max")
                if mx is not None and value > mx:
                    return f"{p.code} ({p.name}): {value:g}{u} is above the DF6 maximum {mx:g}{u}"
        return None

    # -- jog: CTW bit 8 "inching 1" at A038 from "Enable operation" (spec 3.1, manual L542-543) --
    supports_jog = True

    @classmethod
    def jog_refusal_for(cls, profile: Any, layout: str) -> str | None:
        return None                           # jog 1 / jog 2 (CTW bits 8, 9) on every DE6-NET-DP layout

    @classmethod
    def extra_flag_names(cls, profile: Any, layout: str) -> list[str]:
        return ["bus gives commands"]         # status_extras()

    def jog(self, on: bool = True, reverse: bool = False) -> None:
        """Inching 1: operation (bits 0-6, 10) with HSW = 0 and bit 8; reverse = bit 11 (REV), the
        direction of every run on this card (sign of HSW XOR bit 11). Bit 9 (inching 2) is not used."""
        rev = 1 << self.mc.reverse_bit
        if on:
            self.extra_bits = (self.extra_bits | rev) if reverse else (self.extra_bits & ~rev)
        super().jog(on)
        if not on:
            self.extra_bits &= ~rev

    def stop(self, mode: str = "normal", wait: bool = True, timeout: float = 30.0) -> DriveStatus:
        if self.extra_bits & int(pd.Ctw.JOG1):
            self.extra_bits &= ~(1 << self.mc.reverse_bit)     # the jog's direction ends with it
        return super().stop(mode, wait, timeout)

    def start_hint(self, status: DriveStatus) -> str:
        mc = self.mc
        return (f"the card gives run commands only with {mc.commands_param} = {mc.commands_bus_value} "
                f"and the reference only with {mc.frequency_param} = {mc.frequency_bus_value} "
                f"(both writable only while stopped), PNU 928 = 1, and STW bits 10 = 1, "
                f"{mc.commands_invalid_bit} = 0, {mc.reference_invalid_bit} = 0")

    def status_extras(self, area: pd.PpoArea, status: DriveStatus) -> None:
        ctw = self.last_ctw or 0
        # a plain int: IntFlag arithmetic here would cost a microsecond on every cycle
        status.flags["bus gives commands"] = bool(area.word1 & _STW_CONTROL_REQUESTED) and \
            not ctw >> self.mc.commands_invalid_bit & 1
        status.raw["control_word"] = ctw

    def comm_loss_setting(self) -> dict[str, ParamValue]:
        """P002 (and P001): 0 = trip on communication loss, 1 = keep running."""
        out = {self.mc.comm_loss_param: self.read_param(self.mc.comm_loss_param)}
        if self.mc.comm_loss_other_param:
            out[self.mc.comm_loss_other_param] = self.read_param(self.mc.comm_loss_other_param)
        return out

    monitor_mapping = "map"           # PNU 916 is volatile (spec 2.4, manual example 2)

    def on_device(self, p: Any) -> bool:
        """`df6: false` entries are not on a DF6 (PNU 964 says which device it is)."""
        if p.extra.get("df6") is False:
            try:
                return not self.device().startswith("DF")
            except (DriveError, UsageError):
                return True
        return True

    def comm_loss_summary(self) -> str | None:
        first = next(iter(self.comm_loss_setting().values()))
        keep = int(first.raw) == 1
        return (f"{first.code} = {first.raw}: " +
                ("the drive keeps running on the last command" if keep else
                 "the drive trips (E70) and coasts"))

    def comm_loss_reaction(self) -> Reaction | None:
        """P002 (+ P001 shown): 1 keeps running on the last command, else trip (output off)."""
        vals = self.comm_loss_setting()
        code = self.mc.comm_loss_param
        main = vals[code]
        shown = {k: int(v.raw) for k, v in vals.items()}
        others = ", ".join(f"{k} = {v}" for k, v in shown.items() if k != code)
        extra = f" ({others} shown as well: the card's slot decides which one applies)" if others else ""
        if int(main.raw) == 1:
            return Reaction(f"{code} = 1: keep running on the last command{extra}", "none",
                            settings=shown)
        return Reaction(f"{code} = {int(main.raw)}: trip {self.mc.comm_loss_alarm} (output off, "
                        f"the motor coasts){extra}", "trip", alarm=self.mc.comm_loss_alarm,
                        settings=shown)

    def bus_control_check(self) -> list[str]:
        """Problems that keep the bus from controlling the inverter (empty = fine)."""
        mc = self.mc
        probs = []
        f = self.read_param(mc.frequency_param)
        if f.raw != mc.frequency_bus_value:
            probs.append(f"{mc.frequency_param} = {f.raw}: the bus reference is not used "
                         f"(needs {mc.frequency_bus_value})")
        c = self.read_param(mc.commands_param)
        if c.raw != mc.commands_bus_value:
            probs.append(f"{mc.commands_param} = {c.raw}: the bus run commands are not used "
                         f"(needs {mc.commands_bus_value})")
        for pnu, what in ((pd.PNU_EDIT_RIGHTS, "parameter edit rights"),
                          (pd.PNU_CONTROL_RIGHTS, "process-data control rights")):
            try:
                if self.read_raw(pnu) & 0xFFFF != 1:
                    probs.append(f"PNU {pnu} = 0: no {what}")
            except ParamError as e:
                probs.append(str(e))
        return probs


def make_drive(channel: CyclicChannel, profile: Profile, layout: str | None = None) -> MoellerDrive:
    moeller_config(profile)
    return MoellerDrive(channel, profile, layout)


# =============================================================================================
# decoder
# =============================================================================================


def decode_area(profile: Profile, layout: str, direction: str, data: bytes, *,
                max_hz: float | None = None) -> dict[str, Any]:
    mc = moeller_config(profile)
    out = pd.decode_area(profile, layout, direction, data, max_hz=max_hz)
    text = out["text"]
    if direction == "request":
        cw = out["control_word"]["word"]
        hsw = out["reference"]["raw"]
        src = source_selection(cw, mc)
        dirn = direction_text(cw, hsw, mc)
        out["control_word"]["bus_controls"] = src
        out["control_word"]["direction"] = dirn
        text.insert(-1, f"bus controls (with {mc.frequency_param} = {mc.frequency_bus_value}, "
                        f"{mc.commands_param} = {mc.commands_bus_value}): {src}; direction {dirn} "
                        f"(sign of {pd.config(profile).labels['reference']} XOR STW bit "
                        f"{mc.reverse_bit})")
    return out


def speed_plan(profile: Profile, layout: str, direction: str, max_hz: float | None = None
               ) -> SpeedWord | None:
    """sniff --station's fast path (drives/speedplan.py SpeedWord): HSW / HIW as the core's N2
    word (the request's direction text reads HSW's sign: not in the drive object)."""
    return pd.speed_plan(profile, layout, direction, max_hz)


__all__ = ["MoellerConfig", "MoellerDrive", "make_drive", "decode_area", "speed_plan", "param_value",
           "moeller_config", "source_selection", "device_name", "baud_text", "fault_text",
           "address_from_switches", "value_from_wire", "wire_from_value", "in_ranges",
           "direction_text", "DriveError"]
