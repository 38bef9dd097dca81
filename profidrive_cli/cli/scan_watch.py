"""pdrive scan --watch: the watched live list (bustools/buswatch.py) rendered — refreshed in place on a
terminal, a JSON Lines stream with --json, one table at the end otherwise. No protocol logic here."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from profidrive_cli.bustools.buswatch import COUNTER_KEYS, BusWatch, WatchedStation, WatchView
from profidrive_cli.cli.common import BusOptions, emit_json, err, is_tty, out
from profidrive_cli.cli.names import device_name

if TYPE_CHECKING:
    from rich.table import Table

    from profidrive_cli.dp.poller import Master

#: rich style per state category
COLOURS = {"data exchange": "green", "waiting": "cyan", "diagnosis pending": "yellow",
           "configuration fault": "bold red", "not supported": "magenta", "no answer": "red"}

#: counters shown in colour when they rise (a marginal segment shows here first)
ALARM_KEYS = ("retries", "no_answer", "illegal", "reparams")


def _ms(v: float | None) -> str:
    return "-" if v is None else f"{v * 1000:.1f}"


#: short names of the counters in the table
SHORT = {"requests": "req", "retries": "retries", "no_answer": "no answer", "illegal": "illegal",
         "reparams": "re-param"}


def counter_text(ws: WatchedStation, colour: bool = True) -> str:
    """'33 req +10.3/s, 3 retries +1.0/s': requests always, the error counters when not zero, each with
    its rise per second when it rises; a rising error counter in bold red, a standing one in yellow."""
    parts = []
    for k in COUNTER_KEYS:
        n = ws.counters.get(k, 0)
        if k != "requests" and not n:
            continue
        rate = ws.rates.get(k, 0.0)
        text = f"{n} {SHORT[k]}" + (f" +{rate:.1f}/s" if rate > 0 else "")
        if colour and k in ALARM_KEYS:
            text = f"[bold red]{text}[/]" if rate > 0 else f"[yellow]{text}[/]"
        parts.append(text)
    return ", ".join(parts)


def _detail(ws: WatchedStation) -> str:
    """The DP state in words where it says more than the category, and a late first answer."""
    words = _state_detail(ws)
    if ws.unanswered_before:
        n = ws.unanswered_before
        late = f"answered after {n} unanswered request{'' if n == 1 else 's'} (baud-rate search)"
        words = f"{words}; {late}" if words else late
    return words


def _state_detail(ws: WatchedStation) -> str:
    if ws.category == "data exchange":
        return f"master {ws.master}" if ws.master is not None else ""
    if ws.category == "waiting" and ws.state == "waiting for parameters":
        return ""
    if ws.category == "no answer":
        return ""
    return ws.state


def table(view: WatchView, title: str, gsd_dir: str | None, colour: bool = True) -> Table:
    from rich.markup import escape
    from rich.table import Table

    from profidrive_cli.bustools.causes import watch_causes
    likely = "".join(f"\nlikely: {escape(c.title)} ({'; '.join(escape(e) for e in c.evidence)})"
                     for c in watch_causes(view.stations)[:3])
    t = Table(title=title, caption=(f"pass {view.passes}, {view.t_s:.1f} s; one pass over the bus "
                                    f"min/mean/max {_ms(view.cycle_min_s)} / {_ms(view.cycle_mean_s)} / "
                                    f"{_ms(view.cycle_max_s)} ms" + likely))
    for col in ("addr", "type", "ident", "state", "detail", "device", "counters"):
        t.add_column(col)
    for ws in view.stations:
        style = COLOURS.get(ws.category, "") if colour else ""
        cat = f"[{style}]{ws.category}[/]" if style else ws.category
        t.add_row(str(ws.address), ws.station_type,
                  f"0x{ws.ident:04X}" if ws.ident is not None else "",
                  cat, _detail(ws),
                  device_name(ws.ident, gsd_dir) if ws.ident is not None else "",
                  counter_text(ws, colour))
    return t


def view_json(view: WatchView) -> dict[str, Any]:
    from profidrive_cli.bustools.causes import watch_causes
    return {"event": "watch", "t_s": round(view.t_s, 3), "passes": view.passes,
            "causes": [c.as_dict() for c in watch_causes(view.stations)],
            "cycle_min_s": view.cycle_min_s, "cycle_mean_s": view.cycle_mean_s,
            "cycle_max_s": view.cycle_max_s,
            "stations": [{"station": ws.address, "type": ws.station_type, "ident": ws.ident,
                          "ident_hex": f"0x{ws.ident:04X}" if ws.ident is not None else None,
                          "category": ws.category, "state": ws.state, "master": ws.master,
                          "counters": dict(ws.counters),
                          "unanswered_before": ws.unanswered_before,
                          "rates_per_s": {k: round(v, 3) for k, v in ws.rates.items()}}
                         for ws in view.stations]}


def watch(opts: BusOptions, master: Master, first: int, last: int, interval: float,
          duration: float | None, gsd_dir: str | None) -> int:
    """Run the watched live list until --duration or Ctrl-C; the exit code (1: no station answered)."""
    from profidrive_cli.fdl.timing import BAUD_NAMES
    w = BusWatch(master, first, last)
    title = f"{opts.port} at {BAUD_NAMES[opts.baud_rate()]} (watching; Ctrl-C ends)"
    live_mode = is_tty() and not opts.json
    live = None
    try:
        w.start()
        if live_mode:
            from rich.live import Live
            live = Live(table(w.view(), title, gsd_dir), console=out, auto_refresh=False, transient=False)
            live.start()
        end = None if duration is None else w.now() + duration
        next_show = w.now()
        while True:
            w.step()
            now = w.now()
            if now >= next_show:
                v = w.view()
                if opts.json:
                    emit_json(view_json(v))
                elif live is not None:
                    live.update(table(v, title, gsd_dir), refresh=True)
                next_show = now + interval
            if end is not None and now >= end:
                break
            # a pass takes what the bus takes; don't poll faster than ten passes per refresh
            w.wait_until(w.t0 + now + min(interval / 10.0, 0.1))
    except KeyboardInterrupt:
        pass
    finally:
        if live is not None:
            live.update(table(w.view(), title, gsd_dir), refresh=True)     # the last pass, not the last refresh
            live.stop()
        master.link.close()
    v = w.view()
    if opts.json:
        emit_json(dict(view_json(v), event="end"))
    elif live is None:
        out.print(table(v, f"{opts.port} at {BAUD_NAMES[opts.baud_rate()]}: {len(v.stations)} station(s), "
                           f"watched {v.t_s:.1f} s", gsd_dir, colour=False))
    if not v.stations:
        err.print("no station answered")
        return 1
    return 0


__all__ = ["watch", "view_json", "table", "COLOURS"]
