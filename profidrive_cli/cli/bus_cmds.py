"""pdrive scan / diag / io."""

from __future__ import annotations


import click
from rich.progress import Progress
from rich.table import Table

from profidrive_cli import BusError, UsageError
from profidrive_cli.cli.common import bus_options, emit_json, err, hex_option, out, station_address
from profidrive_cli.cli.names import device_name
from profidrive_cli.dp.cfg import CfgError, decode_cfg
from profidrive_cli.fdl.timing import BAUD_NAMES, BAUD_RATES


def _diag_json(d) -> dict | None:
    if d is None:
        return None
    return {"st1": d.st1, "st2": d.st2, "st3": d.st3, "master": None if d.master == 0xFF else d.master,
            "ident": f"0x{d.ident:04X}", "flags": d.flags(), "ready": d.ready,
            "ext": d.ext.hex(" "), "ext_blocks": [b.describe() for b in d.ext_blocks()]}


def _cfg_json(cfg: bytes | None) -> list | None:
    if cfg is None:
        return None
    try:
        return [{"octets": m.raw.hex(" "), "inputs": m.inputs, "outputs": m.outputs,
                 "text": m.describe()} for m in decode_cfg(cfg)]
    except CfgError as e:
        return [{"octets": cfg.hex(" "), "error": str(e)}]


@click.command("scan")
@click.option("--from", "first", default=0, show_default=True, type=click.IntRange(0, 126))
@click.option("--to", "last", default=126, show_default=True, type=click.IntRange(0, 126))
@click.option("--gsd-dir", default=None, help="Extra GSD folder for naming stations.")
@bus_options
def scan_cmd(opts, first, last, gsd_dir):
    """Live list: every station on the bus, its type, ident and DP state."""
    from profidrive_cli.dp.scan import scan
    if first > last:
        raise UsageError(f"--from {first} is above --to {last}")
    opts.require_port()
    rates = BAUD_RATES if opts.baud == "auto" else (opts.baud_rate(),)
    result, used_baud, noise = [], None, 0
    for baud in rates:
        master = opts.open_master(baud)
        try:
            if opts.json or not err.is_terminal:
                result = scan(master, first, last)
            else:
                with Progress(console=err, transient=True) as prog:
                    task = prog.add_task(f"scanning at {BAUD_NAMES[baud]}", total=last - first + 1)
                    result = scan(master, first, last, progress=lambda a: prog.advance(task))
            # corrupt telegrams and noise runs seen while probing (every address, found or not)
            noise = sum(c.illegal for c in master.fdl.counters.values())
        finally:
            master.link.close()
        if opts.baud == "auto" and not opts.json:
            err.print(f"{BAUD_NAMES[baud]}: {len(result)} station(s)")
        if result:
            used_baud = baud
            break
    if opts.json:
        emit_json({"port": opts.port, "baud": used_baud, "line_noise": noise, "stations": [
            {"address": e.address, "type": e.station_type,
             "ident": f"0x{e.ident:04X}" if e.ident is not None else None,
             "state": e.diag.state_words(opts.master_address) if e.diag else e.error,
             "device": device_name(e.ident, gsd_dir) if e.ident is not None else "",
             "diag": _diag_json(e.diag), "counters": e.counters} for e in result]})
        return
    if noise:
        err.print(f"the line is noisy: {noise} corrupt or unexpected telegram(s) during the scan "
                  f"(check termination, shielding, the baud rate and other masters)")
    if not result:
        out.print(f"no station answered on {opts.port}"
                  + (" at any DP baud rate" if opts.baud == "auto" else
                     f" at {BAUD_NAMES[opts.baud_rate()]} (try --baud auto)"))
        raise SystemExit(1)
    t = Table(title=f"{opts.port} at {BAUD_NAMES[used_baud]}: {len(result)} station(s)")
    from profidrive_cli.fdl.master import format_counters
    for col in ("addr", "type", "ident", "DP state", "device", "counters"):
        t.add_column(col)
    for e in result:
        t.add_row(str(e.address), e.station_type,
                  f"0x{e.ident:04X}" if e.ident is not None else "",
                  e.diag.state_words(opts.master_address) if e.diag else e.error,
                  device_name(e.ident, gsd_dir) if e.ident is not None else "",
                  format_counters(e.counters))
    out.print(t)


