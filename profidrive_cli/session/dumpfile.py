"""The parameter dump file (`pdrive param dump` / `restore` / `diff`): its format number, the end
marker, and loading one with file:line errors. Format 2 dumps carry `count:` (the number of rows
under `parameters:`) and end with the line `end: pdrive_dump`, so a file cut off anywhere is refused;
older files (format 1, hand-written) have neither and are accepted with a warning (docs/commands.md
records the decision). Reads files through datafile.py; no bus traffic.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

DUMP_FORMAT = 2              # 2: `count:` and a final `end: pdrive_dump` line (truncation is detected)
DUMP_END = "pdrive_dump"


def dump_text(doc: dict[str, Any], output: str | Path) -> str:
    """A dump document (backup.dump) as the file's text: a comment header, then the YAML; the last line
    is `end: pdrive_dump`. The YAML by libyaml's emitter where PyYAML has it (CSafeDumper: the same
    text as SafeDumper's, tests/test_together.py, in a fifth of the time: a line of 231 Moeller
    settings), else PyYAML's own."""
    import yaml
    st = doc.get("station") or {}
    absent = doc.get("not_dumped")
    return (f"# pdrive parameter dump of station {st.get('address')} ({st.get('title', '')})\n"
            f"# restore with: pdrive param restore {st.get('address')} {output}\n"
            f"# the last line must be 'end: pdrive_dump': a file without it is incomplete\n"
            + (f"# {not_dumped_words(absent)}\n" if absent else "")
            + str(yaml.dump(doc, Dumper=getattr(yaml, "CSafeDumper", yaml.SafeDumper),
                            sort_keys=False, allow_unicode=True, width=120)))


def not_dumped_words(absent: dict[str, Any]) -> str:
    """The line for the settings a dump cannot hold (backup.not_dumped): the header's and stderr's."""
    n = len(absent["codes"])
    return (f"{n} setting(s) of the profile are not in this dump (listed under 'not_dumped'): "
            f"{absent['why']}")


def write_dump(doc: dict[str, Any], output: str | Path) -> None:
    """Write a dump document through outfile.OutputFile (the old file is replaced only when the
    whole text is written)."""
    from profidrive_cli.outfile import OutputFile
    with OutputFile(output, "w") as f:
        f.write(dump_text(doc, output))


def check_complete(path: str | Path, doc: Any, params: dict[str, Any]) -> list[str]:
    """A format-2 dump must carry `count:` = the number of parameters and end with `end: pdrive_dump`
    (so a file cut anywhere is refused). Older files have neither: accepted with a warning."""
    from profidrive_cli.datafile import DataFileError
    fmt = doc.get("pdrive_dump")
    if not isinstance(fmt, int) or isinstance(fmt, bool) or fmt < 2:
        return [f"{path} has no end marker (written by an older pdrive or by hand): pdrive cannot tell "
                f"whether it is complete; check that it lists every parameter you mean to restore"]
    keys = list(doc.keys())
    if doc.get("end") != DUMP_END or keys[-1] != "end":
        raise DataFileError(path, None, f"the file is incomplete (no final 'end: {DUMP_END}' line): it "
                            f"was cut off; dump the drive again or use an intact copy")
    count = doc.get("count")
    if not isinstance(count, int) or isinstance(count, bool) or count != len(params):
        raise DataFileError(path, doc.line_of("count") if "count" in doc else None,
                            f"the file is incomplete or edited: 'count: {count}' but {len(params)} "
                            f"parameter(s) under 'parameters'")
    return []


def load_dump(path: str | Path) -> dict[str, Any]:
    """Read a dump file; UsageError with file:line for anything that is not one."""
    from profidrive_cli.datafile import DataFileError, LineDict, load_yaml
    doc = load_yaml(path)
    if not isinstance(doc, LineDict) or "parameters" not in doc:
        raise DataFileError(path, getattr(doc, "line", 1),
                            "not a pdrive parameter file (no 'parameters:' mapping; make one with "
                            "`pdrive param dump`)")
    params = doc["parameters"]
    if params is None:
        params = LineDict()
        doc["parameters"] = params
    if not isinstance(params, dict):
        raise DataFileError(path, doc.line_of("parameters"), "'parameters' must be a mapping CODE: VALUE")
    for code, v in params.items():
        val = v.get("value") if isinstance(v, dict) else v
        if isinstance(val, bool) or not isinstance(val, (int, float)):
            line = params.line_of(code) if isinstance(params, LineDict) else None
            raise DataFileError(path, line, f"{code}: the value must be a number, got {val!r}")
    st = doc.get("station")
    if st is not None and not isinstance(st, dict):
        raise DataFileError(path, doc.line_of("station"), "'station' must be a mapping")
    doc["_warnings"] = check_complete(path, doc, params)
    doc["_path"] = str(path)
    return doc
