"""Per-card PROFIdrive configuration: the profile's `profidrive:` section, validated with file:line
(declared as ProfidriveKeys and read by drives/sections.py; the checks against the profile's
parameters stay here).

`ProfidriveConfig.from_profile` parses; `config(profile)` caches it and lets a family module build
it from its own keys (`profidrive_config(profile)`). Reads the profile only; no bus, no drive.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from profidrive_cli.datafile import DataFileError, LineDict
from profidrive_cli.drives.profidrive.pkw import GENERIC_ERRORS
from profidrive_cli.drives.profidrive.pnu import (PNU_FAULT_NUMBER, PNU_PZD_ACTUAL,
                                                  PNU_PZD_SETPOINT,
                                                  default_fault_positions)
from profidrive_cli.drives.profidrive.words import CTW_NAMES, DERIVED_BITS, STW_NAMES
from profidrive_cli.drives.sections import key, key_line, section

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import Profile

ERROR_ROLES = ("unknown_pnu", "read_only", "out_of_range", "bad_subindex", "not_array",
               "wrong_type", "stop_only", "no_rights", "bad_request")
_DEFAULT_ERROR_NUMBERS = {"unknown_pnu": 0, "read_only": 1, "out_of_range": 2, "bad_subindex": 3,
                          "not_array": 4, "wrong_type": 5, "stop_only": 17, "no_rights": 11,
                          "bad_request": 18}


@dataclass
class ProfidriveConfig:
    labels: dict[str, str]
    ctw_names: dict[int, str]
    stw_names: dict[int, str]
    held_ctw_bits: int = 0
    #: control-word bits the card's manual marks "not used" (decoders name them so, never "jog")
    unused_ctw_bits: frozenset[int] = frozenset()
    array_pnus: frozenset[int] = frozenset({PNU_PZD_SETPOINT, PNU_PZD_ACTUAL, PNU_FAULT_NUMBER})
    pzd_map: tuple[int, int] = (PNU_PZD_SETPOINT, PNU_PZD_ACTUAL)
    pkw_timeout: float = 2.0
    zero_after_error: bool = False
    zero_between_identical: bool = False
    max_zero_cycles: int = 20
    supported_requests: frozenset[int] | None = None
    supported_responses: frozenset[int] | None = None
    #: what decode appends to a request/response ID outside the card's sets ("not used by this card")
    unsupported_text: str = "not supported by this card"
    error_texts: dict[int, str] = field(default_factory=lambda: dict(GENERIC_ERRORS))
    error_numbers: dict[str, int] = field(default_factory=lambda: dict(_DEFAULT_ERROR_NUMBERS))
    fault_memory_pnu: int = PNU_FAULT_NUMBER
    fault_subindexes: list[int] = field(default_factory=lambda: [1, 9, 17, 25])
    fault_positions: list[str] = field(default_factory=lambda: default_fault_positions(4))
    save_pnu: int | None = None
    baud_codes: dict[int, str] = field(default_factory=dict)
    device_ids: dict[int, str] = field(default_factory=dict)
    ramps: dict[str, str] = field(default_factory=dict)
    jog_reference: str | None = None
    #: parameters over DP-V1 DS47 (the profile's `dpv1:`); None: PKW words only
    dpv1: Dpv1Config | None = None

    def error_text(self, number: int) -> str:
        return self.error_texts.get(number, f"error {number}")

    @classmethod
    def from_profile(cls, profile: Profile) -> ProfidriveConfig:
        path = profile.path or "<profile>"
        doc = profile.raw if isinstance(profile.raw, LineDict) else LineDict()
        sec = section(ProfidriveKeys, path, doc, "profidrive", where="profidrive",
                      unknown_msg="{where}: unknown key '{key}' (known: {known})")
        labels = {"control": "CTW", "status": "STW", "reference": "MRV", "actual": "MAV"}
        labels.update({k: v for k, v in dataclasses.asdict(sec.labels).items() if v is not None})
        ctw: dict[int, str | None] = dict(CTW_NAMES)
        own = _bit_names(path, sec.ctw_bits, "ctw_bits")
        ctw.update(own)
        stw: dict[int, str | None] = dict(STW_NAMES)
        stw.update(_bit_names(path, sec.stw_bits, "stw_bits"))
        held = 0
        for b in sec.held_ctw_bits:
            held |= 1 << b
        if held & DERIVED_BITS:
            raise DataFileError(path, key_line(sec, "held_ctw_bits"), "held_ctw_bits cannot include "
                                "bits 0-3, 7 or 10 (the state machine sets them)")
        cfg = cls(labels=labels, held_ctw_bits=held,
                  ctw_names={b: n for b, n in ctw.items() if n is not None},      # null = bit not used
                  stw_names={b: n for b, n in stw.items() if n is not None},
                  unused_ctw_bits=frozenset(b for b, n in own.items() if n is None))
        if sec.array_pnus is not None:
            cfg.array_pnus = frozenset(sec.array_pnus)
        cfg.pzd_map = (sec.pzd_map.setpoint, sec.pzd_map.actual)
        cfg._read_pkw(path, sec.pkw)
        fm = sec.fault_memory
        cfg.fault_memory_pnu = fm.pnu
        if fm.subindexes is not None:
            cfg.fault_subindexes = list(fm.subindexes)
        cfg.fault_positions = default_fault_positions(len(cfg.fault_subindexes))
        if fm.positions is not None:
            if len(fm.positions) != len(cfg.fault_subindexes):
                raise DataFileError(path, key_line(fm, "positions"),
                                    "fault_memory.positions must be one text per subindex")
            cfg.fault_positions = list(fm.positions)
        cfg.save_pnu = sec.save.pnu
        if sec.dpv1 is not None:
            d = sec.dpv1
            cfg.dpv1 = Dpv1Config(d.slot, d.axis, d.c1_timeout_ms / 1000.0, d.timeout_s)
        cfg.baud_codes.update(_texts(path, sec.baud_codes, "baud_codes: keys are numbers, values texts"))
        cfg.device_ids.update(_texts(path, sec.device_ids, "device_ids: keys are numbers, values texts"))
        cfg.ramps = _ramps(path, profile, sec.ramps)
        if sec.jog_reference is not None:
            if profile.param(sec.jog_reference) is None:
                raise DataFileError(path, key_line(sec, "jog_reference"),
                                    f"jog_reference {sec.jog_reference!r} is not in parameters")
            cfg.jog_reference = sec.jog_reference
        return cfg

    def _read_pkw(self, path: str | Path, pkw: PkwKeys) -> None:
        self.pkw_timeout = pkw.timeout_s
        if pkw.zero_after_error is not None:
            self.zero_after_error = pkw.zero_after_error
        if pkw.zero_between_identical is not None:
            self.zero_between_identical = pkw.zero_between_identical
        self.max_zero_cycles = pkw.max_zero_cycles
        if pkw.requests is not None:
            self.supported_requests = frozenset(pkw.requests)
        if pkw.responses is not None:
            self.supported_responses = frozenset(pkw.responses)
        if pkw.unsupported_text is not None:
            self.unsupported_text = pkw.unsupported_text
        self.error_texts.update(_texts(path, pkw.errors, "pkw.errors: keys are error numbers, values texts"))
        en = pkw.error_numbers
        for k, v in en.items():
            if k not in ERROR_ROLES or not isinstance(v, int) or isinstance(v, bool):
                raise _e(path, en, k, f"pkw.error_numbers: '{k}' must be one of "
                         f"{', '.join(ERROR_ROLES)} with a number")
            self.error_numbers[k] = v


# -- the `profidrive:` section, declared (read by drives/sections.py) ---------------------------------

_MAPPING = "'{key}' must be a mapping"
_INT = "'{key}' must be an integer, got {value!r}"
_INTS = "'{key}' must be a list of integers {lo}..{hi}"
_LABEL = "profidrive.labels: '{key}' must be one of control, status, reference, actual with a text value"


def _sub(decl: type, **rules: Any) -> Any:
    """A nested section field: `'key' must be a mapping`, unknown keys refused."""
    return key("section", section=decl, type_msg=_MAPPING,
               unknown_msg="{where}: unknown key '{key}' (known: {known})", **rules)


@dataclass(frozen=True)
class LabelKeys:
    control: str | None = key("text", None, type_msg=_LABEL)
    status: str | None = key("text", None, type_msg=_LABEL)
    reference: str | None = key("text", None, type_msg=_LABEL)
    actual: str | None = key("text", None, type_msg=_LABEL)


@dataclass(frozen=True)
class PzdMapKeys:
    setpoint: int = key("int", PNU_PZD_SETPOINT, type_msg=_INT)
    actual: int = key("int", PNU_PZD_ACTUAL, type_msg=_INT)


@dataclass(frozen=True)
class PkwKeys:
    timeout_s: float = key("number", 2.0, gt=0, type_msg="pkw.timeout_s must be a number > 0")
    zero_after_error: bool | None = key("bool", None, type_msg="pkw.{key} must be true or false")
    zero_between_identical: bool | None = key("bool", None, type_msg="pkw.{key} must be true or false")
    max_zero_cycles: int = key("int", 20, type_msg=_INT)
    requests: list[int] | None = key("ints", None, lo=0, hi=15, type_msg=_INTS)
    responses: list[int] | None = key("ints", None, lo=0, hi=15, type_msg=_INTS)
    unsupported_text: str | None = key("text", None, nonblank=True,
                                       type_msg="pkw.unsupported_text must be a text")
    errors: dict[Any, Any] = key("mapping", {}, type_msg=_MAPPING)
    error_numbers: dict[Any, Any] = key("mapping", {}, type_msg=_MAPPING)


@dataclass(frozen=True)
class FaultMemoryKeys:
    pnu: int = key("int", PNU_FAULT_NUMBER, type_msg=_INT)
    subindexes: list[int] | None = key("ints", None, lo=0, hi=255, type_msg=_INTS)
    positions: list[str] | None = key("texts", None,
                                      type_msg="fault_memory.positions must be one text per subindex")


@dataclass(frozen=True)
class Dpv1Keys:
    """`dpv1:`: the card's parameters go over DP-V1 (class-1 Read/Write of data record 47, the
    PROFIdrive base mode parameter access) instead of PKW words."""
    slot: int = key("int", 0, lo=0, hi=254, type_msg=_INT, range_msg="dpv1.slot must be 0..254")
    axis: int = key("int", 1, lo=0, hi=255, type_msg=_INT, range_msg="dpv1.axis must be 0..255")
    #: the GSD's C1_Response_Timeout (there in 10 ms) in ms: the longest a Read/Write may take
    c1_timeout_ms: float = key("number", 1000.0, gt=0, type_msg="dpv1.c1_timeout_ms must be a number > 0")
    #: how long a parameter request may keep answering "state conflict" (busy), in s
    timeout_s: float = key("number", 2.0, gt=0, type_msg="dpv1.timeout_s must be a number > 0")


@dataclass(frozen=True)
class Dpv1Config:
    slot: int = 0
    axis: int = 1
    c1_timeout_s: float = 1.0
    timeout_s: float = 2.0


@dataclass(frozen=True)
class SaveKeys:
    pnu: int | None = key("int", None, type_msg=_INT)      # `save: {}` or none: the card has no save PNU


@dataclass(frozen=True)
class ProfidriveKeys:
    """The profile's `profidrive:` section: a card's deviations from the PROFIdrive profile."""
    labels: LabelKeys = key("section", section=LabelKeys, type_msg=_MAPPING, unknown_msg=_LABEL)
    ctw_bits: dict[Any, Any] = key("mapping", {}, type_msg=_MAPPING)
    stw_bits: dict[Any, Any] = key("mapping", {}, type_msg=_MAPPING)
    held_ctw_bits: list[int] = key("ints", [], lo=0, hi=15, type_msg=_INTS)
    array_pnus: list[int] | None = key("ints", None, lo=1, hi=0x7FF, type_msg=_INTS)
    pzd_map: PzdMapKeys = _sub(PzdMapKeys)
    pkw: PkwKeys = _sub(PkwKeys)
    fault_memory: FaultMemoryKeys = _sub(FaultMemoryKeys)
    save: SaveKeys = _sub(SaveKeys)
    dpv1: Dpv1Keys | None = _sub(Dpv1Keys, nullable=True)
    baud_codes: dict[Any, Any] = key("mapping", {}, type_msg=_MAPPING)
    device_ids: dict[Any, Any] = key("mapping", {}, type_msg=_MAPPING)
    ramps: dict[Any, Any] = key("mapping", {}, type_msg=_MAPPING)
    jog_reference: str | None = key("text", None, type_msg="jog_reference {value!r} is not in parameters")


def _texts(path: str | Path, m: dict[Any, Any], message: str) -> dict[int, str]:
    """A mapping number -> text (keys and values checked, `message` on the first bad entry)."""
    for k, v in m.items():
        if not isinstance(k, int) or not isinstance(v, str):
            raise _e(path, m, k, message)
    return dict(m)


def _ramps(path: str | Path, profile: Profile, rp: dict[Any, Any]) -> dict[str, str]:
    out: dict[str, str] = {}
    for k, v in rp.items():
        if k not in ("accel", "decel", "quick_decel") or not isinstance(v, str):
            raise _e(path, rp, k, "ramps: keys accel, decel, quick_decel; values parameter codes")
        if profile.param(v) is None:
            raise _e(path, rp, k, f"ramps.{k}: parameter {v} is not in parameters")
        out[k] = v
    return out


def _e(path: str | Path, node: object, key: str, msg: str) -> DataFileError:
    line = node.line_of(key) if isinstance(node, LineDict) else getattr(node, "line", None)
    return DataFileError(path, line, msg)


def _bit_names(path: str | Path, m: dict[Any, Any], key: str) -> dict[int, str | None]:
    out: dict[int, str | None] = {}
    for k, v in m.items():
        if not isinstance(k, int) or not 0 <= k <= 15 or not (v is None or isinstance(v, str)):
            raise _e(path, m, k, f"{key}: keys are bit numbers 0..15, values names (null = unused)")
        out[k] = v
    return out


_config_cache: dict[int, tuple[object, ProfidriveConfig]] = {}


def config(profile: Profile) -> ProfidriveConfig:
    """The profile's ProfidriveConfig (validated once, cached per profile object).

    A family's row in drives/registry.py may name a `core_config` builder (profile ->
    ProfidriveConfig) from its own profile keys; otherwise the `profidrive:` section is read.
    """
    hit = _config_cache.get(id(profile))
    if hit is not None and hit[0] is profile:
        return hit[1]
    from profidrive_cli.drives.registry import core_config_reader
    hook = core_config_reader(profile)
    cfg = hook(profile) if hook is not None else ProfidriveConfig.from_profile(profile)
    _config_cache[id(profile)] = (profile, cfg)
    return cfg


def ctw_names(profile: Profile) -> dict[int, str]:
    return config(profile).ctw_names


def stw_names(profile: Profile) -> dict[int, str]:
    return config(profile).stw_names
