"""The Python API (profidrive_cli.api, docs/api.md): open_bus / Bus / Drive on the simulator, the safe
stop on every way out of the `with` block, the keep-alive of opened drives, the write checks (exact
values, dangerous parameters, real ports), and the lazy export from the package.

Expected values: the default plant (stations 3..7; sim/plant.py) and the Fuji profile's parameter
table (F03 = 60.0 Hz default, F07 in steps of 0.1 s, H03 data initialisation is dangerous).
Most tests use the virtual-time simulator (sim://?timing=virtual: the same code, no real waiting).
"""

from __future__ import annotations

import dataclasses
import threading
import time

import pytest

import profidrive_cli as pdrive
from profidrive_cli import UsageError
from profidrive_cli.drives.base import DriveError

from conftest import pty_sim_process

SIM = "sim://?timing=virtual"


#: the tests must not see the developer's own config files or PDRIVE_* settings
pytestmark = pytest.mark.usefixtures("no_config_at_all")


def _model(bus, address):
    return bus.master.link.bus.slave(address).model


def _sim_slave(bus, address):
    return bus.master.link.bus.slave(address)


def test_scan_lists_the_default_plant_with_idents_and_profiles():
    with pdrive.open_bus(SIM) as bus:
        found = bus.scan()
    by = {s.station: s for s in found}
    assert sorted(by) == [3, 4, 5, 6, 7]
    assert by[3].ident == 0xFD01 and by[3].ident_hex == "0xFD01" and by[3].profile == "fuji-opc-g1-pdp"
    assert by[7].ident == 0x00CA and by[7].ident_hex == "0x00CA" and by[7].profile == "yaskawa-si-p1"
    assert all(s.kind == "slave" for s in found)
    assert by[3].to_dict()["ident_hex"] == "0xFD01"


def test_results_are_frozen_dataclasses():
    with pdrive.open_bus(SIM) as bus:
        st = bus.drive(3).status()
    assert dataclasses.is_dataclass(st)
    with pytest.raises(dataclasses.FrozenInstanceError):
        st.running = True          # type: ignore[misc]


def test_status_at_rest_and_the_profile_from_the_ident():
    with pdrive.open_bus(SIM) as bus:
        d = bus.drive(3)
        st = d.status()
        assert bus.drive(3) is d                     # the same station twice: the same Drive
    assert d.profile == "fuji-opc-g1-pdp" and d.ident_hex == "0xFD01" and d.station == 3
    assert st.station == 3 and not st.running and st.stopped and not st.fault
    assert st.fmax_hz == 60.0                        # F03 default
    assert st.actual_hz == 0.0
    assert isinstance(st.flags, tuple) and all(isinstance(f, str) for f in st.flags)
    assert set(st.counters) >= {"retries", "no_answer", "illegal", "reparams"}


def test_a_profile_of_another_device_is_refused():
    with pdrive.open_bus(SIM) as bus:
        with pytest.raises(UsageError, match="not toyo"):
            bus.drive(3, profile="toyo-pbus66z")


def test_run_wait_reaches_the_speed_and_stop_stops_it():
    with pdrive.open_bus(SIM) as bus:
        d = bus.drive(3)
        st = d.run(hz=30, wait=True, timeout=30)
        assert st.running and abs(st.actual_hz - 30.0) <= 0.3      # within 1 % of the reference
        assert _model(bus, 3).freq == pytest.approx(30.0, abs=0.3)
        r = d.stop()
        assert r.how == "normal" and r.stopped
        assert _model(bus, 3).freq == 0.0
        assert not d.status().running


def test_run_percent_and_a_speed_above_fmax_is_refused_not_clipped():
    with pdrive.open_bus(SIM) as bus:
        d = bus.drive(3)
        with pytest.raises(UsageError, match="above the maximum frequency 60 Hz"):
            d.run(hz=61)
        with pytest.raises(UsageError, match="one of them"):
            d.run(hz=10, percent=10)
        assert _model(bus, 3).freq == 0.0                # nothing started
        st = d.run(percent=25, wait=True, timeout=30)
        assert st.actual_hz == pytest.approx(15.0, abs=0.15)   # 25 % of 60 Hz


