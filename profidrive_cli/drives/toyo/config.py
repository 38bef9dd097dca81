"""Toyo PBUS66-Z profile keys: layouts (mode 0/1, word lists), fields, bit tables, parameter channel,
fault history and traceback, checked with file:line (DataFileError); and the PROFIdrive core's
configuration for this card (the profidrive_config hook).

May touch: datafile, drives/profile, drives/sections (the Toyo keys' declaration), drives/profidrive (its
config types). Reads the profile only.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from profidrive_cli.datafile import DataFileError, LineDict
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.profile import COMMON_EXTRA_KEYS, per_profile
from profidrive_cli.drives.sections import key, read

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import Profile

FAMILY_PARAM_KEYS = {"power_cycle", "format", "bits", "plc", "scale_400v", "traceback", "note"}
FIELD_KINDS = ("ctw", "zsw", "run_cmd", "bits", "speed", "scaled", "date", "raw", "param")


@dataclass
class ToyoLayout:
    name: str
    mode: int
    pkw: bool
    out: list[str]
    inp: list[str]
    out_plch: list[str] | None = None
    in_plch: list[str] | None = None
    plch: bool = False           # the layout itself is a PLCH frame (toyo_plch)

    def words(self, direction: str, plch: bool) -> list[str]:
        if direction == "request":
            return self.out_plch if plch and self.out_plch else self.out
        return self.in_plch if plch and self.in_plch else self.inp


@dataclass
class ToyoConfig:
    word_order: str = "little"
    diag_word_order: str = "big"
    plch: bool = False
    speed_full_scale: int = 20000
    voltage_class: int = 200
    layouts: dict[str, ToyoLayout] = field(default_factory=dict)
    #: name -> the field's YAML mapping (its kind checked; name, bits, param, unit, scale, signed
    #: read where they are used): Any, parsed YAML
    fields: dict[str, dict[str, Any]] = field(default_factory=dict)
    bits: dict[str, dict[int, str]] = field(default_factory=dict)
    errors: dict[int, str] = field(default_factory=dict)
    block_bit: int = 10
    zero_after_error: bool = True
    history_pnu: int = 720
    history_indexes: list[int] = field(default_factory=lambda: [1, 2, 3, 4, 5, 6])
    history_code_mask: int = 0xFF
    history_mode_shift: int = 8
    history_block_bit: int = 12
    history_modes: dict[int, str] = field(default_factory=dict)
    empty_error: int = 101
    traceback_pnu: int = 700
    traceback_channels: int = 16
    traceback_recordings: int = 4
    traceback_points: int = 100


def input_words(profile: Profile, layout: str) -> list[str]:
    """The names of `layout`'s input words as the drive reads them (PLC registers with PLCH on)."""
    tc = toyo_config(profile)
    tl = tc.layouts[layout]
    return list(tl.words("response", tc.plch or tl.plch))


def _err(profile: Profile, node: object, key: str, msg: str) -> DataFileError:
    line = node.line_of(key) if isinstance(node, LineDict) else getattr(node, "line", None)
    return DataFileError(profile.path or "<profile>", line, msg)


# -- the Toyo keys of the profile, declared (read by drives/sections.py) ------------------------------

_MAPPING = "'{key}' must be a mapping"
_MISSING = "missing section '{key}'"


def _required(kind: str, **rules: Any) -> Any:
    return key(kind, required=True, type_msg=_MAPPING, missing_msg=_MISSING, **rules)


@dataclass(frozen=True)
class ParameterChannelKeys:
    errors: Any = key("any", None)                  # number -> text (the card's PKW error numbers)
    block_bit: Any = key("any", 10)
    zero_after_error: Any = key("any", True)


@dataclass(frozen=True)
class FaultHistoryKeys:
    pnu: Any = key("any", 720)
    indexes: Any = key("any", [1, 2, 3, 4, 5, 6])
    code_mask: Any = key("any", 0xFF)
    mode_shift: Any = key("any", 8)
    block_bit: Any = key("any", 12)
    modes: Any = key("any", None)
    empty_error: Any = key("any", 101)


@dataclass(frozen=True)
class TracebackKeys:
    pnu: Any = key("any", 700)
    channels: Any = key("any", 16)
    recordings: Any = key("any", 4)
    points: Any = key("any", 100)


@dataclass(frozen=True)
class ToyoKeys:
    """The top-level keys only the Toyo family reads (the common ones are drives/profile.py's)."""
    diag_word_order: str = key("any", "big", choices=("big", "little"),
                               type_msg="diag_word_order must be big or little")
    plch: bool = key("bool", False, type_msg="plch must be true or false")
    speed_full_scale: int = key("int", 20000, gt=0, type_msg="speed_full_scale must be a positive integer")
    voltage_class: int = key("any", 200, choices=(200, 400), type_msg="voltage_class must be 200 or 400")
    bits: dict[Any, Any] = _required("mapping")
    fields: dict[Any, Any] = _required("mapping")
    parameter_channel: ParameterChannelKeys = _required("section", section=ParameterChannelKeys)
    fault_history: FaultHistoryKeys = _required("section", section=FaultHistoryKeys)
    traceback: TracebackKeys = _required("section", section=TracebackKeys)


