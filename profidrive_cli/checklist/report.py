"""Reports of a checklist run: JSON (everything), Markdown (for people), JUnit XML (for CI systems).

JUnit: one <testsuite> per station, one <testcase> per step (failed/error steps carry <failure> or <error>
with the measured values, steps not run are <skipped>); the station identity and the run's facts are
<properties>, the parameter snapshots are in the suite's <system-out>.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

from profidrive_cli.checklist.runner import ERROR, FAILED, NOT_RUN, PASSED, SKIPPED, RunResult, StationResult
from profidrive_cli.checklist.report_words import hexv as _hexv
from profidrive_cli.checklist.report_words import snap as _snap
from profidrive_cli.checklist.report_words import val as _val
from profidrive_cli.outfile import format_by_suffix, write_text_atomic

FORMATS = {".json": "json", ".md": "markdown", ".markdown": "markdown", ".xml": "junit", ".html": "html",
           ".htm": "html"}


def report_format(path: str | Path) -> str:
    return format_by_suffix(path, FORMATS, "--report", ".json, .md, .xml or .html")


def render(result: RunResult, fmt: str) -> str:
    if fmt == "json":
        return to_json(result)
    if fmt == "markdown":
        return to_markdown(result)
    if fmt == "junit":
        return to_junit(result)
    if fmt == "html":
        from profidrive_cli.checklist.report_html import to_html
        return to_html(result)
    raise ValueError(fmt)


def write_report(result: RunResult, path: str | Path) -> Path:
    """Render and write one report: a temporary file beside `path`, renamed over it only when
    complete (outfile.write_text_atomic). Creates no directory. OutputPathError / OutputWriteError
    (the old file untouched) on failure."""
    p = Path(path)
    text = render(result, report_format(p))
    return write_text_atomic(p, text, what="--report")


# =============================================================================================
# JSON
# =============================================================================================


def to_json(result: RunResult) -> str:
    """The whole run in the shape of docs/json.md ("checklist run"): stations by `station`, idents
    as `ident` (int) + `ident_hex`, status flags as the list of names set, speeds `actual_hz`."""
    d = result.to_dict()
    d["stations"] = [_station_json(s) for s in d["stations"]]
    return json.dumps(d, indent=2, ensure_ascii=False, default=_default) + "\n"


def _identity_json(d: dict[str, Any] | None) -> dict[str, Any] | None:
    if not d:
        return d
    out: dict[str, Any] = {}
    for k, v in d.items():
        if k == "address":
            out["station"] = v
        elif k == "ident":
            ident = v if v is None or isinstance(v, int) else int(str(v), 16)
            out["ident"] = ident
            out["ident_hex"] = None if ident is None else f"0x{ident:04X}"
        elif k != "ident_hex":
            out[k] = v
    return out


_FINAL_NAMES = {"speed_hz": "actual_hz", "speed_percent": "actual_percent"}


def _measured_json(v: object) -> object:
    """A step's measured values with the status in the contract's names: speed_hz / speed_percent ->
    actual_hz / actual_percent, a status's `flags` (the bits set) as a list; the rest as measured."""
    if isinstance(v, list):
        return [_measured_json(x) for x in v]
    if not isinstance(v, dict):
        return v
    out = {_FINAL_NAMES.get(k, k): _measured_json(x) for k, x in v.items()}
    fl = out.get("flags")
    if isinstance(fl, dict) and all(x is True for x in fl.values()):
        out["flags"] = list(fl)
    return out


def _station_json(s: dict[str, Any]) -> dict[str, Any]:
    out = {("station" if k == "address" else k): v for k, v in s.items()}
    out["steps"] = [{**st, "measured": _measured_json(st.get("measured"))} for st in s.get("steps", [])]
    out["expected_identity"] = _identity_json(s.get("expected_identity"))
    out["identity"] = _identity_json(s.get("identity"))
    fs = s.get("final_status")
    if fs:
        fs = {_FINAL_NAMES.get(k, k): v for k, v in fs.items()}
        if isinstance(fs.get("flags"), dict):
            fs["flags"] = [k for k, v in fs["flags"].items() if v]
        out["final_status"] = fs
    return out


