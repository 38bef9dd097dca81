"""The black-box recorder's parts, sans-IO (issue 27): the trigger language (bustools/triggers.py),
the bus facts it fires on (bustools/passive_live.py notes), the ring and the per-event captures
(bustools/recorder.py), the likely causes (bustools/causes.py), bus load and token rotation, and
the simulator's timed unplug (sim/faults.py unplug=). Telegrams are built here with fdl.frames and
fed at chosen times; every expected figure is worked out by hand in the comments."""

import pytest

from conftest import run_main
from profidrive_cli import UsageError
from profidrive_cli.bustools.causes import likely_causes
from profidrive_cli.bustools.passive_live import LOST_AFTER, LiveList, bus_load_percent
from profidrive_cli.bustools.recorder import Recorder
from profidrive_cli.bustools.triggers import Trigger, TriggerError, TriggerSet, parse, parse_all
from profidrive_cli.dp.capture import Capture
from profidrive_cli.fdl import frames as F

M = 2          # the master


def req_dx(da, fcb=False, sa=M):
    return F.encode(F.make(da, sa, F.request_fc(F.SRD_HIGH, fcb, True), b"\x00\x00"))


def rep(sa, status=F.DL, data=b"\x00\x00", dsap=None, ssap=None):
    return F.encode(F.make(M, sa, F.response_fc(status), data, dsap, ssap))


def req_diag(da, fcb=False):
    return F.encode(F.make(da, M, F.request_fc(F.SRD_HIGH, fcb, True), b"", 60, 62))


def diag(st1=0x00, st2=0x0C, ident=0xFD01, ext=b""):
    """A Slave_Diag answer: Station_Status_1..3, master 2, ident (dp/services.py SlaveDiag)."""
    return bytes((st1, st2, 0x00, M, ident >> 8, ident & 0xFF)) + ext


def set_prm(da, f1=10, f2=10, ident=0xFD01, fcb=False):
    """Set_Prm with Lock_Req + WD_On (0x88): watchdog f1 x f2 x 10 ms, min TSDR 11."""
    return F.encode(F.make(da, M, F.request_fc(F.SRD_HIGH, fcb, True),
                           bytes((0x88, f1, f2, 11, ident >> 8, ident & 0xFF, 0)), 61, 62))


def frames(*timed):
    """(t, octets), ... -> Captured, each telegram fed alone at its time."""
    cap = Capture()
    out = []
    for t, octets in timed:
        out += cap.feed(octets, t)
    return out


def dx_round(t, *stations, fcb=False):
    """A Data_Exchange to each station, each answered, 1 ms apart from t on."""
    out = []
    for i, a in enumerate(stations):
        out += [(t + 0.002 * i, req_dx(a, fcb)), (t + 0.002 * i + 0.001, rep(a))]
    return out


# -- the trigger language ---------------------------------------------------------------------------

def test_parse_triggers_with_stations_lists_and_limits():
    assert parse("lost(3), back(*),fcs") == [Trigger("lost", 3), Trigger("back"), Trigger("fcs")]
    assert parse("lost") == [Trigger("lost")]                       # no parentheses: every station
    assert parse("cycle>20ms") == [Trigger("cycle", None, 0.02)]
    assert parse("cycle(7) > 1.5s") == [Trigger("cycle", 7, 1.5)]
    assert parse("cycle>500us")[0].limit_s == pytest.approx(500e-6)
    assert [t.label for t in parse("rs(4),rr(*),nr(4),ue(4),diag(4),framing,pkw(7)")] == [
        "rs(4)", "rr(*)", "nr(4)", "ue(4)", "diag(4)", "framing", "pkw(7)"]
    # repeated --trigger: one list, duplicates once
    assert parse_all(["lost(*)", "lost(*),back(*)"]) == [Trigger("lost"), Trigger("back")]


