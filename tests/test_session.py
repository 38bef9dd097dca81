"""session.DriveStation on the in-process simulated bus: station choice, profile and layout
checks, cycle rate, the safe stop on every way out, parameters, dump / restore."""

import csv
import time

import pytest

from profidrive_cli import BusError, UsageError
from profidrive_cli.cli.common import BusOptions
from profidrive_cli.drives.base import DriveError
from profidrive_cli.session import (Parameters, DriveStation, SessionTerminated, find_drive_stations,
                                    resolve_layout, wire_limit_hz)
from profidrive_cli.drives.profile import load_profile
from profidrive_cli.fdl.timing import wire_time_data_exchange

DEFAULT = {3: "fuji-opc-g1-pdp", 4: "fuji-opc-pdp3", 5: "toyo-pbus66z", 6: "moeller-de6-net-dp",
           7: "yaskawa-si-p1"}
RAMPS = {3: ("F07", "F08"), 4: ("F07", "F08"), 6: ("F002", "F003"), 7: ("C1-01", "C1-02")}




def master(port="sim://", address=2):
    return BusOptions(port, "19200", address, None, None, False, False, 0, False).open_master()


def session(address=None, port="sim://", **kw):
    """A session; unpaced (cycle_hz=0, as the parameter commands use it) unless a rate is given."""
    kw.setdefault("handle_signals", False)
    kw.setdefault("cycle_hz", 0)
    return DriveStation(master(port), address, **kw)


def drive_model(buses, address, url="sim://"):
    return buses[url].slaves[address].model


def short_ramps(address, seconds=0.2):
    if address not in RAMPS:
        return
    with session(address) as s:
        for code in RAMPS[address]:
            s.params.write(code, seconds)


# -- which station ---------------------------------------------------------------------------------

def test_find_drive_stations_on_the_default_plant():
    m = master()
    try:
        found = find_drive_stations(m)
    finally:
        m.link.close()
    assert {s.address: s.profile.name for s in found} == DEFAULT
    assert m.fdl.params.retries == 1          # the probe's retries are put back


def test_the_only_drive_station_is_chosen():
    with session(None, "sim://?stations=9:yaskawa") as s:
        assert (s.address, s.profile.name, s.layout) == (9, "yaskawa-si-p1", "extended1")


def test_several_drive_stations_need_an_address():
    with pytest.raises(UsageError) as e:
        with session(None):
            pass
    msg = str(e.value)
    assert "5 drive stations" in msg and "3 (fuji-opc-g1-pdp)" in msg and "7 (yaskawa-si-p1)" in msg
    assert "PDRIVE_STATION" in msg


def test_pdrive_station_environment_is_the_default():
    with session(None, env={"PDRIVE_STATION": "6"}) as s:
        assert s.address == 6 and s.profile.family == "moeller"
    with pytest.raises(UsageError, match="PDRIVE_STATION"):
        with session(None, env={"PDRIVE_STATION": "x"}):
            pass


def test_absent_station_is_one_line():
    with pytest.raises(BusError, match="station 42 does not answer"):
        with session(42):
            pass


def test_a_station_locked_by_another_master_fails_fast(sim):
    other = DriveStation(master(address=1), 3, handle_signals=False, cycle_hz=0).open()
    try:
        with pytest.raises(BusError, match="did not reach data exchange: locked by master 1"):
            with session(3):
                pass
    finally:
        other.close()
    with session(3) as s:                           # released: free for us
        assert s.motion.status().status.state


def test_profile_of_another_family_names_the_station_family():
    with pytest.raises(UsageError) as e:
        with session(5, profile="yaskawa"):
            pass
    msg = str(e.value)
    assert "station 5 is toyo-pbus66z" in msg and "family toyo" in msg and "not yaskawa-si-p1" in msg


def test_layout_choice():
    fuji = load_profile("fuji-g1")
    yas = load_profile("yaskawa")
    assert resolve_layout(fuji, ppo=3) == "ppo3"
    assert resolve_layout(yas, fmt="BASIC") == "basic"
    assert resolve_layout(yas) == "extended1"
    with pytest.raises(UsageError, match="no PPO layouts"):
        resolve_layout(yas, ppo=1)
    with pytest.raises(UsageError, match="supports PPO 1, 2, 3, 4"):
        resolve_layout(fuji, ppo=5)
    with pytest.raises(UsageError, match="at most one"):
        resolve_layout(fuji, ppo=1, fmt="ppo1")


# -- cycle rate ------------------------------------------------------------------------------------

