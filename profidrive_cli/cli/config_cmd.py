"""pdrive config show / path: the effective settings and where each came from, and the config files
that apply (profidrive_cli/config.py does the work; this module only parses and renders)."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import click
from rich.markup import escape
from rich.table import Table

from profidrive_cli import config as C
from profidrive_cli.cli.common import baud_from, emit_json, out


@click.group("config")
def config_group() -> None:
    """Config file: the effective settings and where each came from; the files that apply."""


@config_group.command("show")
@click.option("--port", default=None, metavar="PORT", help="As a bus command's --port: a device or a port name from the config file.")
@click.option("--baud", default=None, metavar="RATE", help="As a bus command's --baud.")
@click.option("--master-address", default=None, type=click.IntRange(0, 125))
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
def config_show(port: str | None, baud: str | None, master_address: int | None, as_json: bool) -> None:
    """The settings a bus command would use (port, baud, master address, station defaults), each
    with where it came from: option, env, FILE:LINE or default; and the named ports."""
    cfg = C.load()
    eff = C.resolve(port, baud, master_address, config=cfg)
    if str(eff.baud.value) != "auto":           # what a bus command would refuse, refused here too
        baud_from(str(eff.baud.value), eff.baud.source)
    if as_json:
        d = eff.to_dict()
        d["ports"] = [_port_dict(p) for p in cfg.ports.values()]
        emit_json(d)
        return
    t = Table(show_header=True, title="effective settings")
    for c in ("setting", "value", "from"):
        t.add_column(c)
    dev = eff.port.value if eff.port.value is not None else "(none: give --port)"
    named = f" (port name {eff.port_name})" if eff.port_name else ""
    t.add_row("port", escape(str(dev) + named), escape(eff.port.source))
    t.add_row("baud", escape(str(eff.baud.value)), escape(eff.baud.source))
    t.add_row("master_address", str(eff.master_address.value), escape(eff.master_address.source))
    for a, d in sorted(eff.stations.items()):
        for k, s in d.items():
            t.add_row(f"station {a} {k}", escape(_value(s.value)), escape(s.source))
    out.print(t)
    if cfg.ports:
        pt = Table(show_header=True, title="named ports")
        for c in ("name", "port", "baud", "master_address", "stations", "defined at"):
            pt.add_column(c)
        for p in cfg.ports.values():
            pt.add_row(escape(p.name), escape(p.port.value),
                       escape(str(p.baud.value)) if p.baud else "-",
                       str(p.master_address.value) if p.master_address else "-",
                       escape(", ".join(str(a) for a in sorted(p.stations)) or "-"), escape(p.source))
        out.print(pt)
    _print_files(eff.files)


def _value(v: object) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def _port_dict(p: C.NamedPort) -> dict[str, Any]:
    return {"name": p.name, "port": p.port.to_dict(),
            "baud": p.baud.to_dict() if p.baud else None,
            "master_address": p.master_address.to_dict() if p.master_address else None,
            "stations": [{"station": a, **{k: s.to_dict() for k, s in d.items()}}
                         for a, d in sorted(p.stations.items())],
            "source": p.source}


def _print_files(files: Iterable[C.ConfigFile]) -> None:
    t = Table(show_header=True, title="config files (lowest precedence first)")
    for c in ("kind", "path", "exists"):
        t.add_column(c)
    for f in files:
        t.add_row(f.kind, escape(str(f.path)), "yes" if f.exists else "no")
    out.print(t)


@config_group.command("path")
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
def config_path(as_json: bool) -> None:
    """The config files that apply, lowest precedence first, and whether each exists."""
    files = C.config_files()
    if as_json:
        emit_json({"files": [{"kind": f.kind, "path": str(f.path), "exists": f.exists} for f in files]})
        return
    _print_files(files)