@pytest.mark.parametrize("expr, position, words", [
    # positions are 1-based columns, counted by hand: "lost(3" ends after column 6, so ')' is
    # expected at column 7
    ("lost(3", 7, "expected ')'"),
    ("lost(3),fualt(*)", 9, "unknown trigger 'fualt'"),      # 'f' of fualt is column 9
    ("lost(200)", 6, "station address 0..126"),              # '2' is column 6
    ("fcs(3)", 4, "takes no station"),                       # '(' is column 4
    ("cycle>20", 9, "expected a unit"),                      # after "cycle>20": column 9
    ("cycle", 6, "needs a limit"),
    ("lost(3) back(4)", 9, "unexpected 'b'"),
    ("lost(3),", 9, "expected a trigger after ','"),
    ("", 1, "empty trigger expression"),
])
def test_a_trigger_that_does_not_parse_names_its_position(expr, position, words):
    with pytest.raises(TriggerError) as e:
        parse(expr)
    assert e.value.position == position
    assert words in str(e.value)
    assert f"at position {position}:" in str(e.value) and "\n" not in str(e.value)


def test_drive_triggers_need_the_stations_profile():
    with pytest.raises(UsageError, match=r"fault\(7\): needs --station 7=PROFILE"):
        parse_all(["fault(7)"], watched={3})
    with pytest.raises(UsageError, match="needs --station ADDRESS=PROFILE"):
        parse_all(["lost(*),fault(*)"], watched=set())
    assert parse_all(["fault(*)"], watched={7}) == [Trigger("fault")]


# -- the bus facts: lost, back, RS, diagnosis, FCS, cycle -------------------------------------------

def _fire(expr, timed, **kw):
    ts = TriggerSet(parse(expr), **kw)
    out = []
    for c in frames(*timed):
        out += ts.feed(c)
    return ts, out


def test_lost_after_unanswered_requests_and_back_in_data_exchange():
    # station 5 answers a Data_Exchange, then LOST_AFTER (4) rounds go unanswered (a request to 5,
    # a new FCB each, and one to 6 answered); the 4th unanswered one is known when the next request
    # goes out (t = 0.402): lost fires then. Its next answered Data_Exchange (t = 0.61) is "back"
    timed = dx_round(0.0, 5, 6)
    for i in range(1, LOST_AFTER + 1):
        timed += [(0.1 * i, req_dx(5, fcb=i % 2 == 1)), (0.1 * i + 0.002, req_dx(6, i % 2 == 1)),
                  (0.1 * i + 0.003, rep(6))]
    timed += [(0.6, req_dx(5)), (0.61, rep(5))]
    ts, fired = _fire("lost(*),back(5),lost(6)", timed)
    assert [(f.trigger.label, f.station, f.t) for f in fired] == [("lost(*)", 5, 0.402),
                                                                 ("back(5)", 5, 0.61)]
    assert "4 rounds in a row unanswered; last answer at 0.001 s" in fired[0].text
    assert "back in data exchange" in fired[1].text
    # a request and its three retries (the same FCB, FCV = 1) unanswered are one round, not a loss
    _, fired = _fire("lost(*)", dx_round(0.0, 5) + [(0.1 * i, req_dx(5, True)) for i in range(1, 4)]
                     + [(0.4, req_dx(6))])
    assert fired == []


def test_lost_when_the_master_parameterises_a_station_in_data_exchange_again():
    timed = dx_round(0.0, 5) + [(0.1, set_prm(5, fcb=True)), (0.101, F.encode(F.SC_FRAME))]
    _, fired = _fire("lost(5)", timed)
    assert [f.t for f in fired] == [0.1]
    assert "left data exchange: master 2 parameterises it again" in fired[0].text


