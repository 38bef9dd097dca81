"""Toyo PBUS66-Z describers for pdrive decode: decode_area (any layout, either direction) with its
per-word and PKW text, and the Slave_Diag device block (decode_diag). JSON-serialisable dicts with a
"text" list. And mode 1's status flag as the state of `sniff --station` (mode1_state).

May touch: drives/profidrive (word helpers), config, codec, params (value scaling, param_at).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Sequence

from profidrive_cli import UsageError
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.toyo.codec import (RECORDING_TEXT, bit_names, ctw_command, decode_history_word,
                                              decode_traceback_ind, run_cmd_fields, speed_percent)
from profidrive_cli.drives.toyo.config import toyo_config
from profidrive_cli.drives.toyo.params import param_at, value_from_wire
from profidrive_cli.drives.speedplan import SpeedWord

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import Profile

REQUEST_TEXT: dict[int, str] = {0: "no task", 1: "read data", 2: "write data", 6: "read data with subindex"}
RESPONSE_TEXT: dict[int, str] = {0: "no response / still processing", 1: "requested data transferred",
                 4: "requested data with subindex transferred", 7: "error"}


def decode_diag(profile: Profile, ext: bytes) -> dict[str, Any]:
    """The PBUS66-Z device-related diagnosis (octets from +6 on): 0, or 9 + four flag words."""
    tc = toyo_config(profile)
    if not ext or ext[0] == 0:
        return {"length": 0, "text": ["no device-related data (no trip since power-on)"]}
    if ext[0] != 9 or len(ext) < 9:
        return {"length": ext[0], "text": [f"unexpected device block length {ext[0]} ({len(ext)} octets)"]}
    ws = pd.bytes_to_words(bytes(ext[1:9]), tc.diag_word_order)
    out: dict[str, Any] = {"length": 9}
    text = []
    for key, table, w in (("status_flag", "status_flag", ws[0]), ("fault_flag1", "fault_flag1", ws[1]),
                          ("fault_flag2", "fault_flag2", ws[2]), ("mf_output", "mf_output", ws[3])):
        names = bit_names(profile, table, w)
        out[key] = {"raw": w, "hex": f"0x{w:04X}", "set": names}
        text.append(f"{key.replace('_', ' ')} 0x{w:04X}: {', '.join(names) or 'none'}")
    out["text"] = text
    return out


def describe_word(profile: Profile, fname: str, raw: int, direction: str, *,
                  max_hz: float | None = None) -> dict[str, Any]:
    tc = toyo_config(profile)
    f = tc.fields.get(fname)
    d: dict[str, Any] = {"field": fname, "raw": raw, "hex": f"0x{raw:04X}"}
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
        assert p is not None, "toyo_config checked that fields.*.param is a parameter"
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


def describe_pkw(profile: Profile, words: Sequence[int], direction: str, *,
                 max_hz: float | None = None) -> dict[str, Any]:
    tc = toyo_config(profile)
    pke, ind, pwe1, pwe2 = words
    ak, spm, pnu_field = pd.decode_pke(pke)
    block = (pnu_field >> tc.block_bit) & 1
    pnu = pnu_field & ((1 << tc.block_bit) - 1)
    texts = REQUEST_TEXT if direction == "request" else RESPONSE_TEXT
    d: dict[str, Any] = {"pke": pke, "ak": ak, "ak_text": texts.get(ak, "not defined by the card"), "spm": spm,
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


def decode_area(profile: Profile, layout: str, direction: str, data: bytes, *,
                max_hz: float | None = None) -> dict[str, Any]:
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
    out: dict[str, Any] = {"profile": profile.name, "layout": layout, "mode": tl.mode, "plch": plch,
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


def mode1_state(area: dict[str, Any], d: dict[str, Any]) -> None:
    """Toyo mode 1 has no status word: the status flag (toyo-vf66-pbus66z.md Table 3.9, bit 1
    "running normally", bit 2 "jog running") and the fault flags of a decoded response `area`
    (decode_area's `fields`) say what the drive does: state / status / status_word into the `drive`
    object `d` of sniff --station (ToyoDrive.normalise_area); nothing without a status flag."""
    fields: list[dict[str, Any]] = area.get("fields") or []
    by = {f.get("field"): f for f in fields}
    sf = by.get("status_flag")
    if sf is None:
        return
    names = list(sf.get("set", []))
    faults = [n for k in ("fault_flag1", "fault_flag2") for n in by.get(k, {}).get("set", [])]
    d["state"] = ("fault: " + ", ".join(faults) if faults else
                  "jog running" if "jog running" in names else
                  "running" if "running" in names else "stopped")
    d["status"] = names
    d["status_word"] = sf.get("hex")


def speed_plan(profile: Profile, layout: str, direction: str, max_hz: float | None = None
               ) -> SpeedWord | None:
    """sniff --station's fast path (drives/speedplan.py SpeedWord): the speed word
    decode_area takes as the reference (request: the last `speed_ref`) or the actual value
    (response: the last `motor_speed`), and its reference_hz / reference_percent or actual_hz /
    actual_percent as describe_word and ppo_drive_object compute them. None when the layout has
    no such speed word. The words the drive object does not read are ignored."""
    pd.check_direction(direction)
    tc = toyo_config(profile)
    tl = tc.layouts.get(layout)
    if tl is None:
        return None
    want = "speed_ref" if direction == "request" else "motor_speed"
    names = tl.words(direction, tc.plch or tl.plch)
    at = [i for i, n in enumerate(names) if n == want]
    f = tc.fields.get(want)
    if not at or f is None or f.get("kind") != "speed":
        return None
    offset = (8 if tl.pkw else 0) + 2 * at[-1]
    lay = profile.layouts[layout]
    if offset + 2 > (lay.output_len if direction == "request" else lay.input_len):
        return None
    fmax = max_hz if max_hz is not None else float(profile.max_frequency_default)
    hz_key, pct_key = (("reference_hz", "reference_percent") if direction == "request"
                       else ("actual_hz", "actual_percent"))

    fs = tc.speed_full_scale
    # ppo_drive_object and mode1_state read the control / status / run-command word, the status and
    # fault flags and this word: the others (currents, voltages, registers, dates) not
    read = {"ctw", "zsw", "run_cmd", "status_flag", "fault_flag1", "fault_flag2", want}
    base = 8 if tl.pkw else 0
    ignore = tuple((base + 2 * i, 2) for i, n in enumerate(names) if n not in read)

    def fields(word: int) -> dict[str, Any]:
        pct = pd.to_signed16(word) * 100.0 / fs          # codec.speed_percent
        return {hz_key: round(float(round(pct * fmax / 100.0, 6)), 3),
                pct_key: round(float(round(pct, 6)), 3)}

    def hz(word: int) -> float | None:
        return round(float(round(pd.to_signed16(word) * 100.0 / fs * fmax / 100.0, 6)), 3)
    return SpeedWord(offset, tc.word_order, fields, ignore, hz)
