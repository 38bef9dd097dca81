"""pdrive run 3,4,5: several drives on one bus cycle, the stop of every drive on every way out, --sync
(Global_Control Sync/Freeze where every station's GSD claims it), and the simulated slave's Sync and
Freeze as reference 3.5 describes them (outputs applied only on Sync, inputs latched on Freeze)."""

import json
import signal
import subprocess

import pytest

from conftest import SHORT_RAMPS, pdrive_cmd, read_until_turning, short_ramps_pty_sim, status_of
from test_json_contract import assert_stream
from profidrive_cli.dp import services as S
from profidrive_cli.sim.model import SlaveModel
from profidrive_cli.sim.slave import SimSlave

from test_sim_slave import CFG, IDENT, Link

ALL = [3, 4, 5, 6, 7]
# short ramps keep the tests quick (Toyo's are fixed: 5 s to 60 Hz)
RAMPS = SHORT_RAMPS
SIM_FAST = "sim://?" + "&".join(f"set={a}:{c1}=0.3,{c2}=0.3" for a, (c1, c2) in RAMPS.items())


def pdrive(*args, timeout=120):
    return subprocess.run(pdrive_cmd() + [str(a) for a in args], capture_output=True, text=True,
                          timeout=timeout, stdin=subprocess.DEVNULL)


def events(text):
    """The JSON Lines of `run 3,4,5 --json`, each checked against docs/json.md ("run multi")."""
    lines = [json.loads(line) for line in text.strip().splitlines()]
    assert_stream(lines, "run multi")
    return lines


# -- the simulated slave: Sync and Freeze ---------------------------------------------------------

class Recorder(SlaveModel):
    """Inputs = the outputs the application uses, followed by the time of the call (whole seconds)."""

    def __init__(self):
        super().__init__(IDENT, {"ppo1": CFG})
        self.sync_supported = self.freeze_supported = True
        self.applied = []

    def data_exchange(self, outputs, now):
        self.applied.append((bytes(outputs), now))
        return bytes(outputs[:11]) + bytes([int(now)])


def _gc(slave, command, now, sa=2):
    from profidrive_cli.fdl import frames as F
    f = F.Frame(F.SD2, 127, sa, F.request_fc(F.SDN_HIGH), S.GlobalControl(command, 0).encode(),
                S.SAP_GLOBAL_CONTROL, S.SAP_MASTER)
    assert slave.handle(F.parse(F.encode(f))[0], now) is None


def _started(sync=False, freeze=False):
    slave = SimSlave(3, Recorder())
    m = Link(slave)
    m.diag()
    prm = S.SetPrm(IDENT, 10000, sync=sync, freeze=freeze)
    m.req(S.SAP_SET_PRM, prm.encode())
    m.req(S.SAP_CHK_CFG, CFG)
    return slave, m


def out(n):
    return bytes([n]) * 12


def test_sync_applies_the_outputs_only_on_the_next_sync():
    slave, m = _started(sync=True)
    assert not m.diag().st2 & S.ST2["Sync_Mode"]                     # asked for, not yet in force
    assert m.req(None, out(1), now=1.0).data[:11] == out(1)[:11]     # no Sync yet: applied at once
    _gc(slave, S.GC_SYNC, 2.0)                                        # Sync: out(1) held from now
    assert m.diag().st2 & S.ST2["Sync_Mode"]
    assert m.req(None, out(2), now=3.0).data[:11] == out(1)[:11]     # received, not applied
    assert m.req(None, out(3), now=4.0).data[:11] == out(1)[:11]
    _gc(slave, S.GC_SYNC, 5.0)                                        # the last received takes effect
    assert slave.model.applied[-1] == (out(3), 5.0)
    assert m.req(None, out(4), now=6.0).data[:11] == out(3)[:11]
    _gc(slave, S.GC_UNSYNC, 7.0)                                      # Unsync: out(4) takes effect now
    assert slave.model.applied[-1] == (out(4), 7.0)
    assert not m.diag().st2 & S.ST2["Sync_Mode"]
    assert m.req(None, out(5), now=8.0).data[:11] == out(5)[:11]     # and each exchange again


def test_freeze_latches_the_inputs_until_the_next_freeze():
    slave, m = _started(freeze=True)
    assert m.req(None, out(1), now=1.0).data[11] == 1                 # live inputs
    _gc(slave, S.GC_FREEZE, 2.0)
    assert m.diag().st2 & S.ST2["Freeze_Mode"]
    assert m.req(None, out(1), now=3.0).data[11] == 2                 # sampled at the Freeze
    assert m.req(None, out(1), now=4.0).data[11] == 2
    _gc(slave, S.GC_FREEZE, 5.0)
    assert m.req(None, out(1), now=6.0).data[11] == 5
    _gc(slave, S.GC_UNFREEZE, 7.0)
    assert m.req(None, out(1), now=8.0).data[11] == 8                 # live again


