"""Interpreting a parsed GSD: Set_Prm user-parameter bytes, Chk_Cfg bytes, unit diagnosis. It reads
the model (gsd/model.py) and never the parser.

User_Prm_Data (reference §5), per block:
    device block   = User_Prm_Data padded/cut to User_Prm_Data_Len (zeros when absent)
                     -> overlay every Ext_User_Prm_Data_Const(offset)
                     -> write every Ext_User_Prm_Data_Ref(offset) value (default or override):
                        Bit(n)/BitArea(a-b) into bits a..b of the octet at offset (other bits kept),
                        UnsignedN/SignedN big endian at offset..offset+N/8-1
    module blocks  = the same from Ext_Module_Prm_Data_Len / the module's Ext_User_Prm_Data_*,
                     followed by its PROFIsafe F_Ext_* block, appended in module order.
Chk_Cfg = the selected modules' identifier octets verbatim (0x00 empty-slot octets included).

Module selection (select_module / select_modules) is the model's lookup (gsd/model.py).

A module parameter named "[SlotNumber]" (Siemens convention: the configuration tool fills in the module's
slot) gets Modul_Offset + its 0-based position in the selection, unless overridden or outside its range.

Overrides by parameter name (case-insensitive); "N:name" restricts the name to block N (0 = device block,
1.. = the Nth selected module). Values: integers (decimal, 0x hex, negative) or the parameter's PrmText
text. Every value is checked against the allowed list or range of its ExtUserPrmData.

Unit diagnosis (decode_unit_diag): the caller passes the Slave_Diag octets after the 6 standard octets.
The device-related block(s) there (header bits 7..6 = 00, bits 5..0 = block length including the header)
are decoded with Unit_Diag_Bit / Unit_Diag_Not_Bit / Unit_Diag_Area. Decision: bit n is bit n % 8 of
octet n // 8 *counted from the first octet after the block header* (reference §3.4, the PROFIBUS GSD
specification and profirust's gsdtool agree; the header octet itself carries only type and length).
This fits the real files: the Siemens diagnostic repeater (si0380a7.gsd) puts "Segment DP1..3" at bits
28..31, i.e. the 4th octet after the header, after the DP-V1 status type, slot and specifier octets.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping, Sequence

from profidrive_cli import UsageError
from profidrive_cli.gsd.model import (
    MAX_USER_PRM_LEN, DiagArea, ExtUserPrmData, Gsd, Module, PrmBlock, select_module, select_modules,
)

# ---------------------------------------------------------------- Set_Prm user data
@dataclass
class PrmField:
    offset: int                       # octet offset within User_Prm_Data
    size: int                         # octets
    bits: tuple[int, int] | None      # (first, last) for Bit/BitArea; None for whole octets
    name: str
    value: int
    text: str | None
    block: str                        # "device" or "module N 'name'"
    block_index: int                  # 0 = device, 1.. = selected module
    ref: int
    overridden: bool = False
    param: ExtUserPrmData | None = field(default=None, repr=False)

    @property
    def bits_label(self) -> str:
        if self.bits is None:
            return f"octets {self.offset}-{self.offset + self.size - 1}" if self.size > 1 else "octet"
        lo, hi = self.bits
        return f"bit {lo}" if lo == hi else f"bits {lo}-{hi}"


@dataclass
class PrmBlockInfo:
    label: str
    index: int
    start: int
    length: int


@dataclass
class PrmResult:
    gsd: Gsd
    modules: list[Module]
    user_prm: bytes
    cfg: bytes
    fields: list[PrmField]
    blocks: list[PrmBlockInfo]
    warnings: list[str] = field(default_factory=list)

    @property
    def ident_number(self) -> int | None:
        return self.gsd.ident_number

    def rows(self) -> list[dict[str, Any]]:
        """One row per parameter field, and one per octet no parameter covers (constant octets)."""
        by_off: dict[int, list[PrmField]] = {}
        for f in self.fields:
            by_off.setdefault(f.offset, []).append(f)
        covered: set[int] = set()
        for f in self.fields:
            covered.update(range(f.offset, f.offset + f.size))
        rows: list[dict[str, Any]] = []
        data = self.user_prm
        for blk in self.blocks:
            for off in range(blk.start, blk.start + blk.length):
                if off in by_off:
                    for f in sorted(by_off[off], key=lambda f: (f.bits or (0, 0))):
                        rows.append({
                            "offset": off, "set_prm_octet": 7 + off,
                            "octets": data[off:off + f.size].hex(" ").upper(),
                            "bits": f.bits_label if f.bits or f.size > 1 else "",
                            "name": f.name, "value": f.value, "text": f.text, "block": f.block,
                            "overridden": f.overridden, "constant": False})
                elif off not in covered:
                    name = "constant"
                    if blk.index == 0 and self.gsd.dpv1_slave and off < 3:
                        name = f"DPV1_Status_{off + 1} (constant)"
                    rows.append({"offset": off, "set_prm_octet": 7 + off, "octets": f"{data[off]:02X}",
                                 "bits": "", "name": name, "value": data[off], "text": None,
                                 "block": blk.label, "overridden": False, "constant": True})
        return rows

    def explain(self) -> list[str]:
        """One line per octet / bit field: offset, bits, parameter name, value, text."""
        out = []
        for r in self.rows():
            val = f"{r['value']}" + (f" ({r['text']})" if r["text"] else "")
            if r["constant"]:
                val = f"0x{r['value']:02X}"
            bits = f" {r['bits']}" if r["bits"] else ""
            mark = " [set]" if r["overridden"] else ""
            out.append(f"User_Prm[{r['offset']}] (Set_Prm octet {r['set_prm_octet']}){bits}: "
                       f"{r['octets']}  {r['name']} = {val}  [{r['block']}]{mark}")
        return out

    def cfg_rows(self) -> list[dict[str, Any]]:
        rows, off = [], 0
        for i, m in enumerate(self.modules, 1):
            for c in m.cfg_modules:
                rows.append({"offset": off, "octets": c.raw.hex(" ").upper(), "module": m.display_name,
                             "slot": i, "inputs": c.inputs, "outputs": c.outputs,
                             "description": c.describe()})
                off += len(c.raw)
        return rows

    def explain_cfg(self) -> list[str]:
        return [f"Chk_Cfg[{r['offset']}]: {r['octets']}  module {r['slot']} {r['module']!r}: {r['description']}"
                for r in self.cfg_rows()]

    def to_dict(self) -> dict[str, Any]:
        return {
            "file": self.gsd.path,
            "ident": self.gsd.ident_number,
            "modules": [{"index": m.index, "name": m.display_name, "cfg": m.cfg.hex(" ").upper()}
                        for m in self.modules],
            "user_prm": self.user_prm.hex(" ").upper(),
            "user_prm_len": len(self.user_prm),
            "chk_cfg": self.cfg.hex(" ").upper(),
            "inputs": sum(m.inputs for m in self.modules),
            "outputs": sum(m.outputs for m in self.modules),
            "user_prm_fields": self.rows(),
            "chk_cfg_fields": self.cfg_rows(),
            "warnings": list(self.warnings),
        }


def parse_value(text: str) -> int | None:
    t = text.strip()
    neg = t.startswith("-")
    if neg:
        t = t[1:].strip()
    if re.fullmatch(r"0[xX][0-9a-fA-F]+", t):
        v = int(t, 16)
    elif t.isascii() and t.isdigit():
        v = int(t)
    else:
        return None
    return -v if neg else v


def _resolve_value(d: ExtUserPrmData, raw: int | str, label: str) -> int:
    if isinstance(raw, bool):
        raw = int(raw)
    v: int | None
    if isinstance(raw, int):
        v = raw
    else:
        v = parse_value(str(raw))
        if v is None:
            key = str(raw).strip().casefold()
            hits = [k for k, t in (d.texts or {}).items() if t.strip().casefold() == key]
            if not hits:
                raise UsageError(f"parameter {label}: {raw!r} is neither a number nor one of its texts"
                                 + _choices(d))
            v = hits[0]
    if not d.is_allowed(v):
        raise UsageError(f"parameter {label}: {v} not allowed" + _choices(d))
    return v


def _choices(d: ExtUserPrmData) -> str:
    s = f"; allowed: {d.describe_allowed()}"
    if d.texts:
        vals = d.allowed if d.allowed is not None else sorted(d.texts)
        texts = [f"{v} = {d.texts[v]}" for v in vals if v in d.texts and d.is_allowed(v)]
        if texts:
            s += " (" + ", ".join(texts[:16]) + (", ..." if len(texts) > 16 else "") + ")"
    return s


def _write(buf: bytearray, off: int, d: ExtUserPrmData, value: int) -> None:
    if d.is_bits:
        lo, hi = d.bit_lo, d.bit_hi
        assert lo is not None and hi is not None    # a Bit / BitArea has both (gsd/parser.py)
        mask = ((1 << (hi - lo + 1)) - 1) << lo
        buf[off] = (buf[off] & ~mask & 0xFF) | ((value << lo) & mask)
    else:
        buf[off:off + d.size] = value.to_bytes(d.size, "big", signed=d.data_type.startswith("Signed"))


def _slots(gsd: Gsd, modules: list[Module]) -> list[tuple[int, str, PrmBlock]]:
    out = [(0, "device", gsd.prm)]
    for i, m in enumerate(modules, 1):
        label = f"module {i} {m.display_name!r}"
        out.append((i, label, m.prm))
        if not m.f_prm.empty:
            out.append((i, label + " F-parameters", m.f_prm))
    return out


def build_prm(gsd: Gsd, modules: Iterable[int | str | Module] | None = None,
              overrides: Mapping[str, int | str] | Sequence[str] | None = None) -> PrmResult:
    """Set_Prm user-parameter octets and Chk_Cfg octets for `modules`, with parameter overrides.

    `overrides` is a mapping name -> value, or a list of "NAME=VALUE" strings (split at the last '=',
    since GSD parameter names may contain '=').
    """
    return _build(gsd, select_modules(gsd, modules), overrides)


def device_user_prm(gsd: Gsd) -> bytes:
    """The device block of User_Prm_Data alone (defaults), without any module."""
    return _build(gsd, [], None).user_prm


def _build(gsd: Gsd, mods: list[Module],
           overrides: Mapping[str, int | str] | Sequence[str] | None) -> PrmResult:
    ov = _normalise_overrides(overrides)
    slots = _slots(gsd, mods)
    warnings: list[str] = []

    # 1. every parameter reference with its definition
    refs: list[tuple[int, str, int, Any, ExtUserPrmData]] = []   # (slot no, label, block idx, ref, def)
    for bi, (idx, label, block) in enumerate(slots):
        for r in block.refs:
            d = gsd.ext_user_prm_data.get(r.ref)
            if d is None:
                raise UsageError(f"{gsd.path}:{r.line}: {label}: Ext_User_Prm_Data_Ref({r.offset}) = {r.ref}"
                                 " refers to no ExtUserPrmData")
            if not (d.is_bits or d.size):
                raise UsageError(f"{gsd.path}:{d.line}: ExtUserPrmData {d.ref} {d.name!r}: type "
                                 f"{d.data_type or '(missing)'} cannot be written into Set_Prm")
            refs.append((idx, label, bi, r, d))

    # 2. overrides -> the references they address
    values: dict[int, int] = {}       # position in refs -> value
    for key, raw in ov:
        qual, name = _split_qualifier(key)
        cname = name.strip().casefold()
        hits = [i for i, (idx, _, _, _, d) in enumerate(refs)
                if d.name.strip().casefold() == cname and (qual is None or qual == idx)]
        if not hits:
            known = sorted({d.name.strip() for (_, _, _, _, d) in refs})
            where = "" if qual is None else f" in block {qual}"
            raise UsageError(f"no user parameter {name.strip()!r}{where} for this module selection"
                             + (f"; parameters: {', '.join(repr(k) for k in known[:30])}"
                                + (" ..." if len(known) > 30 else "") if known else "; it has none"))
        slots_hit = sorted({refs[i][0] for i in hits})
        if len(slots_hit) > 1:
            forms = ", ".join(f"'{s}:{name.strip()}'" for s in slots_hit)
            raise UsageError(f"parameter {name.strip()!r} exists in several blocks; say which: {forms} "
                             "(0 = device, N = Nth module)")
        for i in hits:
            d = refs[i][4]
            if not d.changeable:
                raise UsageError(f"parameter {d.name.strip()!r} is not changeable (Changeable = 0 in the GSD)")
            values[i] = _resolve_value(d, raw, repr(d.name.strip()))

    # 3. build each block
    out = bytearray()
    fields: list[PrmField] = []
    blocks: list[PrmBlockInfo] = []
    per_block: dict[int, list[int]] = {}
    for i, (_, _, bi, _, _) in enumerate(refs):
        per_block.setdefault(bi, []).append(i)
    for bi, (idx, label, block) in enumerate(slots):
        if block.empty:
            if idx == 0 or block is not mods[idx - 1].f_prm:
                blocks.append(PrmBlockInfo(label, idx, len(out), 0))
            continue
        if block.length is not None and block.length > MAX_USER_PRM_LEN:
            raise UsageError(f"{gsd.path}:{block.length_line}: {label}: length {block.length} exceeds the "
                             f"{MAX_USER_PRM_LEN} octets Set_Prm can carry")
        buf = bytearray(block.base or b"")
        if block.length is not None:
            if len(buf) > block.length:
                warnings.append(f"{label}: User_Prm_Data has {len(buf)} octets, cut to User_Prm_Data_Len "
                                f"{block.length}")
            buf = buf[:block.length] + bytes(max(0, block.length - len(buf)))
        for c in block.consts:
            end = c.offset + len(c.data)
            if end > len(buf):
                if block.length is not None:
                    warnings.append(f"{gsd.path}:{c.line}: {label}: Ext_User_Prm_Data_Const({c.offset}) runs to "
                                    f"octet {end - 1}, beyond the declared length {block.length}")
                buf.extend(bytes(end - len(buf)))
            buf[c.offset:end] = c.data
        for i in per_block.get(bi, []):
            _, _, _, r, d = refs[i]
            end = r.offset + d.size
            if end > len(buf):
                if block.length is not None:
                    warnings.append(f"{gsd.path}:{r.line}: {label}: Ext_User_Prm_Data_Ref({r.offset}) "
                                    f"({d.name.strip()!r}) lies beyond the declared length {block.length}")
                buf.extend(bytes(end - len(buf)))
            v = values.get(i, d.default)
            text = None
            if i not in values and idx >= 1 and d.name.strip().casefold() == "[slotnumber]":
                slot_no = (gsd._int("modul_offset") or 0) + idx - 1
                if d.is_allowed(slot_no):
                    v, text = slot_no, "slot number"
                else:
                    warnings.append(f"{label}: [SlotNumber] {slot_no} outside {d.describe_allowed()}; "
                                    f"default {v} kept")
            if i not in values and not d.is_allowed(v):
                lo, hi = d.type_range()
                if not lo <= v <= hi:
                    raise UsageError(f"{gsd.path}:{d.type_line}: ExtUserPrmData {d.ref} {d.name!r}: default "
                                     f"{v} does not fit {d.describe_type()}")
            _write(buf, r.offset, d, v)
            fields.append(PrmField(offset=len(out) + r.offset, size=d.size,
                                   bits=(d.bit_lo, d.bit_hi) if d.is_bits and d.bit_lo is not None
                                   and d.bit_hi is not None else None,
                                   name=d.name.strip(), value=v, text=text or d.text_for(v), block=label,
                                   block_index=idx, ref=d.ref, overridden=i in values, param=d))
        blocks.append(PrmBlockInfo(label, idx, len(out), len(buf)))
        out += buf
    if len(out) > MAX_USER_PRM_LEN:
        raise UsageError(f"User_Prm_Data would be {len(out)} octets; Set_Prm carries at most "
                         f"{MAX_USER_PRM_LEN}")
    mx = gsd.max_user_prm_data_len
    if mx is not None and len(out) > mx:
        warnings.append(f"User_Prm_Data is {len(out)} octets, more than Max_User_Prm_Data_Len {mx}")
    cfg = b"".join(m.cfg for m in mods)
    n_in, n_out = sum(m.inputs for m in mods), sum(m.outputs for m in mods)
    for what, n, key, mx in (("input", n_in, "Max_Input_Len", gsd.max_input_len),
                             ("output", n_out, "Max_Output_Len", gsd.max_output_len),
                             ("input+output", n_in + n_out, "Max_Data_Len", gsd.max_data_len)):
        if mx is not None and n > mx:
            warnings.append(f"{n} {what} octets, more than the GSD's {key} {mx}")
    return PrmResult(gsd=gsd, modules=mods, user_prm=bytes(out), cfg=cfg, fields=fields, blocks=blocks,
                     warnings=warnings)


def chk_cfg(gsd: Gsd, modules: Iterable[int | str | Module] | None = None) -> bytes:
    """The Chk_Cfg octets for a module selection: the modules' identifier octets, verbatim."""
    return b"".join(m.cfg for m in select_modules(gsd, modules))


