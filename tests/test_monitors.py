"""run --monitor and the trip records of `faults` (issue 17): the profile sections, the simulated motor
(hand-calculated values), and the commands on sim:// and through `pdrive sim --pty`."""

import csv
import json
import math
import subprocess

import pytest

from profidrive_cli import UsageError
from profidrive_cli.datafile import DataFileError
from profidrive_cli.drives.monitors import monitor_config, trip_record_config
from profidrive_cli.drives.profile import all_profiles, load_profile, load_profile_file
from profidrive_cli.session.monitors import NO_TRIP_RECORDS, monitor_codes
from profidrive_cli.sim.motor import Motor

from test_drive_cmds import lines, ok, pdrive  # noqa: F401  (fixture)

#: the runs of these tests are not about the watchdog: a watchdog of 5 s (instead of 500 ms) keeps a
#: test process stalled at load (the simulator of sim:// runs in it, on the wall clock) from tripping
#: the drive on comm loss (E70) and failing a test about monitors
LONG_WD = ("--watchdog", "5000")


# -- the simulated motor: values by hand from the formulas in sim/motor.py ----------------------------

def test_motor_at_steady_speed_and_while_accelerating():
    m = Motor(rated_a=10.0, rated_v=400.0, load_pct=30.0, inertia_s=2.0, magnetising=0.3)
    m.update(0.0, 25.0, True)
    m.update(1.0, 25.0, True)                        # steady: df/dt = 0
    assert m.torque_pct(50.0) == pytest.approx(30.0)
    assert m.current_a(50.0) == pytest.approx(10.0 * math.hypot(0.3, 0.3))     # 4.243 A
    assert m.voltage_v(50.0) == pytest.approx(200.0)                           # 400 V * 25/50
    m.update(2.0, 30.0, True)                        # +5 Hz/s: 2 s * 100 % * 5 / 50 = 20 % more
    assert m.torque_pct(50.0) == pytest.approx(50.0)
    assert m.current_a(50.0) == pytest.approx(10.0 * math.hypot(0.3, 0.5))
    m.update(3.0, 0.0, False)                        # output off: nothing flows
    assert (m.current_a(50.0), m.voltage_v(50.0), m.torque_pct(50.0)) == (0.0, 0.0, 0.0)
    assert m.dc_link_v() == pytest.approx(560.0 * (1 + 0.01 * math.sin(2 * math.pi * 300 * 3.0)))


# -- the profile sections -----------------------------------------------------------------------------

def test_every_default_monitor_and_trip_record_code_is_one_the_profile_has():
    import re
    seen = 0
    for prof in all_profiles():
        mc = monitor_config(prof)
        for c in mc.default:
            assert prof.param(c) is not None or c in mc.words, (prof.name, c)
            seen += 1
        tr = trip_record_config(prof)
        for rec in (tr.records if tr else []):
            for c in rec.fields:
                base = re.sub(r"\[.*\]$", "", c)       # Toyo traceback points TB03[0,99]
                assert prof.param(base) is not None, (prof.name, c)
    assert seen >= 8


def test_moeller_trip_records_are_d081_to_d086_with_frequency_current_voltage():
    # spec moeller-de6-net-dp.md rows L1116-L1150: PNU 355 + 6k = factor, +1 frequency (Hz *100),
    # +2 output current (A *10), +3 PN (DC) voltage (V *10)
    prof = load_profile("moeller")
    tr = trip_record_config(prof)
    assert [r.fields[0] for r in tr.records] == ["d081", "d082", "d083", "d084", "d085", "d086"]
    for k, r in enumerate(tr.records):
        pnus = [prof.param(c).pnu for c in r.fields[:4]]
        assert pnus == [355 + 6 * k, 356 + 6 * k, 357 + 6 * k, 358 + 6 * k]
        assert [prof.param(c).unit for c in r.fields[1:4]] == ["Hz", "A", "V"]
    assert trip_record_config(load_profile("fuji-g1")) is None
    assert trip_record_config(load_profile("yaskawa")) is None


def _variant(tmp_path, text):
    src = load_profile("moeller").path.read_text()
    p = tmp_path / "m.yaml"
    p.write_text(src.replace("monitors:\n  default: [d001, d002, d013, d012]\n", text))
    return load_profile_file(p)


def test_a_bad_monitors_section_names_file_and_line(tmp_path):
    """Refused when the profile loads (the section is read then; issue 35), file:line."""
    with pytest.raises(DataFileError) as e:
        _variant(tmp_path, "monitors:\n  default: d002\n")
    line = (tmp_path / "m.yaml").read_text().splitlines().index("  default: d002") + 1
    assert f"m.yaml:{line}:" in str(e.value) and "list of codes" in str(e.value)
    with pytest.raises(DataFileError, match="unknown key 'defaults'"):
        _variant(tmp_path, "monitors:\n  defaults: [d002]\n")


