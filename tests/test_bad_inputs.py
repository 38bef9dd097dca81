"""Every command, given bad input, answers with one line on stderr and the documented exit code
(2 bad input, 1 bus / station / write failure), never a traceback, never a hang, and writes nothing.

The cases run pdrive as a separate process (`python -m profidrive_cli`), on real files: FIFOs, devices,
truncated and mutated GSD files, YAML files built to break a loader (bad tags, huge numbers, deep nesting,
alias bombs). Expected exit codes come from the README's promise (exit 2 for bad input, 1 for bus /
station / write problems), not from the code.
"""

from __future__ import annotations

import os
import subprocess
import time
from pathlib import Path

import pytest

from conftest import pdrive_cmd

ROOT = Path(__file__).resolve().parent.parent
YASK = ROOT / "gsd" / "YASK00CA.GSD"
FUJI_CHECKLIST = ROOT / "examples" / "checklists" / "fuji-g1.yaml"

# a checklist header that validates, so that the broken part is what the case is about
HEAD = "name: t\nstations:\n  - {address: 3, profile: fuji-g1}\nsteps:\n"


def _bomb(levels: int, key: str = "a") -> str:
    """A billion-laughs document: each level is 9 aliases of the one before (9**levels strings)."""
    lines = [f'{key}0: &{key}0 ["xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx"]']
    for i in range(1, levels + 1):
        lines.append(f"{key}{i}: &{key}{i} [" + ",".join([f"*{key}{i - 1}"] * 9) + "]")
    return "\n".join(lines) + "\n"


@pytest.fixture(scope="module")
def d(tmp_path_factory) -> Path:
    """A folder of bad input files (and one good capture)."""
    d = tmp_path_factory.mktemp("bad")
    gsd = YASK.read_bytes()
    os.mkfifo(d / "fifo.yaml")
    os.mkfifo(d / "fifo.gsd")
    os.mkfifo(d / "fifo.raw")
    (d / "folder.yaml").mkdir()
    (d / "trunc.gsd").write_bytes(gsd[:600])
    (d / "bigint.gsd").write_bytes(gsd.replace(b"Ident_Number = 0x00CA", b"Ident_Number = " + b"9" * 5000))
    (d / "bighex.gsd").write_bytes(gsd.replace(b"Ident_Number = 0x00CA", b"Ident_Number = 0x" + b"F" * 5000))
    (d / "bigoctet.gsd").write_bytes(gsd.replace(b'"Basic data" 0x72', b'"Basic data" 0x72, ' + b"1" * 4400, 1))
    with open(d / "huge.gsd", "wb") as f:           # sparse: 5 MiB on paper, nothing on disk
        f.truncate(5 * 1024 * 1024)
    with open(d / "huge.yaml", "wb") as f:
        f.truncate(5 * 1024 * 1024)
    with open(d / "huge.raw", "wb") as f:
        f.truncate(17 * 1024 * 1024)
    (d / "good.raw").write_bytes(bytes.fromhex("10 03 02 49 4e 16"))     # SD1 FDL status request 2 -> 3
    (d / "float_x.yaml").write_text(HEAD + "  - wait: !!float x\n")
    (d / "int_12a.yaml").write_text(HEAD + "  - wait: !!int '12a'\n")
    (d / "timestamp.yaml").write_text(HEAD + "  - note: !!timestamp 2020-13-45\n")
    (d / "bigint.yaml").write_text(HEAD + "  - wait: " + "1" * 5000 + "\n")
    (d / "deep.yaml").write_text(HEAD + "  - note: " + "[" * 5000 + "]" * 5000 + "\n")
    (d / "bomb.yaml").write_text(_bomb(11) + "stations: *a11\n")
    (d / "latin1.yaml").write_bytes(HEAD.encode() + b"  - note: \"Gr\xf6\xdfe\"\n")
    (d / "p_bomb.yaml").write_text("station: {profile: fuji-opc-g1-pdp}\nparameters:\n"
                                   + "".join("  " + ln + "\n" for ln in _bomb(11, "F").splitlines()))
    (d / "p_float.yaml").write_text("station: {profile: fuji-opc-g1-pdp}\nparameters:\n  F07: !!float x\n")
    (d / "p_bigint.yaml").write_text("station: {profile: fuji-opc-g1-pdp}\nparameters:\n  F07: "
                                     + "7" * 5000 + "\n")
    # config files (named by PDRIVE_CONFIG): mistakes found late still name their file:line
    (d / "cfg_baud_inf.yaml").write_text("port: sim://\nbaud: 'inf'\n")
    (d / "cfg_baud_1e999.yaml").write_text("port: sim://\nbaud: 1e999\n")
    (d / "cfg_lost_port.yaml").write_text("port: line9\nports:\n  rig: sim://\n")
    (d / "cfg_profile.yaml").write_text("port: rig\nports:\n  rig:\n    port: sim://\n"
                                        "    stations:\n      3: {profile: moeller}\n")
    (d / "cfg_layout.yaml").write_text("port: rig\nports:\n  rig:\n    port: sim://\n"
                                       "    stations:\n      3: {layout: ppo9}\n")
    (d / "cfg_master.yaml").write_text("port: sim://\nmaster_address: 3\n")
    assert len((d / "bomb.yaml").read_bytes()) < 700 and len((d / "p_bomb.yaml").read_bytes()) < 700
    gdir = d / "gsd_user"
    gdir.mkdir()
    (gdir / "YASKCUT.GSD").write_bytes(gsd[:600])                          # claims 0x00CA, truncated
    (gdir / "BIGNUM.GSD").write_bytes((d / "bigint.gsd").read_bytes())
    return d


