"""scan --watch (bustools/buswatch.py, cli/scan_watch.py) and the checklist step bus_health.

Expected values: the Slave_Diag bit positions from the DP reference (st1 bit 0 Station_Non_Existent,
1 Station_Not_Ready, 2 Cfg_Fault, 3 Ext_Diag, 4 Not_Supported, 6 Prm_Fault; st2 bit 0 Prm_Req,
1 Stat_Diag, 2 always 1), counter arithmetic by hand, and the simulator's fault injection
(sim://?drop=P drops telegrams, so retries must rise; a clean sim:// repeats nothing)."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from profidrive_cli.bustools.buswatch import BusWatch, categorize, health_figures
from profidrive_cli.cli.main import cli
from profidrive_cli.dp.services import SlaveDiag
from test_json_contract import assert_stream

ST2_FIXED = 0x04        # st2 bit 2 is always 1 in a slave's reply


def diag(st1=0, st2=ST2_FIXED, master=0xFF):
    return SlaveDiag(st1, st2, 0, master, 0xFD01)


@pytest.mark.parametrize("st1, st2, master, expected", [
    (0x00, ST2_FIXED | 0x01, 0xFF, "waiting"),                     # Prm_Req, never parameterised
    (0x02, ST2_FIXED | 0x01, 0xFF, "waiting"),                     # Station_Not_Ready + Prm_Req
    (0x00, ST2_FIXED, 2, "data exchange"),                         # parameterised by master 2, all clear
    (0x80, ST2_FIXED, 2, "data exchange"),                         # Master_Lock: another master's slave
    (0x04, ST2_FIXED, 2, "configuration fault"),                   # Cfg_Fault
    (0x40, ST2_FIXED | 0x01, 0xFF, "configuration fault"),         # Prm_Fault (with Prm_Req)
    (0x08, ST2_FIXED, 2, "diagnosis pending"),                     # Ext_Diag
    (0x00, ST2_FIXED | 0x02, 2, "diagnosis pending"),              # Stat_Diag
    (0x10, ST2_FIXED, 2, "not supported"),                         # Not_Supported
    (0x01, ST2_FIXED, 0xFF, "no answer"),                          # Station_Non_Existent
])
def test_categories_follow_the_diagnosis_bits(st1, st2, master, expected):
    assert categorize(diag(st1, st2, master)) == expected


def test_no_reply_is_no_answer():
    assert categorize(None) == "no answer"


def test_a_fault_outranks_pending_diagnosis():
    # Cfg_Fault and Ext_Diag together: the fault is what the engineer must fix first
    assert categorize(diag(0x04 | 0x08, ST2_FIXED, 2)) == "configuration fault"


def test_health_figures_by_hand():
    before = {"requests": 1000, "retries": 4, "no_answer": 0, "illegal": 1, "reparams": 0, "data_exchanges": 990}
    after = {"requests": 3000, "retries": 34, "no_answer": 2, "illegal": 1, "reparams": 1, "data_exchanges": 2985}
    f = health_figures(before, after)
    assert f["requests"] == 2000 and f["retries"] == 30 and f["no_answer"] == 2
    assert f["illegal"] == 0 and f["reparams"] == 1 and f["data_exchanges"] == 1995
    assert f["retries_per_1000"] == pytest.approx(15.0)        # 30 retries in 2000 requests


def test_health_figures_without_requests_divide_by_nothing():
    same = {"requests": 5, "retries": 1}
    assert health_figures(same, same)["retries_per_1000"] == 0.0


def _master(url):
    from profidrive_cli.dp.poller import Master
    from profidrive_cli.fdl.timing import BusParams
    from profidrive_cli.link import open_link
    return Master(open_link(url, 19200), BusParams.for_baud(19200))


def _watch(url, passes=20):
    m = _master(url)
    w = BusWatch(m, 0, 126, window_s=1.0)
    w.start()
    for _ in range(passes):
        w.step()
    return m, w


def test_the_watch_finds_the_default_plant_and_polls_each_station_every_pass():
    m, w = _watch("sim://", passes=10)
    try:
        v = w.view()
        assert [s.address for s in v.stations] == [3, 4, 5, 6, 7]
        assert {s.ident for s in v.stations} == {0xFD01, 0xFD02, 0x0BE7, 0xFD06, 0x00CA}
        assert all(s.category == "waiting" for s in v.stations)      # no master has them
        assert v.passes == 10
        # one Slave_Diag per station per pass, after the scan's FDL status and Slave_Diag
        assert all(s.counters["requests"] == 2 + 10 for s in v.stations)
        assert all(s.counters["retries"] == 0 and s.counters["no_answer"] == 0 for s in v.stations)
        assert v.cycle_min_s is not None and v.cycle_min_s <= v.cycle_mean_s <= v.cycle_max_s
    finally:
        m.link.close()


def test_the_watch_sees_retries_rise_on_a_lossy_line():
    m, w = _watch("sim://?drop=0.05&stations=3:fuji-g1", passes=200)
    try:
        (s,) = w.view().stations
        assert s.counters["retries"] > 0                # 200 passes at 5 % loss: ~10 expected
    finally:
        m.link.close()


def test_a_station_in_data_exchange_is_shown_so(sim):
    from profidrive_cli.drives.profile import load_profile
    from conftest import drive_on_bus
    m = _master("sim://?stations=3:fuji-g1,4:fuji-pdp3")
    try:
        drive_on_bus(m, 3, load_profile("fuji-g1"), "ppo1", wd_ms=5000)
        w = BusWatch(m, 0, 10)
        w.start()
        w.step()
        by = {s.address: s for s in w.view().stations}
        assert by[3].category == "data exchange" and by[3].master == m.address
        assert by[4].category == "waiting" and by[4].master is None
    finally:
        m.link.close()


def test_an_address_that_appears_later_is_found_by_the_round_robin_probe():
    m = _master("sim://?stations=3:fuji-g1,9:yaskawa")
    try:
        w = BusWatch(m, 0, 20, probe_per_pass=4)
        bus_slaves = m.link.bus.slaves if hasattr(m.link, "bus") else None
        if bus_slaves is None:
            pytest.skip("the sim link does not expose its bus")
        hidden = bus_slaves.pop(9)            # station 9 is off the bus during the first scan
        w.start()
        assert [s.address for s in w.view().stations] == [3]
        bus_slaves[9] = hidden                # plugged in
        # 19 empty addresses (0..20 without 1 = master, 3 and 9... 9 is empty now) at 4 per pass
        for _ in range(6):
            w.step()
        assert [s.address for s in w.view().stations] == [3, 9]
    finally:
        m.link.close()


# ---------------------------------------------------------------------------------------------
# the command
# ---------------------------------------------------------------------------------------------


def run(*args):
    return CliRunner().invoke(cli, list(args))


def test_watch_json_is_a_stream_that_ends_with_an_end_event():
    r = run("scan", "--port", "sim://?stations=3:fuji-g1,6:moeller", "--watch", "--duration", "1.2",
            "--interval", "0.5", "--json")
    assert r.exit_code == 0, r.output
    lines = [json.loads(x) for x in r.output.splitlines()]
    assert [x["event"] for x in lines[:-1]] == ["watch"] * (len(lines) - 1) and len(lines) >= 3
    end = lines[-1]
    assert end["event"] == "end"
    assert [(s["station"], s["ident"], s["ident_hex"]) for s in end["stations"]] == [
        (3, 0xFD01, "0xFD01"), (6, 0xFD06, "0xFD06")]
    assert end["t_s"] >= 1.2


def test_watch_on_a_lossy_line_shows_rising_retries():
    r = run("scan", "--port", "sim://?drop=0.05&stations=3:fuji-g1", "--watch", "--duration", "2",
            "--interval", "1", "--json")
    assert r.exit_code == 0, r.output
    lines = [json.loads(x) for x in r.output.splitlines()]
    assert_stream(lines, "scan watch")                    # docs/json.md
    end = lines[-1]
    (s,) = end["stations"]
    assert s["counters"]["retries"] > 0 and s["rates_per_s"]["retries"] > 0


def test_watch_text_without_a_terminal_prints_one_table_at_the_end():
    r = run("scan", "--port", "sim://?stations=3:fuji-g1", "--watch", "--duration", "0.5", "--interval", "0.2")
    assert r.exit_code == 0, r.output
    assert r.output.count("watched") == 1 and "0xFD01" in r.output and "waiting" in r.output


def test_watch_with_no_station_exits_1():
    r = run("scan", "--port", "sim://", "--from", "10", "--to", "12", "--watch", "--duration", "0.3")
    assert r.exit_code == 1


def test_duration_without_watch_is_a_usage_error():
    from profidrive_cli import UsageError           # main() turns it into one line and exit 2
    r = run("scan", "--port", "sim://", "--duration", "3")
    assert isinstance(r.exception, UsageError) and "--duration goes with --watch" in str(r.exception)


# ---------------------------------------------------------------------------------------------
# the checklist step
# ---------------------------------------------------------------------------------------------

CHECKLIST = """\
name: bus health
port: sim://
stations:
  - address: 3
    profile: fuji-g1