def test_monitor_codes_expands_default_and_refuses_what_cannot_be_read():
    prof = load_profile("moeller")
    assert monitor_codes(prof, "ppo1", "default") == ["d001", "d002", "d013", "d012"]
    assert monitor_codes(prof, "ppo1", "d002, default") == ["d002", "d001", "d013", "d012"]
    with pytest.raises(UsageError, match="no parameter d999"):
        monitor_codes(prof, "ppo1", "d999")
    with pytest.raises(UsageError, match="layout ppo3 .* no parameter channel"):
        monitor_codes(prof, "ppo3", "default")           # PPO3: no PKW (spec 2.x, PPO table)


# -- run --monitor on sim:// -----------------------------------------------------------------------

def _end(r):
    return [x for x in lines(r) if x.get("event") == "end"][0]


def test_moeller_default_monitors_in_json_and_csv(pdrive, tmp_path):
    log = tmp_path / "run.csv"
    r = ok(pdrive("run", "6", "--hz", "20", "--duration", "8", "--monitor", "default", "--json", *LONG_WD,
                  "--log", str(log)))
    start = lines(r)[0]
    assert {m["code"]: m["unit"] for m in start["monitors"]} == {"d001": "Hz", "d002": "A", "d013": "V",
                                                                 "d012": "%"}
    ups = [x for x in lines(r) if x.get("event") == "update" and x.get("monitors", {}).get("d002", {}).get("value")]
    assert ups, "no update carried a monitor value"
    end = _end(r)
    # d012 (torque) is DV6-only; the simulated card is a DF6 and refuses it (error 0, unknown PNU)
    assert "d012" in end["monitors_dropped"] and "d012" not in end["monitors"]
    # steady 20 Hz of A004 = 50 Hz at 30 % load: V = 400 * 20/50 = 160 V; I = 10 A * hypot(0.3, 0.3)
    mon = {c: v["value"] for c, v in end["monitors"].items()}
    assert mon["d001"] == pytest.approx(20.0, abs=0.01)
    assert mon["d013"] == pytest.approx(160.0, abs=0.1)
    assert mon["d002"] == pytest.approx(4.2, abs=0.05)
    rows = list(csv.reader(log.open()))
    assert rows[0][-4:] == ["d001 [Hz]", "d002 [A]", "d013 [V]", "d012 [%]"]
    assert any(row[-3] and float(row[-3]) > 4.0 for row in rows[1:])


def test_toyo_default_monitors_follow_the_motor(pdrive):
    r = ok(pdrive("run", "5", "--hz", "30", "--duration", "10", "--monitor", "default", "--json", *LONG_WD))
    start = lines(r)[0]
    assert {m["code"]: m["unit"] for m in start["monitors"]} == {
        "current": "A", "output-voltage": "V", "torque": "%", "dc-voltage": "V"}
    mon = {c: v["value"] for c, v in _end(r)["monitors"].items()}
    # 30 of 60 Hz, steady, 30 % load: torque 30 % (0.02 %/count), current 4.2 A, output voltage 200 V * 1/2,
    # DC link 283.0 V (the manual's example D1 value)
    assert mon["torque"] == pytest.approx(30.0, abs=0.05)
    assert mon["current"] == pytest.approx(4.2, abs=0.05)
    assert mon["output-voltage"] == pytest.approx(100.0, abs=0.1)
    assert mon["dc-voltage"] == pytest.approx(283.0)


def test_monitor_errors_are_one_line_before_anything_moves(pdrive):
    r = pdrive("run", "6", "--hz", "20", "--duration", "1", "--monitor", "d999")
    assert r.exit_code == 2 and "d999" in r.stderr and r.stderr.count("\n") == 1, r.output
    assert "start" not in r.stdout
    r = pdrive("run", "6", "--ppo", "3", "--hz", "20", "--duration", "1", "--monitor", "default")
    assert r.exit_code == 2 and "no parameter channel" in r.stderr, r.output


# -- trip records ---------------------------------------------------------------------------------

def test_moeller_trip_record_after_an_injected_trip(pdrive):
    d = json.loads(ok(pdrive("faults", "6", "--json", port="sim://?trip=6:E05")).stdout)
    tr = d["trip_records"]
    assert tr["supported"] and len(tr["records"]) == 1
    f = {x["code"]: x for x in tr["records"][0]["fields"]}
    assert f["d081"]["raw"] == 5                      # factor = the fault number of E05
    assert f["PNU358"]["value"] == pytest.approx(560.0, abs=6) and f["PNU358"]["unit"] == "V"
    r = ok(pdrive("faults", "6", port="sim://?trip=6:E05"))
    assert "trip records" in r.stdout and "1 (d081)" in r.stdout


