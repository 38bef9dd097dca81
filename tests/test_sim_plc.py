"""`pdrive sim --plc`: a built-in PLC runs the plant and the whole bus goes to the endpoint as a tap
hears it; `pdrive sniff --port <pty> --station ...` then shows the PLC's commands to every drive in
words. Expected words from the specs' bit tables, speeds from the PLC's script (sim/plc.py:
50 % of the max frequency first) and the profiles' max frequencies (F03 = 60 Hz Fuji, A-00 = 60 Hz
Toyo, A004 = 50 Hz Moeller, E1-04 = 60 Hz Yaskawa)."""

import json
import os
import subprocess
import time

import pytest

from conftest import pdrive_cmd, start_pty_sim, stop_pty_sim
from test_json_contract import assert_contract

STATIONS = ["3=fuji-g1", "4=fuji-pdp3", "5=toyo", "6=moeller:ppo1", "7=yaskawa"]
STATION_ARGS = [a for s in STATIONS for a in ("--station", s)]


def sniff(port, seconds, *extra):
    r = subprocess.run(pdrive_cmd() + ["sniff", "--port", port, "--duration", str(seconds), *extra],
                       capture_output=True, text=True, timeout=seconds + 30)
    assert r.returncode == 0, r.stderr
    return r.stdout


@pytest.fixture(scope="module")
def plc_pty():
    p, port = start_pty_sim("--plc")
    try:
        yield port
    finally:
        stop_pty_sim(p)


#: the PLC script runs each drive at 50 %, then 25 % of its max frequency (in Hz per station)
SPEEDS = {3: {30.0, 15.0}, 4: {30.0, 15.0}, 5: {30.0, 15.0}, 6: {25.0, 12.5}, 7: {30.0, 15.0}}
#: what the PLC reads on the parameter channel (the Yaskawa codec also reads o1-03, the frequency
#: unit, with E1-04), and the values the profiles give for some of them (the max frequency
#: parameters and Fuji's F07 factory setting 6.0 s)
READS = {3: ("F03", "F07", "W90"), 6: ("A004", "F002", "PNU340"),
         7: ("E1-04", "o1-03", "C1-01", "PWR")}
KNOWN = {"F03": "60.0 Hz", "F07": "6.0 s", "A004": "50 Hz", "E1-04": "60 Hz"}