SIM = ["--port", "sim://"]

# (id, argv with {d} for the data folder, expected exit code, expected stderr lines, marks)
# 2 stderr lines: a checklist's problems are listed one per line, then one summary line
CASES = [
    # ---- GSD files
    ("gsd-truncated", ["gsd", "show", "{d}/trunc.gsd"], 2, 1, ()),
    ("gsd-truncated-prm", ["gsd", "prm", "{d}/trunc.gsd"], 2, 1, ()),
    ("gsd-4300-digit-number", ["gsd", "show", "{d}/bigint.gsd"], 2, 1, ()),
    ("gsd-huge-hex-json", ["gsd", "show", "{d}/bighex.gsd", "--json"], 2, 1, ()),
    ("gsd-huge-octet", ["gsd", "show", "{d}/bigoctet.gsd"], 2, 1, ()),
    ("gsd-fifo", ["gsd", "show", "{d}/fifo.gsd"], 2, 1, ()),
    ("gsd-device", ["gsd", "show", "/dev/zero"], 2, 1, ()),
    ("gsd-too-large", ["gsd", "show", "{d}/huge.gsd"], 2, 1, ()),
    ("gsd-missing", ["gsd", "show", "{d}/nope.gsd"], 2, 1, ()),
    ("gsd-5000-digit-ident", ["gsd", "show", "1" * 5000], 2, 1, ()),
    ("gsd-dir-missing", ["gsd", "list", "--gsd-dir", "{d}/nope"], 2, 1, ()),
    ("gsd-env-dir-missing", ["gsd", "list", "ENV:PDRIVE_GSD_DIR={d}/nope"], 2, 1, ()),
    ("io-gsd-truncated", ["io", "3", "--gsd", "{d}/trunc.gsd", "--module", "x", *SIM], 2, 1, ()),
    # ---- checklists (YAML)
    ("checklist-float-x", ["checklist", "validate", "{d}/float_x.yaml"], 2, 2, ()),
    ("checklist-int-12a", ["checklist", "validate", "{d}/int_12a.yaml"], 2, 2, ()),
    ("checklist-bad-timestamp", ["checklist", "validate", "{d}/timestamp.yaml"], 2, 2, ()),
    ("checklist-5000-digits", ["checklist", "validate", "{d}/bigint.yaml"], 2, 2, ()),
    ("checklist-5000-deep", ["checklist", "validate", "{d}/deep.yaml"], 2, 2, ()),
    ("checklist-alias-bomb", ["checklist", "validate", "{d}/bomb.yaml"], 2, 2, ()),
    ("checklist-not-utf8", ["checklist", "validate", "{d}/latin1.yaml"], 2, 1, ()),
    ("checklist-dev-zero", ["checklist", "validate", "/dev/zero"], 2, 1, ()),
    ("checklist-fifo", ["checklist", "validate", "{d}/fifo.yaml"], 2, 1, ()),
    ("checklist-folder", ["checklist", "validate", "{d}/folder.yaml"], 2, 1, ()),
    ("checklist-too-large", ["checklist", "validate", "{d}/huge.yaml"], 2, 1, ()),
    ("checklist-run-bomb-report", ["checklist", "run", "{d}/bomb.yaml", "--dry-run", "--report",
                                   "{d}/out/r.json"], 2, 2, ()),
    # ---- parameter files
    ("restore-alias-bomb", ["param", "restore", "3", "{d}/p_bomb.yaml", *SIM], 2, 1, ()),
    ("restore-float-x", ["param", "restore", "3", "{d}/p_float.yaml", *SIM], 2, 1, ()),
    ("restore-5000-digits", ["param", "restore", "3", "{d}/p_bigint.yaml", *SIM], 2, 1, ()),
    ("restore-dev-zero", ["param", "restore", "3", "/dev/zero", *SIM], 2, 1, ()),
    ("restore-fifo", ["param", "restore", "3", "{d}/fifo.yaml", *SIM], 2, 1, ()),
    ("dump-dev-full", ["param", "dump", "3", "-o", "/dev/full", *SIM], 1, 1, ()),
    ("dump-missing-dir", ["param", "dump", "3", "-o", "{d}/out/nodir/p.yaml", *SIM], 2, 1, ()),
    # ---- profiles given as a path (decode)
    ("decode-dev-zero", ["decode", "/dev/zero", "--request", "00"], 2, 1, ()),
    ("decode-fifo", ["decode", "{d}/fifo.yaml", "--request", "00"], 2, 1, ()),
    ("decode-alias-bomb", ["decode", "{d}/bomb.yaml", "--request", "00"], 2, 1, ()),
    ("decode-bad-hex", ["decode", "moeller", "--ppo", "1", "--request", "zz"], 2, 1, ()),
    ("decode-odd-hex", ["decode", "moeller", "--ppo", "1", "--request", "301"], 2, 1, ()),
    ("decode-huge-ppo", ["decode", "moeller", "--ppo", "9" * 5000, "--request", "00"], 2, 1, ()),
    # ---- raw captures and pcap output
    ("sniff-dev-zero", ["sniff", "--from-file", "/dev/zero"], 2, 1, ()),
    ("sniff-fifo", ["sniff", "--from-file", "{d}/fifo.raw"], 2, 1, ()),
    ("sniff-too-large", ["sniff", "--from-file", "{d}/huge.raw"], 2, 1, ()),
    ("sniff-missing", ["sniff", "--from-file", "{d}/nope.raw"], 2, 1, ()),
    ("sniff-folder", ["sniff", "--from-file", "{d}"], 2, 1, ()),
    ("sniff-bad-input-no-pcap", ["sniff", "--from-file", "/dev/zero", "--pcap", "{d}/out/x.pcap"], 2, 1, ()),
    ("sniff-pcap-missing-dir", ["sniff", "--from-file", "{d}/good.raw", "--pcap", "{d}/out/nodir/x.pcap"],
     2, 1, ()),
    ("sniff-pcap-dev-full", ["sniff", "--from-file", "{d}/good.raw", "--pcap", "/dev/full"], 1, 1, ()),
    # ---- simulator endpoints
    ("sim-listen-port-99999", ["sim", "--listen", "127.0.0.1:99999"], 2, 1, ()),
    ("sim-listen-no-port", ["sim", "--listen", "localhost"], 2, 1, ()),
    ("sim-listen-bad-host", ["sim", "--listen", "no.such.host.invalid:5000"], 2, 1, ()),
    ("sim-port-missing", ["sim", "--port", "{d}/no-tty"], 1, 1, ()),
    ("sim-bad-plant", ["sim", "--pty", "--plant", "sim://?stations=999:fuji-g1"], 2, 1, ()),
    # ---- numbers and hex on the command line
    ("scan-from-999", ["scan", "--from", "999", *SIM], 2, 1, ()),
    ("scan-bad-baud", ["scan", "--baud", "7", *SIM], 2, 1, ()),
    ("io-bad-cfg-hex", ["io", "3", "--cfg", "zz", *SIM], 2, 1, ()),
    ("io-bad-prm-hex", ["io", "3", "--cfg", "F1", "--prm", "1g", *SIM], 2, 1, ()),
    ("status-address-999", ["status", "999", *SIM], 2, 1, ()),
    ("run-hz-text", ["run", "3", "--hz", "abc", *SIM], 2, 1, ()),
    ("run-hz-inf", ["run", "3", "--hz", "1e999", "--duration", "0.1", *SIM], 2, 1, ()),
    ("param-set-inf", ["param", "set", "3", "F07", "1e999", *SIM], 2, 1, ()),
    ("scan-baud-inf", ["scan", "--baud", "inf", *SIM], 2, 1, ()),
    ("scan-baud-1e999", ["scan", "--baud", "1e999", *SIM], 2, 1, ()),
    ("scan-env-baud-minus-inf", ["scan", "ENV:PDRIVE_BAUD=-inf", *SIM], 2, 1, ()),
    ("status-master-is-the-station", ["status", "3", "--master-address", "3", *SIM], 2, 1, ()),
    ("run-master-is-the-station", ["run", "3", "--hz", "5", "--duration", "0.1", "--master-address", "3",
                                   *SIM], 2, 1, ()),
    ("run-several-master-is-one", ["run", "3,4", "--hz", "5", "--duration", "0.1", "--master-address",
                                   "4", *SIM], 2, 1, ()),
    # ---- config files
    ("config-baud-inf", ["scan", "ENV:PDRIVE_CONFIG={d}/cfg_baud_inf.yaml"], 2, 1, ()),
    ("config-baud-1e999", ["scan", "ENV:PDRIVE_CONFIG={d}/cfg_baud_1e999.yaml"], 2, 1, ()),
    ("config-undefined-port-name", ["scan", "ENV:PDRIVE_CONFIG={d}/cfg_lost_port.yaml"], 2, 1, ()),
    ("config-wrong-station-profile", ["status", "3", "ENV:PDRIVE_CONFIG={d}/cfg_profile.yaml"], 2, 1, ()),
    ("config-unknown-station-layout", ["run", "3", "--hz", "5", "--duration", "0.1",
                                       "ENV:PDRIVE_CONFIG={d}/cfg_layout.yaml"], 2, 1, ()),
    ("config-master-is-the-station", ["diag", "3", "ENV:PDRIVE_CONFIG={d}/cfg_master.yaml"], 2, 1, ()),
    ("unknown-command", ["frobnicate"], 2, 1, ()),
    ("scan-missing-port", ["scan", "--port", "{d}/no-tty"], 1, 1, ()),
]