def test_a_moeller_with_no_trip_stored_names_no_newest_record(pdrive):
    # PNU 354, "Pointer of history of last trip", runs 00 to 05 (DE6-NET-DP parameter list L1116):
    # it reads 00 before the first trip as after it, so with none stored no record is "newest"
    r = ok(pdrive("faults", "6", port="sim://"))
    assert "trip records: none stored\n" in r.stdout and "newest" not in r.stdout


def test_trip_record_of_a_drive_that_tripped_while_running(sim, pdrive):
    port = "sim://?drivetrip=0.01&only=6&seed=1"
    r = pdrive("run", "6", "--hz", "30", "--duration", "20", "--json", *LONG_WD, port=port)
    assert r.exit_code == 1 and "tripped" in r.stderr
    tr = json.loads(ok(pdrive("faults", "6", "--json", port=port)).stdout)["trip_records"]
    f = {x["code"]: x["value"] for x in tr["records"][0]["fields"]}
    assert f["PNU356"] > 0 and f["PNU357"] > 0      # frequency and current at the trip


def test_toyo_traceback_as_trip_records(pdrive):
    d = json.loads(ok(pdrive("faults", "5", "--json", port="sim://?trip=5:OC")).stdout)
    recs = d["trip_records"]["records"]
    assert [r["position"] for r in recs] == ["newest"]       # the other recordings answer 101 (empty)
    f = {x["code"]: x for x in recs[0]["fields"]}
    assert f["TB03[0,99]"]["value"] == 283.0 and f["TB03[0,99]"]["unit"] == "V"


@pytest.mark.parametrize("address", [3, 4, 7])
def test_cards_without_trip_records_say_so_in_one_line(pdrive, address):
    r = ok(pdrive("faults", str(address)))
    assert f"trip records: {NO_TRIP_RECORDS}" in r.stdout
    d = json.loads(ok(pdrive("faults", str(address), "--json")).stdout)
    assert d["trip_records"] == {"supported": False, "records": [], "note": NO_TRIP_RECORDS}


# -- the same over a real byte path ----------------------------------------------------------------

def test_monitors_and_trip_records_over_a_pty():
    from conftest import pdrive_cmd
    from test_pty_bus import _start_sim, _stop
    sim, info = _start_sim(["--pty", "--plant", "sim://?trip=6:E05"])
    port = info["port"]

    def pd(*args):
        return subprocess.run(pdrive_cmd() + list(args) + ["--port", port], capture_output=True, text=True,
                              timeout=180)
    try:
        r = pd("faults", "6", "--json")
        assert r.returncode == 0, r.stderr
        assert json.loads(r.stdout)["trip_records"]["records"][0]["fields"][0]["raw"] == 5
        r = pd("run", "5", "--hz", "30", "--duration", "3", "--monitor", "default", "--json", "--yes")
        assert r.returncode == 0, r.stderr
        evs = [json.loads(x) for x in r.stdout.splitlines()]
        assert [m["unit"] for m in evs[0]["monitors"]] == ["A", "V", "%", "V"]
        end = evs[-1]
        assert end["monitors"]["current"]["value"] > 0 and end["monitors"]["dc-voltage"]["value"] == 283.0
    finally:
        assert _stop(sim) == 0


# -- the cyclic words: Moeller PZD3.. via PNU 916 (restored after), Fuji PCD1-4 as o48-o51 assign them ------

def test_moeller_ppo2_maps_monitors_into_pzd3_and_restores_pnu916(sim, pdrive):
    before = [p["raw"] for p in json.loads(ok(pdrive("param", "get", "6", "PNU916[1]", "PNU916[2]",
                                                      "PNU916[3]", "--ppo", "2", "--json")).stdout)["parameters"]]
    assert before == [0, 0, 0]
    r = ok(pdrive("run", "6", "--ppo", "2", "--hz", "20", "--duration", "8", "--monitor", "default", "--json", *LONG_WD))
    mon = _end(r)["monitors"]
    # d001 is 4 octets: not mappable (spec: PZD words are 2 octets) -> parameter channel;
    # d002 (PNU 407) and d013 (PNU 417) into PZD3/PZD4; d012 is DV6-only and refused on the DF6
    assert {c: v["via"] for c, v in mon.items()} == {"d001": "parameter channel", "d002": "cyclic",
                                                     "d013": "cyclic"}
    assert mon["d013"]["value"] == pytest.approx(160.0, abs=0.1)
    ups = [x for x in lines(r) if x.get("event") == "update" and x["raw"].get("pzd3")
           and x.get("monitors", {}).get("d013", {}).get("raw")]
    assert ups and ups[-1]["raw"]["pzd4"] == ups[-1]["monitors"]["d013"]["raw"]     # the word itself
    after = [p["raw"] for p in json.loads(ok(pdrive("param", "get", "6", "PNU916[1]", "PNU916[2]",
                                                     "PNU916[3]", "--ppo", "2", "--json")).stdout)["parameters"]]
    assert after == [0, 0, 0]


