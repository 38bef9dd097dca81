"""Stations already in data exchange stay in the cycle while the master brings up the next ones
(dp.poller.Master.keep / keep_alive): `pdrive run 3,4,5,6,7`, the checklist's `together` and the API
all bring stations up one after another, and none of the stations already up may go longer than its
DP watchdog without a Data_Exchange meanwhile.

All on the virtual-time simulator (sim://?timing=virtual: exact wire times, no real waiting) at
9.6 kbit/s, where one start-up (Slave_Diag, Set_Prm, Chk_Cfg, Slave_Diag: about 0.13 s on the wire)
per further station quickly adds up to more than the 500 ms watchdog of the first one. The bound is
the watchdog the stations were given in Set_Prm (DEFAULT_WATCHDOG_MS = 500 ms for `run` and the API,
the checklist's default the same); the simulated slave enforces it and counts each expiry
(sim/slave.py tick: no telegram from its master within the watchdog -> Wait_Prm).
"""

from __future__ import annotations

import pytest

from profidrive_cli.dp import services as S
from profidrive_cli.fdl import frames as F

#: the DP watchdog every station gets here (ms): run's and the API's default
WATCHDOG_MS = 500


def no_dx_spans(log, baud: int) -> dict[int, float]:
    """{station: the longest time it was in data exchange without a Data_Exchange} from the
    simulated bus's log ((start, "M"/"S", octets) per telegram). A station counts from the end of
    the last request of its start-up (Chk_Cfg, then the Slave_Diag reads until it is ready: the
    master takes it into data exchange there) to the end of each Data_Exchange request (when the
    slave has it and retriggers its watchdog), until the start of the next Set_Prm to it (its
    release or a new start-up: where it left data exchange, the span up to there counts too)."""
    char_s = 11.0 / baud                        # one UART character: 11 bits (reference §2)
    since: dict[int, float] = {}
    worst: dict[int, float] = {}
    in_dx: set[int] = set()
    for t, who, octets in log:
        if who != "M":
            continue
        res = F.parse(octets)
        if not isinstance(res, tuple) or res[0].sd not in (F.SD1, F.SD2, F.SD3):
            continue
        fr = res[0]
        a, end = fr.da, t + len(octets) * char_s
        if fr.dsap == S.SAP_CHK_CFG or (fr.dsap == S.SAP_SLAVE_DIAG and a in since
                                        and a not in in_dx):
            since[a] = end
        elif fr.dsap == S.SAP_SET_PRM:
            in_dx.discard(a)
            if a in since:
                worst[a] = max(worst.get(a, 0.0), t - since.pop(a))
        elif fr.dsap is None and fr.function == F.SRD_HIGH and a in since:
            worst[a] = max(worst.get(a, 0.0), end - since[a])
            since[a] = end
            in_dx.add(a)
    return worst


class BroughtUp(Exception):
    """Raised by the test where `run` has every station in data exchange (its first fmax read)."""


@pytest.mark.parametrize("url", [
    "sim://?timing=virtual&baud=9600",                                      # default plant, Yaskawa at 7
    "sim://?timing=virtual&baud=9600&stations=3:yaskawa,4:fuji-g1,5:toyo,6:moeller,7:yaskawa",
])
def test_run_brings_up_five_stations_at_9600_without_a_watchdog_expiring(sim, monkeypatch, url):
    """`run 3,4,5,6,7` at 9.6k: the stations are brought up one after another; stopped where every
    one is in data exchange (the first max-frequency read), then released. Before the keep-alive,
    station 3 had no telegram for the 4 further start-ups (~0.5 s): its watchdog expired."""
    from profidrive_cli.cli.common import BusOptions
    from profidrive_cli.session.motion import Motion
    from profidrive_cli.session.multirun import MultiRun

    def brought_up(self, override=None):
        raise BroughtUp
    monkeypatch.setattr(Motion, "fmax", brought_up)
    front = BusOptions(url, "9600", 2, None, None, False, False, 0, False).open_bus()
    master = front.master
    bus = next(iter(sim.values()))
    bus.log = []
    run = MultiRun(front, [3, 4, 5, 6, 7], [("hz", 20.0)] * 5, duration=1.0,
                   watchdog_ms=WATCHDOG_MS)
    with pytest.raises(BroughtUp):
        run.run()
    assert all(r.session.drive is not None for r in run.runs)     # all five were brought up
    spans = no_dx_spans(bus.log, 9600)
    assert sorted(spans) == [3, 4, 5, 6, 7]
    assert max(spans.values()) <= WATCHDOG_MS / 1000.0, spans
    assert {a: s.stats["watchdog_expired"] for a, s in bus.slaves.items()} == dict.fromkeys(spans, 0)
    assert master.keep_alives > 0


