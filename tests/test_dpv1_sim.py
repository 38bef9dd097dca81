"""The simulator's DP-V1 side: SAP 51 in sim/slave.py and the DS47 axis of sim/dpv1_axis.py
(profiles/profidrive-dpv1.yaml), driven with hand-built telegrams.

Expected octets come from published examples or are calculated by hand here, never from the code
under test:
  * Toshiba E6581738 (PDP003Z, DP-V1) 6.2 "Example 2. Change the PROFIdrive parameter": the Write
    DS47 request 5F 00 2F 0E 01 02 01 01 10 01 03 9F 00 00 06 01 00 00 (set PNU 927 to 0), the
    positive Read response 5E 00 2F 04 01 02 01 01, the negative one (set 2 to PNU 927) of length 8
    with format 0x44 and error 0x0002 (low or high limit exceeded);
  * the PROFIdrive error numbers (ABB FPBA-01 / SINAMICS tables: 0x00 impermissible PNU, 0x01 cannot
    be changed, 0x02 limits, 0x03 subindex, 0x04 no array, 0x0B no operation priority, 0x11 operating
    state, 0x16 parameter address, 0x17 format, 0x18 number of values, 0x19 axis) and the DP-V1
    error codes (80 B0 invalid index, 80 B2 invalid slot, 80 B5 state conflict, 80 B8 invalid
    parameter);
  * the values of profiles/profidrive-dpv1.yaml (PNU 964: 42, 0x8158, 300, 2007, 1707, 1; P100
    50.00 Hz at 0.01 -> 5000; ...), encoded by hand below.
"""

from __future__ import annotations

import pytest

from profidrive_cli.dp import services as S
from profidrive_cli.drives.profile import load_profile
from profidrive_cli.drives.registry import FAMILIES
from profidrive_cli.fdl import frames as F
from profidrive_cli.sim.dpv1_axis import Dpv1AxisModel, make_model
from profidrive_cli.sim.plant import build_bus
from profidrive_cli.sim.slave import DATA_EXCH, SimSlave

ADDR = 9
MASTER = 2
IDENT = 0x8158
TEL1 = bytes.fromhex("E1 D1")            # SI028158.gsd: Module="Standard telegram 1" 0xE1, 0xD1
DPV1_ON = bytes.fromhex("80 00 00")      # DPV1_Status_1..3: DPV1_Enable (bit 7 of the first)
SC = b"\xE5"

#: the Toshiba example: Write DS47, change PNU 927 (0x039F) to 0
TOSHIBA_WRITE = bytes.fromhex("5F 00 2F 0E 01 02 01 01 10 01 03 9F 00 00 06 01 00 00")


def hx(s: str) -> bytes:
    return bytes.fromhex(s)


@pytest.fixture(scope="module")
def profile():
    return load_profile("profidrive-dpv1")


class Master:
    """Drives one SimSlave with hand-built SRD telegrams, the frame count bit as a master keeps it."""

    def __init__(self, slave: SimSlave):
        self.s = slave
        self.fcb = True
        self.started = False
        self.now = 0.0

    def srd(self, dsap: int | None, data: bytes = b"", ssap: int = S.SAP_MASTER,
            at: float | None = None) -> bytes:
        """The raw reply octets to one SRD (high priority), sent at `at` (default: the clock as it
        stands)."""
        if at is not None:
            self.now = at
        if self.started:
            self.fcb = not self.fcb
        fc = F.request_fc(F.SRD_HIGH, fcb=self.fcb, fcv=self.started)
        self.started = True
        frame = F.Frame(F.SD2, self.s.address, MASTER, fc, data, dsap, None if dsap is None else ssap)
        raw = self.s.handle(F.parse(F.encode(frame))[0], self.now)
        assert raw is not None
        return raw

    def c1(self, du: bytes, at: float | None = None) -> bytes:
        """An SRD to DSAP 51 from SSAP 51: the raw reply."""
        return self.srd(51, du, ssap=51, at=at)

    def poll(self, at: float | None = None) -> bytes:
        return self.c1(b"", at=at)

    def answer(self, du: bytes, at: float, poll_at: float) -> bytes:
        """Request `du` at `at`, poll at `poll_at`: the DU of the answer (asserting the request
        was acknowledged with SC and the answer came with DL from SAP 51 to SAP 51)."""
        assert self.c1(du, at=at) == SC
        raw = self.poll(at=poll_at)
        reply = F.parse(raw)[0]
        assert reply.sd == F.SD2 and reply.fc & 0x0F == F.DL, raw.hex(" ")
        assert (reply.dsap, reply.ssap) == (51, 51)
        return bytes(reply.data)

    def start(self, user_prm: bytes = DPV1_ON, at: float = 0.0) -> None:
        self.now = at
        assert self.srd(S.SAP_SET_PRM, S.SetPrm(IDENT, 1000, user_prm=user_prm).encode()) == SC
        assert self.srd(S.SAP_CHK_CFG, TEL1) == SC
        assert self.s.state == DATA_EXCH

    def exchange(self, stw: int, nsoll: int, at: float) -> bytes:
        self.now = at
        raw = self.srd(None, stw.to_bytes(2, "big") + nsoll.to_bytes(2, "big"))
        return bytes(F.parse(raw)[0].data)


