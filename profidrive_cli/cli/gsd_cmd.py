"""`pdrive gsd ...`: show a GSD, list the library, build Set_Prm / Chk_Cfg octets, match a configuration
(`gsd match`: gsd/match.py; on the bus it reads Slave_Diag and Get_Cfg as `diag` does). Rendering only; the
work is in profidrive_cli.gsd."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

import click
from rich.console import Console
from rich.table import Table
from rich.text import Text

from profidrive_cli import UsageError
from profidrive_cli.cli.common import BusOptions, bus_options, emit_json, hex_option, make_console, out, station_address
from profidrive_cli.cli.jsonout import ident_fields, octets
from profidrive_cli.gsd import build_prm, user_params
from profidrive_cli.gsd.interp import device_user_prm
from profidrive_cli.gsd.library import list_library, load_gsd, search_dirs
from profidrive_cli.gsd.model import Gsd

if TYPE_CHECKING:
    from profidrive_cli.dp.poller import Master
    from profidrive_cli.dp.services import SlaveDiag

_gsd_dir_option = click.option(
    "--gsd-dir", "gsd_dir", metavar="DIR", default=None,
    help="Folder with your own GSD files (searched before the library; also $PDRIVE_GSD_DIR).")
_json_option = click.option("--json", "as_json", is_flag=True, help="Print JSON instead of tables.")


def _console() -> Console:
    # markup off: GSD texts contain brackets ("[SlotNumber]") that rich would otherwise eat as tags;
    # not wrapped at 80 columns in a pipe (common.make_console)
    return make_console(markup=False)


def _echo_json(obj: Any) -> None:
    click.echo(json.dumps(obj, indent=2, ensure_ascii=False))


def _hex(b: bytes) -> str:
    return b.hex(" ").upper() if b else "-"


def _ident(v: int | None) -> str:
    return "-" if v is None else f"0x{v:04X}"


def _device_prm(g: Gsd) -> bytes:
    try:
        return device_user_prm(g)
    except UsageError:
        return b""


def _squeeze(items: list[str]) -> str:
    """'a; b; b; b' -> 'a; 3 x b' (modules built from many equal identifiers)."""
    out: list[tuple[int, str]] = []
    for it in items:
        if out and out[-1][1] == it:
            out[-1] = (out[-1][0] + 1, it)
        else:
            out.append((1, it))
    return "; ".join(it if n == 1 else f"{n} x {it}" for n, it in out)


def _octets(n: int) -> str:
    return f"{n} octet" if n == 1 else f"{n} octets"


def _yn(v: bool) -> str:
    return "yes" if v else "no"


def _identity(g: Gsd) -> dict[str, Any]:
    return {
        "file": g.path, "encoding": g.encoding, "vendor": g.vendor_name, "model": g.model_name,
        "revision": g.revision, **ident_fields(g.ident_number),
        "gsd_revision": g.gsd_revision, "protocol_ident": g.protocol_ident, "station_type": g.station_type,
        "slave_family": g.slave_family_text, "hardware_release": g.hardware_release,
        "software_release": g.software_release,
        "freeze_mode_supp": g.freeze_mode_supp, "sync_mode_supp": g.sync_mode_supp,
        "auto_baud_supp": g.auto_baud_supp, "set_slave_add_supp": g.set_slave_add_supp,
        "fail_safe": g.fail_safe, "dpv1_slave": g.dpv1_slave, "min_slave_intervall": g.min_slave_intervall,
        "modular_station": g.modular_station, "max_module": g.max_module, "max_input_len": g.max_input_len,
        "max_output_len": g.max_output_len, "max_data_len": g.max_data_len,
        "max_diag_data_len": g.max_diag_data_len, "user_prm_data_len": g.user_prm_data_len,
        "max_user_prm_data_len": g.max_user_prm_data_len,
    }


def _modules(g: Gsd) -> list[dict[str, Any]]:
    out = []
    for m in g.modules:
        prm_len = (m.prm.length or 0) if not m.prm.empty else 0
        out.append({"index": m.index, "name": m.display_name, "reference": m.reference,
                    "cfg": _hex(m.cfg), "inputs": m.inputs, "outputs": m.outputs,
                    "identifiers": [{"octets": _hex(c.raw), "description": c.describe()} for c in m.cfg_modules],
                    "prm_len": prm_len, "prm_refs": len(m.prm.refs) + len(m.f_prm.refs),
                    "line": m.line})
    return out


def _module_json(m: dict[str, Any]) -> dict[str, Any]:
    """A module row in the contract's shape: octets in lower-case hex ("" for none)."""
    return {**m, "cfg": octets(m["cfg"]),
            "identifiers": [{**c, "octets": octets(c["octets"])} for c in m["identifiers"]]}