def test_rs_diagnosis_change_fcs_and_cycle_fire():
    bad = bytearray(rep(6))
    bad[-2] ^= 0x01                                   # the FCS octet: a checksum error
    timed = dx_round(0.0, 5, 6)
    timed += [(0.010, req_diag(5)), (0.011, rep(5, F.DL, diag(), 62, 60)),
              (0.020, req_diag(5, True)), (0.021, rep(5, F.DL, diag(st1=0x08), 62, 60)),
              (0.030, req_dx(5, True)), (0.031, rep(5, F.RS, b"")),
              (0.040, req_dx(6, True)), (0.041, bytes(bad)),
              # station 6's Data_Exchange 0.040 - 0.002 = 38 ms after its last: over 30 ms
              (0.050, req_dx(5)), (0.051, rep(5))]
    _, fired = _fire("rs(5),diag(*),fcs,cycle(6)>30ms", timed)
    got = [(f.trigger.label, f.t) for f in fired]
    assert got == [("diag(*)", 0.021), ("rs(5)", 0.031), ("cycle(6)>30ms", 0.040), ("fcs", 0.041)]
    assert "+Ext_Diag" in fired[0].text            # Station_Status_1 bit 3 (dp/services.py ST1_BITS)
    assert "RS SAP not enabled" in fired[1].text
    assert "38.0 ms" in fired[2].text


def test_octets_before_the_first_whole_frame_are_no_framing_error():
    # a listener joins a running line in the middle of a telegram: its tail is no event
    timed = [(0.0, req_dx(5)[4:]), (0.01, req_dx(5)), (0.011, rep(5)), (0.02, b"\x55")]
    _, fired = _fire("framing", timed)
    assert [f.t for f in fired] == [0.02]


def test_drive_fault_state_and_pkw_error_from_the_stations_profile():
    # Moeller PPO1 inputs (--station 6=moeller:ppo1): PKW (4 words) then STW and HIW. STW bit 3 is
    # "fault" (PROFIdrive status word, drives/profidrive/words.py Stw): 0x0237 -> 0x023F sets it.
    # A PKW answer with AK 7 ("task cannot be executed") carries the error number in PWE (0:
    # unknown parameter number): PKE 0x7154 = AK 7, PNU 0x154 = 340
    from profidrive_cli.bustools.passive import PassiveDecoder, watch_list

    def inputs(stw, pkw=bytes(8)):
        return rep(6, F.DL, pkw + stw.to_bytes(2, "big") + bytes(2))
    timed = [(0.0, req_dx(6)), (0.001, inputs(0x0237)),
             (0.1, req_dx(6, True)), (0.101, inputs(0x023F)),
             (0.2, req_dx(6)), (0.201, inputs(0x0237, bytes((0x71, 0x54, 0, 0, 0, 0, 0, 0))))]
    dec = PassiveDecoder(watch_list(["6=moeller:ppo1"]))
    _, fired = _fire("fault(6),state(*),pkw(6)", timed, decoder=dec)
    assert [(f.trigger.label, f.t) for f in fired] == [
        ("fault(6)", 0.101), ("state(*)", 0.101), ("fault(6)", 0.201), ("state(*)", 0.201),
        ("pkw(6)", 0.201)]
    assert fired[0].text == "drive 6 (moeller-de6-net-dp): fault on (fault)"
    assert fired[1].text == "drive 6 (moeller-de6-net-dp): S4 operation -> fault"
    assert fired[2].text == "drive 6 (moeller-de6-net-dp): fault cleared"
    assert "PNU340: error 0 (unknown parameter number)" in fired[4].text


def test_a_data_exchange_answered_with_high_priority_shows_diagnosis():
    # passive_live.py's doc: "diagnosis: the station answered Data_Exchange with high priority
    # (diagnosis pending)": FC status DH (fdl/frames.py RESPONSE_NAMES 10); kept when the reply
    # status is read once for the RS/RR/NR triggers too
    live = _live(dx_round(0.0, 5, 6) + [(0.1, req_dx(5, True)), (0.101, rep(5, F.DH))])
    assert {s["station"]: s["state"] for s in live.snapshot(0.2)["stations"]} == {
        5: "diagnosis", 6: "data exchange"}


