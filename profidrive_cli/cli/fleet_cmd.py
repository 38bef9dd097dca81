"""pdrive param fleet dump / diff — a line of drives: options, the sessions the API opens, rendering.

The logic is session/fleet.py's (the matrix, the odd values, the golden file); the dumps are the
session level's Parameters.dump, written through outfile.OutputFile (session/dumpfile.write_dump).
The HTML page uses the checklist report's style (checklist/report_html.CSS).
"""

from __future__ import annotations

import contextlib
import functools
from html import escape as html_escape
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, TypeVar, cast

import click
from rich.markup import escape
from rich.table import Table

from profidrive_cli import BusError, UsageError
from profidrive_cli.cli.common import BusOptions, bus_options, emit_json, err, out
from profidrive_cli.cli.drive_opts import _terminations, drive_options
from profidrive_cli.drives.base import DriveError, value_text
from profidrive_cli.outfile import check_output_path, format_by_suffix, write_text_atomic
from profidrive_cli.api import fleet
from profidrive_cli.api.station import write_dump

if TYPE_CHECKING:
    from profidrive_cli.api.station import DriveStation, Outcome

T = TypeVar("T")

#: --html writes a page: the file name says so (as checklist run --report, run --plot)
HTML_SUFFIXES = {".html": "html", ".htm": "html"}


@click.group("fleet")
def fleet_group() -> None:
    """A line of drives: dump several stations into a directory, compare them side by side (the odd
    values, a golden file with per-drive exceptions)."""


def _read_stations(opts: BusOptions, addresses: list[int], profile_name: str | None, ppo: int | None,
                   fmt: str | None, watchdog_ms: int,
                   job: Callable[[DriveStation], T], each: Callable[[int, DriveStation, T], None]
                   ) -> dict[int, str]:
    """Open every station on one bus (api.Bus.station), then job(session) of all of them at once
    (Bus.together: one bus cycle carries a request to each); as each job ends, each(address,
    session, result) here and the station released. A station that cannot be opened or read is
    reported and skipped: {address: why}. The sessions' exits stop and release every station on
    every way out."""
    failed: dict[int, str] = {}

    def fail(a: int, e: BaseException) -> None:
        failed[a] = str(e)
        if not opts.json:
            err.print(escape(f"station {a}: {e}"))
    with opts.open_bus(None) as bus, contextlib.ExitStack() as stack:
        sessions: dict[int, DriveStation] = {}
        for a in addresses:
            defaults = opts.station_defaults(a)
            try:
                # the config file's profile and layout for this station, below the options
                layout = defaults.get("layout") if ppo is None and fmt is None else None
                # cycle_hz 0: no pace of its own -- while the others are brought up it is kept by
                # its watchdog's rule alone (a quarter of it), not once per cycle period (at 19.2k
                # that was a keep-alive every 27 ms per station), and together() sets the pace
                sessions[a] = stack.enter_context(bus.station(
                    a, profile=profile_name or defaults.get("profile"), layout=layout, ppo=ppo,
                    fmt=fmt, watchdog_ms=watchdog_ms, cycle_hz=0, handle_signals=True,
                    on_message=lambda t: err.print(escape(t))))
            except (BusError, DriveError) as e:
                fail(a, e)
        def done(a: int, o: Outcome[T]) -> None:
            # as soon as its job ended: the result, then the station released (its session's exit)
            s = sessions[a]
            try:
                if o.error is None:
                    each(a, s, cast(T, o.value))
                elif isinstance(o.error, (BusError, DriveError)):
                    fail(a, o.error)
                else:
                    raise o.error
            finally:
                s.close()
        bus.together(sessions, {a: functools.partial(job, s) for a, s in sessions.items()},
                     on_done=done)
    return failed


def _dump(s: DriveStation) -> dict[str, Any]:
    return s.params.dump()


@fleet_group.command("dump")
@click.argument("stations", metavar="STATIONS")
@click.option("-o", "--output", "directory", required=True, metavar="DIR",
              help="The directory (it must exist) for one dump file per station (station-NNN.yaml).")
