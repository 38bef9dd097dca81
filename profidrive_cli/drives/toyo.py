"""Toyo Denki VF66 with the PBUS66-Z option: the PROFIdrive core plus the card's dialect.

Dialect (profiles/toyo-pbus66z.yaml, keys layouts[out/in], fields, bits, parameter_channel,
traceback, fault_history, plch, speed_full_scale, voltage_class, diag_word_order):
  * little-endian words on the bus, as the manual's frame tables show (profile `word_order`)
  * J-08 mode 0 (PROFIdrive-compatible, PPO1-5, control word STW / status word ZSW) and mode 1 (Toyo
    original frame: run-command word, multi-function input words, status and fault flag words);
    the layout name says which (ppo1..ppo5 = mode 0; toyo, toyo_plch = mode 1)
  * speed words: 20000 = A-00 (not 0x4000), signed; mode 0 reverse = negative speed command, mode 1
    reverse = run-command bit 2
  * control word bits 8/9 = jog 1 (forward) / jog 2 (reverse) with bits 4-6 = 0; no direction bit
  * PKW: tasks 1 (read), 2 (write), 6 (read with subindex); responses 0 (busy), 1, 4, 7; IND is one
    16-bit word (fault history 1-6; traceback recording << 8 | point); PNU bit 10 = 2nd setting
    block; after an error answer task 0 is sent once before the next request (zero_after_error)
  * monitors PNU 677-698 (by name: dc-voltage, motor-speed, ...), traceback PNU 700-715 (TB00-TB15),
    fault history PNU 720 (protection code, inverter mode, setting block)
  * Slave_Diag device block: 0 or 9 octets, words high byte first

Module API: make_drive, decode_area, param_value, profidrive_config, toyo_config, speed_word,
speed_percent, history_word, decode_history_word, traceback_ind, decode_traceback_ind, decode_diag,
protection, ToyoDrive, ToyoConfig.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from profidrive_cli import UsageError
from profidrive_cli.datafile import DataFileError, LineDict
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.base import DriveError, DriveStatus, FaultRecord, ParamError, ParamValue
from profidrive_cli.drives.profile import COMMON_EXTRA_KEYS, per_profile
from profidrive_cli.drives.values import value_problem

FAMILY_PARAM_KEYS = {"power_cycle", "format", "bits", "plc", "scale_400v", "traceback", "note"}
FIELD_KINDS = ("ctw", "zsw", "run_cmd", "bits", "speed", "scaled", "date", "raw", "param")

REQUEST_TEXT = {0: "no task", 1: "read data", 2: "write data", 6: "read data with subindex"}
RESPONSE_TEXT = {0: "no response / still processing", 1: "requested data transferred",
                 4: "requested data with subindex transferred", 7: "error"}

# =============================================================================================
# profile keys
# =============================================================================================


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


# =============================================================================================
# scaling and small decoders
# =============================================================================================


def speed_word(profile, percent: float) -> int:
    """Percent of A-00 -> speed word (20000 = 100 %), two's complement, clamped to 16 bits."""
    fs = toyo_config(profile).speed_full_scale
    raw = round(percent * fs / 100.0)
    return max(-0x8000, min(0x7FFF, raw)) & 0xFFFF


def speed_percent(profile, word: int) -> float:
    return pd.to_signed16(word) * 100.0 / toyo_config(profile).speed_full_scale


def effective_scale(profile, p) -> float:
    if toyo_config(profile).voltage_class == 400 and "scale_400v" in p.extra:
        return float(p.extra["scale_400v"])
    return p.scale


def value_from_wire(profile, p, raw: int):
    raw &= 0xFFFF
    if p.signed and raw & 0x8000:
        raw -= 0x10000
    sc = effective_scale(profile, p)
    v = raw * sc
    if float(sc).is_integer():
        return int(round(v))
    return round(v, 6)


def wire_from_value(profile, p, value) -> int:
    """Setting values go without their decimal point (15.0 with scale 0.1 -> 150)."""
    sc = effective_scale(profile, p)
    raw = round(value / sc) if sc else int(value)
    return int(raw) & 0xFFFF


def param_value(profile, param, raw: int):
    """Hook used by the core decoder."""
    return value_from_wire(profile, param, raw)


def protection(profile, code: int) -> tuple[str, str]:
    """Protection code -> (short name, meaning)."""
    al = profile.alarms_for(code)
    if al:
        return al[0].code, al[0].meaning
    if code >= 33:
        return f"GAC{code}", f"GAC protection {code} (GAC-equipped models; see the model's manual)"
    return f"?{code}", f"unknown protection code {code}"


def history_word(code: int, mode: int = 0, block: int = 0) -> int:
    return (code & 0xFF) | (mode & 0x3) << 8 | (block & 1) << 12


