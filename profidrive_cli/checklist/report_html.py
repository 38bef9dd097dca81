"""The HTML report of a checklist run: one self-contained page (inline CSS, plots as inline SVG, no
script, nothing fetched) that opens in any browser and can be mailed or archived as one file.

The verdict and the run's facts, then per station: identity expected/found, the steps with their
result, measured values and message, one plot per step that moved the drive (run, stop, jog: speed
reference and actual over the step, from checklist/steptrace.py), the drive's state at the end and
the parameter snapshots. Plots need matplotlib (the optional extra `plot`); without it the report is
written without them and says how to get them.
"""

from __future__ import annotations

from html import escape

from profidrive_cli.checklist.report_words import hexv, snap, val
from profidrive_cli.checklist.runner import (ERROR, FAILED, NOT_RUN, PASSED, SKIPPED, RunResult, StationResult,
                                             StepResult)
from profidrive_cli.checklist.steptrace import PLOTTED, to_plot_trace

RESULT = {PASSED: ("passed", "pass"), FAILED: ("failed", "fail"), ERROR: ("error", "fail"),
          SKIPPED: ("skipped", "skip"), NOT_RUN: ("not run", "skip"), "interrupted": ("interrupted", "fail")}

CSS = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 72em; color: #222; }
h1 { margin-bottom: 0.2em; } h2 { margin-top: 2em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; margin: 0.8em 0; } td, th { border: 1px solid #ccc; padding: 0.3em 0.6em;
  text-align: left; vertical-align: top; } th { background: #f2f2f2; }
.pass { color: #0a7a2f; font-weight: bold; } .fail { color: #b00020; font-weight: bold; }
.skip { color: #777; } .verdict { font-size: 1.4em; } .note { color: #555; font-style: italic; }
.plot { margin: 0.5em 0 1.5em 0; } .plot svg { max-width: 100%; height: auto; }
.dry { background: #fff4d6; padding: 0.5em; border: 1px solid #e0c060; }
"""


def _e(v: object) -> str:
    return escape("" if v is None else str(v))


def _mark(status: str) -> str:
    word, cls = RESULT.get(status, (status, ""))
    return f'<span class="{cls}">{_e(word)}</span>'


def _plots_available() -> bool:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


def to_html(result: RunResult) -> str:
    cl = result.checklist
    c = result.counts()
    verdict = {"passed": "PASSED", "failed": "FAILED", "interrupted": "INTERRUPTED"}[result.status]
    vcls = "pass" if result.status == "passed" else "fail"
    out = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
           f"<title>{_e(cl.name)} — {verdict}</title>", f"<style>{CSS}</style></head><body>",
           f"<h1>Checklist: {_e(cl.name)}</h1>"]
    if cl.description:
        out.append(f"<p>{_e(cl.description)}</p>")
    out.append(f'<p class="verdict">Result: <span class="{vcls}">{verdict}</span> — {c[PASSED]} passed, '
               f"{c[FAILED]} failed, {c[ERROR]} errors, {c[NOT_RUN]} not run"
               + (f" ({_e(result.interrupted)})" if result.interrupted else "") + "</p>")
    if result.dry_run:
        out.append('<p class="dry"><b>Dry run</b>: rehearsed against a simulated station of each profile, '
                   "not against the plant.</p>")
    rows = [("file", f"<code>{_e(cl.path)}</code> (sha256 <code>{_e(cl.sha256[:16])}…</code>)"),
            ("port", f"<code>{_e(result.port)}</code>"), ("started", _e(result.started)),
            ("finished", f"{_e(result.finished)} ({result.duration_s:.1f} s)")]
    if cl.variables:
        rows.append(("variables", _e(", ".join(f"{k} = {val(v)}" for k, v in cl.variables.items()))))
    out.append("<table>" + "".join(f"<tr><th>{k}</th><td>{v}</td></tr>" for k, v in rows) + "</table>")
    plots = _plots_available()
    if not plots:
        out.append('<p class="note">Plots of the runs need matplotlib: '
                   "<code>pip install 'profidrive-cli[plot]'</code></p>")
    for sr in result.stations:
        out += _station(sr, plots)
    out.append("</body></html>")
    return "\n".join(out) + "\n"


def _station(sr: StationResult, plots: bool) -> list[str]:
    spec = sr.spec
    exp = spec.identity()
    got = sr.identity or {}
    out = [f"<h2>Station {_e(spec.name)} (address {spec.address}) — {_mark(sr.status)}</h2>"]
    if sr.error:
        out.append(f'<p class="fail">{_e(sr.error)}</p>')
    out.append("<table><tr><th>identity</th><th>expected</th><th>found</th></tr>"
               f"<tr><td>ident</td><td>{_e(exp['ident'])} ({_e(exp['ident_source'])})</td>"
               f"<td>{_e(hexv(got.get('ident')))}</td></tr>"
               f"<tr><td>profile</td><td>{_e(exp['profile'])} ({_e(spec.profile.title)})</td>"
               f"<td>{_e(got.get('profile'))}</td></tr>"
               f"<tr><td>GSD</td><td>{_e(exp['gsd'] or '(not checked)')}</td><td>{_e(got.get('gsd'))}</td></tr>"
               f"<tr><td>layout</td><td>{_e(exp['layout'])}</td><td>{_e(got.get('layout'))}</td></tr></table>")
    out.append("<table><tr><th>#</th><th>step</th><th>line</th><th>result</th><th>measured</th>"
               "<th>message</th><th>time</th></tr>")
    figures = []
    for r in sr.steps:
        s = r.step
        label = s.name + f" — {s.title}" if s.name else s.title
        out.append(f"<tr><td>{s.index}</td><td>{_e(label)}</td><td>{s.line}</td><td>{_mark(r.status)}</td>"
                   f"<td>{_e(val(r.measured))}</td><td>{_e(r.message)}</td>"
                   f"<td>{_e((r.started or '')[11:23])}</td></tr>")
        if plots and s.type in PLOTTED and r.trace is not None and len(r.trace) > 1:
            figures.append((s.index, label, r))
    out.append("</table>")
    for index, label, r in figures:
        out.append(f"<h3>Step {index}: {_e(label)} — {_mark(r.status)}</h3>")
        out.append(f'<div class="plot">{_svg(r, f"station {spec.name}, step {index}")}</div>')
    fs = sr.final_status
    if fs:
        if "error" in fs:
            out.append(f'<p>Drive at the end: <span class="fail">{_e(fs["error"])}</span></p>')
        else:
            stopped = '<span class="pass">stopped</span>' if fs.get("stopped") else \
                '<span class="fail">NOT STOPPED</span>'
            out.append(f"<p>Drive at the end: {stopped} (state {_e(fs.get('state'))}, fault "
                       f"{'yes' if fs.get('fault') else 'no'})</p>")
    if sr.snapshot_before or sr.snapshot_after:
        out.append("<table><tr><th>parameter</th><th>before</th><th>after</th><th></th></tr>")
        for code in dict.fromkeys(list(sr.snapshot_before) + list(sr.snapshot_after)):
            b, a = sr.snapshot_before.get(code), sr.snapshot_after.get(code)
            changed = "changed" if b and a and "value" in b and "value" in a and b["value"] != a["value"] else ""
            out.append(f"<tr><td>{_e(code)}</td><td>{_e(snap(b))}</td><td>{_e(snap(a))}</td>"
                       f"<td>{changed}</td></tr>")
        out.append("</table>")
    if sr.snapshot_note:
        out.append(f'<p class="note">{_e(sr.snapshot_note)}</p>')
    return out


def _svg(r: StepResult, title: str) -> str:
    """The step's plot as inline SVG (the XML declaration and DOCTYPE dropped)."""
    from profidrive_cli.plot import render
    assert r.trace is not None              # only a step with a trace is plotted (_station)
    svg = render(to_plot_trace(r.trace, title, r.expected), "svg", width_in=8.0).decode("utf-8")
    i = svg.find("<svg")
    return svg[i:] if i >= 0 else svg


__all__ = ["to_html"]