def _listing(d: Path) -> set[str]:
    return {str(p.relative_to(d)) for p in d.rglob("*")}


@pytest.mark.parametrize("argv,rc,lines", [pytest.param(a, r, n, id=i, marks=m) for i, a, r, n, m in CASES])
def test_bad_input_gives_one_line_and_exit_code(d, argv, rc, lines, tmp_path):
    (d / "out").mkdir(exist_ok=True)
    env = dict(os.environ, PDRIVE_PORT="", PDRIVE_STATION="", COLUMNS="200",
               PYTHONPATH=os.pathsep.join([str(ROOT)] + os.environ.get("PYTHONPATH", "").split(os.pathsep)))
    env.pop("PDRIVE_GSD_DIR", None)
    args = []
    for a in argv:
        a = a.replace("{d}", str(d))
        if a.startswith("ENV:"):
            k, _, v = a[4:].partition("=")
            env[k] = v
        else:
            args.append(a)
    before = _listing(d)
    t0 = time.monotonic()
    p = subprocess.run(pdrive_cmd() + args, cwd=tmp_path, env=env, capture_output=True, text=True,
                       timeout=60, stdin=subprocess.DEVNULL)
    took = time.monotonic() - t0
    err = p.stderr.splitlines()
    assert "Traceback" not in p.stderr, p.stderr[-2000:]
    assert p.returncode == rc, p.stderr
    assert len(err) == lines, p.stderr
    assert all(ln.startswith("pdrive: ") and len(ln) <= 600 for ln in err), p.stderr
    assert _listing(d) == before, "a failed command wrote a file"
    assert list(tmp_path.iterdir()) == [], "a failed command wrote a file"
    assert took < 30                                      # no hang, no alias expansion


