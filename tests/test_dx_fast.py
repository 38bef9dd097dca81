"""The Data_Exchange fast path (fdl/fast.py, FdlMaster.dx_request/dx_feed, dp/dx_fast.py) against the
general engine: the same request octets at the same (virtual) times, the same counters, FCB states,
station states and inputs, under every injected fault kind; and the telegrams themselves by hand."""

import pytest

from profidrive_cli.dp.poller import Master
from profidrive_cli.dp.station import SlaveConfig
from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.master import MORE, NO_ANSWER, REPLY, FdlMaster
from profidrive_cli.fdl.timing import BusParams
from profidrive_cli.link import open_link
from profidrive_cli.link.base import Link
from profidrive_cli.link.parity import LineOctets
from profidrive_cli.sim.faults import KINDS, FaultPlan

BAUD = 187500


def _run(fast: bool, kind: str, polls: int = 1500, rate: float = 0.03, seed: int = 5):
    """A virtual-clock bus with the default plant, every station brought up, then `polls` rounds of
    Master.poll() with `kind` injected at `rate`. Returns what the master sent and ended with."""
    link = open_link(f"sim://?baud={BAUD}&timing=virtual", BAUD)
    m = Master(link, BusParams.for_baud(BAUD, retries=1))
    m.fast_dx = fast
    sent = []
    write = link.write

    def logged(data):
        sent.append((link.now(), bytes(data)))
        write(data)
    link.write = logged
    for a, s in sorted(link.bus.slaves.items()):
        m.add_station(a, SlaveConfig(ident=s.model.ident, cfg=s.model.real_cfg(), wd_ms=500))
        m.bring_up(a)
    plan = link.bus.faults = FaultPlan({kind: rate}, seed=seed)
    taken = [0]
    feed = m.fdl.dx_feed

    def counted(data, now):
        r = feed(data, now)
        taken[0] += type(r) is bytes
        return r
    m.fdl.dx_feed = counted
    for _ in range(polls):
        m.poll()
    fcb = {a: (f._started, f._fcb) for a, f in sorted(m.fdl._fcb.items())}
    stations = {a: (st.state, st.inputs, st.last_error) for a, st in m.stations.items()}
    result = dict(sent=sent, counters=m.counters(), fcb=fcb, stations=stations,
                  injected=dict(plan.by_station), clock=link.now())
    link.close()
    return result, taken[0]


@pytest.mark.parametrize("kind", KINDS)
def test_fast_and_general_path_are_the_same_on_the_wire_under_every_fault(kind):
    fast, taken_fast = _run(True, kind)
    general, taken_general = _run(False, kind)
    assert taken_general == 0
    assert taken_fast > 5000                       # the fast path really carried the traffic
    assert sum(v[kind] for v in fast["injected"].values()) >= 20, fast["injected"]
    assert fast["injected"] == general["injected"]
    assert len(fast["sent"]) == len(general["sent"])
    for i, (a, b) in enumerate(zip(fast["sent"], general["sent"])):
        assert a == b, (i, a, b)                    # same octets at the same virtual time
    assert fast["counters"] == general["counters"]
    assert fast["fcb"] == general["fcb"]
    assert fast["stations"] == general["stations"]
    assert fast["clock"] == general["clock"]


def test_fast_path_counts_each_fault_as_the_fault_plan_says():
    """The soak's accounting (FaultPlan.expected_counters) with the fast path on, every kind."""
    rates = {k: 0.006 for k in KINDS}
    link = open_link(f"sim://?baud={BAUD}&timing=virtual", BAUD)
    m = Master(link, BusParams.for_baud(BAUD, retries=1))
    assert m.fast_dx
    for a, s in sorted(link.bus.slaves.items()):
        m.add_station(a, SlaveConfig(ident=s.model.ident, cfg=s.model.real_cfg(), wd_ms=500))
        m.bring_up(a)
    plan = link.bus.faults = FaultPlan(rates, seed=3)
    for _ in range(2000):
        m.poll()
    link.bus.faults = None
    for _ in range(30):
        m.poll()
    for a, st in m.stations.items():
        c, e = m.fdl.counters[a], plan.expected_counters(a)
        assert st.in_data_exchange, (a, st.state, st.last_error)
        assert (c.illegal, c.retries + c.no_answer, c.rs, c.reparams, c.dh) == \
            (e["illegal"], e["failed_attempts"], e["rs"], e["reparams"], e["dh"]), a
    link.close()


