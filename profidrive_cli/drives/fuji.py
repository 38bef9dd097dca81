"""Fuji Electric OPC-G1-PDP (FRENIC-MEGA) and OPC-PDP3 (FRENIC): the PROFIdrive core plus the dialect.

Dialect (profiles/fuji-opc-g1-pdp.yaml, profiles/fuji-opc-pdp3.yaml; keys function_codes,
ppo_select, parameter_channel, storage, comm_loss, zero_data, fault_history, baud_codes):
  * the card's words: CTW/STW, MRV/MAV, PCV = PCA (RC|SPM|PNU), IND, PVA(H)/PVA(L), PCD1-4
  * every inverter function code through the PKW channel: PNU = 0x100 + group code, subindex = the
    code's number (F26 -> PNU 0x104, IND 0x1A00), non-array request IDs 1/2; codes not in the profile
    are reached raw by name ("C05"); PROFIdrive PNUs 915/916/947 use the array IDs 6/7/9
  * request IDs 1, 2, 6, 7, 9; response IDs 1, 4, 6, 7; 16-bit values in PVA(L) only
  * error numbers 0-4, 11 (running), 17, 101 (link priority), 104 (busy: retried until the timeout)
  * CTW bit 10 = PCD valid, bit 11 = reverse (direction = sign of MRV XOR bit 11);
    STW bit 8 FAR, 9 R/L, 10 FDT (E31); MRV/MAV: 0x4000 = F03
  * o30 selects the PPO (power cycle); o27/o28 the reaction to a communication loss (trip Er5);
    y97 (OPC-PDP3) RAM vs EEPROM storage, save = write 2 and wait for 1
  * fault memory PNU947 subindexes 1, 9, 17, 25 (PROFIdrive malfunction codes, several alarms per
    code) and M16-M19 (the exact alarm code): the history lists every candidate, narrowed by M16-M19

Module API: make_drive, decode_area, param_value, profidrive_config, fuji_config,
parse_function_code, function_code_name, pcd_assignment, pcd_assignment_code, alarm_candidates,
alarm_by_mcode, ppo_for_o30, comm_loss_action, FujiDrive, FujiConfig.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from profidrive_cli import UsageError
from profidrive_cli.datafile import DataFileError, LineDict
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.base import DriveError, DriveStatus, FaultRecord, ParamError, ParamValue
from profidrive_cli.drives.profile import COMMON_EXTRA_KEYS, per_profile

# =============================================================================================
# profile keys
# =============================================================================================

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
        except ValueError as e:
            raise _err(profile, doc.get("layouts"), name, f"layout {name}: {e}") from None
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
        except ValueError as e:
            raise DataFileError(path, getattr(a, "line", cl.line), f"comm_loss.actions[{i}]: {e}") from None
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
                              ctw_names=ctw, stw_names=stw)
    cfg.array_pnus = frozenset({pd.PNU_PZD_SETPOINT, pd.PNU_PZD_ACTUAL, fc.history_pnu})
    cfg.pkw_timeout = 2.0
    # the manual gives no handshake; hold the request until answered, AK 0 between two identical
    # requests (so a retried request after error 104 is a new task)
    cfg.zero_between_identical = True
    cfg.supported_requests = frozenset({1, 2, 6, 7, 9})
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


# =============================================================================================
# function codes
# =============================================================================================

def parse_function_code(profile, text: str) -> tuple[str, int, int, int] | None:
    """'F26' -> ('F26', group code 4, pnu 0x104, subindex 26); None when it is not a function code.

    Group letters match in any case ('Y98' = 'y98'). A two-character group (W1, J1, o1, ...) wins when
    exactly two digits follow ('J101' = J1 number 1); otherwise one letter and 1..3 digits ('y100').
    """
    fc = fuji_config(profile)
    t = text.strip()
    low = fc.by_lower
    m = re.fullmatch(r"([A-Za-z])([A-Za-z0-9]?)(\d+)", t)
    if not m:
        return None
    g2 = (m.group(1) + m.group(2)).lower()
    digits = m.group(3)
    if m.group(2) and m.group(2).isdigit():
        # letter + digit + digits: could be a two-character group or a one-letter code
        two = (m.group(1) + m.group(2)).lower()
        if two in low and len(digits) == 2:
            g, num = low[two], int(digits)
        elif m.group(1).lower() in low:
            g, num = low[m.group(1).lower()], int(m.group(2) + digits)
        else:
            return None
    elif m.group(2):
        if g2 not in low:
            return None
        g, num = low[g2], int(digits)
    else:
        if m.group(1).lower() not in low:
            return None
        g, num = low[m.group(1).lower()], int(digits)
    if not 0 <= num <= 255:
        return None
    return f"{g}{num:02d}", fc.groups[g], fc.pnu_base + fc.groups[g], num


def function_code_name(profile, pnu: int, subindex: int) -> str | None:
    """PNU 0x104, subindex 26 -> 'F26' (None outside the function-code PNUs)."""
    fc = fuji_config(profile)
    code = pnu - fc.pnu_base
    for g, c in fc.groups.items():
        if c == code and 0 <= code <= 0xFF:
            return f"{g}{subindex:02d}"
    return None


def pcd_assignment(profile, code: str) -> int:
    """The o40-o51 / PNU915/916 word for a function code: group << 8 | number (F26 -> 0x041A)."""
    r = parse_function_code(profile, code)
    if r is None:
        raise UsageError(f"{code} is not a function code of {profile.name}")
    return r[1] << 8 | r[3]


def pcd_assignment_code(profile, word: int) -> str | None:
    """0x041A -> 'F26'; 0 -> None (not assigned)."""
    if word == 0:
        return None
    fc = fuji_config(profile)
    return function_code_name(profile, fc.pnu_base + (word >> 8), word & 0xFF)


# =============================================================================================
# alarms, PPO selection, communication loss
# =============================================================================================


def alarm_candidates(profile, number: int) -> list:
    """Every alarm that a PNU947 malfunction code can stand for (several for 0x2212 etc.)."""
    return profile.alarms_for(number)


def alarm_by_mcode(profile, mcode: int):
    fc = fuji_config(profile)
    for a in profile.alarms:
        if fc.mcodes.get(a.code) == mcode:
            return a
    return None


def mcode_of(profile, code: str) -> int | None:
    return fuji_config(profile).mcodes.get(code)


def alarm_text(profile, number: int) -> str:
    if number == 0:
        return "no alarm"
    al = alarm_candidates(profile, number)
    if not al:
        return f"unknown malfunction code 0x{number:04X}"
    txt = " or ".join(f"{a.code} ({a.meaning})" for a in al)
    return txt if len(al) == 1 else f"one of {txt}"


def ppo_for_o30(profile, value: int) -> str | None:
    for name, vals in fuji_config(profile).ppo_values.items():
        if value in vals:
            return name
    return None


def o30_for_layout(profile, layout: str) -> int | None:
    vals = fuji_config(profile).ppo_values.get(layout)
    if not vals:
        return None
    n = re.fullmatch(r"ppo(\d)", layout)
    if n and int(n.group(1)) in vals:
        return int(n.group(1))
    return min(vals)


def comm_loss_action(profile, o27: int) -> CommLossAction:
    for a in fuji_config(profile).comm_loss_actions:
        if o27 in a.values:
            return a
    # outside the table: the factory behaviour (coast and trip)
    return CommLossAction(frozenset({o27}), "coast", False, False, True)


def comm_loss_text(profile, o27: int, o28: float) -> str:
    fc = fuji_config(profile)
    a = comm_loss_action(profile, o27)
    if a.stop == "none":
        return f"{fc.comm_loss_param} = {o27}: a communication loss is ignored (no {fc.comm_loss_alarm})"
    stop = "coast to a stop" if a.stop == "coast" else f"decelerate with {fc.comm_loss_decel}"
    when = f"after {fc.comm_loss_timer} = {o28:g} s" if a.delayed else "at once"
    rec = (f" unless the link returns within {o28:g} s" if a.recover else "") if a.delayed else ""
    return f"{fc.comm_loss_param} = {o27}: {stop} {when}{rec}, then trip {fc.comm_loss_alarm}"


def param_value(profile, param, raw: int):
    """Hook used by the core decoder: engineering value of a wire value."""
    return param.from_raw(raw & 0xFFFF)


# =============================================================================================
# the Drive
# =============================================================================================


class FujiDrive(pd.ProfidriveDrive):
    family = "fuji"

    def __init__(self, channel, profile, layout: str | None = None):
        self.fc = fuji_config(profile)
        super().__init__(channel, profile, layout)
        #: remarks for the user from the last calls (e.g. "o30 takes effect after a power cycle")
        self.notes: list[str] = []

    # -- addressing ----------------------------------------------------------------------------
    def resolve_param(self, code: str) -> pd.ParamRef:
        text = code.strip()
        fcode = parse_function_code(self.profile, text)
        if fcode is not None:
            canon, _, pnu, sub = fcode
            p = self.profile.param(canon)
            if p is not None:
                return pd.ParamRef(p.code, p.name, p.pnu, p.index or 0, False, p.size, p)
            return pd.ParamRef(canon, "", pnu, sub, False, 16, None)
        m = re.fullmatch(r"(?i)P(?:NU)?\s*(\d+)", text)   # "PNU918" / "P918" short forms
        if m and self.profile.param(f"PNU{int(m.group(1))}") is not None:
            text = f"PNU{int(m.group(1))}"
        return pd.resolve_code(self.profile, text, self.cfg)

    # -- PKW with the busy retry ---------------------------------------------------------------
    def request(self, frame: pd.PkwFrame, timeout: float | None = None) -> pd.PkwResult:
        """Run one request; error 104 (busy, a write still in progress) is retried until the timeout."""
        limit = timeout if timeout is not None else self.cfg.pkw_timeout
        end = self.channel.now() + max(limit, 6.0)
        while True:
            res = super().request(frame, timeout)
            if res.error != self.fc.busy_error or self.channel.now() > end:
                return res
            for _ in range(3):
                self.cycle()

    def write_refused_message(self, ref: pd.ParamRef, value, result: pd.PkwResult) -> str:
        if result.error == 1:
            return (f"{ref.label}: the card refused the write (error 1: {result.error_text}); either "
                    f"the code is read-only or PNU927 = 0 blocks parameter writes (write PNU927 = 1)")
        if result.error == 11:
            return (f"{ref.label} cannot be changed while the inverter runs or a run-command input is "
                    f"on (error 11); stop it first")
        if result.error == 101:
            return (f"{ref.label}: link priority error (error 101): another command source (y99, LE/LOC "
                    f"terminals) has priority")
        if result.error == self.fc.busy_error:
            return f"{ref.label}: the card stayed busy (error {result.error}); try again"
        return super().write_refused_message(ref, value, result)

    def write_param(self, code: str, value) -> ParamValue:
        pv = super().write_param(code, value)
        ref = self.resolve_param(code)
        if ref.param is not None and ref.param.extra.get("power_cycle"):
            self.notes.append(f"{ref.code} takes effect after the inverter is switched off and on")
        return pv

    def jog(self, on: bool = True) -> None:
        raise DriveError(f"{self.profile.name}: CTW bits 8 and 9 are not used by this card; there is no jog "
                         f"over PROFIBUS (use a reference instead)")

    def start_hint(self, status: DriveStatus) -> str:
        hint = ("the card takes CTW/MRV only with y98 = 3 (run and frequency from PROFIBUS), CTW bits "
                "4, 5, 6 and 10 = 1, and no higher-priority source (H30, y99, LE/LOC terminals)")
        if not status.flags.get(FUJI_STW_BITS[9], True):
            hint = "STW bit 9 (R/L) is 0: PROFIBUS is not the command source; " + hint
        return hint

    # -- faults --------------------------------------------------------------------------------
    def _mcode(self, param: str | None) -> int | None:
        if param is None or self.pkw is None:
            return None
        try:
            return int(self.read_param(param).raw)
        except DriveError:
            return None

    def fault_record(self, position: str, raw: int, mcode: int | None) -> FaultRecord:
        if raw == 0 and not mcode:
            return FaultRecord(position, 0, [], ["no alarm"])
        cands = alarm_candidates(self.profile, raw)
        exact = alarm_by_mcode(self.profile, mcode) if mcode else None
        if exact is not None and (not cands or exact in cands):
            return FaultRecord(position, raw, [exact.code], [exact.meaning])
        if not cands:
            return FaultRecord(position, raw, [f"?0x{raw:04X}"], [f"unknown malfunction code 0x{raw:04X}"])
        return FaultRecord(position, raw, [a.code for a in cands], [a.meaning for a in cands])

    def fault_history(self) -> list[FaultRecord]:
        """PNU947 (1, 9, 17, 25), each narrowed to one alarm by M16-M19 when they can be read."""
        out = []
        for pos, ind, mparam in self.fc.history:
            res = self.request(pd.read_request(self.fc.history_pnu, ind, array=True))
            if not res.ok:
                raise ParamError(f"fault memory PNU {self.fc.history_pnu}[{ind}]: {res.describe_error()}",
                                 res.error)
            out.append(self.fault_record(pos, res.value & 0xFFFF, self._mcode(mparam)))
        return out

    def current_alarm(self) -> FaultRecord | None:
        if self.pkw is None:
            return None
        pos, ind, mparam = self.fc.history[0]
        try:
            raw = self.read_raw(self.fc.history_pnu, ind, array=True) & 0xFFFF
        except DriveError:
            return None
        return self.fault_record(pos, raw, self._mcode(mparam))

    def status(self) -> DriveStatus:
        self._ensure_fmax()
        st = self.cycle()
        if st.fault:
            rec = self.current_alarm()
            if rec is not None and rec.codes:
                st.fault_code = "/".join(rec.codes)
        return st

    # -- storage -------------------------------------------------------------------------------
    def save(self, timeout: float = 15.0) -> None:
        """OPC-PDP3: y97 = 2 copies the RAM data into EEPROM; y97 reads 1 when done."""
        s = self.fc.storage
        if s is None:
            raise DriveError(f"{self.profile.name}: PKW writes go straight to the inverter's memory; "
                             f"there is no separate save (y97 is an OPC-PDP3 feature)")
        code = s["param"]
        self.write_raw_code(code, s["save"])
        end = self.channel.now() + max(timeout, float(s.get("save_time_s", 5.0)) + 1.0)
        while True:
            if int(self.read_param(code).raw) == s["saved_reads"]:
                return
            if self.channel.now() > end:
                raise DriveError(f"{code} did not return to {s['saved_reads']} within {timeout:g} s: "
                                 f"save not confirmed (do not switch off yet)")
            for _ in range(10):
                self.cycle()

    def write_raw_code(self, code: str, raw: int) -> None:
        ref = self.resolve_param(code)
        res = self.request(pd.write_request(ref.pnu, raw, ref.subindex, ref.array))
        if not res.ok:
            raise ParamError(self.write_refused_message(ref, raw, res), res.error)

    def storage_mode(self) -> str:
        s = self.fc.storage
        if s is None:
            return "direct (every write is stored)"
        v = int(self.read_param(s["param"]).raw)
        return {s["eeprom"]: "EEPROM (non-volatile; limited write cycles)",
                s["ram"]: "RAM only (lost at power-off; save to keep)"}.get(v, f"{s['param']} = {v}")

    def set_storage(self, where: str) -> None:
        s = self.fc.storage
        if s is None:
            raise DriveError(f"{self.profile.name}: storage selection (y97) is an OPC-PDP3 feature")
        if where not in ("ram", "eeprom"):
            raise UsageError("storage must be ram or eeprom")
        self.write_raw_code(s["param"], s[where])

    # -- settings summaries --------------------------------------------------------------------
    def comm_loss_setting(self) -> str:
        fc = self.fc
        o27 = int(self.read_param(fc.comm_loss_param).raw)
        o28 = float(self.read_param(fc.comm_loss_timer).value)
        return comm_loss_text(self.profile, o27, o28)

    def ppo_setting(self) -> str:
        v = int(self.read_param(self.fc.ppo_param).raw)
        lay = ppo_for_o30(self.profile, v)
        return f"{self.fc.ppo_param} = {v}: {lay.upper() if lay else '?'}" + (
            "" if lay == self.layout else f" (the master uses {self.layout.upper()}: power-cycle "
                                          f"after changing {self.fc.ppo_param})")


def make_drive(channel, profile, layout: str | None = None) -> FujiDrive:
    fuji_config(profile)
    return FujiDrive(channel, profile, layout)


# =============================================================================================
# decoder
# =============================================================================================


def _hex_word(w: int) -> str:
    return f"0x{w:04X}"


def _replace_value_text(out: dict, pk: dict, new: str) -> None:
    old = pk.get("value_text")
    if not old:
        return
    for holder in (pk, out):
        holder["summary"] = holder["summary"].replace(old, new)
    pk["text"] = pk["text"].replace(f"-> {old}", f"-> {new}")
    text = out["text"]
    for i, line in enumerate(text):
        if line.startswith("PKE ") and f"-> {old}" in line:
            text[i] = line.replace(f"-> {old}", f"-> {new}")
    if text and text[-1].startswith("summary: "):
        text[-1] = "summary: " + out["summary"]
    pk["value_text"] = new


def _rename_in_summary(out: dict, pk: dict, code: str) -> None:
    """Say 'F26' instead of 'PNU 260[26] = F26' / 'PNU 271' in the one-line summaries."""
    pnu, sub = pk["pnu"], pk["subindex"]
    pats = [rf"PNU {pnu}\[{sub}\] = {re.escape(code)}\b", rf"PNU {pnu}\[{sub}\]", rf"PNU {pnu}\b"]
    for key, holder in (("summary", pk), ("summary", out)):
        s = holder.get(key, "")
        for pat in pats:
            s2 = re.sub(pat, code, s, count=1)
            if s2 != s:
                holder[key] = s2
                break
    text = out["text"]
    if text and text[-1].startswith("summary: "):
        text[-1] = "summary: " + out["summary"]


def decode_area(profile, layout: str, direction: str, data: bytes, *,
                max_hz: float | None = None) -> dict:
    """The core PPO decoder plus function-code names, alarm candidates, direction and PCD words."""
    fc = fuji_config(profile)
    out = pd.decode_area(profile, layout, direction, data, max_hz=max_hz)
    text: list[str] = out["text"]
    pk = out.get("pkw")
    if pk is not None and pk["ak"] != 0:
        code = function_code_name(profile, pk["pnu"], pk["subindex"])
        if code is not None:
            group = code.rstrip("0123456789")
            pk["function_code"] = code
            pk.setdefault("code", code)
            line = (f"function code {code}: group {group} (0x{fc.groups[group]:02X}, "
                    f"{fc.group_names.get(group, '')}) -> PNU 0x{pk['pnu']:03X}, subindex "
                    f"0x{pk['subindex']:02X} ({pk['subindex']})")
            if profile.param(code) is None:
                line += "; not in the profile table, value shown raw"
            text.insert(text.index(pk["text"]) + 1, line)
            _rename_in_summary(out, pk, code)
        if pk["pnu"] == fc.history_pnu and "error" not in pk and (
                direction == "response" and pk["ak"] in (1, 4)):
            num = pk["pwe"] & 0xFFFF
            pk["alarm_candidates"] = [{"code": a.code, "mcode": fc.mcodes.get(a.code), "meaning": a.meaning}
                                      for a in alarm_candidates(profile, num)]
            text.insert(text.index(pk["text"]) + 1, f"PNU{fc.history_pnu} malfunction code "
                        f"0x{num:04X}: {alarm_text(profile, num)}")
            if pk.get("value_text", "").startswith(f"{num} ("):
                _replace_value_text(out, pk, f"0x{num:04X}" + pk["value_text"][len(str(num)):])
        if pk["pnu"] in (pd.PNU_PZD_SETPOINT, pd.PNU_PZD_ACTUAL) and "error" not in pk and \
                (direction == "request" and pk["ak"] == 7 or direction == "response" and pk["ak"] == 4):
            w = pk["pwe"] & 0xFFFF
            c = pcd_assignment_code(profile, w)
            pk["assigned_code"] = c
            text.insert(text.index(pk["text"]) + 1, f"PCD{pk['subindex']} assignment {_hex_word(w)} = "
                        + (c if c else "not assigned"))
            _replace_value_text(out, pk, f"{_hex_word(w)} ({c or 'not assigned'})")
    if direction == "request":
        cw = out["control_word"]["word"]
        mrv = out["reference"]["raw"]
        rev = bool(cw >> 11 & 1)
        neg = pd.to_signed16(mrv) < 0
        dirn = "reverse" if (neg != rev) else "forward"
        out["control_word"]["direction"] = dirn
        note = ""
        if neg and rev:
            note = " (negative MRV with bit 11: not specified by the manual; taken as forward)"
        if cw & pd.Ctw.CONTROL_BY_PLC:
            text.insert(-1, f"direction {dirn} (sign of MRV XOR CTW bit 11 reverse){note}")
        elif cw:
            text.insert(-1, "CTW bit 10 (PCD valid) is 0: the card ignores CTW and MRV")
    else:
        sw = out["status_word"]
        stw = sw["word"]
        if stw & 0x7 == 0b011 and not stw & 0x48:
            sw["note"] = "S3 and S5 share this status pattern; MAV != 0 means S5 (stopping)"
            if pd.to_signed16(out["actual"]["raw"]) != 0:
                # the manual's ramp-stop example: 0x0233 while decelerating is S5 (decision in the profile)
                old_state = sw["state"]
                sw["state"] = pd.State.S5.value
                sw["maybe_s5"] = False
                for i, line in enumerate(text):
                    if line == sw["text"]:
                        text[i] = sw["text"] = line.split(" -> ")[0] + f" -> {pd.State.S5.value} (MAV != 0: " \
                            f"decelerating; the same pattern at standstill is S3)"
                out["summary"] = out["summary"].replace(old_state, pd.State.S5.value, 1)
                if text[-1].startswith("summary: "):
                    text[-1] = "summary: " + out["summary"]
    # PCD1-4 (PPO2 / PPO4): function-code words assigned by o40-o43 / o48-o51
    if "pzd" in out:
        which = "o40-o43 / PNU915" if direction == "request" else "o48-o51 / PNU916"
        for e in out["pzd"]:
            e["pcd"] = e["pzd"] - 2
        for i, line in enumerate(text):
            if line.startswith("PZD3..:"):
                text[i] = ("PCD1-4: " + ", ".join(f"PCD{e['pcd']} {_hex_word(e['raw'])} ({e['raw']})"
                                                  for e in out["pzd"])
                           + f" (function codes assigned by {which}; raw)")
    return out


__all__ = ["FujiConfig", "FujiDrive", "make_drive", "decode_area", "param_value", "fuji_config",
           "profidrive_config", "parse_function_code", "function_code_name", "pcd_assignment",
           "pcd_assignment_code", "alarm_candidates", "alarm_by_mcode", "alarm_text", "ppo_for_o30",
           "o30_for_layout", "comm_loss_action", "comm_loss_text", "mcode_of", "CommLossAction"]