def _run(args, env_extra=None, cwd=None):
    env = dict(os.environ, PDRIVE_PORT="", PDRIVE_STATION="", COLUMNS="200",
               PYTHONPATH=os.pathsep.join([str(ROOT)] + os.environ.get("PYTHONPATH", "").split(os.pathsep)))
    env.pop("PDRIVE_GSD_DIR", None)
    env.update(env_extra or {})
    return subprocess.run(pdrive_cmd() + args, env=env, capture_output=True, text=True, timeout=60,
                          cwd=cwd, stdin=subprocess.DEVNULL)


def test_broken_user_gsd_never_shadows_the_library(d):
    """A truncated file claiming 0x00CA and a file with a 5000-digit number in the user folder: the
    library's YASK00CA.GSD is used, one warning names the skipped file, and `scan` names the station."""
    g = d / "gsd_user"
    p = _run(["gsd", "show", "0x00CA", "--json", "--gsd-dir", str(g)])
    assert p.returncode == 0, p.stderr
    assert '"model": "PROFIBUS-DP INTERFACE CARD SI-P1"' in p.stdout      # YASK00CA.GSD, Model_Name
    assert p.stderr.count("\n") == 1 and "YASKCUT.GSD" in p.stderr and "Protocol_Ident" in p.stderr
    p = _run(["scan", "--port", "sim://?stations=7:yaskawa"], {"PDRIVE_GSD_DIR": str(g)})
    assert p.returncode == 0 and "Traceback" not in p.stderr, p.stderr
    assert "YASKAWA ELECTRIC PROFIBUS-DP INTERFACE CARD SI-P1" in " ".join(p.stdout.split())


