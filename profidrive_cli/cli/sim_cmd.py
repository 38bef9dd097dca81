"""pdrive sim: serve the simulated bus on a pty, a TCP port or a serial device, in the foreground."""

from __future__ import annotations

import signal
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING

import click

from profidrive_cli import UsageError
from profidrive_cli.cli.common import emit_json, err, out

if TYPE_CHECKING:
    from profidrive_cli.sim.bus import SimBus
    from profidrive_cli.sim.control_http import ControlServer
    from profidrive_cli.sim.server import Endpoint


def _host_port(listen: str, option: str = "--listen", lowest: int = 0) -> tuple[str, int]:
    """--listen HOST:PORT (HOST may be empty: 127.0.0.1; an IPv6 address in brackets or not;
    PORT lowest..65535, 0 picks a free one)."""
    host, colon, p = listen.rpartition(":")
    p = p.strip()
    if not colon or not (p.isascii() and p.isdigit()) or len(p) > 5 or not lowest <= int(p) <= 65535:
        raise UsageError(f"{option} needs HOST:PORT with PORT {lowest}..65535, got {listen[:80]!r}")
    host = host.strip()
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    return host or "127.0.0.1", int(p)


@click.command("sim")
@click.option("--pty", "use_pty", is_flag=True, help="Create a pty and print its path.")
@click.option("--listen", default=None, metavar="HOST:PORT", help="Serve on a TCP port.")
@click.option("--port", "serial_port", default=None, metavar="DEVICE",
              help="Serve on an existing serial device (e.g. one end of a socat pty pair).")
@click.option("--plant", default=None,
              help="Which stations: a sim:// URL, e.g. sim://?stations=3:fuji-g1,9:yaskawa  "
                   "[default: sim://]")
@click.option("--learn", "learn", default=None, metavar="CAPTURE",
              help="The stations of a capture file (raw, pcap, pcapng, ptd), answering as the captured "
                   "ones did: idents, diagnosis, Get_Cfg, Chk_Cfg, inputs (drive models where a "
                   "profile has the ident). Not with --plant.")
@click.option("--baud", default="19200", show_default=True)
@click.option("--json", "as_json", is_flag=True, help="Print the endpoint as JSON.")
@click.option("--plc", is_flag=True,
              help="Also run a built-in cyclic master (a PLC) on the stations and send the whole bus "
                   "traffic to the endpoint as a tap hears it (listen-only: for `pdrive sniff`).")
@click.option("--control", default=None, metavar="HOST:PORT",
              help="Also serve the plant's control (JSON over HTTP: trip, clear, unplug, replug, set, "
                   "faults, state; `pdrive sim-ctl`), on 127.0.0.1 unless a host is named (then "
                   "with a token). PORT 0 picks a free one.")