def decode_history_word(profile, word: int) -> dict:
    tc = toyo_config(profile)
    code = word & tc.history_code_mask
    mode = (word >> tc.history_mode_shift) & 0x3
    block = (word >> tc.history_block_bit) & 1
    name, meaning = protection(profile, code)
    return {"word": word, "code": code, "name": name, "meaning": meaning, "mode": mode,
            "mode_text": tc.history_modes.get(mode, str(mode)), "block": block + 1,
            "text": f"protection {code} {name} ({meaning}); inverter mode {tc.history_modes.get(mode, mode)}; "
                    f"setting block {block + 1}"}


def traceback_ind(recording: int, point: int) -> int:
    """recording 0 = newest .. 3 = oldest, point 0..99 -> IND word."""
    if not 0 <= recording <= 3 or not 0 <= point <= 0xFF:
        raise ValueError("recording must be 0..3 and point 0..255")
    return recording << 8 | point


def decode_traceback_ind(ind: int) -> tuple[int, int]:
    return (ind >> 8) & 0x3, ind & 0xFF


RECORDING_TEXT = {0: "newest", 1: "2nd newest", 2: "3rd newest", 3: "oldest (4th)"}


def bit_names(profile, table: str, word: int) -> list[str]:
    names = toyo_config(profile).bits.get(table, {})
    return [names.get(b, f"bit {b}") for b in range(16) if word >> b & 1]


def decode_diag(profile, ext: bytes) -> dict:
    """The PBUS66-Z device-related diagnosis (octets from +6 on): 0, or 9 + four flag words."""
    tc = toyo_config(profile)
    if not ext or ext[0] == 0:
        return {"length": 0, "text": ["no device-related data (no trip since power-on)"]}
    if ext[0] != 9 or len(ext) < 9:
        return {"length": ext[0], "text": [f"unexpected device block length {ext[0]} ({len(ext)} octets)"]}
    ws = pd.bytes_to_words(bytes(ext[1:9]), tc.diag_word_order)
    out: dict = {"length": 9}
    text = []
    for key, table, w in (("status_flag", "status_flag", ws[0]), ("fault_flag1", "fault_flag1", ws[1]),
                          ("fault_flag2", "fault_flag2", ws[2]), ("mf_output", "mf_output", ws[3])):
        names = bit_names(profile, table, w)
        out[key] = {"raw": w, "hex": f"0x{w:04X}", "set": names}
        text.append(f"{key.replace('_', ' ')} 0x{w:04X}: {', '.join(names) or 'none'}")
    out["text"] = text
    return out


# =============================================================================================
# the words of one area
# =============================================================================================


def run_cmd_fields(word: int) -> dict:
    preset = (word >> 6) & 0x7
    accdec = (word >> 9) & 0x3
    return {"run": bool(word & 1), "jog": bool(word & 2), "reverse": bool(word & 4),
            "initial_excitation": bool(word & 8), "dc_brake": bool(word & 0x10), "reset": bool(word & 0x20),
            "preset_speed": preset, "accel_set": accdec + 1, "speed_up": bool(word & 0x800),
            "speed_down": bool(word & 0x1000), "speed_hold": bool(word & 0x2000),
            "s_curve_inhibit": bool(word & 0x4000), "max_speed_reduction": bool(word & 0x8000)}


def ctw_command(word: int) -> str:
    """What a mode-0 control word asks the VF66 for (priority OFF2 > OFF3 > OFF1)."""
    if not word & pd.Ctw.CONTROL_BY_PLC:
        return "master control invalid (bit 10 = 0: the previous command is kept)"
    parts = []
    if not word & pd.Ctw.NO_OFF2:
        parts.append("OFF2 coast stop")
    elif not word & pd.Ctw.NO_OFF3:
        parts.append("OFF3 quick stop")
    elif not word & pd.Ctw.ON:
        parts.append("OFF1 normal stop" + (" (bit 3 = 1: runs as soon as bit 0 goes to 1)"
                                           if word & pd.Ctw.ENABLE_OPERATION else " (ready to switch on)"))
    elif not word & pd.Ctw.ENABLE_OPERATION:
        parts.append("ON (ready, run inhibited)")
    else:
        missing = [t for b, t in ((4, "ramp inhibit (ARC = 0)"), (5, "ramp stop (ARC held)"),
                                  (6, "setpoint inhibit")) if not word >> b & 1]
        parts.append("RUN" + (" with " + ", ".join(missing) if missing else ""))
    if word & (pd.Ctw.ENABLE_RFG | pd.Ctw.UNFREEZE_RFG | pd.Ctw.ENABLE_SETPOINT) == 0 and \
            word & (pd.Ctw.JOG1 | pd.Ctw.JOG2) and word & pd.Ctw.ON and word & pd.Ctw.NO_OFF2 \
            and word & pd.Ctw.NO_OFF3:
        parts.append("forward jog (jog 1)" if word & pd.Ctw.JOG1 else "reverse jog (jog 2)")
    elif word & (pd.Ctw.JOG1 | pd.Ctw.JOG2):
        parts.append("jog bit ignored (needs bits 4-6 = 0)")
    if word & pd.Ctw.FAULT_ACK:
        parts.append("fault acknowledge")
    return "; ".join(parts)