def _prm_json(d: dict[str, Any]) -> dict[str, Any]:
    """build_prm's dict in the contract's shape: ident + ident_hex, octets in lower-case hex."""
    out: dict[str, Any] = {}
    for k, v in d.items():
        if k == "ident":
            out.update(ident_fields(v))
        elif k in ("user_prm", "chk_cfg"):
            out[k] = octets(v)
        elif k == "modules":
            out[k] = [{**m, "cfg": octets(m["cfg"])} for m in v]
        elif k in ("user_prm_fields", "chk_cfg_fields"):
            out[k] = [{**r, "octets": octets(r["octets"])} for r in v]
        else:
            out[k] = v
    return out


@click.group("gsd")
def gsd_group() -> None:
    """GSD device description files: show one, list the library, build Set_Prm / Chk_Cfg octets, match a
    slave's configuration to modules."""


@gsd_group.command("show")
@click.argument("source", metavar="FILE|IDENT")
@_gsd_dir_option
@click.option("--module-params", is_flag=True, help="Also list every module's own user parameters.")
@_json_option
def show_cmd(source: str, gsd_dir: str | None, module_params: bool, as_json: bool) -> None:
    """Identity, baud rates and MaxTsdr, modules with decoded cfg octets, user parameters.

    FILE|IDENT is a GSD file, an ident number (0x00CA) or a library file name (YASK00CA).
    """
    g = load_gsd(source, gsd_dir)
    params = user_params(g, g.modules if module_params or as_json else None)
    if as_json:
        _echo_json({
            "identity": _identity(g),
            "baud_rates": g.max_tsdr_table(),
            "modules": [_module_json(m) for m in _modules(g)],
            "user_params": params,
            "unit_diag_bits": {str(k): v for k, v in sorted(g.unit_diag_bits.items())},
            "unit_diag_areas": [{"bits": f"{a.first_bit}-{a.last_bit}", "values": len(a.values)}
                                for a in g.unit_diag_areas],
            "slots": [{"slot": s.number, "name": s.name, "default": s.default, "allowed": list(s.allowed)}
                      for s in g.slots],
            "unknown_keywords": [{"keyword": k, "line": n} for k, n in g.unknown],
            "warnings": g.warnings,
        })
        return
    con = _console()
    t = Table(title=g.title, show_header=False, title_justify="left")
    t.add_column("key", style="bold")
    t.add_column("value")
    station_types: dict[int | None, object] = {0: "0 (DP slave)", 1: "1 (DP master)"}
    rows = [
        ("File", g.path), ("Vendor", g.vendor_name), ("Model", g.model_name), ("Revision", g.revision),
        ("Ident", _ident(g.ident_number)), ("GSD revision", g.gsd_revision),
        ("Station type", station_types.get(g.station_type, g.station_type)),
        ("Slave family", g.slave_family_text), ("HW / SW release", f"{g.hardware_release} / {g.software_release}"),
        ("Freeze / Sync", f"{_yn(g.freeze_mode_supp)} / {_yn(g.sync_mode_supp)}"),
        ("Auto baud / Set_Slave_Add", f"{_yn(g.auto_baud_supp)} / {_yn(g.set_slave_add_supp)}"),
        ("Fail_Safe / DPV1", f"{_yn(g.fail_safe)} / {_yn(g.dpv1_slave)}"),
        ("Min_Slave_Intervall", g.min_slave_intervall),
        ("Modular / Max_Module", f"{_yn(g.modular_station)} / {g.max_module}"),
        ("Max input / output / data", f"{g.max_input_len} / {g.max_output_len} / {g.max_data_len}"),
        ("Max_Diag_Data_Len", g.max_diag_data_len),
        ("User_Prm_Data_Len / max", f"{g.user_prm_data_len} / {g.max_user_prm_data_len}"),
    ]
    for k, v in rows:
        t.add_row(k, "-" if v is None else str(v).replace("None", "-"))
    con.print(t)

    bt = Table(title="Baud rates", title_justify="left")
    for c in ("baud", "supported", "MaxTsdr (bit times)"):
        bt.add_column(c, justify="right" if c != "supported" else "left")
    for r in g.max_tsdr_table():
        if r["baud"] == "31.25" and not r["supported"]:
            continue
        bt.add_row(r["baud"], _yn(r["supported"]),
                   f"{r['max_tsdr']}" + (" (default)" if r["default"] else ""))
    con.print(bt)

    mt = Table(title=f"Modules ({len(g.modules)})", title_justify="left")
    for c in ("#", "name", "cfg octets", "decoded", "in", "out", "prm"):
        mt.add_column(c, justify="right" if c in ("#", "in", "out", "prm") else "left")
    for m in _modules(g):
        mt.add_row(str(m["index"]), m["name"], m["cfg"],
                   _squeeze([i["description"] for i in m["identifiers"]]), str(m["inputs"]), str(m["outputs"]),
                   str(m["prm_len"] or (m["prm_refs"] and "yes") or ""))
    con.print(mt)

    if params:
        pt = Table(title="User parameters", title_justify="left")
        for c in ("block", "offset", "type", "name", "default", "allowed"):
            pt.add_column(c, justify="right" if c == "offset" else "left")
        for p in params:
            default = str(p["default"]) + (f" ({p['default_text']})" if p["default_text"] else "")
            allowed = p["allowed"]
            if p["texts"]:
                allowed += "  " + ", ".join(f"{k}={v}" for k, v in list(p["texts"].items())[:8])
                if len(p["texts"]) > 8:
                    allowed += ", ..."
            if not p["changeable"]:
                allowed += "  (not changeable)"
            pt.add_row(p["block"], str(p["offset"]), p["type"], p["name"], default, allowed)
        con.print(pt)
    else:
        con.print("User parameters: none" if g.prm.empty else
                  f"Device User_Prm_Data (constant): {_hex(_device_prm(g))}")
    if g.unit_diag_bits or g.unit_diag_areas:
        con.print(f"Unit diagnosis texts: {len(g.unit_diag_bits)} bits, {len(g.unit_diag_areas)} areas")
    for w in g.warnings:
        con.print(Text.assemble(("warning: ", "yellow"), w))


