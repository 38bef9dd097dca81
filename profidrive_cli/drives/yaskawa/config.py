"""Yaskawa profile keys: the `yaskawa:` section, layouts, registers, alarms and LED table, validated
with file:line (DataFileError); plus the register names and 'REG0x..' codes used to address them.

May touch: datafile, drives/sections (the `yaskawa:` section's declaration), codec (FORMATS). Reads the
profile, writes nothing but its cache on the profile.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, ClassVar

from profidrive_cli.datafile import DataFileError, LineDict
from profidrive_cli.drives.profile import per_profile
from profidrive_cli.drives.sections import key, read, section
from profidrive_cli.drives.yaskawa.codec import FORMATS

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import Profile

# ---------------------------------------------------------------------------------------------------
# Family keys of the profile (validated with file:line)
# ---------------------------------------------------------------------------------------------------

LED_STATES = ("off", "green", "red", "green-flash", "red-flash")
REGISTER_SOURCES = ("printed", "inferred", "external")
ALARM_KINDS = ("fault", "ope", "cpf", "alarm")


@dataclass
class YaskawaConfig:
    reference_unit_hz: float = 0.01
    feedback_unit_hz: float = 0.1
    o1_03: int = 0
    rated_current_a: float | None = None
    fast_stop_input: int | None = None
    timeout_s: float = 1.0
    settle_cycles: int = 1
    enter_register: int | None = None
    fault_history: list[tuple[str, str]] = field(default_factory=list)   # (position, param code)
    alarm_kinds: dict[str, str] = field(default_factory=dict)            # code -> fault|ope|cpf|alarm
    led_diagnostics: list[dict[str, str]] = field(default_factory=list)   # pwr, com, err, wd, condition, ...


_NUMBER = "'{key}' must be a number, got {value!r}"


@dataclass(frozen=True)
class HandshakeKeys:
    """yaskawa.handshake: how long a parameter-access request may take, how many cycles to settle."""
    RULES: ClassVar[tuple[tuple[Callable[[HandshakeKeys], bool], str], ...]] = (
        (lambda h: h.timeout_s > 0 and h.settle_cycles >= 1,
         "handshake: timeout_s must be > 0 and settle_cycles >= 1"),)
    timeout_s: float = key("number", 1.0, type_msg=_NUMBER)
    settle_cycles: int = key("int", 1, type_msg=_NUMBER)


@dataclass(frozen=True)
class YaskawaKeys:
    """The profile's `yaskawa:` section (read by drives/sections.py)."""
    reference_unit_hz: float = key("number", 0.01, gt=0, type_msg=_NUMBER, range_msg="'{key}' must be > 0")
    feedback_unit_hz: float = key("number", 0.1, gt=0, type_msg=_NUMBER, range_msg="'{key}' must be > 0")
    o1_03: int = key("int", 0, lo=0, hi=39999, type_msg=_NUMBER, range_msg="'o1_03' must be 0..39999")
    rated_current_a: float | None = key("number", None, nullable=True, gt=0, type_msg=_NUMBER,
                                        range_msg="'rated_current_a' must be > 0 or null")
    fast_stop_input: int | None = key(
        "int", None, nullable=True, lo=3, hi=12, type_msg=_NUMBER,
        range_msg="'fast_stop_input' must be a multi-function input 3..12 or null")
    handshake: HandshakeKeys = key("section", section=HandshakeKeys, type_msg="'handshake' must be a mapping")
    enter_register: Any = key("mapping", None, nullable=True,
                              type_msg="'enter_register' must be a mapping with an integer 'register'")
    fault_history: list[Any] = key("list", [], type_msg="'fault_history' must be a list")


@dataclass(frozen=True)
class YaskawaTopKeys:
    """Top-level keys only this family reads (the common ones are drives/profile.py's)."""
    led_diagnostics: list[Any] = key("list", [], type_msg="'led_diagnostics' must be a list")
    decisions: list[str] = key("texts", [], type_msg="'decisions' must be a list of strings")


def _build_config(profile: Profile) -> YaskawaConfig:
    """Validate and return the Yaskawa keys of a profile."""
    path = profile.path or profile.name
    raw = profile.raw if isinstance(profile.raw, LineDict) else LineDict()
    _check_layouts(path, profile, raw)
    y = section(YaskawaKeys, path, raw, "yaskawa")
    cfg = YaskawaConfig(reference_unit_hz=y.reference_unit_hz, feedback_unit_hz=y.feedback_unit_hz,
                        o1_03=y.o1_03, rated_current_a=y.rated_current_a, fast_stop_input=y.fast_stop_input,
                        timeout_s=y.handshake.timeout_s, settle_cycles=y.handshake.settle_cycles)
    if y.enter_register is not None:
        cfg.enter_register = _enter_register(path, raw, y.enter_register)
    cfg.fault_history = _fault_history(path, profile, y.fault_history)
    _check_params(path, profile, raw)
    cfg.alarm_kinds = _alarm_kinds(path, raw)
    top = read(YaskawaTopKeys, path, raw)
    cfg.led_diagnostics = [_led_row(path, item) for item in top.led_diagnostics]
    return cfg


family_config = per_profile(_build_config)   # -> YaskawaConfig, built once per profile


