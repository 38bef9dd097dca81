"""Where each field of a profile's cyclic areas sits on the wire, for decoders outside Python (the
Wireshark dissector's station table): name, octet offset and size, and how to read it.

Derived from the profile (layouts, word order, max frequency, the `profidrive:` labels and bit names,
parameters) and the family codecs' own tables (Yaskawa word lists and bit names, Toyo fields) --
the same sources `pdrive decode` (drives/*/describe.py) reads. No per-family text is written here by
hand. Field kinds:

    pkw     the 4-word PROFIdrive parameter channel (PKE, IND, PWE high, PWE low), 8 octets
    bits    a 16-bit word with bit names; role "control" or "status" for the PZD1 words
    n2      a 16-bit N2 value: 0x4000 = 100 % of max_hz (when known)
    scaled  a 16-bit value times `scale` in `unit` (signed when `signed`)
    word    a 16-bit word shown raw
    bytes   octets shown raw (e.g. a vendor parameter-access area)
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from profidrive_cli import UsageError

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import Profile

DIRECTIONS = ("request", "response")

#: one field of an area, as the station table's JSON has it (kind, name, offset, size, and the
#: kind's own keys: role, bits, scale, unit, ...)
WireField = dict[str, Any]


def _field(kind: str, name: str, offset: int, size: int = 2, **extra: object) -> WireField:
    d: WireField = {"kind": kind, "name": name, "offset": offset, "size": size}
    d.update({k: v for k, v in extra.items() if v is not None})
    return d


def _ppo_fields(profile: Profile, layout: str, direction: str) -> tuple[int, list[WireField]]:
    from profidrive_cli.drives.profidrive.config import config
    from profidrive_cli.drives.profidrive.ppo import PKW_WORDS, ppo_layout
    cfg = config(profile)
    ppo = ppo_layout(profile, layout)
    fields: list[WireField] = []
    off = 0
    if ppo.pkw:
        fields.append(_field("pkw", "PKW", 0, 2 * PKW_WORDS))
        off = 2 * PKW_WORDS
    fmax = float(profile.max_frequency_default)
    if direction == "request":
        fields.append(_field("bits", cfg.labels["control"], off, role="control", what="control word",
                             bits=dict(cfg.ctw_names)))
        fields.append(_field("n2", cfg.labels["reference"], off + 2, role="reference", what="reference",
                             max_hz=fmax))
    else:
        fields.append(_field("bits", cfg.labels["status"], off, role="status", what="status word",
                             bits=dict(cfg.stw_names)))
        fields.append(_field("n2", cfg.labels["actual"], off + 2, role="actual", what="actual value",
                             max_hz=fmax))
    for i in range(2, ppo.pzd_words(direction)):
        fields.append(_field("word", f"PZD{i + 1}", off + 2 * i))
    return ppo.length(direction), fields


def yaskawa_fields(profile: Profile, layout: str, direction: str) -> tuple[int, list[WireField]]:
    from profidrive_cli.drives.yaskawa.codec import (COMMAND_BITS, COMMAND_TEXT, FORMATS, MFO_BITS,
                                                     SIGNED_WORDS, STATUS_BITS, STATUS_TEXT,
                                                     FrequencyScale)
    from profidrive_cli.drives.yaskawa.config import family_config
    if layout not in FORMATS:
        raise UsageError(f"{profile.name}: no layout '{layout}' (known: {', '.join(FORMATS)})")
    fmt = FORMATS[layout]
    cfg = family_config(profile)
    scale = FrequencyScale(cfg.o1_03, float(profile.max_frequency_default), cfg.reference_unit_hz,
                           cfg.feedback_unit_hz)
    names = fmt.out_words if direction == "request" else fmt.in_words
    fields: list[WireField] = []
    for i, name in enumerate(names):
        off = 2 * i
        if name == "command":
            fields.append(_field("bits", name, off, role="control", what="run command",
                                 bits={b: COMMAND_TEXT[n] for n, b in COMMAND_BITS.items()}))
        elif name == "status":
            fields.append(_field("bits", name, off, role="status", what="drive status", state=False,
                                 bits={b: STATUS_TEXT[n] for n, b in STATUS_BITS.items()}))
        elif name == "mf_outputs":
            fields.append(_field("bits", name, off, bits={b: n for n, b in MFO_BITS.items()}))
        elif name in ("reference", "speed_feedback", "frequency_reference", "output_frequency"):
            which = "reference" if name == "reference" else "feedback"
            role = "reference" if name == "reference" else "actual" if name == "speed_feedback" else None
            fields.append(_field("scaled", name, off, role=role, signed=False, unit="Hz",
                                 scale=scale.raw_to_hz(1, which)))
        elif name in ("torque_reference", "torque_compensation"):
            fields.append(_field("scaled", name, off, signed=True, unit="%", scale=0.1))
        elif name == "output_current":
            fields.append(_field("scaled", name, off, signed=False, unit="% of rating",
                                 scale=100.0 / 8192))
        else:
            fields.append(_field("scaled" if name in SIGNED_WORDS else "word", name, off,
                                 signed=True if name in SIGNED_WORDS else None,
                                 scale=1 if name in SIGNED_WORDS else None))
    if fmt.param_offset is not None:                 # (fmt.has_params)
        fields.append(_field("bytes", "parameter access", fmt.param_offset, fmt.param_len))
    return fmt.size, fields


def toyo_fields(profile: Profile, layout: str, direction: str) -> tuple[int, list[WireField]]:
    from profidrive_cli.drives.toyo.codec import speed_percent
    from profidrive_cli.drives.toyo.config import toyo_config
    from profidrive_cli.drives.toyo.params import value_from_wire
    tc = toyo_config(profile)
    lay = tc.layouts.get(layout)
    if lay is None:
        raise UsageError(f"{profile.name}: no layout '{layout}' (known: {', '.join(tc.layouts)})")
    fields: list[WireField] = []
    off = 0
    if lay.pkw:
        fields.append(_field("pkw", "PKW", 0, 8))
        off = 8
    fmax = float(profile.max_frequency_default)
    for i, fname in enumerate(lay.words(direction, tc.plch)):
        o = off + 2 * i
        f = tc.fields.get(fname)
        if f is None:
            fields.append(_field("word", fname, o))
            continue
        kind, name = f["kind"], f["name"]
        if kind in ("ctw", "zsw", "run_cmd", "bits"):
            table = {"ctw": "ctw", "zsw": "zsw", "run_cmd": "run_cmd"}.get(kind, f.get("bits"))
            role = {"ctw": "control", "zsw": "status"}.get(kind)
            bits = tc.bits.get(table, {}) if table is not None else {}
            fields.append(_field("bits", name, o, role=role, bits=dict(bits)))
        elif kind == "speed":
            # the first speed word is the main reference / actual value
            role = None
            if not any(x.get("role") in ("reference", "actual") for x in fields):
                role = "reference" if direction == "request" else "actual"
            fields.append(_field("scaled", name, o, role=role, signed=True, unit="Hz",
                                 scale=speed_percent(profile, 1) * fmax / 100.0))
        elif kind == "scaled":
            fields.append(_field("scaled", name, o, signed=bool(f.get("signed")), unit=f.get("unit", ""),
                                 scale=float(f.get("scale", 1))))
        elif kind == "param":
            p = profile.param(f["param"])
            assert p is not None, "toyo_config checked that fields.*.param is a parameter"
            per_count = value_from_wire(profile, p, 1000) / 1000.0
            fields.append(_field("scaled", name, o, signed=p.signed, unit=p.unit, scale=per_count))
        else:
            fields.append(_field("word", name, o))
    n = off + 2 * len(lay.words(direction, tc.plch))
    return n, fields


def area_fields(profile: Profile, layout: str, direction: str) -> dict[str, Any]:
    """{"length": octets, "fields": [...]} of one direction of a layout (request = master -> drive)."""
    if direction not in DIRECTIONS:
        raise UsageError(f"direction must be request or response, got {direction!r}")
    if layout not in profile.layouts:
        raise UsageError(f"{profile.name} has no layout '{layout}' (known: {', '.join(profile.layouts)})")
    from profidrive_cli.drives.registry import resolve, wire_fields_ref
    ref = wire_fields_ref(profile)                 # the family's own layout, else PPO words
    length, fields = (resolve(ref) if ref else _ppo_fields)(profile, layout, direction)
    lay = profile.layouts[layout]
    want = lay.output_len if direction == "request" else lay.input_len
    if length != want:
        raise UsageError(f"{profile.name} {layout}: the {direction} fields cover {length} octets, "
                         f"the layout's cfg says {want}")
    return {"length": length, "fields": fields}


def _ak_texts(profile: Profile) -> tuple[dict[int, str], dict[int, str]]:
    if profile.family == "toyo":
        from profidrive_cli.drives.toyo.describe import REQUEST_TEXT, RESPONSE_TEXT
        return dict(REQUEST_TEXT), dict(RESPONSE_TEXT)
    from profidrive_cli.drives.profidrive.pkw import REQUEST_TEXT, RESPONSE_TEXT
    return dict(REQUEST_TEXT), dict(RESPONSE_TEXT)


def _params(profile: Profile) -> dict[int, str]:
    """PNU * 256 + subindex (255: any subindex) -> 'code name', for PKW requests and answers."""
    out: dict[int, str] = {}
    for p in profile.parameters.values():
        if p.pnu is None or not 0 <= p.pnu <= 0x7FF:
            continue
        sub = 255 if p.index is None else p.index
        if 0 <= sub <= 255:
            out.setdefault(p.pnu * 256 + sub, f"{p.code} {p.name}")
    return out


def layout_table(profile: Profile, layout: str) -> dict[str, Any]:
    """Everything a decoder needs for one layout of a profile: both directions' fields, the word order,
    PKW request/response texts and parameter names."""
    d: dict[str, Any] = {"profile": profile.name, "layout": layout, "title": profile.title,
         "word_order": profile.word_order,
         "request": area_fields(profile, layout, "request"),
         "response": area_fields(profile, layout, "response")}
    if any(f["kind"] == "pkw" for f in d["request"]["fields"]):
        d["ak_request"], d["ak_response"] = _ak_texts(profile)
        d["params"] = _params(profile)
    return d
