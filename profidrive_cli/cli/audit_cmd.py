"""pdrive audit [ADDRESS...]: which setting will hurt, per drive, by its family's rules (api Bus.audit
-> session/audit.py -> Drive.audit_rules). This module parses the options and renders: text, --json
(docs/json.md), and --checklist FILE (a checklist that checks the findings were fixed, then runs the
comm-loss test; docs/checklists.md)."""

from __future__ import annotations

import math
import sys
from typing import Any

import click
from rich.markup import escape

from profidrive_cli import UsageError
from profidrive_cli.cli.common import bus_options, emit_json, out, station_address
from profidrive_cli.cli.drive_cmds import _message
from profidrive_cli.cli.drive_opts import _terminations, drive_options
from profidrive_cli.outfile import OutputFile, check_output_path

#: the comm-loss step of the written checklist runs the drive at this speed before the break
CHECKLIST_HZ = 20


@click.command("audit")
@click.argument("addresses", nargs=-1, type=int, metavar="[ADDRESS]...")
@click.option("--max-reaction", type=float, default=None, metavar="S",
              help="How long the process allows a drive to run on without its master "
                   "(watchdog + the drive's comm-loss delay); without it a delay is a warning.")
@click.option("--cycle-ms", type=float, default=None, metavar="MS",
              help="The master's (PLC's) bus cycle the watchdog is checked against "
                   "(default: pdrive's own cycle on this bus).")
@click.option("--checklist", "checklist_path", default=None, metavar="FILE",
              help="Write a checklist (YAML) that checks the findings were fixed and runs the "
                   "comm-loss test.")
@drive_options
@bus_options
@_terminations
def audit_cmd(opts: Any, addresses: tuple[int, ...], max_reaction: float | None,
              cycle_ms: float | None, checklist_path: str | None, profile_name: str | None,
              ppo: int | None, fmt: str | None, watchdog_ms: int) -> None:
    """Lint each drive's safety and commissioning settings, each finding with the manual's fix.

    The rules (per family, each citing its card manual's line): comm-loss reaction and delay,
    watchdog against the master's cycle, command sources, ramps, maximum frequency, save mode.

    ADDRESS...: the stations (default: every drive station the scan finds). Each finding has its
    severity, code, value, why it matters and the manual's fix. Nothing is written; no drive is
    started. Exit 1 when a finding is an error.
    """
    for name, v in (("--max-reaction", max_reaction), ("--cycle-ms", cycle_ms)):
        if v is not None and not (math.isfinite(v) and v > 0):
            raise UsageError(f"{name} must be a number above 0")
    for a in addresses:
        station_address(a)
    if checklist_path is not None:
        check_output_path(checklist_path, "--checklist")          # before anything is sent
    cycle_s = None if cycle_ms is None else cycle_ms / 1000.0
    with opts.open_bus(None, handle_signals=True, on_message=_message) as bus:
        results = bus.audit(list(addresses) or None, profile=profile_name, layout=fmt, ppo=ppo,
                            watchdog_ms=watchdog_ms, cycle_s=cycle_s, max_reaction_s=max_reaction)
    errors = sum(r.errors for r in results)
    warnings = sum(r.warnings for r in results)
    if checklist_path is not None:
        with OutputFile(checklist_path, "w") as f:
            f.write(checklist_yaml(results, opts.port))
    if opts.json:
        emit_json({"port": opts.port, "errors": errors, "warnings": warnings,
                   "checklist": checklist_path, "stations": [r.to_dict() for r in results]})
    else:
        for r in results:
            _print_result(r)
        out.print(escape(f"{len(results)} station{'s' if len(results) != 1 else ''} audited: "
                         f"{errors} error{'s' if errors != 1 else ''}, {warnings} "
                         f"warning{'s' if warnings != 1 else ''}"
                         + (f"; checklist written to {checklist_path}" if checklist_path else "")))
    if errors:
        sys.exit(1)


_MARK = {"error": "[bold red]ERROR[/]", "warning": "[yellow]WARNING[/]", "info": "INFO"}


def _print_result(r: Any) -> None:
    head = (f"station {r.station} ({r.profile}, {r.layout}): {r.errors} error"
            f"{'s' if r.errors != 1 else ''}, {r.warnings} warning{'s' if r.warnings != 1 else ''}")
    out.print(escape(head))
    for f in r.findings:
        out.print(f"  {_MARK.get(f.severity, f.severity)} " + escape(f"{f.code} = {f.value}  [{f.rule}]"))
        out.print(escape(f"      why:    {f.why}"))
        out.print(escape(f"      fix:    {f.fix}"))
        out.print(escape(f"      manual: {f.manual}"))
    for k in r.not_checked:
        out.print(escape(f"  not checked: {k.topic} ({k.rule}): {k.reason}"))
    for k in r.not_applicable:
        out.print(escape(f"  not applicable: {k.topic}: {k.reason} ({k.manual})"))


def _read_step(f: Any) -> dict[str, Any]:
    check = dict(f.check)
    read: dict[str, Any] = {"param": check.pop("param")}
    if "min" in check and "max" in check:
        read["range"] = [check.pop("min"), check.pop("max")]
    read.update(check)
    return {"read": read}


def checklist_yaml(results: list[Any], port: str | None) -> str:
    """A checklist (docs/checklists.md) over the audited stations: their identity, a read step per
    finding that names a setting (it fails until the setting is fixed), a note per finding that
    does not, then the comm-loss test of every station."""
    import yaml
    names = {r.station: f"station-{r.station}" for r in results}
    stations = [{"name": names[r.station], "address": r.station, "profile": r.profile,
                 "layout": r.layout} for r in results]
    steps: list[Any] = ["expect_identity"]
    for r in results:
        for f in r.findings:
            step: dict[str, Any] = (_read_step(f) if f.check is not None else
                    {"note": f"{f.code} = {f.value}: {f.why}. Fix: {f.fix} ({f.manual})"})
            step.update({"name": f"audit {f.severity}: {f.rule} ({f.code})",
                         "stations": [names[r.station]], "on_fail": "continue"})
            steps.append(step)
    steps.append({"prompt": f"Comm-loss test next: each drive runs at {CHECKLIST_HZ} Hz, then the "
                            f"master stops talking to it. Guards closed, nobody at the machines?"})
    steps.append({"comm_loss": {"hz": CHECKLIST_HZ, "mode": "silence", "ack": True},
                  "on_fail": "continue"})
    doc: dict[str, Any] = {
        "name": "Audit fixes: station" + ("s " if len(results) != 1 else " ")
                + ", ".join(str(r.station) for r in results),
        "description": "Written by pdrive audit: each read step fails until its finding is fixed; "
                       "the comm-loss test checks the drive stops without its master.",
    }
    if port:
        doc["port"] = port
    doc.update({"stations": stations, "steps": steps})
    return str(yaml.safe_dump(doc, sort_keys=False, allow_unicode=True, width=100))