def _check_layouts(path: str | Path, profile: Profile, raw: LineDict) -> None:
    layouts_node = raw.get("layouts")
    for name, lay in profile.layouts.items():
        line = layouts_node.line_of(name) if isinstance(layouts_node, LineDict) else None
        lnode = layouts_node.get(name) if isinstance(layouts_node, LineDict) else None
        if name not in FORMATS:
            raise DataFileError(path, line, f"layout '{name}': the yaskawa codec knows "
                                f"{', '.join(FORMATS)}")
        if lay.cfg != FORMATS[name].cfg:
            if isinstance(lnode, LineDict):
                line = lnode.line_of("cfg")
            raise DataFileError(path, line, f"layout '{name}': cfg must be {FORMATS[name].cfg.hex(' ').upper()}")


def _enter_register(path: str | Path, raw: LineDict, en: LineDict) -> int:
    reg = en.get("register")
    if not isinstance(reg, int):
        raise DataFileError(path, raw["yaskawa"].line_of("enter_register"),
                            "'enter_register' must be a mapping with an integer 'register'")
    _check_source(path, en)
    return reg


def _fault_history(path: str | Path, profile: Profile, fh: list[Any]) -> list[tuple[str, str]]:
    out: list[tuple[str, str]] = []
    for i, item in enumerate(fh):
        line = fh.line_of(i) if hasattr(fh, "line_of") else None
        if not isinstance(item, LineDict) or not isinstance(item.get("position"), str) \
                or not isinstance(item.get("param"), str):
            raise DataFileError(path, line, "fault_history entries need 'position' and 'param' (strings)")
        p = profile.param(item["param"])
        if p is None or p.register is None:
            raise DataFileError(path, item.line_of("param"),
                                f"fault_history: {item['param']} is not a parameter with a register")
        out.append((item["position"], p.code))
    return out


def _check_params(path: str | Path, profile: Profile, raw: LineDict) -> None:
    for code, p in profile.parameters.items():
        node = _param_node(raw, p.line)
        src = p.extra.get("register_source")
        if src is not None and src not in REGISTER_SOURCES:
            raise DataFileError(path, node.line_of("register_source") if node else p.line,
                                f"{code}: register_source must be one of {', '.join(REGISTER_SOURCES)}")
        vals = p.extra.get("values")
        if vals is not None and not isinstance(vals, dict):
            raise DataFileError(path, node.line_of("values") if node else p.line,
                                f"{code}: 'values' must be a mapping of value -> meaning")
        if p.register is not None and not 0 <= p.register <= 0xFFFF:
            raise DataFileError(path, node.line_of("register") if node else p.line,
                                f"{code}: register must be 0..0xFFFF")


def _alarm_kinds(path: str | Path, raw: LineDict) -> dict[str, str]:
    out: dict[str, str] = {}
    alarms = raw.get("alarms", [])
    for a in alarms if isinstance(alarms, list) else []:
        if not isinstance(a, LineDict):
            continue
        kind = a.get("kind", "fault")
        if kind not in ALARM_KINDS:
            raise DataFileError(path, a.line_of("kind"), f"alarm kind must be one of {', '.join(ALARM_KINDS)}")
        out[str(a.get("code")).upper()] = kind
    return out


def _led_row(path: str | Path, item: object) -> dict[str, str]:
    if not isinstance(item, LineDict):
        raise DataFileError(path, getattr(item, "line", None), "an LED row must be a mapping")
    for k in ("pwr", "com", "err", "wd"):
        if item.get(k) is False:        # YAML 1.1 reads a bare `off` as false
            item[k] = "off"
        if item.get(k) not in LED_STATES:
            raise DataFileError(path, item.line_of(k) if k in item else item.line,
                                f"LED row: '{k}' must be one of {', '.join(LED_STATES)}")
    if not isinstance(item.get("condition"), str):
        raise DataFileError(path, item.line, "LED row: 'condition' (text) is missing")
    return {k: str(v) for k, v in item.items()}


def _check_source(path: str | Path, node: LineDict) -> None:
    src = node.get("register_source")
    if src is not None and src not in REGISTER_SOURCES:
        raise DataFileError(path, node.line_of("register_source"),
                            f"register_source must be one of {', '.join(REGISTER_SOURCES)}")


def _param_node(raw: LineDict, line: int) -> LineDict | None:
    for node in raw.get("parameters", []) or []:
        if isinstance(node, LineDict) and node.line == line:
            return node
    return None


def led_diagnosis(profile: Profile, pwr: str, com: str, err: str, wd: str) -> dict[str, str]:
    """The LED table row for a state (pwr, com, err, wd), or an 'unspecified' row (spec §1.7)."""
    for row in family_config(profile).led_diagnostics:
        if (row["pwr"], row["com"], row["err"], row["wd"]) == (pwr, com, err, wd):
            return row
    return {"pwr": pwr, "com": com, "err": err, "wd": wd, "condition": "Unspecified option error",
            "cause": "LED combination not in the manual's table", "remedy": "Treat as an option fault"}


def register_name(profile: Profile, reg: int) -> str | None:
    for p in profile.parameters.values():
        if p.register == reg:
            return p.code
    return None


_REG_RE = re.compile(r"^REG(?:0X([0-9A-F]{1,4})|([0-9]{1,5}))$", re.IGNORECASE)


def parse_register_code(code: str) -> int | None:
    """'REG0x0180' (hex) or 'REG384' (decimal) -> register number; None if not that form."""
    m = _REG_RE.match(code.strip())
    if not m:
        return None
    return int(m.group(1), 16) if m.group(1) else int(m.group(2))
