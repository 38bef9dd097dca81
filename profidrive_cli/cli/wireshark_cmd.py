"""pdrive wireshark: install the dissector (+ station table, extcap launcher); the extcap entry point."""

from __future__ import annotations

import json
import sys

import click

from profidrive_cli import UsageError


@click.group("wireshark")
def wireshark_group() -> None:
    """Wireshark: install pdrive's PROFIBUS dissector and the live-capture (extcap) entry."""


@wireshark_group.command("install")
@click.option("--dir", "plugins_dir", default=None, metavar="DIR",
              help="Plugins folder to write into (default: Wireshark's personal Lua plugins folder).")
@click.option("--station", "stations", multiple=True, metavar="ADDR=PROFILE[:LAYOUT]",
              help="Decode this station's Data_Exchange areas with a profile's layout (repeatable), "
                   "e.g. 3=fuji-g1 or 6=moeller:ppo1.")
@click.option("--extcap-dir", default=None, metavar="DIR",
              help="Folder for the extcap launcher (default: Wireshark's personal extcap folder; "
                   "with --dir only when given).")
@click.option("--no-extcap", is_flag=True, help="Do not write the extcap launcher.")
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
def install_cmd(plugins_dir: str | None, stations: tuple[str, ...], extcap_dir: str | None,
                no_extcap: bool, as_json: bool) -> None:
    """Install pdrive's PROFIBUS dissector (and a station table) into Wireshark's plugins folder.

    Writes pdrive.lua, pdrive_stations.lua (layouts from the profiles, the stations given with
    --station) and the extcap launcher `pdrive-extcap`, each replacing the old file only when
    complete. Restart Wireshark (or Analyze > Reload Lua Plugins) to load them.
    """
    from profidrive_cli.bustools.wireshark import install
    with_extcap = not no_extcap and (extcap_dir is not None or plugins_dir is None)
    res = install(plugins_dir, list(stations), extcap_dir, with_extcap)
    if as_json:
        click.echo(json.dumps({
            "plugins_dir": str(res.plugins_dir), "files": [str(p) for p in res.files],
            "extcap": [str(p) for p in res.extcap],
            "stations": [{"station": s.address, "profile": s.profile, "layout": s.layout}
                         for s in res.stations]}))
        return
    click.echo(f"dissector:       {res.files[0]}")
    st = ", ".join(f"{s.address}={s.profile}:{s.layout}" for s in res.stations) or \
        "no stations (areas decoded as PROFIdrive PPO by length)"
    click.echo(f"station table:   {res.files[1]} ({st})")
    for path in res.extcap:
        click.echo(f"extcap launcher: {path} (interface 'pdrive' in Wireshark's capture list)")
    click.echo("restart Wireshark or use Analyze > Reload Lua Plugins; with tshark: "
               f"tshark -X lua_script:{res.files[0]} -r FILE.pcap -V")


@wireshark_group.command("extcap", context_settings={"ignore_unknown_options": True,
                                                     "allow_extra_args": True})
@click.option("--extcap-interfaces", is_flag=True, help="List the capture interface (extcap protocol).")
@click.option("--extcap-interface", default=None, metavar="NAME", help="The interface (pdrive).")
@click.option("--extcap-dlts", is_flag=True, help="The link type of the interface.")
@click.option("--extcap-config", is_flag=True, help="The options Wireshark shows for the interface.")
@click.option("--extcap-version", default=None, metavar="VERSION", help="Wireshark's version (ignored).")
@click.option("--capture", is_flag=True, help="Capture into --fifo until Wireshark stops it.")
@click.option("--fifo", default=None, metavar="PATH", help="Where Wireshark reads the pcap stream.")
@click.option("--port", default=None, metavar="PORT",
              help="Serial device, pyserial URL, pty, or a port name from the config file.")
@click.option("--baud", default=None, metavar="RATE",
              help="Bus baud rate (default: the config file's for the port, else 19200).")
@click.option("--rs485", is_flag=True, help="Kernel RS-485 mode.")
@click.option("--duration", default=None, type=float, metavar="S",
              help="Stop after S seconds (default: when Wireshark stops the capture).")
@click.pass_context
def extcap_cmd(ctx: click.Context, extcap_interfaces: bool, extcap_interface: str | None,
               extcap_dlts: bool, extcap_config: bool, extcap_version: str | None, capture: bool,
               fifo: str | None, port: str | None, baud: str | None, rs485: bool,
               duration: float | None) -> None:
    """The extcap entry point Wireshark runs (through the launcher pdrive wireshark install writes)."""
    from profidrive_cli.bustools import extcap as X
    if extcap_interfaces:
        sys.stdout.write(X.interfaces_text())
        return
    if extcap_dlts:
        sys.stdout.write(X.dlts_text(extcap_interface))
        return
    if extcap_config:
        sys.stdout.write(X.config_text(extcap_interface))
        return
    if not capture:
        raise UsageError("say what Wireshark asks: --extcap-interfaces, --extcap-dlts, "
                         "--extcap-config or --capture")
    X.dlts_text(extcap_interface)             # the interface must be ours
    if not fifo:
        raise UsageError("--capture needs --fifo PATH")
    if not port:
        raise UsageError("--capture needs --port PORT (set it in the interface's options)")
    from profidrive_cli.config import resolve
    eff = resolve(port, baud)                  # a port name from the config file, its baud rate
    port, baud = eff.port.value, eff.baud.value
    if duration is not None and duration <= 0:
        raise UsageError("--duration must be positive")
    from profidrive_cli.fdl.timing import parse_baud
    from profidrive_cli.link import open_link
    try:
        rate = parse_baud(baud)
    except ValueError as e:
        raise UsageError(str(e)) from None
    link = open_link(port, rate, rs485=rs485, echo=False)
    # nothing on stderr: Wireshark shows anything an extcap prints there as an error
    X.capture(link, fifo, duration)