def rig(profile, **options) -> tuple[Dpv1AxisModel, SimSlave, Master]:
    model = make_model(profile, address=ADDR, **options)
    slave = SimSlave(ADDR, model)
    m = Master(slave)
    m.start()
    return model, slave, m


def write_ds47(request: bytes) -> bytes:
    """The Write DS47 PDU around a parameter request (slot 0, index 47 = 0x2F, its length)."""
    return bytes((0x5F, 0x00, 0x2F, len(request))) + request


READ_DS47 = hx("5E 00 2F F0")             # Read DS47, slot 0, up to 240 octets


def ds47(m: Master, request: bytes, at: float) -> bytes:
    """Write the parameter request at `at`, then read its response: the Read response's DU."""
    assert m.answer(write_ds47(request), at, at + 0.003) == write_ds47(request)[:4]
    return m.answer(READ_DS47, at + 0.004, at + 0.007)


# -- SAP 51 enabled only with DPV1_Enable, in data exchange, for a model with a C1 server ------------

def _is_rs(raw: bytes) -> bool:
    f = F.parse(raw)[0]
    return f.sd != F.SC and f.fc & 0x0F == F.RS


def test_without_dpv1_enable_sap_51_is_answered_rs(profile):
    slave = SimSlave(ADDR, make_model(profile, address=ADDR))
    m = Master(slave)
    m.start(user_prm=hx("00 00 00"))
    assert _is_rs(m.c1(TOSHIBA_WRITE))
    assert _is_rs(m.poll())
    m.start(user_prm=b"")                                   # no DPV1_Status octets at all
    assert _is_rs(m.c1(TOSHIBA_WRITE))


def test_with_dpv1_enable_only_in_data_exchange(profile):
    slave = SimSlave(ADDR, make_model(profile, address=ADDR))
    m = Master(slave)
    assert _is_rs(m.c1(TOSHIBA_WRITE))                      # Wait_Prm
    assert m.srd(S.SAP_SET_PRM, S.SetPrm(IDENT, 1000, user_prm=DPV1_ON).encode()) == SC
    assert _is_rs(m.c1(TOSHIBA_WRITE))                      # Wait_Cfg
    assert m.srd(S.SAP_CHK_CFG, TEL1) == SC
    assert m.c1(TOSHIBA_WRITE) == SC                        # data exchange: taken
    assert _is_rs(m.srd(51, TOSHIBA_WRITE, ssap=S.SAP_MASTER))    # not from SSAP 51


def test_a_dp_v0_profidrive_profile_has_no_c1_server(tmp_path):
    from profidrive_cli.drives.profile import load_profile_file
    f = tmp_path / "v0.yaml"
    f.write_text("profile: v0\nfamily: profidrive\ntitle: t\nidentity: {ident: 0x1234}\n"
                 "layouts:\n  ppo1: {cfg: \"F3 F1\", pkw: true}\ndefault_layout: ppo1\n")
    model = make_model(load_profile_file(f))
    assert model.c1_server is None
    slave = SimSlave(3, model)
    m = Master(slave)
    m.now = 0.0
    assert m.srd(S.SAP_SET_PRM, S.SetPrm(0x1234, 1000, user_prm=DPV1_ON).encode()) == SC
    assert m.srd(S.SAP_CHK_CFG, hx("F3 F1")) == SC
    assert _is_rs(m.c1(TOSHIBA_WRITE))


# -- the Toshiba example, octet for octet ------------------------------------------------------------