@pytest.mark.parametrize("sync", [False, True])
def test_run_of_several_yaskawa_stations_at_19200_passes(sim, sync):
    """The issue's other case: several Yaskawa stations (32-octet telegrams) at 19.2k, the whole run
    (a regression check: on the virtual clock this one came up before too). With --sync (every
    YASK00CA.GSD claims Sync and Freeze) the keep-alives of the bring-up are no rounds: one
    Global_Control per round, then Unsync+Unfreeze, as without them."""
    from profidrive_cli.cli.common import BusOptions
    from profidrive_cli.session.multirun import MultiRun
    # without --sync four Yaskawa and a Fuji (its GSD claims no Sync); with it four Yaskawa
    yask = (3, 4, 5, 6) if sync else (3, 4, 5, 7)
    addresses = [3, 4, 5, 6] if sync else [3, 4, 5, 6, 7]
    plant = ",".join(f"{a}:yaskawa" if a in yask else f"{a}:fuji-g1" for a in addresses)
    ramps = "&".join(f"set={a}:C1-01=0.3,C1-02=0.3" if a in yask else f"set={a}:F07=0.3,F08=0.3"
                     for a in addresses)
    url = f"sim://?timing=virtual&baud=19200&stations={plant}&{ramps}"
    front = BusOptions(url, "19200", 2, None, None, False, False, 0, False).open_bus()
    master = front.master
    bus = next(iter(sim.values()))
    bus.log = []
    run = MultiRun(front, addresses, [("hz", 20.0)] * len(addresses), duration=2.0,
                   watchdog_ms=WATCHDOG_MS, sync=sync)
    assert run.run() == 0, run.end_dict()
    spans = no_dx_spans(bus.log, 19200)
    assert max(spans.values()) <= WATCHDOG_MS / 1000.0, spans
    assert all(s.stats["watchdog_expired"] == 0 for s in bus.slaves.values())
    assert master.keep_alives > 0
    end = run.end_dict()
    assert end["global_controls"] == (end["rounds"] + 1 if sync else 0)


LINE = """name: line
stations:
  - {name: c1, address: 3, profile: fuji-g1}
  - {name: c2, address: 4, profile: fuji-pdp3}
  - {name: c3, address: 6, profile: moeller}
  - {name: c4, address: 8, profile: fuji-g1}
  - {name: c5, address: 9, profile: moeller}
steps:
  - run: {hz: 20, duration: 0.5, together: true}
"""


def test_checklist_together_keeps_the_first_station_while_it_opens_the_others(sim):
    """The checklist's `together`: c1's session is open (and on the group) while the step opens
    c2..c5 one after another at 9.6k; c1 is kept in data exchange meanwhile, and the step passes."""
    from profidrive_cli.checklist.runner import PASSED, Runner, session_opener
    from profidrive_cli.checklist.spec import load_checklist_text
    from profidrive_cli.cli.common import BusOptions
    url = ("sim://?timing=virtual&baud=9600&stations=3:fuji-g1,4:fuji-pdp3,6:moeller,8:fuji-g1,"
           "9:moeller&set=3:F07=0.3,F08=0.3&set=8:F07=0.3,F08=0.3&set=6:F002=0.3,F003=0.3"
           "&set=9:F002=0.3,F003=0.3")
    front = BusOptions(url, "9600", 2, None, None, False, False, 0, False).open_bus()
    bus = next(iter(sim.values()))
    bus.log = []
    res = Runner(load_checklist_text(LINE, "line.yaml"), session_opener(front, watchdog_ms=WATCHDOG_MS),
                 yes=True).run()
    front.close()
    assert [s.status for s in res.stations] == [PASSED] * 5, \
        [(s.spec.name, [(r.status, r.message) for r in s.steps]) for s in res.stations]
    spans = no_dx_spans(bus.log, 9600)
    assert sorted(spans) == [3, 4, 6, 8, 9]
    assert max(spans.values()) <= WATCHDOG_MS / 1000.0, spans
    assert all(s.stats["watchdog_expired"] == 0 for s in bus.slaves.values())