def module_prm_template(gsd: Gsd, module: Module) -> tuple[bytes, bytes] | None:
    """A module's own Set_Prm block (its parameters and F-parameters) with the GSD's defaults, and a mask
    of the bits no parameter may change (0xFF: a constant octet); None when the GSD's block is broken."""
    try:
        res = _build(gsd, [module], None)
    except UsageError:
        return None
    mine = [b for b in res.blocks if b.index == 1]
    if not mine:
        return b"", b""
    start = mine[0].start
    data = res.user_prm[start:]
    mask = bytearray(b"\xff" * len(data))
    for f in res.fields:
        if f.block_index != 1:
            continue
        off = f.offset - start
        if f.bits is None:
            mask[off:off + f.size] = bytes(f.size)
        else:
            lo, hi = f.bits
            mask[off] &= ~(((1 << (hi - lo + 1)) - 1) << lo) & 0xFF
    return bytes(data), bytes(mask)


def decode_user_prm(gsd: Gsd, modules: Iterable[int | str | Module] | None,
                    user_prm: bytes) -> tuple[list[dict[str, Any]], list[str]]:
    """A slave's Set_Prm user data (the octets from Set_Prm octet 7 on) read back with the GSD: one row
    per parameter (ExtUserPrmData name, the value in the octets, its Prm_Text, the GSD's default) in the
    layout build_prm writes for `modules`; and warnings (a length other than the GSD's)."""
    mods = list(modules or [])
    res = _build(gsd, [select_module(gsd, m) if not isinstance(m, Module) else m for m in mods], None)
    data = bytes(user_prm)
    warnings = list(res.warnings)
    if len(data) != len(res.user_prm):
        warnings.append(f"the user data has {len(data)} octets, the GSD's layout for these modules "
                        f"{len(res.user_prm)}")
    rows: list[dict[str, Any]] = []
    for f in res.fields:
        if f.offset + f.size > len(data) or f.param is None:
            continue
        d = f.param
        if f.bits is not None:
            lo, hi = f.bits
            v = (data[f.offset] >> lo) & ((1 << (hi - lo + 1)) - 1)
        else:
            v = int.from_bytes(data[f.offset:f.offset + f.size], "big",
                               signed=d.data_type.startswith("Signed"))
        rows.append({"offset": f.offset, "set_prm_octet": 7 + f.offset,
                     "octets": data[f.offset:f.offset + f.size].hex(" "), "bits": f.bits_label,
                     "name": f.name, "value": v, "text": d.text_for(v), "default": f.value,
                     "block": f.block, "allowed": d.is_allowed(v)})
    return rows, warnings


