"""Every package under profidrive_cli/ is listed in pyproject.toml (the list is explicit, because
profiles/ and gsd/ are mapped into the package): a package left out would be missing from the wheel."""

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.skipif(sys.version_info < (3, 11), reason="tomllib")
def test_every_package_is_in_the_wheel():
    import tomllib
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text())
    listed = set(conf["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts)
             for p in (ROOT / "profidrive_cli").rglob("__init__.py")}
    assert found - listed == set(), f"add to [tool.setuptools] packages: {sorted(found - listed)}"
    mapped = {"profidrive_cli.profiles", "profidrive_cli.gsd_files", "profidrive_cli.wireshark_files"}
    assert listed - found - mapped == set(), f"listed but gone: {sorted(listed - found - mapped)}"


@pytest.mark.skipif(sys.version_info < (3, 11), reason="tomllib")
def test_the_wireshark_dissector_is_package_data():
    """wireshark/pdrive.lua is carried as profidrive_cli.wireshark_files (pdrive wireshark install
    copies it from there once installed)."""
    import tomllib
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text())
    st = conf["tool"]["setuptools"]
    assert st["package-dir"]["profidrive_cli.wireshark_files"] == "wireshark"
    assert "profidrive_cli.wireshark_files" in st["packages"]
    patterns = st["package-data"]["profidrive_cli.wireshark_files"]
    import fnmatch
    assert any(fnmatch.fnmatch("pdrive.lua", pat) for pat in patterns)
    assert (ROOT / "wireshark" / "pdrive.lua").is_file()