def describe_word(profile, fname: str, raw: int, direction: str, *, max_hz: float | None = None) -> dict:
    tc = toyo_config(profile)
    f = tc.fields.get(fname)
    d: dict = {"field": fname, "raw": raw, "hex": f"0x{raw:04X}"}
    if f is None:      # i000xx / o000xx PLC registers
        reg = "communication input register" if fname.startswith("i") else "communication output register"
        d["name"] = f"{fname} ({reg})"
        d["text"] = f"{fname} ({reg}, user data) 0x{raw:04X} = {raw}"
        return d
    kind = f["kind"]
    d["name"] = f["name"]
    if kind in ("ctw", "zsw", "run_cmd", "bits"):
        d["word"] = raw
    head = f"{f['name']} 0x{raw:04X}"
    if kind == "ctw":
        names = bit_names(profile, "ctw", raw)
        d["set"] = names
        d["command"] = ctw_command(raw)
        d["text"] = f"{head}: {', '.join(names) or 'no bits set'} -> {d['command']}"
    elif kind == "zsw":
        names = bit_names(profile, "zsw", raw)
        st = pd.state_from_status(raw)
        d["set"], d["state"] = names, st.value
        d["text"] = f"{head}: {', '.join(names) or 'no bits set'} -> {st.value}"
    elif kind == "run_cmd":
        rc = run_cmd_fields(raw)
        d.update(rc)
        d["set"] = bit_names(profile, "run_cmd", raw)
        extra = []
        if rc["preset_speed"]:
            extra.append(f"preset speed {rc['preset_speed']}")
        extra.append(f"accel/decel set {rc['accel_set']}")
        cmd = "run " + ("reverse" if rc["reverse"] else "forward") if rc["run"] else "stop"
        if rc["jog"]:
            cmd += "; jog"
        d["command"] = cmd
        d["text"] = f"{head}: {cmd}; " + ", ".join(extra) + (
            "; set: " + ", ".join(x for x in d["set"] if not x.startswith("preset") and not x.startswith("accel"))
            if d["set"] else "")
    elif kind == "bits":
        names = bit_names(profile, f["bits"], raw)
        d["set"] = names
        d["text"] = f"{head}: {', '.join(names) or 'none'}"
    elif kind == "speed":
        pct = speed_percent(profile, raw)
        d["percent"] = round(pct, 6)
        fmax = max_hz if max_hz is not None else float(profile.max_frequency_default)
        d["hz"] = round(pct * fmax / 100.0, 6)
        d["text"] = (f"{head} = {pd.to_signed16(raw)}: {round(pct, 4):g} % of A-00 = {d['hz']:.2f} Hz "
                     f"(A-00 = {fmax:g} Hz{'' if max_hz is not None else ', profile default'})")
    elif kind == "scaled":
        v = pd.to_signed16(raw) if f.get("signed") else raw
        val = round(v * float(f.get("scale", 1)), 6)
        d["value"], d["unit"] = val, f.get("unit", "")
        d["text"] = f"{head} = {val:g} {d['unit']}".rstrip()
    elif kind == "param":
        p = profile.param(f["param"])
        val = value_from_wire(profile, p, raw)
        d["value"], d["unit"] = val, p.unit
        d["text"] = f"{head} = {pd.format_value(p, val, raw)}" + (
            f" ({tc.voltage_class} V class)" if "scale_400v" in p.extra else "")
    elif kind == "date":
        lo, hi = raw & 0xFF, raw >> 8
        d[f.get("low", "low")], d[f.get("high", "high")] = lo, hi
        d["text"] = f"{head}: {f.get('high', 'high')} {hi}, {f.get('low', 'low')} {lo}"
    else:
        d["text"] = f"{head} ({f['name']})"
    return d


def param_at(profile, pnu: int):
    for p in profile.parameters.values():
        if p.pnu == pnu:
            return p
    return None