@gsd_group.command("list")
@_gsd_dir_option
@_json_option
def list_cmd(gsd_dir: str | None, as_json: bool) -> None:
    """The GSD library plus your own folders (--gsd-dir, $PDRIVE_GSD_DIR); your files win."""
    entries = list_library(gsd_dir)
    if as_json:
        _echo_json([e.to_dict() for e in entries])
        return
    con = _console()
    t = Table(title="GSD files (your folders first: they win over the library)", title_justify="left")
    for c in ("ident", "vendor", "model", "mods", "source", "file"):
        t.add_column(c, justify="right" if c == "mods" else "left", no_wrap=c in ("ident", "file", "mods"))
    for e in entries:
        cell = Text(e.path.name)
        if e.error:
            cell.append(f"\nerror: {e.error}", style="red")
        elif e.shadowed_by:
            cell.append(f"\n(overridden by {e.shadowed_by.name})")
        t.add_row(_ident(e.ident), e.vendor or "-", e.model or "-", str(e.modules) if not e.error else "-",
                  e.source, cell)
    con.print(t)
    if not entries:
        con.print("no GSD files found")
    for folder, source in search_dirs(gsd_dir):
        con.print(f"{source}: {folder}")


@gsd_group.command("prm")
@click.argument("source", metavar="FILE|IDENT")
@click.option("--module", "-m", "modules", multiple=True, metavar="NAME",
              help="Module by name, number (as in `gsd show`) or PPO number (PPO3); repeat for more slots.")