# -- the telegrams, by hand -----------------------------------------------------------------------

def _fm(retries=1):
    return FdlMaster(BusParams.for_baud(BAUD, retries=retries), address=2)


def test_dx_request_octets_per_fcb_state():
    fm = _fm()
    out = fm.dx_request(8, bytes([1, 2, 3, 4]), 0.0, 4)
    # SD2 LE=7 LEr SD2, DA 8, SA 2, FC SRD high with FCB=1 FCV=0 (0x6D), data, FCS = sum(8..4) & 0xFF
    assert out == bytes.fromhex("68 07 07 68 08 02 6D 01 02 03 04 81 16")
    reply = bytes.fromhex("68 07 07 68 02 08 08 0A 0B 0C 0D 40 16")  # DL, FCS 02+08+08+0A..0D = 0x40
    assert fm.dx_feed(reply, 0.001) == bytes([0x0A, 0x0B, 0x0C, 0x0D])
    assert not fm.busy
    out = fm.dx_request(8, bytes([1, 2, 3, 4]), 0.002, 4)
    assert out == bytes.fromhex("68 07 07 68 08 02 5D 01 02 03 04 71 16")   # FCB=0 FCV=1
    assert fm.dx_feed(reply, 0.003) == bytes([0x0A, 0x0B, 0x0C, 0x0D])
    out = fm.dx_request(8, bytes([1, 2, 3, 4]), 0.004, 4)
    assert out[6] == 0x7D                                                  # FCB=1 FCV=1
    assert fm.counters[8].requests == 3


def test_dx_request_chooses_sd1_and_sd3_like_encode():
    fm = _fm()
    # no outputs: SD1 10 DA SA FC FCS ED
    assert fm.dx_request(5, b"", 0.0, 0) == bytes.fromhex("10 05 02 6D 74 16")
    fm.abort()
    # 8 outputs: SD3 (fixed length) A2 DA SA FC 8 octets FCS ED
    out = fm.dx_request(5, bytes(range(8)), 0.0, 8)
    assert out == bytes.fromhex("A2 05 02 6D 00 01 02 03 04 05 06 07") + bytes([(0x74 + 28) & 0xFF, 0x16])


def test_dx_request_sets_the_same_deadlines_as_request():
    a, b = _fm(), _fm()
    out_a = a.dx_request(8, bytes(12), 1.0, 12)
    out_b, dl = b.request(8, F.SRD_HIGH, bytes(12), None, None, 1.0, 12 + 9)
    assert out_a == out_b and a.deadline == dl and a._hard == b._hard


GOOD = bytes.fromhex("68 07 07 68 02 08 08 0A 0B 0C 0D 40 16")


@pytest.mark.parametrize("reply,why", [
    (F.encode(F.Frame(F.SD2, 2, 8, F.response_fc(F.DH), bytes([10, 11, 12, 13]))), "DH"),
    (F.encode(F.Frame(F.SD2, 2, 8, F.response_fc(F.RS), b"")), "RS"),
    (b"\xE5", "SC"),
    (F.encode(F.Frame(F.SD2, 2, 8, F.response_fc(F.DL), bytes([10, 11, 12]))), "short"),
    (F.encode(F.Frame(F.SD2, 2, 9, F.response_fc(F.DL), bytes([10, 11, 12, 13]))), "wrong SA"),
    (GOOD[:-2] + bytes([0x41, 0x16]), "FCS"),
    (GOOD[:-1] + b"\x17", "ED"),
    (b"\x55" + GOOD, "noise"),
])
def test_dx_feed_leaves_anything_else_to_the_general_engine(reply, why):
    fast, general = _fm(), _fm()
    fast.dx_request(8, bytes(4), 0.0, 4)
    general.request(8, F.SRD_HIGH, bytes(4), None, None, 0.0, 13)
    assert fast.dx_feed(reply, 0.001) is None, why
    a, b = fast.feed(reply, 0.001), general.feed(reply, 0.001)
    assert (a is None) == (b is None)
    if a is not None:
        assert (a.kind, a.frame, a.retries, a.illegal) == (b.kind, b.frame, b.retries, b.illegal)
    assert fast.deadline == general.deadline
    assert fast.counters[8].as_dict() == general.counters[8].as_dict()


