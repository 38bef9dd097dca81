"""The first-contact rule of a Siemens CBP2 drive board in the simulator (issue 26), and pdrive's master
against it.

The rule, from kolod/profibus (profibus_debug/diagnostics.py, read_diagnostics: "first request to a slave
must have FCB=1, FCV=0 ... FCV=1 on first contact is rejected by CBP2 because the slave has no prior FCB
record for this master. FCV=0 + FCB=0 is also rejected"; its warm-up FDL status probes are answered):
`sim://?firstcontact=3` makes station 3 ignore (no answer at all) an SRD/SDA from a master it keeps no
frame count for unless that request starts a sequence, FCV=0 with FCB=1.

The standard (../shared/spec/profibus-dp-reference.md §2.3, "FCB/FCV rules"):
  rule 1: "First SRD/SDA to a station after (re)start: FCV = 0, FCB = 1 (e.g. Slave_Diag FC 0x6D)."
  rule 4: "FDL-status requests and SDN (broadcast) telegrams carry FCV = 0, FCB = 0 (FC 0x49, 0x46)."
So a master that keeps the standard meets the CBP2's rule; these tests show pdrive's does (fdl/fcb.py
MasterFcb, fdl/master.py), and that the simulated rule has teeth: a master opening with FCV=1 fails.
"""

import json
import subprocess
import sys

import pytest

from profidrive_cli import BusError, UsageError
from profidrive_cli.dp import scan as scan_mod
from profidrive_cli.dp import services as S
from profidrive_cli.dp.poller import Master
from profidrive_cli.dp.station import SlaveConfig
from profidrive_cli.fdl import fcb as fcb_mod
from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.timing import BusParams
from profidrive_cli.link import open_link
from profidrive_cli.sim.plant import build_bus

# FC octets of reference §2.2 (bit 6 request, bit 5 FCB, bit 4 FCV, bits 3..0 function 13 = SRD high)
SRD_START = 0x6D        # FCV=0, FCB=1: rule 1's "Slave_Diag FC 0x6D"
SRD_FCV_FCB0 = 0x5D     # FCV=1, FCB=0 (rule 2's 0x5D)
SRD_FCV_FCB1 = 0x7D     # FCV=1, FCB=1 (rule 2's 0x7D)
SRD_NO_COUNT = 0x4D     # FCV=0, FCB=0
FDL_STATUS = 0x49       # rule 4
MASTER = 2
# Fuji OPC-G1-PDP, the default plant's station 3: ident 0xFD01 (docs/architecture.md's family table),
# PPO1 Chk_Cfg F3 F1
FUJI = SlaveConfig(ident=0xFD01, cfg=bytes.fromhex("F3F1"), wd_ms=200)


def _diag_request(fc, da=3, sa=MASTER):
    return F.encode(F.Frame(F.SD2, da, sa, fc, b"", S.SAP_SLAVE_DIAG, S.SAP_MASTER))


def _answers(bus, octets, t=0.0):
    return [r.octets for r in bus.receive(octets, t)]


def _master(url, retries=1):
    return Master(open_link(url, 19200), BusParams.for_baud(19200, retries=retries))


def _run(*args):
    p = subprocess.run([sys.executable, "-m", "profidrive_cli", *args], capture_output=True,
                       text=True, stdin=subprocess.DEVNULL, timeout=120)
    return p.returncode, p.stdout, p.stderr


# -- the simulated rule ------------------------------------------------------------------------------

@pytest.mark.parametrize("fc", [SRD_FCV_FCB0, SRD_FCV_FCB1, SRD_NO_COUNT])
def test_a_cbp2_ignores_a_first_srd_that_does_not_start_a_sequence(fc):
    bus = build_bus("sim://?stations=3:fuji-g1&firstcontact=3")
    assert _answers(bus, _diag_request(fc)) == []
    assert bus.slave(3).stats["ignored_first_contact"] == 1
    assert bus.slave(3).stats["requests"] == 0              # not executed


