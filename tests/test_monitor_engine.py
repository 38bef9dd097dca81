"""The monitor's engine, sans-IO (issue 37: monitor/engine.py): telegrams built here with fdl.frames and
fed at chosen times; every expected figure is worked out by hand in the comments.

- a station that goes silent while another answers is an event "lost" whose capture closes
  `after_s` after it, with the silent-station cause (bustools/causes.py) and the capture's name;
- counters are sampled per interval as increments;
- a drive is learned from the ident of its Set_Prm (drives.profile.profile_for_ident) and its fault
  bit becomes an event "fault" and the live view's drive state;
- a master heard only later is an event "master"; the line's own at the start is not;
- memory: the live view's events, the recorder's ring and the cause counts are bounded.
"""

from profidrive_cli.bustools.passive_live import LOST_AFTER
from profidrive_cli.dp.capture import Capture
from profidrive_cli.fdl import frames as F
from profidrive_cli.monitor.engine import MASTERS_SETTLE_S, MAX_CAUSE_TITLES, Monitor
from profidrive_cli.monitor.model import LIVE_EVENTS, MonEvent

M = 2
FUJI_G1 = 0xFD01            # profiles/fuji-g1 (OPC-G1-PDP) ident, fuji-opc-g1-pdp.md


def req_dx(da, fcb, data=bytes(12), sa=M):
    return F.encode(F.make(da, sa, F.request_fc(F.SRD_HIGH, fcb, True), data))


def rep(sa, data=bytes(12), da=M):
    return F.encode(F.make(da, sa, F.response_fc(F.DL), data))


def set_prm(da, ident, fcb=False):
    """Set_Prm with Lock_Req + WD_On (0x88), watchdog 10 x 10 x 10 ms = 1 s, min TSDR 11."""
    return F.encode(F.make(da, M, F.request_fc(F.SRD_HIGH, fcb, True),
                           bytes((0x88, 10, 10, 11, ident >> 8, ident & 0xFF, 0)), 61, 62))


def sc():
    return bytes((F.SC,))


def token(da, sa):
    return bytes((F.SD4, da, sa))


def feed_all(m, timed):
    outs = []
    for t, octets in timed:
        outs.append(m.feed(octets, t))
        outs.append(m.tick(t))
    return outs


def cycle(t, fcb, answering=(3, 5), silent=(), resp=None):
    """One round: a Data_Exchange to 3 and 5, 10 ms apart; `silent` stations do not answer."""
    out = []
    for i, a in enumerate((3, 5)):
        t_req = t + 0.01 * i
        out.append((t_req, req_dx(a, fcb)))
        if a not in silent:
            out.append((t_req + 0.002, rep(a, (resp or {}).get(a, bytes(12)))))
    return out


def test_a_silent_station_is_an_event_with_its_cause_and_capture():
    m = Monitor(baud=187_500, wall0=1_000_000.0, interval_s=1000.0, ring_s=5.0, after_s=1.0)
    timed = []
    t = 0.0
    fcb = False
    for _ in range(5):                       # five answered rounds, 100 ms apart
        timed += cycle(t, fcb)
        t += 0.1
        fcb = not fcb
    # station 5 goes silent: a master repeats an unanswered request with the same FCB (a retry, same
    # round), then goes on; LOST_AFTER rounds unanswered, while 3 answers after the silence began
    for _ in range(LOST_AFTER + 2):
        timed += cycle(t, fcb, silent=(5,))
        t += 0.1
        fcb = not fcb
    outs = feed_all(m, timed)
    assert not any(o.captures for o in outs)          # the window (1 s after) is still open
    # 1 s after the event, on a tick with no telegrams, the capture closes
    later = m.tick(t + 2.0)
    assert len(later.captures) == 1
    done = later.captures[0]
    evs = m.events_of(done, "000001-lost-5.pcap")
    assert [(e.kind, e.station) for e in evs] == [("lost", 5)]
    ev = evs[0]
    assert ev.capture == "000001-lost-5.pcap"
    assert ev.cause is not None and "5" in ev.cause      # the silent-station rule names it
    assert ev.evidence
    # its time: the wall clock of the link time it fired at (wall0 + t)
    assert 1_000_000.0 < ev.t < 1_000_000.0 + t
    # the capture holds the ring before the event (5 s: all of it) and the second after it
    assert done.packets[0][1] == req_dx(3, False)


def test_the_cause_is_the_one_standing_when_the_event_fired():
    """Station 5 silent and back inside one capture (after_s 30 s): the lost event keeps the
    silent-station cause it had when it fired, though 5 answers again when the capture closes; the
    back event, fired when 5 answered again (no rounds unanswered then), has none."""
    m = Monitor(baud=187_500, wall0=0.0, interval_s=1000.0, ring_s=5.0, after_s=30.0)
    timed, t, fcb = [], 0.0, False
    for silent in [()] * 5 + [(5,)] * (LOST_AFTER + 2) + [()] * 5:
        timed += cycle(t, fcb, silent=silent)
        t += 0.1
        fcb = not fcb
    outs = feed_all(m, timed)
    assert not any(o.captures for o in outs)
    done = m.tick(t + 31.0).captures
    assert len(done) == 1
    evs = {e.kind: e for e in m.events_of(done[0], "c.pcap") if e.station == 5}
    assert set(evs) >= {"lost", "back"}
    assert evs["lost"].cause is not None and "5" in evs["lost"].cause
    assert evs["back"].cause is None