# -- bus load, token rotation -------------------------------------------------------------------------

def test_bus_load_is_busy_bit_times_over_elapsed_bit_times():
    # 100 FDL status requests (SD1: SD DA SA FC FCS ED = 6 octets) each answered SC (1 octet) in
    # 1.0 s at 19200 bit/s: 100 x 7 octets x 11 bit = 7700 busy bit times of 19200 elapsed:
    # 7700 / 19200 = 40.104 % -> 40.1
    fdl = F.encode(F.make(5, M, F.request_fc(F.FDL_STATUS)))
    assert len(fdl) == 6
    live = LiveList(baud=19200)
    for c in frames(*[x for i in range(100) for x in ((i * 0.01, fdl), (i * 0.01 + 0.001, b"\xE5"))]):
        live.feed(c)
    assert live.snapshot(1.0)["bus_load_percent"] == 40.1
    assert bus_load_percent(700, 1.0, 19200) == 40.1
    # 12 Mbit/s, 1 s, 1,090,909 octets = 11,999,999 bit: 100.0 %
    assert bus_load_percent(1_090_909, 1.0, 12_000_000) == 100.0
    assert bus_load_percent(700, 1.0, None) is None and LiveList().snapshot(1.0)["bus_load_percent"] is None


def test_token_rotation_per_master():
    # master 2 passes the token at 0, 10 ms and 30 ms: rotations 10 and 20 ms
    live = LiveList()
    for c in frames((0.0, F.encode(F.token(3, 2))), (0.005, F.encode(F.token(2, 3))),
                    (0.010, F.encode(F.token(3, 2))), (0.030, F.encode(F.token(3, 2)))):
        live.feed(c)
    rot = live.snapshot(0.03)["token_rotation_s"]
    assert rot == {"min": 0.01, "mean": 0.015, "max": 0.02, "n": 2}


# -- the recorder -----------------------------------------------------------------------------------

def test_the_ring_is_bounded_by_seconds_and_by_telegrams():
    # a frame every 0.25 s from 0 to 5 s; a 1 s ring keeps 4.0, 4.25, 4.5, 4.75, 5.0
    rec = Recorder(TriggerSet(parse("lost(*)")), ring_s=1.0, after_s=1.0)
    rec.feed(frames(*[(i * 0.25, F.encode(F.token(3, 2))) for i in range(21)]))
    assert [t for t, _ in rec.ring] == [4.0, 4.25, 4.5, 4.75, 5.0]
    rec = Recorder(TriggerSet(parse("lost(*)")), ring_s=100.0, after_s=1.0, max_ring=3)
    rec.feed(frames(*[(i * 0.25, F.encode(F.token(3, 2))) for i in range(21)]))
    assert [t for t, _ in rec.ring] == [4.5, 4.75, 5.0]


def _lost_line(t_lost_from=1.0, until=4.0):
    """Stations 5 and 6 exchange every 0.1 s; from t_lost_from on station 5 answers nothing."""
    timed = []
    t = 0.0
    i = 0
    while t <= until + 1e-9:
        fcb = bool(i % 2)
        if t < t_lost_from:
            timed += dx_round(t, 5, 6, fcb=fcb)
        else:
            timed += [(t, req_dx(5, fcb)), (t + 0.002, req_dx(6, fcb)), (t + 0.003, rep(6))]
        i += 1
        t = round(t + 0.1, 6)
    return timed