def test_dx_feed_leaves_flagged_octets_to_the_general_engine():
    fm = _fm()
    fm.dx_request(8, bytes(4), 0.0, 4)
    assert fm.dx_feed(LineOctets(GOOD, errors=(5,)), 0.001) is None
    assert fm.busy
    # an unflagged LineOctets is an ordinary reply
    assert fm.dx_feed(LineOctets(GOOD), 0.001) == bytes([0x0A, 0x0B, 0x0C, 0x0D])


def test_dx_feed_collects_a_reply_in_pieces_like_feed():
    fast, general = _fm(), _fm()
    fast.dx_request(8, bytes(4), 0.0, 4)
    general.request(8, F.SRD_HIGH, bytes(4), None, None, 0.0, 13)
    for i, piece in enumerate((GOOD[:1], GOOD[1:5], GOOD[5:12])):
        assert fast.dx_feed(piece, 0.001 * (i + 1)) is MORE
        assert general.feed(piece, 0.001 * (i + 1)) is None
        assert fast.deadline == general.deadline and fast.missing() == general.missing()
    assert fast.dx_feed(GOOD[12:], 0.004) == bytes([0x0A, 0x0B, 0x0C, 0x0D])
    assert general.feed(GOOD[12:], 0.004).kind == REPLY
    assert fast.counters[8].as_dict() == general.counters[8].as_dict()


def test_dx_feed_broken_in_pieces_goes_on_in_the_general_engine():
    fm = _fm()
    fm.dx_request(8, bytes(4), 0.0, 4)
    bad = GOOD[:-2] + bytes([0x41, 0x16])
    assert fm.dx_feed(bad[:6], 0.001) is MORE
    assert fm.dx_feed(bad[6:], 0.002) is None          # the general engine takes it from here
    assert fm.feed(bad[6:], 0.002) is None             # FCS error: attempt spoilt
    nxt = fm.expire(fm.deadline)                       # one retry, the same octets
    assert nxt[0] == bytes.fromhex("68 07 07 68 08 02 6D 00 00 00 00 77 16")
    assert fm.dx_feed(GOOD, fm.deadline) == bytes([0x0A, 0x0B, 0x0C, 0x0D])
    c = fm.counters[8]
    assert (c.requests, c.retries, c.illegal, c.no_answer) == (1, 1, 1, 0)


def test_failed_dx_restarts_the_fcb_sequence():
    fm = _fm(retries=0)
    fm.dx_request(8, bytes(4), 0.0, 4)
    fm.dx_feed(GOOD, 0.001)
    out = fm.dx_request(8, bytes(4), 0.002, 4)
    assert out[6] == 0x5D
    res = fm.expire(1.0)
    assert res.kind == NO_ANSWER
    assert fm.dx_request(8, bytes(4), 1.1, 4)[6] == 0x6D   # FCV=0 FCB=1: a new sequence


class _CannedLink(Link):
    """Answers every request at once with the same prepared octets."""
    instant = True
    latency = 0.0

    def __init__(self, reply: bytes):
        self.reply = reply
        self.sent = []

    def write(self, data):
        self.sent.append(bytes(data))

    def read(self, deadline):
        return self.reply

    def flush_input(self):
        pass


