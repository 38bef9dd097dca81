"""Per-card PROFIdrive configuration: the profile's `profidrive:` section, validated with file:line.

`ProfidriveConfig.from_profile` parses; `config(profile)` caches it and lets a family module build
it from its own keys (`profidrive_config(profile)`). Reads the profile only; no bus, no drive.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from profidrive_cli.datafile import DataFileError, LineDict
from profidrive_cli.drives.profidrive.pkw import GENERIC_ERRORS
from profidrive_cli.drives.profidrive.pnu import (PNU_FAULT_NUMBER, PNU_PZD_ACTUAL,
                                                  PNU_PZD_SETPOINT, PNU_SAVE,
                                                  default_fault_positions)
from profidrive_cli.drives.profidrive.words import CTW_NAMES, DERIVED_BITS, STW_NAMES

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

    def error_text(self, number: int) -> str:
        return self.error_texts.get(number, f"error {number}")

    @classmethod
    def from_profile(cls, profile) -> "ProfidriveConfig":
        path = profile.path or "<profile>"
        doc = profile.raw if isinstance(profile.raw, LineDict) else LineDict()
        sec = doc.get("profidrive", LineDict())
        if not isinstance(sec, dict):
            raise DataFileError(path, doc.line_of("profidrive"), "'profidrive' must be a mapping")
        known = {"labels", "ctw_bits", "stw_bits", "held_ctw_bits", "array_pnus", "pzd_map", "pkw",
                 "fault_memory", "save", "baud_codes", "device_ids", "ramps", "jog_reference"}
        _unknown(path, sec, known, "profidrive")
        labels = {"control": "CTW", "status": "STW", "reference": "MRV", "actual": "MAV"}
        lab = _map(path, sec, "labels")
        for k, v in lab.items():
            if k not in labels or not isinstance(v, str):
                raise _e(path, lab, k, f"profidrive.labels: '{k}' must be one of "
                         f"{', '.join(labels)} with a text value")
            labels[k] = v
        ctw: dict[int, str | None] = dict(CTW_NAMES)
        own = _bit_names(path, sec, "ctw_bits")
        ctw.update(own)
        stw: dict[int, str | None] = dict(STW_NAMES)
        stw.update(_bit_names(path, sec, "stw_bits"))
        ctw_names = {b: n for b, n in ctw.items() if n is not None}      # null = bit not used
        stw_names = {b: n for b, n in stw.items() if n is not None}
        held = 0
        for b in _int_list(path, sec, "held_ctw_bits", 0, 15):
            held |= 1 << b
        if held & DERIVED_BITS:
            raise _e(path, sec, "held_ctw_bits",
                     "held_ctw_bits cannot include bits 0-3, 7 or 10 (the state machine sets them)")
        cfg = cls(labels=labels, ctw_names=ctw_names, stw_names=stw_names, held_ctw_bits=held,
                  unused_ctw_bits=frozenset(b for b, n in own.items() if n is None))
        if "array_pnus" in sec:
            cfg.array_pnus = frozenset(_int_list(path, sec, "array_pnus", 1, 0x7FF))
        pm = _map(path, sec, "pzd_map")
        if pm:
            _unknown(path, pm, {"setpoint", "actual"}, "profidrive.pzd_map")
            cfg.pzd_map = (_int(path, pm, "setpoint", PNU_PZD_SETPOINT),
                           _int(path, pm, "actual", PNU_PZD_ACTUAL))
        pkw = _map(path, sec, "pkw")
        if pkw:
            _unknown(path, pkw, {"timeout_s", "zero_after_error", "zero_between_identical",
                                 "max_zero_cycles", "requests", "responses", "unsupported_text",
                                 "errors", "error_numbers"},
                     "profidrive.pkw")
            t = pkw.get("timeout_s", cfg.pkw_timeout)
            if not isinstance(t, (int, float)) or isinstance(t, bool) or t <= 0:
                raise _e(path, pkw, "timeout_s", "pkw.timeout_s must be a number > 0")
            cfg.pkw_timeout = float(t)
            for k in ("zero_after_error", "zero_between_identical"):
                if k in pkw:
                    if not isinstance(pkw[k], bool):
                        raise _e(path, pkw, k, f"pkw.{k} must be true or false")
                    setattr(cfg, k, pkw[k])
            cfg.max_zero_cycles = _int(path, pkw, "max_zero_cycles", cfg.max_zero_cycles)
            if "requests" in pkw:
                cfg.supported_requests = frozenset(_int_list(path, pkw, "requests", 0, 15))
            if "responses" in pkw:
                cfg.supported_responses = frozenset(_int_list(path, pkw, "responses", 0, 15))
            if "unsupported_text" in pkw:
                if not isinstance(pkw["unsupported_text"], str) or not pkw["unsupported_text"].strip():
                    raise _e(path, pkw, "unsupported_text", "pkw.unsupported_text must be a text")
                cfg.unsupported_text = pkw["unsupported_text"]
            errs = _map(path, pkw, "errors")
            for k, v in errs.items():
                if not isinstance(k, int) or not isinstance(v, str):
                    raise _e(path, errs, k, "pkw.errors: keys are error numbers, values texts")
                cfg.error_texts[k] = v
            en = _map(path, pkw, "error_numbers")
            for k, v in en.items():
                if k not in ERROR_ROLES or not isinstance(v, int) or isinstance(v, bool):
                    raise _e(path, en, k, f"pkw.error_numbers: '{k}' must be one of "
                             f"{', '.join(ERROR_ROLES)} with a number")
                cfg.error_numbers[k] = v
        fm = _map(path, sec, "fault_memory")
        if fm:
            _unknown(path, fm, {"pnu", "subindexes", "positions"}, "profidrive.fault_memory")
            cfg.fault_memory_pnu = _int(path, fm, "pnu", PNU_FAULT_NUMBER)
            if "subindexes" in fm:
                cfg.fault_subindexes = _int_list(path, fm, "subindexes", 0, 255)
            cfg.fault_positions = default_fault_positions(len(cfg.fault_subindexes))
            if "positions" in fm:
                pos = fm["positions"]
                if not isinstance(pos, list) or len(pos) != len(cfg.fault_subindexes) \
                        or not all(isinstance(p, str) for p in pos):
                    raise _e(path, fm, "positions",
                             "fault_memory.positions must be one text per subindex")
                cfg.fault_positions = list(pos)
        sv = _map(path, sec, "save")
        if sv:
            _unknown(path, sv, {"pnu"}, "profidrive.save")
            cfg.save_pnu = _int(path, sv, "pnu", PNU_SAVE)
        for key, attr in (("baud_codes", "baud_codes"), ("device_ids", "device_ids")):
            m = _map(path, sec, key)
            for k, v in m.items():
                if not isinstance(k, int) or not isinstance(v, str):
                    raise _e(path, m, k, f"{key}: keys are numbers, values texts")
                getattr(cfg, attr)[k] = v
        rp = _map(path, sec, "ramps")
        for k, v in rp.items():
            if k not in ("accel", "decel", "quick_decel") or not isinstance(v, str):
                raise _e(path, rp, k, "ramps: keys accel, decel, quick_decel; values parameter codes")
            if profile.param(v) is None:
                raise _e(path, rp, k, f"ramps.{k}: parameter {v} is not in parameters")
            cfg.ramps[k] = v
        if "jog_reference" in sec:
            jr = sec["jog_reference"]
            if not isinstance(jr, str) or profile.param(jr) is None:
                raise _e(path, sec, "jog_reference", f"jog_reference {jr!r} is not in parameters")
            cfg.jog_reference = jr
        return cfg


def _e(path, node, key, msg) -> DataFileError:
    line = node.line_of(key) if isinstance(node, LineDict) else getattr(node, "line", None)
    return DataFileError(path, line, msg)


def _unknown(path, node, known: set, where: str) -> None:
    for k in node:
        if k not in known:
            raise _e(path, node, k, f"{where}: unknown key '{k}' (known: {', '.join(sorted(known))})")


def _map(path, node, key) -> LineDict:
    v = node.get(key, LineDict()) if isinstance(node, dict) else LineDict()
    if not isinstance(v, dict):
        raise _e(path, node, key, f"'{key}' must be a mapping")
    if not isinstance(v, LineDict):
        ld = LineDict(v)
        ld.line, ld.key_lines = 0, {}
        v = ld
    return v


def _int(path, node, key, default: int) -> int:
    v = node.get(key, default)
    if not isinstance(v, int) or isinstance(v, bool):
        raise _e(path, node, key, f"'{key}' must be an integer, got {v!r}")
    return v


def _int_list(path, node, key, lo: int, hi: int) -> list[int]:
    v = node.get(key, [])
    if not isinstance(v, list) or not all(isinstance(x, int) and not isinstance(x, bool)
                                          and lo <= x <= hi for x in v):
        raise _e(path, node, key, f"'{key}' must be a list of integers {lo}..{hi}")
    return list(v)


def _bit_names(path, node, key) -> dict[int, str | None]:
    m = _map(path, node, key)
    out = {}
    for k, v in m.items():
        if not isinstance(k, int) or not 0 <= k <= 15 or not (v is None or isinstance(v, str)):
            raise _e(path, m, k, f"{key}: keys are bit numbers 0..15, values names (null = unused)")
        out[k] = v
    return out


_config_cache: dict[int, tuple[object, ProfidriveConfig]] = {}


def config(profile) -> ProfidriveConfig:
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


def ctw_names(profile) -> dict[int, str]:
    return config(profile).ctw_names


def stw_names(profile) -> dict[int, str]:
    return config(profile).stw_names
