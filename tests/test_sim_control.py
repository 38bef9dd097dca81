"""Steering the simulator while a master runs (issue 29; sim/control.py): trip a drive, clear its fault,
unplug and replug a station, change a setting, inject faults, read the plant -- from the Python API
(Bus.simulator, in process), and over HTTP (`pdrive sim --control`, `pdrive sim-ctl`) while `pdrive run`
runs against `pdrive sim --pty`."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

import profidrive_cli as pdrive
from profidrive_cli.sim.control import ControlError

ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.usefixtures("no_config_at_all")


# -- in process -------------------------------------------------------------------------------------

def test_a_trip_through_the_api_is_seen_by_the_running_drive() -> None:
    with pdrive.open_bus("sim://?timing=virtual") as bus:
        drive = bus.drive(3)
        drive.run(hz=10, wait=True, timeout=30)
        assert bus.simulator.trip(3, "OC1") == {"station": 3, "tripped": "OC1"}
        st = drive.status()
        # fuji-opc-g1-pdp.yaml alarms: OC1 is "overcurrent during acceleration"; the card reports
        # it in its status (fault bit, alarm code)
        assert st.fault and st.fault_code is not None and "OC1" in st.fault_code
        bus.simulator.clear(3)
        assert not drive.status().fault


def test_unplug_and_replug_a_station() -> None:
    with pdrive.open_bus("sim://?timing=virtual") as bus:
        sim = bus.simulator
        sim.unplug(5)
        assert [s.station for s in bus.scan(3, 7)] == [3, 4, 6, 7]
        row = {r["station"]: r for r in sim.state()["stations"]}[5]
        assert row["plugged"] is False
        with pytest.raises(ControlError, match="station 5 is unplugged"):
            sim.trip(5)
        sim.replug(5)
        found = {s.station: s.state for s in bus.scan(3, 7)}
        assert sorted(found) == [3, 4, 5, 6, 7]
        # plugged back in: as after power-up, waiting for its parameters (Wait_Prm)
        assert "parameters" in str(found[5]).lower() or "prm" in str(found[5]).lower(), found[5]


def test_set_a_value_is_checked_and_read_back() -> None:
    with pdrive.open_bus("sim://?timing=virtual") as bus:
        drive = bus.drive(3)
        bus.simulator.set(3, "F07", 12.5)
        assert drive.param("F07").value == 12.5
        # F07 has 0.1 s steps (fuji-opc-g1-pdp.yaml, scale 0.1): 12.55 cannot be held exactly
        with pytest.raises(ControlError, match="set station 3"):
            bus.simulator.set(3, "F07", 12.55)
        with pytest.raises(ControlError, match="not a parameter"):
            bus.simulator.set(3, "NOPE", 1)


def test_faults_are_injected_and_cleared() -> None:
    with pdrive.open_bus("sim://?timing=virtual") as bus:
        assert bus.simulator.faults("drop=1,only=4") == {"faults": {"drop": 1.0}, "faults_only": [4],
                                                         "faults_spec": "drop=1,only=4"}
        assert [s.station for s in bus.scan(3, 5)] == [3, 5]       # every reply of 4 dropped
        assert bus.simulator.faults("only=4,3,drop=1") == {"faults": {"drop": 1.0}, "faults_only": [3, 4],
                                                           "faults_spec": "drop=1,only=3,4"}
        assert [s.station for s in bus.scan(3, 5)] == [5]
        assert bus.simulator.faults("late=0.5,late_ms=50,tripcode=3:OC2,unplug=6@5-8")["faults_spec"] \
            == "late=0.5,late_ms=50,tripcode=3:OC2,unplug=6@5-8"
        assert bus.simulator.faults("") == {"faults": {}, "faults_only": None, "faults_spec": ""}
        assert [s.station for s in bus.scan(3, 5)] == [3, 4, 5]
        with pytest.raises(ControlError, match="unknown option 'bogus'"):
            bus.simulator.faults("bogus=1")


def test_bad_commands_are_one_line() -> None:
    with pdrive.open_bus("sim://?timing=virtual") as bus:
        sim = bus.simulator
        for call, match in ((lambda: sim.call("explode"), "unknown command 'explode'"),
                            (lambda: sim.call("trip", {}), "'station' is missing"),
                            (lambda: sim.call("trip", {"station": 3, "x": 1}), "unknown argument 'x'"),
                            (lambda: sim.trip(99), "no station 99"),
                            (lambda: sim.trip(3, "NOPE"), "unknown alarm 'NOPE'")):
            with pytest.raises(ControlError, match=match) as ei:
                call()
            assert "\n" not in str(ei.value)


def test_a_real_port_has_no_simulator(monkeypatch) -> None:
    with pdrive.open_bus("sim://?timing=virtual") as bus:
        monkeypatch.setattr(bus.master.link, "bus", None)
        assert bus.simulator is None


# -- over HTTP, with pdrive run on a pty ----------------------------------------------------------

def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("PDRIVE_")}
    env["PYTHONPATH"] = str(ROOT)
    return env


def _pdrive(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "profidrive_cli", *args], capture_output=True,
                          text=True, env=_env(), timeout=timeout)


@pytest.fixture()
def served(request):
    host = getattr(request, "param", "127.0.0.1")
    p = subprocess.Popen([sys.executable, "-m", "profidrive_cli", "sim", "--pty", "--control",
                          f"{host}:0", "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True, env=_env())
    try:
        assert p.stdout is not None
        info = json.loads(p.stdout.readline())
        yield info
    finally:
        p.terminate()
        try:
            p.wait(timeout=30)
        except subprocess.TimeoutExpired:
            p.kill()


def _where(info: dict) -> str:
    return info["control"].removeprefix("http://")


@pytest.mark.skipif(os.name != "posix", reason="pdrive sim --pty")
def test_a_trip_through_sim_ctl_is_reported_by_a_running_pdrive_run(served) -> None:
    run = subprocess.Popen([sys.executable, "-m", "profidrive_cli", "run", "3", "--hz", "10",
                            "--duration", "120", "--port", served["port"], "--yes"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env())
    try:
        # wait until the drive runs (the plant's state says so), then trip it
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            st = json.loads(_pdrive("sim-ctl", "--control", _where(served), "state", "--json").stdout)
            row = {r["station"]: r for r in st["stations"]}[3]
            if row.get("hz", 0) > 0:
                break
            assert run.poll() is None, run.communicate()
            time.sleep(0.2)
        trip = _pdrive("sim-ctl", "--control", _where(served), "trip", "3", "OC1")
        assert trip.returncode == 0, trip.stderr
        assert trip.stdout.strip() == "station 3, tripped OC1"
        out, err = run.communicate(timeout=120)
    finally:
        if run.poll() is None:
            run.kill()
    assert run.returncode == 1, out + err
    assert "the drive tripped (OC1)" in err, err


# (a control off loopback and its token: tests/test_sim_server_limits.py, bound to loopback only)


@pytest.mark.skipif(os.name != "posix", reason="pdrive sim --pty")
def test_sim_ctl_bad_input_is_one_line(served) -> None:
    where = _where(served)
    for args, code, words in (
            (("state",), 2, "no --control"),
            (("--control", where, "trip"), 2, "takes STATION ALARM"),
            (("--control", where, "trip", "x3"), 2, "station 'x3' is not an address"),
            (("--control", where, "trip", "42"), 2, "no station 42"),
            (("--control", where, "set", "3", "F07", "fast"), 2, "'fast' is not a number"),
            (("--control", "127.0.0.1:1", "state"), 1, "no simulator control at 127.0.0.1:1"),
            # a --control that is no HOST:PORT is bad input, as for `pdrive sim --control` (issue 34)
            (("--control", "nonsense", "state"), 2, "--control needs HOST:PORT"),
            (("--control", "127.0.0.1:0", "state"), 2, "PORT 1..65535"),
            (("--control", "127.0.0.1:99999", "state"), 2, "--control needs HOST:PORT"),
            # no HOST urllib can put in a URL (it raised ValueError: a traceback)
            (("--control", "ftp://x:1", "state"), 2, "not HOST:PORT")):
        p = _pdrive("sim-ctl", *args)
        assert p.returncode == code, (args, p.stderr)
        assert p.stderr.count("\n") == 1 and words in p.stderr and "Traceback" not in p.stderr, p.stderr
    bad = _pdrive("sim", "--pty", "--control", "nowhere")
    assert bad.returncode == 2 and "--control needs HOST:PORT" in bad.stderr


@pytest.mark.skipif(os.name != "posix", reason="pdrive sim --pty")
def test_sim_ctl_takes_the_control_url_the_simulator_printed(served) -> None:
    # `pdrive sim --control` prints http://HOST:PORT; pasting it was a traceback (Invalid IPv6 URL)
    p = _pdrive("sim-ctl", "--control", served["control"], "state", "--json")
    assert p.returncode == 0, p.stderr
    assert 3 in {r["station"] for r in json.loads(p.stdout)["stations"]}


@pytest.mark.skipif(os.name != "posix", reason="pdrive sim --pty")
def test_sim_ctl_faults_says_what_it_applied_in_the_words_it_takes(served) -> None:
    """issue 34: `sim-ctl faults` echoed a Python dict ({'drop': 0.1}) and left out only=."""
    where = _where(served)
    p = _pdrive("sim-ctl", "--control", where, "faults", "drop=0.1,only=3,4")
    assert p.returncode == 0, p.stderr
    assert p.stdout == "faults drop=0.1,only=3,4\n"
    st = _pdrive("sim-ctl", "--control", where, "state")
    assert st.stdout.splitlines()[-1] == "faults: drop=0.1,only=3,4"
    js = json.loads(_pdrive("sim-ctl", "--control", where, "state", "--json").stdout)
    assert (js["faults"], js["faults_only"], js["faults_spec"]) == ({"drop": 0.1}, [3, 4], "drop=0.1,only=3,4")
    p = _pdrive("sim-ctl", "--control", where, "faults", "")
    assert p.returncode == 0 and p.stdout == "faults none\n", p.stderr
