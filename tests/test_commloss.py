"""The comm-loss acceptance test (session/commloss.py, pdrive commloss-test, the checklist step
comm_loss) on the simulated plant.

Expected bounds are worked by hand from the rule in docs/commands.md: watchdog + configured delay +
stop time at the test speed (ramp time from max frequency x speed / max frequency) + tolerance
(0.25 s + half the watchdog). With a 200 ms watchdog the tolerance is 0.35 s. The drives' own
settings come from the manuals (Fuji o27 table 9.1, Moeller P002, Yaskawa F6-01, Toyo protection 18);
the virtual-clock simulator makes the times exact and the tests fast.
"""

import json

import pytest
from click.testing import CliRunner

from conftest import pdrive_cmd, pty_sim_process, run_main
from profidrive_cli.cli.common import BusOptions
from profidrive_cli.cli.main import cli
from profidrive_cli.session import DriveStation
from profidrive_cli.session.commloss import run_commloss
from test_json_contract import assert_stream

URL = "sim://?timing=virtual"
WD_MS = 200


def session(url, address, **kw):
    m = BusOptions(url, "19200", 2, None, None, False, False, 0, False).open_master()
    return DriveStation(m, address, watchdog_ms=WD_MS, cycle_hz=20, handle_signals=False, **kw)


def commloss(url, address, hz=20.0, **kw):
    with session(url, address) as s:
        res = run_commloss(s, hz, **kw)
    return res, s


# (station, sim presets, expected bound by hand (s), earliest possible reaction (s), fault code)
PASSING = [
    # Fuji o27 = 0 (factory): coast + Er5 at once: 0.2 + 0.35
    (3, "", 0.55, 0.2, "Er5"),
    # Fuji PDP3 o27 = 11, o28 = 1.5 s: wait o28, then F08 (6 s from F03 = 60 Hz) from 20 Hz = 2 s,
    # Er5 once stopped: 0.2 + 1.5 + 2.0 + 0.35; not before 0.2 + 1.5 + 2.0
    (4, "&set=4:o27=11,o28=1.5", 4.05, 3.7, "Er5"),
    # Fuji PDP3 o27 = 12, o28 = 1 s (forgiven if the link returns within o28: the master stays away
    # longer): 0.2 + 1 + 2 + 0.35; not before 3.2
    (4, "&set=4:o27=12,o28=1", 3.55, 3.2, "Er5"),
    # Toyo: protection 18 at once: 0.2 + 0.35
    (5, "", 0.55, 0.2, "COMM"),
    # Moeller P002 = 0: trip E70 at once
    (6, "", 0.55, 0.2, "E70"),
    # Yaskawa F6-01 = 0: ramp with C1-02 = 3 s from E1-04 = 60 Hz -> 1 s from 20 Hz, then BUS
    (7, "&set=7:F6-01=0,C1-02=3", 1.55, 1.2, "BUS"),
]


@pytest.mark.parametrize("address,preset,bound,earliest,code", PASSING,
                         ids=["fuji-g1-o27=0", "pdp3-o27=11", "pdp3-o27=12", "toyo", "moeller-P002=0",
                              "yaskawa-F6-01=0"])
def test_every_family_passes_with_the_reaction_measured_within_the_bound(address, preset, bound,
                                                                         earliest, code):
    res, s = commloss(URL + preset, address)
    assert res.expected_s == pytest.approx(bound, abs=1e-6)
    assert res.passed, res.verdict
    assert res.reacted and res.watchdog_expired is True
    assert earliest - 1e-6 <= res.measured_s <= bound
    assert res.fault_code == code and res.final_state.startswith("fault")
    assert s.motion.stop_report.stopped
    assert res.acknowledged is False                  # no --ack: the fault stays


def test_yaskawa_default_coast_is_seen_when_the_master_comes_back():
    """F6-01 = 1 (factory): coast + BUS at the watchdog; the reaction is seen at the first cycle back,
    whose answer comes in before the 0.55 s limit (the fault code is read after that look)."""
    res, _ = commloss(URL, 7)
    assert res.reaction.settings == {"F6-01": 1}
    assert res.passed and res.fault_code == "BUS"
    assert res.measured_s == res.back_s and 0.2 <= res.measured_s <= res.expected_s
    assert "a look that came back then saw it" in res.verdict


# (station, preset that makes the drive ride through a lost master, words in the reaction)
IGNORING = [
    (3, "&set=3:o27=3", "o27 = 3"),
    (4, "&set=4:o27=13", "o27 = 13"),
    (6, "&set=6:P002=1", "P002 = 1"),
    (7, "&set=7:F6-01=3", "F6-01 = 3"),
]