@drive_options
@bus_options
@_terminations
def fleet_dump(opts: BusOptions, stations: str, directory: str, profile_name: str | None, ppo: int | None,
               fmt: str | None, watchdog_ms: int) -> None:
    """Dump every station of STATIONS into DIR, one file each (as `param dump`). STATIONS: 3-7,9.
    Exit 1 when a station could not be read (the others are written)."""
    addresses = fleet.parse_stations(stations)
    paths = {a: Path(directory) / fleet.dump_file_name(a) for a in addresses}
    for p in paths.values():
        check_output_path(p, "-o")              # before the bus is opened
    written: dict[int, dict[str, Any]] = {}

    def each(a: int, s: DriveStation, doc: dict[str, Any]) -> None:
        assert s.profile is not None            # an open session has its profile
        write_dump(doc, paths[a])
        written[a] = {"station": a, "profile": s.profile.name, "file": str(paths[a]),
                      "settings": len(doc["parameters"])}

    failed = _read_stations(opts, addresses, profile_name, ppo, fmt, watchdog_ms, _dump, each)
    if opts.json:
        emit_json({"directory": str(directory), "written": [written[a] for a in sorted(written)],
                   "failed": {str(a): why for a, why in failed.items()}})
    else:
        for w in (written[a] for a in sorted(written)):
            out.print(escape(f"station {w['station']} ({w['profile']}): {w['settings']} settings "
                             f"written to {w['file']}"))
        out.print(escape(f"{len(written)} of {len(addresses)} station(s) dumped into {directory}"))
    if failed:
        raise SystemExit(1)


@fleet_group.command("diff")
@click.argument("source", metavar="DIR | STATIONS")
@click.option("--golden", metavar="FILE.yaml", default=None,
              help="Values every drive must hold, with per-drive exceptions (docs/commands.md).")
@click.option("--html", "html_path", metavar="FILE.html", default=None,
              help="Also write the matrix as an HTML page (the checklist report's style).")
@click.option("--all", "show_all", is_flag=True, help="Show every code, not only those with a finding.")
@drive_options
@bus_options
@_terminations
def fleet_diff(opts: BusOptions, source: str, golden: str | None, html_path: str | None, show_all: bool,
               profile_name: str | None, ppo: int | None, fmt: str | None, watchdog_ms: int) -> None:
    """Compare a line of drives: the dumps in DIR, or the live STATIONS (e.g. 3-7) on --port. A
    matrix station x code with the odd values (those that differ from the majority of the same
    profile) marked. Exit 1 when a drive differs from the golden file outside its exceptions, or,
    without a golden file, when a value is odd."""
    gold = fleet.load_golden(golden) if golden else None
    if html_path:
        format_by_suffix(html_path, HTML_SUFFIXES, "--html", ".html or .htm")
        check_output_path(html_path, "--html")
    if Path(source).is_dir():
        sets = fleet.load_dir(source)
        failed: dict[int, str] = {}
    else:
        try:
            addresses = fleet.parse_stations(source)
        except UsageError:
            raise UsageError(f"{source}: neither a directory nor station addresses (e.g. 3-7)") from None
        sets = []

        def each(a: int, s: DriveStation, doc: dict[str, Any]) -> None:
            sets.append(fleet.from_dump(doc))

        failed = _read_stations(opts, addresses, profile_name, ppo, fmt, watchdog_ms, _dump, each)
    result = fleet.compare(sorted(sets, key=lambda x: x.station), gold)
    if html_path:
        write_text_atomic(html_path, to_html(result), "--html")
    if opts.json:
        d = result.to_dict()
        d["failed"] = {str(a): why for a, why in failed.items()}
        emit_json(d)
    else:
        _print(result, bool(show_all or opts.verbose))
    if result.violations or (gold is None and result.odd) or failed:
        raise SystemExit(1)