def test_toshiba_write_ds47_and_its_answers_octet_for_octet(profile):
    model, slave, m = rig(profile)
    assert m.c1(TOSHIBA_WRITE, at=0.010) == SC               # acknowledged at once
    assert m.poll(at=0.011) == SC                            # 1 ms later: not ready (2 ms)
    # the answer at 2 ms: SD2, DA 2 | 0x80, SA 9 | 0x80, FC 08 (DL), DSAP 51, SSAP 51, DU 5F 00 2F 0E;
    # LE = 3 + 2 + 4 = 9; FCS = 82+89+08+33+33+5F+00+2F+0E = 0x215 -> 0x15
    assert m.poll(at=0.0125) == hx("68 09 09 68 82 89 08 33 33 5F 00 2F 0E 15 16")
    assert m.poll(at=0.013) == SC                            # handed out once
    # Read DS47: Toshiba's positive response, header alone (length 4)
    assert m.answer(READ_DS47, 0.014, 0.017) == hx("5E 00 2F 04 01 02 01 01")
    assert model.edit_rights == 0
    # with PNU 927 = 0 the bus may change nothing else: 0x0B no operation priority
    # (ref 2, change, axis 1, 1 parameter; P102 = PNU 0x0066 to 500 = 0x01F4, Unsigned16)
    assert ds47(m, hx("02 02 01 01 10 01 00 66 00 00 06 01 01 F4"), 0.02) == \
        hx("5E 00 2F 08 02 82 01 01 44 01 00 0B")
    # Toshiba's negative example: set 2 to PNU 927 -> 0x44 Error, 1 value, 0x0002 (limits)
    assert ds47(m, hx("01 02 01 01 10 01 03 9F 00 00 06 01 00 02"), 0.03) == \
        hx("5E 00 2F 08 01 82 01 01 44 01 00 02")
    # and back to 1
    assert ds47(m, hx("03 02 01 01 10 01 03 9F 00 00 06 01 00 01"), 0.04) == \
        hx("5E 00 2F 04 03 02 01 01")
    assert model.edit_rights == 1


# -- reads ------------------------------------------------------------------------------------------

def test_pnu_964_device_identification_by_hand(profile):
    _, _, m = rig(profile)
    # ref 5, read, axis 1, 1 parameter: attribute 10, 6 elements, PNU 964 = 0x03C4, subindex 0
    got = ds47(m, hx("05 01 01 01 10 06 03 C4 00 00"), 0.01)
    # response: ref 05, 01 read ok, axis 01, 1 parameter; Unsigned16 (06), 6 values:
    # 42 = 002A, 0x8158, 300 = 012C, 2007 = 07D7, 1707 = 06AB, 1 = 0001; 4 + 2 + 12 = 18 = 0x12
    assert got == hx("5E 00 2F 12 05 01 01 01 06 06 00 2A 81 58 01 2C 07 D7 06 AB 00 01")


def test_reads_by_hand(profile):
    model, _, m = rig(profile)
    # PNU 918 (0x0396), the ABB example's request with 0 elements: the station address 9
    assert ds47(m, hx("09 01 01 01 10 00 03 96 00 00"), 0.01) == \
        hx("5E 00 2F 08 09 01 01 01 06 01 00 09")
    # PNU 965 (0x03C5): Word 03 29 (PROFIdrive 3, version 4.1)
    assert ds47(m, hx("0A 01 01 01 10 01 03 C5 00 00"), 0.02) == \
        hx("5E 00 2F 08 0A 01 01 01 42 01 03 29")
    # two parameters in one request: P100 (0x64) 50.00 Hz -> 5000 = 1388, P102 (0x66) 5.00 s -> 500
    assert ds47(m, hx("0B 01 01 02 10 01 00 64 00 00 10 01 00 66 00 00"), 0.03) == \
        hx("5E 00 2F 0C 0B 01 01 02 06 01 13 88 06 01 01 F4")
    # P110 (0x6E), 32 bits: 4.200 A at 0.001 -> 4200 = 00001068, Unsigned32
    assert ds47(m, hx("0C 01 01 01 10 01 00 6E 00 00"), 0.04) == \
        hx("5E 00 2F 0A 0C 01 01 01 07 01 00 00 10 68")
    # a tripped drive's fault number at PNU 947 (0x03B3) subindex 0: OC = 1
    model.trip("OC", 0.05)
    assert ds47(m, hx("0D 01 01 01 10 01 03 B3 00 00"), 0.05) == \
        hx("5E 00 2F 08 0D 01 01 01 06 01 00 01")