def test_sniff_shows_the_plcs_commands_to_each_drive_in_words(plc_pty):
    out = sniff(plc_pty, 6, *STATION_ARGS, "--json")
    objs = [json.loads(line) for line in out.splitlines()]
    # a tap that joins a running line may hear the tail of a frame first, in one or more pieces (on
    # a loaded machine a read can split it), and a data octet E5 in that tail reads as a short
    # acknowledgement (CI saw "e5" then a bad_frame): bad_frames only in that tail, the whole tail
    # (up to the last bad_frame) shorter than the longest telegram (SD2 with LE = 249:
    # 4 + 249 + 2 = 255 octets); every frame after it is whole
    bads = [i for i, o in enumerate(objs) if o["event"] == "bad_frame"]
    tail_objs, objs = (objs[:bads[-1] + 1], objs[bads[-1] + 1:]) if bads else ([], objs)
    for o in tail_objs:
        assert_contract(o, "sniff event=" + o["event"])
    tail = sum(len(o["raw"].split()) for o in tail_objs)
    assert tail < 255, tail
    assert objs and all(o["event"] == "frame" for o in objs)
    for o in objs:                         # the JSON contract (docs/json.md), every family's drive object
        assert_contract(o, "sniff event=frame")
        if "drive" in o:
            assert_contract(o["drive"], "sniff drive")
    drives = [o["drive"] for o in objs if "drive" in o and "error" not in o["drive"]]
    by = {(d["station"], d["direction"]): [] for d in drives}
    for d in drives:
        by[(d["station"], d["direction"])].append(d)
    assert {s for s, _ in by} == {3, 4, 5, 6, 7}
    # the PROFIdrive cards: CTW bit 3 "enable operation" (fuji-opc-g1-pdp.md bit table; Moeller
    # STW bit 3 "Operation enabled"), the state S4, reference from the script
    for st in (3, 4, 6):
        reqs = by[(st, "request")]
        assert any("enable operation" in d["flags"] and d["reference_hz"] in SPEEDS[st]
                   for d in reqs), st
        assert any(d["state"].startswith("S4") for d in by[(st, "response")]), st
    # Toyo: STW 0x047F is "RUN" (toyo-vf66-pbus66z.md D8), 10000 counts = 50 % of 60 Hz
    assert any(d["command"] == "RUN" and d["reference_hz"] in SPEEDS[5] for d in by[(5, "request")])
    assert any(d["state"].startswith("S4") for d in by[(5, "response")])
    # Yaskawa: command bit 0 Forward Run, 0.01 Hz per count; status bit 0 Running
    assert any(d["command"] == "forward run" and d["reference_hz"] in SPEEDS[7]
               for d in by[(7, "request")])
    assert any(d["state"] == "running" for d in by[(7, "response")])
    # the drives turn: some answer shows an actual frequency above 1 Hz
    for st in (3, 4, 5, 6, 7):
        assert any((d.get("actual_hz") or 0) > 1.0 for d in by[(st, "response")]), st
    # parameter reads now and then, and the answers in the card's own codes
    for st, codes in READS.items():
        asked = {d["param"]["code"] for d in by[(st, "request")]
                 if d.get("param", {}).get("request") == "read"}
        answered = {d["param"]["code"]: d["param"]["text"] for d in by[(st, "response")]
                    if d.get("param") and "error" not in d["param"]}
        assert asked and asked <= set(codes), (st, asked)
        assert asked & set(answered), (st, asked, answered)
        for code, text in answered.items():
            if code in KNOWN:
                assert text == f"{code} = {KNOWN[code]}"


def test_sniff_text_lines_and_live_list(plc_pty):
    out = sniff(plc_pty, 2.5, *STATION_ARGS)
    lines = out.splitlines()
    assert lines[-1].endswith("frame(s)")
    for st in (3, 4, 5, 6, 7):
        assert any(f"-> drive {st} (" in x for x in lines), st
        assert any(f"<- drive {st} (" in x for x in lines), st
    out = sniff(plc_pty, 2.0, "--live", "--json")
    objs = [json.loads(line) for line in out.splitlines()]
    assert objs and all(o["event"] == "live" for o in objs)
    for o in objs:
        assert_contract(o, "sniff event=live")
    final = objs[-1]
    assert final["masters"] == [2]
    assert {s["station"]: s["state"] for s in final["stations"]} == {a: "data exchange"
                                                                    for a in (3, 4, 5, 6, 7)}
    assert 0 < final["cycle_min_s"] <= final["cycle_mean_s"] <= final["cycle_max_s"] < 2.0
    assert all(s["cycles_measured"] > 0 for s in final["stations"]) and final["final"] is True
    assert all(o["final"] is False for o in objs[:-1])
    assert all(s["counters"]["retries"] == 0 for s in final["stations"])


def test_plc_endpoint_is_listen_only_and_a_slow_listener_does_not_stall_it(plc_pty):
    # a client that writes garbage and then reads nothing for a while: the PLC keeps its bus
    # running (the tap drops what the pty cannot take) and the stations stay in data exchange
    fd = os.open(plc_pty, os.O_RDWR | os.O_NOCTTY)
    try:
        os.write(fd, b"\x10\x03\x02\x49\x4e\x16" * 50)
    finally:
        os.close(fd)
    time.sleep(3.0)
    out = sniff(plc_pty, 1.5, "--live", "--json")
    final = json.loads(out.splitlines()[-1])
    assert {s["state"] for s in final["stations"]} == {"data exchange"}