@click.option("--set", "sets", multiple=True, metavar="NAME=VALUE",
              help="Override a user parameter (number or its text); N:NAME picks block N (0 = device).")
@_gsd_dir_option
@_json_option
def prm_cmd(source: str, modules: tuple[str, ...], sets: tuple[str, ...], gsd_dir: str | None,
            as_json: bool) -> None:
    """Set_Prm user-parameter octets and Chk_Cfg octets for a module selection, explained octet by octet."""
    g = load_gsd(source, gsd_dir)
    res = build_prm(g, list(modules), list(sets))
    if as_json:
        _echo_json(_prm_json(res.to_dict()))
        return
    con = _console()
    con.print(Text.assemble((g.title, "bold"), f"  ident {_ident(g.ident_number)}  ({g.path})"))
    con.print("modules: " + ", ".join(f"{m.index}: {m.display_name}" for m in res.modules))
    con.print(Text.assemble(("User_Prm_Data", "bold"),
                            f" ({_octets(len(res.user_prm))}): {_hex(res.user_prm)}"))
    con.print(Text.assemble(("Chk_Cfg", "bold"), f" ({_octets(len(res.cfg))}): {_hex(res.cfg)}   "
                            f"-> {sum(m.inputs for m in res.modules)} octets in, "
                            f"{sum(m.outputs for m in res.modules)} out"))
    rows = res.rows()
    if rows:
        t = Table(title="User_Prm_Data", title_justify="left")
        for c in ("offset", "Set_Prm", "octets", "bits", "parameter", "value", "block"):
            t.add_column(c, justify="right" if c in ("offset", "Set_Prm") else "left")
        for r in rows:
            if r["constant"]:
                value = f"0x{r['value']:02X}"
            else:
                value = str(r["value"]) + (f" ({r['text']})" if r["text"] else "")
                if r["overridden"]:
                    value += " [set]"
            t.add_row(str(r["offset"]), str(r["set_prm_octet"]), r["octets"], r["bits"], r["name"], value,
                      r["block"])
        con.print(t)
    ct = Table(title="Chk_Cfg", title_justify="left")
    for c in ("offset", "octets", "slot", "module", "meaning"):
        ct.add_column(c, justify="right" if c in ("offset", "slot") else "left")
    for r in res.cfg_rows():
        ct.add_row(str(r["offset"]), r["octets"], str(r["slot"]), r["module"], r["description"])
    con.print(ct)
    for w in res.warnings:
        con.print(Text.assemble(("warning: ", "yellow"), w))


@gsd_group.command("match")
@click.argument("address", type=int, required=False)
@click.option("--cfg", "cfg_hex", default=None, metavar="HEX",
              help="Offline: the configuration octets to match (Get_Cfg / Chk_Cfg), e.g. 'F3 F1'.")
@click.option("--ident", "ident_text", default=None, metavar="IDENT",
              help="Offline: the slave's ident (0x00CA), or a GSD file / library name; on the bus: "
                   "use this GSD instead of the one for the slave's ident.")
@click.option("--prm", "prm_hex", default=None, metavar="HEX",
              help="The slave's Set_Prm user data (octets from 7 on): narrows modules that share octets.")
