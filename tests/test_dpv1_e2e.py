"""DP-V1 end to end (issue 39's done-when): the commands a user types, on the generic PROFIdrive V4
axis (profiles/profidrive-dpv1.yaml, sim/dpv1_axis.py) whose parameters travel only over class-1
Read/Write of data record 47.

Expected values come from the profile (its `values:` for PNU 964 and its P-parameter defaults, as the
simulator's table is built from them) and from the PROFIdrive profile's numbering of PNU 964
(subindex 0 manufacturer, 1 drive unit type, 2 version xxyy, 3 year, 4 ddmm, 5 drive objects);
never from the master's code.
"""

from __future__ import annotations

import json

import pytest
import yaml

from conftest import TcpSim, pty_sim_process, run_main, run_pdrive

ADDR = 9
PLANT = f"sim://?stations={ADDR}:profidrive-dpv1"

#: profiles/profidrive-dpv1.yaml PNU964 values: [42, 0x8158, 300, 2007, 1707, 1]
IDENT_TEXT = "manufacturer 42, drive unit type 0x8158, firmware 3.00 of 2007-07-17, 1 drive object"


def _profile_param(code: str) -> dict:
    from pathlib import Path
    doc = yaml.safe_load((Path(__file__).parents[1] / "profiles" / "profidrive-dpv1.yaml").read_text())
    return next(p for p in doc["parameters"] if p["code"] == code)


def test_param_get_pnu964_is_the_device_identification_over_ds47(capsys, monkeypatch):
    r = run_main(capsys, monkeypatch, "param", "get", ADDR, "PNU964", "--json", "--port", PLANT)
    assert r.exit_code == 0, r.output
    (p,) = json.loads(r.stdout)["parameters"]
    assert p["code"] == "PNU964" and p["raw"] == 42 and p["text"] == IDENT_TEXT
    # one element on its own: subindex 1, the drive unit type
    r = run_main(capsys, monkeypatch, "param", "get", ADDR, "PNU964[1]", "--json", "--port", PLANT)
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["parameters"][0]["raw"] == 0x8158


@pytest.mark.parametrize("timing", ["", "&baud=19200&timing=virtual"])
def test_param_set_of_a_writable_parameter_is_read_back(capsys, monkeypatch, timing):
    """At 19.2k the Write telegram alone (25 octets x 11 bits = 14.3 ms) outlasts the profile's
    10 ms C1_Response_Timeout: the timeout counts from the slave's acknowledgement."""
    port = PLANT + timing
    p102 = _profile_param("P102")
    assert p102["access"] == "rw"
    new = 7.5 if p102.get("default") != 7.5 else 8.5
    r = run_main(capsys, monkeypatch, "param", "set", ADDR, "P102", new, "--yes", "--port", port)
    assert r.exit_code == 0, r.output
    assert f"= {new:.2f}" in r.stdout or f"= {new:g}" in r.stdout, r.stdout
    # a fresh connection on the same plant would not keep the value (a new sim:// plant per
    # command); the write's own read-back is what `param set` prints above


def test_a_busy_drive_is_waited_out(capsys, monkeypatch):
    """busy=0.5: the axis answers Read DS47 with 'state conflict' (80 B5) for 0.5 s after each
    Write; the master polls it out (the profile's timeout_s 2 s) and gets the value."""
    port = PLANT + f"&set={ADDR}:busy=0.5"
    r = run_main(capsys, monkeypatch, "param", "get", ADDR, "PNU918", "--json", "--port", port)
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["parameters"][0]["raw"] == ADDR      # PNU 918: the station address


def test_a_class1_timeout_is_one_line_exit_1_and_the_drive_left_safe(capsys, monkeypatch):
    port = PLANT + f"&set={ADDR}:c1_silent=1"
    r = run_main(capsys, monkeypatch, "param", "get", ADDR, "PNU964", "--port", port)
    assert r.exit_code == 1
    assert r.stdout == "" and len(r.stderr.strip().splitlines()) == 1, r.output
    assert "C1_Response_Timeout" in r.stderr and "Traceback" not in r.stderr
    # a write that times out: refused in one line, and the drive's outputs at their safe state
    r = run_main(capsys, monkeypatch, "param", "set", ADDR, "P102", 5, "--yes", "--port", port)
    assert r.exit_code == 1 and len(r.stderr.strip().splitlines()) == 1, r.output
    # status still works: the max frequency (P100) is the profile default, said so
    r = run_main(capsys, monkeypatch, "status", ADDR, "--json", "--port", port)
    assert r.exit_code == 0, r.output
    st = json.loads(r.stdout)
    assert st["stopped"] is True and st["running"] is False and st["fault"] is False
    assert st["fmax_hz"] == 50.0                       # the profile's default_hz
    assert st["fmax_source"].startswith("the profile default (P100 could not be read")


