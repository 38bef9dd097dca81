"""Toyo PBUS66-Z profile keys: layouts (mode 0/1, word lists), fields, bit tables, parameter channel,
fault history and traceback, checked with file:line (DataFileError); and the PROFIdrive core's
configuration for this card (the profidrive_config hook).

May touch: datafile, drives/profile, drives/profidrive (its config types). Reads the profile only.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from profidrive_cli.datafile import DataFileError, LineDict
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.profile import COMMON_EXTRA_KEYS, per_profile

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
    fields: dict[str, dict] = field(default_factory=dict)
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


def input_words(profile, layout: str) -> list[str]:
    """The names of `layout`'s input words as the drive reads them (PLC registers with PLCH on)."""
    tc = toyo_config(profile)
    tl = tc.layouts[layout]
    return list(tl.words("response", tc.plch or tl.plch))


def _err(profile, node, key, msg) -> DataFileError:
    line = node.line_of(key) if isinstance(node, LineDict) else getattr(node, "line", None)
    return DataFileError(profile.path or "<profile>", line, msg)


def _sec(profile, doc, key) -> dict:
    v = doc.get(key)
    if not isinstance(v, dict):
        raise _err(profile, doc, key, f"'{key}' must be a mapping") if key in doc else \
            DataFileError(profile.path or "<profile>", doc.line if isinstance(doc, LineDict) else None,
                          f"missing section '{key}'")
    return v


def _build_config(profile) -> ToyoConfig:
    doc = profile.raw if isinstance(profile.raw, LineDict) else LineDict()
    path = profile.path or "<profile>"
    c = ToyoConfig(word_order=profile.word_order)
    dwo = doc.get("diag_word_order", "big")
    if dwo not in ("big", "little"):
        raise _err(profile, doc, "diag_word_order", "diag_word_order must be big or little")
    c.diag_word_order = dwo
    plch = doc.get("plch", False)
    if not isinstance(plch, bool):
        raise _err(profile, doc, "plch", "plch must be true or false")
    c.plch = plch
    c.speed_full_scale = doc.get("speed_full_scale", 20000)
    if not isinstance(c.speed_full_scale, int) or c.speed_full_scale <= 0:
        raise _err(profile, doc, "speed_full_scale", "speed_full_scale must be a positive integer")
    c.voltage_class = doc.get("voltage_class", 200)
    if c.voltage_class not in (200, 400):
        raise _err(profile, doc, "voltage_class", "voltage_class must be 200 or 400")
    for p in profile.parameters.values():
        unknown = set(p.extra) - FAMILY_PARAM_KEYS - COMMON_EXTRA_KEYS
        if unknown:
            raise DataFileError(path, p.line, f"{p.code}: unknown key(s) {', '.join(sorted(unknown))} "
                                f"(Toyo keys: {', '.join(sorted(FAMILY_PARAM_KEYS))})")
    bits = _sec(profile, doc, "bits")
    for name, table in bits.items():
        if not isinstance(table, dict) or not all(isinstance(k, int) and 0 <= k <= 15 for k in table):
            raise _err(profile, bits, name, f"bits.{name}: keys are bit numbers 0..15")
        c.bits[str(name)] = {int(k): str(v) for k, v in table.items()}
    fields = _sec(profile, doc, "fields")
    for name, f in fields.items():
        if not isinstance(f, dict) or f.get("kind") not in FIELD_KINDS:
            raise _err(profile, fields, name, f"fields.{name}: kind must be one of {', '.join(FIELD_KINDS)}")
        if f["kind"] == "bits" and f.get("bits") not in c.bits:
            raise _err(profile, f, "bits", f"fields.{name}: bits {f.get('bits')!r} is not in bits")
        if f["kind"] == "param" and profile.param(str(f.get("param"))) is None:
            raise _err(profile, f, "param", f"fields.{name}: {f.get('param')!r} is not a parameter")
        c.fields[str(name)] = dict(f)
    lays = doc.get("layouts")
    for name, lay in profile.layouts.items():
        ex = lay.extra
        node = lays.get(name) if isinstance(lays, dict) else None
        mode = ex.get("mode", 0)
        if mode not in (0, 1):
            raise _err(profile, node, "mode", f"layout {name}: mode must be 0 or 1")
        lists = {}
        for key in ("out", "in", "out_plch", "in_plch"):
            v = ex.get(key)
            if v is None:
                continue
            if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
                raise _err(profile, node, key, f"layout {name}: {key} must be a list of field names")
            for x in v:
                if x not in c.fields and not re.fullmatch(r"[io]000[0-9A-F]{2}", x):
                    raise _err(profile, node, key, f"layout {name}: unknown field {x!r}")
            pk = 4 if lay.pkw else 0
            want = (lay.output_len if key.startswith("out") else lay.input_len) // 2 - pk
            if len(v) != want:
                raise _err(profile, node, key, f"layout {name}: {key} lists {len(v)} words, the cfg "
                           f"gives {want}")
            lists[key] = list(v)
        if "out" not in lists or "in" not in lists:
            raise _err(profile, lays, name, f"layout {name}: needs out and in word lists")
        c.layouts[name] = ToyoLayout(name, mode, lay.pkw, lists["out"], lists["in"], lists.get("out_plch"),
                                     lists.get("in_plch"), bool(ex.get("plch", False)))
    pc = _sec(profile, doc, "parameter_channel")
    for k, v in (pc.get("errors") or {}).items():
        c.errors[int(k)] = str(v)
    c.block_bit = pc.get("block_bit", 10)
    c.zero_after_error = bool(pc.get("zero_after_error", True))
    fh = _sec(profile, doc, "fault_history")
    c.history_pnu = fh.get("pnu", 720)
    c.history_indexes = list(fh.get("indexes", [1, 2, 3, 4, 5, 6]))
    c.history_code_mask = fh.get("code_mask", 0xFF)
    c.history_mode_shift = fh.get("mode_shift", 8)
    c.history_block_bit = fh.get("block_bit", 12)
    c.history_modes = {int(k): str(v) for k, v in (fh.get("modes") or {}).items()}
    c.empty_error = fh.get("empty_error", 101)
    tb = _sec(profile, doc, "traceback")
    c.traceback_pnu = tb.get("pnu", 700)
    c.traceback_channels = tb.get("channels", 16)
    c.traceback_recordings = tb.get("recordings", 4)
    c.traceback_points = tb.get("points", 100)
    return c


toyo_config = per_profile(_build_config)   # -> ToyoConfig, built once per profile


def profidrive_config(profile) -> pd.ProfidriveConfig:
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