def test_fuji_reads_a_monitor_from_the_pcd_word_o48_assigns(sim, pdrive):
    # TV17 style: assignment word = group << 8 | number; M = group 3, M12 -> 0x030C
    ok(pdrive("param", "set", "3", "o49", "0x030C", "--ppo", "2", "--yes"))
    r = ok(pdrive("run", "3", "--ppo", "2", "--hz", "30", "--duration", "8", "--monitor", "default", "--json", *LONG_WD))
    mon = _end(r)["monitors"]
    assert mon["M12"]["via"] == "cyclic" and mon["M11"]["via"] == "parameter channel"
    assert mon["M12"]["value"] == pytest.approx(200.0, abs=0.1)            # 400 V * 30/60 Hz
    assert mon["M09"]["value"] == pytest.approx(30.0, abs=0.01)
    assert mon["M07"]["value"] == pytest.approx(30.0, abs=0.05)
    assert mon["M11"]["value"] == pytest.approx(42.43, abs=0.05)            # 100 * hypot(0.3, 0.3)


@pytest.mark.parametrize("address,units", [(3, ["Hz", "%", "V", "%"]), (4, ["Hz", "%", "V", "%"])])
def test_fuji_default_monitors_have_units(pdrive, address, units):
    # 10 Hz is reached 1 s after the start (the fixture's ramp): 1.5 s leave the 0.1 s it must stay
    # there to count as reached (issue 34's rule, docs/commands.md)
    r = ok(pdrive("run", str(address), "--hz", "10", "--duration", "1.5", "--monitor", "default", "--json"))
    assert [m["unit"] for m in lines(r)[0]["monitors"]] == units


# -- Yaskawa: the fast-I/O input words (spec 2.4: output current = rating / 8192 per count) ---------------

@pytest.mark.parametrize("fmt,expect", [
    ("extended1", {"output-current", "torque-reference", "PWR"}),
    ("basic", {"output-current"}),                 # 3-word message: current only, no parameter access
    ("extended2", {"PWR"}),                        # 6-word message: no current word
])
def test_yaskawa_default_monitors_per_layout(pdrive, fmt, expect):
    r = ok(pdrive("run", "7", "--format", fmt, "--hz", "30", "--duration", "6", "--monitor", "default", "--json", *LONG_WD))
    mon = _end(r)["monitors"]
    assert set(mon) == expect
    if "output-current" in mon:
        # the simulated drive: 30 % + 50 % * f/fmax of its rating at steady speed (sim/yaskawa.py);
        # 30 of 60 Hz -> 55 % -> round(0.55 * 8192) = 4506 counts -> 4506 * 100 / 8192 %
        assert mon["output-current"]["raw"] == 4506
        assert mon["output-current"]["value"] == pytest.approx(4506 * 100 / 8192)
        assert mon["output-current"]["unit"] == "%"


def test_pnu916_is_restored_also_when_the_drive_trips_mid_run(sim, pdrive):
    port = "sim://?drivetrip=0.005&only=6&seed=2"
    r = pdrive("run", "6", "--ppo", "2", "--hz", "30", "--duration", "20", "--monitor", "d002,d013", "--json",
               port=port)
    assert r.exit_code == 1 and "tripped" in r.stderr, r.output
    assert {c: v["via"] for c, v in _end(r)["monitors"].items()} == {"d002": "cyclic", "d013": "cyclic"}
    got = json.loads(ok(pdrive("param", "get", "6", "PNU916[1]", "PNU916[2]", "--ppo", "2", "--json",
                               port=port)).stdout)["parameters"]
    assert [p["raw"] for p in got] == [0, 0]


def test_the_question_before_a_real_port_run_names_the_pnu916_mapping():
    from types import SimpleNamespace
    from profidrive_cli.session.monitors import Monitors
    for layout, note in (("ppo2", True), ("ppo5", True), ("ppo1", False)):
        sess = SimpleNamespace(profile=load_profile("moeller"), layout=layout)
        m = Monitors(sess, ["d002"])
        assert ("maps PNU 916" in m.question_note()) is note, layout
    sess = SimpleNamespace(profile=load_profile("fuji-g1"), layout="ppo2")
    assert Monitors(sess, ["M11"]).question_note() == ""      # Fuji: nothing is written
