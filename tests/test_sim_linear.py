"""A simulator linear in stations (issue 29): a station's clock (watchdog, drive model) runs when a
request addresses it or when it is due (its watchdog's expiry, the model's next_due), not at every
tick of the bus; a station that was not run at some ticks makes up for them when it next runs.

The reference for "the same behaviour" is the bus as it was: every station's clock run at every tick
(EveryTick below). Same plant, same master script, virtual clock: the same octets at the same times
on the wire, and the same state in every model (timestamps, Toyo traceback samples, Moeller trip
records included) once the stations are made up to the last tick."""

from __future__ import annotations

import pytest

from conftest import drive_on_bus
from profidrive_cli.dp.poller import Master
from profidrive_cli.dp.station import SlaveConfig
from profidrive_cli.drives.profile import load_profile
from profidrive_cli.fdl.timing import BusParams
from profidrive_cli.link import open_link
from profidrive_cli.sim.bus import SimBus
from profidrive_cli.sim.lazy import LazyModel
from profidrive_cli.sim.model import SlaveModel
from profidrive_cli.sim.slave import DATA_EXCH, SimSlave

FUJI_IDENT, PPO1 = 0xFD01, bytes.fromhex("F3F1")       # fuji-g1 (profile), PPO1: 12 octets each way


class EveryTick(SimBus):
    """The bus before issue 29: every station's clock runs at every tick, no queue, no catch-up."""

    def tick(self, now):
        if self.pending:
            self.run_pending(now)
        for s in self.slaves.values():
            s.tick(now)

    def resync(self, now=None):
        self._synced = len(self._slaves)

    def schedule(self, s):
        pass

    def settle(self):
        pass


def _counting(model, counter):
    real = model.tick

    def tick(now):
        counter[0] += 1
        real(now)
    model.tick = tick


@pytest.mark.parametrize("baud", [19200, 1500000])
def test_model_ticks_per_exchange_do_not_grow_with_the_stations(baud):
    """N Fuji stations in Data_Exchange (watchdog 60 s), polled round robin: per exchange, the drive
    models run as often with 40 stations as with 5 -- the addressed one (SimSlave.handle, then
    its own data_exchange: 2), none of the others (standstill, watchdog not due). The old bus ran
    every station's model at every 10 ms tick: at 19.2 kbit/s an exchange spans 2-3 ticks."""
    per_exchange = {}
    for n in (5, 40):
        addrs = list(range(3, 3 + n))
        url = "sim://?stations=" + ",".join(f"{a}:fuji-g1" for a in addrs) + f"&timing=virtual&baud={baud}"
        link = open_link(url, baud)
        m = Master(link, BusParams.for_baud(baud, retries=1))
        for a in addrs:
            m.add_station(a, SlaveConfig(ident=FUJI_IDENT, cfg=PPO1, wd_ms=60000))
            m.bring_up(a)
        ticks = [0]
        for s in link.bus.slaves.values():
            _counting(s.model, ticks)
        exchanges = 4 * n
        for i in range(exchanges):
            m.exchange(addrs[i % n], bytes(12))
        assert all(m.stations[a].in_data_exchange for a in addrs)
        per_exchange[n] = ticks[0] / exchanges
        link.close()
    assert per_exchange[5] == per_exchange[40] == 2.0


URL = ("sim://?stations=3:fuji-g1,4:fuji-pdp3,5:toyo,6:moeller,7:yaskawa,8:fuji-g1,9:toyo,10:fuji-g1,"
       "11:toyo,12:moeller,13:toyo&timing=virtual&baud={baud}&set=8:o27=1,o28=0.5")