@pytest.mark.usefixtures("no_config_at_all")
def test_api_drives_opened_one_after_another_keep_the_first_running():
    """The API: drive 3 runs at 20 Hz while drives 4..7 are opened at 9.6k (the bus lock is held for
    each open, so the API's own keep-alive thread cannot send meanwhile): 3 stays in data exchange
    and at its speed."""
    import profidrive_cli as pdrive
    with pdrive.open_bus("sim://?timing=virtual&set=3:F07=0.3,F08=0.3", baud=9600) as bus:
        sim_bus = bus.master.link.bus
        sim_bus.log = []
        d3 = bus.drive(3, watchdog_ms=WATCHDOG_MS)
        d3.run(hz=20, wait=True, timeout=30)
        for a in (4, 5, 6, 7):
            bus.drive(a, watchdog_ms=WATCHDOG_MS)
        assert sim_bus.slave(3).stats["watchdog_expired"] == 0
        assert d3.status().running and sim_bus.slave(3).model.freq == pytest.approx(20.0, abs=0.3)
        spans = no_dx_spans(sim_bus.log, 9600)
        assert max(spans.values()) <= WATCHDOG_MS / 1000.0, spans
    assert sim_bus.slave(3).model.freq == 0.0


def test_keep_within_is_a_quarter_of_the_watchdog_never_later_than_the_period():
    from profidrive_cli.dp.poller import keep_within
    assert keep_within(500) == pytest.approx(0.125)           # 500 ms / 4
    assert keep_within(500, 0.05) == pytest.approx(0.05)      # 20 rounds/s: every period
    assert keep_within(500, 0.4) == pytest.approx(0.125)
    assert keep_within(None, 0.1) == pytest.approx(0.1)       # no watchdog: the period alone
    assert keep_within(None) is None                          # neither: not kept


def _master(baud=9600):
    from profidrive_cli.dp.poller import Master
    from profidrive_cli.fdl.timing import BusParams
    from profidrive_cli.link import open_link
    link = open_link("sim://?timing=virtual", baud)
    return Master(link, BusParams.for_baud(baud, retries=1))


def _configs(m):
    from profidrive_cli.dp.station import SlaveConfig
    return {a: SlaveConfig(ident=s.model.ident, cfg=s.model.real_cfg(), wd_ms=WATCHDOG_MS)
            for a, s in sorted(m.link.bus.slaves.items())}


@pytest.mark.parametrize("kept", [True, False])
def test_only_stations_marked_kept_get_keep_alives(kept):
    """Master level: stations 3..7 brought up one after another at 9.6k. Marked kept, none goes a
    watchdog without a Data_Exchange; unmarked, the master sends nothing it was not asked for (the
    comm-loss test's silence stays silence) and the first one's watchdog expires, as before."""
    m = _master()
    bus = m.link.bus
    bus.log = []
    for a, cfg in _configs(m).items():
        m.add_station(a, cfg)
        m.bring_up(a)
        if kept:
            m.keep(a)
    m.exchange(3)                                  # the first one's next cycle
    spans = no_dx_spans(bus.log, 9600)
    expired = bus.slaves[3].stats["watchdog_expired"]
    if kept:
        assert max(spans.values()) <= WATCHDOG_MS / 1000.0, spans
        assert expired == 0 and m.keep_alives > 0
    else:
        assert m.keep_alives == 0
        assert spans[3] > WATCHDOG_MS / 1000.0 and expired == 1
    m.link.close()


@pytest.mark.parametrize("round_s, expect_ms", [
    (0.3115, 940.0),      # 3 x 311.5 ms = 934.5 ms -> the next multiple of 10
    (0.1, 300.0),         # exactly 3 rounds of 100 ms
    (0.0266, 80.0),       # 3 x 26.6 = 79.8 ms -> 80
])
def test_the_group_watchdog_outlasts_three_rounds(round_s, expect_ms):
    from profidrive_cli.session.group import min_watchdog_ms
    assert min_watchdog_ms(round_s) == expect_ms


def test_run_of_five_stations_at_9600_runs_through_with_a_watchdog_raised_to_three_rounds(sim):
    """`run 3,4,5,6,7` at 9.6k: one round of five Data_Exchanges takes ~0.31 s, and a station can
    wait two rounds (0.62 s) for its next exchange while a drive's handshake completes rounds early:
    a 500 ms watchdog expired while station 7 started (station 6 left data exchange, RS). The run
    raises the watchdog to three rounds, says so, and every drive reaches 20 Hz and stops."""
    from profidrive_cli.cli.common import BusOptions
    from profidrive_cli.session.multirun import MultiRun
    url = "sim://?timing=virtual&baud=9600"
    front = BusOptions(url, "9600", 2, None, None, False, False, 0, False).open_bus()
    bus = next(iter(sim.values()))
    run = MultiRun(front, [3, 4, 5, 6, 7], [("hz", 20.0)] * 5, duration=5.0,
                   watchdog_ms=WATCHDOG_MS)
    assert run.run() == 0, run.end_dict()
    round_s = 1.0 / run.wire_hz
    assert 0.2 < round_s < 0.5                                 # five telegram pairs at 9.6k
    assert run.watchdog_ms >= 3 * round_s * 1000.0 > WATCHDOG_MS
    assert any(w.startswith(f"watchdog raised from {WATCHDOG_MS} ms to {run.watchdog_ms:g} ms")
               for w in run.warnings), run.warnings
    assert all(r.reached_after is not None for r in run.runs)
    assert all(s.stats["watchdog_expired"] == 0 for s in bus.slaves.values())