def _build_config(profile: Profile) -> ToyoConfig:
    doc = profile.raw if isinstance(profile.raw, LineDict) else LineDict()
    path = profile.path or "<profile>"
    k = read(ToyoKeys, path, doc)
    c = ToyoConfig(word_order=profile.word_order, diag_word_order=k.diag_word_order, plch=k.plch,
                   speed_full_scale=k.speed_full_scale, voltage_class=k.voltage_class)
    for p in profile.parameters.values():
        unknown = set(p.extra) - FAMILY_PARAM_KEYS - COMMON_EXTRA_KEYS
        if unknown:
            raise DataFileError(path, p.line, f"{p.code}: unknown key(s) {', '.join(sorted(unknown))} "
                                f"(Toyo keys: {', '.join(sorted(FAMILY_PARAM_KEYS))})")
    for name, table in k.bits.items():
        if not isinstance(table, dict) or not all(isinstance(b, int) and 0 <= b <= 15 for b in table):
            raise _err(profile, k.bits, name, f"bits.{name}: keys are bit numbers 0..15")
        c.bits[str(name)] = {int(b): str(v) for b, v in table.items()}
    c.fields = _fields(profile, k.fields, c.bits)
    c.layouts = _layouts(profile, doc.get("layouts"), c.fields)
    pc = k.parameter_channel
    c.errors = {int(n): str(v) for n, v in (pc.errors or {}).items()}
    c.block_bit, c.zero_after_error = pc.block_bit, bool(pc.zero_after_error)
    fh = k.fault_history
    c.history_pnu, c.history_indexes, c.history_code_mask = fh.pnu, list(fh.indexes), fh.code_mask
    c.history_mode_shift, c.history_block_bit, c.empty_error = fh.mode_shift, fh.block_bit, fh.empty_error
    c.history_modes = {int(m): str(v) for m, v in (fh.modes or {}).items()}
    tb = k.traceback
    c.traceback_pnu, c.traceback_channels = tb.pnu, tb.channels
    c.traceback_recordings, c.traceback_points = tb.recordings, tb.points
    return c


def _fields(profile: Profile, fields: dict[Any, Any], bits: dict[str, dict[int, str]]
            ) -> dict[str, dict[str, Any]]:
    out: dict[str, dict[str, Any]] = {}
    for name, f in fields.items():
        if not isinstance(f, dict) or f.get("kind") not in FIELD_KINDS:
            raise _err(profile, fields, name, f"fields.{name}: kind must be one of {', '.join(FIELD_KINDS)}")
        if f["kind"] == "bits" and f.get("bits") not in bits:
            raise _err(profile, f, "bits", f"fields.{name}: bits {f.get('bits')!r} is not in bits")
        if f["kind"] == "param" and profile.param(str(f.get("param"))) is None:
            raise _err(profile, f, "param", f"fields.{name}: {f.get('param')!r} is not a parameter")
        out[str(name)] = dict(f)
    return out


def _layouts(profile: Profile, lays: object, fields: dict[str, dict[str, Any]]) -> dict[str, ToyoLayout]:
    out: dict[str, ToyoLayout] = {}
    for name, lay in profile.layouts.items():
        ex = lay.extra
        node = lays.get(name) if isinstance(lays, dict) else None
        mode = ex.get("mode", 0)
        if mode not in (0, 1):
            raise _err(profile, node, "mode", f"layout {name}: mode must be 0 or 1")
        lists: dict[str, list[str]] = {}
        for key in ("out", "in", "out_plch", "in_plch"):
            v = ex.get(key)
            if v is None:
                continue
            if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
                raise _err(profile, node, key, f"layout {name}: {key} must be a list of field names")
            for x in v:
                if x not in fields and not re.fullmatch(r"[io]000[0-9A-F]{2}", x):
                    raise _err(profile, node, key, f"layout {name}: unknown field {x!r}")
            pk = 4 if lay.pkw else 0
            want = (lay.output_len if key.startswith("out") else lay.input_len) // 2 - pk
            if len(v) != want:
                raise _err(profile, node, key, f"layout {name}: {key} lists {len(v)} words, the cfg "
                           f"gives {want}")
            lists[key] = list(v)
        if "out" not in lists or "in" not in lists:
            raise _err(profile, lays, name, f"layout {name}: needs out and in word lists")
        out[name] = ToyoLayout(name, mode, lay.pkw, lists["out"], lists["in"], lists.get("out_plch"),
                               lists.get("in_plch"), bool(ex.get("plch", False)))
    return out


toyo_config = per_profile(_build_config)   # -> ToyoConfig, built once per profile


def profidrive_config(profile: Profile) -> pd.ProfidriveConfig:
    """The core's configuration for this card (hook used by pd.config)."""
    tc = toyo_config(profile)
    ctw = {b: t for b, t in tc.bits.get("ctw", {}).items()}
    stw = {b: t for b, t in tc.bits.get("zsw", {}).items()}
    cfg = pd.ProfidriveConfig(labels={"control": "STW", "status": "ZSW", "reference": "speed command",
                                      "actual": "motor speed"},
                              ctw_names=ctw or dict(pd.CTW_NAMES), stw_names=stw or dict(pd.STW_NAMES))
    cfg.array_pnus = frozenset(list(range(tc.traceback_pnu, tc.traceback_pnu + tc.traceback_channels))
                               + [tc.history_pnu])
    cfg.pkw_timeout = 2.0
    cfg.zero_after_error = tc.zero_after_error
    cfg.zero_between_identical = True
    cfg.supported_requests = frozenset({1, 2, 6})
    cfg.error_texts = dict(pd.GENERIC_ERRORS)
    cfg.error_texts.update(tc.errors)
    cfg.error_numbers.update({"unknown_pnu": 0, "read_only": 1, "out_of_range": 2, "bad_subindex": 3,
                              "not_array": 102, "wrong_type": 2, "stop_only": 1, "no_rights": 1,
                              "bad_request": 102})
    cfg.fault_memory_pnu = tc.history_pnu
    cfg.fault_subindexes = list(tc.history_indexes)
    cfg.fault_positions = ["newest"] + [f"{i} back" for i in range(1, len(tc.history_indexes))]
    cfg.save_pnu = None
    return cfg
