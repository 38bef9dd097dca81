"""Fuji OPC-G1-PDP / OPC-PDP3: the profile's Fuji keys (validated with file:line) and the core config.

`fuji_config(profile)` parses function_codes, ppo_select, parameter_channel, storage, comm_loss,
zero_data, fault_history, baud_codes (declared as FujiKeys, read by drives/sections.py) and the alarms'
M-codes into a FujiConfig (once per profile); `profidrive_config(profile)` builds the PROFIdrive core's
ProfidriveConfig from it (the family's core_config in drives/registry.py). Reads the profile only; no bus.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterable

from profidrive_cli.datafile import DataFileError, LineDict
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.profile import COMMON_EXTRA_KEYS, per_profile
from profidrive_cli.drives.sections import key, key_line, node_line, read

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import Profile

#: parameter keys this family reads besides the common schema
FAMILY_PARAM_KEYS = {"note", "dangerous", "format", "power_cycle", "array"}
FORMATS = ("hex", "fcode", "alarm", "alarm947", "baud")
STOP_ACTIONS = ("coast", "ramp", "none")


@dataclass
class CommLossAction:
    values: frozenset[int]
    stop: str            # coast | ramp | none
    delayed: bool        # wait o28 before reacting
    recover: bool        # forget the loss when the link returns within o28
    trip: bool           # trip the comm-loss alarm (Er5)


@dataclass
class FujiConfig:
    pnu_base: int = 0x100
    groups: dict[str, int] = field(default_factory=dict)          # canonical letter(s) -> code
    group_names: dict[str, str] = field(default_factory=dict)
    ppo_param: str = "o30"
    ppo_values: dict[str, frozenset[int]] = field(default_factory=dict)   # layout -> o30 values
    errors: dict[int, str] = field(default_factory=dict)
    busy_error: int = 104
    storage: dict[Any, Any] | None = None            # y97 (OPC-PDP3): its YAML mapping, checked
    comm_loss_param: str = "o27"
    comm_loss_timer: str = "o28"
    comm_loss_decel: str = "F08"
    comm_loss_alarm: str = "Er5"
    comm_loss_actions: list[CommLossAction] = field(default_factory=list)
    zero_data: dict[Any, Any] | None = None          # o32 (OPC-PDP3): its YAML mapping
    history_pnu: int = 947
    history_elements: int = 32
    history: list[tuple[str, int, str | None]] = field(default_factory=list)  # position, ind, M-code
    baud_codes: dict[int, str] = field(default_factory=dict)
    mcodes: dict[str, int] = field(default_factory=dict)         # alarm code -> M16-M19 number

    @property
    def by_lower(self) -> dict[str, str]:
        return {g.lower(): g for g in self.groups}


def _err(profile: Profile, node: object, key: str, msg: str) -> DataFileError:
    line = node.line_of(key) if isinstance(node, LineDict) else getattr(node, "line", None)
    return DataFileError(profile.path or "<profile>", line, msg)


def parse_int_set(items: Iterable[object], what: str = "value") -> frozenset[int]:
    """[0, 1, "6-255"] -> {0, 1, 6, ..., 255}."""
    out: set[int] = set()
    for it in items:
        if isinstance(it, int) and not isinstance(it, bool):
            out.add(it)
            continue
        m = re.fullmatch(r"\s*(\d+)\s*-\s*(\d+)\s*", str(it))
        if not m or int(m.group(1)) > int(m.group(2)):
            raise ValueError(f"{what} {it!r} is neither a number nor a range 'a-b'")
        out.update(range(int(m.group(1)), int(m.group(2)) + 1))
    return frozenset(out)


# -- the Fuji keys of the profile, declared (read by drives/sections.py) ------------------------------

_MAPPING = "'{key}' must be a mapping"
_GROUPS = "function_codes.groups must map group letters to {{code, name}}"


def _required(decl: type) -> Any:
    return key("section", required=True, section=decl, null_is_missing=True, type_msg=_MAPPING,
               missing_msg="missing section '{key}'")


@dataclass(frozen=True)
class FunctionCodeKeys:
    pnu_base: int = key("int", 0x100, lo=0, hi=0x700, type_msg="function_codes.pnu_base must be an integer")
    groups: dict[Any, Any] = key("mapping", required=True, type_msg=_GROUPS, missing_msg=_GROUPS)


@dataclass(frozen=True)
class PpoSelectKeys:
    param: str = key("code", "o30")


@dataclass(frozen=True)
class ParameterChannelKeys:
    errors: dict[Any, Any] = key("mapping", {}, type_msg="parameter_channel.errors must map numbers to texts")
    busy_error: Any = key("any", 104)


@dataclass(frozen=True)
class CommLossKeys:
    action_param: Any = key("any", "o27")
    timer_param: Any = key("any", "o28")
    decel_param: Any = key("any", "F08")
    alarm: Any = key("any", "Er5")
    actions: list[Any] = key("list", [], type_msg="comm_loss.actions must be a list")


@dataclass(frozen=True)
class FaultHistoryKeys:
    pnu: Any = key("any", 947)
    elements: Any = key("any", 32)
    entries: list[Any] = key("list", [], type_msg="fault_history.entries must be a list")


@dataclass(frozen=True)
class FujiKeys:
    """The top-level keys only the Fuji family reads (the common ones are drives/profile.py's)."""
    function_codes: FunctionCodeKeys = _required(FunctionCodeKeys)
    ppo_select: PpoSelectKeys = _required(PpoSelectKeys)
    parameter_channel: ParameterChannelKeys = _required(ParameterChannelKeys)
    storage: dict[Any, Any] | None = key("mapping", None, nullable=True, type_msg=_MAPPING)   # y97 (PDP3)
    comm_loss: CommLossKeys = _required(CommLossKeys)
    zero_data: dict[Any, Any] | None = key("mapping", None, nullable=True, type_msg=_MAPPING)   # o32 (PDP3)
    fault_history: FaultHistoryKeys = _required(FaultHistoryKeys)
    baud_codes: Any = key("any", {})                # number -> text; anything else is ignored


def _build_config(profile: Profile) -> FujiConfig:
    doc = profile.raw if isinstance(profile.raw, LineDict) else LineDict()
    path = profile.path or "<profile>"
    _check_params(path, profile)
    k = read(FujiKeys, path, doc, codes=lambda c: profile.param(c) is not None)
    c = FujiConfig(pnu_base=k.function_codes.pnu_base, ppo_param=str(k.ppo_select.param),
                   busy_error=k.parameter_channel.busy_error, storage=k.storage, zero_data=k.zero_data,
                   history_pnu=k.fault_history.pnu, history_elements=k.fault_history.elements)
    _read_groups(profile, k.function_codes, c)
    for name, lay in profile.layouts.items():
        vals = lay.extra.get("o30")
        if vals is None:
            continue
        try:
            c.ppo_values[name] = parse_int_set(vals if isinstance(vals, list) else [vals], "o30 value")
        except ValueError as err:
            raise _err(profile, doc.get("layouts"), name, f"layout {name}: {err}") from None
    errs = k.parameter_channel.errors
    for n, v in errs.items():
        if not isinstance(n, int) or not isinstance(v, str):
            raise _err(profile, errs, n, "parameter_channel.errors: keys are numbers, values texts")
        c.errors[n] = v
    if c.storage is not None:
        _check_storage(profile, c.storage)
    _read_comm_loss(path, profile, k.comm_loss, c)
    c.history = _history(path, profile, k.fault_history)
    if isinstance(k.baud_codes, dict):
        c.baud_codes = {int(n): str(v) for n, v in k.baud_codes.items()}
    for a in doc.get("alarms", []) or []:
        if isinstance(a, dict) and "mcode" in a:
            if not isinstance(a["mcode"], int):
                raise _err(profile, a, "mcode", "mcode must be an integer")
            c.mcodes[str(a["code"])] = a["mcode"]
    return c


def _check_params(path: str | Path, profile: Profile) -> None:
    for p in profile.parameters.values():
        unknown = set(p.extra) - FAMILY_PARAM_KEYS - COMMON_EXTRA_KEYS
        if unknown:
            raise DataFileError(path, p.line, f"{p.code}: unknown key(s) {', '.join(sorted(unknown))} "
                                f"(Fuji keys: {', '.join(sorted(FAMILY_PARAM_KEYS))})")
        fmt = p.extra.get("format")
        if fmt is not None and fmt not in FORMATS:
            raise DataFileError(path, p.line, f"{p.code}: format must be one of {', '.join(FORMATS)}")


def _read_groups(profile: Profile, fc: FunctionCodeKeys, c: FujiConfig) -> None:
    groups = fc.groups
    if not groups:
        raise DataFileError(profile.path or "<profile>", key_line(fc, "groups"), _GROUPS.format())
    for g, node in groups.items():
        if not isinstance(node, dict) or not isinstance(node.get("code"), int) \
                or not 0 <= node["code"] <= 0xFF:
            raise _err(profile, groups, g, f"group {g}: needs code 0..255")
        if not re.fullmatch(r"[A-Za-z][A-Za-z0-9]?", str(g)):
            raise _err(profile, groups, g, f"group {g!r}: one letter, optionally followed by one character")
        c.groups[str(g)] = node["code"]
        c.group_names[str(g)] = str(node.get("name", ""))
    if len({g.lower() for g in c.groups}) != len(c.groups):
        raise DataFileError(profile.path or "<profile>", key_line(fc, "groups"),
                            "group letters must differ in more than case")


def _check_storage(profile: Profile, storage: dict[Any, Any]) -> None:
    for k in ("param", "eeprom", "ram", "save", "saved_reads"):
        if k not in storage:
            raise _err(profile, storage, k if k in storage else "param", f"storage: missing '{k}'")
    if profile.param(storage["param"]) is None:
        raise _err(profile, storage, "param", f"storage.param {storage['param']} is not a parameter")


def _read_comm_loss(path: str | Path, profile: Profile, cl: CommLossKeys, c: FujiConfig) -> None:
    c.comm_loss_param, c.comm_loss_timer = str(cl.action_param), str(cl.timer_param)
    c.comm_loss_decel, c.comm_loss_alarm = str(cl.decel_param), str(cl.alarm)
    for k, code in (("action_param", c.comm_loss_param), ("timer_param", c.comm_loss_timer),
                    ("decel_param", c.comm_loss_decel)):
        if profile.param(code) is None:
            raise DataFileError(path, key_line(cl, k), f"comm_loss.{k}: {code} is not a parameter")
    if profile.alarm_by_code(c.comm_loss_alarm) is None:
        raise DataFileError(path, key_line(cl, "alarm"),
                            f"comm_loss.alarm {c.comm_loss_alarm} is not in alarms")
    if not cl.actions:
        raise DataFileError(path, key_line(cl, "actions"), "comm_loss.actions must be a list")
    for i, a in enumerate(cl.actions):
        line = getattr(a, "line", node_line(cl))
        if not isinstance(a, dict) or a.get("stop") not in STOP_ACTIONS:
            raise DataFileError(path, line, f"comm_loss.actions[{i}]: "
                                f"needs o27: [values], stop: {' | '.join(STOP_ACTIONS)}")
        try:
            vals = parse_int_set(a.get("o27", []), "o27 value")
        except ValueError as err:
            raise DataFileError(path, line, f"comm_loss.actions[{i}]: {err}") from None
        c.comm_loss_actions.append(CommLossAction(vals, a["stop"], bool(a.get("delayed", False)),
                                                  bool(a.get("recover", False)), bool(a.get("trip", True))))


def _history(path: str | Path, profile: Profile, fh: FaultHistoryKeys) -> list[tuple[str, int, str | None]]:
    if not fh.entries:
        raise DataFileError(path, key_line(fh, "entries"), "fault_history.entries must be a list")
    out: list[tuple[str, int, str | None]] = []
    for e in fh.entries:
        line = getattr(e, "line", node_line(fh))
        if not isinstance(e, dict) or not isinstance(e.get("index"), int):
            raise DataFileError(path, line, "fault_history entry needs position and index")
        m = e.get("mcode_param")
        if m is not None and profile.param(m) is None:
            raise DataFileError(path, line, f"fault_history: {m} is not a parameter")
        out.append((str(e.get("position", e["index"])), e["index"], m))
    return out


fuji_config = per_profile(_build_config)   # -> FujiConfig, built once per profile


FUJI_CTW_BITS = {0: "ON (run command)", 1: "ON2 (no OFF2 coast stop)", 2: "ON3 (no OFF3 quick stop)",
                 3: "enable operation", 4: "enable ramp generator", 5: "unfreeze ramp generator",
                 6: "enable setpoint (ON bit valid)", 7: "alarm reset (0->1 edge)", 10: "PCD valid",
                 11: "reverse"}
FUJI_STW_BITS = {0: "ready for run-ON", 1: "ready to run", 2: "running", 3: "alarm (tripped)",
                 4: "ON2 (CTW bit 1)", 5: "ON3 (CTW bit 2)", 6: "not ready for run-ON (switch-on inhibited)",
                 8: "FAR (frequency arrival)", 9: "R/L (PROFIBUS commands active)", 10: "FDT (frequency >= E31)"}


def profidrive_config(profile: Profile) -> pd.ProfidriveConfig:
    """The core's per-card configuration, built from the Fuji keys (hook used by pd.config)."""
    fc = fuji_config(profile)
    ctw = dict(pd.CTW_NAMES)
    for b in (8, 9):
        ctw.pop(b, None)
    ctw.update(FUJI_CTW_BITS)
    stw = dict(pd.STW_NAMES)
    stw.pop(7, None)
    stw.update(FUJI_STW_BITS)
    cfg = pd.ProfidriveConfig(labels={"control": "CTW", "status": "STW", "reference": "MRV",
                                      "actual": "MAV"},
                              ctw_names=ctw, stw_names=stw,
                              # Table 8.5: "b8, b9 Not used", "b12 to b15 Not used" (G1 manual L2227,
                              # L2230; PDP3 manual L5166)
                              unused_ctw_bits=frozenset({8, 9, 12, 13, 14, 15}))
    cfg.array_pnus = frozenset({pd.PNU_PZD_SETPOINT, pd.PNU_PZD_ACTUAL, fc.history_pnu})
    cfg.pkw_timeout = 2.0
    # the manual gives no handshake; hold the request until answered, AK 0 between two identical
    # requests (so a retried request after error 104 is a new task)
    cfg.zero_between_identical = True
    # Table 8.9 (spec 5.2): requests 3-5, 8, 10-15 and responses 2, 3, 5, 8-15 are "Not used"
    cfg.supported_requests = frozenset({0, 1, 2, 6, 7, 9})
    cfg.supported_responses = frozenset({0, 1, 4, 6, 7})
    cfg.unsupported_text = "not used by this card"
    cfg.error_texts = dict(pd.GENERIC_ERRORS)
    cfg.error_texts.update(fc.errors)
    cfg.error_numbers.update({"unknown_pnu": 0, "read_only": 1, "out_of_range": 2, "bad_subindex": 3,
                              "not_array": 4, "stop_only": 11, "no_rights": 1, "bad_request": 17,
                              "wrong_type": 3})
    cfg.fault_memory_pnu = fc.history_pnu
    cfg.fault_subindexes = [i for _, i, _ in fc.history]
    cfg.fault_positions = [p for p, _, _ in fc.history]
    cfg.save_pnu = None
    cfg.baud_codes = dict(fc.baud_codes)
    ramps = {}
    for role, code in (("accel", "F07"), ("decel", "F08"), ("quick_decel", "H56")):
        if profile.param(code) is not None:
            ramps[role] = code
    cfg.ramps = ramps
    return cfg
