"""No phantom stations (issue 26): a lone noise octet 0xE5 reads as a short acknowledgement (SC, the
single octet 0xE5: fdl/frames.py SC) and must not make `scan` list a station.

Fault injection: sim://?phantom=R (sim/faults.py) puts a lone 0xE5 in the reply slot of a request to
an address where no station is. A station is listed only when its answer is a valid telegram, or an
SC that a second probe confirms (and, as an SC carries no address, a Slave_Diag answered with a
valid telegram: dp/scan.py).
"""

import json
import subprocess
import sys

import pytest

from profidrive_cli import UsageError
from profidrive_cli.dp import scan as scan_mod
from profidrive_cli.dp.poller import Master
from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.timing import BusParams
from profidrive_cli.link import open_link
from profidrive_cli.sim.plant import build_bus


def _master(url, baud=19200):
    return Master(open_link(url, baud), BusParams.for_baud(baud, retries=1))


def _run(*args):
    p = subprocess.run([sys.executable, "-m", "profidrive_cli", *args], capture_output=True,
                       text=True, stdin=subprocess.DEVNULL, timeout=120)
    return p.returncode, p.stdout, p.stderr


def test_phantom_is_a_lone_e5_where_nobody_is():
    bus = build_bus("sim://?stations=3:fuji-g1&phantom=1")
    to9 = F.encode(F.make(9, 2, F.request_fc(F.FDL_STATUS)))
    replies = bus.receive(to9, 0.0)
    assert [r.octets for r in replies] == [b"\xE5"]           # SC (reference: SC = 0xE5)
    assert bus.faults.counts["phantom"] == 1
    # a station that is there answers itself: no phantom on top of its reply
    to3 = F.encode(F.make(3, 2, F.request_fc(F.FDL_STATUS)))
    replies = bus.receive(to3, 1.0)
    assert len(replies) == 1 and replies[0].octets[0] == F.SD1
    assert bus.faults.counts["phantom"] == 1


def test_bad_phantom_rate_is_a_usage_error():
    with pytest.raises(UsageError) as e:
        build_bus("sim://?phantom=x")
    assert "phantom" in str(e.value)
    code, out, err = _run("scan", "--port", "sim://?phantom=2")
    assert code == 2 and out == "" and "phantom" in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("quick", [True, False])
def test_one_lone_e5_per_empty_address_lists_nothing(quick):
    """Each empty address answers its first probe with a lone 0xE5 (one-shot injections): before,
    every one of them was listed as a slave."""
    m = _master("sim://?stations=3:fuji-g1&only=0")      # faults on, none by rate
    plan = m.link.ser.bus.faults
    for a in range(0, 127):
        if a not in (2, 3):
            plan.inject_next(a, "phantom")
    found = scan_mod.scan(m, 0, 126, quick=quick)
    assert [e.address for e in found] == [3]
    assert plan.counts["phantom"] == 127 - 2
    m.link.close()


@pytest.mark.parametrize("rate", ["0.3", "1"])
def test_a_noisy_line_lists_only_the_stations_that_are_there(rate):
    """Random lone 0xE5 in the empty slots, up to every one of them (rate 1: each probe and each
    Slave_Diag to an empty address is 'answered' by an SC): the scan lists 3 and 6, nothing else."""
    m = _master(f"sim://?stations=3:fuji-g1,6:moeller&phantom={rate}&seed=7")
    found = scan_mod.scan(m, 0, 126)
    assert [e.address for e in found] == [3, 6]
    assert all(e.diag is not None for e in found)
    assert m.link.ser.bus.faults.counts["phantom"] > 0
    m.link.close()


def test_scan_command_on_a_noisy_line():
    code, out, err = _run("scan", "--json", "--port", "sim://?stations=5:toyo&phantom=0.5")
    assert code == 0, err
    assert [s["station"] for s in json.loads(out)["stations"]] == [5]


def test_a_real_sc_confirmed_twice_is_still_a_station():
    """A station that answers FDL status with SC (and Slave_Diag with a valid telegram) is listed:
    the second probe confirms the SC."""
    class ScMaster:
        address = 2

        def __init__(self):
            self.calls = 0
            import dataclasses

            @dataclasses.dataclass
            class P:
                retries: int = 1
            self.params = P()

            class C:
                illegal = 0
            self.fdl = type("Fdl", (), {"counters_for": lambda _s, a: C()})()

        def fdl_status(self, a):
            self.calls += 1
            return F.Frame(F.SC) if a == 4 else None

    m = ScMaster()
    assert scan_mod.probe(m, 4) is not None and m.calls == 2      # the SC, then its confirmation
    m.calls = 0
    assert scan_mod.probe(m, 5) is None and m.calls == 1
