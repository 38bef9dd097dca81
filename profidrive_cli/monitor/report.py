"""`pdrive monitor report` (issue 37): what the history holds for a time window (and a station) --
the runs, the stations with their counter totals, the events with their likely cause, evidence and
capture -- as one JSON document (report), a readable list (report_text) and one self-contained
HTML page (report_html: no external resource, every text escaped). The keys: docs/monitor.md.

It reads through a store.Reader only; every list it holds is bounded (MAX_EVENTS events, the
newest; the runs the reader gives).
"""

from __future__ import annotations

import html
import re
from datetime import datetime, timezone
from typing import Any

from profidrive_cli import UsageError
from profidrive_cli.monitor.model import SAMPLE_COUNTERS
from profidrive_cli.monitor.store import Reader

#: the most events a report lists (the newest); events_by_kind counts them all
MAX_EVENTS = 10_000
_AGE = re.compile(r"\s*([0-9]+(?:\.[0-9]+)?)\s*([smhd])\s*", re.IGNORECASE)
_AGE_S = {"s": 1.0, "m": 60.0, "h": 3600.0, "d": 86400.0}
_ISO_FORMS = ("%Y-%m-%d", "%Y-%m-%dT%H:%M", "%Y-%m-%d %H:%M", "%Y-%m-%dT%H:%M:%S",
              "%Y-%m-%d %H:%M:%S")


def parse_since(text: str, now: float, option: str = "--since") -> float:
    """--since (or --until): an ISO date or time in local time (2026-12-04, 2026-12-04T22:00,
    "2026-12-04 22:00", seconds allowed) or an age back from `now` (90s, 30m, 12h, 7d) -> epoch
    seconds. UsageError naming the option and the accepted forms otherwise."""
    m = _AGE.fullmatch(text)
    if m is not None:
        return now - float(m.group(1)) * _AGE_S[m.group(2).lower()]
    for form in _ISO_FORMS:
        try:
            return datetime.strptime(text.strip(), form).timestamp()
        except ValueError:
            continue
    raise UsageError(f"{option} {text!r}: expected a date or time (2026-12-04, 2026-12-04T22:00, "
                     f"'2026-12-04 22:00') or an age (90s, 30m, 12h, 7d)")


def iso(t: float | None) -> str | None:
    """Epoch seconds as a local ISO time with its offset (None stays None)."""
    if t is None:
        return None
    return datetime.fromtimestamp(t, timezone.utc).astimezone().isoformat(timespec="seconds")


def report(reader: Reader, since: float | None, until: float | None,
           station: int | None = None) -> dict[str, Any]:
    """The JSON document of the window [since, until] (None: open) and of one station (None:
    all): keys in docs/monitor.md "monitor report"."""
    infos = {s["station"]: s for s in reader.stations()}
    totals = reader.totals(since, until, station)
    numbers = sorted(set(totals) | ({station} if station is not None else set(infos)))
    stations = []
    for n in numbers:
        info = infos.get(n, {"station": n, "ident": None, "ident_hex": None, "profile": None,
                             "first_seen": None, "last_seen": None, "state": None})
        tot = totals.get(n) or {**{c: 0 for c in SAMPLE_COUNTERS}, "samples": 0, "seconds": 0.0}
        stations.append({**info, "totals": tot})
    events = reader.events(since, until, station, limit=MAX_EVENTS)
    by_kind = reader.event_counts(since, until, station)
    return {
        "store": str(reader.directory),
        "window": {"since": since, "until": until, "since_iso": iso(since), "until_iso": iso(until)},
        "station": station,
        "runs": reader.runs(since, until),
        "stations": stations,
        "events": [{**e, "t_iso": iso(e["t"])} for e in events],
        "events_total": sum(by_kind.values()),
        "events_listed": len(events),
        "events_by_kind": by_kind,
    }


def _who(station: Any) -> str:
    return "bus" if station is None else f"station {station}"