@click.command("diag")
@click.argument("address", type=int)
@click.option("--gsd-dir", default=None, help="Extra GSD folder for diagnosis texts.")
@bus_options
def diag_cmd(opts, address, gsd_dir):
    """The whole Slave_Diag of one station decoded, and its Get_Cfg."""
    station_address(address)
    master = opts.open_master()
    try:
        d = master.slave_diag(address)
        if d is None:
            raise BusError(f"station {address} does not answer on {opts.port}")
        cfg = master.get_cfg(address)
        counters = master.fdl.counters_for(address).as_dict()
    finally:
        master.link.close()
    unit = _unit_diag_texts(d, gsd_dir)
    if opts.json:
        emit_json({"address": address, "state": d.state_words(opts.master_address),
                   "device": device_name(d.ident, gsd_dir), "diag": _diag_json(d),
                   "explain": d.explain(), "unit_diag": unit, "cfg": _cfg_json(cfg),
                   "counters": counters})
        return
    out.print(f"[bold]station {address}[/bold]: {d.state_words(opts.master_address)}"
              f"  (ident 0x{d.ident:04X} {device_name(d.ident, gsd_dir)})")
    out.print(f"raw: {d.encode().hex(' ')}")
    for line in d.explain():
        out.print(f"  {line}")
    for b in d.ext_blocks():
        out.print(f"  ext: {b.describe()}")
    for line in unit:
        out.print(f"  unit diag: {line}")
    if cfg is not None:
        out.print(f"Get_Cfg: {cfg.hex(' ') or '(empty)'}")
        for m in _cfg_json(cfg):
            out.print(f"  {m.get('octets')}: {m.get('text', m.get('error'))}")
    from profidrive_cli.fdl.master import format_counters
    out.print(f"counters: {format_counters(counters)}")


def _unit_diag_texts(d, gsd_dir) -> list[str]:
    if not any(b.kind == "device" for b in d.ext_blocks()):
        return []
    from profidrive_cli.gsd import decode_unit_diag
    from profidrive_cli.gsd.library import find_by_ident
    g = find_by_ident(d.ident, gsd_dir)
    if g is None:
        return []
    return decode_unit_diag(g, d.ext)


@click.command("io")
@click.argument("address", type=int)
@click.option("--cfg", "cfg_hex", default=None, help="Chk_Cfg identifier octets, hex.")
@click.option("--ident", "ident_hex", default=None, help="Ident number (default: from the diagnosis).")
@click.option("--prm", "prm_hex", default=None, help="Set_Prm user-parameter octets, hex.")
@click.option("--out", "out_hex", default=None, help="Output octets to send, hex (default zeros).")
@click.option("--count", default=5, show_default=True, type=click.IntRange(1, 10**9))
@click.option("--watchdog", "wd_ms", default=500, show_default=True, type=click.IntRange(10, 650000),
              help="Slave watchdog in ms (always armed).")
@click.option("--gsd", "gsd_file", default=None, help="GSD file or ident for --module.")
@click.option("--module", "modules", multiple=True, help="GSD module name (with --gsd).")
@bus_options
def io_cmd(opts, address, cfg_hex, ident_hex, prm_hex, out_hex, count, wd_ms, gsd_file, modules):
    """Bring any DP slave to Data_Exchange with a given configuration and show its inputs."""
    from profidrive_cli.dp.station import SlaveConfig
    station_address(address)
    cfg = hex_option(cfg_hex, "--cfg")
    prm = hex_option(prm_hex, "--prm") or b""
    if gsd_file:
        cfg_g, prm_g, ident_g = _from_gsd(gsd_file, modules)
        cfg = cfg if cfg is not None else cfg_g
        prm = prm or prm_g
        ident_hex = ident_hex or f"{ident_g:04X}"
    if not cfg:
        raise UsageError("give the configuration with --cfg HEX (or --gsd FILE --module NAME)")
    try:
        decode_cfg(cfg)
    except CfgError as e:
        raise UsageError(f"--cfg: {e}") from None
    master = opts.open_master()
    try:
        if ident_hex:
            try:
                ident = int(ident_hex, 16)
            except ValueError:
                raise UsageError(f"--ident: not hex: {ident_hex}") from None
        else:
            d = master.slave_diag(address)
            if d is None:
                raise BusError(f"station {address} does not answer on {opts.port}")
            ident = d.ident
        sc = SlaveConfig(ident=ident, cfg=cfg, user_prm=prm, wd_ms=wd_ms)
        st = master.add_station(address, sc)
        outputs = hex_option(out_hex, "--out")
        if outputs is not None and len(outputs) != st.output_len:
            raise UsageError(f"--out has {len(outputs)} octets, the configuration has "
                             f"{st.output_len} output octets")
        master.bring_up(address, timeout=3.0, fail_fast=True)
        rows = []
        for i in range(count):
            inputs = master.exchange(address, outputs if outputs is not None else None)
            rows.append(inputs)
            if opts.json:
                emit_json({"address": address, "cycle": i, "inputs": inputs.hex(" ")})
            else:
                out.print(f"{i:>5}  in: {inputs.hex(' ') or '(none)'}")
        master.release(address)
    finally:
        master.link.close()


def _from_gsd(gsd_file, modules):
    from profidrive_cli.gsd import build_prm
    from profidrive_cli.gsd.library import load_gsd
    g = load_gsd(gsd_file)
    res = build_prm(g, list(modules))
    return res.cfg, res.user_prm, g.ident
