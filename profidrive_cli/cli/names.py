"""Naming stations: ident -> device name from the GSD library, else from a drive profile."""

from __future__ import annotations


def device_name(ident: int, gsd_dir: str | None = None) -> str:
    try:
        from profidrive_cli.gsd.library import find_by_ident
        g = find_by_ident(ident, gsd_dir)
        if g is not None:
            vendor = getattr(g, "vendor_name", "") or ""
            model = getattr(g, "model_name", "") or ""
            return f"{vendor} {model}".strip()
    except ImportError:
        pass
    from profidrive_cli.drives.profile import profile_for_ident
    p = profile_for_ident(ident)
    return p.title if p else ""
