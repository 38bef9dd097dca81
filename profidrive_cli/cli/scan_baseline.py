"""pdrive scan --save FILE / --compare FILE [--junit FILE]: the accepted network and what changed
(bustools/baseline.py), rendered as a table and lines, JSON (docs/json.md `scan save`, `scan compare`)
or JUnit XML. No protocol logic here."""

from __future__ import annotations

import math
from dataclasses import replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from profidrive_cli.bustools import baseline as B
from profidrive_cli.cli.common import emit_json, err, out
from profidrive_cli.cli.names import device_name
from profidrive_cli.fdl.master import format_counters
from profidrive_cli.fdl.timing import BAUD_NAMES


def _rate(baud: int) -> str:
    return BAUD_NAMES.get(baud, f"{baud} bit/s")


def _measure(opts: Any, master: Any, first: int, last: int, quick: bool) -> B.NetworkRecord:
    saved = datetime.now(timezone.utc).isoformat(timespec="seconds")
    try:
        return B.measure(master, first, last, port=str(opts.port), saved=saved, quick=quick)
    finally:
        master.link.close()


def save(opts: Any, master: Any, first: int, last: int, path: str, quick: bool, gsd_dir: Any) -> int:
    """Measure the network, write it to `path` (outfile: replaced only on success). 1: nobody answered
    (nothing written)."""
    from profidrive_cli.outfile import OutputFile
    rec = _measure(opts, master, first, last, quick)
    if not rec.stations:
        err.print(f"no station answered on {opts.port} at {_rate(rec.baud)}: no baseline saved "
                  f"(nothing written to {path})")
        return 1
    with OutputFile(path, "w", what="baseline file") as f:
        f.write(B.dumps(rec, path))
    if opts.json:
        emit_json(B.to_doc(rec))
        return 0
    out.print(_table(rec, f"{opts.port} at {_rate(rec.baud)}: {len(rec.stations)} station(s)", gsd_dir))
    out.print(f"baseline saved to {path}: {len(rec.stations)} station(s), {first}..{last} at "
              f"{_rate(rec.baud)}; compare later with: pdrive scan --compare {path}")
    return 0


def _table(rec: B.NetworkRecord, title: str, gsd_dir: Any) -> Any:
    from rich.table import Table
    t = Table(title=title)
    for col in ("addr", "type", "ident", "Get_Cfg", "reply ms", "device", "counters"):
        t.add_column(col)
    for s in rec.stations:
        t.add_row(str(s.address), s.station_type, f"0x{s.ident:04X}" if s.ident is not None else "",
                  s.cfg.hex(" ").upper() if s.cfg is not None else "",
                  f"{s.reply_ms:.2f}" if s.reply_ms is not None else "",
                  device_name(s.ident, gsd_dir) if s.ident is not None else "",
                  format_counters(s.counters))
    return t


def compare(opts: Any, master: Any, base: B.NetworkRecord, path: str, junit: str | None,
            quick: bool) -> int:
    """Measure the baseline's range now and say what differs: 1 on any difference, 0 when equal."""
    rec = _measure(opts, master, base.first, base.last, quick)
    margins = B.Margins()
    notes = []
    if rec.baud != base.baud:
        margins = replace(margins, reply_ms=math.inf)
        notes.append(f"the baseline was saved at {_rate(base.baud)}, now {_rate(rec.baud)}: reply "
                     f"times not compared")
    diffs = B.compare(base, rec, margins)
    if junit:
        from profidrive_cli.outfile import OutputFile
        with OutputFile(junit, "w", what="JUnit report") as f:
            f.write(to_junit(base, rec, diffs, path))
    if opts.json:
        emit_json({"baseline": path, "saved": base.saved, "port": rec.port, "baud": rec.baud,
                   "first": base.first, "last": base.last, "equal": not diffs,
                   "margins": B.Margins().as_dict(), "notes": notes,
                   "differences": [d.as_dict() for d in diffs],
                   "stations": B.to_doc(rec)["stations"]})
        return 1 if diffs else 0
    for n in notes:
        err.print(n)
    head = (f"compared with {path} (saved {base.saved} on {base.port} at {_rate(base.baud)}, "
            f"{len(base.stations)} station(s), addresses {base.first}..{base.last})")
    if not diffs:
        out.print(f"{head}: no difference ({len(rec.stations)} station(s) as accepted)")
        return 0
    out.print(f"{head}: {len(diffs)} difference{'s' if len(diffs) != 1 else ''}")
    for d in diffs:
        out.print(f"  {d.text}")
    return 1


def to_junit(base: B.NetworkRecord, rec: B.NetworkRecord, diffs: list[B.Difference], path: str) -> str:
    """One testsuite, one testcase per address in the baseline or now; a failure per station that
    differs, with its differences."""
    import xml.etree.ElementTree as ET
    addrs = sorted({s.address for s in base.stations} | {s.address for s in rec.stations})
    failed = {d.station for d in diffs}
    root = ET.Element("testsuites", {"name": "pdrive scan --compare", "tests": str(len(addrs)),
                                     "failures": str(len(failed)), "errors": "0"})
    suite = ET.SubElement(root, "testsuite", {
        "name": f"baseline {path}", "tests": str(len(addrs)), "failures": str(len(failed)),
        "errors": "0", "skipped": "0", "hostname": rec.port, "timestamp": base.saved})
    props = ET.SubElement(suite, "properties")
    for k, v in (("baseline.file", path), ("baseline.saved", base.saved), ("baseline.port", base.port),
                 ("baseline.baud", str(base.baud)), ("port", rec.port), ("baud", str(rec.baud))):
        ET.SubElement(props, "property", {"name": k, "value": v})
    for a in addrs:
        tc = ET.SubElement(suite, "testcase", {"classname": "pdrive.baseline", "name": f"station {a}"})
        mine = [d for d in diffs if d.station == a]
        if mine:
            f = ET.SubElement(tc, "failure", {"message": "; ".join(d.text for d in mine),
                                              "type": ",".join(dict.fromkeys(d.kind for d in mine))})
            f.text = "\n".join(d.text for d in mine)
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def check_paths(save_path: str | None, compare_path: str | None, junit: str | None) -> B.NetworkRecord | None:
    """Before anything is sent: the files to write can be written, the baseline can be read (one line,
    file:line, exit 2 otherwise). The baseline of --compare, or None."""
    from profidrive_cli.outfile import check_output_path
    if save_path is not None:
        check_output_path(save_path, "baseline file")
    if junit is not None:
        check_output_path(junit, "JUnit report")
    if compare_path is not None:
        if junit is not None and Path(junit).resolve() == Path(compare_path).resolve():
            from profidrive_cli import UsageError
            raise UsageError(f"--junit {junit} would overwrite the baseline --compare {compare_path}")
        return B.load(compare_path)
    return None


__all__ = ["check_paths", "compare", "save", "to_junit"]
