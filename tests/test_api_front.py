"""The API as the front door of the tools (issue 25 step 7): the master built in one place
(api.bus.make_master: open_bus and the CLI's BusOptions), and Bus.session, the station at the session
level the CLI's drive commands and the checklist stand on. On the virtual-time simulator."""

from __future__ import annotations

import pytest

import profidrive_cli as pdrive
from profidrive_cli import UsageError
from profidrive_cli.api import Bus, make_master
from profidrive_cli.link import open_link
from profidrive_cli.session import DriveStation

SIM = "sim://?timing=virtual"

#: the tests must not see the developer's own config files or PDRIVE_* settings
pytestmark = pytest.mark.usefixtures("no_config_at_all")


# -- make_master: the one place the master is built ---------------------------------------------------

def test_the_master_of_the_simulator_and_of_a_real_port_gets_the_documented_defaults():
    # `pdrive --help` of every bus command (cli/common.py bus_options, --retries): "default 2 on real
    # ports, 1 on sim://"; the reply timeout is widened for USB/OS latency on a real port only
    # (reference §4.3), never on the instant simulator
    m = make_master(open_link("sim://"), 19200, 2)
    try:
        assert m.params.retries == 1 and m.params.link_latency == 0.0 and m.address == 2
    finally:
        m.link.close()
    m = make_master(open_link("loop://"), 19200, 1)
    try:
        assert m.params.retries == 2 and m.params.link_latency > 0.0 and m.address == 1
    finally:
        m.link.close()
    m = make_master(open_link("loop://"), 19200, 2, retries=0, slot_time=1000)
    try:
        assert m.params.retries == 0 and m.params.tsl == 1000
    finally:
        m.link.close()


def test_a_bad_bus_parameter_is_a_usage_error_and_the_port_is_closed():
    link = open_link("loop://")
    with pytest.raises(UsageError, match="slot time 1 outside"):
        make_master(link, 19200, 2, slot_time=1)
    assert not link.ser.is_open
    link = open_link("loop://")
    with pytest.raises(UsageError, match="master address 126 outside 0..125"):
        make_master(link, 19200, 126)
    assert not link.ser.is_open


def test_open_bus_and_the_cli_build_the_same_master():
    from profidrive_cli.cli.common import BusOptions
    with pdrive.open_bus(SIM, baud=187500, master_address=1, retries=3) as bus:
        api_params = bus.master.params
    m = BusOptions(SIM, "187500", 1, None, 3, False, False, 0, False).open_master()
    try:
        assert m.params == api_params and m.address == 1
    finally:
        m.link.close()


# -- Bus.session ---------------------------------------------------------------------------------------

def test_a_session_from_the_bus_opens_the_station_and_leaves_the_port_to_the_bus():
    with pdrive.open_bus(SIM) as bus:
        s = bus.station(3, profile="fuji-g1", watchdog_ms=300)
        assert isinstance(s, DriveStation) and s.drive is None          # not opened yet
        with s:
            assert s.address == 3 and s.profile.name == "fuji-opc-g1-pdp" and s.watchdog_ms == 300
            assert s.motion.status().status.state
        assert s.motion.stop_report is not None and s.motion.stop_report.how == "not needed"
        assert not bus.closed and bus.master.link.ser.is_open          # the port stays the bus's
        assert [st.station for st in bus.scan(3, 3)] == [3]             # and the bus still works
        link = bus.master.link
    assert not link.ser.is_open


def test_a_session_that_owns_the_port_closes_it_and_the_bus_is_done():
    bus = pdrive.open_bus(SIM)
    link = bus.master.link
    s = bus.station(3, own_port=True)
    assert bus.closed
    with pytest.raises(UsageError, match="closed"):
        bus.scan()
    assert link.ser.is_open
    with s:
        assert s.address == 3
    assert not link.ser.is_open


def test_a_bad_session_request_is_one_usage_error():
    with pdrive.open_bus(SIM) as bus:
        with pytest.raises(UsageError, match="station 126 is not a bus address 0..125"):
            bus.station(126)
        with pytest.raises(UsageError, match="watchdog 5 ms outside 10..650000 ms"):
            bus.station(3, watchdog_ms=5)
        assert not bus.closed                       # a refused request leaves the bus as it was
        bus.drive(3)
        with pytest.raises(UsageError, match="has drives open: own_port needs a bus of its own"):
            bus.station(4, own_port=True)
        assert not bus.closed and bus.master.link.ser.is_open
    # own_port and a refused request: the bus is closed with it (nothing is left open)
    bus = pdrive.open_bus(SIM)
    with pytest.raises(UsageError, match="watchdog"):
        bus.station(3, watchdog_ms=5, own_port=True)
    assert bus.closed and not bus.master.link.ser.is_open


def test_the_cli_bus_options_open_an_api_bus():
    from profidrive_cli.cli.common import BusOptions
    bus = BusOptions(SIM, "19200", 2, None, None, False, False, 0, False).open_bus()
    try:
        assert isinstance(bus, Bus) and bus.is_simulator and bus.master.address == 2
    finally:
        bus.close()