def _normalise_overrides(ov: Mapping[str, int | str] | Sequence[str] | None) -> list[tuple[str, Any]]:
    if not ov:
        return []
    if isinstance(ov, Mapping):
        return list(ov.items())
    out = []
    for item in ov:
        if not isinstance(item, str) or "=" not in item:
            raise UsageError(f"--set {item!r}: expected NAME=VALUE")
        name, _, value = item.rpartition("=")
        if not name.strip():
            raise UsageError(f"--set {item!r}: parameter name missing")
        out.append((name, value))
    return out


def _split_qualifier(key: str) -> tuple[int | None, str]:
    m = re.match(r"\s*(\d+)\s*:(.*)\Z", key, re.S)
    if m:
        return int(m.group(1)), m.group(2)
    return None, key


def user_params(gsd: Gsd, modules: Iterable[Module] | None = None) -> list[dict[str, Any]]:
    """The user parameters of the device block (and of `modules`) with offsets, defaults, allowed values."""
    out = []
    blocks: list[tuple[str, PrmBlock]] = [("device", gsd.prm)]
    for m in modules or []:
        blocks.append((f"module {m.index} {m.display_name!r}", m.prm))
        if not m.f_prm.empty:
            blocks.append((f"module {m.index} {m.display_name!r} F-parameters", m.f_prm))
    for label, block in blocks:
        for r in block.refs:
            d = gsd.ext_user_prm_data.get(r.ref)
            if d is None:
                continue
            out.append({"block": label, "offset": r.offset, "ref": d.ref, "name": d.name.strip(),
                        "type": d.describe_type(), "default": d.default,
                        "default_text": d.text_for(d.default), "allowed": d.describe_allowed(),
                        "texts": {str(k): v for k, v in (d.texts or {}).items()},
                        "changeable": d.changeable, "visible": d.visible})
    return out