def test_data_exchange_builds_no_frame_objects(monkeypatch):
    """The point of the fast path: in data exchange neither the request nor the reply becomes an
    fdl.frames.Frame, nothing is parsed (the general engine builds two Frames per exchange)."""
    link = open_link("sim://?stations=3:fuji-g1", 19200)
    m = Master(link, BusParams.for_baud(19200))
    s = link.bus.slave(3)
    m.add_station(3, SlaveConfig(ident=s.model.ident, cfg=s.model.real_cfg()))
    st = m.stations[3]
    m.bring_up(3)
    link.close()
    inputs = bytes(range(1, st.input_len + 1))
    m.link = _CannedLink(F.encode(F.Frame(F.SD2, 2, 3, F.response_fc(F.DL), inputs)))
    outputs = bytes(range(st.output_len))
    for _ in range(2):
        m.exchange(3, outputs)        # the templates of both FCB states are built once
    built = []
    real = F.Frame

    class Counting(real):
        __slots__ = ()

        def __init__(self, *a, **kw):
            built.append(a)
            super().__init__(*a, **kw)
    monkeypatch.setattr(F, "Frame", Counting)
    monkeypatch.setattr(F, "parse", lambda *a: pytest.fail("reply parsed by the general engine"))
    before = m.fdl.counters[3].data_exchanges
    for _ in range(20):
        assert m.exchange(3, outputs) == inputs
    assert built == []
    assert m.fdl.counters[3].data_exchanges == before + 20
    # and what went out is what encode() makes of it (FCV=1, FCB alternating)
    fcs = [r[6] for r in m.link.sent]
    assert all(f & 0x1F == 0x1D for f in fcs) and len({f & 0x20 for f in fcs[:2]}) == 2
    monkeypatch.undo()
    for r in m.link.sent:
        f, used = F.parse(r)
        assert used == len(r) and f.data == outputs and (f.da, f.sa) == (3, 2)


# -- the real byte path: a pty to `pdrive sim --pty` ------------------------------------------------

def _pty_sim(plant):
    import json
    import subprocess
    from conftest import pdrive_cmd
    p = subprocess.Popen(pdrive_cmd() + ["sim", "--json", "--pty", "--plant", plant],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = p.stdout.readline()
    if not line:
        p.kill()
        pytest.fail("pdrive sim printed nothing: " + p.stderr.read())
    return p, json.loads(line)["port"]


def _stop(p):
    import signal
    p.send_signal(signal.SIGINT)
    try:
        p.wait(timeout=10)
    except Exception:
        p.kill()
        raise


WD_MS = 2000


@pytest.mark.parametrize("faults", ["", "&drop=0.05&flip=0.05&noise=0.05&seed=4"])
def test_fast_path_over_a_pty(faults):
    """Replies through a real pty arrive in pieces: the fast path collects them (as the general
    engine would) and takes them; faults on the way still go through the general engine."""
    p, port = _pty_sim("sim://?stations=7:yaskawa" + faults)
    try:
        # 187.5k (the instant simulator answers at any rate): 150 exchanges take under a second.
        # The reply margin: without faults every reply comes, only late when the machine is busy
        # (the simulator's process not run for a while: at load 20 more than pdrive's usual 20 ms,
        # which then counted retries and no-answers), so the margin is half the watchdog (WD_MS):
        # a reply later than that would find the slave out of data exchange anyway; a reply that
        # comes ends the wait at once. With faults every dropped or spoilt reply waits the whole
        # margin: pdrive's 20 ms, and what is checked there allows for retries and no-answers.
        link = open_link(port, 187500)
        margin = 0.02 if faults else WD_MS / 2 / 1000
        m = Master(link, BusParams.for_baud(187500, retries=1, link_latency=margin))
        cfg = SlaveConfig(ident=0x00CA, cfg=bytes.fromhex("5F6F"), wd_ms=WD_MS)
        st = m.add_station(7, cfg)
        m.bring_up(7)
        taken = [0]
        feed = m.fdl.dx_feed

        def counted(data, now):
            r = feed(data, now)
            taken[0] += type(r) is bytes
            return r
        m.fdl.dx_feed = counted
        n = 150
        before = m.fdl.counters[7].data_exchanges
        fresh = 0
        for _ in range(n):
            m.exchange(7, bytes(st.output_len))
            fresh += st.fresh_inputs
        c = m.fdl.counters[7]
        assert st.in_data_exchange, st.last_error
        if not faults:
            assert (c.retries, c.illegal, c.no_answer) == (0, 0, 0)
            assert c.data_exchanges - before == taken[0] == n
        else:
            assert c.retries > 0 and c.illegal > 0           # the faults reached the master
            assert taken[0] > n // 2                         # the rest still took the fast path
            # each exchange: inputs (counted once), or its tries ended without them -- no answer, or
            # every reply spoilt (flip and noise spoil both tries of an exchange now and then: which
            # request a fault meets moves with the machine's load, so "no answer" alone is not enough)
            assert c.data_exchanges - before == fresh
            assert n - fresh <= c.no_answer + c.illegal
        link.close()
    finally:
        _stop(p)