def test_signed_values_travel_as_integer16(profile):
    model, _, m = rig(profile)
    # P105 (0x69) frequency trim -2.50 Hz at 0.01 -> -250 = FF06, Integer16 (03)
    assert ds47(m, hx("0E 02 01 01 10 01 00 69 00 00 03 01 FF 06"), 0.01) == hx("5E 00 2F 04 0E 02 01 01")
    assert ds47(m, hx("0F 01 01 01 10 01 00 69 00 00"), 0.02) == hx("5E 00 2F 08 0F 01 01 01 03 01 FF 06")
    assert model.param_value("P105") == -2.5


def test_a_read_shorter_than_the_response_gets_its_first_octets(profile):
    _, _, m = rig(profile)
    req = hx("05 01 01 01 10 06 03 C4 00 00")
    assert m.answer(write_ds47(req), 0.01, 0.013) == hx("5F 00 2F 0A")
    # Read of 6 octets: the first 6 of the 18-octet response, length 06
    assert m.answer(hx("5E 00 2F 06"), 0.014, 0.017) == hx("5E 00 2F 06 05 01 01 01 06 06")
    # handed out once: the next Read finds nothing requested
    assert m.answer(READ_DS47, 0.018, 0.021) == hx("DE 80 B5 00")


# -- parameter errors -------------------------------------------------------------------------------

@pytest.mark.parametrize("request_,response", [
    # PNU 999 (0x03E7) is not in the table: 0x00
    ("20 01 01 01 10 01 03 E7 00 00", "20 81 01 01 44 01 00 00"),
    # P120 (0x78, output frequency) is read-only: 0x01
    ("21 02 01 01 10 01 00 78 00 00 03 01 00 01", "21 82 01 01 44 01 00 01"),
    # P100 = 500.00 Hz (50000 = C350) over its 400 Hz: 0x02
    ("22 02 01 01 10 01 00 64 00 00 06 01 C3 50", "22 82 01 01 44 01 00 02"),
    # PNU 964 subindex 6: past its six elements: 0x03
    ("23 01 01 01 10 01 03 C4 00 06", "23 81 01 01 44 01 00 03"),
    # P100 with subindex 1: no array: 0x04
    ("24 01 01 01 10 01 00 64 00 01", "24 81 01 01 44 01 00 04"),
    # P102 (16 bits) written as Unsigned32 (07): 0x17
    ("25 02 01 01 10 01 00 66 00 00 07 01 00 00 01 F4", "25 82 01 01 44 01 00 17"),
    # P102, one element, two values: 0x18
    ("26 02 01 01 10 01 00 66 00 00 06 02 01 F4 01 F4", "26 82 01 01 44 01 00 18"),
    # axis 2 does not exist: 0x19 (axis mirrored)
    ("27 01 02 01 10 01 00 64 00 00", "27 81 02 01 44 01 00 19"),
    # the description (attribute 0x20) is not served: 0x09
    ("28 01 01 01 20 01 00 64 00 00", "28 81 01 01 44 01 00 09"),
    # request id 3 is no service: the request does not decode; 0x21, reference and axis mirrored
    ("29 03 01 01 10 01 00 64 00 00", "29 81 01 01 44 01 00 21"),
    # 2 parameters announced, one address: the request does not decode; 0x16
    ("2A 01 01 02 10 01 00 64 00 00", "2A 81 01 01 44 01 00 16"),
])
def test_parameter_errors(profile, request_, response):
    _, _, m = rig(profile)
    req, res = hx(request_), hx(response)
    assert ds47(m, req, 0.01) == bytes((0x5E, 0x00, 0x2F, len(res))) + res


def test_a_change_of_a_stop_parameter_while_running_is_refused(profile):
    model, _, m = rig(profile)
    m.exchange(0x047E, 0x2000, 0.001)                        # S1 -> S2 (ready to switch on)
    m.exchange(0x047F, 0x2000, 0.002)                        # -> operation, 50 % of P100
    for k in range(1, 20):
        m.exchange(0x047F, 0x2000, 0.002 + 0.05 * k)
    assert model.running
    # P100 (access stop) = 60.00 Hz (6000 = 1770): 0x11 while running
    assert ds47(m, hx("30 02 01 01 10 01 00 64 00 00 06 01 17 70"), 1.0) == \
        hx("5E 00 2F 08 30 82 01 01 44 01 00 11")
    # P102 (rw) may change while running: 4.00 s -> 400 = 0190
    assert ds47(m, hx("31 02 01 01 10 01 00 66 00 00 06 01 01 90"), 1.01) == hx("5E 00 2F 04 31 02 01 01")