def test_wire_limit_and_default_rate():
    assert wire_limit_hz(19200, 12, 12) == pytest.approx(1 / wire_time_data_exchange(19200, 12, 12))
    assert wire_limit_hz(1500000, 12, 12) > 1000
    with session(3, ppo=3, cycle_hz=None) as s:  # PPO3 at 19.2k: the wire allows ~57 Hz, sim cap 50
        assert s.wire_hz == pytest.approx(wire_limit_hz(19200, 4, 4)) and s.wire_hz > 50
        assert s.cycle_hz == 50.0
    with session(3, cycle_hz=None) as s:        # PPO1: 12 octets each way, ~38 Hz
        assert s.cycle_hz == pytest.approx(wire_limit_hz(19200, 12, 12)) and s.cycle_hz < 40
    with session(7, cycle_hz=None) as s:        # extended1: 32 octets each way, ~20 Hz at 19.2k
        assert s.cycle_hz == pytest.approx(s.wire_hz) and s.cycle_hz < 25
        assert not s.warnings


def test_a_rate_above_the_wire_warns_and_is_measured():
    with session(3, cycle_hz=200) as s:
        assert any("more than 19.2k allows" in w for w in s.warnings)
        for _ in range(30):
            s.motion.poll()
        assert s.cycles >= 30
        assert s.achieved_hz > 60                # the instant sim keeps up with the request
        c = s.counters
        assert c["data_exchanges"] >= 30 and c["no_answer"] == 0


def test_cycle_log_has_a_row_per_exchange(tmp_path):
    log = tmp_path / "c.csv"
    with session(6, log_csv=log) as s:
        for _ in range(5):
            s.motion.poll()
        n = s.cycles
    rows = list(csv.reader(log.open()))
    assert rows[0][:6] == ["time_s", "cycle", "control_word", "reference", "status_word", "actual"]
    assert len(rows) == n + 1
    assert rows[-1][4].startswith("0x")


# -- the safe stop ---------------------------------------------------------------------------------

@pytest.mark.parametrize("exc", [RuntimeError("boom"), KeyboardInterrupt(), SessionTerminated(15)])
def test_any_exception_stops_the_drive(sim, exc):
    short_ramps(3)
    s = session(3)
    with pytest.raises(type(exc)):
        with s:
            s.motion.start(s.motion.percent_for_hz(20))
            for _ in range(10):
                assert s.motion.poll().status.running
            raise exc
    assert s.motion.stop_report.how == "normal" and s.motion.stop_report.stopped
    model = drive_model(sim, 3)
    assert model.freq == 0.0
    with session(3) as s2:
        st = s2.motion.status().status
    assert st.stopped and not st.running


def test_stop_escalates_to_coast(sim):
    s = session(6, stop_timeout=0.05)                # F003 5 s: a normal stop takes far longer
    with s:
        s.motion.start(s.motion.percent_for_hz(25))
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            s.motion.poll()
        assert abs(s.motion.poll().actual_hz) > 2
    assert s.motion.stop_report.how == "coast" and s.motion.stop_report.stopped
    assert any("coasting" in w for w in s.warnings)
    assert drive_model(sim, 6).freq == 0.0


def test_no_stop_for_a_drive_this_session_did_not_start():
    with session(4) as s:
        s.motion.status()
    assert s.motion.stop_report.how == "not needed"


def test_link_loss_says_the_watchdog_stops_the_drive(sim):
    from profidrive_cli.link.base import LinkLost
    s = session(7, watchdog_ms=300)
    with pytest.raises(LinkLost):
        with s:
            s.motion.start(20.0)
            raise LinkLost("sim://: port lost while reading")
    r = s.motion.stop_report
    assert r.how == "not sent (link lost)" and not r.stopped
    assert "watchdog (300 ms)" in r.message and "BUS fault" in r.message
    assert s.link_lost


def test_fmax_sources():
    with session(3, ppo=3) as s:                     # no parameter channel: profile default / --fmax
        hz, src = s.motion.fmax()
        assert hz == 60.0 and "profile default" in src and "no parameter channel" in src
        assert s.motion.percent_for_hz(30, 50.0) == pytest.approx(60.0)
        assert "--fmax" in s.motion.fmax(50.0)[1]
    with session(6) as s:                            # Moeller PPO1: A004 read from the drive
        assert s.motion.fmax() == (50.0, "read from the drive (A004)")
        with pytest.raises(UsageError, match="above the maximum frequency 50 Hz"):
            s.motion.percent_for_hz(60)