def test_sync_without_sync_req_is_ignored_and_a_new_set_prm_ends_it():
    slave, m = _started(sync=False)
    m.req(None, out(1), now=1.0)
    _gc(slave, S.GC_SYNC, 2.0)
    assert m.req(None, out(2), now=3.0).data[:11] == out(2)[:11]     # not parameterised for Sync
    slave, m = _started(sync=True)
    m.req(None, out(1), now=1.0)
    _gc(slave, S.GC_SYNC, 2.0)
    m.req(S.SAP_SET_PRM, S.SetPrm(IDENT, 10000, sync=True).encode(), now=3.0)   # leaves data exchange
    m.req(S.SAP_CHK_CFG, CFG, now=3.0)
    assert m.req(None, out(2), now=4.0).data[:11] == out(2)[:11]     # no Sync in force any more


def test_the_plant_offers_sync_and_freeze_where_the_gsd_claims_them():
    from profidrive_cli.sim.plant import build_bus
    bus = build_bus("sim://")
    # gsd/*.GSD: only YASK00CA.GSD has Sync_Mode_supp = 1 and Freeze_Mode_supp = 1
    modes = {a: (s.model.sync_supported, s.model.freeze_supported) for a, s in bus.slaves.items()}
    assert modes == {3: (False, False), 4: (False, False), 5: (False, False), 6: (False, False),
                     7: (True, True)}
    slave = bus.slaves[3]
    m = Link(slave, master=2)
    m.diag()
    m.req(S.SAP_SET_PRM, S.SetPrm(0xFD01, 500, sync=True).encode())
    d = m.diag()
    assert d.st1 & S.ST1["Prm_Fault"] and d.st1 & S.ST1["Not_Supported"]


# -- several drives on sim:// ---------------------------------------------------------------------

def test_five_drives_reach_20_hz_and_end_stopped_on_sim():
    r = pdrive("run", "3,4,5,6,7", "--hz", "20", "--duration", "2", "--yes", "--json", "--port", SIM_FAST)
    assert r.returncode == 0, r.stderr
    ev = events(r.stdout)
    assert ev[0]["event"] == "start" and [s["station"] for s in ev[0]["stations"]] == ALL
    assert all(s["reference_hz"] == 20.0 for s in ev[0]["stations"])
    for a in ALL:
        ups = [e for e in ev if e["event"] == "update" and e["station"] == a]
        running = [e["actual_hz"] for e in ups if e["phase"] == "running"]
        assert running and abs(running[-1] - 20.0) <= 0.2, (a, running[-3:])
        assert ups[-1]["phase"] == "stopping" and ups[-1]["stopped"] and not ups[-1]["fault"]
        assert ups[-1]["actual_hz"] == 0.0
    end = ev[-1]
    assert end["event"] == "end" and end["stopped"] and not end["failed"]
    for s in end["stations"]:
        assert s["reached_after_s"] is not None and s["stop"]["how"] == "normal" and s["stopped"]


def test_one_speed_each():
    r = pdrive("run", "3,6", "--hz", "20,10", "--duration", "1.5", "--yes", "--json", "--port", SIM_FAST)
    assert r.returncode == 0, r.stderr
    ev = events(r.stdout)
    last = {e["station"]: e for e in ev if e["event"] == "update" and e["phase"] == "running"}
    assert abs(last[3]["actual_hz"] - 20.0) <= 0.2 and abs(last[6]["actual_hz"] - 10.0) <= 0.2


@pytest.mark.parametrize("args, words", [
    (["3,4", "--hz", "20,10,5"], "3 values for 2 stations"),
    (["3", "--hz", "20,10"], "2 values for one station"),
    (["3,4", "--hz", "20", "--torque", "10"], "--torque: one station only"),
    (["3,3", "--hz", "20"], "station 3 given twice"),
    (["3", "--hz", "20", "--sync"], "--sync: give several stations"),
])
def test_bad_lists_are_refused_before_anything_is_sent(args, words):
    r = pdrive("run", *args, "--yes", "--port", "sim://")
    assert r.returncode == 2 and words in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert r.stdout == ""