@pytest.mark.parametrize("address,preset,words", IGNORING, ids=["fuji-g1", "fuji-pdp3", "moeller", "yaskawa"])
def test_a_drive_set_to_ignore_the_loss_fails_and_ends_stopped(address, preset, words):
    res, s = commloss(URL + preset, address)
    assert not res.passed
    assert res.verdict.startswith("FAIL: the drive is set to keep running without a master")
    assert words in res.verdict
    assert not res.reacted                    # it really kept running
    assert res.stop["needed"] is True and res.stop["stopped"] is True
    assert s.motion.final_status.stopped and not s.motion.final_status.running


def test_toyo_configured_to_ignore_in_the_sim_fails_and_ends_stopped(sim):
    """The Toyo manual names no setting: the sim's comm_loss="ignore" stands in for such a drive. The
    reaction read from the drive still says protection 18, so the measured running motor fails it."""
    with session(URL, 5) as s:
        sim[URL].slaves[5].model.comm_loss = "ignore"
        res = run_commloss(s, 20.0)
    assert not res.passed and not res.reacted
    assert res.verdict.startswith("FAIL: still running at")
    assert res.stop["needed"] is True and s.motion.final_status.stopped


def test_ack_acknowledges_the_fault(sim):
    res, s = commloss(URL, 6, ack=True)
    assert res.passed and res.acknowledged
    assert not s.motion.final_status.fault and s.motion.final_status.stopped


def test_clear_mode_keeps_the_last_command_on_fuji_and_fails():
    """Global_Control Clear: outputs zero, so CTW bit 10 = 0, which on the OPC-G1-PDP leaves the last
    command in force (spec 3.1): the drive keeps running -> FAIL, and pdrive stops it."""
    res, s = commloss(URL, 3, mode="clear")
    assert not res.passed and not res.reacted
    assert s.motion.final_status.stopped


def test_bad_arguments_are_refused_before_anything_moves():
    from profidrive_cli import UsageError
    with session(URL, 3) as s:
        with pytest.raises(UsageError, match="mode"):
            run_commloss(s, 20.0, mode="loud")
        with pytest.raises(UsageError, match="0 Hz"):
            run_commloss(s, 0.0)
        assert s.cycles <= 2 and not s.motion.may_run


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args], env={"PDRIVE_PORT": ""})


def test_cli_pass_text_and_fail_json_exit_codes():
    r = run("commloss-test", 6, "--port", URL, "--watchdog", WD_MS)
    assert r.exit_code == 0, r.output
    assert "P002 = 0" in r.output and "PASS: tripped (E70)" in r.output
    r = run("commloss-test", 6, "--port", URL + "&set=6:P002=1", "--watchdog", WD_MS, "--json")
    assert r.exit_code == 1
    events = [json.loads(line) for line in r.stdout.splitlines()]
    assert all("event" in e for e in events)
    assert_stream(events, "commloss-test")                # docs/json.md
    assert events[0]["event"] == "start" and events[0]["ident_hex"] == "0xFD06"
    last = events[-1]
    assert last["event"] == "result" and last["passed"] is False and last["watchdog_s"] == WD_MS / 1000.0
    assert last["stop"]["stopped"] is True and "duration_s" in last["stop"] and "seconds" not in last["stop"]
    assert events[0]["watchdog_s"] == WD_MS / 1000.0 and "watchdog_ms" not in events[0]


def test_checklist_step_comm_loss_passes_and_fails():
    from pathlib import Path
    ex = Path(__file__).resolve().parents[1] / "examples" / "checklists" / "acceptance" / "comm-loss.yaml"
    r = run("checklist", "run", ex, "--yes", "--watchdog-ms", WD_MS, "--port", URL)
    assert r.exit_code == 0, r.output
    assert r.output.count("PASS: tripped") == 5
    r = run("checklist", "run", ex, "--yes", "--watchdog-ms", WD_MS, "--port", URL + "&set=3:o27=3")
    assert r.exit_code != 0
    assert "keep running without a master" in r.output