def describe_pkw(profile, words, direction: str, *, max_hz: float | None = None) -> dict:
    tc = toyo_config(profile)
    pke, ind, pwe1, pwe2 = words
    ak, spm, pnu_field = pd.decode_pke(pke)
    block = (pnu_field >> tc.block_bit) & 1
    pnu = pnu_field & ((1 << tc.block_bit) - 1)
    texts = REQUEST_TEXT if direction == "request" else RESPONSE_TEXT
    d: dict = {"pke": pke, "ak": ak, "ak_text": texts.get(ak, "not defined by the card"), "spm": spm,
               "pnu": pnu, "pnu_hex": f"0x{pnu:03X}", "block": block + 1, "ind": ind, "pwe1": pwe1,
               "pwe": pwe2}
    head = f"PKE 0x{pke:04X}: {'task' if direction == 'request' else 'response'} ID {ak} ({d['ak_text']})"
    if ak == 0:
        d["summary"] = d["ak_text"]
        d["text"] = f"{head}; PNU {pnu}; IND 0x{ind:04X}; PWE2 0x{pwe2:04X}"
        return d
    p = param_at(profile, pnu)
    label = f"PNU {pnu} (0x{pnu:03X})"
    if p is not None:
        d["code"], d["name"] = p.code, p.name
        label += f" = {p.code} {p.name}"
    if block:
        label += ", 2nd setting block"
    value_text = None
    tb = tc.traceback_pnu <= pnu < tc.traceback_pnu + tc.traceback_channels
    sub_read = ak == 6 if direction == "request" else ak in (4, 7)
    ind_text = ""
    if pnu == tc.history_pnu and sub_read:
        d["history_index"] = ind
        ind_text = f"IND {ind} ({'newest' if ind == 1 else f'{ind - 1} back'} of 6)"
    elif tb and sub_read:
        rec, pt = decode_traceback_ind(ind)
        d["recording"], d["point"] = rec, pt
        ind_text = f"IND 0x{ind:04X} (recording {RECORDING_TEXT[rec]}, data point {pt})"
    else:
        ind_text = f"IND 0x{ind:04X}" + (" (ignored)" if direction == "request" and ind else "")
    if direction == "response" and ak == 7:
        d["error"] = pwe2
        d["error_text"] = tc.errors.get(pwe2, f"unknown error {pwe2}")
        value_text = f"error {pwe2}: {d['error_text']}"
    elif (direction == "request" and ak == 2) or (direction == "response" and ak in (1, 4)):
        if pnu == tc.history_pnu and direction == "response":
            h = decode_history_word(profile, pwe2)
            d["history"] = h
            value_text = f"0x{pwe2:04X} = {h['text']}"
        elif p is not None:
            fmt = p.extra.get("format")
            val = value_from_wire(profile, p, pwe2)
            d["value"], d["unit"] = val, p.unit
            if fmt == "bits":
                names = bit_names(profile, p.extra.get("bits", ""), pwe2)
                d["set"] = names
                value_text = f"0x{pwe2:04X}: {', '.join(names) or 'none'}"
            elif fmt == "speed":
                fmax = max_hz if max_hz is not None else float(profile.max_frequency_default)
                d["hz"] = round(speed_percent(profile, pwe2) * fmax / 100.0, 6)
                value_text = f"{pd.to_signed16(pwe2)} = {val:g} % = {d['hz']:.2f} Hz"
            elif fmt == "hex":
                value_text = f"0x{pwe2:04X}"
            else:
                value_text = f"{pwe2} = {pd.format_value(p, val, pwe2)}" if p.scale != 1 or p.unit \
                    else str(val)
        else:
            value_text = f"{pwe2} (0x{pwe2:04X}; value without decimal point: 15.0 travels as 150)"
    d["value_text"] = value_text
    d["summary"] = f"{d['ak_text']}, {label}" + (f" [{ind_text}]" if ind_text.startswith("IND ") and
                                                 ("recording" in ind_text or "of 6" in ind_text) else "") \
        + (f": {value_text}" if value_text else "")
    d["text"] = (f"{head}, SPM {spm}, {label}; {ind_text}; PWE1 0x{pwe1:04X}; PWE2 0x{pwe2:04X}"
                 + (f" -> {value_text}" if value_text else ""))
    return d


def decode_area(profile, layout: str, direction: str, data: bytes, *,
                max_hz: float | None = None) -> dict:
    """Decode a captured output (request) or input (response) area of any PBUS66-Z layout."""
    pd.check_direction(direction)
    tc = toyo_config(profile)
    if layout not in tc.layouts:
        raise UsageError(f"profile {profile.name} has no layout '{layout}' (known: {', '.join(tc.layouts)})")
    tl = tc.layouts[layout]
    lay = profile.layouts[layout]
    want = lay.output_len if direction == "request" else lay.input_len
    data = bytes(data)
    if len(data) != want:
        raise UsageError(f"{layout} {direction} is {want} octets, got {len(data)}")
    words = pd.bytes_to_words(data, tc.word_order)
    plch = tc.plch or tl.plch
    arrow = "master -> drive" if direction == "request" else "drive -> master"
    out: dict = {"profile": profile.name, "layout": layout, "mode": tl.mode, "plch": plch,
                 "direction": direction, "word_order": tc.word_order, "octets": data.hex(" ").upper()}
    text = [f"{profile.name} {layout} (mode {tl.mode}{', PLCH on' if plch else ''}) {direction} ({arrow}), "
            f"{len(data)} octets, {tc.word_order}-endian words: {out['octets']}"]
    summary = []
    if tl.pkw:
        pk = describe_pkw(profile, words[:4], direction, max_hz=max_hz)
        out["pkw"] = pk
        text.append(pk["text"])
        summary.append(pk["summary"])
        words = words[4:]
    fields = []
    for name, w in zip(tl.words(direction, plch), words):
        if name == "unused":
            continue
        d = describe_word(profile, name, w, direction, max_hz=max_hz)
        fields.append(d)
        text.append(d["text"])
        if name == "ctw":
            out["control_word"] = d
            summary.append(d["command"])
        elif name == "zsw":
            out["status_word"] = d
            summary.append(d["state"])
        elif name == "run_cmd":
            out["run_command"] = d
            if tl.mode == 0:
                d["note"] = "bits 0-2 (run, jog, reverse) are ignored in mode 0"
                text[-1] += " (mode 0: bits 0-2 ignored)"
            else:
                summary.append(d["command"])
        elif name in ("speed_ref", "motor_speed"):
            out["reference" if name == "speed_ref" else "actual"] = d
            summary.append(f"{'reference' if name == 'speed_ref' else 'speed'} {d['percent']:g} %")
        elif name in ("fault_flag1", "fault_flag2") and d.get("set"):
            summary.append(f"{name.replace('_', ' ')}: {', '.join(d['set'])}")
    out["fields"] = fields
    out["summary"] = "; ".join(summary)
    text.append("summary: " + out["summary"])
    out["text"] = text
    return out