def test_sync_is_refused_where_a_gsd_does_not_claim_it():
    r = pdrive("run", "3,7", "--hz", "20", "--sync", "--yes", "--json", "--port", "sim://")
    assert r.returncode == 2
    assert r.stderr.strip().splitlines()[-1].endswith(
        "--sync: station 3 (fuji-opc-g1-pdp, ident 0xFD01): its GSD FUJIFD01.GSD does not claim "
        "Sync_Mode_supp; nothing was written")
    # under --json the same line is the one object on stdout (docs/json.md: errors)
    assert [json.loads(x) for x in r.stdout.splitlines()] == [{
        "event": "error", "exit_code": 2, "error": r.stderr.strip().splitlines()[-1].removeprefix("pdrive: ")}]


def test_sync_on_stations_whose_gsd_claims_it(sim):
    """Two Yaskawa stations (YASK00CA.GSD: Sync_Mode_supp = 1, Freeze_Mode_supp = 1): Set_Prm asks
    for both modes, every round ends with Sync+Freeze, the drives reach their speeds and stop."""
    from profidrive_cli.cli.common import BusOptions
    from profidrive_cli.session.multirun import MultiRun
    url = "sim://?stations=7:yaskawa,8:yaskawa&set=7:C1-01=0.3,C1-02=0.3&set=8:C1-01=0.3,C1-02=0.3"
    front = BusOptions(url, "19200", 2, None, None, False, False, 0, False).open_bus()
    seen = []

    def on_sample(address, t, sample, phase):
        bus = next(iter(sim.values()))
        s = bus.slaves[address]
        seen.append((s.sync, s.freeze, s.synced_outputs is not None, s.frozen_inputs is not None))
    run = MultiRun(front, [7, 8], [("hz", 20.0), ("hz", 10.0)], duration=1.0, sync=True,
                   on_sample=on_sample)
    assert run.run() == 0
    assert run.sync and run.freeze
    assert (True, True, True, True) in seen          # both modes in force on the stations
    end = run.end_dict()
    assert end["global_controls"] == end["rounds"] + 1      # one per round, then Unsync+Unfreeze
    assert [s["stopped"] for s in end["stations"]] == [True, True]
    bus = next(iter(sim.values()))
    assert bus.slaves[7].synced_outputs is None and bus.slaves[8].frozen_inputs is None


@pytest.mark.parametrize("addresses", [[3, 4], [3, 9]])
def test_the_run_takes_its_stations_from_the_bus_and_closes_its_port_once(sim, addresses):
    """MultiRun on the front door (api.Bus): one Bus.station per station, in order; at the end (also
    when a station is not on the bus: station 9 is not in the default plant, ALL above) the bus is
    closed and its port closed exactly once; closing the bus again does not touch the port."""
    from profidrive_cli import PdriveError
    from profidrive_cli.cli.common import BusOptions
    from profidrive_cli.session.multirun import MultiRun
    front = BusOptions(SIM_FAST + "&timing=virtual", "19200", 2, None, None, False, False, 0,
                       False).open_bus()
    link, closes, asked = front.master.link, [], []
    real_close, real_session = link.close, front.station

    def close():
        closes.append(1)
        real_close()

    def session(station, **kw):
        asked.append(station)
        return real_session(station, **kw)
    link.close, front.station = close, session
    run = MultiRun(front, addresses, [("hz", 20.0)] * 2, duration=0.5)
    if 9 in addresses:
        with pytest.raises(PdriveError):
            run.run()
    else:
        assert run.run() == 0, run.end_dict()
    assert asked == addresses[:len(run.runs)] and asked[0] == 3
    assert front.closed and closes == [1]
    front.close()
    assert closes == [1]
    assert run.end_dict()["stopped"]

# -- signals over a real byte path (pdrive sim --pty) ---------------------------------------------

@pytest.fixture(scope="module")
def pty_sim(tmp_path_factory):
    with short_ramps_pty_sim(tmp_path_factory) as port:
        yield port