def test_missing_env_gsd_dir_is_named_in_a_scan(d):
    """PDRIVE_GSD_DIR=/nonexistent is an error for gsd commands (as --gsd-dir is) and a warning for
    naming stations in a scan, never ignored silently."""
    p = _run(["scan", "--port", "sim://?stations=7:yaskawa"], {"PDRIVE_GSD_DIR": str(d / "nope")})
    assert p.returncode == 0
    assert p.stderr.splitlines() == [f"pdrive: warning: PDRIVE_GSD_DIR {d / 'nope'}: no such folder (ignored)"]
    p = _run(["gsd", "show", "0x00CA"], {"PDRIVE_GSD_DIR": str(d / "nope")})
    assert p.returncode == 2 and p.stderr == f"pdrive: PDRIVE_GSD_DIR {d / 'nope'}: no such folder\n"


def test_yaml_bomb_refused_fast(d):
    """The 600-byte alias bomb (9**11 strings if expanded) is refused in well under a second of work."""
    from profidrive_cli.datafile import DataFileError, load_yaml
    t0 = time.monotonic()
    with pytest.raises(DataFileError, match=r"p_bomb.yaml:4: YAML error: aliases \(\*F0\) are not supported"):
        load_yaml(d / "p_bomb.yaml")
    assert time.monotonic() - t0 < 5            # generous: the old loader took 20 s and 2.6 GB here


def test_last_line_of_defence_for_os_errors(monkeypatch, capsys):
    """An OSError that no command turned into its own message: one line with path and reason, exit 1."""
    import click

    from profidrive_cli.cli import main as main_mod

    @click.command("boom")
    def boom():
        raise PermissionError(13, "Permission denied", "/some/file")

    real_get = main_mod.LazyGroup.get_command
    monkeypatch.setattr(main_mod.LazyGroup, "get_command",
                        lambda self, ctx, name: boom if name == "boom" else real_get(self, ctx, name))
    with pytest.raises(SystemExit) as ei:
        main_mod.main(["boom"])
    assert ei.value.code == 1
    assert capsys.readouterr().err == "pdrive: /some/file: Permission denied\n"


def test_unreadable_gsd_file_is_one_line(tmp_path, monkeypatch):
    """`gsd show` on a file that cannot be opened (permission): DataFileError with path and reason.
    (Simulated: the tests may run as root, who can read anything.)"""
    from profidrive_cli import datafile
    from profidrive_cli.gsd.library import clear_cache, load_gsd
    p = tmp_path / "x.gsd"
    p.write_bytes(YASK.read_bytes())
    real_open = os.open

    def deny(path, *a, **k):
        if str(path) == str(p):
            raise PermissionError(13, "Permission denied", str(path))
        return real_open(path, *a, **k)

    monkeypatch.setattr(datafile.os, "open", deny)
    clear_cache()
    with pytest.raises(datafile.DataFileError) as ei:
        load_gsd(str(p))
    assert str(ei.value) == f"{p}: cannot read GSD file: Permission denied"