def test_one_capture_holds_the_ring_before_and_the_seconds_after():
    # station 5 is silent from 1.0 s on: its 4th unanswered request (1.0, 1.1, 1.2, 1.3) is known
    # at 1.302 (station 6's request after it) -> lost at 1.302. Ring 0.5 s: the capture starts at
    # the first telegram at or after 0.802 (0.802, station 5's request of the 0.8 round); after
    # 1.0 s it holds telegrams up to 2.302 (the last at or before: station 6's request at 2.302)
    rec = Recorder(TriggerSet(parse("lost(*)")), ring_s=0.5, after_s=1.0)
    done = rec.feed(frames(*_lost_line()))
    assert len(done) == 1
    d = done[0]
    assert d.t_event == pytest.approx(1.302)
    assert d.packets[0][0] == pytest.approx(0.802)
    assert d.packets[-1][0] == pytest.approx(2.302)
    assert d.before_s == pytest.approx(0.5) and d.after_s == pytest.approx(1.0)
    assert d.complete and [e.fired.trigger.label for e in d.events] == ["lost(*)"]
    assert rec.close() == []


def test_events_inside_an_open_window_join_it_and_repeats_are_counted():
    # station 6's Data_Exchange comes every 0.1 s > 50 ms: the first interval (0.002 -> 0.102)
    # opens a 2 s window (to 2.102); lost at 1.302 joins it; the cycle trigger fires again for
    # the rounds 0.2 .. 2.0 (19 more intervals, each 0.1 s): one event with 19 repeats
    rec = Recorder(TriggerSet(parse("lost(*),cycle(6)>50ms")), ring_s=0.5, after_s=2.0)
    done = rec.feed(frames(*_lost_line(until=2.0)))
    done += rec.close()
    assert len(done) == 1
    assert [(e.fired.trigger.label, e.fired.t, e.repeats) for e in done[0].events] == [
        ("cycle(6)>50ms", pytest.approx(0.102), 19), ("lost(*)", pytest.approx(1.302), 0)]


def test_a_window_closes_on_a_silent_line_and_at_the_end_of_listening():
    rec = Recorder(TriggerSet(parse("lost(*)")), ring_s=0.5, after_s=1.0)
    assert rec.feed(frames(*_lost_line(until=1.4))) == []
    assert rec.tick(2.0) == []                       # 1.302 + 1.0 not reached yet
    done = rec.tick(2.31)
    assert len(done) == 1 and done[0].complete
    rec = Recorder(TriggerSet(parse("lost(*)")), ring_s=0.5, after_s=10.0)
    rec.feed(frames(*_lost_line(until=1.4)))
    done = rec.close()
    assert len(done) == 1 and not done[0].complete


# -- likely causes ------------------------------------------------------------------------------------

def _live(timed, **kw):
    live = LiveList(**kw)
    for c in frames(*timed):
        live.feed(c)
    return live


def test_cause_a_silent_station_while_the_others_answer():
    causes = likely_causes(_live(_lost_line(until=2.0)))
    assert causes[0].stations == (5,)
    assert "station 5 stopped answering while the others answer" in causes[0].title
    assert "last answer at 0.901 s" in causes[0].evidence[0]
    assert causes[0].evidence[1] == "stations 6 answered after its silence began"


def test_cause_watchdog_expired_with_the_silence_and_the_watchdog():
    # Set_Prm: watchdog 10 x 10 x 10 ms = 1000 ms; Data_Exchange at 0.1, then the master is silent
    # towards station 5 until 1.6: 1500 ms > 1000 ms, and the station answers RS
    timed = [(0.0, set_prm(5, 10, 10)), (0.001, F.encode(F.SC_FRAME)),
             (0.1, req_dx(5)), (0.101, rep(5)), (1.6, req_dx(5, True)), (1.601, rep(5, F.RS, b""))]
    causes = likely_causes(_live(timed))
    wd = [c for c in causes if "watchdog expired" in c.title]
    assert wd and wd[0].evidence == ("at 1.601 s: 1500 ms without a request to it, watchdog 1000 ms "
                                     "(its Set_Prm)",)


