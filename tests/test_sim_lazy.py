"""Stations of a sim:// plant built on first use (sim/lazy.py): the same bytes on the wire and the
same drive state as a plant whose models are built when it opens."""

from __future__ import annotations

import pytest

from conftest import drive_on_bus
from profidrive_cli.dp.poller import Master
from profidrive_cli.drives.profile import load_profile, profile_index
from profidrive_cli.fdl.timing import BusParams
from profidrive_cli.link import open_link
from profidrive_cli.sim import lazy
from profidrive_cli.sim.lazy import LazyModel
from profidrive_cli.sim.plant import build_bus, make_model

NAMES = [e.name for e in profile_index() if e.name]


def test_the_shipped_profiles_are_all_indexed():
    assert len(NAMES) == 6              # the five seed cards and the generic DP-V1 axis (issue 39)


@pytest.mark.parametrize("name", NAMES)
def test_an_untouched_station_answers_what_its_built_model_would(name):
    """ident, max_diag_len and the extended diagnosis of a fresh drive, before and after building;
    the built model is the one make_model gives for the profile."""
    bus = build_bus(f"sim://?stations=3:{name}")
    slave = bus.slaves[3]
    proxy = slave.model
    assert isinstance(proxy, LazyModel) and not proxy.built
    before = (proxy.ident, proxy.max_diag_len, proxy.ext_diag(), slave.diag().encode())
    assert not proxy.built                     # none of these builds it
    ref = make_model(load_profile(name))
    assert before[:3] == (ref.ident, ref.max_diag_len, ref.ext_diag())
    real = proxy.materialize()
    assert slave.model is real and type(real) is type(ref)
    assert slave.diag().encode() == before[3]
    assert proxy.ident == real.ident and proxy.family == real.family      # forwards once built


def test_setting_an_attribute_builds_the_model_and_sets_it_there():
    bus = build_bus("sim://?stations=5:toyo")
    proxy = bus.slaves[5].model
    proxy.accel_s = 0.5
    assert proxy.built and bus.slaves[5].model.accel_s == 0.5


def test_a_station_with_presets_trips_or_faults_is_built_at_once():
    bus = build_bus("sim://?stations=3:fuji-g1,5:toyo,7:yaskawa&set=7:A1-02=3&trip=3:OC1&faults=5:OC")
    assert not any(isinstance(s.model, LazyModel) for s in bus.slaves.values())


def test_an_unknown_station_name_is_refused_when_the_plant_opens():
    from profidrive_cli import UsageError
    with pytest.raises(UsageError, match="unknown profile 'nosuch'"):
        build_bus("sim://?stations=3:nosuch")


def _run(materialize_first: bool):
    """Station 3 exchanges for 3 s of virtual time while station 5 (Toyo) stands by (its clock runs),
    then 5 is brought up, runs and trips. Everything the master saw, and the Toyo's trip recording
    (traceback samples, taken at standstill before it was addressed)."""
    link = open_link("sim://?stations=3:fuji-g1,5:toyo&timing=virtual", 19200)
    bus = link.bus
    if materialize_first:
        for s in bus.slaves.values():
            s.model.materialize()
    m = Master(link, BusParams.for_baud(19200, retries=1))
    seen = []
    d3 = drive_on_bus(m, 3, load_profile("fuji-g1"), "ppo1", wd_ms=5000)
    t_end = link.now() + 3.0
    while link.now() < t_end:
        seen.append(repr(d3.status()))
    seen.append(m.slave_diag(5).encode())
    toyo = load_profile("toyo")
    d5 = drive_on_bus(m, 5, toyo, "ppo1", wd_ms=5000)
    d5.set_speed_hz(20.0)
    d5.start()
    for _ in range(20):
        seen.append(repr(d5.status()))
    model5 = bus.slaves[5].model
    model5.trip("OC", link.now())
    for _ in range(3):
        seen.append(repr(d5.status()))
    seen.append(m.slave_diag(5).encode())
    rec = model5.recordings[0]
    link.close()
    return seen, rec


def test_a_lazily_built_plant_behaves_like_one_built_when_it_opens():
    seen_lazy, rec_lazy = _run(False)
    seen_eager, rec_eager = _run(True)
    assert seen_lazy == seen_eager
    assert len(rec_lazy) == 100                         # TB: 100 points per recording
    # the recording's first samples are the standstill before station 5 was addressed (the DC link
    # ripples, so each has its own value): not the zero padding of a drive with no history
    assert rec_lazy[0] != (0,) * 16
    assert rec_lazy == rec_eager


def test_the_tick_replay_is_bounded():
    calls = []

    class Fake:
        ident = 1

        def tick(self, now):
            calls.append(now)
    p = LazyModel(Fake, 1, "plain")
    for i in range(lazy.REPLAY_TICKS + 50):
        p.tick(float(i))
    p.materialize()
    assert calls == [float(i) for i in range(50, lazy.REPLAY_TICKS + 50)]
    p.tick(999.0)
    assert calls[-1] == 999.0


def test_a_served_plant_builds_every_station_before_the_first_request():
    """pdrive sim --pty / --listen: a master on the other end must not wait for a model to be built."""
    from profidrive_cli.sim import server
    bus = build_bus("sim://?stations=3:fuji-g1,5:toyo")

    class NoEndpoint:
        def read(self, timeout):
            return b""

        def write(self, data):
            raise AssertionError("nothing was asked")
    server.serve(bus, NoEndpoint(), stop=iter([False, True]).__next__)
    assert not any(isinstance(s.model, LazyModel) for s in bus.slaves.values())
