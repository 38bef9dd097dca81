"""pyproject.toml lists its packages by hand: every package directory under profidrive_cli/ must be in
that list, or an installed pdrive lacks it (the checkout, where the tests run, would not notice)."""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_every_package_directory_is_listed_in_pyproject():
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {".".join(init.parent.relative_to(ROOT).parts)
             for init in (ROOT / "profidrive_cli").rglob("__init__.py")}
    missing = sorted(found - listed)
    assert not missing, f"pyproject.toml [tool.setuptools] packages lacks {', '.join(missing)}"
    assert "profidrive_cli.drives.yaskawa" in found and "profidrive_cli.drives.toyo" in found