# =============================================================================================
# the Drive
# =============================================================================================


def _toyo_frame(ak: int, pnu: int, ind: int = 0, value: int = 0) -> pd.PkwFrame:
    return pd.PkwFrame(ak, pnu, (ind >> 8) & 0xFF, value & 0xFFFF, ind_low=ind & 0xFF)


_TB_RE = re.compile(r"^TB(\d{1,2})\s*\[\s*(\d)\s*[,:]\s*(\d{1,3})\s*\]$", re.I)


class ToyoDrive(pd.ProfidriveDrive):
    """Mode 0 (PPO1-5) runs the PROFIdrive state machine; mode 1 (toyo, toyo_plch) the run-command word."""

    family = "toyo"

    def __init__(self, channel, profile, layout: str | None = None):
        self.tc = toyo_config(profile)
        super().__init__(channel, profile, layout)
        self.tl = self.tc.layouts[self.layout]
        self.mode = self.tl.mode
        self.plch = self.tc.plch or self.tl.plch
        self.run_cmd = 0                      # mode 1 run-command / multi-function input 1
        self.mf_input2 = 0
        self.torque_ref = 0
        self.words_out: dict[str, int] = {}
        self.jogging = False
        self._reset_pulse = 0

    # -- addressing ----------------------------------------------------------------------------
    def _find(self, text: str):
        t = text.strip()
        p = self.profile.param(t)
        if p is not None:
            return p
        for q in self.profile.parameters.values():
            if q.code.lower() == t.lower():
                return q
        return None

    def resolve_param(self, code: str) -> pd.ParamRef:
        """Monitor names ('dc-voltage'), console codes ('A-00', needs a pnu in the profile),
        'TB06[1,10]' (traceback: recording 0-3, point 0-99), 'FH[2]' (fault history), 'PNU688',
        'PNU720[3]' (IND word), '688'."""
        t = code.strip()
        m = _TB_RE.match(t)
        if m:
            ch, rec, pt = int(m.group(1)), int(m.group(2)), int(m.group(3))
            if not 0 <= ch < self.tc.traceback_channels or rec > 3 or pt >= self.tc.traceback_points:
                raise UsageError(f"{code}: channel 0..{self.tc.traceback_channels - 1}, recording 0..3, "
                                 f"point 0..{self.tc.traceback_points - 1}")
            p = param_at(self.profile, self.tc.traceback_pnu + ch)
            ind = traceback_ind(rec, pt)
            return pd.ParamRef(f"TB{ch:02d}[{rec},{pt}]", p.name if p else "", self.tc.traceback_pnu + ch,
                               ind, True, 16, p)
        m = re.fullmatch(r"(?i)(?:PNU\s*)?(0x[0-9a-f]+|\d+)(?:\s*\[\s*(0x[0-9a-f]+|\d+)\s*\])?", t)
        base = None
        ind = None
        if m:
            pnu = int(m.group(1), 0)
            ind = int(m.group(2), 0) if m.group(2) is not None else None
            if not 0 < pnu <= 0x7FF:
                raise UsageError(f"{code}: PNU must be 1..2047 (bit 10 = 2nd setting block)")
            p = param_at(self.profile, pnu)
            base = (pnu, p)
        else:
            m2 = re.fullmatch(r"(.+?)\s*\[\s*(0x[0-9a-f]+|\d+)\s*\]", t, re.I)
            name, ind = (m2.group(1), int(m2.group(2), 0)) if m2 else (t, None)
            p = self._find(name)
            if p is None:
                raise UsageError(f"unknown parameter '{code}' in {self.profile.name} (monitor names such as "
                                 f"dc-voltage, TB06[0,10], FH[1], or PNU<n>)")
            if p.pnu is None:
                raise UsageError(f"{p.code} ({p.name}): Toyo does not publish its PNU; add `pnu:` to the "
                                 f"profile (values travel without the decimal point)")
            base = (p.pnu, p)
        pnu, p = base
        sub = pnu == self.tc.history_pnu or \
            self.tc.traceback_pnu <= (pnu & 0x3FF) < self.tc.traceback_pnu + self.tc.traceback_channels
        if sub and ind is None:
            ind = 1 if pnu == self.tc.history_pnu else 0
        codename = p.code if p is not None and (pnu & 0x3FF) == p.pnu else f"PNU{pnu}"
        if ind is not None and sub:
            codename += f"[{ind}]"
        return pd.ParamRef(codename, p.name if p is not None else "", pnu, ind or 0, sub, 16, p)

    def _frame_for(self, ref: pd.ParamRef, write: bool = False, value: int = 0) -> pd.PkwFrame:
        if write:
            return _toyo_frame(2, ref.pnu, 0, value)
        return _toyo_frame(6 if ref.array else 1, ref.pnu, ref.subindex if ref.array else 0)

    def raw_to_value(self, ref: pd.ParamRef, raw: int):
        return value_from_wire(self.profile, ref.param, raw) if ref.param is not None else raw & 0xFFFF

    def check_value(self, ref: pd.ParamRef, value) -> str | None:
        if ref.param is None:
            return super().check_value(ref, value)
        return value_problem(ref.param, value, scale=effective_scale(self.profile, ref.param))

    def value_to_raw(self, ref: pd.ParamRef, value) -> int:
        return wire_from_value(self.profile, ref.param, value) if ref.param is not None else int(value) & 0xFFFF

    def read_param(self, code: str) -> ParamValue:
        ref = self.resolve_param(code)
        res = self.request(self._frame_for(ref))
        if not res.ok:
            raise ParamError(f"{ref.label}: the card refused the read: {res.describe_error()}", res.error)
        return self._param_value(ref, res.value)

    def write_param(self, code: str, value) -> ParamValue:
        ref = self.resolve_param(code)
        p = ref.param
        if ref.array or (p is not None and not p.writable):
            raise ParamError(f"{ref.label} is read-only", 1)
        msg = self.check_value(ref, value)
        if msg:
            raise ParamError(msg, 2)
        raw = self.value_to_raw(ref, value)
        res = self.request(self._frame_for(ref, write=True, value=raw))
        if not res.ok:
            if res.error == 1 and p is not None and p.access == "stop":
                raise ParamError(f"{ref.label}: refused (error 1, write-protected); it can only be changed "
                                 f"while the inverter is stopped", 1)
            raise ParamError(f"{ref.label}: the card refused the value {value}: {res.describe_error()}",
                             res.error)
        # the answer carries the value actually written (the card writes to EEPROM)
        return self._param_value(ref, res.value)

    def read_raw(self, pnu: int, subindex: int = 0, array: bool | None = None) -> int:
        if array is None:
            array = pnu in self.cfg.array_pnus
        res = self.request(_toyo_frame(6 if array else 1, pnu, subindex if array else 0))
        if not res.ok:
            raise ParamError(f"PNU {pnu}" + (f"[{subindex}]" if array else "") + f": {res.describe_error()}",
                             res.error)
        return res.value & 0xFFFF

    def save(self) -> None:
        raise DriveError("PBUS66-Z: every parameter write goes straight to the inverter's EEPROM "
                         "(limited write cycles); there is no separate save")

    def max_frequency(self) -> float:
        if self._fmax is None:
            p = self.profile.param(self.profile.max_frequency_param or "")
            if p is not None and p.pnu is not None and self.pkw is not None:
                self._fmax = float(self.read_param(p.code).value)
            else:
                self._fmax = float(self.profile.max_frequency_default)
        return self._fmax

    # -- faults --------------------------------------------------------------------------------
    def fault_history(self) -> list[FaultRecord]:
        """PNU 720, IND 1 (newest) .. 6; stops at the first empty slot (error 101)."""
        out = []
        for i, ind in enumerate(self.tc.history_indexes):
            res = self.request(_toyo_frame(6, self.tc.history_pnu, ind))
            if not res.ok:
                if res.error == self.tc.empty_error:
                    break
                raise ParamError(f"fault history PNU {self.tc.history_pnu}[{ind}]: {res.describe_error()}",
                                 res.error)
            h = decode_history_word(self.profile, res.value & 0xFFFF)
            pos = "newest" if i == 0 else f"{i} back"
            out.append(FaultRecord(pos, h["code"], [h["name"]],
                                   [f"{h['meaning']} (inverter mode {h['mode_text']}, setting block {h['block']})"]))
        return out

    def status(self) -> DriveStatus:
        st = self.cycle()
        if st.fault and self.pkw is not None:
            try:
                res = self.request(_toyo_frame(6, self.tc.history_pnu, self.tc.history_indexes[0]))
                if res.ok:
                    st.fault_code = decode_history_word(self.profile, res.value & 0xFFFF)["name"]
            except DriveError:
                pass
        return st

    # -- one cycle -----------------------------------------------------------------------------
    def _out_words(self, ctw: int) -> list[int]:
        names = self.tl.words("request", self.plch)
        vals = {"ctw": ctw, "speed_ref": self.reference, "torque_ref": self.torque_ref,
                "run_cmd": self.run_cmd | (0x20 if self._reset_pulse else 0), "mf_input2": self.mf_input2}
        vals.update(self.words_out)
        return [vals.get(n, 0) & 0xFFFF for n in names]

    def cycle(self) -> DriveStatus:
        ctw = self._control_word() if self.mode == 0 else 0
        area = self._exchange_area(self._out_words(ctw))
        if self._reset_pulse:
            self._reset_pulse -= 1
        self.last_ctw = ctw
        if self.mode == 0:
            self.last_stw = area.word1
        st = self._decode_status(area)
        self.last_status = st
        return st

    def _control_word(self) -> int:
        if self.target is None:
            return 0
        stw = self.last_stw if self.last_stw is not None else int(pd.Stw.SWITCHING_ON_INHIBITED)
        moving = None
        if self.last_area is not None and len(self.last_area.pzd) > 1:
            moving = pd.to_signed16(self.last_area.pzd[1]) != 0
        extra = self.control_extra_bits()
        target = self.target
        if self.jogging and target is pd.Target.OPERATE:
            target = pd.Target.SWITCHED_ON       # jog: ON with bits 4-6 = 0 and bit 8 / 9
        return pd.next_control_word(stw, target, extra, previous=self.last_ctw, moving=moving)

    def _decode_status(self, area: pd.PpoArea) -> DriveStatus:
        names = self.tl.words("response", self.plch)
        w = dict(zip(names, area.pzd))
        fmax = self._fmax if self._fmax is not None else float(self.profile.max_frequency_default)
        raw = {n: v for n, v in w.items() if n != "unused"}
        flags: dict[str, bool] = {}
        sf = w.get("status_flag")
        ff1, ff2 = w.get("fault_flag1", 0), w.get("fault_flag2", 0)
        if sf is not None:
            for b, t in self.tc.bits["status_flag"].items():
                flags[t] = bool(sf >> b & 1)
        fan = self._fan_bit()
        fault_flags = bool(ff1) or bool(ff2 & ~fan)
        for table, word in (("fault_flag1", ff1), ("fault_flag2", ff2)):
            if word:
                for b, t in self.tc.bits[table].items():
                    if word >> b & 1:
                        flags[f"fault: {t}"] = True
        speed = w.get("motor_speed")
        pct = speed_percent(self.profile, speed) if speed is not None else None
        ref_pct = speed_percent(self.profile, self.reference)
        if self.mode == 0:
            zsw = w["zsw"]
            raw["status_word"] = zsw
            moving = pct is not None and abs(pct) > 0
            state = pd.state_from_status(zsw, moving)
            if self.jogging and state is pd.State.S5:
                state = pd.State.S3             # jog runs in the switched-on state (bits 4-6 = 0)
            flags["jogging"] = self.jogging
            for b, t in self.tc.bits["zsw"].items():
                flags[t] = bool(zsw >> b & 1)
            running = state in (pd.State.S4, pd.State.S5) or bool(moving)
            st = DriveStatus(state=state.value, running=running, fault=state is pd.State.FAULT,
                             flags=flags, speed_percent=None if pct is None else round(pct, 4),
                             speed_hz=None if pct is None else round(pct * fmax / 100.0, 4),
                             reference_percent=round(ref_pct, 4), raw=raw)
        else:
            sf = sf or 0
            running = bool(sf & 0x2) or bool(sf & 0x4) or (pct is not None and pct != 0)
            if fault_flags:
                state = "fault"
            elif sf & 0x4:
                state = "jog"
            elif sf & 0x1:
                state = "running"
            elif running:
                state = "stopping"
            else:
                state = "stopped"
            if self.run_cmd & 4 and ref_pct > 0:
                ref_pct = -ref_pct
            st = DriveStatus(state=state, running=running, fault=fault_flags, flags=flags,
                             speed_percent=None if pct is None else round(pct, 4),
                             speed_hz=None if pct is None else round(pct * fmax / 100.0, 4),
                             reference_percent=round(ref_pct, 4), raw=raw)
        if st.fault and (ff1 or ff2):
            st.fault_code = self._flag_fault_code(ff1, ff2)
        return st

    def _fan_bit(self) -> int:
        for b, t in self.tc.bits.get("fault_flag2", {}).items():
            if t.startswith("fan"):
                return 1 << b
        return 0

    def _flag_fault_code(self, ff1: int, ff2: int) -> str | None:
        names = bit_names(self.profile, "fault_flag1", ff1) + [
            n for n in bit_names(self.profile, "fault_flag2", ff2) if not n.startswith("fan")]
        return ", ".join(names) or None

    # -- motion --------------------------------------------------------------------------------
    def set_speed(self, percent: float) -> None:
        if self.mode == 1:
            # mode 1: the direction is run-command bit 2 with a positive speed command
            self.reference = speed_word(self.profile, abs(percent))
            self.run_cmd = (self.run_cmd | 0x4) if percent < 0 else (self.run_cmd & ~0x4)
        else:
            self.reference = speed_word(self.profile, percent)    # mode 0: negative = reverse
        self.cycle()

    def start(self, timeout: float = 5.0) -> DriveStatus:
        if self.mode == 0:
            self.jogging = False
            self.extra_bits &= ~int(pd.Ctw.JOG1 | pd.Ctw.JOG2)
            return super().start(timeout)
        st = self.cycle()
        if st.fault:
            raise DriveError("the drive is in fault: reset it first")
        self.run_cmd = (self.run_cmd | 0x1) & ~0x2
        try:
            return self.cycles_until(lambda s: s.flags.get(self.tc.bits["status_flag"][0], False)
                                     and s.flags.get(self.tc.bits["status_flag"][1], False), timeout,
                                     "the run command to be taken (status flag bits 0 and 1)")
        except DriveError as e:
            raise DriveError(f"{e}; {self.start_hint(self.last_status)}") from None

    def stop(self, mode: str = "normal", wait: bool = True, timeout: float = 30.0) -> DriveStatus:
        if self.mode == 0:
            self.jogging = False
            self.extra_bits &= ~int(pd.Ctw.JOG1 | pd.Ctw.JOG2)
            return super().stop(mode, wait, timeout)
        if mode not in ("normal", "ramp", "off1"):
            raise DriveError("mode 1 (Toyo original frame) has only the run bit: use a normal stop, or "
                             "mode 0 (J-08 = 0) for coast / quick stops")
        self.run_cmd &= ~0x3
        st = self.cycle()
        if not wait:
            return st
        return self.cycles_until(lambda s: s.fault or s.stopped, timeout, "the drive to stop")

    def jog(self, on: bool = True, reverse: bool = False) -> None:
        if self.mode == 1:
            self.run_cmd = (self.run_cmd | 0x2) if on else (self.run_cmd & ~0x2)
            if on:
                self.run_cmd = (self.run_cmd | 0x4) if reverse else (self.run_cmd & ~0x4)
            self.cycle()
            return
        bit = int(pd.Ctw.JOG2 if reverse else pd.Ctw.JOG1)
        if on:
            self.jogging = True
            self.extra_bits = (self.extra_bits & ~int(pd.Ctw.JOG1 | pd.Ctw.JOG2)) | bit
            self.target = pd.Target.OPERATE     # sent as SWITCHED_ON + jog bit while jogging
        else:
            self.jogging = False
            self.extra_bits &= ~int(pd.Ctw.JOG1 | pd.Ctw.JOG2)
            self.target = pd.Target.READY
        self.cycle()

    def reset_fault(self, timeout: float = 5.0) -> DriveStatus:
        if self.mode == 0:
            return super().reset_fault(timeout)
        st = self.cycle()
        if not st.fault:
            return st
        if self.run_cmd & 0x3:
            raise DriveError("refusing to reset with the run (or jog) bit set: the motor would restart at "
                             "once; stop first")
        self._reset_pulse = 3       # protection reset: bit 5 high for a few cycles (rising edge)
        return self.cycles_until(lambda s: not s.fault and not self._reset_pulse, timeout,
                                 "the protection to clear (is its cause still present?)")

    def start_hint(self, status: DriveStatus | None) -> str:
        return ("the VF66 takes network commands with J-00 = 4, b-11 = 3 (run) and b-10 = 3 (speed) "
                "(or 0 with b-09 = 2), C-00 = 1 for the multi-function inputs, the ST-F terminal on, and "
                + ("control-word bit 10 = 1" if self.mode == 0 else "J-08 = 1 for this frame"))

    # -- traceback -----------------------------------------------------------------------------
    def read_traceback(self, channel: int, recording: int = 0, points: range | None = None) -> list[float]:
        """Samples of one traceback channel (0-15) from one recording (0 newest .. 3 oldest)."""
        p = param_at(self.profile, self.tc.traceback_pnu + channel)
        vals = []
        for pt in points or range(self.tc.traceback_points):
            res = self.request(_toyo_frame(6, self.tc.traceback_pnu + channel, traceback_ind(recording, pt)))
            if not res.ok:
                raise ParamError(f"traceback channel {channel} recording {recording} point {pt}: "
                                 f"{res.describe_error()}", res.error)
            raw = res.value & 0xFFFF
            vals.append(value_from_wire(self.profile, p, raw) if p is not None else raw)
        return vals


def make_drive(channel, profile, layout: str | None = None) -> ToyoDrive:
    toyo_config(profile)
    return ToyoDrive(channel, profile, layout)


__all__ = ["ToyoConfig", "ToyoDrive", "make_drive", "decode_area", "param_value", "profidrive_config",
           "toyo_config", "speed_word", "speed_percent", "history_word", "decode_history_word",
           "traceback_ind", "decode_traceback_ind", "decode_diag", "protection", "describe_pkw",
           "ctw_command", "run_cmd_fields", "value_from_wire", "wire_from_value"]