def test_a_change_with_one_refused_parameter_and_the_change_that_stays(profile):
    model, _, m = rig(profile)
    # P101 = 1.00 Hz (0064) and P100 = 500.00 Hz (C350): the first changed (0x40 Zero, no values),
    # the second refused (0x02)
    got = ds47(m, hx("32 02 01 02 10 01 00 65 00 00 10 01 00 64 00 00 06 01 00 64 06 01 C3 50"), 0.01)
    assert got == hx("5E 00 2F 0A 32 82 01 02 40 00 44 01 00 02")
    assert model.param_value("P101") == 1.0 and model.param_value("P100") == 50.0
    assert ds47(m, hx("33 01 01 01 10 01 00 65 00 00"), 0.02) == hx("5E 00 2F 08 33 01 01 01 06 01 00 64")


# -- DP-V1 errors of the record and of the PDU -------------------------------------------------------

def test_nothing_requested_is_a_state_conflict(profile):
    _, _, m = rig(profile)
    assert m.answer(READ_DS47, 0.01, 0.013) == hx("DE 80 B5 00")


def test_invalid_index_and_slot(profile):
    _, _, m = rig(profile)
    assert m.answer(hx("5E 00 2E F0"), 0.01, 0.013) == hx("DE 80 B0 00")            # index 46
    assert m.answer(hx("5F 00 30 02 00 00"), 0.02, 0.023) == hx("DF 80 B0 00")      # Write index 48
    assert m.answer(hx("5E 01 2F F0"), 0.03, 0.033) == hx("DE 80 B2 00")            # slot 1
    assert m.answer(hx("5E 01 30 F0"), 0.04, 0.043) == hx("DE 80 B2 00")            # both: the slot


def test_a_pdu_that_does_not_decode_is_answered_invalid_parameter(profile):
    _, _, m = rig(profile)
    # Write whose length says 5 with 1 data octet: 80 B8 00 on the next poll
    assert m.answer(hx("5F 00 2F 05 01"), 0.01, 0.011) == hx("DF 80 B8 00")
    # Read with data after its header
    assert m.answer(hx("5E 00 2F F0 00"), 0.02, 0.021) == hx("DE 80 B8 00")
    # a Write DS47 too short for a parameter request header: write length error
    assert m.answer(hx("5F 00 2F 02 01 01"), 0.03, 0.033) == hx("DF 80 B1 00")


def test_busy_gives_state_conflicts_until_the_response_is_ready(profile):
    model, slave, m = rig(profile, busy=0.02)
    req = hx("05 01 01 01 10 01 00 64 00 00")                # read P100
    assert m.answer(write_ds47(req), 0.100, 0.103) == hx("5F 00 2F 0A")
    # the Write answered from 0.102 on; the response ready 20 ms later (0.122)
    answers = []
    t = 0.104
    while True:
        du = m.answer(READ_DS47, t, t + 0.003)
        answers.append(du)
        if du != hx("DE 80 B5 00"):
            break
        t += 0.004
    assert len(answers) >= 5                    # 0.104, 0.108, 0.112, 0.116, 0.120: busy
    assert answers[-1] == hx("5E 00 2F 08 05 01 01 01 06 01 13 88")
    assert model.ds47.stats["state_conflicts"] == len(answers) - 1


def test_a_new_request_replaces_the_pending_one(profile):
    _, _, m = rig(profile)
    assert m.c1(READ_DS47, at=0.01) == SC                    # would be a state conflict ...
    assert m.c1(hx("5E 00 2E F0"), at=0.011) == SC           # ... replaced: invalid index
    assert m.poll(at=0.02) != SC
    assert F.parse(m.poll(at=0.021))[0].sd == F.SC            # one answer only
    # a new Write DS47 before the response was read: only the new response
    assert m.answer(write_ds47(hx("05 01 01 01 10 01 00 64 00 00")), 0.03, 0.033) == hx("5F 00 2F 0A")
    assert m.answer(write_ds47(hx("06 01 01 01 10 01 00 66 00 00")), 0.033, 0.036) == hx("5F 00 2F 0A")
    assert m.answer(READ_DS47, 0.036, 0.039) == hx("5E 00 2F 08 06 01 01 01 06 01 01 F4")