def _scenario(baud, reference):
    """Five families running, stopping and standing still unaddressed; drives left alone while
    running at a steady speed, then tripped through the control (Moeller trip record, Toyo
    traceback) or faulted by their own timer (Yaskawa comm_timeout: BUS); a watchdog running out on a
    running drive (o27 = 1: Er5 after o28) and on a stopped one; a y97 save at standstill without
    traffic to its station; trips at standstill through the control; an unplugged and replugged
    station; a station built on first use after standing by. What the master saw, the wire log,
    and every model's state at the end."""
    link = open_link(URL.format(baud=baud), baud)
    bus = link.bus
    if reference:
        bus.__class__ = EveryTick
    bus.log = []
    m = Master(link, BusParams.for_baud(baud, retries=1))
    ctl = bus.control(clock=link.now)
    P = {n: load_profile(n) for n in ("fuji-g1", "fuji-pdp3", "toyo", "moeller", "yaskawa")}
    d = {3: drive_on_bus(m, 3, P["fuji-g1"], "ppo1", 5000), 4: drive_on_bus(m, 4, P["fuji-pdp3"], "ppo1", 5000),
         5: drive_on_bus(m, 5, P["toyo"], "ppo1", 5000), 6: drive_on_bus(m, 6, P["moeller"], "ppo1", 5000),
         7: drive_on_bus(m, 7, P["yaskawa"], "extended1", 5000), 8: drive_on_bus(m, 8, P["fuji-g1"], "ppo1", 300),
         10: drive_on_bus(m, 10, P["fuji-g1"], "ppo1", 200), 12: drive_on_bus(m, 12, P["moeller"], "ppo1", 9000),
         13: drive_on_bus(m, 13, P["toyo"], "ppo1", 9000)}
    seen: list = [m.slave_diag(9).encode()]

    def poll(addrs, seconds):
        end = link.now() + seconds
        while link.now() < end:
            for a in addrs:
                seen.append((a, repr(d[a].status())))
    for a, hz in ((3, 20.0), (5, 15.0), (6, 25.0), (7, 30.0), (8, 10.0), (12, 12.0), (13, 6.0)):
        d[a].set_speed_hz(hz)
        d[a].start()
    poll([3, 4, 5, 6, 7, 8], 1.0)
    poll([3, 4, 5, 6, 7], 1.5)            # 8 (300 ms) and 10 (200 ms) are left alone: watchdogs
    poll([3, 4, 5, 6], 1.5)               # 7, 12, 13 left alone, running (at a steady speed)
    seen.append(ctl.trip(12))
    seen.append(ctl.trip(13, "OC"))
    poll([12, 13], 0.2)
    for a in (3, 5, 6):
        d[a].stop(wait=False)
    poll([3, 5, 6, 7], 4.0)
    d[4].write_raw_code("y97", 2)          # a save at standstill; station 4 not addressed meanwhile
    poll([3, 7], 0.6)
    seen.append(int(d[4].read_param("y97").raw))
    poll([3, 7], 0.6)
    seen.append(int(d[4].read_param("y97").raw))
    poll([3, 7], 1.0)                      # 5 (Toyo) and 6 (Moeller) stand still, unaddressed
    seen.append(ctl.trip(5, "OC"))
    seen.append(ctl.trip(6))
    poll([3, 5, 6, 7], 0.5)
    seen.append(ctl.unplug(11))
    poll([3, 7], 0.7)
    seen.append(ctl.replug(11))
    seen.append(ctl.state())
    d[9] = drive_on_bus(m, 9, P["toyo"], "ppo1", 5000)
    poll([9, 3], 0.5)
    seen.append(ctl.trip(9, "OC"))
    poll([9, 7], 0.3)
    for a in (8, 10, 11):
        seen.append(m.slave_diag(a).encode())
    bus.settle()                           # every station made up to the last tick
    state = {}
    for a, s in sorted(bus.slaves.items()):
        model = s.model.materialize() if isinstance(s.model, LazyModel) else s.model
        row = {"dp": (s.state, dict(s.stats), s.last_seen, s.wd_s)}
        for k in ("values", "regs", "freq", "out_hz", "state", "recordings", "samples", "run_seconds",
                  "eeprom", "history", "alarm_log", "trip_log", "fault", "_last_tick", "motor", "_now"):
            if hasattr(model, k):
                v = getattr(model, k)
                row[k] = list(v) if k == "samples" else (repr(v) if k == "motor" else v)
        state[a] = row
    link.close()
    return bus.log, seen, state


@pytest.mark.parametrize("baud", [19200, 1500000])
def test_the_plant_behaves_as_when_every_station_ticked(baud):
    log, seen, state = _scenario(baud, reference=False)
    log_ref, seen_ref, state_ref = _scenario(baud, reference=True)
    assert seen == seen_ref
    assert log == log_ref                                   # octets and their times
    for a in state_ref:
        assert state[a] == state_ref[a], a
    # the scenario did what it says (so the comparison covers it)
    assert [x for x in seen if isinstance(x, int)] == [2, 1]     # y97: saving (1 s), then saved
    assert state[10]["dp"][1]["watchdog_expired"] == 1 and state[10]["dp"][0] != DATA_EXCH
    assert state[8]["dp"][1]["watchdog_expired"] >= 1
    assert state[8]["alarm_log"][0][1].lower() == "er5"      # o27 = 1: Er5 after o28
    assert len(state[5]["recordings"]) == 1 and len(state[5]["recordings"][0]) == 100
    assert state[6]["values"]["d080"] == 1                   # the Moeller trip counter
    assert state[12]["values"]["d080"] == 1 and state[12]["run_seconds"] > 1.0
    assert state[13]["recordings"][0][-2][8] != 0            # tripped while turning: speed word
    assert state[7]["fault"] == "BUS"                        # comm_timeout while running