def test_run_refuses_to_start_without_its_max_frequency_and_nothing_turns(capsys, monkeypatch):
    """A Hz reference needs P100; over a silent class-1 channel it cannot be read: run ends in one
    line with exit 1 before any start command (the axis never leaves S1/S2)."""
    port = PLANT + f"&set={ADDR}:c1_silent=1"
    r = run_main(capsys, monkeypatch, "run", ADDR, "--hz", 10, "--duration", 1, "--yes", "--port", port)
    assert r.exit_code == 1 and "C1_Response_Timeout" in r.stderr, r.output
    assert "S4" not in r.stdout and "operation" not in r.stdout


def test_the_dpv1_axis_over_a_pty():
    """The same commands over `pdrive sim --pty` (a real byte path, its own process)."""
    with pty_sim_process("--plant", PLANT) as pty:
        r = run_pdrive("param", "get", ADDR, "PNU964", "--json", "--port", pty)
        assert r.returncode == 0, r.stderr
        assert json.loads(r.stdout)["parameters"][0]["text"] == IDENT_TEXT
        r = run_pdrive("param", "set", ADDR, "P103", 6.5, "--yes", "--port", pty)
        assert r.returncode == 0, r.stderr
        r = run_pdrive("param", "get", ADDR, "P103", "--json", "--port", pty)
        assert r.returncode == 0, r.stderr
        assert json.loads(r.stdout)["parameters"][0]["value"] == pytest.approx(6.5)   # kept by the plant


def test_fleet_dump_reads_ds47_drives_beside_pkw_drives_in_the_same_rounds(capsys, monkeypatch, tmp_path):
    """session/together.py: each telegram of a DS47 call is its station's part of a round, beside a
    Fuji's PKW exchanges (station 3); the values are the profiles' defaults."""
    port = f"sim://?stations=3,{ADDR}:profidrive-dpv1,10:profidrive-dpv1&baud=19200&timing=virtual"
    r = run_main(capsys, monkeypatch, "param", "fleet", "dump", f"3,{ADDR},10", "-o", tmp_path,
                 "--port", port)
    assert r.exit_code == 0, r.output
    for a in (ADDR, 10):
        doc = yaml.safe_load((tmp_path / f"station-{a:03d}.yaml").read_text())
        got = doc["parameters"]
        assert got["P102"]["value"] == pytest.approx(_profile_param("P102")["default"])
        assert got["P100"]["value"] == pytest.approx(_profile_param("P100")["default"])
    assert (tmp_path / "station-003.yaml").exists()


def test_the_api_reads_a_ds47_drive_through_the_one_door():
    from profidrive_cli.api import open_bus
    with open_bus(PLANT) as bus:
        got = bus.read_params({ADDR: ["P104", "PNU964"]})
        assert got[ADDR]["P104"].value == pytest.approx(_profile_param("P104")["default"])
        assert got[ADDR]["PNU964"].text == IDENT_TEXT


def test_the_dpv1_axis_over_socket():
    """`pdrive sim --listen`'s byte path (replies in TCP segments) in its own thread: the SC after a
    request and the polls come as a converter delivers them."""
    with TcpSim(PLANT) as srv:
        r = run_pdrive("param", "get", ADDR, "PNU964", "--json", "--port", srv.url)
        assert r.returncode == 0, r.stderr
        assert json.loads(r.stdout)["parameters"][0]["text"] == IDENT_TEXT
        r = run_pdrive("param", "set", ADDR, "P104", 2.5, "--yes", "--port", srv.url)
        assert r.returncode == 0, r.stderr
        r = run_pdrive("param", "get", ADDR, "P104", "--json", "--port", srv.url)
        assert json.loads(r.stdout)["parameters"][0]["value"] == pytest.approx(2.5)


def test_a_tripped_axis_names_its_fault_over_ds47(capsys, monkeypatch):
    """trip=9:OV: status reads the fault number from PNU 947 subindex 0 (profile fault_memory) over
    DS47 and names it with the profile's alarm table (number 2 = OV, DC-link overvoltage)."""
    r = run_main(capsys, monkeypatch, "status", ADDR, "--json", "--port", PLANT + f"&trip={ADDR}:OV")
    assert r.exit_code == 0, r.output
    st = json.loads(r.stdout)
    assert st["fault"] is True and st["fault_code"] == "OV"


