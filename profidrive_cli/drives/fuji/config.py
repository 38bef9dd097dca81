"""Fuji OPC-G1-PDP / OPC-PDP3: the profile's Fuji keys (validated with file:line) and the core config.

`fuji_config(profile)` parses function_codes, ppo_select, parameter_channel, storage, comm_loss,
zero_data, fault_history, baud_codes and the alarms' M-codes into a FujiConfig (once per profile);
`profidrive_config(profile)` builds the PROFIdrive core's ProfidriveConfig from it (the hook
drives/profidrive/config.py calls). Reads the profile only; no bus.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from profidrive_cli.datafile import DataFileError, LineDict
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.profile import COMMON_EXTRA_KEYS, per_profile

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
    storage: dict | None = None            # y97 (OPC-PDP3)
    comm_loss_param: str = "o27"
    comm_loss_timer: str = "o28"
    comm_loss_decel: str = "F08"
    comm_loss_alarm: str = "Er5"
    comm_loss_actions: list[CommLossAction] = field(default_factory=list)
    zero_data: dict | None = None          # o32 (OPC-PDP3)
    history_pnu: int = 947
    history_elements: int = 32
    history: list[tuple[str, int, str | None]] = field(default_factory=list)  # position, ind, M-code
    baud_codes: dict[int, str] = field(default_factory=dict)
    mcodes: dict[str, int] = field(default_factory=dict)         # alarm code -> M16-M19 number

    @property
    def by_lower(self) -> dict[str, str]:
        return {g.lower(): g for g in self.groups}


def _err(profile, node, key, msg) -> DataFileError:
    line = node.line_of(key) if isinstance(node, LineDict) else getattr(node, "line", None)
    return DataFileError(profile.path or "<profile>", line, msg)


def parse_int_set(items, what: str = "value") -> frozenset[int]:
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


def _section(profile, doc, key, required=True):
    v = doc.get(key)
    if v is None:
        if required:
            raise DataFileError(profile.path or "<profile>", doc.line if isinstance(doc, LineDict) else None,
                                f"missing section '{key}'")
        return None
    if not isinstance(v, dict):
        raise _err(profile, doc, key, f"'{key}' must be a mapping")
    return v


def _build_config(profile) -> FujiConfig:
    doc = profile.raw if isinstance(profile.raw, LineDict) else LineDict()
    path = profile.path or "<profile>"
    c = FujiConfig()
    for p in profile.parameters.values():
        unknown = set(p.extra) - FAMILY_PARAM_KEYS - COMMON_EXTRA_KEYS
        if unknown:
            raise DataFileError(path, p.line, f"{p.code}: unknown key(s) {', '.join(sorted(unknown))} "
                                f"(Fuji keys: {', '.join(sorted(FAMILY_PARAM_KEYS))})")
        fmt = p.extra.get("format")
        if fmt is not None and fmt not in FORMATS:
            raise DataFileError(path, p.line, f"{p.code}: format must be one of {', '.join(FORMATS)}")
    fc = _section(profile, doc, "function_codes")
    base = fc.get("pnu_base", 0x100)
    if not isinstance(base, int) or not 0 <= base <= 0x700:
        raise _err(profile, fc, "pnu_base", "function_codes.pnu_base must be an integer")
    c.pnu_base = base
    groups = fc.get("groups")
    if not isinstance(groups, dict) or not groups:
        raise _err(profile, fc, "groups", "function_codes.groups must map group letters to {code, name}")
    for g, node in groups.items():
        if not isinstance(node, dict) or not isinstance(node.get("code"), int) \
                or not 0 <= node["code"] <= 0xFF:
            raise _err(profile, groups, g, f"group {g}: needs code 0..255")
        if not re.fullmatch(r"[A-Za-z][A-Za-z0-9]?", str(g)):
            raise _err(profile, groups, g, f"group {g!r}: one letter, optionally followed by one character")
        c.groups[str(g)] = node["code"]
        c.group_names[str(g)] = str(node.get("name", ""))
    if len({g.lower() for g in c.groups}) != len(c.groups):
        raise _err(profile, fc, "groups", "group letters must differ in more than case")
    ps = _section(profile, doc, "ppo_select")
    c.ppo_param = str(ps.get("param", "o30"))
    for name, lay in profile.layouts.items():
        vals = lay.extra.get("o30")
        if vals is None:
            continue
        try:
            c.ppo_values[name] = parse_int_set(vals if isinstance(vals, list) else [vals], "o30 value")
        except ValueError as err:
            raise _err(profile, doc.get("layouts"), name, f"layout {name}: {err}") from None
    pc = _section(profile, doc, "parameter_channel")
    errs = pc.get("errors", {})
    if not isinstance(errs, dict):
        raise _err(profile, pc, "errors", "parameter_channel.errors must map numbers to texts")
    for k, v in errs.items():
        if not isinstance(k, int) or not isinstance(v, str):
            raise _err(profile, errs, k, "parameter_channel.errors: keys are numbers, values texts")
        c.errors[k] = v
    c.busy_error = pc.get("busy_error", 104)
    c.storage = _section(profile, doc, "storage", required=False)
    if c.storage is not None:
        for k in ("param", "eeprom", "ram", "save", "saved_reads"):
            if k not in c.storage:
                raise _err(profile, c.storage, k if k in c.storage else "param",
                           f"storage: missing '{k}'")
        if profile.param(c.storage["param"]) is None:
            raise _err(profile, c.storage, "param", f"storage.param {c.storage['param']} is not a parameter")
    cl = _section(profile, doc, "comm_loss")
    c.comm_loss_param = str(cl.get("action_param", "o27"))
    c.comm_loss_timer = str(cl.get("timer_param", "o28"))
    c.comm_loss_decel = str(cl.get("decel_param", "F08"))
    c.comm_loss_alarm = str(cl.get("alarm", "Er5"))
    for k, code in (("action_param", c.comm_loss_param), ("timer_param", c.comm_loss_timer),
                    ("decel_param", c.comm_loss_decel)):
        if profile.param(code) is None:
            raise _err(profile, cl, k, f"comm_loss.{k}: {code} is not a parameter")
    if profile.alarm_by_code(c.comm_loss_alarm) is None:
        raise _err(profile, cl, "alarm", f"comm_loss.alarm {c.comm_loss_alarm} is not in alarms")
    acts = cl.get("actions", [])
    if not isinstance(acts, list) or not acts:
        raise _err(profile, cl, "actions", "comm_loss.actions must be a list")
    for i, a in enumerate(acts):
        if not isinstance(a, dict) or a.get("stop") not in STOP_ACTIONS:
            raise DataFileError(path, getattr(a, "line", cl.line), f"comm_loss.actions[{i}]: "
                                f"needs o27: [values], stop: {' | '.join(STOP_ACTIONS)}")
        try:
            vals = parse_int_set(a.get("o27", []), "o27 value")
        except ValueError as err:
            raise DataFileError(path, getattr(a, "line", cl.line), f"comm_loss.actions[{i}]: {err}") from None
        c.comm_loss_actions.append(CommLossAction(vals, a["stop"], bool(a.get("delayed", False)),
                                                  bool(a.get("recover", False)), bool(a.get("trip", True))))
    c.zero_data = _section(profile, doc, "zero_data", required=False)
    fh = _section(profile, doc, "fault_history")
    c.history_pnu = fh.get("pnu", 947)
    c.history_elements = fh.get("elements", 32)
    entries = fh.get("entries", [])
    if not isinstance(entries, list) or not entries:
        raise _err(profile, fh, "entries", "fault_history.entries must be a list")
    for e in entries:
        if not isinstance(e, dict) or not isinstance(e.get("index"), int):
            raise DataFileError(path, getattr(e, "line", fh.line), "fault_history entry needs position and index")
        m = e.get("mcode_param")
        if m is not None and profile.param(m) is None:
            raise DataFileError(path, getattr(e, "line", fh.line), f"fault_history: {m} is not a parameter")
        c.history.append((str(e.get("position", e["index"])), e["index"], m))
    bc = doc.get("baud_codes", {})
    if isinstance(bc, dict):
        c.baud_codes = {int(k): str(v) for k, v in bc.items()}
    for a in doc.get("alarms", []) or []:
        if isinstance(a, dict) and "mcode" in a:
            if not isinstance(a["mcode"], int):
                raise _err(profile, a, "mcode", "mcode must be an integer")
            c.mcodes[str(a["code"])] = a["mcode"]
    return c


fuji_config = per_profile(_build_config)   # -> FujiConfig, built once per profile


FUJI_CTW_BITS = {0: "ON (run command)", 1: "ON2 (no OFF2 coast stop)", 2: "ON3 (no OFF3 quick stop)",
                 3: "enable operation", 4: "enable ramp generator", 5: "unfreeze ramp generator",
                 6: "enable setpoint (ON bit valid)", 7: "alarm reset (0->1 edge)", 10: "PCD valid",
                 11: "reverse"}
FUJI_STW_BITS = {0: "ready for run-ON", 1: "ready to run", 2: "running", 3: "alarm (tripped)",
                 4: "ON2 (CTW bit 1)", 5: "ON3 (CTW bit 2)", 6: "not ready for run-ON (switch-on inhibited)",
                 8: "FAR (frequency arrival)", 9: "R/L (PROFIBUS commands active)", 10: "FDT (frequency >= E31)"}


def profidrive_config(profile) -> pd.ProfidriveConfig:
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