def sim_cmd(use_pty: bool, listen: str | None, serial_port: str | None, plant: str | None,
            learn: str | None, baud: str, as_json: bool, plc: bool, control: str | None) -> None:
    """Serve a simulated PROFIBUS segment for another master (Ctrl-C ends it).

    With --plc the segment has its own master: a PLC brings every station up and runs a scripted
    motion on each drive; the endpoint only listens to that bus (what a client writes is ignored).
    """
    from profidrive_cli.fdl.timing import parse_baud
    from profidrive_cli.sim import server
    from profidrive_cli.sim.plant import build_bus
    if sum(bool(x) for x in (use_pty, listen, serial_port)) != 1:
        raise UsageError("choose exactly one of --pty, --listen HOST:PORT, --port DEVICE")
    if learn is not None:
        if plant is not None:
            raise UsageError("--learn and --plant exclude each other (--learn takes the capture's stations)")
        from urllib.parse import quote
        plant = "sim://?learn=" + quote(learn, safe="/")
    plant = plant or "sim://"
    if not plant.startswith("sim://"):
        raise UsageError(f"--plant must be a sim:// URL, got {plant!r}")
    try:
        b = parse_baud(baud)
    except ValueError as e:
        raise UsageError(str(e)) from None
    if plc:
        _check_plc_port(serial_port)
        plant = _wire_timed(plant)
    bus = build_bus(plant, default_baud=b)     # PNU 963 of the simulated cards follows --baud
    ep: server.PtyEndpoint | server.TcpEndpoint | server.SerialEndpoint
    if use_pty:
        ep = server.PtyEndpoint()
        where = ep.path
    elif listen:
        host, port = _host_port(listen)
        try:
            tcp = server.TcpEndpoint(host, port)      # (its events: one line on stderr each)
        except OSError as e:
            raise UsageError(f"--listen {listen}: {e.strerror or e}") from None
        ep = tcp
        where = f"socket://{tcp.address[0]}:{tcp.address[1]}"
    else:
        assert serial_port is not None               # (exactly one of the three, checked above)
        ep = server.SerialEndpoint(serial_port, b)
        where = serial_port
    ctl = _control_server(bus, control) if control else None
    stations = {a: s.model.family for a, s in sorted(bus.slaves.items())}
    if as_json:
        emit_json({"port": where, "stations": [{"station": a, "family": f} for a, f in stations.items()],
                   **({"plc": True} if plc else {}),
                   **({"control": ctl.url, "token": ctl.token} if ctl is not None else {})})
    else:
        out.print(where)
        err.print("simulated stations: " + ", ".join(f"{a} {f}" for a, f in stations.items())
                  + (" with a built-in PLC (listen-only endpoint: `pdrive sniff --port "
                     f"{where}`)" if plc else "") + " — Ctrl-C ends")
        if ctl is not None:
            err.print(f"control: {ctl.url} (`pdrive sim-ctl --control {ctl.host}:{ctl.port} ...`)"
                      + (f"; reachable from the network: every request needs the token {ctl.token}"
                         if ctl.token else ""), markup=False)
    sys.stdout.flush()
    stopping: list[int] = []
    signal.signal(signal.SIGTERM, lambda *a: stopping.append(1))
    signal.signal(signal.SIGINT, lambda *a: stopping.append(1))
    try:
        if plc:
            _run_plc(bus, ep, stop=lambda: bool(stopping))
        else:
            server.serve(bus, ep, stop=lambda: bool(stopping))
    except KeyboardInterrupt:
        pass
    finally:
        ep.close()
        if ctl is not None:
            ctl.close()
    err.print("simulator stopped")


def _control_server(bus: SimBus, control: str) -> ControlServer:
    """--control HOST:PORT: the plant's control over HTTP (sim/control.py), queued onto the bus."""
    from profidrive_cli.sim.control import QueuedController
    from profidrive_cli.sim.control_http import ControlServer
    host, port = _host_port(control, "--control")
    try:
        return ControlServer(QueuedController(bus), host, port).start()
    except OSError as e:
        raise UsageError(f"--control {control}: {e.strerror or e}") from None


def _check_plc_port(serial_port: str | None) -> None:
    """--plc sends a master's telegrams to the endpoint: on a real line they would reach real
    drives, so --port takes a pty only (e.g. one end of a socat pair)."""
    if serial_port is None:
        return
    from profidrive_cli.link.serial_link import _is_pty
    if not _is_pty(serial_port):
        raise UsageError(f"--plc --port {serial_port}: not a pty; the PLC's telegrams would go out on "
                         f"a real line and could start real drives (use --pty, --listen, or one "
                         f"end of a socat pty pair)")


def _wire_timed(plant: str) -> str:
    """The plant at wire timing (the tap then hears the bus at its own pace), unless asked otherwise."""
    from urllib.parse import parse_qs, urlsplit
    if "timing" in parse_qs(urlsplit(plant).query):
        return plant
    return plant + ("&" if "?" in plant else "?") + "timing=wire"


def _run_plc(bus: SimBus, ep: Endpoint, stop: Callable[[], bool]) -> None:
    from profidrive_cli.sim.plc import Plc
    from profidrive_cli.sim.tap import Tap
    tap = Tap(ep)
    Plc(bus, tap.write, log=lambda line: err.print(line, markup=False)).run(stop)