def _default(o: object) -> list[Any] | str:
    if isinstance(o, (set, tuple)):
        return list(o)
    if isinstance(o, Path):
        return str(o)
    return str(o)


# =============================================================================================
# Markdown
# =============================================================================================

_MARK = {PASSED: "✅ passed", FAILED: "❌ failed", ERROR: "❌ error", SKIPPED: "⏭ skipped", NOT_RUN: "– not run",
         "interrupted": "⚠ interrupted"}


def _md(text: object) -> str:
    """One table cell: no pipes or newlines."""
    s = "" if text is None else str(text)
    return s.replace("\\", "\\\\").replace("|", "\\|").replace("\n", " ").strip()


def to_markdown(result: RunResult) -> str:
    cl = result.checklist
    c = result.counts()
    out = [f"# Checklist: {cl.name}", ""]
    if cl.description:
        out += [cl.description, ""]
    verdict = {"passed": "**PASSED**", "failed": "**FAILED**", "interrupted": "**INTERRUPTED**"}[result.status]
    out += [f"Result: {verdict} — {c[PASSED]} passed, {c[FAILED]} failed, {c[ERROR]} errors, "
            f"{c[NOT_RUN]} not run" + (f" ({result.interrupted})" if result.interrupted else ""), ""]
    if result.dry_run:
        out += ["> **Dry run**: rehearsed against a simulated station of each profile, not against the plant.", ""]
    out += ["| | |", "|---|---|",
            f"| file | `{_md(cl.path)}` (sha256 `{cl.sha256[:16]}…`) |",
            f"| port | `{_md(result.port)}` |",
            f"| started | {_md(result.started)} |",
            f"| finished | {_md(result.finished)} ({result.duration_s:.1f} s) |"]
    if cl.variables:
        out.append(f"| variables | {_md(', '.join(f'{k} = {_val(v)}' for k, v in cl.variables.items()))} |")
    out.append("")
    for sr in result.stations:
        out += _md_station(sr)
    return "\n".join(out).rstrip() + "\n"


def _md_station(sr: StationResult) -> list[str]:
    spec = sr.spec
    exp = spec.identity()
    got = sr.identity or {}
    out = [f"## Station {spec.name} (address {spec.address}) — {_MARK.get(sr.status, sr.status)}", ""]
    if sr.error:
        out += [f"**{_md(sr.error)}**", ""]
    out += ["| identity | expected | found |", "|---|---|---|",
            f"| ident | {exp['ident']} ({exp['ident_source']}) | {_md(_hexv(got.get('ident')))} |",
            f"| profile | {exp['profile']} ({spec.profile.title}) | {_md(got.get('profile'))} |",
            f"| GSD | {_md(exp['gsd'] or '(not checked)')} | {_md(got.get('gsd'))} |",
            f"| layout | {exp['layout']} | {_md(got.get('layout'))} |", ""]
    extra = {k: v for k, v in got.items() if k not in ("ident", "profile", "gsd", "layout", "address")}
    if extra:
        out += ["Also reported: " + _md(_val(extra)), ""]
    out += ["| # | step | line | result | measured | message | time |", "|---|---|---|---|---|---|---|"]
    for r in sr.steps:
        s = r.step
        label = s.name + f" — {s.title}" if s.name else s.title
        out.append(f"| {s.index} | {_md(label)} | {s.line} | {_MARK.get(r.status, r.status)} | "
                   f"{_md(_val(r.measured))} | {_md(r.message)} | {_md((r.started or '')[11:23])} |")
    out.append("")
    if sr.final_status:
        fs = sr.final_status
        if "error" in fs:
            out += [f"Drive at the end: **{_md(fs['error'])}**", ""]
        else:
            out += [f"Drive at the end: {'stopped' if fs.get('stopped') else '**NOT STOPPED**'} "
                    f"(state {_md(fs.get('state'))}, fault {'yes' if fs.get('fault') else 'no'})", ""]
    if sr.snapshot_before or sr.snapshot_after:
        out += ["| parameter | before | after | |", "|---|---|---|---|"]
        for code in dict.fromkeys(list(sr.snapshot_before) + list(sr.snapshot_after)):
            b, a = sr.snapshot_before.get(code), sr.snapshot_after.get(code)
            changed = "changed" if b and a and "value" in b and "value" in a and b["value"] != a["value"] else ""
            out.append(f"| {_md(code)} | {_md(_snap(b))} | {_md(_snap(a))} | {changed} |")
        out.append("")
    if sr.snapshot_note:
        out += [f"_{_md(sr.snapshot_note)}_", ""]
    return out