def test_checklist_step_validation(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_text("name: x\nstations:\n  - {name: a, address: 3, profile: fuji-g1}\nsteps:\n"
                 "  - comm_loss: {hz: 20, mode: loud}\n")
    r = run("checklist", "validate", p)
    assert r.exit_code == 2
    text = r.output + (r.stderr if r.stderr_bytes is not None else "")
    assert "c.yaml:5" in text and "mode must be silence or clear, got 'loud'" in text


def test_over_a_pty_simulator():
    import subprocess
    with pty_sim_process() as port:
        q = subprocess.run(pdrive_cmd() + ["commloss-test", "3", "--port", port, "--watchdog", "200"],
                           capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
        p = subprocess.run(pdrive_cmd() + ["commloss-test", "3", "--port", port, "--watchdog", "200",
                                           "--yes", "--json"],
                           capture_output=True, text=True, timeout=60)
    assert q.returncode == 2 and "add --yes" in q.stderr       # a real port asks; nothing was sent
    assert p.returncode == 0, p.stderr
    last = json.loads(p.stdout.splitlines()[-1])
    assert last["passed"] is True and last["fault_code"] == "Er5"
    assert 0.2 <= last["measured_s"] <= last["expected_s"] + 2.0


@pytest.mark.parametrize("sig", ["SIGTERM", "SIGINT"])
def test_a_signal_while_the_master_is_silent_still_stops_the_drive(sig):
    """o27 = 2 with o28 = 30 s: during the silence the drive is still running (it forgives a link that
    returns within o28). A signal then must bring the station back and stop the drive."""
    import signal
    import subprocess
    with pty_sim_process("--plant", "sim://?set=3:o27=2,o28=30") as port:
        p = subprocess.Popen(pdrive_cmd() + ["commloss-test", "3", "--port", port, "--watchdog", "200",
                                             "--yes", "--json"], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True)
        try:
            for line in p.stdout:
                if json.loads(line)["event"] == "silence":
                    break
            p.send_signal(getattr(signal, sig))
            out, err = p.communicate(timeout=30)
        finally:
            if p.poll() is None:
                p.kill()
        assert p.returncode == (143 if sig == "SIGTERM" else 130), err
        assert "Traceback" not in err
        st = subprocess.run(pdrive_cmd() + ["status", "3", "--port", port, "--json"],
                            capture_output=True, text=True, timeout=30)
        doc = json.loads(st.stdout)
        assert doc["stopped"] and not doc["running"], doc


def test_late_watchdog_tick_times_the_reaction_from_the_expiry():
    """The simulated station's watchdog expires at last telegram + watchdog, also when its clock is
    ticked only later (a silent master on the virtual clock): the drive model hears of it then."""
    from profidrive_cli.sim.model import SlaveModel
    from profidrive_cli.sim.slave import DATA_EXCH, WAIT_PRM, SimSlave

    class Spy(SlaveModel):
        left = None

        def on_leave_data_exchange(self, now, reason):
            self.left = (now, reason)
    m = Spy(0x1234)
    s = SimSlave(3, m)
    s.state, s.wd_s, s.last_seen = DATA_EXCH, 0.2, 1.0
    s.tick(3.0)
    assert m.left == (pytest.approx(1.2), "watchdog")
    assert s.state == WAIT_PRM


def test_fuji_o27_1_trips_after_o28_although_the_master_is_back():
    """o27 = 1: coast and Er5 when o28 has elapsed, even if the link returns (table 9.1). The master
    comes back after 1.25 x 0.2 + 0.05 s and keeps sending the run command; the trip comes at
    0.2 + 1.0 s. Bound 0.2 + 1.0 + 0.35."""
    res, _ = commloss(URL + "&set=3:o27=1,o28=1", 3)
    assert res.back_s < 1.2 and res.expected_s == pytest.approx(1.55)
    assert res.passed and res.fault_code == "Er5"
    assert 1.2 - 1e-6 <= res.measured_s <= 1.55


def test_yaskawa_fast_stop_uses_c1_09():
    """F6-01 = 2: fast stop with C1-09 = 1.5 s (from E1-04 = 60 Hz: 0.5 s from 20 Hz), then BUS.
    Bound 0.2 + 0.5 + 0.35; not before 0.7."""
    res, _ = commloss(URL + "&set=7:F6-01=2,C1-09=1.5", 7)
    assert res.expected_s == pytest.approx(1.05)
    assert res.passed and res.fault_code == "BUS"
    assert 0.7 - 1e-6 <= res.measured_s <= 1.05


def test_a_layout_without_parameter_channel_is_refused():
    import subprocess
    p = subprocess.run(pdrive_cmd() + ["commloss-test", "3", "--port", URL, "--ppo", "4"],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 2
    assert "layout ppo4 has no parameter channel" in p.stderr and "Traceback" not in p.stderr


@pytest.mark.parametrize("args, words", [
    (("--tolerance", "-1"), "--tolerance -1 must be 0 s or more"),
    (("--start-timeout", "0"), "--start-timeout 0 must be above 0 s"),
    (("--hz", "0"), "--hz 0: the test needs a speed other than 0 Hz"),
])
def test_bad_options_are_refused_before_the_bus_is_opened(capsys, monkeypatch, args, words):
    """One line, exit 2, and no telegram: the header (printed once the station is open) never comes,
    and a bus that fails when opened shows the check ran first."""
    from profidrive_cli.cli import common

    def no_bus(*a, **k):
        raise AssertionError("the bus was opened")
    monkeypatch.setattr(common.BusOptions, "open_master", no_bus)
    r = run_main(capsys, monkeypatch, "commloss-test", "3", "--port", "sim://", *args)
    assert r.exit_code == 2, r.output
    assert r.stderr == f"pdrive: {words}\n" and r.stdout == ""