def test_plc_refuses_a_real_serial_device():
    from click.testing import CliRunner

    from profidrive_cli import UsageError
    from profidrive_cli.cli.main import cli
    r = CliRunner().invoke(cli, ["sim", "--plc", "--port", "/dev/null"])
    assert isinstance(r.exception, UsageError)          # exit 2 (test_exit_codes.py)
    assert "not a pty" in str(r.exception)


def test_plc_in_process_brings_up_every_station_and_releases_them():
    from profidrive_cli.dp.capture import Capture
    from profidrive_cli.sim.plc import WATCHDOG_MS, Plc
    from profidrive_cli.sim.plant import build_bus
    bus = build_bus("sim://?timing=wire&baud=187500", now=time.monotonic())
    cap = Capture()
    seen = []
    t0 = time.monotonic()

    def tap(data):
        seen.extend(cap.feed(data, time.monotonic() - t0))
    plc = Plc(bus, tap)
    end = time.monotonic() + 1.5
    plc.run(lambda: time.monotonic() > end)
    frames = [c.frame for c in seen if c.frame is not None]
    assert len(frames) == len(seen)                      # the tap carries whole, valid telegrams
    prm = [f for f in frames if f.is_request and f.dsap == 61]
    # Set_Prm with Lock_Req and WD_On (station status 0x88) to every station, watchdog factors
    # 200 x 1 x 10 ms = WATCHDOG_MS; at the end Set_Prm with Unlock_Req (0x48) releases each
    starts = {f.da: f.data for f in prm if f.data[0] == 0x88}
    assert set(starts) == {3, 4, 5, 6, 7}
    assert all(d[1] * d[2] * 10 == WATCHDOG_MS for d in starts.values())
    assert {f.da for f in prm if f.data[0] == 0x48} == {3, 4, 5, 6, 7}
    chk = {f.da for f in frames if f.is_request and f.dsap == 62}
    assert chk == {3, 4, 5, 6, 7}
    dx = [f for f in frames if f.is_request and f.dsap is None and f.da in (3, 4, 5, 6, 7)]
    assert len(dx) >= 5 * 10
    assert plc.cycles >= 10
    assert all(not p.thread.is_alive() for p in plc.plans.values())


def test_tap_never_blocks_without_a_listener():
    from profidrive_cli.sim.server import PtyEndpoint
    from profidrive_cli.sim.tap import Tap
    ep = PtyEndpoint()
    tap = Tap(ep)
    try:
        t = time.monotonic()
        for _ in range(200):
            tap.write(bytes(1000))
        assert time.monotonic() - t < 5.0
        assert tap.dropped > 0 and tap.written + tap.dropped == 200 * 1000
    finally:
        tap.close()


def test_a_script_that_fails_unexpectedly_stops_its_drive(monkeypatch):
    # a codec bug in the middle of a run (here: read_param raising) must not leave the drive
    # turning: the PLC stops it and keeps its station in data exchange with idle cycles
    from profidrive_cli.dp.capture import Capture
    from profidrive_cli.sim import plc as plc_mod
    from profidrive_cli.bustools.passive import PassiveDecoder, watch_list
    from profidrive_cli.sim.plant import build_bus
    import profidrive_cli.drives as drives

    real = drives.make_drive

    def broken(channel, profile, layout=None):
        d = real(channel, profile, layout)
        ok = d.read_param

        def boom(code):
            if code == "F07":              # the script's second read, after the start
                raise RuntimeError("codec bug")
            return ok(code)
        d.read_param = boom
        return d
    monkeypatch.setattr(drives, "make_drive", broken)
    bus = build_bus("sim://?stations=3:fuji-g1&timing=wire&baud=187500", now=time.monotonic())
    cap, seen = Capture(), []
    plc = plc_mod.Plc(bus, lambda data: seen.extend(cap.feed(data, time.monotonic())))
    end = time.monotonic() + 2.0
    plc.run(lambda: time.monotonic() > end)
    assert any("codec bug" in e for e in plc.plans[3].errors)
    dec = PassiveDecoder(watch_list(["3=fuji-g1"]))
    reqs = [d for d in (dec.decode(c) for c in seen) if d and d["direction"] == "request"]
    assert any("ON (run command)" in d["control"] for d in reqs)          # it had started
    # the last commands: ON (CTW bit 0) off = OFF1, a ramp stop (fuji-opc-g1-pdp.md T8)
    assert all("ON (run command)" not in d["control"] for d in reqs[-3:])