def test_counters_are_sampled_as_increments_per_interval():
    m = Monitor(baud=187_500, wall0=0.0, interval_s=1.0, ring_s=1.0, after_s=0.0)
    timed = []
    fcb = False
    for k in range(15):                      # 15 rounds, 100 ms apart: t = 0.0 .. 1.4
        timed += cycle(0.1 * k, fcb)
        fcb = not fcb
    outs = feed_all(m, timed)
    samples = [s for o in outs for s in o.samples]
    bus = [o.bus for o in outs if o.bus is not None]
    # the first sample is due at t >= 1.0: the tick after station 5's reply at 1.012 (round 10's
    # request to 3 at 1.0 answered at 1.002 comes first: its tick is at 1.0 already)
    first = [s for s in samples if s.station == 3][0]
    # rounds 0..10 have requested station 3 by t = 1.0 (the request at 1.0 counts when answered:
    # an exchange is a request answered) -> 10 answered exchanges before 1.0, the 11th at 1.002
    # whose tick came at the sample's moment or after: between 10 and 11 by where the tick fell
    assert first.counts["exchanges"] in (10, 11)
    assert first.counts["retries"] == 0 and first.counts["no_answer"] == 0
    assert first.state == "data exchange"
    assert abs(first.cycle_mean_s - 0.1) < 1e-6      # 100 ms between requests to it
    assert len(bus) == 1 and bus[0].frames >= 40     # 11 rounds x 4 frames, at least 10 of them
    # the end: one more sample with the rest; the two add up to every exchange (15 per station)
    end = m.close(1.5)
    last3 = [s for s in end.samples if s.station == 3][0]
    assert first.counts["exchanges"] + last3.counts["exchanges"] == 15


def test_a_drive_is_learned_from_its_ident_and_its_fault_is_an_event():
    m = Monitor(baud=187_500, wall0=0.0, interval_s=1000.0, ring_s=1.0, after_s=0.0)
    timed = [(0.0, set_prm(3, FUJI_G1)), (0.002, sc())]
    fcb = True
    ok = bytes(8) + bytes((0x02, 0x37)) + bytes(2)        # ZSW 0x0237: ready, operation enabled, no fault
    bad = bytes(8) + bytes((0x02, 0x08 | 0x30)) + bytes(2)  # ZSW bit 3 (fault) set, PROFIdrive
    t = 0.1
    for k in range(6):
        timed += cycle(t, fcb, resp={3: ok if k < 3 else bad})
        t += 0.1
        fcb = not fcb
    outs = feed_all(m, timed)
    captures = [d for o in outs for d in o.captures] + m.tick(t + 1.0).captures
    kinds = [(e.kind, e.station) for d in captures for e in m.events_of(d, None)]
    assert ("fault", 3) in kinds
    view = m.live()
    row = {s["station"]: s for s in view["stations"]}[3]
    assert row["profile"] == "fuji-opc-g1-pdp"
    assert row["fault"] is True
    assert row["ident_hex"] == "0xFD01"


def test_a_master_heard_later_is_an_event_and_the_lines_own_is_not():
    m = Monitor(baud=187_500, wall0=0.0, interval_s=1000.0, ring_s=1.0, after_s=0.0)
    outs = feed_all(m, [(0.0, token(M, M)), (1.0, token(M, M))])
    assert not [e for o in outs for e in o.events]
    outs = feed_all(m, [(MASTERS_SETTLE_S + 5, token(1, 1))])
    evs = [e for o in outs for e in o.events]
    assert [(e.kind, e.station) for e in evs] == [("master", None)]
    assert "master 1" in evs[0].text


def test_the_live_view_keeps_a_bounded_number_of_events_and_cause_titles():
    m = Monitor(baud=None, wall0=0.0)
    for i in range(LIVE_EVENTS * 3):
        m.note(MonEvent(t=float(i), kind="lost", station=3, text="x", cause=f"cause {i}"))
    view = m.live(1.0)
    assert len(view["events"]) == LIVE_EVENTS
    assert view["events"][0]["t"] == LIVE_EVENTS * 3 - 1          # newest first
    assert view["events_total"] == LIVE_EVENTS * 3
    assert view["events_by_kind"] == {"lost": LIVE_EVENTS * 3}
    assert len(view["events_by_cause"]) == MAX_CAUSE_TITLES + 1    # the titles, then "other"
    assert view["events_by_cause"]["other"] == LIVE_EVENTS * 3 - MAX_CAUSE_TITLES


def test_frames_decode_as_the_tests_mean_them():
    # the helpers' octets are valid telegrams (the engine's input is what dp.capture decodes)
    cap = Capture()
    got = cap.feed(req_dx(3, True) + rep(3) + set_prm(3, FUJI_G1) + sc() + token(2, 2), 0.0)
    assert [(c.frame is not None, c.error or None) for c in got] == [(True, None)] * 5