def _shown_codes(result: fleet.FleetDiff, show_all: bool) -> list[str]:
    flagged = {c for _, c in result.odd} | {v.code for v in result.violations} | {c for _, c in result.split}
    flagged |= {c for c in result.codes for cell in result.cells[c].values() if cell.excepted}
    return [c for c in result.codes if show_all or c in flagged]


def _cell_text(result: fleet.FleetDiff, code: str, station: int) -> str:
    cell = result.cells[code][station]
    unit = next((s.units.get(code, "") for s in result.stations if s.station == station), "")
    return "-" if cell.value is None else value_text(cell.value, unit)


def _print(result: fleet.FleetDiff, show_all: bool) -> None:
    codes = _shown_codes(result, show_all)
    n = len(result.stations)
    title = (f"{n} station(s): {len(result.odd)} odd value(s)"
             + (f", {len(result.violations)} difference(s) from the golden file" if result.golden else ""))
    if codes:
        t = Table(title=title, show_header=True)
        t.add_column("code")
        for s in result.stations:
            t.add_column(f"{s.station}\n{s.profile}")
        for c in codes:
            row = [escape(c)]
            for s in result.stations:
                cell = result.cells[c][s.station]
                text = escape(_cell_text(result, c, s.station))
                if cell.violation:
                    text = f"[bold red]{text} ≠ {escape(value_text(cell.golden, ''))}[/]"
                elif cell.odd:
                    text = f"[bold yellow]{text} (odd)[/]"
                elif cell.excepted:
                    text = f"[dim]{text} (except)[/]"
                row.append(text)
            t.add_row(*row)
        out.print(t)
    else:
        out.print(escape(title))
    for a, c in result.odd:
        out.print(escape(f"odd: station {a} {c} = {_cell_text(result, c, a)}"))
    for p, c in result.split:
        out.print(escape(f"no majority: {c} ({p}) differs across the stations"))
    for v in result.violations:
        have = "missing" if v.value is None else _cell_text(result, v.code, v.station)
        out.print(escape(f"golden: station {v.station} {v.code} = {have}, the golden file says "
                         f"{value_text(v.golden, '')}"))


def to_html(result: fleet.FleetDiff) -> str:
    """The matrix as one self-contained page in the checklist report's style."""
    from profidrive_cli.checklist.report_html import CSS
    e = html_escape
    css = CSS + ".odd { background: #fff4d6; font-weight: bold; } .viol { background: #fde0e0; }\n"
    verdict = ("FAILED" if result.violations else "PASSED") if result.golden else (
        f"{len(result.odd)} odd value(s)")
    vcls = "fail" if result.violations or (not result.golden and result.odd) else "pass"
    parts = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
             f"<title>pdrive fleet diff — {e(verdict)}</title>", f"<style>{css}</style></head><body>",
             "<h1>A line of drives</h1>",
             f'<p class="verdict">Result: <span class="{vcls}">{e(verdict)}</span> — '
             f"{len(result.stations)} station(s), {len(result.odd)} odd value(s)"
             + (f", golden file <code>{e(result.golden.path)}</code>: {len(result.violations)} "
                f"difference(s)" if result.golden else "") + "</p>"]
    parts.append("<table><tr><th>code</th>" + "".join(
        f"<th>{s.station}<br>{e(s.profile)}</th>" for s in result.stations) + "</tr>")
    for c in _shown_codes(result, True):
        row = [f"<th>{e(c)}</th>"]
        for s in result.stations:
            cell = result.cells[c][s.station]
            cls = ' class="viol"' if cell.violation else ' class="odd"' if cell.odd else ""
            extra = (f" (golden {e(value_text(cell.golden, ''))})" if cell.violation else
                     " (except)" if cell.excepted else "")
            row.append(f"<td{cls}>{e(_cell_text(result, c, s.station))}{extra}</td>")
        parts.append("<tr>" + "".join(row) + "</tr>")
    parts.append("</table>")
    if result.odd:
        parts.append('<p class="note">Marked: the value differs from the majority of the stations of '
                     "the same profile.</p>")
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"