def test_set_prm_drops_what_is_pending(profile):
    _, slave, m = rig(profile)
    assert m.c1(write_ds47(hx("05 01 01 01 10 01 00 64 00 00")), at=0.01) == SC
    m.start(at=0.011)                                         # the master parameterises again
    assert m.poll(at=0.02) == SC                              # the Write's answer is gone
    assert m.answer(READ_DS47, 0.03, 0.033) == hx("DE 80 B5 00")     # and the response with it
    # a Write answered, the response not yet read, the watchdog runs out (1 s)
    assert m.answer(write_ds47(hx("05 01 01 01 10 01 00 64 00 00")), 0.04, 0.043) == hx("5F 00 2F 0A")
    slave.tick(2.0)
    assert slave.state != DATA_EXCH
    m.start(at=2.1)
    assert m.answer(READ_DS47, 2.2, 2.203) == hx("DE 80 B5 00")


def test_silent_injection_never_answers(profile):
    _, slave, m = rig(profile, c1_silent=1)
    assert m.c1(TOSHIBA_WRITE, at=0.01) == SC
    for k in range(1, 50):
        assert m.poll(at=0.01 + 0.01 * k) == SC
    assert slave.stats["c1_answers"] == 0


def test_silence_makes_the_master_time_out_and_restart_the_station():
    """Through the master (dp/poller.py): C1_Response_Timeout (the profile's 10 ms) fires, and the
    station is parameterised again."""
    from profidrive_cli.dp.acyclic import C1Timeout
    from profidrive_cli.dp.poller import Master as DpMaster
    from profidrive_cli.dp.station import SlaveConfig
    from profidrive_cli.fdl.timing import BusParams
    from profidrive_cli.link import open_link
    link = open_link(f"sim://?stations={ADDR}:profidrive-dpv1&set={ADDR}:c1_silent=1")
    try:
        dm = DpMaster(link, BusParams.for_baud(19200, retries=1))
        dm.add_station(ADDR, SlaveConfig(ident=IDENT, cfg=TEL1, user_prm=DPV1_ON, wd_ms=500))
        dm.bring_up(ADDR)
        t0 = link.now()
        with pytest.raises(C1Timeout, match="C1_Response_Timeout"):
            dm.c1_read(ADDR, 0, 47, 240, 0.010)
        assert link.now() - t0 >= 0.010
    finally:
        link.close()


# -- the plant ---------------------------------------------------------------------------------------

def test_the_family_row_names_the_model_and_the_plant_builds_it():
    assert FAMILIES["profidrive"].sim_model == "profidrive_cli.sim.dpv1_axis:make_model"
    bus = build_bus(f"sim://?stations={ADDR}:profidrive-dpv1&set={ADDR}:busy=0.05,c1_silent=1")
    model = bus.slaves[ADDR].model
    assert isinstance(model, Dpv1AxisModel)
    assert (model.ds47.busy_s, model.ds47.silent, model.node_address) == (0.05, True, ADDR)
    bus = build_bus(f"sim://?stations={ADDR}:dpv1-axis")       # the alias; built on first use
    assert bus.slaves[ADDR].model.ident == IDENT


def test_options_are_checked():
    from profidrive_cli import UsageError
    with pytest.raises(UsageError, match="busy"):
        build_bus(f"sim://?stations={ADDR}:profidrive-dpv1&set={ADDR}:busy=0.003")


def test_sim_ctl_set_steers_the_injections(profile):
    model = make_model(profile)
    model.set_value("busy", 0.05)
    model.set_value("C1_SILENT", 1)
    assert (model.ds47.busy_s, model.ds47.silent) == (0.05, True)
    with pytest.raises(ValueError, match="busy takes 0 or"):
        model.set_value("busy", 7)
    model.set_value("P102", 2.5)                               # a parameter as before
    assert model.param_value("P102") == 2.5
    assert model.snapshot()["dpv1"] == {"busy_s": 0.05, "c1_silent": True, "writes": 0, "reads": 0,
                                        "state_conflicts": 0, "refused": 0}