def test_run_wait_timeout_raises_and_the_with_block_still_stops_the_drive():
    with pytest.raises(DriveError, match="not reached within 0.2 s"):
        with pdrive.open_bus(SIM) as bus:
            d = bus.drive(3)
            d.run(hz=50, wait=True, timeout=0.2)     # F07 = 6 s to 60 Hz: 50 Hz takes 5 s
    assert _model(bus, 3).freq == 0.0
    assert d._station.motion.stop_report.how in ("normal", "coast") and d._station.motion.stop_report.stopped


@pytest.mark.parametrize("exc", [RuntimeError("boom"), KeyboardInterrupt()])
def test_an_exception_inside_the_with_stops_every_started_drive(exc):
    with pytest.raises(type(exc)):
        with pdrive.open_bus(SIM) as bus:
            d3 = bus.drive(3)
            d5 = bus.drive(5)
            d3.run(hz=30, wait=True, timeout=30)
            d5.run(hz=20, wait=True, timeout=30)
            assert _model(bus, 3).freq > 29 and _model(bus, 5).freq > 19
            raise exc
    assert _model(bus, 3).freq == 0.0 and _model(bus, 5).freq == 0.0
    for d in (d3, d5):
        assert d._station.motion.stop_report.stopped
    assert bus.closed
    with pytest.raises(UsageError, match="closed"):
        d3.status()


def test_close_without_a_with_block_stops_too():
    bus = pdrive.open_bus(SIM)
    d = bus.drive(3)
    d.run(hz=20, wait=True, timeout=30)
    bus.close()
    bus.close()                                      # idempotent
    assert _model(bus, 3).freq == 0.0


def test_drive_close_stops_and_releases_only_that_drive():
    with pdrive.open_bus(SIM) as bus:
        d3, d5 = bus.drive(3), bus.drive(5)
        d3.run(hz=20, wait=True, timeout=30)
        d5.run(hz=20, wait=True, timeout=30)
        r = d3.close()
        assert r is not None and r.stopped
        assert _model(bus, 3).freq == 0.0 and _model(bus, 5).freq > 19
        assert bus.drives == [d5]
        assert d5.status().running


def test_params_read_write_exact_and_dangerous():
    with pdrive.open_bus(SIM) as bus:
        d = bus.drive(3)
        before = d.param("F07")
        assert before.code == "F07" and before.unit == "s"
        with pytest.raises(UsageError, match="cannot be held exactly"):
            d.set_param("F07", 5.001)                # resolution 0.1 s: refused, never rounded
        assert d.param("F07").raw == before.raw      # nothing written
        new = d.set_param("F07", 5.0)
        assert new.value == 5.0 and new.raw == 50
        assert d.param("F07").raw == 50
        with pytest.raises(UsageError, match="dangerous"):
            d.set_param("H03", 1)
        with pytest.raises(UsageError):
            d.param("NOPE99")


def test_faults_returns_the_history():
    with pdrive.open_bus(SIM) as bus:
        f = bus.drive(3).faults()
    assert f.station == 3 and not f.fault and f.fault_code is None
    assert f.history == ()                    # a fresh drive: every slot reads 0, "no alarm"
    with pdrive.open_bus("sim://?stations=3:fuji-g1&trip=3:OC1") as bus:
        f = bus.drive(3).faults()
    assert f.fault and [x.codes for x in f.history] == [("OC1",)]


