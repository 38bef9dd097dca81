"""`pdrive monitor`: a listener left on a line for weeks (issue 37), and `pdrive monitor report`: what
its history holds. The options are checked and the parts put together here; the loop is
monitor/service.py, the engine monitor/engine.py, the history monitor/store.py, the page
monitor/web.py, the alarms monitor/mqtt.py (docs/monitor.md).
"""

from __future__ import annotations

import signal
import time
from typing import TYPE_CHECKING, Any

import click

from profidrive_cli import UsageError
from profidrive_cli.cli.common import BusOptions, bus_options, emit_json, err, out

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.link.base import Link
    from profidrive_cli.monitor.service import Sink


@click.group("monitor", invoke_without_command=True)
@click.option("--db", "db_dir", default=None, metavar="DIR",
              help="The history's directory (it must exist): monitor.sqlite3 and captures/ inside; "
                   "an earlier run's history there is resumed.")
@click.option("--station", "stations", multiple=True, metavar="ADDR=PROFILE[:LAYOUT]",
              help="Decode this drive's state and faults with PROFILE (default: learned from the "
                   "station's ident on the line). Repeatable.")
@click.option("--interval", type=float, default=60.0, show_default=True, metavar="SECONDS",
              help="How often each station's counters are sampled into the history.")
@click.option("--ring", "ring_s", type=float, default=30.0, show_default=True, metavar="SECONDS",
              help="Seconds of telegrams kept before an event, for its capture.")
@click.option("--after", "after_s", type=float, default=10.0, show_default=True, metavar="SECONDS",
              help="Seconds recorded after an event into its capture.")
@click.option("--max-disk", default="1G", show_default=True, metavar="SIZE",
              help="The most disk the history and its captures take together; the oldest go first.")
@click.option("--keep", "keep_days", type=float, default=None, metavar="DAYS",
              help="Remove history and captures older than DAYS (default: kept while within "
                   "--max-disk).")
@click.option("--web", default=None, metavar="HOST:PORT",
              help="Serve the live page, the history's trends and events, the captures and "
                   "/metrics (loopback unless a token: printed at start). Needs the monitor extra.")
@click.option("--mqtt", default=None, metavar="URL",
              help="Publish events and stations' states: mqtt://[user[:pw]@]host[:port][/prefix]. "
                   "Needs the mqtt extra.")
@click.option("--duration", type=float, default=None, metavar="SECONDS",
              help="Stop after SECONDS on the line's clock (default: run until Ctrl-C or SIGTERM).")
@bus_options
@click.pass_context
def monitor_group(ctx: click.Context, opts: BusOptions, db_dir: str | None, stations: tuple[str, ...],
                  interval: float, ring_s: float, after_s: float, max_disk: str,
                  keep_days: float | None, web: str | None, mqtt: str | None,
                  duration: float | None) -> None:
    """A permanent bus monitor: listens (never transmits) and keeps the live list, counters, drive
    states, likely causes and a capture around every event in a history; a web page, /metrics and
    MQTT alarms on request. `pdrive monitor report` reads the history."""
    if ctx.invoked_subcommand is not None:
        return
    run_monitor(opts, db_dir, stations, interval, ring_s, after_s, max_disk, keep_days, web, mqtt,
                duration)


def _checked(db_dir: str | None, interval: float, ring_s: float, after_s: float,
             keep_days: float | None, duration: float | None) -> str:
    if db_dir is None:
        raise UsageError("--db DIR: the directory the history is kept in (an existing directory; "
                         "an earlier run's history there is resumed)")
    if not interval > 0:
        raise UsageError(f"--interval {interval:g}: must be above 0 seconds")
    if not ring_s > 0:
        raise UsageError(f"--ring {ring_s:g}: must be above 0 seconds")
    if not after_s >= 0:
        raise UsageError(f"--after {after_s:g}: must be 0 or more seconds")
    if keep_days is not None and not keep_days > 0:
        raise UsageError(f"--keep {keep_days:g}: must be above 0 days")
    if duration is not None and not duration > 0:
        raise UsageError(f"--duration {duration:g}: must be above 0 seconds")
    return db_dir


