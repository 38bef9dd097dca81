"""The generic PROFIdrive decoder (`pdrive decode`): PKW, CTW/STW and N2 words as text and JSON.

Turns captured PPO areas into named fields with one-line texts, using the profile's parameters and
alarms and the card config; a family module may supply `param_value(profile, param, raw)`. No bus.
And such a decoded area in the common words of `sniff --station` (ppo_drive_object: command, state,
Hz, the PKW channel), what ProfidriveDrive.normalise_area answers for the families on the core.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable

from profidrive_cli import UsageError
from profidrive_cli.drives.formats import display_text
from profidrive_cli.drives.profidrive.config import ProfidriveConfig, config
from profidrive_cli.drives.profidrive.params import format_value, param_for
from profidrive_cli.drives.profidrive.pkw import (ERROR_RESPONSES, REQUEST_TEXT, RESPONSE_TEXT,
                                                  WRITE_REQUESTS, PkwFrame)
from profidrive_cli.drives.profidrive.pnu import (PNU_BAUD, PNU_CONTROL_WORD, PNU_DEVICE_ID,
                                                  PNU_STATUS_WORD, decode_baud, decode_device_id)
from profidrive_cli.drives.profidrive.ppo import PKW_WORDS, decode_area_bytes, ppo_layout
from profidrive_cli.drives.profidrive.scaling import N2_FULL, n2_to_percent, to_signed16
from profidrive_cli.drives.speedplan import SpeedWord
from profidrive_cli.drives.profidrive.words import (CTW_ZERO_NAMES, Ctw, State, bit_list,
                                                    command_from_control_word,
                                                    state_from_status)

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import ParamDef, Profile

#: a decoded word or area: named fields, JSON-serialisable, with its `text`
Decoded = dict[str, Any]


def _pct_text(pct: float) -> str:
    r = round(pct, 4)
    return f"{r:g} %" if abs(r) < 1e6 else f"{r} %"


def _hz_text(hz: float) -> str:
    return f"{hz:.2f} Hz"


def describe_pkw(profile: Profile, frame: PkwFrame, direction: str, cfg: ProfidriveConfig | None = None,
                 request: PkwFrame | None = None) -> Decoded:
    """Named fields of one PKW frame; `text` (one line) and `summary` (short) included."""
    cfg = cfg or config(profile)
    texts = REQUEST_TEXT if direction == "request" else RESPONSE_TEXT
    d: Decoded = {"pke": frame.pke, "ak": frame.ak, "ak_text": texts.get(frame.ak, "reserved"),
               "spm": frame.spm, "pnu": frame.pnu, "ind": frame.ind, "subindex": frame.subindex,
               "pwe": frame.value}
    card = cfg.supported_requests if direction == "request" else cfg.supported_responses
    if card is not None and frame.ak and frame.ak not in card:
        # the generic PROFIdrive meaning, but the card's table says it does not use this ID
        d["card_supported"] = False
        d["ak_text"] += f" ({cfg.unsupported_text})"
    if frame.ak == 0:
        d["text"] = (f"PKE 0x{frame.pke:04X}: AK 0 ({d['ak_text']}); IND 0x{frame.ind:04X}; "
                     f"PWE 0x{frame.value:08X}")
        d["summary"] = d["ak_text"]
        return d
    p = param_for(profile, frame.pnu, frame.subindex)
    where = f"PNU {frame.pnu}" + (f"[{frame.subindex}]" if frame.subindex else "")
    if p is not None:
        d["code"], d["name"] = p.code, p.name
        named = p.code.upper() != f"PNU{frame.pnu}"
        label = f"{where} = {p.code} {p.name}" if named else f"{where} {p.name}"
        pnu_label = f"PNU {frame.pnu} = {p.code} {p.name}" if named else \
            f"PNU {frame.pnu} {p.name}"
    else:
        label = pnu_label = where if not frame.subindex else f"PNU {frame.pnu}"
    value_text = None
    is_error = direction == "response" and frame.ak in ERROR_RESPONSES
    carries_value = (direction == "request" and frame.ak in WRITE_REQUESTS) or (
        direction == "response" and frame.ak in (1, 2, 4, 5, 9, 10))
    if is_error:
        num = frame.value & 0xFFFF
        d["error"] = num
        d["error_text"] = cfg.error_text(num)
        value_text = f"error {num}: {d['error_text']}"
    elif direction == "response" and frame.ak == 6 or direction == "request" and frame.ak == 9:
        if direction == "response":
            value_text = f"{frame.value} elements"
    elif carries_value:
        value_text = _value_text(profile, cfg, p, frame, d)
    line = f"{d['ak_text']}, {label}"
    if value_text is not None:
        line += f" = {value_text}" if not is_error else f": {value_text}"
    d["value_text"] = value_text
    d["summary"] = line
    d["text"] = (f"PKE 0x{frame.pke:04X}: AK {frame.ak} {d['ak_text']}, SPM {frame.spm}, "
                 + pnu_label + f"; IND 0x{frame.ind:04X} (subindex {frame.subindex}); "
                 f"PWE 0x{frame.value:08X} = {frame.value}"
                 + (f" -> {value_text}" if value_text is not None else ""))
    return d


def _value_text(profile: Profile, cfg: ProfidriveConfig, p: ParamDef | None, frame: PkwFrame,
                d: Decoded) -> str:
    pnu = frame.pnu
    if pnu in cfg.pzd_map:
        w = frame.value & 0xFFFF
        mp = param_for(profile, w) if w else None
        d["maps"] = {"pnu": w, "code": mp.code if mp else None}
        return f"{w} (" + (f"{mp.code} {mp.name}" if mp else ("word unused" if w == 0 else "?")) + ")"
    if pnu == cfg.fault_memory_pnu:
        w = frame.value & 0xFFFF
        alarms = profile.alarms_for(w)
        d["alarms"] = [a.code for a in alarms]
        if w == 0:
            return "0 (no fault)"
        return f"{w} (" + (" / ".join(f"{a.code} {a.meaning}" for a in alarms) or "unknown") + ")"
    if pnu == PNU_DEVICE_ID and cfg.device_ids:
        w = frame.value & 0xFFFF
        return f"0x{w:04X} ({decode_device_id(w, cfg)})"
    if pnu == PNU_BAUD and cfg.baud_codes:
        return f"{frame.value} ({decode_baud(frame.value & 0xFFFF, cfg)})"
    if pnu in (PNU_CONTROL_WORD, PNU_STATUS_WORD):
        return f"0x{frame.value & 0xFFFF:04X}"
    if p is None:
        return str(frame.value)
    raw = frame.value & (0xFFFF if p.size == 16 else 0xFFFFFFFF)
    value = _family_value(profile, p, raw)
    d["raw"], d["value"], d["unit"] = raw, value, p.unit
    return display_text(profile, p, raw, value) or format_value(p, value, raw)


def _family_value(profile: Profile, p: ParamDef, raw: int) -> float | int:
    """Engineering value; family modules may provide `param_value(profile, param, raw)`."""
    from profidrive_cli.drives import codec_module
    try:
        mod = codec_module(profile)
    except UsageError:
        mod = None
    fn: Callable[[Profile, ParamDef, int], float | int] | None = (
        getattr(mod, "param_value", None) if mod is not None else None)
    if fn is not None:
        return fn(profile, p, raw)
    return p.from_raw(raw)


def describe_control_word(profile: Profile, ctw: int, cfg: ProfidriveConfig | None = None) -> Decoded:
    cfg = cfg or config(profile)
    names = dict(cfg.ctw_names)
    for b in cfg.unused_ctw_bits | ({8, 9} - set(names)):
        names[b] = f"bit {b} (not used)"
    bits: list[Decoded] = []
    for b in range(16):
        on = bool(ctw >> b & 1)
        if b in names or on:
            bits.append({"bit": b, "set": on, "name": names.get(b, f"bit {b}")})
    zero = [CTW_ZERO_NAMES[b] for b in (0, 1, 2) if not ctw >> b & 1 and ctw & Ctw.CONTROL_BY_PLC]
    command = command_from_control_word(ctw, cfg.ctw_names, cfg.unused_ctw_bits)
    lab = cfg.labels["control"]
    text = (f"{lab} (control word) 0x{ctw:04X}: " + (", ".join(bit_list(ctw, names)) or "no bits set")
            + (f" [{', '.join(zero)} active]" if zero else "") + f" -> {command}")
    return {"word": ctw, "hex": f"0x{ctw:04X}", "label": lab, "bits": bits,
            "set": bit_list(ctw, names), "command": command, "text": text}


def describe_status_word(profile: Profile, stw: int, actual: int | None = None,
                         cfg: ProfidriveConfig | None = None) -> Decoded:
    cfg = cfg or config(profile)
    names = cfg.stw_names
    # a captured area is one snapshot: the state comes from the status word alone; an actual value
    # != 0 with the S2/S3 pattern may also mean S5 (manual examples show 0x0331 with HIW 0x2000)
    state = state_from_status(stw)
    moving = actual is not None and to_signed16(actual) != 0
    maybe_s5 = moving and state in (State.S2, State.S3)
    bits = [{"bit": b, "set": bool(stw >> b & 1), "name": names.get(b, f"bit {b}")}
            for b in range(16) if b in names or stw >> b & 1]
    lab = cfg.labels["status"]
    text = (f"{lab} (status word) 0x{stw:04X}: " + (", ".join(bit_list(stw, names)) or "no bits set")
            + f" -> {state.value}" + (" (or S5 switching off, if the motor is still turning)"
                                       if maybe_s5 else ""))
    return {"word": stw, "hex": f"0x{stw:04X}", "label": lab, "bits": bits,
            "set": bit_list(stw, names), "state": state.value, "maybe_s5": maybe_s5,
            "text": text}


def describe_n2(word: int, max_hz: float | None, label: str, what: str, max_note: str = "") -> Decoded:
    pct = n2_to_percent(word)
    d: Decoded = {"raw": word, "hex": f"0x{word:04X}", "percent": round(pct, 6), "label": label}
    text = f"{label} ({what}) 0x{word:04X}: {_pct_text(pct)}"
    if max_hz:
        hz = pct * max_hz / 100.0
        d["hz"] = round(hz, 6)
        d["max_hz"] = max_hz
        text += f" = {_hz_text(hz)}" + (f" ({max_note})" if max_note else "")
    d["text"] = text
    return d


def check_direction(direction: str) -> None:
    if direction not in ("request", "response"):
        raise UsageError(f"direction must be request or response, got {direction!r}")


def decode_area(profile: Profile, layout: str, direction: str, data: bytes, *,
                max_hz: float | None = None) -> Decoded:
    """Decode a captured PPO output (direction "request") or input ("response") area."""
    check_direction(direction)
    cfg = config(profile)
    ppo = ppo_layout(profile, layout)
    try:
        area = decode_area_bytes(ppo, bytes(data), direction)
    except ValueError as e:
        raise UsageError(str(e)) from None
    if max_hz is None:
        mhz = float(profile.max_frequency_default)
        note = (f"{profile.max_frequency_param} = {mhz:g} Hz, profile default"
                if profile.max_frequency_param else f"max frequency {mhz:g} Hz, profile default")
    else:
        mhz, note = float(max_hz), f"max frequency {max_hz:g} Hz"
    out: Decoded = {"profile": profile.name, "layout": ppo.name, "direction": direction,
                 "word_order": ppo.word_order, "octets": bytes(data).hex(" ").upper()}
    arrow = "master -> drive" if direction == "request" else "drive -> master"
    text = [f"{profile.name} {ppo.name.upper()} {direction} ({arrow}), {len(data)} octets: "
            f"{out['octets']}"]
    summary: list[str] = []
    if area.pkw is not None:
        frame = PkwFrame.from_words(area.pkw)
        pk = describe_pkw(profile, frame, direction, cfg)
        out["pkw"] = pk
        text.append(pk["text"])
        summary.append(pk["summary"])
    if direction == "request":
        cw = describe_control_word(profile, area.word1, cfg)
        out["control_word"] = cw
        ref = describe_n2(area.word2, mhz, cfg.labels["reference"], "reference", note)
        out["reference"] = ref
        text += [cw["text"], ref["text"]]
        summary += [cw["command"], f"reference {_pct_text(ref['percent'])}"]
    else:
        sw = describe_status_word(profile, area.word1, area.word2, cfg)
        out["status_word"] = sw
        act = describe_n2(area.word2, mhz, cfg.labels["actual"], "actual value", note)
        out["actual"] = act
        text += [sw["text"], act["text"]]
        summary += [sw["state"], f"actual {_pct_text(act['percent'])}"]
    extra: list[Decoded] = []
    for i, w in enumerate(area.pzd[2:], start=3):
        extra.append({"pzd": i, "raw": w, "hex": f"0x{w:04X}"})
    if extra:
        out["pzd"] = extra
        text.append("PZD3..: " + ", ".join(f"PZD{e['pzd']} 0x{e['raw']:04X} ({e['raw']})"
                                           for e in extra)
                    + f" (raw; meaning per PNU {cfg.pzd_map[0 if direction == 'request' else 1]})")
    out["summary"] = "; ".join(summary)
    text.append("summary: " + out["summary"])
    out["text"] = text
    return out


# -- a decoded area in the common words of `sniff --station` (Drive.normalise_area) -------------------

#: the common `drive` object of `pdrive sniff --station` (docs/json.md): command / control, state /
#: status, reference_hz / actual_hz, param
DriveObject = dict[str, Any]


def _round(x: float | None) -> float | None:
    return None if x is None else round(float(x), 3)


def ppo_drive_object(direction: str, area: Decoded, *,
                     state_without_status_word: Callable[[Decoded, DriveObject], None] | None = None
                     ) -> DriveObject:
    """The common fields of a decoded PPO-style area (this package's decode_area, and a family's on
    the core): CTW/STW words (or a `run_command` word), N2 or the family's speed words as Hz, the
    PKW channel as `param` (pkw_drive_param). A response without a status word: the family's
    `state_without_status_word(area, d)` fills state / status / status_word from the area's other
    words (nothing when None)."""
    d: DriveObject = {}
    if direction == "request":
        cw = area.get("control_word") or area.get("run_command")
        if cw:
            d["command"] = cw.get("command")
            d["control"] = list(cw.get("set", []))
            d["control_word"] = cw.get("hex") or f"0x{cw.get('word', cw.get('raw', 0)):04X}"
        ref = area.get("reference")
        if ref:
            d["reference_hz"] = _round(ref.get("hz"))
            d["reference_percent"] = _round(ref.get("percent"))
    else:
        sw = area.get("status_word")
        if sw:
            d["state"] = sw.get("state")
            d["status"] = list(sw.get("set", []))
            d["status_word"] = sw.get("hex") or f"0x{sw.get('word', sw.get('raw', 0)):04X}"
        elif state_without_status_word is not None:
            state_without_status_word(area, d)
        act = area.get("actual")
        if act:
            d["actual_hz"] = _round(act.get("hz"))
            d["actual_percent"] = _round(act.get("percent"))
    pk = area.get("pkw")
    if pk and pk.get("ak"):
        d["param"] = pkw_drive_param(direction, pk)
    return d


def pkw_drive_param(direction: str, pk: Decoded) -> dict[str, Any]:
    """A decoded PKW request or answer (describe_pkw's fields) as the `param` of the drive object:
    request (read / write / other) or error, the native code, and one line ("read F07", "F07 = 5.0 s")."""
    code = pk.get("code") or f"PNU{pk.get('pnu')}"
    if code.upper().startswith("PNU") and pk.get("subindex") and "[" not in code:
        code += f"[{pk['subindex']}]"              # an array element (Fuji's subindex is the code)
    p: dict[str, Any] = {"ak": pk["ak"], "code": code, "ak_text": pk.get("ak_text")}
    vt = pk.get("value_text")
    if "value" in pk:
        p["value"] = pk["value"]
        p["unit"] = pk.get("unit", "")
    if direction == "request":
        if vt is not None:
            p["request"], p["text"] = "write", f"write {code} = {vt}"
        elif "read" in (pk.get("ak_text") or "").lower() or "request" in (pk.get("ak_text") or "").lower():
            p["request"], p["text"] = "read", f"read {code}"
        else:
            p["request"], p["text"] = "other", f"{pk.get('ak_text')} {code}"
    else:
        if "error" in pk and pk.get("error") is not None and pk.get("error") is not False:
            p["error"] = pk["error"]
            p["text"] = f"{code}: error {pk['error']} ({pk.get('error_text', '')})"
        elif vt is not None:
            p["text"] = f"{code} = {vt}"
        else:
            p["text"] = f"{code}: {pk.get('ak_text')}"
    return p


# -- the speed word of sniff --station's fast path (bustools/passive.py) -------------------------------

def speed_plan(profile: Profile, layout: str, direction: str, max_hz: float | None = None
               ) -> SpeedWord | None:
    """sniff --station's fast path (drives/speedplan.py SpeedWord): the N2 reference / actual
    word of a PPO area (the word after CTW / STW) and its fields:
    reference_hz and reference_percent, or actual_hz and actual_percent (ppo_drive_object over
    describe_n2). None when the layout is not a PPO layout."""
    check_direction(direction)
    try:
        ppo = ppo_layout(profile, layout)
    except UsageError:
        return None
    mhz = float(profile.max_frequency_default) if max_hz is None else float(max_hz)
    hz_key, pct_key = (("reference_hz", "reference_percent") if direction == "request"
                       else ("actual_hz", "actual_percent"))

    def fields(word: int) -> DriveObject:
        pct = n2_to_percent(word)
        # describe_n2: percent round(pct, 6), hz round(pct * max / 100, 6) when max; then _round
        return {hz_key: round(float(round(pct * mhz / 100.0, 6)), 3) if mhz else None,
                pct_key: round(float(round(pct, 6)), 3)}

    def hz(word: int) -> float | None:
        # n2_to_percent inline (to_signed16 of a 16-bit word, * 100.0 / N2_FULL): the same floats
        if not mhz:
            return None
        return round(round((word - 0x10000 if word & 0x8000 else word) * 100.0 / N2_FULL * mhz
                           / 100.0, 6), 3)
    pzd = (2 * PKW_WORDS if ppo.pkw else 0)
    # PZD3.. (raw words, ppo_drive_object reads none of them)
    rest = ppo.length(direction) - (pzd + 4)
    return SpeedWord(pzd + 2, ppo.word_order, fields, ((pzd + 4, rest),) if rest > 0 else (), hz)