@pytest.mark.parametrize("fc", [SRD_FCV_FCB0, SRD_FCV_FCB1, SRD_NO_COUNT])
def test_a_standard_station_answers_the_same_first_srd(fc):
    """The contrast: without the option the station answers any first SRD (the simulator as before)."""
    bus = build_bus("sim://?stations=3:fuji-g1")
    assert len(_answers(bus, _diag_request(fc))) == 1


def test_after_fcv0_fcb1_the_cbp2_counts_frames_and_answers():
    bus = build_bus("sim://?stations=3:fuji-g1&firstcontact=3")
    (first,) = _answers(bus, _diag_request(SRD_START))
    d = S.SlaveDiag.decode(F.parse(first)[0].data)
    assert d.ident == 0xFD01 and d.has("Prm_Req")
    # rule 2: then FCV=1 with the FCB toggled: a new request, answered
    assert len(_answers(bus, _diag_request(SRD_FCV_FCB0), 0.1)) == 1
    # another master (address 1) has no frame count there: its FCV=1 is ignored, its start is not
    assert _answers(bus, _diag_request(SRD_FCV_FCB1, sa=1), 0.2) == []
    assert len(_answers(bus, _diag_request(SRD_START, sa=1), 0.3)) == 1


def test_the_cbp2_answers_fdl_status_as_kolod_profibus_warm_up_saw():
    bus = build_bus("sim://?stations=3:fuji-g1&firstcontact=3")
    req = F.encode(F.Frame(F.SD1, 3, MASTER, F.request_fc(F.FDL_STATUS)))
    assert req[3] == FDL_STATUS
    (reply,) = _answers(bus, req)
    assert F.parse(reply)[0].sa == 3


def test_a_power_cycle_forgets_the_frame_count():
    bus = build_bus("sim://?stations=3:fuji-g1&firstcontact=3")
    assert len(_answers(bus, _diag_request(SRD_START))) == 1
    bus.slave(3).power_cycle(0.1)
    assert _answers(bus, _diag_request(SRD_FCV_FCB0), 0.2) == []


# -- the URL option ----------------------------------------------------------------------------------

def test_firstcontact_url_sets_each_station_and_may_repeat():
    bus = build_bus("sim://?firstcontact=3,5&firstcontact=7")
    assert {a: s.first_contact for a, s in bus.slaves.items()} == {3: True, 4: False, 5: True,
                                                                  6: False, 7: True}


@pytest.mark.parametrize("url", ["sim://?firstcontact=", "sim://?firstcontact=x",
                                 "sim://?firstcontact=3,200", "sim://?firstcontact=9",
                                 "sim://?firstcontact=3:4"])
def test_bad_firstcontact_is_a_usage_error_naming_the_option(url):
    with pytest.raises(UsageError) as e:
        build_bus(url)
    assert "firstcontact=" in str(e.value)


def test_bad_firstcontact_on_the_command_line_is_one_line_exit_2():
    code, out, err = _run("scan", "--port", "sim://?firstcontact=3,x")
    assert code == 2 and out == ""
    lines = [x for x in err.splitlines() if x.strip()]
    assert len(lines) == 1 and "firstcontact=3,x" in lines[0] and "Traceback" not in err


# -- pdrive's master meets it ------------------------------------------------------------------------

def test_every_first_srd_of_a_scan_and_a_bring_up_starts_a_sequence():
    """Rule 1 on the wire: the first SRD the master sends to each station is FC 0x6D; FDL status
    carries 0x49 (rule 4)."""
    m = _master("sim://?firstcontact=3,4,5,6,7")
    bus = m.link.bus
    bus.log = []
    found = scan_mod.scan(m, 0, 126, read_cfg=True)
    assert [e.address for e in found] == [3, 4, 5, 6, 7]
    assert all(e.diag is not None and e.cfg for e in found)
    m.add_station(3, FUJI)
    m.bring_up(3)
    first_srd, fdl_status = {}, set()
    for _, who, octets in bus.log:
        if who != "M":
            continue
        f = F.parse(octets)[0]
        if f.function == F.FDL_STATUS:
            fdl_status.add(f.fc)
        elif f.function in (F.SRD_LOW, F.SRD_HIGH, F.SDA_LOW, F.SDA_HIGH):
            first_srd.setdefault(f.da, f.fc)
    assert first_srd == {3: SRD_START, 4: SRD_START, 5: SRD_START, 6: SRD_START, 7: SRD_START}
    assert fdl_status == {FDL_STATUS}
    assert sum(s.stats["ignored_first_contact"] for s in bus.slaves.values()) == 0
    m.link.close()