def _set_prm_watchdogs(log) -> dict[int, set[float]]:
    """{station: the DP watchdogs (ms) its Set_Prm telegrams carried} from the simulated bus's log
    (an Unlock_Req, the release, carries none that counts)."""
    out: dict[int, set[float]] = {}
    for _, who, octets in log:
        res = F.parse(octets) if who == "M" else None
        if not isinstance(res, tuple) or res[0].sd not in (F.SD1, F.SD2, F.SD3):
            continue
        fr = res[0]
        if fr.dsap == S.SAP_SET_PRM:
            prm = S.SetPrm.decode(fr.data)
            if not prm.unlock and prm.wd_ms is not None:
                out.setdefault(fr.da, set()).add(prm.wd_ms)
    return out


@pytest.mark.usefixtures("no_config_at_all")
def test_checklist_together_raises_the_watchdog_to_three_rounds_of_its_group(sim, tmp_path):
    """`checklist run` with a `together` step of five stations at 9.6k: each station is parameterised
    with the group's watchdog (three rounds, as run 3,4,5 does: session/group.py), also on its own
    turn before the step, and the report says so. Before, they kept the 500 ms asked for while one
    round of the five takes 266 ms (a station may wait two rounds plus a retry)."""
    from click.testing import CliRunner
    from profidrive_cli.cli.main import cli
    # one Data_Exchange of a PPO1 station (12 octets each way) at 9.6k, by hand: request and reply
    # are SD2 frames of LE + 6 = (3 + 12) + 6 = 21 octets (reference table of start delimiters,
    # profibus-dp-reference.md:63,71), 11 bits each: 462 bit times, + min TSDR 11 + TID1 37
    # (reference line 350) = 510 bit times = 53.125 ms; five stations a round: 265.6 ms;
    # three rounds 796.9 ms -> the next multiple of 10: 800 ms
    expect_ms = 800.0
    url = ("sim://?timing=virtual&baud=9600&stations=3:fuji-g1,4:fuji-pdp3,6:moeller,8:fuji-g1,"
           "9:moeller&set=3:F07=0.3,F08=0.3&set=8:F07=0.3,F08=0.3&set=6:F002=0.3,F003=0.3"
           "&set=9:F002=0.3,F003=0.3")
    from profidrive_cli.sim import plant
    bus = plant.build_bus(url)                     # the plant the command's port opens (the fixture)
    bus.log = []
    f = tmp_path / "line.yaml"
    f.write_text(LINE)
    report = tmp_path / "r.json"
    r = CliRunner().invoke(cli, ["checklist", "run", str(f), "--port", url, "--baud", "9600", "--yes",
                                 "--watchdog-ms", str(WATCHDOG_MS), "--report", str(report)])
    assert r.exit_code == 0, r.output
    assert list(sim.values()) == [bus]
    wds = _set_prm_watchdogs(bus.log)
    assert wds == dict.fromkeys([3, 4, 6, 8, 9], {expect_ms}), wds
    import json
    doc = json.loads(report.read_text())
    for st in doc["stations"]:
        assert any(f"watchdog raised from {WATCHDOG_MS} ms to {expect_ms:g} ms" in w
                   for w in st["identity"].get("warnings", [])), st["identity"]
    assert all(s.stats["watchdog_expired"] == 0 for s in bus.slaves.values())


def test_the_cycle_of_a_station_not_kept_lets_the_kept_ones_have_their_keep_alive():
    """Master.exchange of a station in data exchange that is not kept (issue 38: exchange() takes
    the fast path itself, as step() decides): a kept station that is due gets its keep-alive
    first, so over 2 s (four watchdogs) of cycles of station 4 alone, station 3 never goes a
    watchdog without a Data_Exchange."""
    m = _master()
    bus = m.link.bus
    bus.log = []
    cfgs = _configs(m)
    for a in (3, 4):
        m.add_station(a, cfgs[a])
        m.bring_up(a)
    m.keep(3)
    end = m.link.now() + 4 * WATCHDOG_MS / 1000.0
    while m.link.now() < end:
        m.exchange(4)
    m.exchange(3)
    spans = no_dx_spans(bus.log, 9600)
    assert spans[3] < WATCHDOG_MS / 1000.0, spans
    assert m.stations[3].counters.reparams == 0 and m.stations[3].in_data_exchange