def test_cause_duplicate_address_and_second_master():
    timed = [(0.0, req_diag(5)), (0.001, rep(5, F.DL, diag(ident=0xFD01), 62, 60)),
             (0.01, req_diag(5, True)), (0.011, rep(5, F.DL, diag(ident=0x00CA), 62, 60)),
             (0.02, F.encode(F.token(3, 2))), (0.03, F.encode(F.token(2, 3)))]
    titles = [c.title for c in likely_causes(_live(timed))]
    assert any("two devices answer as station 5" in t for t in titles)
    assert any("more than one master passes the token: 2, 3" in t for t in titles)


def test_cause_repeats_concentrated_on_one_station():
    # station 5: 8 retries (the same FCB again, FCV = 1), stations 6 and 7: none -> 8 of 8 (100 %);
    # a line dropping at random puts all 8 on one given station of 3 with P = (1/3)^8 = 1.5e-4,
    # x 3 stations = 4.6e-4 < causes.BY_CHANCE (0.001)
    timed = dx_round(0.0, 5, 6, 7)
    for i in range(8):
        timed += [(0.1 + 0.01 * i, req_dx(5)), (0.105 + 0.01 * i, rep(5))]
    c = [c for c in likely_causes(_live(timed)) if "repeats" in c.title]
    assert c and c[0].stations == (5,) and "(100 % of 8)" in c[0].title
    assert c[0].evidence[0].startswith("station 5: 8 retries, 0 corrupt replies")


def test_no_cause_on_a_clean_line():
    assert likely_causes(_live(dx_round(0.0, 5, 6) + dx_round(0.1, 5, 6, fcb=True), baud=19200)) == []


# -- the simulator's timed unplug ---------------------------------------------------------------------

def test_sim_unplug_silences_a_station_from_a_time_and_plugs_it_in_again():
    from profidrive_cli.sim.plant import build_bus
    bus = build_bus("sim://?stations=3:fuji-g1,4:toyo&unplug=3@1-2")
    fdl = {a: F.encode(F.make(a, M, F.request_fc(F.FDL_STATUS))) for a in (3, 4)}

    def answers(a, t):
        return bool(bus.receive(fdl[a], t))
    # the clock starts at the bus's first telegram (10.0 here)
    assert answers(3, 10.0) and answers(3, 10.9)
    assert not answers(3, 11.0) and not answers(3, 11.9) and answers(4, 11.5)
    assert answers(3, 12.0)
    assert bus.faults.counts["unplug"] == 1 and bus.faults.counts["replug"] == 1


@pytest.mark.parametrize("value", ["3", "x@5", "3@", "3@5-4", "200@1"])
def test_sim_unplug_refuses_a_bad_value(value):
    from profidrive_cli.sim.plant import build_bus
    with pytest.raises(UsageError, match="unplug=.* must be ADDRESS@SECONDS"):
        build_bus(f"sim://?unplug={value}")
    with pytest.raises(UsageError, match="unplug=9@...: no station 9 on the bus"):
        build_bus("sim://?unplug=9@1")


# -- the CLI's refusals: one line, exit 2, nothing written -------------------------------------------

@pytest.mark.parametrize("args, words", [
    (["--ring", "10", "--trigger", "lost(3"], "at position 7: expected ')'"),
    (["--trigger", "lost(*)"], "give --ring SECONDS"),
    (["--ring", "10", "--trigger", "fault(7)"], "needs --station 7=PROFILE"),
    (["--ring", "0", "--trigger", "lost(*)"], "--ring must be positive"),
    (["--ring", "10", "--trigger", "lost(*)", "--live"], "not with --live"),
    (["--ring", "10", "--trigger", "lost(*)", "--out", "OUT/ev.pcap"], "needs {n} or {time}"),
    (["--ring", "10", "--trigger", "lost(*)", "--out", "OUT/ev-{n}-{x}.pcap"], "a pattern may use only"),
    (["--ring", "10"], "give at least one trigger"),
])
def test_recorder_refusals(capsys, monkeypatch, tmp_path, args, words):
    args = [a.replace("OUT", str(tmp_path)) for a in args]
    r = run_main(capsys, monkeypatch, "sniff", "--port", "sim://", *args)
    assert r.exit_code == 2, r.output
    assert words in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert list(tmp_path.iterdir()) == []