def test_plc_on_one_end_of_a_socat_pair_keeps_running_without_a_listener(socat_pair):
    # `pdrive sim --plc --port A`: nobody reads B for a while (socat stops taking octets once B's
    # buffer is full); the tap drops instead of blocking, so the PLC's bus keeps running and a
    # listener that comes later sees every station in data exchange
    a, b = socat_pair
    p = subprocess.Popen(pdrive_cmd() + ["sim", "--plc", "--port", a, "--baud", "187500", "--json"], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    try:
        assert json.loads(p.stdout.readline())["plc"] is True
        time.sleep(3.0)
        out = sniff(b, 1.5, "--live", "--json")
        final = json.loads(out.splitlines()[-1])
        assert {s["station"]: s["state"] for s in final["stations"]} == {
            a: "data exchange" for a in (3, 4, 5, 6, 7)}
        assert all(s["counters"]["reparams"] == 0 for s in final["stations"])
    finally:
        stop_pty_sim(p)


def test_tap_on_a_serial_device_drops_instead_of_blocking(socat_pair):
    # nobody reads the other end: the pair's buffers fill and a blocking write would stall the PLC
    # (and, after the write timeout, drop the device); the tap drops octets instead
    from profidrive_cli.sim.server import SerialEndpoint
    from profidrive_cli.sim.tap import Tap
    a, _ = socat_pair
    ep = SerialEndpoint(a, 19200)
    tap = Tap(ep)
    try:
        t = time.monotonic()
        for _ in range(300):
            tap.write(bytes(1000))
        assert time.monotonic() - t < 5.0
        assert tap.dropped > 0 and tap.written + tap.dropped == 300 * 1000
        assert ep.reopened == 0 and ep.ser is not None        # the device was never given up
    finally:
        tap.close()


def test_the_plc_takes_only_an_in_process_simulated_bus():
    from profidrive_cli.link.serial_link import SerialLink
    from profidrive_cli.sim.plc import Plc
    link = SerialLink("sim://")
    try:
        with pytest.raises(TypeError):
            Plc(link)                          # a port (even the simulator's) is not a plant
    finally:
        link.close()


def test_the_plc_keeps_each_station_in_the_cycle_while_it_brings_up_the_next():
    """The built-in PLC brings its stations up one after another, like `run 3,4,5`: each one in data
    exchange is kept by the master (dp/poller.py Master.keep), so its watchdog never waits for the
    others' start-up (tests/test_keep_in_dx.py checks the keep rounds themselves on the wire)."""
    from profidrive_cli.dp.poller import keep_within
    from profidrive_cli.sim.plc import WATCHDOG_MS, Plc
    from profidrive_cli.sim.plant import build_bus
    bus = build_bus("sim://?timing=virtual&baud=9600", now=0.0)
    plc = Plc(bus, lambda data: None)
    plc.bring_up()
    assert sorted(plc.plans) == [3, 4, 5, 6, 7]
    # a quarter of the watchdog (no cycle period of its own): WATCHDOG_MS / 4
    assert keep_within(WATCHDOG_MS, 0.0) == pytest.approx(WATCHDOG_MS / 4000.0)
    assert plc.master.kept == dict.fromkeys([3, 4, 5, 6, 7], pytest.approx(WATCHDOG_MS / 4000.0))
