"""The monitored line (sim/virtual_line.py open_line): what a tap on `sim://?timing=virtual&...` hears.

Expected values come from the module's spec and from PROFIBUS DP itself, not from the code:
    the token SD4 is DC DA SA (3 octets); a lone master passes it to itself (DA = SA = 2)
    Slave_Diag, Set_Prm, Chk_Cfg are SRDs to the slave's SAPs 60, 61, 62 from the master's SAP 62;
    Data_Exchange carries no SAP; Set_Prm and Chk_Cfg are acknowledged with the short SC (E5)
    Set_Prm's octets 2 and 3 are the watchdog factors: watchdog = f1 * f2 * 10 ms
    a station's reply to the master is DA 2, SA = the station; DH (FC status 10) flags a diagnosis
    the default plant is stations 3, 4, 5, 6, 7 (sim/plant.py); at 19200 bit/s (the plant's default)
    a cycle of five Data_Exchanges takes well under 0.1 s (each: ~20 octets * 11 bits / 19200 plus
    the idle times, < 15 ms), so cycles of 0.5 s and more start exactly `cycle` apart
"""

from __future__ import annotations

import time
import tracemalloc

import pytest

from profidrive_cli import BusError, UsageError
from profidrive_cli.dp.capture import Capture
from profidrive_cli.fdl import frames as F
from profidrive_cli.link.base import LinkLost
from profidrive_cli.sim.virtual_line import RX_BUFFER_OCTETS, open_line

MASTER = 2
SLAVE_DIAG, SET_PRM, CHK_CFG, MASTER_SAP = 60, 61, 62, 62
DEFAULT_STATIONS = (3, 4, 5, 6, 7)
V = "sim://?timing=virtual"


def listen(line, seconds, poll=0.2, into=None):
    """(time heard, octets) of every read for `seconds` of line time, as bustools/listen.py reads
    (into: a list to add them to, kept when a read raises)."""
    out = [] if into is None else into
    end = line.now() + seconds
    while line.now() < end:
        data = line.read(min(end, line.now() + poll))
        if data:
            out.append((line.now(), data))
    return out


def frames(heard):
    """Each read is exactly one whole FDL telegram: (time, Frame)."""
    out = []
    for t, data in heard:
        r = F.parse(data)
        assert isinstance(r, tuple), (t, data.hex(), r)
        f, used = r
        assert used == len(data), (t, data.hex())
        out.append((t, f))
    return out


def service(f):
    """What a request to a slave asks (by its SAPs, DP)."""
    if f.dsap is None:
        return "Data_Exchange"
    return {SLAVE_DIAG: "Slave_Diag", SET_PRM: "Set_Prm", CHK_CFG: "Chk_Cfg"}.get(f.dsap, f.dsap)


def tokens(fs):
    return [(t, (f.da, f.sa)) for t, f in fs if f.sd == F.SD4]


def requests_to(fs, a):
    return [(t, f) for t, f in fs if f.is_request and f.da == a and f.sa == MASTER]


def replies_from(fs, a):
    return [(t, f) for t, f in fs if f.sd in (F.SD1, F.SD2, F.SD3) and not f.is_request
            and f.sa == a and f.da == MASTER]


# -- what is heard ----------------------------------------------------------------------------------

@pytest.mark.parametrize("plant,stations", [
    ("", DEFAULT_STATIONS),
    ("&stations=12:fuji-g1,13:toyo,14:moeller,15:yaskawa,16:fuji-pdp3", (12, 13, 14, 15, 16)),
])
def test_tokens_requests_and_replies_of_every_station(plant, stations):
    line = open_line(f"{V}&cycle=0.5{plant}")
    heard = listen(line, 10)
    fs = frames(heard)
    assert tokens(fs) and all(k == (MASTER, MASTER) for _, k in tokens(fs))
    assert {f.da for _, f in fs if f.is_request} == set(stations)
    for a in stations:
        assert requests_to(fs, a) and replies_from(fs, a), a
        # every request is answered: the next telegram is its station's reply or the short SC
        for i, (_, f) in enumerate(fs[:-1]):
            if f.is_request and f.da == a:
                nxt = fs[i + 1][1]
                assert nxt.sd == F.SC or (nxt.sa == a and nxt.da == MASTER and not nxt.is_request)
    # the telegrams are heard in time order, each once: the monitor's decoder takes them all
    times = [t for t, _ in heard]
    assert times == sorted(times)
    cap = Capture()
    got = [c for t, d in heard for c in cap.feed(d, t)]
    assert len(got) == len(heard) and all(c.frame is not None for c in got)