# -- parameters ------------------------------------------------------------------------------------

def test_unknown_code_suggests_the_closest():
    with session(3) as s:
        with pytest.raises(UsageError) as e:
            s.params.read("F3x")
    assert "closest fuji codes: F03" in str(e.value)


def test_code_of_another_family_names_both_families():
    with session(7) as s:
        with pytest.raises(UsageError) as e:
            s.params.read("A004")
    msg = str(e.value)
    assert "A004 is a moeller code" in msg and "station 7 is yaskawa-si-p1" in msg


def test_value_checks_before_writing():
    with session(3) as s:
        with pytest.raises(UsageError, match=r"expected a number 0..6000 s, got 'fast'"):
            s.params.parse("F07", "fast")
        with pytest.raises(UsageError, match=r"outside 0..6000 s"):
            s.params.write("F07", 7000)
        with pytest.raises(UsageError, match="read-only"):
            s.params.write("M16", 1)
        assert s.params.read("F07").value == 6.0     # nothing was written


def test_stop_only_parameter_refused_while_running(sim):
    short_ramps(7)
    with session(7) as s:
        s.motion.start(30.0)
        for _ in range(5):
            s.motion.poll()
        with pytest.raises(DriveError, match="only be changed while the motor is stopped"):
            s.params.write("E1-04", 50)
    with session(7) as s:
        assert s.params.read("E1-04").value == 60.0


@pytest.mark.parametrize("address,code,value", [(3, "F07", 2.5), (4, "E31", 40.0), (6, "F002", 1.5),
                                                (7, "C1-01", 4.0)])
def test_write_is_read_back_and_survives(sim, address, code, value):
    with session(address) as s:
        assert s.params.write(code, value).value == pytest.approx(value)
    with session(address) as s:
        assert s.params.read(code).value == pytest.approx(value)


def test_dump_compare_restore(sim, tmp_path):
    import yaml
    with session(6) as s:
        doc = s.params.dump()
    assert doc["station"]["profile"] == "moeller-de6-net-dp" and doc["station"]["ident"] == "0xFD06"
    assert doc["parameters"]["F002"]["value"] == 5.0
    assert "PNU971" not in doc["parameters"] and "PNU927" in doc["readonly"]   # command / rights
    f = tmp_path / "m.yaml"
    f.write_text(yaml.safe_dump(doc, sort_keys=False))
    with session(6) as s:
        s.params.write("F002", 2.0)
        s.params.write("A004", 60)
    loaded = Parameters.load_dump(f)
    with session(6) as s:
        rows = {r.code: r for r in s.params.compare(loaded)}
        assert rows["F002"].result == "differs" and rows["F002"].drive_value == 2.0
        assert rows["F003"].result == "unchanged"
        dry = {r.code: r.result for r in s.params.restore(loaded, dry_run=True)}
        assert dry["F002"] == "would apply"
        assert s.params.read("F002").value == 2.0
        rows = {r.code: r for r in s.params.restore(loaded)}
    assert rows["F002"].result == "applied" and rows["F002"].new_value == 5.0
    assert rows["A004"].result == "applied"
    assert not [r for r in rows.values() if r.result == "refused"]
    with session(6) as s:
        assert s.params.read("F002").value == 5.0 and s.params.read("A004").value == 50


def test_restore_refuses_a_file_of_another_device(sim, tmp_path):
    f = tmp_path / "y.yaml"
    f.write_text("pdrive_dump: 1\nstation: {address: 7, profile: yaskawa-si-p1}\n"
                 "parameters:\n  C1-01: {value: 1.0}\n")
    doc = Parameters.load_dump(f)
    with session(3) as s:
        with pytest.raises(UsageError, match="dumped from a yaskawa-si-p1 station"):
            s.params.restore(doc)


def test_dump_file_errors_name_file_and_line(tmp_path):
    f = tmp_path / "bad.yaml"
    f.write_text("parameters:\n  F07: fast\n")
    with pytest.raises(UsageError, match=r"bad.yaml:2: F07: the value must be a number"):
        Parameters.load_dump(f)
    f.write_text("hello: 1\n")
    with pytest.raises(UsageError, match="not a pdrive parameter file"):
        Parameters.load_dump(f)


def test_fault_history_and_clear():
    with session(6, "sim://?trip=6:E05") as s:
        cur = s.motion.status().status
        assert cur.fault and cur.fault_code == "E05"
        hist = s.fault_history()
        assert hist[0].codes == ["E05"]
        after = s.clear_fault().status
        assert not after.fault
