"""Step type `baseline`: the network compared with an accepted one (a file of `pdrive scan --save`), the
same comparison as `pdrive scan --compare` (bustools/baseline.py): a station missing or new, another
ident, type or configuration (Get_Cfg), counters or reply times worse than the baseline's by more than
the margins.

    - baseline: accepted.yaml                       # the file, relative to the checklist's folder
    - baseline: {file: accepted.yaml, scope: station, counter_margin: 1, reply_margin_ms: 5,
                 reply_margin_percent: 50}

scope: `bus` (default) compares every station of the baseline's address range; `station` only the
station the step runs on. The margins default to bustools/baseline.py's (Margins). The station of
the step stays in data exchange during the scan (the master keeps it: dp/poller.py Master.keep). The
dry run reads the file and compares nothing (the simulator is not the plant): it says so.

validate() checks the step's fields and reads the file (its problems as file:line, through the
FieldChecker); execute() measures and compares for the Runner."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from profidrive_cli import PdriveError
from profidrive_cli.bustools import baseline as B
from profidrive_cli.checklist.fields import RawStepFacts, StationFacts, StepArgs, fmt
from profidrive_cli.checklist.steps.base import Handle, R, SR, StepFailed, StepRun, StepType

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.checklist.fields import FieldChecker
    from profidrive_cli.drives.base import Drive

SCOPES = ("bus", "station")
FIELDS = ("file", "scope", "counter_margin", "reply_margin_ms", "reply_margin_percent")


class Baseline(StepType):
    name = "baseline"

    def validate(self, check: FieldChecker, st: StationFacts, rs: RawStepFacts, body: Any,
                 state: dict[str, bool]) -> tuple[StepArgs, str]:
        w = f"step {rs.index} (baseline)"
        d = check.fields(rs, body, FIELDS, "file", required=("file",))
        file = d["file"]
        if not isinstance(file, str) or not file:
            check.fail(d.line_of("file"), f"{w}: 'file' must be the path of a `pdrive scan --save` file")
        path = Path(file)
        if not path.is_absolute():
            path = Path(check.path).parent / path
        scope = d.get("scope", "bus")
        if scope not in SCOPES:
            check.fail(d.line_of("scope"), f"{w}: 'scope' must be {' or '.join(SCOPES)}, got {scope!r}")
        counter = check.num(rs, d, "counter_margin", default=B.COUNTER_MARGIN, minimum=0)
        reply_ms = check.num(rs, d, "reply_margin_ms", default=B.REPLY_MARGIN_MS, minimum=0)
        percent = check.num(rs, d, "reply_margin_percent", default=B.REPLY_MARGIN_RATIO * 100, minimum=0)
        try:
            base = B.load(path)
        except PdriveError as e:
            check.fail(d.line_of("file"), f"{w}: {e}")
        if scope == "station" and base.station(st.address) is None:
            check.fail(d.line_of("scope"), f"{w}: station {st.address} is not in {path} "
                                           f"(scope: station)")
        args = {"file": str(path), "scope": scope, "counter_margin": counter, "reply_margin_ms": reply_ms,
                "reply_margin_percent": percent}
        what = "the bus" if scope == "bus" else f"station {st.address}"
        return args, (f"{what} as in baseline {file} (margins: counters +{fmt(counter)}, reply time "
                      f"+{fmt(reply_ms)} ms and +{fmt(percent)} %)")

    def execute(self, run: StepRun[SR, R], sr: SR, r: R, d: Drive, h: Handle) -> str:
        a = r.step.args
        base = B.load(a["file"])
        margins = B.Margins(int(a["counter_margin"]), float(a["reply_margin_ms"]),
                            float(a["reply_margin_percent"]) / 100.0)
        r.expected = {"file": a["file"], "saved": base.saved, "stations": [s.address for s in base.stations],
                      "margins": margins.as_dict()}
        if run.dry_run:
            r.measured = {"compared": False}
            return (f"dry run: baseline {a['file']} read ({len(base.stations)} station(s), saved "
                    f"{base.saved}); the comparison runs on the plant")
        master = h.session.master
        run.progress(sr, r, f"scanning addresses {base.first}..{base.last}")
        rec = B.measure(master, base.first, base.last, port=str(getattr(master.link, "name", "")))
        notes = []
        if rec.baud != base.baud:
            margins = replace(margins, reply_ms=float("inf"))
            notes.append(f"baseline saved at {base.baud} bit/s, now {rec.baud}: reply times not compared")
        if a["scope"] == "station":
            keep = {sr.spec.address}
            base, rec = B.only(base, keep), B.only(rec, keep)
        diffs = B.compare(base, rec, margins)
        r.measured = {"compared": True, "stations": [s.address for s in rec.stations],
                      "differences": [x.as_dict() for x in diffs], "notes": notes}
        if diffs:
            raise StepFailed(f"{len(diffs)} difference(s) from the baseline: "
                             + "; ".join(x.text for x in diffs))
        return (f"as accepted: {len(rec.stations)} station(s) as in {Path(a['file']).name}"
                + (f" ({'; '.join(notes)})" if notes else ""))


STEP = Baseline()