def test_an_idle_drive_is_kept_in_data_exchange_between_calls():
    # real-time simulator: nobody calls for 1.2 s, longer than twice the 500 ms DP watchdog
    with pdrive.open_bus("sim://") as bus:
        d = bus.drive(3)
        d.set_param("F07", 0.5)                      # ramps of 0.5 s to 60 Hz: a short test
        d.set_param("F08", 0.5)
        d.run(hz=10, wait=True, timeout=30)
        slave = _sim_slave(bus, 3)
        n0 = slave.stats["data_exchange"]
        time.sleep(1.2)
        n1 = slave.stats["data_exchange"]
        assert slave.stats["watchdog_expired"] == 0
        assert n1 - n0 >= 6                          # at least one exchange per 0.2 s
        assert d.status().running and _model(bus, 3).freq == pytest.approx(10.0, abs=0.1)
    assert _model(bus, 3).freq == 0.0


def test_work_on_one_drive_keeps_the_other_in_data_exchange():
    # virtual time: 20 parameter reads of station 4 take well over the 500 ms watchdog of station 3
    with pdrive.open_bus(SIM) as bus:
        d3, d4 = bus.drive(3), bus.drive(4)
        d3.run(hz=30, wait=True, timeout=30)
        t0 = bus.master.link.now()
        for _ in range(20):
            d4.param("F07")
        assert bus.master.link.now() - t0 > 1.0
        assert _sim_slave(bus, 3).stats["watchdog_expired"] == 0
        assert _model(bus, 3).freq == pytest.approx(30.0, abs=0.3)


def test_calls_from_two_threads_are_serialised():
    with pdrive.open_bus(SIM) as bus:
        d3, d4 = bus.drive(3), bus.drive(4)
        errors = []

        def reader(d):
            try:
                for _ in range(10):
                    d.param("F07")
            except Exception as e:      # noqa: BLE001
                errors.append(e)
        ts = [threading.Thread(target=reader, args=(d,)) for d in (d3, d4)]
        for t in ts:
            t.start()
        for t in ts:
            t.join(timeout=60)
        assert not errors


def test_a_real_port_refuses_writes_unless_allowed():
    with pty_sim_process() as port:
        with pdrive.open_bus(port) as bus:
            d = bus.drive(3)
            assert not d.status().running
            with pytest.raises(UsageError, match="allow_real_port_writes=True"):
                d.run(hz=10)
            with pytest.raises(UsageError, match="allow_real_port_writes=True"):
                d.set_param("F07", 5.0)
            assert d.param("F07").value == 6.0       # nothing written
        with pdrive.open_bus(port, allow_real_port_writes=True) as bus:
            d = bus.drive(3)
            st = d.run(hz=10, wait=True, timeout=30)
            assert st.running and abs(st.actual_hz - 10.0) <= 0.1
        # the bus closed with the drive running: it was stopped on the way out
        with pdrive.open_bus(port) as bus:
            assert not bus.drive(3).status().running


def test_named_port_from_the_config_file(tmp_path, monkeypatch):
    (tmp_path / "pdrive.yaml").write_text(
        "ports:\n  rig:\n    port: 'sim://?timing=virtual'\n    baud: 187500\n"
        "    stations:\n      3: {profile: fuji-g1}\n")
    sub = tmp_path / "a" / "b"
    sub.mkdir(parents=True)
    monkeypatch.chdir(sub)                           # the nearest pdrive.yaml up the tree
    monkeypatch.delenv("PDRIVE_CONFIG")
    with pdrive.open_bus("rig") as bus:
        assert bus.baud == 187500
        d = bus.drive(3)
        assert d.profile == "fuji-opc-g1-pdp"


def test_bad_arguments_are_usage_errors():
    with pytest.raises(UsageError, match="no port"):
        pdrive.open_bus(None)
    with pytest.raises(UsageError, match="baud"):
        pdrive.open_bus(SIM, baud="77")
    with pdrive.open_bus(SIM) as bus:
        with pytest.raises(UsageError, match="0..125"):
            bus.drive(126)
        d = bus.drive(3)
        with pytest.raises(UsageError, match="not a speed"):
            d.run(hz=float("nan"))
        with pytest.raises(UsageError, match="not a value"):
            d.set_param("F07", None)                 # type: ignore[arg-type]