def report_text(doc: dict[str, Any]) -> str:
    """A readable list: the window, the stations with their totals, one line per event (time,
    station, kind, text, likely cause, capture), oldest first."""
    w = doc["window"]
    lines = [f"history {doc['store']}: {w['since_iso'] or 'the beginning'} .. "
             f"{w['until_iso'] or 'now'}" + ("" if doc["station"] is None
                                              else f", station {doc['station']}")]
    for r in doc["runs"]:
        lines.append(f"run {r['id']}: {iso(r['started'])} .. {iso(r['ended']) or 'running'} on "
                     f"{r['port']}" + (f" ({r['end_reason']})" if r["end_reason"] else ""))
    for s in doc["stations"]:
        tot = s["totals"]
        counts = ", ".join(f"{c} {tot[c]}" for c in SAMPLE_COUNTERS)
        lines.append(f"station {s['station']}" + (f" {s['ident_hex']}" if s["ident_hex"] else "")
                     + (f" ({s['profile']})" if s["profile"] else "")
                     + f": {s['state'] or 'not seen'}; {counts}")
    lines.append(f"{doc['events_total']} events" + (
        f" (the newest {doc['events_listed']} listed)" if doc["events_listed"] < doc["events_total"]
        else "") + (": " + ", ".join(f"{k} {n}" for k, n in doc["events_by_kind"].items())
                    if doc["events_by_kind"] else ""))
    for e in reversed(doc["events"]):
        cap = ""
        if e["capture"]:
            cap = f"  [{e['capture']}{'' if e['capture_present'] else ', removed'}]"
        cause = f"  likely: {e['cause']}" if e["cause"] else ""
        lines.append(f"{e['t_iso']}  {_who(e['station']):<11} {e['kind']:<8} {e['text']}{cause}{cap}")
    return "\n".join(lines) + "\n"


_CSS = ("body{font-family:sans-serif;margin:1.5em}table{border-collapse:collapse}"
        "td,th{border:1px solid #bbb;padding:2px 6px;text-align:left;vertical-align:top}"
        "th{background:#eee}.gone{color:#888}")


def report_html(doc: dict[str, Any]) -> str:
    """One HTML page (inline style, no script, no external resource); every text escaped."""
    def e(v: Any) -> str:
        return html.escape("" if v is None else str(v), quote=True)

    w = doc["window"]
    title = (f"pdrive monitor report: {w['since_iso'] or 'the beginning'} .. {w['until_iso'] or 'now'}"
             + ("" if doc["station"] is None else f", station {doc['station']}"))
    out = ["<!DOCTYPE html>", "<html><head><meta charset=\"utf-8\">", f"<title>{e(title)}</title>",
           f"<style>{_CSS}</style></head><body>", f"<h1>{e(title)}</h1>",
           f"<p>store {e(doc['store'])}</p>", "<h2>Runs</h2><table><tr><th>run</th><th>started</th>"
           "<th>ended</th><th>port</th><th>baud</th><th>end</th></tr>"]
    for r in doc["runs"]:
        out.append(f"<tr><td>{e(r['id'])}</td><td>{e(iso(r['started']))}</td><td>{e(iso(r['ended']))}"
                   f"</td><td>{e(r['port'])}</td><td>{e(r['baud'])}</td><td>{e(r['end_reason'])}"
                   "</td></tr>")
    out.append("</table><h2>Stations</h2><table><tr><th>station</th><th>ident</th><th>profile</th>"
               "<th>state</th>" + "".join(f"<th>{e(c)}</th>" for c in SAMPLE_COUNTERS) + "</tr>")
    for s in doc["stations"]:
        out.append(f"<tr><td>{e(s['station'])}</td><td>{e(s['ident_hex'])}</td><td>{e(s['profile'])}"
                   f"</td><td>{e(s['state'])}</td>"
                   + "".join(f"<td>{e(s['totals'][c])}</td>" for c in SAMPLE_COUNTERS) + "</tr>")
    kinds = ", ".join(f"{k} {n}" for k, n in doc["events_by_kind"].items())
    out.append(f"</table><h2>Events ({e(doc['events_total'])})</h2><p>{e(kinds)}</p>"
               "<table><tr><th>time</th><th>station</th><th>kind</th><th>text</th>"
               "<th>likely cause</th><th>evidence</th><th>capture</th></tr>")
    for ev in reversed(doc["events"]):
        cap = ""
        if ev["capture"]:
            cap = (e(ev["capture"]) if ev["capture_present"]
                   else f"<span class=\"gone\">{e(ev['capture'])} (removed)</span>")
        evidence = "<br>".join(e(x) for x in ev["evidence"])
        out.append(f"<tr><td>{e(ev['t_iso'])}</td><td>{e(_who(ev['station']))}</td>"
                   f"<td>{e(ev['kind'])}</td><td>{e(ev['text'])}</td><td>{e(ev['cause'])}</td>"
                   f"<td>{evidence}</td><td>{cap}</td></tr>")
    out.append("</table></body></html>")
    return "\n".join(out) + "\n"


__all__ = ["MAX_EVENTS", "iso", "parse_since", "report", "report_html", "report_text"]