_status = status_of


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_signal_leaves_every_drive_stopped(pty_sim, sig):
    p = subprocess.Popen(pdrive_cmd() + ["run", "3,4,5,6,7", "--hz", "20", "--port", pty_sim, "--yes",
                                         "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         stdin=subprocess.DEVNULL, text=True)
    try:
        read_until_turning(p, deadline_s=60)
        p.send_signal(sig)
        outs, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == (143 if sig == signal.SIGTERM else 130), err
    end = json.loads(outs.strip().splitlines()[-1])
    assert end["event"] == "end" and end["reason"] == ("SIGTERM" if sig == signal.SIGTERM else "Ctrl-C")
    assert "Traceback" not in err
    for s in end["stations"]:
        if s["started"]:
            assert s["stop"]["how"] == "normal" and s["stopped"], s
    for a in ALL:
        st = _status(pty_sim, a)
        assert st["stopped"] and not st["running"] and not st["fault"], (a, st)


def test_five_drives_over_a_pty_reach_20_hz_and_end_stopped(pty_sim):
    # the slowest ramp is the Toyo drive's (station 5: no short ramp, sim/toyo.py accel_s 5 s for
    # 60 Hz): 20 Hz after 5 x 20 / 60 = 1.67 s; three times that leaves room for a loaded machine
    r = pdrive("run", "3,4,5,6,7", "--hz", "20", "--duration", "5", "--yes", "--json", "--port", pty_sim)
    assert r.returncode == 0, r.stderr
    for a in ALL:
        st = _status(pty_sim, a)
        assert st["stopped"] and not st["running"] and not st["fault"], (a, st)
    last = {e["station"]: e for e in events(r.stdout) if e["event"] == "update" and e["phase"] == "running"}
    assert all(abs(last[a]["actual_hz"] - 20.0) <= 0.2 for a in ALL), last


@pytest.mark.parametrize("fault, station", [("powercycle", 5), ("drivetrip", 6)])
def test_a_station_dropping_out_or_tripping_stops_every_drive(fault, station):
    """sim fault injection on one station: the run ends with exit 1 naming it, and every other
    drive that was started is stopped by its normal stop."""
    r = pdrive("run", "3,4,5,6,7", "--hz", "20", "--duration", "4", "--yes", "--json", "--port",
               f"{SIM_FAST}&{fault}=0.03&only={station}&seed=3")
    assert r.returncode == 1, r.stderr
    assert f"station {station}" in r.stderr.strip().splitlines()[-1] and "Traceback" not in r.stderr
    *_, end, error = events(r.stdout)
    assert error["event"] == "error" and error["exit_code"] == 1       # the error object follows "end"
    assert end["event"] == "end" and end["failed"] and f"station {station}" in end["reason"]
    by = {s["station"]: s for s in end["stations"]}
    assert by[station]["problem"]
    for a in ALL:
        if a != station and by[a]["started"]:
            assert by[a]["stop"]["how"] == "normal" and by[a]["stopped"], by[a]
    assert end["stopped"]


# -- checklists: run with together: true ----------------------------------------------------------

LINE = """name: line
stations:
  - {name: conveyor-1, address: 3, profile: fuji-g1}
  - {name: conveyor-2, address: 6, profile: moeller}
  - {name: hoist, address: 7, profile: yaskawa}
steps:
  - run: {hz: 20, duration: 1, together: true}
    stations: [conveyor-1, hoist]
  - expect_status: {stopped: true, fault: false}
"""


def test_checklist_run_together_runs_the_stations_at_once_and_stops_them(sim):
    from profidrive_cli.checklist.runner import PASSED, Observer, Runner, session_opener
    from profidrive_cli.checklist.spec import load_checklist_text
    from profidrive_cli.cli.common import BusOptions
    url = ("sim://?stations=3:fuji-g1,6:moeller,7:yaskawa&set=3:F07=0.3,F08=0.3&set=6:F002=0.3,F003=0.3"
           "&set=7:C1-01=0.3,C1-02=0.3")
    front = BusOptions(url, "19200", 2, None, None, False, False, 0, False).open_bus()
    seen = []

    class Watch(Observer):
        def step_progress(self, station, result, text):
            bus = next(iter(sim.values()))
            # which stations' motors turn at this moment (the simulated drives' own speed)
            seen.append({a for a, s in bus.slaves.items() if abs(_turning(s)) > 0.5})

    res = Runner(load_checklist_text(LINE, "line.yaml"), session_opener(front), yes=True,
                 observer=Watch()).run()
    front.close()
    by = {s.spec.name: s for s in res.stations}
    assert [s.status for s in res.stations] == [PASSED, PASSED, PASSED], \
        [(s.spec.name, [(r.status, r.message) for r in s.steps]) for s in res.stations]
    for name in ("conveyor-1", "hoist"):
        run = by[name].steps[0]
        assert abs(run.measured["actual_hz"] - 20.0) <= 0.5 and run.measured["stopped"] is True
        assert run.expected["together_with"] == ("hoist" if name == "conveyor-1" else "conveyor-1")
    assert [r.step.type for r in by["conveyor-2"].steps] == ["expect_status"]   # not in the step's list
    assert {3, 7} in seen                   # both motors turned at the same time
    assert not any(6 in s for s in seen)    # the station not in the list never moved


def _turning(slave) -> float:
    """The simulated drive's output frequency (PROFIdrive models: freq, Yaskawa: out_hz)."""
    m = slave.model
    return getattr(m, "out_hz", None) if hasattr(m, "out_hz") else m.freq


def test_link_loss_names_each_stations_watchdog():
    from conftest import start_pty_sim
    sim, port = start_pty_sim()
    p = subprocess.Popen(pdrive_cmd() + ["run", "3,4,5,6,7", "--hz", "20", "--port", port, "--yes", "--json"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True)
    try:
        read_until_turning(p, deadline_s=60)
        sim.kill()
        sim.wait()
        outs, err = p.communicate(timeout=60)
    finally:
        for proc in (p, sim):
            if proc.poll() is None:
                proc.kill()
    assert p.returncode == 1 and "Traceback" not in err
    *_, end, error = events(outs)
    assert error["event"] == "error" and error["exit_code"] == 1       # the error object follows "end"
    assert end["event"] == "end" and end["reason"].startswith("error: link lost")
    started = [s for s in end["stations"] if s["started"]]
    assert started
    for s in started:
        assert s["stop"]["how"] == "not sent (link lost)" and not s["stopped"]
        assert "DP watchdog (500 ms)" in s["stop"]["message"]
    assert err.count("pdrive cannot send a stop") == len(started)


@pytest.mark.parametrize("sync", [True, False])
def test_with_sync_the_references_take_effect_in_the_same_instant(sim, sync):
    """Two Yaskawa stations: the instant each simulated drive first applies a non-zero reference.
    With --sync both come from the one Sync broadcast (the same time); without it, from two
    Data_Exchanges one after the other (different times)."""
    from profidrive_cli.cli.common import BusOptions
    from profidrive_cli.session.multirun import MultiRun
    url = "sim://?stations=7:yaskawa,8:yaskawa&set=7:C1-01=0.3,C1-02=0.3&set=8:C1-01=0.3,C1-02=0.3"
    front = BusOptions(url, "19200", 2, None, None, False, False, 0, False).open_bus()
    bus = next(iter(sim.values()))
    first = {}
    for a, slave in bus.slaves.items():
        model = slave.model

        def wrapped(outputs, now, _orig=model.data_exchange, _m=model, _a=a):
            res = _orig(outputs, now)
            if _m._ref_raw and _a not in first:
                first[_a] = now
            return res
        model.data_exchange = wrapped
    run = MultiRun(front, [7, 8], [("hz", 20.0), ("hz", 10.0)], duration=0.5, sync=sync)
    assert run.run() == 0
    assert set(first) == {7, 8}
    assert (first[7] == first[8]) is sync, first


def test_a_real_port_asks_once_for_all_stations(pty_sim):
    r = pdrive("run", "3,7", "--hz", "20", "--port", pty_sim)       # no --yes, no terminal to ask
    assert r.returncode == 2 and "Traceback" not in r.stderr
    line = r.stderr.strip().splitlines()[-1]
    assert "run 2 drives — stations 3 (fuji-opc-g1-pdp), 7 (yaskawa-si-p1) at 20 Hz, 20 Hz" in line
    assert "add --yes" in line and r.stdout == ""
    for a in (3, 7):
        st = _status(pty_sim, a)
        assert st["stopped"] and not st["running"], st


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)], ids=["SIGINT", "SIGTERM"])
def test_checklist_run_together_interrupted_leaves_every_drive_stopped(pty_sim, tmp_path, sig, code):
    import os
    import time
    f = tmp_path / "line.yaml"
    f.write_text(LINE.replace("duration: 1, together: true", "duration: 60, together: true, within: 30")
                 .replace("    stations: [conveyor-1, hoist]\n", "")
                 .replace("steps:\n", "steps:\n  - note: go\n    stations: conveyor-1\n"))
    p = subprocess.Popen(pdrive_cmd() + ["checklist", "run", str(f), "--port", pty_sim, "--yes"],
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                         env=dict(os.environ, PYTHONUNBUFFERED="1"))
    seen = []
    try:
        for line in p.stdout:
            seen.append(line)
            if "go" in line and "PASS" in line:
                break
        time.sleep(4)               # the three stations are opened and started (or starting)
        p.send_signal(sig)
        outs, _ = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == code, "".join(seen) + outs
    assert "Traceback" not in outs
    run_line = next(x for x in outs.splitlines() if "together with every station" in x)
    assert "ERROR" in run_line and "interrupted by" in run_line, outs
    for a in (3, 6, 7):
        st = _status(pty_sim, a)
        assert st["stopped"] and not st["running"] and not st["fault"], (a, st)