def test_sigterm_inside_the_with_stops_the_drive(tmp_path):
    import os
    import signal
    import subprocess
    import sys
    from pathlib import Path
    root = Path(__file__).resolve().parent.parent
    script = tmp_path / "rig.py"
    script.write_text(
        "import time\n"
        "import profidrive_cli as pdrive\n"
        "try:\n"
        "    with pdrive.open_bus('sim://') as bus:\n"
        "        sim = bus.master.link.bus\n"
        "        d = bus.drive(3)\n"
        "        d.set_param('F07', 0.5)\n"
        "        d.set_param('F08', 0.5)\n"
        "        d.run(hz=20, wait=True, timeout=20)\n"
        "        print('RUNNING', flush=True)\n"
        "        time.sleep(30)\n"
        "finally:\n"
        "    r = d._station.motion.stop_report\n"
        "    print('STOP', r.how, r.stopped, sim.slave(3).model.freq, flush=True)\n")
    p = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True, cwd=tmp_path, env={**os.environ, "PYTHONPATH": str(root)})
    try:
        assert p.stdout.readline().strip() == "RUNNING"
        p.send_signal(signal.SIGTERM)
        out, err = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
    assert "STOP normal True 0.0" in out, out + err
    assert "SessionTerminated" in err and p.returncode != 0


def test_the_api_loads_no_cli_and_prints_nothing():
    import subprocess
    import sys
    from pathlib import Path
    code = ("import sys, profidrive_cli as pdrive\n"
            "with pdrive.open_bus('sim://?timing=virtual') as bus:\n"
            "    d = bus.drive(4, layout='ppo3')\n"
            "    d.run(hz=10, wait=True, timeout=30)\n"
            "print('LOADED', sorted(m for m in ('rich', 'click', 'profidrive_cli.cli.common')"
            " if m in sys.modules))\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                       cwd=Path(__file__).resolve().parent.parent)
    assert p.stdout == "LOADED []\n", p.stdout + p.stderr
    assert p.stderr == ""


def test_py_typed_is_shipped():
    import tomllib
    from pathlib import Path
    root = Path(__file__).resolve().parent.parent
    assert (root / "profidrive_cli" / "py.typed").is_file()
    conf = tomllib.loads((root / "pyproject.toml").read_text())
    assert "py.typed" in conf["tool"]["setuptools"]["package-data"]["profidrive_cli"]


def test_fmax_for_a_layout_without_a_parameter_channel():
    # Fuji PPO3 carries no PKW: F03 cannot be read; fmax=50 makes 100 % = 50 Hz
    with pdrive.open_bus(SIM) as bus:
        d = bus.drive(4, layout="ppo3", fmax=50)
        assert d.fmax_hz == 50.0
        st = d.run(hz=25, wait=True, timeout=30)
        assert st.reference_percent == pytest.approx(50.0, abs=0.01)
        assert st.fmax_hz == 50.0 and st.actual_hz == pytest.approx(25.0, abs=0.25)
        assert "Bus sim://" in repr(bus) and "[4]" in repr(bus)


def test_a_link_lost_while_idle_is_reported_at_the_next_call():
    # the keep-alive thread meets the unplugged port; the next call says so (BusError), and the
    # way out of the with block says that no stop could be sent (the watchdog stops the drive)
    with pytest.raises(pdrive.BusError, match="keeping the drives in data exchange failed"):
        with pdrive.open_bus("sim://") as bus:
            d = bus.drive(3)
            d.set_param("F07", 0.5)
            d.run(hz=10, wait=True, timeout=30)
            bus.master.link.ser.unplug()
            deadline = time.monotonic() + 5
            while bus._keepalive_error is None and time.monotonic() < deadline:
                time.sleep(0.05)
            d.status()
    assert d._station.motion.stop_report.how == "not sent (link lost)"
    assert "watchdog" in d._station.motion.stop_report.message
