"""Start-up work of the commands the performance issue measures (benchmarks/bench_startup.py): what they
import and which data files they read. No timing here: the assertions are about work done."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from profidrive_cli.data import gsd_dir
from profidrive_cli.gsd import library

ROOT = Path(__file__).resolve().parent.parent

# A command run in process; then the modules it loaded and the profiles it loaded in full.
_PROBE = """
import os, sys
from profidrive_cli.drives import profile as pm
real = pm.load_profile_file
def counting(path):
    print("FULL", os.path.basename(str(path)))
    return real(path)
pm.load_profile_file = counting
from profidrive_cli.cli.main import main
try:
    main(sys.argv[1:])
except SystemExit:
    pass
print("MODULES", sorted(m for m in ("rich.progress", "profidrive_cli.sim.plant", "profidrive_cli.gsd.parser",
                                    "profidrive_cli.sim.fuji", "profidrive_cli.sim.toyo",
                                    "profidrive_cli.sim.moeller", "profidrive_cli.sim.yaskawa")
                        if m in sys.modules))
"""


def _probe(*args: str) -> tuple[str, list[str]]:
    p = subprocess.run([sys.executable, "-c", _PROBE, *args], cwd=ROOT, capture_output=True, text=True,
                       timeout=120, stdin=subprocess.DEVNULL)
    assert "MODULES" in p.stdout, p.stdout + p.stderr
    return p.stdout, [line.split()[1] for line in p.stdout.splitlines() if line.startswith("FULL ")]


def test_decode_loads_only_its_profile_and_no_sim_gsd_or_progress():
    out, full = _probe("decode", "moeller", "--ppo", "1", "--request", "3017 0000 0000 0190 047F 2000")
    assert "PNU 23 = F002" in out
    assert full == ["moeller-de6-net-dp.yaml"]
    assert "MODULES []" in out


def test_a_one_station_sim_scan_does_not_load_the_other_profiles():
    """sim://?stations=3:fuji-g1: a scan asks the station for FDL status and Slave_Diag only, which
    an untouched drive answers without its model (sim/lazy.py): no profile loaded in full, no drive
    model imported; rich.progress only on a terminal (not here)."""
    out, full = _probe("scan", "--port", "sim://?stations=3:fuji-g1")
    assert "1 station(s)" in out and "0xFD01" in out, out
    assert full == []
    assert "MODULES ['profidrive_cli.sim.plant']" in out


def test_a_default_plant_scan_loads_no_profile_no_model_and_no_gsd_parser():
    out, full = _probe("scan", "--port", "sim://")
    # the five stations of the default plant, idents and names as the GSD library has them
    for ident, name in (("0xFD01", "Fuji Electric"), ("0xFD02", "OPC-PDP3"), ("0x0BE7", "Toyo Denki"),
                        ("0xFD06", "Moeller"), ("0x00CA", "YASKAWA ELECTRIC")):
        assert ident in out and name in out, out
    assert "5 station(s)" in out
    assert full == []
    assert "MODULES ['profidrive_cli.sim.plant']" in out


def test_parameterising_a_station_builds_its_model_and_loads_only_its_profile():
    out, full = _probe("io", "--port", "sim://?stations=3:fuji-g1,5:toyo", "3", "--cfg", "F3F1",
                       "--count", "1")
    assert full == ["fuji-opc-g1-pdp.yaml"], out
    assert "'profidrive_cli.sim.fuji'" in out and "'profidrive_cli.sim.toyo'" not in out


def test_naming_a_station_from_the_library_parses_no_gsd_file(monkeypatch):
    monkeypatch.delenv("PDRIVE_GSD_DIR", raising=False)
    library.clear_cache()
    parsed: list[str] = []
    real = library.parse_gsd

    def counting(path):
        parsed.append(Path(path).name)
        return real(path)
    monkeypatch.setattr(library, "parse_gsd", counting)
    assert len(library.gsd_files(gsd_dir())) == 5
    name = library.station_name(0x00CA)
    # YASK00CA.GSD lines 20-21: Vendor_Name = "YASKAWA ELECTRIC", Model_Name = "PROFIBUS-DP INTERFACE CARD SI-P1"
    assert name == "YASKAWA ELECTRIC PROFIBUS-DP INTERFACE CARD SI-P1"
    assert parsed == []
    assert library.station_name(0x4242) is None and parsed == []
    library.clear_cache()
