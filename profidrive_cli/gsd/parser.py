"""GSD parser for files as found in the wild (reference §5).

Two small stages, plain Python; this module builds the model (gsd/model.py) and may touch gsd/lexer.py,
gsd/required.py, dp/cfg.py and datafile.py:

1. lines (gsd/lexer.py): decode (UTF-8 if the bytes are valid UTF-8, else Latin-1), split on
   CRLF / CR / LF (mixed is fine), skip everything before the `#Profibus_DP` line, cut `;` comments
   (not inside strings) and join `\\` continuations (also inside number lists and strings) into
   logical lines that remember the physical line they started on.
2. statements: each logical line is `Keyword[(args)] [=] value`, keywords compared case-insensitively.
   A small stack of open blocks (PrmText, ExtUserPrmData, Module, Data_Area, Unit_Diag_Area,
   UnitDiagType, SlotDefinition, ...) decides what a keyword means.

Errors raise `DataFileError(path, line, message)` (a UsageError: one line, no traceback): missing
`#Profibus_DP`, unterminated string or block, bad number, malformed Bit/BitArea, undecodable cfg bytes.
Unknown keywords are kept (`Gsd.values`, `Gsd.unknown`) and reported in `Gsd.warnings` as
"file:line: ..."; so are soft problems (undefined Prm_Text_Ref, default outside its range, ...).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from profidrive_cli.datafile import DataFileError, read_input_file
from profidrive_cli.dp.cfg import CfgError, decode_cfg
from profidrive_cli.gsd.lexer import HEAD, MAX_GSD_BYTES, MAX_NUMBER_CHARS, NUM, SPLIT, Toks, decode, logical_lines
from profidrive_cli.gsd.required import check_complete
from profidrive_cli.gsd.model import (
    BAUDS, INT_TYPES, MAX_USER_PRM_LEN, DiagArea, ExtUserPrmData, Gsd, Module, PrmBlock, PrmConst, PrmRef,
    PrmText, Slot, UnitDiagType,
)


_BAUD_SUFFIXES = tuple(s.lower() for s, _, _ in BAUDS)
_BAUD_KEY = re.compile(r"(maxtsdr|maxtsd|tsdi|trdy|tqui|tset|transmission_delay|reaction_delay)_("
                       + "|".join(re.escape(s) for s in _BAUD_SUFFIXES) + r")\Z")

_STR_KEYS = frozenset("""
vendor_name model_name revision hardware_release software_release implementation_type bitmap_device
bitmap_diag bitmap_sf info_text ordernumber family_name version_name webpage
""".split())

_INT_KEYS = frozenset("""
gsd_revision revision_number ident_number protocol_ident station_type fms_supp redundancy
repeater_ctrl_sig 24v_pins freeze_mode_supp sync_mode_supp auto_baud_supp set_slave_add_supp
user_prm_data_len min_slave_intervall modular_station max_module max_input_len max_output_len max_data_len
modul_offset fail_safe max_diag_data_len max_user_prm_data_len diag_update_delay fail_safe_required
physical_interface
dpv1_slave c1_read_write_supp c2_read_write_supp c1_max_data_len c2_max_data_len c1_response_timeout
c2_response_timeout c1_read_write_required c2_read_write_required c2_max_count_channels
max_initiate_pdu_length diagnostic_alarm_supp process_alarm_supp pull_plug_alarm_supp status_alarm_supp
update_alarm_supp manufacturer_specific_alarm_supp extra_alarm_sap_supp alarm_sequence_mode_count
alarm_type_mode_supp diagnostic_alarm_required process_alarm_required pull_plug_alarm_required
status_alarm_required update_alarm_required manufacturer_specific_alarm_required dpv1_data_types
wd_base_1ms_supp wb_base_1ms_supp check_cfg_mode
publisher_supp subscriber_supp dxb_max_link_count dxb_max_data_length dxb_subscribertable_block_location
x_prm_sap_supp x_max_user_prm_data_len x_prm_block_structure_supp prm_block_structure_supp
prm_block_structure_req prm_structure_supp prm_structure_req
isochron_mode_supp isochron_mode_required tbase_dp tdp_max tdp_min tbase_io ti_min to_min t_pll_w_max
time_sync_supp ident_maintenance_supp firmware_download_supp ds248_fct fixpresetmodules
slave_redundancy_supp slave_max_switch_over_time max_iso_channels
max_slaves_supp max_master_input_len max_master_output_len max_master_data_len max_mps_length max_lsdu_ms
min_poll_timeout las_len master_freeze_mode_supp master_sync_mode_supp master_fail_safe_supp download_supp
upload_supp act_para_brct_supp act_param_supp dpv1_master dpv1_conformance_class c1_master_read_write_supp
master_dpv1_alarm_supp isochron_mode_synchronised dxb_master_supp x_master_prm_sap_supp
""".split())

# keywords that open a block, with the keyword that closes it
_BLOCKS = {
    "prmtext": "endprmtext",
    "extuserprmdata": "endextuserprmdata",
    "module": "endmodule",
    "unit_diag_area": "unit_diag_area_end",
    "x_unit_diag_area": "x_unit_diag_area_end",
    "unitdiagtype": "endunitdiagtype",
    "unit_diag_type": "endunitdiagtype",
    "slotdefinition": "endslotdefinition",
    "data_area_beg": "data_area_end",
    "version_firmware_download": "end_version_firmware_download",
}
_BLOCK_NAMES = {
    "prmtext": "PrmText", "extuserprmdata": "ExtUserPrmData", "module": "Module",
    "unit_diag_area": "Unit_Diag_Area", "x_unit_diag_area": "X_Unit_Diag_Area",
    "unitdiagtype": "UnitDiagType", "unit_diag_type": "UnitDiagType", "slotdefinition": "SlotDefinition",
    "data_area_beg": "Data_Area_Beg", "version_firmware_download": "Version_Firmware_Download",
}
_END_NAMES = {
    "endprmtext": "EndPrmText", "endextuserprmdata": "EndExtUserPrmData", "endmodule": "EndModule",
    "unit_diag_area_end": "Unit_Diag_Area_End", "x_unit_diag_area_end": "X_Unit_Diag_Area_End",
    "endunitdiagtype": "EndUnitDiagType", "endslotdefinition": "EndSlotDefinition",
    "data_area_end": "Data_Area_End", "end_version_firmware_download": "End_Version_Firmware_Download",
}
_ENDS = frozenset(_END_NAMES)

_TYPE_NAMES = {t.lower(): t for t in list(INT_TYPES) + ["Bit", "BitArea"]}

# module-level keywords that are kept without a warning
_MODULE_KNOWN = frozenset("""
preset f_paramdesccrc f_io_structuredesccrc f_io_structuredescversion f_ext_module_prm_data_len
x_ext_module_prm_data_len ext_module_prm_data_len module_reference info_text channel_diag channel_diag_help
slot_number alarm_supp
""".split())


class _Parser:
    def __init__(self, path: str):
        self.path = path
        self.gsd = Gsd(path=path)
        self.stack: list[tuple[str, Any, int]] = []   # (block keyword, object, line)
        self.module_index = 0

    # ------------------------------------------------------------------ helpers
    def warn(self, line: int, msg: str) -> None:
        self.gsd.warnings.append(f"{self.path}:{line}: {msg}")

    def err(self, line: int, msg: str) -> DataFileError:
        return DataFileError(self.path, line, msg)

    def toks(self, text: str, line: int, what: str) -> Toks:
        return Toks(text, self.path, line, what)

    def args_int(self, args: str | None, line: int, kw: str, signed: bool = False) -> int:
        if args is None:
            raise self.err(line, f"{kw}: (number) missing")
        t = self.toks(args, line, kw)
        v = t.int("number in ( )", signed=signed)
        t.end()
        return v

    # ------------------------------------------------------------------ entry
    def parse(self, text: str) -> Gsd:
        lines = SPLIT.split(text)
        start = None
        for i, raw in enumerate(lines):
            if raw.lstrip()[:12].lower() == "#profibus_dp":
                start = i
                break
        if start is None:
            raise self.err(1, "not a GSD file: no '#Profibus_DP' line")
        self.gsd.start_line = start + 1
        for line, text_ in logical_lines(self.path, lines, start + 1):
            if not text_ or text_.isspace():
                continue
            m = HEAD.match(text_)
            if m is None:
                self.gsd.unknown.append((text_.strip(), line))
                self.warn(line, f"line not understood: {text_.strip()[:40]!r} (ignored)")
                continue
            kw_raw, args, eq, rest = m.groups()
            self.statement(line, kw_raw, kw_raw.lower(), args, eq, rest)
        if self.stack:
            kind, obj, line = self.stack[-1]
            name = f" {obj.name.strip()!r}" if isinstance(obj, Module) else ""
            raise self.err(line, f"{_BLOCK_NAMES[kind]}{name} not terminated: "
                                 f"{_END_NAMES[_BLOCKS[kind]]} missing before the end of the file")
        self.finish()
        self.gsd.end_line = len(lines)
        return self.gsd

    # ------------------------------------------------------------------ dispatch
    def statement(self, line: int, kw_raw: str, kw: str, args: str | None, eq: str | None, rest: str) -> None:
        if kw.startswith("maxtsd_"):
            kw = "maxtsdr_" + kw[7:]
        if kw == "#profibus_dp":
            return
        if self.stack:
            kind = self.stack[-1][0]
            if kw in _ENDS:
                if _BLOCKS[kind] == kw or (kind in ("unit_diag_area", "x_unit_diag_area")
                                           and kw in ("unit_diag_area_end", "x_unit_diag_area_end")):
                    _, obj, _ = self.stack.pop()
                    if kind == "module":
                        obj.end_line = line
                    return
                raise self.unterminated(line, kw_raw)
            if kw in _BLOCKS and not (kind == "unitdiagtype" or kind == "unit_diag_type") \
                    and not (kind == "module" and kw == "data_area_beg"):
                raise self.unterminated(line, kw_raw)
            handler = getattr(self, "in_" + ("unitdiagtype" if kind == "unit_diag_type" else
                                            "unit_diag_area" if kind == "x_unit_diag_area" else kind))
            handler(line, kw_raw, kw, args, eq, rest)
            return
        if kw in _ENDS:
            raise self.err(line, f"{kw_raw} without a matching "
                                 f"{_BLOCK_NAMES[next(k for k, v in _BLOCKS.items() if v == kw)]}")
        self.top(line, kw_raw, kw, args, eq, rest)

    def unterminated(self, line: int, kw_raw: str) -> DataFileError:
        kind, obj, start = self.stack[-1]
        name = f" {obj.name.strip()!r}" if isinstance(obj, Module) else ""
        return self.err(start, f"{_BLOCK_NAMES[kind]}{name} not terminated: "
                               f"{_END_NAMES[_BLOCKS[kind]]} missing before {kw_raw} at line {line}")

    def store(self, line: int, kw: str, value: Any) -> None:
        g = self.gsd
        if kw in g.values and kw not in ("info_text",):
            self.warn(line, f"{kw} given again (first at line {g.value_lines[kw]}); the last one counts")
        g.values[kw] = value
        g.value_lines[kw] = line

    def unknown(self, line: int, kw_raw: str, args: str | None, rest: str, where: str = "") -> str:
        self.gsd.unknown.append((kw_raw, line))
        self.warn(line, f"unknown keyword {kw_raw!r}{where} (kept, not interpreted)")
        return rest.strip() if args is None else f"({args}) {rest.strip()}".strip()

    # ------------------------------------------------------------------ top level
    def top(self, line: int, kw_raw: str, kw: str, args: str | None, eq: str | None,
            rest: str) -> None:
        g = self.gsd
        if kw in _INT_KEYS or _BAUD_KEY.match(kw) or (kw.endswith("_supp") and kw[:-5] in _BAUD_SUFFIXES):
            t = self.toks(rest, line, kw_raw)
            v = t.int()
            t.end()
            self.store(line, kw, v)
        elif kw in _STR_KEYS:
            t = self.toks(rest, line, kw_raw)
            if t.peek() == "s":
                text = t.string()
                t.end()
            else:
                text = rest.strip()
                self.warn(line, f"{kw_raw}: value is not in quotes")
            self.store(line, kw, text)
        elif kw == "slave_family":
            self.store(line, kw, rest.strip())
        elif kw == "user_prm_data":
            t = self.toks(rest, line, kw_raw)
            data = bytes(t.int_list("octet", 0, 255))
            self.store(line, kw, data)
            g.prm.base, g.prm.base_line = data, line
        elif kw in ("ext_user_prm_data_const", "ext_user_prm_data_ref"):
            self.prm_statement(g.prm, line, kw_raw, kw, args, rest)
        elif kw == "prmtext":
            t = self.toks(rest, line, kw_raw)
            ref = t.int("reference number")
            t.end()
            if ref in g.prm_texts:
                self.warn(line, f"PrmText {ref} defined again (first at line {g.prm_texts[ref].line})")
            pt = PrmText(ref=ref, line=line)
            g.prm_texts[ref] = pt
            self.stack.append((kw, pt, line))
        elif kw == "extuserprmdata":
            t = self.toks(rest, line, kw_raw)
            ref = t.int("reference number")
            name = t.string("name") if not t.at_end() else ""
            t.end()
            if ref in g.ext_user_prm_data:
                self.warn(line, f"ExtUserPrmData {ref} defined again "
                                f"(first at line {g.ext_user_prm_data[ref].line})")
            d = ExtUserPrmData(ref=ref, name=name, line=line)
            g.ext_user_prm_data[ref] = d
            self.stack.append((kw, d, line))
        elif kw == "module":
            t = self.toks(rest, line, kw_raw)
            name = t.string("module name")
            cfg = bytes(t.int_list("configuration octet", 0, 255))
            if not cfg:
                raise self.err(line, f"Module {name.strip()!r}: no configuration (identifier) octets")
            try:
                decode_cfg(cfg)
            except CfgError as e:
                raise self.err(line, f"Module {name.strip()!r}: bad configuration octets: {e}") from None
            self.module_index += 1
            mod = Module(name=name, cfg=cfg, line=line, index=self.module_index)
            g.modules.append(mod)
            self.stack.append((kw, mod, line))
        elif kw in ("unit_diag_bit", "unit_diag_not_bit", "channel_diag"):
            n = self.args_int(args, line, kw_raw)
            t = self.toks(rest, line, kw_raw)
            text = t.string("text")
            t.end()
            target = {"unit_diag_bit": g.unit_diag_bits, "unit_diag_not_bit": g.unit_diag_not_bits,
                      "channel_diag": g.channel_diag}[kw]
            target[n] = text
        elif kw in ("unit_diag_bit_help", "unit_diag_not_bit_help", "channel_diag_help"):
            self.args_int(args, line, kw_raw)
            g.values.setdefault(kw, {})
        elif kw in ("unit_diag_area", "x_unit_diag_area"):
            area = self.diag_area(line, kw_raw, rest)
            g.unit_diag_areas.append(area)
            self.stack.append((kw, area, line))
        elif kw in ("unitdiagtype", "unit_diag_type"):
            t = self.toks(rest, line, kw_raw)
            v = t.int("type value")
            t.end()
            dt = UnitDiagType(type_value=v, line=line)
            g.unit_diag_types[v] = dt
            self.stack.append((kw, dt, line))
        elif kw == "slotdefinition":
            self.stack.append((kw, None, line))
        elif kw == "version_firmware_download":
            block: dict[str, Any] = {}
            g.values.setdefault(kw, []).append(block)
            self.stack.append((kw, block, line))
        else:
            if NUM.match(kw):
                self.gsd.unknown.append((kw_raw, line))
                self.warn(line, f"stray number {kw_raw!r} outside a Module (ignored)")
                return
            g.values[kw] = self.unknown(line, kw_raw, args, rest)
            g.value_lines[kw] = line

    def diag_area(self, line: int, kw_raw: str, rest: str) -> DiagArea:
        t = self.toks(rest, line, kw_raw)
        a = t.int("first bit")
        if not t.skip("-"):
            raise t.error("expected first-last bit range")
        b = t.int("last bit")
        t.end()
        if b < a:
            raise self.err(line, f"{kw_raw}: last bit {b} before first bit {a}")
        if b - a >= 32:
            raise self.err(line, f"{kw_raw}: {a}-{b} is wider than 32 bits")
        return DiagArea(first_bit=a, last_bit=b, line=line)

    def prm_statement(self, block: PrmBlock, line: int, kw_raw: str, kw: str, args: str | None,
                      rest: str) -> None:
        off = self.args_int(args, line, kw_raw)
        if off >= MAX_USER_PRM_LEN:
            raise self.err(line, f"{kw_raw}({off}): offset beyond the {MAX_USER_PRM_LEN} octets "
                                 "Set_Prm can carry")
        t = self.toks(rest, line, kw_raw)
        if kw.endswith("const"):
            data = bytes(t.int_list("octet", 0, 255))
            if not data:
                raise self.err(line, f"{kw_raw}({off}): no octets")
            if off + len(data) > MAX_USER_PRM_LEN:
                raise self.err(line, f"{kw_raw}({off}): {len(data)} octets run beyond the "
                                     f"{MAX_USER_PRM_LEN} octets Set_Prm can carry")
            block.consts.append(PrmConst(offset=off, data=data, line=line))
        else:
            ref = t.int("ExtUserPrmData reference")
            t.end()
            block.refs.append(PrmRef(offset=off, ref=ref, line=line))

    # ------------------------------------------------------------------ blocks
    def in_prmtext(self, line: int, kw_raw: str, kw: str, args: str | None, eq: str | None,
                   rest: str) -> None:
        pt: PrmText = self.stack[-1][1]
        if kw == "text":
            v = self.args_int(args, line, kw_raw, signed=True)
            t = self.toks(rest, line, kw_raw)
            pt.texts[v] = t.string("text")
            t.end()
        else:
            self.unknown(line, kw_raw, args, rest, " inside PrmText")

    def in_extuserprmdata(self, line: int, kw_raw: str, kw: str, args: str | None, eq: str | None,
                          rest: str) -> None:
        d: ExtUserPrmData = self.stack[-1][1]
        if kw in _TYPE_NAMES:
            if d.data_type:
                self.warn(line, f"ExtUserPrmData {d.ref}: second type line (first at line {d.type_line})")
            d.data_type = _TYPE_NAMES[kw]
            d.type_line = line
            if d.is_bits:
                if args is None:
                    raise self.err(line, f"{kw_raw}: bit number(s) in ( ) missing")
                ta = self.toks(args, line, kw_raw)
                lo = ta.int("bit number")
                hi = lo
                if d.data_type == "BitArea":
                    if not ta.skip("-"):
                        raise ta.error("expected BitArea(first-last)")
                    hi = ta.int("last bit number")
                ta.end()
                if not (0 <= lo <= 7 and 0 <= hi <= 7) or hi < lo:
                    raise self.err(line, f"{kw_raw}({args.strip()}): bits must be 0..7, first <= last")
                d.bit_lo, d.bit_hi = lo, hi
            elif args is not None:
                raise self.err(line, f"{kw_raw}: unexpected ( ) after the type")
            t = self.toks(rest, line, kw_raw)
            d.default = t.int("default value", signed=True)
            if not t.at_end():
                first = t.int("allowed value", signed=True)
                if t.skip("-"):
                    d.min_value, d.max_value = first, t.int("maximum", signed=True)
                    t.end()
                    if d.max_value < d.min_value:
                        raise self.err(line, f"{kw_raw}: range {d.min_value}-{d.max_value} is empty")
                else:
                    vals = [first]
                    if t.skip(","):
                        vals += t.int_list("allowed value", signed=True)
                    t.end()
                    d.allowed = tuple(vals)
        elif kw == "prm_text_ref":
            t = self.toks(rest, line, kw_raw)
            d.text_ref = t.int("PrmText reference")
            t.end()
        elif kw in ("changeable", "visible"):
            t = self.toks(rest, line, kw_raw)
            v = t.int("0 or 1")
            t.end()
            setattr(d, kw, bool(v))
        elif kw in ("octetstring", "visiblestring", "float32", "float64", "date", "time_of_day",
                    "time_difference", "prm_data_value"):
            self.warn(line, f"ExtUserPrmData {d.ref}: {kw_raw} is not supported (kept, not interpreted)")
            d.data_type = d.data_type or kw_raw
        else:
            self.unknown(line, kw_raw, args, rest, " inside ExtUserPrmData")

    def in_module(self, line: int, kw_raw: str, kw: str, args: str | None, eq: str | None,
                  rest: str) -> None:
        mod: Module = self.stack[-1][1]
        if kw.isascii() and kw.isdigit() and args is None and not rest.strip():
            if len(kw) > MAX_NUMBER_CHARS:
                raise self.err(line, f"Module {mod.display_name!r}: reference number too long "
                                     f"({len(kw)} digits)")
            if mod.reference is not None:
                self.warn(line, f"Module {mod.display_name!r}: second reference number {kw}")
            mod.reference = int(kw)
            return
        if kw == "module_reference":
            t = self.toks(rest, line, kw_raw)
            mod.reference = t.int()
            t.end()
        elif kw in ("ext_module_prm_data_len", "f_ext_module_prm_data_len", "x_ext_module_prm_data_len"):
            t = self.toks(rest, line, kw_raw)
            block = {"e": mod.prm, "f": mod.f_prm, "x": mod.x_prm}[kw[0]]
            block.length = t.int("length")
            block.length_line = line
            t.end()
        elif kw in ("ext_user_prm_data_const", "ext_user_prm_data_ref"):
            self.prm_statement(mod.prm, line, kw_raw, kw, args, rest)
        elif kw in ("f_ext_user_prm_data_const", "f_ext_user_prm_data_ref"):
            self.prm_statement(mod.f_prm, line, kw_raw, kw[2:], args, rest)
        elif kw in ("x_ext_user_prm_data_const", "x_ext_user_prm_data_ref"):
            self.prm_statement(mod.x_prm, line, kw_raw, kw[2:], args, rest)
        elif kw == "info_text":
            t = self.toks(rest, line, kw_raw)
            mod.info_text = t.string() if t.peek() == "s" else rest.strip()
        elif kw == "channel_diag":
            n = self.args_int(args, line, kw_raw)
            t = self.toks(rest, line, kw_raw)
            mod.channel_diag[n] = t.string("text")
            t.end()
        elif kw == "data_area_beg":
            area: dict[str, Any] = {"line": line}
            mod.data_areas.append(area)
            self.stack.append((kw, area, line))
        else:
            key = kw if args is None else f"{kw}({args.strip()})"
            if kw in _MODULE_KNOWN or kw.startswith(("f_", "x_")):
                mod.extra[key] = rest.strip()
            else:
                mod.extra[key] = self.unknown(line, kw_raw, args, rest, f" in Module {mod.display_name!r}")

    def in_data_area_beg(self, line: int, kw_raw: str, kw: str, args: str | None, eq: str | None,
                         rest: str) -> None:
        area: dict[str, Any] = self.stack[-1][1]
        area[kw] = rest.strip()

    def in_version_firmware_download(self, line: int, kw_raw: str, kw: str, args: str | None, eq: str | None,
                                     rest: str) -> None:
        block: dict[str, Any] = self.stack[-1][1]
        block[kw if args is None else f"{kw}({args.strip()})"] = rest.strip()

    def in_unit_diag_area(self, line: int, kw_raw: str, kw: str, args: str | None, eq: str | None,
                          rest: str) -> None:
        area: DiagArea = self.stack[-1][1]
        if kw in ("value", "x_value"):
            v = self.args_int(args, line, kw_raw)
            t = self.toks(rest, line, kw_raw)
            area.values[v] = t.string("text")
            t.end()
        elif kw.endswith("_help"):
            return
        else:
            self.unknown(line, kw_raw, args, rest, " inside Unit_Diag_Area")

    def in_unitdiagtype(self, line: int, kw_raw: str, kw: str, args: str | None, eq: str | None,
                        rest: str) -> None:
        dt: UnitDiagType = self.stack[-1][1]
        base = kw[2:] if kw.startswith("x_") else kw
        if base in ("unit_diag_bit", "unit_diag_not_bit"):
            n = self.args_int(args, line, kw_raw)
            t = self.toks(rest, line, kw_raw)
            (dt.bits if base == "unit_diag_bit" else dt.not_bits)[n] = t.string("text")
            t.end()
        elif base.endswith("_help"):
            return
        elif base == "unit_diag_area":
            area = self.diag_area(line, kw_raw, rest)
            dt.areas.append(area)
            self.stack.append((kw, area, line))
        elif kw in _BLOCKS:
            raise self.unterminated(line, kw_raw)
        else:
            self.unknown(line, kw_raw, args, rest, " inside UnitDiagType")

    def in_slotdefinition(self, line: int, kw_raw: str, kw: str, args: str | None, eq: str | None,
                          rest: str) -> None:
        if kw != "slot":
            self.unknown(line, kw_raw, args, rest, " inside SlotDefinition")
            return
        n = self.args_int(args, line, kw_raw)
        t = self.toks(rest, line, kw_raw)
        name = t.string("slot name")
        default = t.int("default module reference") if not t.at_end() else None
        allowed: list[int] = []
        if not t.at_end():
            first = t.int("allowed module reference")
            if t.skip("-"):
                last = t.int("last module reference")
                if last < first or last - first > 1000:
                    raise t.error(f"bad range {first}-{last}")
                allowed = list(range(first, last + 1))
            else:
                allowed = [first]
                if t.skip(","):
                    allowed += t.int_list("allowed module reference")
        t.end()
        self.gsd.slots.append(Slot(number=n, name=name, default=default, allowed=tuple(allowed), line=line))

    # ------------------------------------------------------------------ checks after the last line
    def finish(self) -> None:
        g = self.gsd
        if isinstance(g.values.get("user_prm_data_len"), int):
            g.prm.length = g.values["user_prm_data_len"]
            g.prm.length_line = g.value_lines["user_prm_data_len"]
        for d in g.ext_user_prm_data.values():
            if not d.data_type:
                self.warn(d.line, f"ExtUserPrmData {d.ref} {d.name!r}: no type line (Bit/BitArea/UnsignedN)")
                continue
            if d.text_ref is not None:
                pt = g.prm_texts.get(d.text_ref)
                if pt is None:
                    self.warn(d.line, f"ExtUserPrmData {d.ref} {d.name!r}: Prm_Text_Ref {d.text_ref} "
                                      "is not defined")
                else:
                    d.texts = pt.texts
            if (d.is_bits or d.data_type in INT_TYPES) and not d.is_allowed(d.default):
                self.warn(d.type_line, f"ExtUserPrmData {d.ref} {d.name!r}: default {d.default} is outside "
                                       f"{d.describe_allowed()}")
        blocks = [("device", g.prm)] + [(f"Module {m.display_name!r}", b) for m in g.modules
                                        for b in (m.prm, m.f_prm)]
        for label, block in blocks:
            for r in block.refs:
                if r.ref not in g.ext_user_prm_data:
                    self.warn(r.line, f"{label}: Ext_User_Prm_Data_Ref({r.offset}) = {r.ref}: "
                                      "no ExtUserPrmData with that number")


def parse_gsd_text(text: str, path: str | Path = "<string>", encoding: str = "ascii") -> Gsd:
    """Parse GSD text (already decoded). Raises DataFileError(path, line, ...)."""
    p = _Parser(str(path))
    p.gsd.encoding = encoding
    return p.parse(text)


def parse_gsd_bytes(data: bytes, path: str | Path = "<bytes>") -> Gsd:
    text, enc = decode(data)
    return parse_gsd_text(text, path, enc)


def parse_gsd(path: str | Path) -> Gsd:
    """Read and parse one GSD file (Latin-1 or UTF-8; a regular file of at most MAX_GSD_BYTES) and check
    that it has what a DP slave's GSD must have (gsd.required). Raises DataFileError(path, line, ...)."""
    p = Path(path)
    g = parse_gsd_bytes(read_input_file(p, "GSD file", MAX_GSD_BYTES), p)
    check_complete(g, g.end_line)
    return g