def test_a_master_opening_with_fcv1_cannot_bring_a_cbp2_up(monkeypatch):
    """The rule has teeth: a master that sends FCV=1 in its first SRD (as if MasterFcb started
    'started') gets no answer from the CBP2, while a standard station takes it."""
    def started_fcb(self):
        self._started, self._fcb = True, True
    monkeypatch.setattr(fcb_mod.MasterFcb, "reset", started_fcb)
    m = _master("sim://?stations=3:fuji-g1&firstcontact=3", retries=0)
    assert m.slave_diag(3) is None
    m.link.close()
    m = _master("sim://?stations=3:fuji-g1", retries=0)
    assert m.slave_diag(3) is not None
    m.link.close()


def test_the_master_brings_up_a_cbp2_in_baud_search():
    """A CBP2 as kolod/profibus met it: still searching the rate (warm-up) and strict on first
    contact. Slave_Diag with wake (dp/poller.py) then the start-up reach data exchange."""
    m = _master("sim://?stations=3:fuji-g1&firstcontact=3&warmup=3:4")
    assert m.slave_diag(3, wake=True) is not None
    m.add_station(3, FUJI)
    m.bring_up(3)
    assert m.stations[3].in_data_exchange and len(m.exchange(3, bytes(12))) == 12
    assert m.link.bus.slave(3).stats["ignored_first_contact"] == 0
    m.link.close()


def test_after_a_power_cycle_the_master_restarts_its_frame_count_and_recovers():
    """In data exchange the master's Data_Exchange carries FCV=1; after a power cycle the CBP2 keeps
    no frame count and ignores it. The master's failed transaction restarts the sequence (reference
    §2.3 rule 1 after (re)start; fdl/fcb.py MasterFcb.failed), so the next request is FCV=0/FCB=1,
    answered RS, and the start-up runs again: one unanswered request (with its retry), no more."""
    m = _master("sim://?stations=3:fuji-g1&firstcontact=3", retries=1)
    m.add_station(3, FUJI)
    m.bring_up(3)
    slave = m.link.bus.slave(3)
    slave.power_cycle(m.link.now())
    for _ in range(20):
        m.exchange(3, bytes(12))
        if slave.stats["power_cycles"] and m.stations[3].in_data_exchange and slave.state == "Data_Exch":
            break
    assert m.stations[3].in_data_exchange
    c = m.fdl.counters[3]
    assert (c.no_answer, c.rs, c.reparams) == (1, 1, 1)
    assert slave.stats["ignored_first_contact"] == 2          # the request and its one retry
    m.link.close()


def test_status_and_scan_on_a_cbp2_plant():
    code, out, err = _run("status", "3", "--port", "sim://?firstcontact=3&warmup=3:4")
    assert code == 0, err
    assert "station 3: fuji-opc-g1-pdp" in out
    code, out, err = _run("scan", "--json", "--port", "sim://?firstcontact=3,4,5,6,7")
    assert code == 0, err
    doc = json.loads(out)
    assert [s["station"] for s in doc["stations"]] == [3, 4, 5, 6, 7]
    assert all(s["diag"] is not None for s in doc["stations"])


def test_a_bad_master_fails_where_it_is_said_to(monkeypatch):
    """bring_up of a CBP2 with a master whose first SRD has FCV=1 ends in 'no answer' (BusError)."""
    def started_fcb(self):
        self._started, self._fcb = True, True
    monkeypatch.setattr(fcb_mod.MasterFcb, "reset", started_fcb)
    m = _master("sim://?stations=3:fuji-g1&firstcontact=3", retries=0)
    m.add_station(3, FUJI)
    with pytest.raises(BusError, match="no answer"):
        m.bring_up(3, timeout=0.3)
    m.link.close()