# =============================================================================================
# JUnit XML
# =============================================================================================


def to_junit(result: RunResult) -> str:
    cl = result.checklist
    c = result.counts()
    root = ET.Element("testsuites", {
        "name": cl.name, "tests": str(sum(len(s.steps) for s in result.stations)),
        "failures": str(c[FAILED]), "errors": str(c[ERROR] + sum(1 for s in result.stations if s.error)),
        "skipped": str(c[NOT_RUN] + c[SKIPPED]), "time": f"{result.duration_s:.3f}",
        "timestamp": result.started})
    for sr in result.stations:
        sc = sr.counts()
        suite = ET.SubElement(root, "testsuite", {
            "name": f"{cl.name} / {sr.spec.name}", "tests": str(len(sr.steps)), "failures": str(sc[FAILED]),
            "errors": str(sc[ERROR] + (1 if sr.error else 0)), "skipped": str(sc[NOT_RUN] + sc[SKIPPED]),
            "time": f"{sr.duration_s:.3f}", "timestamp": sr.started or result.started,
            "hostname": result.port, "id": str(sr.spec.address)})
        props = ET.SubElement(suite, "properties")
        facts = {"checklist.file": str(cl.path), "checklist.sha256": cl.sha256, "port": result.port,
                 "dry_run": str(result.dry_run).lower(), "station.name": sr.spec.name,
                 "station.address": str(sr.spec.address)}
        for k, v in sr.spec.identity().items():
            facts[f"expected.{k}"] = "" if v is None else str(v)
        for k, v in (sr.identity or {}).items():
            facts[f"identity.{k}"] = "" if v is None else str(_hexv(v) if k == "ident" else v)
        if sr.final_status and "error" not in sr.final_status:
            facts["final.stopped"] = str(bool(sr.final_status.get("stopped"))).lower()
            facts["final.state"] = str(sr.final_status.get("state"))
        for k, v in cl.variables.items():
            facts[f"var.{k}"] = str(v)
        for k, v in facts.items():
            ET.SubElement(props, "property", {"name": k, "value": v})
        classname = f"{_cls(cl.name)}.{_cls(sr.spec.name)}"
        for r in sr.steps:
            s = r.step
            tc = ET.SubElement(suite, "testcase", {
                "classname": classname, "name": f"{s.index:02d} {s.label}", "time": f"{r.duration_s:.3f}",
                "file": str(cl.path), "line": str(s.line)})
            measured = json.dumps(r.measured, ensure_ascii=False, default=str)
            expected = json.dumps(r.expected, ensure_ascii=False, default=str)
            if r.status == FAILED:
                f = ET.SubElement(tc, "failure", {"message": r.message, "type": s.type})
                f.text = f"expected: {expected}\nmeasured: {measured}\n{cl.path}:{s.line}"
            elif r.status == ERROR:
                e = ET.SubElement(tc, "error", {"message": r.message, "type": s.type})
                e.text = f"expected: {expected}\nmeasured: {measured}\n{cl.path}:{s.line}"
            elif r.status in (NOT_RUN, SKIPPED):
                ET.SubElement(tc, "skipped", {"message": r.message or r.status})
            out = ET.SubElement(tc, "system-out")
            out.text = (f"{r.status}: {r.message}\nstarted: {r.started}\nfinished: {r.finished}\n"
                        f"expected: {expected}\nmeasured: {measured}\n")
        snap = {"before": sr.snapshot_before, "after": sr.snapshot_after, "final_status": sr.final_status}
        ET.SubElement(suite, "system-out").text = "parameter snapshots and final status:\n" + json.dumps(
            snap, ensure_ascii=False, indent=1, default=str)
        if sr.error:
            ET.SubElement(suite, "system-err").text = sr.error
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _cls(text: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in str(text)).strip("_") or "checklist"