@click.option("--configured", "configured_hex", default=None, metavar="HEX",
              help="The Chk_Cfg your master sends: say where it parts from the slave's modules.")
@_gsd_dir_option
@bus_options
def match_cmd(opts: BusOptions, address: int | None, cfg_hex: str | None, ident_text: str | None, prm_hex: str | None,
              configured_hex: str | None, gsd_dir: str | None) -> None:
    """The GSD modules that give a slave's configuration.

    With ADDRESS: reads the slave's diagnosis (ident, Cfg_Fault) and Get_Cfg on the bus. Offline:
    --cfg HEX --ident IDENT. A Cfg_Fault, or --configured, is explained: the slave has these modules;
    you configured those. Exit 1 when no module sequence gives the configuration or the configured
    one differs.
    """
    from profidrive_cli.gsd.match import MAX_FITS, explain_refusal, match_cfg
    cfg = hex_option(cfg_hex, "--cfg")
    prm = hex_option(prm_hex, "--prm")
    configured = hex_option(configured_hex, "--configured")
    ident: int | None = None
    cfg_fault: bool | None = None
    if address is None:
        if cfg is None or ident_text is None:
            raise UsageError("give a station ADDRESS (read on the bus), or --cfg HEX and --ident IDENT offline")
    else:
        if cfg is not None:
            raise UsageError("--cfg is for offline use; with ADDRESS the slave's Get_Cfg is read")
        station_address(address)
        ident, cfg, cfg_fault = _read_slave(opts, address)
    g = load_gsd(ident_text if ident_text is not None else ident, gsd_dir)   # type: ignore[arg-type]
    assert cfg is not None
    res = match_cfg(g, cfg, prm)
    explain: list[str] = []
    if configured is not None:
        explain = explain_refusal(g, cfg, configured, prm)
    elif cfg_fault:
        explain = ["the slave reports Cfg_Fault: its master's Chk_Cfg is not these modules (give that "
                   "Chk_Cfg with --configured HEX to compare slot by slot)"]
    differs = configured is not None and configured != cfg
    if opts.json:
        emit_json({"station": address, **ident_fields(g.ident_number), "file": g.path, "device": g.title,
                   "cfg_from": "option" if address is None else "get_cfg", "cfg_fault": cfg_fault,
                   "configured": None if configured is None else configured.hex(" "),
                   "max_fits": MAX_FITS, **res.to_dict(), "explain": explain})
    else:
        where = "offline" if address is None else f"station {address} on {opts.port}"
        out.print(f"{where}: configuration {cfg.hex(' ') or '(empty)'}"
                  + ("" if cfg_fault is None else f"; Cfg_Fault {'set' if cfg_fault else 'not set'}"),
                  markup=False)
        for line in res.describe() + explain:
            out.print(line, markup=False)
    if not res.fits or differs:
        raise SystemExit(1)


def _read_slave(opts: BusOptions, address: int) -> tuple[int, bytes, bool]:
    """Ident, Get_Cfg and Cfg_Fault of a station on the port of the bus options."""
    port = opts.require_port()
    master = opts.open_master(address=address)
    try:
        d, cfg = read_slave(master, address, port)
    finally:
        master.link.close()
    return d.ident, cfg, d.has("Cfg_Fault")


def read_slave(master: Master, address: int, port: str = "the bus") -> tuple[SlaveDiag, bytes]:
    """(Slave_Diag, Get_Cfg octets) of a station, the bus-level way `diag` reads them (BusError when
    it does not answer)."""
    from profidrive_cli import BusError
    d = master.slave_diag(address, wake=True)
    if d is None:
        raise BusError(f"station {address} does not answer on {port}")
    cfg = master.get_cfg(address)
    if cfg is None:
        raise BusError(f"station {address} does not answer Get_Cfg on {port}")
    return d, bytes(cfg)