# ---------------------------------------------------------------- unit diagnosis
def _bit(body: bytes, n: int) -> int | None:
    o = n // 8
    if o >= len(body):
        return None
    return (body[o] >> (n % 8)) & 1


def _area_value(body: bytes, a: DiagArea) -> int | None:
    v = 0
    for i, n in enumerate(range(a.first_bit, a.last_bit + 1)):
        b = _bit(body, n)
        if b is None:
            return None
        v |= b << i
    return v


def _decode_body(body: bytes, bits: Mapping[int, str], not_bits: Mapping[int, str],
                 areas: Sequence[DiagArea]) -> list[str]:
    out = []
    for n in sorted(bits):
        if _bit(body, n) == 1:
            out.append(f"{bits[n]} (unit diag bit {n})")
    for n in sorted(not_bits):
        if _bit(body, n) == 0:
            out.append(f"{not_bits[n]} (unit diag bit {n} = 0)")
    for a in areas:
        v = _area_value(body, a)
        if v is None:
            continue
        if v in a.values:
            out.append(f"{a.values[v]} (unit diag bits {a.first_bit}-{a.last_bit} = {v})")
        elif v:
            out.append(f"unit diag bits {a.first_bit}-{a.last_bit} = {v} (no text in the GSD)")
    return out


def device_diag_blocks(ext_diag: bytes) -> list[bytes]:
    """Bodies (octets after the header) of the device-related blocks in the extended diagnosis."""
    data = bytes(ext_diag)
    out, i = [], 0
    while i < len(data):
        h = data[i]
        kind = h >> 6
        if kind == 0:                       # device-related: length incl. header
            n = h & 0x3F
            if n == 0:
                break
            out.append(data[i + 1:i + n])
            i += n
        elif kind == 1:                     # identifier-related
            n = h & 0x3F
            if n == 0:
                break
            i += n
        elif kind == 2:                     # channel-related: always 3 octets
            i += 3
        else:                               # reserved: stop
            break
    return out


def decode_unit_diag(gsd: Gsd, ext_diag_bytes: bytes) -> list[str]:
    """Texts for the device-related (unit) diagnosis, from the Slave_Diag octets after the 6 standard ones.

    One string per set Unit_Diag_Bit, per clear Unit_Diag_Not_Bit and per Unit_Diag_Area value with a text
    (or a non-zero value without one). Bit numbers count from the first octet after the block header.
    UnitDiagType = n texts apply to blocks whose first octet after the header is n.
    """
    out: list[str] = []
    for body in device_diag_blocks(ext_diag_bytes):
        out += _decode_body(body, gsd.unit_diag_bits, gsd.unit_diag_not_bits, gsd.unit_diag_areas)
        if body and body[0] in gsd.unit_diag_types:
            dt = gsd.unit_diag_types[body[0]]
            out += _decode_body(body, dt.bits, dt.not_bits, dt.areas)
    return out