def test_a_users_own_profile_turns_dpv1_on_for_another_drive(capsys, monkeypatch, tmp_path):
    """"By profile": a user's profile in $PDRIVE_PROFILE_PATH with a `profidrive.dpv1:` entry (here
    a small one of their own: two parameters, telegram 1) reads the axis over DS47 -- no switch
    needed and nothing of pdrive's own changed."""
    (tmp_path / "my-axis.yaml").write_text(
        "profile: my-axis\nfamily: profidrive\ntitle: my own DP-V1 axis\n"
        "identity: {ident: 0x8158}\nword_order: big\n"
        "layouts:\n  tel1: {cfg: \"E1 D1\", pkw: false}\ndefault_layout: tel1\n"
        "max_frequency: {param: FMAX, default_hz: 50.0}\n"
        "profidrive:\n  labels: {control: STW1, status: ZSW1, reference: NSOLL_A, actual: NIST_A}\n"
        "  dpv1: {slot: 0, axis: 1, c1_timeout_ms: 10}\n"
        "parameters:\n"
        "  - {code: FMAX, name: Maximum frequency, pnu: 100, unit: Hz, scale: 0.01, min: 10, max: 400, access: stop}\n"
        "  - {code: RAMP_UP, name: Ramp-up time, pnu: 102, unit: s, scale: 0.01, min: 0.1, max: 600, access: rw}\n"
        "  - {code: ADDR, name: Station address, pnu: 918, index: 0, access: ro}\n")
    monkeypatch.setenv("PDRIVE_PROFILE_PATH", str(tmp_path))
    r = run_main(capsys, monkeypatch, "param", "get", ADDR, "RAMP_UP", "ADDR", "FMAX", "--profile", "my-axis",
                 "--json", "--port", PLANT)
    assert r.exit_code == 0, r.output
    got = {p["code"]: p for p in json.loads(r.stdout)["parameters"]}
    assert got["RAMP_UP"]["value"] == pytest.approx(_profile_param("P102")["default"])
    assert got["ADDR"]["raw"] == ADDR
    assert got["FMAX"]["value"] == pytest.approx(_profile_param("P100")["default"])


@pytest.mark.parametrize("seed", range(1, 9))
def test_a_dump_over_a_noisy_line_equals_the_clean_one(capsys, monkeypatch, tmp_path, seed):
    """Dropped, garbled and noisy replies (5 %, 2 %, 3 %): an MSAC_C1 answer spoilt on the line
    (its telegram and its FDL retry) is gone for good, as the slave has handed it out. The DS47
    request is sent once more (drives/profidrive/drive.py DS47_REPEATS), and a poll with no reply is
    asked again (dp/acyclic.py SILENT_POLLS); the dump is the same as on a clean line. (Seed 6 lost
    P105 before.)"""
    clean, noisy = tmp_path / "clean.yaml", tmp_path / "noisy.yaml"
    r = run_main(capsys, monkeypatch, "param", "dump", ADDR, "-o", clean, "--port", PLANT)
    assert r.exit_code == 0, r.output
    r = run_main(capsys, monkeypatch, "param", "dump", ADDR, "-o", noisy, "--port",
                 PLANT + f"&drop=0.05&noise=0.03&flip=0.02&seed={seed}")
    assert r.exit_code == 0, r.output
    a, b = (yaml.safe_load(p.read_text()) for p in (clean, noisy))
    assert "unreadable" not in b
    assert a["parameters"] == b["parameters"] and a.get("values") == b.get("values")


def test_a_max_frequency_read_again_after_a_failure_is_no_longer_said_unread(monkeypatch):
    """Drive.fmax_unread says why the codec uses the profile default; once the drive's own value is
    read (after P100 was written, say), it is cleared: motion must not keep calling it unread."""
    from conftest import drive_on_bus
    from profidrive_cli.dp.poller import Master
    from profidrive_cli.drives.base import DriveError
    from profidrive_cli.drives.profile import load_profile
    from profidrive_cli.fdl.timing import BusParams
    from profidrive_cli.link import open_link
    m = Master(open_link("sim://?stations=3:fuji-g1"), BusParams.for_baud(19200))
    try:
        d = drive_on_bus(m, 3, load_profile("fuji-g1"), "ppo1", wd_ms=5000)
        real = type(d).max_frequency

        def fails(self):
            raise DriveError("F03: no answer")
        monkeypatch.setattr(type(d), "max_frequency", fails)
        d._ensure_fmax()
        assert d.fmax_unread == "F03: no answer"
        assert d._fmax == load_profile("fuji-g1").max_frequency_default
        monkeypatch.setattr(type(d), "max_frequency", real)
        d._fmax = None                                  # as a write of F03 forgets it
        d._ensure_fmax()
        assert d.fmax_unread is None
    finally:
        m.link.close()