def test_a_toyo_makes_up_for_ticks_at_standstill_as_if_ticked():
    """The Toyo card samples its traceback at every tick (sim/toyo.py): catch_up at standstill gives
    the samples, clocks and motor of a model ticked at each of those times."""
    from profidrive_cli.sim.toyo import make_model
    toyo = load_profile("toyo")
    a, b = make_model(toyo), make_model(toyo)
    times = [0.01 * i for i in range(1, 180)]
    for t in times:
        a.tick(t)
    b.catch_up(times)
    assert list(b.samples) == list(a.samples) and len(a.samples) == 100
    assert (b._last_tick, repr(b.motor)) == (a._last_tick, repr(a.motor))
    later = [1.8 + 0.01 * i for i in range(1, 40)]
    for t in later:
        a.tick(t)
    b.catch_up(later, then=2.3)
    a.tick(2.3)
    b.tick(2.3)
    assert list(b.samples) == list(a.samples) and repr(b.motor) == repr(a.motor)


def test_next_due_of_the_families():
    """At standstill nothing of their own (None); running: every tick (the time of the last tick);
    Yaskawa in data exchange: the end of comm_timeout (1 s, the sim's default) after the last one."""
    from profidrive_cli.drives.profidrive import State
    from profidrive_cli.sim.plant import make_model
    for name in ("fuji-g1", "fuji-pdp3", "toyo", "moeller"):
        model = make_model(load_profile(name))
        assert model.next_due(2.0) is None, name
        model.state, model.freq = State.S4, 10.0
        assert model.next_due(2.0) == 2.0, name
        model.trip(model.profile.alarms[0].code, 2.0)
        model.freq = 0.0
        assert model.next_due(2.5) is None, name
    y = make_model(load_profile("yaskawa"))
    assert y.next_due(0.0) is None
    assert y.check_cfg(y.cfgs["extended1"])
    y.data_exchange(bytes(y.output_len), 3.0)
    assert y.next_due(3.0) == 4.0
    y.tick(4.5)                                         # the link is gone: BUS (the drive was idle:
    assert y.next_due(4.5) is None                      # bus_fault=running keeps it quiet)


class _TickRecorder(SlaveModel):
    """A model written before next_due: its own tick(), which records when it ran."""

    def __init__(self):
        super().__init__(0x4711, {"x": bytes([0x31])})
        self.times = []

    def tick(self, now):
        self.times.append(now)


def test_a_model_without_next_due_is_ticked_at_every_tick_as_before():
    """A model written before next_due (its own tick, e.g. a plug-in family's) keeps its clock."""
    old = _TickRecorder()
    bus = SimBus([SimSlave(9, old)], timing="virtual")
    for i in range(1, 51):
        bus.tick(0.01 * i)
    assert old.times == [0.01 * i for i in range(1, 51)]


def test_a_station_plugged_back_in_does_not_replay_the_time_it_was_out():
    """The old bus did not run unplugged stations; a station plugged back in starts from there."""
    model = _TickRecorder()
    bus = SimBus([SimSlave(9, model)], timing="virtual")
    ctl = bus.control(clock=lambda: t)
    t = 0.0
    for i in range(1, 11):
        t = 0.01 * i
        bus.tick(t)
    ctl.unplug(9)
    for i in range(11, 21):
        t = 0.01 * i
        bus.tick(t)
    ctl.replug(9)
    for i in range(21, 31):
        t = 0.01 * i
        bus.tick(t)
    assert model.times == [0.01 * i for i in list(range(1, 11)) + list(range(21, 31))]


def test_which_models_are_ticked_at_every_tick():
    """The shipped families say next_due where they say tick; a subclass that changes tick() and
    not next_due() (a plug-in family on top of a shipped model) keeps the old clock."""
    from profidrive_cli.sim.fuji import FujiModel
    from profidrive_cli.sim.plant import make_model
    from profidrive_cli.sim.model import ticks_always
    for name in ("fuji-g1", "fuji-pdp3", "toyo", "moeller", "yaskawa"):
        assert not ticks_always(make_model(load_profile(name))), name
    assert not ticks_always(SlaveModel(1))

    class Plugin(FujiModel):
        def tick(self, now):
            super().tick(now)

    class Declared(Plugin):
        def next_due(self, now):
            return None
    assert ticks_always(Plugin(load_profile("fuji-g1")))
    assert not ticks_always(Declared(load_profile("fuji-g1")))