# -- what the CLI writes for a capture: the pcap and the event (text line, JSON event) -------------

def _one_done():
    tset = TriggerSet(parse("lost(*)"))
    rec = Recorder(tset, ring_s=0.5, after_s=1.0)
    (done,) = rec.feed(frames(*_lost_line()))
    return tset, done


@pytest.mark.parametrize("as_json", [False, True])
def test_the_writer_writes_the_pcap_and_one_event(tmp_path, capsys, as_json):
    import json

    from profidrive_cli.bustools.ringstore import out_pattern
    from profidrive_cli.cli.sniff_ring import _Writer
    from profidrive_cli.dp.capture import read_pcap
    from test_json_contract import assert_contract
    tset, done = _one_done()
    w = _Writer(out_pattern(str(tmp_path)), 147, as_json, tset)
    w.start = 1_000_000.0                   # wall clock of t = 0
    capsys.readouterr()
    w.write(done)
    text = capsys.readouterr().out
    (f,) = tmp_path.iterdir()
    linktype, pkts = read_pcap(f.read_bytes())
    # the pcap's times: the wall clock of t = 0 plus each telegram's time (0.802 .. 2.302)
    assert linktype == 147 and len(pkts) == len(done.packets)
    assert pkts[0][0] == pytest.approx(1_000_000.802) and pkts[-1][0] == pytest.approx(1_000_002.302)
    assert f.name.endswith("-1-lostall.pcap")
    if as_json:
        obj = json.loads(text)
        assert_contract(obj, "sniff event=trigger")
        assert (obj["trigger"], obj["station"], obj["capture"], obj["telegrams"]) == (
            "lost(*)", 5, str(f), len(pkts))
        assert (obj["before_s"], obj["after_s"], obj["complete"]) == (0.5, 1.0, True)
        assert "stopped answering while the others answer" in obj["causes"][0]["title"]
    else:
        assert len(text.splitlines()) == 1
        assert (f"lost(*)  station 5 stopped answering: 4 rounds in a row unanswered; last answer "
                f"at 0.901 s; capture {f} ({len(pkts)} telegrams, 0.5 s before, 1.0 s after); likely: "
                f"station 5 stopped answering while the others answer") in text


# -- sniff --live: the caption carries bus load, token rotation and the likely causes ---------------

def test_live_list_caption_shows_bus_load_and_causes(capsys):
    from profidrive_cli.cli.sniff_view import SniffView
    # the hand-calculated line of test_bus_load_...: 100 x (6 + 1) octets x 11 bit in 1.0 s at
    # 19200 bit/s = 40.1 %; then station 5 of _lost_line goes silent while 6 answers
    fdl = F.encode(F.make(5, M, F.request_fc(F.FDL_STATUS)))
    timed = [x for i in range(100) for x in ((i * 0.01, fdl), (i * 0.01 + 0.001, b"\xE5"))]
    view = SniffView((), live=True, baud=19200)
    for c in frames(*timed):
        view.frame(c)
    capsys.readouterr()
    view.finish(1.0)
    text = capsys.readouterr().out
    assert "token rotation -/-/- ms; bus load 40.1 %; framing errors: none" in text
    assert "likely:" not in text
    view = SniffView((), live=True, baud=19200)
    for c in frames(*_lost_line(until=2.0)):
        view.frame(c)
    view.finish(2.1)
    text = capsys.readouterr().out
    assert ("likely: station 5 stopped answering while the others answer: its power, its bus "
            "connector or the cable to it (station 5: 11 rounds in a row unanswered since 1.000 s "
            "(last answer at 0.901 s); stations 6 answered after its silence began)") in text