steps:
  - bus_health: {seconds: 1.5}
"""


def _checklist(tmp_path, text=CHECKLIST):
    p = tmp_path / "bh.yaml"
    p.write_text(text)
    return p


def test_bus_health_passes_on_a_clean_simulated_segment(tmp_path):
    r = run("checklist", "run", str(_checklist(tmp_path)), "--yes", "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.output)
    step = doc["stations"][0]["steps"][0]
    assert step["status"] == "passed"
    assert step["measured"]["retries"] == 0 and step["measured"]["requests"] > 0


def test_bus_health_fails_a_lossy_segment(tmp_path):
    r = run("checklist", "run", str(_checklist(tmp_path)), "--port", "sim://?drop=0.05", "--yes", "--json")
    assert r.exit_code == 1, r.output
    step = json.loads(r.output)["stations"][0]["steps"][0]
    assert step["status"] == "failed"
    assert step["measured"]["retries_per_1000"] > 10
    assert "marginal segment" in step["message"]


def test_bus_health_thresholds_are_the_users(tmp_path):
    # a loose threshold lets the same lossy line pass: the step compares with the user's numbers
    text = CHECKLIST.replace("{seconds: 1.5}", "{seconds: 1.5, max_retries_per_1000: 1000, max_no_answer: 1000}")
    r = run("checklist", "run", str(_checklist(tmp_path, text)), "--port", "sim://?drop=0.05", "--yes", "--json")
    assert r.exit_code == 0, r.output


@pytest.mark.parametrize("body, message", [
    ("{seconds: 0}", "'seconds' must be above 0"),
    ("{max_retries_per_1000: -1}", "'max_retries_per_1000' must be at least 0"),
    ("{retries: 3}", "retries"),
])
def test_bad_bus_health_fields_name_the_line(tmp_path, body, message):
    r = run("checklist", "validate", str(_checklist(tmp_path, CHECKLIST.replace("{seconds: 1.5}", body))))
    assert r.exit_code == 2
    assert "bh.yaml:7" in r.output and message in r.output
