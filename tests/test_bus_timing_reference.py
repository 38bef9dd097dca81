"""Bus timing pinned to the reference's own numbers, not to fdl/timing.py.

The master, the wire-timed simulator and the session's rate limit all compute their times with
fdl/timing.py; tests that derive their expected values from it cannot see a wrong constant there.
Every expected value below is typed in from /work/shared/spec/profibus-dp-reference.md:

  §1   one character = 11 bit times (8E1)
  §2   SD2 frame = LE + 6 octets, LE = DA SA FC + DU (no SAP octets for Data_Exchange)
  §4.1 per baud: TSL, min/max TSDR, TID1 = 35 + 2·TSET + TQUI, TID2 = max TSDR (the table's values)
  §4.2 message cycle: request octets × 11 + TSDR + reply octets × 11 + TID1
  §6.1 PPO1 = 12 octets each way, PPO3 = 4

Worked by hand:
  PPO1: 12 + 3 = LE 15 -> 21 octets each way; at TSDR 11 (the simulated station answers after
        min TSDR): 21·11 + 11 + 21·11 + 37 = 510 bit -> 19200 / 510 = 37.647 cycles/s at 19.2k
        (docs/commands.md: "37.6/s for PPO1"); at 12M TID1 = 76: 549 bit -> 21 857.9/s
  PPO3: 4 + 3 = LE 7 -> 13 octets; 13·11 + 11 + 13·11 + 37 = 334 bit -> 57.485/s at 19.2k
"""

import pytest

from profidrive_cli.dp.poller import Master
from profidrive_cli.dp.station import SlaveConfig
from profidrive_cli.fdl.timing import BusParams
from profidrive_cli.link import open_link

# §4.1: baud -> (TSL, min TSDR, max TSDR, TID1, TID2), bit times
TABLE_4_1 = {
    9600: (100, 11, 60, 37, 60), 19200: (100, 11, 60, 37, 60), 45450: (100, 11, 60, 37, 60),
    93750: (100, 11, 60, 37, 60), 187500: (100, 11, 60, 37, 60), 500000: (200, 11, 100, 37, 100),
    1500000: (300, 11, 150, 37, 150), 3000000: (400, 11, 250, 46, 250),
    6000000: (600, 11, 450, 57, 450), 12000000: (1000, 11, 800, 76, 800),
}


@pytest.mark.parametrize("baud", sorted(TABLE_4_1))
def test_default_timing_parameters_are_the_reference_table(baud):
    p = BusParams.for_baud(baud)
    assert (p.tsl, p.min_tsdr, p.max_tsdr, p.tid1, p.tid2) == TABLE_4_1[baud]
    assert p.tid1_seconds == pytest.approx(TABLE_4_1[baud][3] / baud, rel=1e-12)
    assert p.chars(1) == pytest.approx(11 / baud, rel=1e-12)          # §1.1: 8E1, 11 bit


def _bus_with_one_station(baud, cfg):
    link = open_link(f"sim://?stations=3:fuji-g1&baud={baud}&timing=virtual", baud)
    m = Master(link, BusParams.for_baud(baud))
    m.add_station(3, SlaveConfig(ident=link.bus.slave(3).model.ident, cfg=cfg))
    m.bring_up(3)
    return m


# (baud, Chk_Cfg, octets of each SD2 frame, TID1 bit, cycles per second by hand)
CYCLES = [
    (19200, "F3F1", 21, 37, 19200 / 510),          # PPO1: 37.647/s
    (9600, "F3F1", 21, 37, 9600 / 510),            # 18.824/s
    (19200, "F1", 13, 37, 19200 / 334),            # PPO3: 57.485/s
    (3000000, "F3F1", 21, 46, 3000000 / 519),      # TID1 46 at 3M
    (12000000, "F3F1", 21, 76, 12000000 / 549),    # TID1 76 at 12M: 21 857.9/s
]


@pytest.mark.parametrize("baud,cfg,octets,tid1,rate", CYCLES)
def test_data_exchange_cycle_rate_and_idle_times_match_the_reference(baud, cfg, octets, tid1, rate):
    m = _bus_with_one_station(baud, bytes.fromhex(cfg))
    bus = m.link.bus
    n = 40
    bus.log = []
    t0 = m.link.now()
    for _ in range(n):
        assert m.poll() == 1
    took = m.link.now() - t0
    assert n / took == pytest.approx(rate, rel=1e-6)
    # the wire, telegram by telegram: request, TSDR 11, reply, TID1 idle, next request
    log = bus.log
    assert [w for _, w, _ in log] == ["M", "S"] * n
    for i in range(0, 2 * n - 2, 2):
        (tm, _, req), (ts, _, rep), (tn, _, _) = log[i], log[i + 1], log[i + 2]
        assert len(req) == octets and len(rep) == octets
        assert (ts - tm) * baud == pytest.approx(octets * 11 + 11, abs=1e-6)        # request + TSDR
        assert (tn - ts) * baud == pytest.approx(octets * 11 + tid1, abs=1e-6)      # reply + TID1
    m.link.close()


def test_session_knows_the_documented_ppo1_rate_at_19200():
    """The default cycle rate a session picks (`pdrive run`'s "bus limit"): 37.6/s for PPO1 at
    19.2k (docs/commands.md), 57.5/s for PPO3."""
    from profidrive_cli.session import wire_limit_hz
    assert wire_limit_hz(19200, 12, 12) == pytest.approx(37.647, abs=0.001)
    assert wire_limit_hz(19200, 4, 4) == pytest.approx(57.485, abs=0.001)
    assert wire_limit_hz(12000000, 12, 12) == pytest.approx(21857.9, abs=0.1)
