"""dp/dx_fast.py: what the fast path tells its listeners and its poller, and how long it sleeps on a
link without µs timing, compared with the general engine (Master.fast_dx = False) and with the
reference's times (§1.1 / §4: 11 bit per character, min TSDR 11 bit, TSL 100 bit at 19.2k).
Short in-process runs on the virtual-clock simulator. Written for mutation testing
(tools/mutation/run.py dp/dx_fast.py).
"""

import logging

import pytest

from profidrive_cli.dp.poller import Master
from profidrive_cli.dp.station import SlaveConfig
from profidrive_cli.fdl.timing import BusParams
from profidrive_cli.link import open_link
from profidrive_cli.sim.faults import FaultPlan

BAUD = 19200


def bus(fast=True, timing="virtual", slot_time=None):
    link = open_link(f"sim://?stations=3:fuji-g1&baud={BAUD}&timing={timing}", BAUD)
    m = Master(link, BusParams.for_baud(BAUD, retries=1, slot_time=slot_time))
    m.fast_dx = fast
    m.add_station(3, SlaveConfig(ident=link.bus.slave(3).model.ident, cfg=bytes.fromhex("F3F1"),
                                 wd_ms=500))
    m.bring_up(3)
    return m


def events(fast):
    m = bus(fast)
    got = []
    m.on_event = lambda a, e: got.append((a, e.kind, e.text, e.data))
    sent = [m.poll() for _ in range(5)]
    m.link.close()
    return got, sent


def test_the_fast_path_tells_listeners_what_the_general_path_tells():
    fast, sent = events(True)
    slow, _ = events(False)
    assert fast == slow
    assert [k for _, k, _, _ in fast] == ["inputs"] * 5
    assert all(a == 3 and t == "" and isinstance(d, bytes) and len(d) == 12 for a, _, t, d in fast)
    assert sent == [1] * 5                  # poll(): one request sent per station and pass


def test_a_retry_on_the_fast_path_is_logged_with_the_station(caplog):
    m = bus(True)
    m.link.bus.faults = FaultPlan({"drop": 1.0}, seed=1)     # every reply lost
    with caplog.at_level(logging.INFO, logger="profidrive_cli"):
        m.poll()
    m.link.close()
    assert "station 3: retry (no valid reply in time)" in caplog.messages
    assert "station 3: no valid reply after 1 retry" in caplog.messages


@pytest.mark.parametrize("slot_time,reply_sleep", [
    (None, 331),      # TSL 100: request 231 + 100 = 331 bit < 473: the deadline bounds it
    (1000, 473),      # TSL 1000: the whole reply (473 bit) is there before the deadline (1231)
])
def test_one_sleep_for_the_whole_reply_on_a_link_without_us_timing(slot_time, reply_sleep):
    m = bus(True, slot_time=slot_time)
    link = m.link
    link.us_timing = False                 # as a pty or a USB adapter
    slept = []
    real = link.sleep

    def sleep(s):
        slept.append(s)
        real(s)
    link.sleep = sleep
    assert m.poll() == 1
    link.close()
    # first the idle time after the last reply (TID1 = 37 bit), then one sleep for the reply:
    # request 21 octets (231 bit) + min TSDR 11 + reply 21 octets (231 bit) = 473 bit, but not
    # past the reply deadline (request + TSL after the write)
    assert len(slept) >= 2
    assert abs(slept[0] * BAUD - 37) < 1e-6 and abs(slept[1] * BAUD - reply_sleep) < 1e-6


def test_a_link_lost_during_a_fast_exchange_names_the_cause_and_the_port():
    from profidrive_cli.link.base import LinkLost
    m = bus(True)

    def gone(data):
        raise LinkLost("the adapter was unplugged", port="/dev/ttyUSB7")
    m.link.write = gone
    with pytest.raises(LinkLost) as e:
        m.poll()
    assert str(e.value).startswith("link lost: the adapter was unplugged (counters: station 3: ")
    assert e.value.port == "/dev/ttyUSB7" and 3 in e.value.counters
    assert not m.fdl.busy