def run_monitor(opts: BusOptions, db_dir: str | None, stations: tuple[str, ...], interval: float,
                ring_s: float, after_s: float, max_disk: str, keep_days: float | None,
                web: str | None, mqtt: str | None, duration: float | None) -> None:
    from profidrive_cli.bustools.listen import POLL_S
    from profidrive_cli.bustools.passive import watch_list
    from profidrive_cli.bustools.ringstore import parse_size
    from profidrive_cli.cli.sim_cmd import _host_port
    from profidrive_cli.cli.sniff_ring import listen_baud
    from profidrive_cli.monitor.engine import Monitor
    from profidrive_cli.monitor.service import LiveBox, Stopped, run
    from profidrive_cli.monitor.store import History

    directory = _checked(db_dir, interval, ring_s, after_s, keep_days, duration)
    max_bytes = parse_size(max_disk)
    watched = watch_list(stations) if stations else {}
    web_at = _host_port(web, "--web") if web else None
    port = opts.require_port()
    history = History(directory, max_bytes, None if keep_days is None else keep_days * 86400.0)
    sinks: list[Sink] = []
    server: Any = None
    reader: Any = None
    try:
        if mqtt:
            from profidrive_cli.monitor.mqtt import MqttAlarms
            alarms = MqttAlarms(mqtt, log=_log_line)
            alarms.start()
            sinks.append(alarms)
        link, opener = _open(opts, port)
        baud = listen_baud(opts) if not port.startswith("sim://") else getattr(link, "baud", None)
        engine = Monitor(baud=baud, watched=watched, wall0=_wall0(port, history.newest_t),
                         interval_s=interval,
                         ring_s=ring_s, after_s=after_s, port=port)
        box = LiveBox()
        if web_at is not None:
            from profidrive_cli.monitor.web import serve
            reader = history.reader()
            server = serve(box.get, reader, host=web_at[0], port=web_at[1], log=_log_line)
        if not opts.json:
            err.print(f"monitoring {port} (listening only), history {directory}"
                      + (" (resumed)" if history.resumed else "")
                      + f", at most {max_disk} with its captures"
                      + (f"; page {server.page_url}" if server is not None else "")
                      + (" (on every address of this machine)" if server is not None
                         and web_at is not None and web_at[0] in ("0.0.0.0", "::") else ""),
                      markup=False, soft_wrap=True)
        elif server is not None:
            emit_json({"event": "web", "url": server.page_url, "port": server.port,
                       "token": server.token})
        old = signal.getsignal(signal.SIGTERM)

        def on_term(*_a: object) -> None:
            raise Stopped()
        signal.signal(signal.SIGTERM, on_term)
        try:
            summary = run(link, engine, history, say=_sayer(opts.json), opener=opener,
                          duration=duration, sinks=sinks, box=box, port=port,
                          poll_s=VIRTUAL_POLL_S if _virtual(port) else POLL_S)
        finally:
            signal.signal(signal.SIGTERM, old)
    finally:
        if server is not None:
            server.close()
        if reader is not None:
            reader.close()
        for s in sinks:
            s.close()
        history.close()
    if opts.json:
        emit_json({"event": "end", "events": summary.events, "captures": summary.captures,
                   "seconds": round(summary.seconds, 3), "adapter_losses": summary.adapter_losses,
                   "ended": summary.ended})
    else:
        err.print(f"{summary.events} event(s), {summary.captures} capture(s), "
                  f"{summary.seconds:.0f} s on the line"
                  + (f", the adapter lost {summary.adapter_losses} time(s)"
                     if summary.adapter_losses else "") + f"; history in {directory}",
                  markup=False)


def _open(opts: BusOptions, port: str) -> tuple[Link, Any]:
    """The link listened to, and how to open it anew: sim:// is the virtual plant with a master of
    its own (sim/virtual_line.py); anything else the port as `sniff` opens it."""
    if port.startswith("sim://"):
        from profidrive_cli.sim.virtual_line import open_line
        return open_line(port), lambda: open_line(port)
    return opts.open_link(), opts.open_link


#: how often a read on a virtual plant returns when nothing is heard (line seconds): its idle reads
#: are CPU only, and a second is finer than anything the monitor times (samples, --after)
VIRTUAL_POLL_S = 1.0


def _virtual(port: str) -> bool:
    return port.startswith("sim://") and "timing=virtual" in port


def _wall0(port: str, newest: float | None) -> float:
    """The wall-clock time of the line's time 0: now; on a virtual plant (whose clock runs ahead of
    the wall's) after the newest time of a resumed history, so that its runs follow each other."""
    now = time.time()
    if newest is not None and _virtual(port):
        return max(now, newest + 1.0)
    return now


def _log_line(text: str) -> None:
    err.print(text, markup=False, soft_wrap=True)


def _sayer(as_json: bool) -> Any:
    def say(obj: dict[str, Any], line: str) -> None:
        if as_json:
            emit_json(obj)
        else:
            out.print(line, markup=False, soft_wrap=True)
    return say


@monitor_group.command("report")
@click.option("--db", "db_dir", required=True, metavar="DIR", help="The monitor's history directory.")
@click.option("--since", default=None, metavar="WHEN",
              help="From (default: the beginning): an age (90s, 30m, 12h, 7d) or a date and time "
                   "(2026-12-04, '2026-12-04 22:00').")
@click.option("--until", default=None, metavar="WHEN", help="Up to (default: now); the same forms.")
@click.option("--station", type=click.IntRange(0, 126), default=None, help="Only this station.")
@click.option("--html", "html_file", default=None, metavar="FILE", help="Also write one HTML page.")
@click.option("--json", "as_json", is_flag=True, help="The report as one JSON document.")
def report_cmd(db_dir: str, since: str | None, until: str | None, station: int | None,
               html_file: str | None, as_json: bool) -> None:
    """What the monitor's history holds for a time window: runs, stations with their counters,
    every event with its likely cause and capture."""
    from profidrive_cli.monitor.report import parse_since, report, report_html, report_text
    from profidrive_cli.monitor.store import Reader
    from profidrive_cli.outfile import check_output_path, write_text_atomic

    now = time.time()
    t_since = None if since is None else parse_since(since, now, "--since")
    t_until = None if until is None else parse_since(until, now, "--until")
    if html_file:
        check_output_path(html_file)
    reader = Reader(db_dir)
    try:
        doc = report(reader, t_since, t_until, station)
    finally:
        reader.close()
    if html_file:
        write_text_atomic(html_file, report_html(doc))
    if as_json:
        emit_json(doc)
    else:
        out.print(report_text(doc), markup=False, soft_wrap=True)