def test_bring_up_of_each_station_then_data_exchange():
    cycle = 1.0
    line = open_line(f"{V}&cycle={cycle:g}")
    fs = frames(listen(line, 8))
    for a in DEFAULT_STATIONS:
        reqs = requests_to(fs, a)
        assert [service(f) for _, f in reqs[:5]] == ["Slave_Diag", "Set_Prm", "Chk_Cfg", "Slave_Diag",
                                                    "Data_Exchange"], a
        assert all(service(f) == "Data_Exchange" for _, f in reqs[4:])
        assert all(f.ssap == MASTER_SAP for _, f in reqs[:4])
        # one request per cycle: the bring-up's steps in the cycles 0, 1, 2, 3, 4
        assert [int(t // cycle) for t, _ in reqs[:5]] == [0, 1, 2, 3, 4]
        # Set_Prm: the watchdog covers at least 4 cycles and 2 s (module doc)
        prm = reqs[1][1].data
        assert prm[1] * prm[2] * 10 >= max(2000, 4 * cycle * 1000)
        # Set_Prm and Chk_Cfg acknowledged with SC
        for t, f in reqs[1:3]:
            i = fs.index((t, f))
            assert fs[i + 1][1].sd == F.SC
        assert len(replies_from(fs, a)) >= 4         # 2 diagnoses + DX from cycle 4 on (4..7)


@pytest.mark.parametrize("cycle,seconds", [(0.5, 30), (2.0, 60), (10.0, 200)])
def test_cycle_sets_the_spacing_of_tokens(cycle, seconds):
    line = open_line(f"{V}&cycle={cycle:g}")
    ts = [t for t, _ in tokens(frames(listen(line, seconds)))]
    assert abs(len(ts) - seconds / cycle) <= 1
    assert all(abs((b - a) - cycle) < 1e-6 for a, b in zip(ts, ts[1:]))


def test_a_cycle_longer_than_its_telegrams_sets_the_pace_else_the_wire_does():
    # cycle=0.001 is shorter than one Data_Exchange at 19200 bit/s: cycles follow one another
    # as fast as the wire lets them, never overlapping (each token after the last reply)
    line = open_line(f"{V}&cycle=0.001")
    fs = frames(listen(line, 2))
    ts = [t for t, _ in tokens(fs)]
    assert len(ts) < 2 / 0.001 / 10            # far fewer than 2000: the wire sets the pace
    assert len(ts) > 2 / 0.2                   # but a cycle of five stations is < 0.2 s
    times = [t for t, _ in fs]
    assert times == sorted(times)


# -- the plant's faults and the line's own ----------------------------------------------------------

def test_unplugged_station_is_silent_in_its_window_and_brought_up_after():
    line = open_line(f"{V}&cycle=1&unplug=5@3-8")
    fs = frames(listen(line, 20))
    rep5 = [t for t, _ in replies_from(fs, 5)]
    assert any(t < 3 for t in rep5)
    assert not [t for t in rep5 if 3.2 <= t < 8.0]            # silent in the window
    # the master goes on asking (retries: more than one request per cycle in the window)
    assert len([t for t, _ in requests_to(fs, 5) if 3.2 <= t < 8.0]) >= 5
    after = [(t, service(f)) for t, f in requests_to(fs, 5) if t >= 8.0]
    names = [s for _, s in after]
    i = names.index("Set_Prm")
    assert names[i:i + 4] == ["Set_Prm", "Chk_Cfg", "Slave_Diag", "Data_Exchange"]
    t_dx = after[i + 3][0]
    assert [t for t in rep5 if t > t_dx]                        # answered in data exchange again
    # the other stations never noticed
    for a in (3, 4, 6, 7):
        assert all(service(f) == "Data_Exchange" for _, f in requests_to(fs, a)[4:])


def test_second_master_in_the_ring_only_inside_its_window():
    line = open_line(f"{V}&cycle=1&master2=1@5-8")
    tk = tokens(frames(listen(line, 15)))
    to1 = [t for t, k in tk if k == (1, MASTER)]
    back = [t for t, k in tk if k == (MASTER, 1)]
    # cycles start at 5, 6, 7 inside [5, 8): three passes each way
    assert len(to1) == len(back) == 3
    assert all(5 <= t < 8 for t in to1 + back)
    assert all(k == (MASTER, MASTER) for t, k in tk if not 5 <= t < 8)
    assert {k for _, k in tk} == {(MASTER, MASTER), (1, MASTER), (MASTER, 1)}


def test_adapter_pulled_raises_linklost_until_it_is_back_then_reads_go_on():
    line = open_line(f"{V}&cycle=1&adapter=10-13")
    before = listen(line, 9.5)
    assert before and before[-1][0] < 10
    with pytest.raises(LinkLost):
        listen(line, 5)
    assert line.now() == pytest.approx(10.0)
    tries = 0
    while True:
        with pytest.raises(LinkLost):              # a read while it is out: LinkLost again
            line.read(line.now() + 0.2)
        line.sleep(1.0)
        tries += 1
        try:
            line.reopen()
            break
        except LinkLost:
            assert line.now() < 13
    assert line.now() >= 13 and tries >= 3
    after = frames(listen(line, 5))
    assert after and after[0][0] >= 13
    # the plant ran on meanwhile: its stations are still in data exchange
    for a in DEFAULT_STATIONS:
        reqs = requests_to(after, a)
        assert reqs and all(service(f) == "Data_Exchange" for _, f in reqs)
        assert replies_from(after, a)


def test_repeat_repeats_every_window():
    line = open_line(f"{V}&cycle=1&adapter=2-3&master2=1@5-7&unplug=5@12-16&repeat=20")
    losses = []
    heard = []
    end = 65.0
    while line.now() < end:
        try:
            listen(line, end - line.now(), into=heard)
        except LinkLost:
            losses.append(line.now())
            while True:
                line.sleep(0.5)
                try:
                    line.reopen()
                    break
                except LinkLost:
                    pass
    assert losses == pytest.approx([2.0, 22.0, 42.0, 62.0])
    fs = frames(heard)
    to1 = [t for t, k in tokens(fs) if k == (1, MASTER)]
    assert [int(t) for t in to1] == [5, 6, 25, 26, 45, 46]
    rep5 = [t for t, _ in replies_from(fs, 5)]
    for k in range(3):           # unplug windows (from the first request, ~0.01 s after open)
        lo, hi = 12 + 20 * k, 16 + 20 * k
        assert not [t for t in rep5 if lo + 0.2 <= t < hi]
        assert [t for t in rep5 if hi <= t < lo + 20]             # back between the windows


def test_a_diagnosis_flagged_dh_is_read_and_the_trip_acknowledged():
    line = open_line(f"{V}&cycle=1&drivetrip=0.3&only=3&ack=2&seed=5")
    fs = frames(listen(line, 40))
    dh = [(t, f) for t, f in replies_from(fs, 3) if f.fc & 0x0F == F.DH and t < 38]
    assert dh
    reqs = requests_to(fs, 3)
    for t, _ in dh:
        nxt = next(f for tr, f in reqs if tr > t)
        assert service(nxt) == "Slave_Diag"
    # the operator's reset (ack=2): the drive is not left tripped
    assert line.bus.faults.counts["drivetrip"] >= 1
    line2 = open_line(f"{V}&cycle=1&trip=3:OC1&ack=5")
    listen(line2, 4)
    assert _fault(line2, 3)
    listen(line2, 2.5)
    assert not _fault(line2, 3)


def _fault(line, station):
    rows = line.bus.control().state()["stations"]
    return next(r for r in rows if r["station"] == station).get("fault")


# -- a tap -------------------------------------------------------------------------------------

def test_write_is_refused():
    line = open_line(V)
    with pytest.raises(BusError) as e:
        line.write(b"\x10\x03\x02\x49\x4e\x16")
    assert not isinstance(e.value, LinkLost)
    assert "\n" not in str(e.value)


def test_the_receive_buffer_is_bounded_while_nobody_reads():
    line = open_line(f"{V}&cycle=0.01")
    listen(line, 1)
    line.sleep(100)               # ~170 000 octets go by at 19200 bit/s meanwhile
    t = line.now()
    stale = 0
    while True:
        data = line.read(t)       # what waited in the buffer (heard before t)
        if not data:
            break
        stale += len(data)
    assert RX_BUFFER_OCTETS - 255 <= stale <= RX_BUFFER_OCTETS
    assert line.overrun_octets > 100_000
    assert listen(line, 1)        # and on it goes


def test_closed_line():
    line = open_line(V)
    line.close()
    with pytest.raises(BusError):
        line.read(1.0)


def test_virtual_clock_moves_only_by_reads_and_sleeps():
    line = open_line(V)
    assert line.now() == 0.0
    time.sleep(0.01)
    assert line.now() == 0.0
    line.sleep(2.5)
    assert line.now() == 2.5
    line.read(3.0)
    assert 2.5 <= line.now() <= 3.0


def test_real_clock_without_timing():
    line = open_line("sim://?cycle=0.05")
    try:
        heard = []
        give_up = time.monotonic() + 30          # (a loaded machine: generous)
        while not tokens(frames(heard)) and time.monotonic() < give_up:
            d = line.read(line.now() + 0.2)
            if d:
                heard.append((line.now(), d))
        assert tokens(frames(heard))
        assert line.now() > 0
    finally:
        line.close()


def test_same_seed_same_bytes():
    url = f"{V}&cycle=0.2&drop=0.05&flip=0.03&late=0.02&noise=0.02&drivetrip=0.01&ack=3&seed=11"
    a = listen(open_line(url), 30)
    b = listen(open_line(url), 30)
    assert a == b
    line = open_line(url)
    listen(line, 30)
    assert line.bus.faults.counts["drop"] and line.bus.faults.counts["flip"]
    c = listen(open_line(url.replace("seed=11", "seed=12")), 30)
    assert c != a


def test_faulty_replies_are_heard_as_they_were_on_the_wire():
    # a flipped bit: the telegram heard fails its FCS; noise: a garbage octet before the reply
    line = open_line(f"{V}&cycle=0.2&flip=0.05&noise=0.05&seed=3")
    heard = listen(line, 30)
    cap = Capture()
    got = [c for t, d in heard for c in cap.feed(d, t)]
    assert [c for c in got if c.frame is None]
    assert line.bus.faults.counts["flip"] and line.bus.faults.counts["noise"]


# -- bad input ---------------------------------------------------------------------------------

@pytest.mark.parametrize("query,key", [
    ("cycle=0", "cycle"), ("cycle=abc", "cycle"), ("cycle=1000", "cycle"),
    ("master2=2@1-2", "master2"), ("master2=1@5", "master2"), ("master2=x@1-2", "master2"),
    ("master2=3@1-2", "master2"), ("adapter=5-3", "adapter"), ("adapter=5", "adapter"),
    ("ack=-1", "ack"), ("repeat=x", "repeat"), ("repeat=2&adapter=1-4", "repeat"),
    ("repeat=3&unplug=3@1-5", "repeat"), ("bogus=1", "bogus"), ("timing=instant", "timing"),
    ("unplug=9@1-2", "unplug"), ("drop=x", "drop"), ("stations=3:nosuchdrive", "nosuchdrive"),
])
def test_bad_key_or_value_is_one_line_naming_it(query, key):
    with pytest.raises(UsageError) as e:
        open_line(f"{V}&{query}")
    msg = str(e.value)
    assert "\n" not in msg and key in msg


@pytest.mark.parametrize("url", ["/dev/ttyUSB0", "tcp://10.0.0.5:4001", "serial:///dev/ttyS0",
                                 "rfc2217://host:2217", "SIM-ish://?timing=virtual"])
def test_not_a_sim_url_is_one_line(url):
    with pytest.raises(UsageError) as e:
        open_line(url)
    assert "\n" not in str(e.value) and "sim://" in str(e.value)


# -- bounded -----------------------------------------------------------------------------------

def test_memory_is_bounded_over_a_long_run():
    """10 000 cycles with every episode repeating: the traced memory's peak after a warm-up grows
    by less than 1 MB. What is held by design: the tap (one cycle: < 20 telegrams of < 100 octets),
    the receive buffer (4 KB), the bus's tick log (512 floats), the stations' lazy tick replay (256
    floats each): < 100 KB. A leak of 100 octets a cycle would be 1 MB."""
    url = (f"{V}&stations=3:fuji-g1,7:yaskawa&cycle=0.1&drop=0.01&drivetrip=0.005&ack=2"
           f"&unplug=3@20-25&master2=1@30-40&adapter=50-52&repeat=60")
    line = open_line(url)
    _run(line, 120)                    # warm-up: every episode once, the models built
    tracemalloc.start()
    try:
        _run(line, 200)
        base = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        _run(line, 1000)
        current, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert line.cycles >= 0.9 * (120 + 200 + 1000) / 0.1      # (some cycles longer: retries)
    assert peak - base < 1_000_000, (base, current, peak)


def _run(line, seconds):
    end = line.now() + seconds
    while line.now() < end:
        try:
            line.read(min(end, line.now() + 0.2))
        except LinkLost:
            while True:
                line.sleep(0.5)
                try:
                    line.reopen()
                    break
                except LinkLost:
                    pass


def test_a_reply_is_read_whole_days_into_the_line():
    """After 2**16 s of line time the bus's octet count by division rounds a reply's last octet
    away at its exact end; the line must still hand the reply over (it once hung there)."""
    line = open_line(f"{V}&stations=3:fuji-g1&cycle=10")
    listen(line, 60)                          # in data exchange
    line.sleep(65536 - 60 - line.now())
    fs = frames(listen(line, 600))
    assert len(replies_from(fs, 3)) >= 50


def test_the_line_says_its_baud_rate():
    """The monitor's bus load needs the line's baud rate: the plant's (19200 bit/s by default,
    sim/plant.py; baud= sets it)."""
    from profidrive_cli.sim.virtual_line import open_line
    assert open_line("sim://?timing=virtual").baud == 19200
    assert open_line("sim://?timing=virtual&baud=187500").baud == 187_500
