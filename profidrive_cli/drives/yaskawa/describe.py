"""Yaskawa decode_area: a captured output or input area -> named fields and text (pdrive decode).

JSON-serialisable dict with a "text" list; and such an area in the common words of `sniff --station`
(drive_object, what YaskawaDrive.normalise_area answers). May touch: codec, paramaccess (area
parsing), config, drives/base (value_text).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from profidrive_cli import UsageError
from profidrive_cli.drives.base import value_text
from profidrive_cli.drives.yaskawa.codec import (COMMAND_TEXT, FORMATS, MFO_BITS, STATUS_TEXT, AreaFormat,
                                                 FrequencyScale, _s16, decode_bits, decode_command,
                                                 decode_status, unpack_words)
from profidrive_cli.drives.yaskawa.config import family_config, register_name
from profidrive_cli.drives.speedplan import SpeedWord
from profidrive_cli.drives.yaskawa.paramaccess import (ERROR_CODES, FC_NONE, FC_READ, FC_WRITE,
                                                       FUNCTION_NAMES, HS_STATUS_NAMES, ParamArea,
                                                       decode_hs, error_text)

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import ParamDef, Profile

# ---------------------------------------------------------------------------------------------------
# decode_area: captured areas -> named fields (pdrive decode)
# ---------------------------------------------------------------------------------------------------


def _flags_text(word: int, flags: dict[str, bool], names: dict[str, str]) -> str:
    on = [names.get(k, k) for k, v in flags.items() if v]
    return f"0x{word:04X}" + (": " + ", ".join(on) if on else ": (none)")


def _reg_label(profile: Profile, reg: int) -> str:
    n = register_name(profile, reg)
    return f"0x{reg:04X}" + (f" ({n})" if n else "")


def decode_area(profile: Profile, layout: str, direction: str, data: bytes) -> dict[str, Any]:
    """Decode one captured output area (direction "request") or input area ("response")."""
    if layout not in FORMATS or layout not in profile.layouts:
        raise UsageError(f"{profile.name}: no layout '{layout}' (known: {', '.join(profile.layouts)})")
    if direction not in ("request", "response"):
        raise UsageError(f"direction must be request or response, got {direction!r}")
    fmt = FORMATS[layout]
    data = bytes(data)
    if len(data) != fmt.size:
        raise UsageError(f"{profile.name} {layout}: a {direction} area is {fmt.size} octets, got {len(data)}")
    cfg = family_config(profile)
    fmax = float(profile.max_frequency_default)
    scale = FrequencyScale(cfg.o1_03, fmax, cfg.reference_unit_hz, cfg.feedback_unit_hz)
    names = fmt.out_words if direction == "request" else fmt.in_words
    fast = data[:2 * len(names)]
    words = dict(zip(names, unpack_words(fast, profile.word_order)))
    out: dict[str, Any] = {"profile": profile.name, "layout": layout, "direction": direction,
                           "word_order": profile.word_order, "words": dict(words)}
    text: list[str] = []

    for name, w in words.items():
        if name == "command":
            fl = decode_command(w)
            out["command"] = {"raw": w, "flags": fl}
            text.append("run command " + _flags_text(w, fl, COMMAND_TEXT))
            if fl["forward_run"] and fl["reverse_run"]:
                text.append("  forward and reverse together: the drive stops and shows an alarm")
        elif name == "status":
            fl = decode_status(w)
            out["status"] = {"raw": w, "flags": fl}
            text.append("drive status " + _flags_text(w, fl, STATUS_TEXT))
        elif name == "reference":
            hz = scale.raw_to_hz(w, "reference")
            out["frequency_reference"] = {"raw": w, "hz": hz, "unit": scale.unit_text("reference")}
            text.append(f"frequency reference {w} = {hz:g} Hz ({scale.unit_text('reference')}/count, "
                        f"o1-03 = {cfg.o1_03} assumed)")
        elif name in ("speed_feedback", "frequency_reference", "output_frequency"):
            hz = scale.raw_to_hz(w, "feedback")
            out[name] = {"raw": w, "hz": hz, "unit": scale.unit_text("feedback")}
            label = {"speed_feedback": "speed feedback", "frequency_reference": "frequency reference (drive)",
                     "output_frequency": "output frequency"}[name]
            text.append(f"{label} {w} = {hz:g} Hz ({scale.unit_text('feedback')}/count)")
        elif name in ("torque_reference", "torque_compensation"):
            pct = round(_s16(w) * 0.1, 1)
            out[name] = {"raw": w, "percent": pct}
            text.append(f"{name.replace('_', ' ')} {_s16(w)} = {pct:g} % (flux-vector control only)")
        elif name == "output_current":
            pct = round(w * 100.0 / 8192, 2)
            entry: dict[str, Any] = {"raw": w, "percent_of_rating": pct}
            line = f"output current {w} = {pct:g} % of the drive rating"
            if cfg.rated_current_a:
                entry["amps"] = round(w * cfg.rated_current_a / 8192, 3)
                line += f" = {entry['amps']:g} A"
            out[name] = entry
            text.append(line)
        elif name in ("analog_out1", "analog_out2", "analog_in1"):
            out[name] = {"raw": w, "signed": _s16(w)}
            text.append(f"{name.replace('_', ' ')} {_s16(w)} (count scaling not given by the manual)")
        elif name == "pg_count":
            out[name] = {"raw": w, "signed": _s16(w)}
            text.append(f"PG count {_s16(w)}")
        elif name == "mf_outputs":
            fl = decode_bits(w, MFO_BITS)
            out[name] = {"raw": w, "flags": fl}
            text.append("MF outputs " + _flags_text(w, fl, {}))
            if w & 0xFF00:
                text.append("  bits 8-15 are reserved but set")
        elif name == "reserved":
            out[name] = w
            if w:
                text.append(f"reserved word 0x{w:04X} (should be 0)")

    if fmt.has_params:
        area = data[fmt.param_offset:]
        pa, ptext = _decode_param(profile, fmt, direction, area)
        out["parameter_access"] = pa
        text.extend(ptext)
    out["text"] = text
    return out


def _decode_param(profile: Profile, fmt: AreaFormat, direction: str, area: bytes
                  ) -> tuple[dict[str, Any], list[str]]:
    p = ParamArea.parse(fmt, area)
    fn = p.function
    d: dict[str, Any] = {"function": fn, "function_name": FUNCTION_NAMES.get(fn, "invalid"),
                         "start_register": p.start, "data_quantity": p.quantity, "data": p.data}
    text: list[str] = []
    nregs = p.quantity // 2 if p.quantity % 2 == 0 else 0
    if direction == "request":
        hs = area[-1] >> 7 & 1
        d["handshake"] = {"raw": area[-1], "hs": hs}
        if fn == FC_NONE:
            text.append(f"parameter access: no request (HS {hs})")
        elif fn in (FC_READ, FC_WRITE):
            what = "read" if fn == FC_READ else "write"
            line = f"parameter access: {what} {nregs or '?'} register(s) from {_reg_label(profile, p.start)} (HS {hs})"
            text.append(line)
            if p.quantity not in fmt.data_quantities:
                text.append(f"  data quantity {p.quantity} is not allowed here "
                            f"({'/'.join(map(str, fmt.data_quantities))}): the drive answers 0x03")
            if fn == FC_WRITE:
                for i, v in enumerate(p.data[:max(1, min(nregs, fmt.max_registers))]):
                    text.append(f"  {_reg_label(profile, p.start + i)} := 0x{v:04X} ({v})")
            elif any(p.data):
                text.append("  data words should be 0 in a read request")
        else:
            text.append(f"parameter access: function code 0x{fn:02X} is invalid (drive answers 0x01)")
        if area[-1] & 0x7F:
            text.append(f"  handshake bits 6-0 should be 0 (0x{area[-1]:02X})")
        return d, text

    hs, status, wd = decode_hs(area[-1])
    d["handshake"] = {"raw": area[-1], "hs": hs, "status": status, "status_name": HS_STATUS_NAMES[status],
                      "wd": wd, "complete": status == 3}
    text.append(f"handshake 0x{area[-1]:02X}: HS {hs}, STATUS {status:02b} ({HS_STATUS_NAMES[status]}), "
                f"watchdog {wd}")
    valid = "" if status == 3 else " (not valid yet: STATUS is not 11)"
    if fn == FC_NONE:
        text.append("parameter access: no reply data")
    elif p.is_error and (fn & 0x7F) in (FC_READ, FC_WRITE):
        code = p.error_code
        name, meaning = ERROR_CODES.get(code, (f"unknown (0x{code:02X})", "not in the manual's table"))
        d.update({"error": True, "error_code": code, "error_name": name, "error_meaning": meaning})
        text.append(f"parameter access: {FUNCTION_NAMES[fn]}, code {error_text(code)}{valid}")
    elif fn in (FC_READ, FC_WRITE):
        d["error"] = False
        if fn == FC_READ:
            vals = p.data[:max(0, min(nregs, fmt.max_registers))]
            d["values"] = vals
            text.append(f"parameter access: read reply from {_reg_label(profile, p.start)}{valid}")
            for i, v in enumerate(vals):
                text.append(f"  {_reg_label(profile, p.start + i)} = 0x{v:04X} ({v})")
        else:
            text.append(f"parameter access: write to {_reg_label(profile, p.start)} accepted "
                        f"({nregs} register(s)){valid}")
    else:
        text.append(f"parameter access: function code 0x{fn:02X} is not a valid reply")
    return d, text


# ---------------------------------------------------------------------------------------------------
# the common `drive` object of sniff --station (YaskawaDrive.normalise_area)
# ---------------------------------------------------------------------------------------------------


def _round(x: float | None) -> float | None:
    return None if x is None else round(float(x), 3)


def drive_object(profile: Profile, direction: str, area: dict[str, Any]) -> dict[str, Any]:
    """A decoded area (decode_area) in the common words of `pdrive sniff --station`: the run
    command and status flags in the manual's words (codec COMMAND_TEXT / STATUS_TEXT), reference
    and output frequency in Hz, the MEMOBUS parameter area as `param` (memobus_param)."""
    d: dict[str, Any] = {}
    if direction == "request":
        cmd = area.get("command")
        if cmd:
            fl = cmd["flags"]
            d["command"] = ("forward and reverse (the drive stops with an alarm)"
                            if fl.get("forward_run") and fl.get("reverse_run") else
                            "forward run" if fl.get("forward_run") else
                            "reverse run" if fl.get("reverse_run") else "stop")
            d["control"] = [COMMAND_TEXT.get(k, k) for k, v in fl.items() if v]
            d["control_word"] = f"0x{cmd['raw']:04X}"
        ref = area.get("frequency_reference")
        if ref:
            d["reference_hz"] = _round(ref.get("hz"))
    else:
        stw = area.get("status")
        if stw:
            fl = stw["flags"]
            d["state"] = ("fault" if fl.get("fault") else "alarm" if fl.get("alarm") else
                          ("running reverse" if fl.get("reverse") else "running")
                          if fl.get("running") else "ready" if fl.get("ready") else "not ready")
            d["status"] = [STATUS_TEXT.get(k, k) for k, v in fl.items() if v]
            d["status_word"] = f"0x{stw['raw']:04X}"
        act = area.get("output_frequency") or area.get("speed_feedback")
        if act:
            d["actual_hz"] = _round(act.get("hz"))
    pa = area.get("parameter_access")
    if pa and pa.get("function"):
        p = memobus_param(profile, direction, pa)
        if p is not None:
            d["param"] = p
    return d


def memobus_param(profile: Profile, direction: str, pa: dict[str, Any]) -> dict[str, Any] | None:
    """The parameter-access area (decode_area's `parameter_access`) as the `param` of the drive
    object: request (read / write / other) or error, the profile's code of the register, one line
    ("read C1-01", "C1-01 = 10.0 s"); None for an answer whose handshake is still running."""
    reg = pa.get("start_register", 0)
    prm = next((p for p in profile.parameters.values() if p.register == reg), None)
    code = prm.code if prm is not None else f"register 0x{reg:04X}"
    fn = pa["function"]
    p: dict[str, Any] = {"function": fn, "code": code}
    if direction == "request":
        if fn == FC_READ:
            p["request"], p["text"] = "read", f"read {code}"
        elif fn == FC_WRITE:
            vals = pa.get("data") or [0]
            p["request"] = "write"
            p["text"] = f"write {code} = {_reg_value(prm, vals[0])}"
        else:
            p["request"], p["text"] = "other", f"function 0x{fn:02X} {code}"
        return p
    hs = pa.get("handshake") or {}
    if not hs.get("complete"):
        return None            # the handshake is still running: the area holds no answer yet
    if pa.get("error"):
        p["error"] = pa.get("error_code")
        p["text"] = f"{code}: error {pa.get('error_name')} ({pa.get('error_meaning')})"
    elif fn == FC_READ and pa.get("values"):
        raw = pa["values"][0]
        if prm is not None:
            p["value"] = prm.from_raw(raw)
            p["unit"] = prm.unit or ""
        p["text"] = f"{code} = {_reg_value(prm, raw)}"
    else:
        p["text"] = f"{code}: {pa.get('function_name')} accepted"
    return p


def _reg_value(prm: ParamDef | None, raw: int) -> str:
    if prm is None:
        return f"0x{raw:04X}"
    return value_text(prm.from_raw(raw), prm.unit or "")


def speed_plan(profile: Profile, layout: str, direction: str, max_hz: float | None = None
               ) -> SpeedWord | None:
    """sniff --station's fast path (drives/speedplan.py SpeedWord): the word drive_object
    reads the Hz from -- the reference (request), the output frequency or else the speed feedback
    (response) -- and its reference_hz / actual_hz as decode_area and drive_object compute them
    (the profile's max frequency: decode_area takes no other); the other fast words ignored. None
    for an unknown layout."""
    if layout not in FORMATS or layout not in profile.layouts:
        return None
    fmt = FORMATS[layout]
    names = fmt.out_words if direction == "request" else fmt.in_words
    want = (("reference",) if direction == "request" else
            ("output_frequency",) if "output_frequency" in names else ("speed_feedback",))
    if want[0] not in names:
        return None
    cfg = family_config(profile)
    scale = FrequencyScale(cfg.o1_03, float(profile.max_frequency_default), cfg.reference_unit_hz,
                           cfg.feedback_unit_hz)
    which, key = ("reference", "reference_hz") if direction == "request" else ("feedback", "actual_hz")
    raw_to_hz = scale.raw_to_hz

    def fields(word: int) -> dict[str, Any]:
        return {key: _round(raw_to_hz(word, which))}

    def hz(word: int) -> float | None:
        return _round(raw_to_hz(word, which))
    # drive_object reads the command / status word, this word and the parameter area: the other
    # fast words (torque, current, analog, PG count, MF outputs, the drive's own reference) not
    read = {"command", "status", want[0]}
    ignore = tuple((2 * i, 2) for i, n in enumerate(names) if n not in read)
    return SpeedWord(2 * names.index(want[0]), profile.word_order, fields, ignore, hz)
