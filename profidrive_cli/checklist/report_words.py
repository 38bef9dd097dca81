"""Words for values in the checklist reports (Markdown, HTML): a measured dict in one line, a
parameter snapshot entry, an ident in hex. Shared by report.py and report_html.py."""

from __future__ import annotations

from typing import Any, TypeVar

_T = TypeVar("_T")


def val(v: object) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, dict):
        return ", ".join(f"{k}: {val(x)}" for k, x in v.items() if x not in (None, "", [], {}))
    if isinstance(v, list):
        return "; ".join(val(x) for x in v)
    if isinstance(v, bool):
        return "yes" if v else "no"
    return "" if v is None else str(v)


def snap(e: dict[str, Any] | None) -> str:
    if not e:
        return "—"
    if "error" in e:
        return f"error: {e['error']}"
    return f"{val(e['value'])}{(' ' + e['unit']) if e.get('unit') else ''}"


def hexv(v: _T) -> _T | str:
    return f"0x{v:04X}" if isinstance(v, int) and not isinstance(v, bool) else v


__all__ = ["val", "snap", "hexv"]
