"""pdrive doctor: check a serial setup (permission, baud rates, USB latency, echo, RS-485, the
adapter's turnaround and request gap) and recommend slot time and retries. The checks live in
dp/doctor.py and dp/doctor_timing.py; this is rendering only."""

from __future__ import annotations

from typing import Any

import click
from rich.markup import escape
from rich.table import Table

from profidrive_cli import UsageError
from profidrive_cli.cli.common import BusOptions, bus_options, emit_json, out

_MARK = {"ok": "[green]ok[/green]", "warn": "[yellow]warn[/yellow]", "fail": "[red]FAIL[/red]",
         "info": "info", "skip": "[dim]skip[/dim]"}


@click.command("doctor")
@click.option("--probe-address", default=126, show_default=True, type=click.IntRange(0, 126),
              help="Address for the FDL status requests of the echo test, the turnaround and the "
                   "request gap (sent only when the line is quiet; pick one no station uses).")
@click.option("--station", default=None, type=click.IntRange(0, 126),
              help="Measure the round trip to this station (default: the first that answers an FDL "
                   "status request).")
@click.option("--listen", "listen_s", default=0.3, show_default=True, type=click.FloatRange(0.0, 10.0),
              help="Seconds to listen for other traffic before transmitting.")
@bus_options
def doctor_cmd(opts: BusOptions, probe_address: int, station: int | None, listen_s: float) -> None:
    """Check a serial setup for PROFIBUS: permission, DP baud rates, FTDI latency_timer, echo,
    kernel RS-485, the adapter's turnaround and request gap; recommend --slot-time and --retries.
    Without --port: list the ports."""
    from profidrive_cli.dp.doctor import diagnose
    if opts.trace:
        # doctor tests the port's serial settings with raw octets at several rates, not DP
        # telegrams through a master: nothing it sends would be in the pcap
        raise UsageError(f"doctor records no --trace (it tests the serial port itself, not DP "
                         f"telegrams); trace a bus command instead, e.g. pdrive scan --trace "
                         f"{opts.trace}")
    if not opts.port:
        _list_ports(opts)
        return
    if opts.baud == "auto":
        raise UsageError("doctor needs one baud rate for its echo test (--baud RATE)")
    rep = diagnose(opts.port, opts.baud_rate(), opts.master_address, probe_address, opts.rs485,
                   listen_s, station=station)
    if opts.json:
        emit_json(_report_json(rep.as_dict()))
    else:
        t = Table(title=f"pdrive doctor: {rep.port} ({rep.kind})", show_lines=False)
        t.add_column("check")
        t.add_column("")
        t.add_column("finding", overflow="fold")
        for c in rep.checks:
            t.add_row(c.name, _MARK.get(c.status, c.status), c.detail)
        out.print(t)
        if rep.recommend.get("options"):
            out.print(f"recommended: [bold]{rep.recommend['options']}[/bold]")
            out.print(f"  why: {rep.recommend['why']}", markup=False)
    if rep.failed:
        raise SystemExit(1)


def _list_ports(opts: BusOptions) -> None:
    import serial.tools.list_ports
    ports = sorted(serial.tools.list_ports.comports(), key=lambda p: p.device)
    rows = [{"port": p.device, "description": p.description, "hwid": p.hwid} for p in ports]
    if opts.json:
        emit_json({"port": None, "ports": rows,
                   "hint": "pdrive doctor --port PORT checks one port; --port sim:// is the simulator"})
        return
    if not rows:
        out.print("no serial ports found; pdrive doctor --port PORT checks one (sim:// is the simulator)")
        return
    t = Table(title=f"serial ports: {len(rows)}", show_header=True)
    for col in ("port", "description", "hardware id"):
        t.add_column(col, overflow="fold")
    for r in rows:
        t.add_row(escape(r["port"]), escape(r["description"]), escape(r["hwid"]))
    out.print(t)
    out.print("pdrive doctor --port PORT checks one of them")


def _ms_to_s(v: Any) -> Any:
    if isinstance(v, list):
        return [_ms_to_s(x) for x in v]
    return None if v is None else round(v / 1000.0, 6)


def _report_json(d: dict[str, Any]) -> dict[str, Any]:
    """The report in the contract's shape (docs/json.md): the simulator's stations as a list of
    {station, profile}, times in seconds (`*_ms` -> `*_s`, the latency timer's `ms` -> `latency_timer_s`),
    the kernel's RS-485 flag word as `ioctl_flags` (`flags` is a list of names everywhere else)."""
    checks = []
    for c in d["checks"]:
        out: dict[str, Any] = {}
        for k, v in c.items():
            if k == "stations" and isinstance(v, dict):
                out[k] = [{"station": int(a), "profile": name} for a, name in v.items()]
            elif k == "ms":
                out["latency_timer_s"] = _ms_to_s(v)
            elif k.endswith("_ms"):
                out[k[:-3] + "_s"] = _ms_to_s(v)
            elif k == "flags":
                out["ioctl_flags"] = v
            else:
                out[k] = v
        checks.append(out)
    return {**d, "checks": checks}
