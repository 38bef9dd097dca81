"""The simulated DP slave answers each state the way reference §3.6 says, refusals included."""

import pytest

from profidrive_cli.dp import services as S
from profidrive_cli.fdl import frames as F
from profidrive_cli.sim.model import SlaveModel
from profidrive_cli.sim.slave import DATA_EXCH, WAIT_CFG, WAIT_PRM, SimSlave

IDENT = 0x1234
CFG = bytes.fromhex("F3F1")


class Echo(SlaveModel):
    """Inputs = outputs (so a test sees the data went through)."""

    def __init__(self):
        super().__init__(IDENT, {"ppo1": CFG})
        self.left = []

    def data_exchange(self, outputs, now):
        return outputs

    def on_leave_data_exchange(self, now, reason):
        self.left.append(reason)


class Link:
    """Drives one SimSlave with the same frame codec, tracking FCB like a master."""

    def __init__(self, slave, master=2):
        self.s = slave
        self.master = master
        self.fcb = True
        self.started = False

    def req(self, dsap, data=b"", now=0.0, repeat=False, sa=None):
        if not repeat:
            if self.started:
                self.fcb = not self.fcb
        fc = F.request_fc(F.SRD_HIGH, fcb=self.fcb if self.started or repeat else True,
                          fcv=self.started)
        self.started = True
        frame = F.Frame(F.SD2, self.s.address, sa if sa is not None else self.master, fc, data,
                        dsap, None if dsap is None else S.SAP_MASTER)
        raw = self.s.handle(F.parse(F.encode(frame))[0], now)
        return F.parse(raw)[0] if raw else None

    def diag(self, now=0.0):
        r = self.req(S.SAP_SLAVE_DIAG, now=now)
        return S.SlaveDiag.decode(r.data)

    def start(self, wd_ms=100, cfg=CFG, ident=IDENT, now=0.0):
        self.diag(now)
        assert self.req(S.SAP_SET_PRM, S.SetPrm(ident, wd_ms).encode(), now).sd == F.SC
        assert self.req(S.SAP_CHK_CFG, cfg, now).sd == F.SC
        return self.diag(now)


@pytest.fixture
def slave():
    return SimSlave(3, Echo())


def test_fdl_status_reply_byte_exact(slave):
    raw = slave.handle(F.parse(bytes.fromhex("10 03 02 49 4E 16"))[0], 0.0)
    assert raw == bytes.fromhex("10 02 03 00 05 16")


def test_wait_prm_diag_and_refusals(slave):
    m = Link(slave)
    d = m.diag()
    assert d.encode() == bytes.fromhex("020500FF1234")
    assert m.req(S.SAP_CHK_CFG, CFG).fc & 0x0F == F.RS          # Chk_Cfg before Set_Prm: RS
    assert m.req(None, bytes(12)).fc & 0x0F == F.RS              # Data_Exchange: RS
    assert slave.state == WAIT_PRM


def test_wrong_ident_gives_prm_fault(slave):
    m = Link(slave)
    m.req(S.SAP_SET_PRM, S.SetPrm(0x9999, 100).encode())
    d = m.diag()
    assert d.has("Prm_Fault") and d.has("Prm_Req") and slave.state == WAIT_PRM


def test_wrong_cfg_gives_cfg_fault_then_good_start(slave):
    m = Link(slave)
    d = m.start(cfg=b"\xF1")
    assert d.has("Cfg_Fault") and slave.state == WAIT_PRM
    d = m.start()
    assert d.encode() == bytes.fromhex("000C00021234")          # ready, WD_On, master 2
    assert slave.state == DATA_EXCH
    r = m.req(None, bytes(range(12)))
    assert (r.fc & 0x0F, r.data) == (F.DL, bytes(range(12)))


def test_fcb_repetition_gets_cached_reply_without_executing(slave):
    m = Link(slave)
    m.start()
    r1 = m.req(None, bytes([1] * 12))
    n = slave.stats["data_exchange"]
    r2 = m.req(None, bytes([2] * 12), repeat=True)                # same FCB: a repetition
    assert r2 == r1 and slave.stats["data_exchange"] == n and slave.stats["repeats"] == 1


def test_watchdog_expiry_drops_to_wait_prm_and_answers_rs(slave):
    m = Link(slave)
    m.start(wd_ms=100, now=0.0)
    assert m.req(None, bytes(12), now=0.05).fc & 0x0F == F.DL
    r = m.req(None, bytes(12), now=0.5)
    assert r.fc & 0x0F == F.RS and slave.state == WAIT_PRM
    assert slave.model.left == ["watchdog"]
    assert m.diag(now=0.5).has("Prm_Req")


def test_other_master_cannot_take_a_locked_station(slave):
    m = Link(slave)
    m.start()
    other = Link(slave, master=1)
    other.req(S.SAP_SET_PRM, S.SetPrm(IDENT, 100).encode())
    assert slave.master == 2 and slave.state == DATA_EXCH
    assert other.diag().master == 2
    assert other.req(None, bytes(12)).fc & 0x0F == F.RS        # its Data_Exchange is refused


def test_output_length_mismatch_leaves_data_exchange(slave):
    m = Link(slave)
    m.start()
    assert m.req(None, bytes(4)).fc & 0x0F == F.RS
    assert slave.state == WAIT_PRM and slave.model.left == ["output length mismatch"]


def test_get_cfg_and_unlock(slave):
    m = Link(slave)
    assert m.req(S.SAP_GET_CFG).data == CFG
    m.start()
    m.req(S.SAP_SET_PRM, S.SetPrm(IDENT, 100, lock=False, unlock=True).encode())
    assert slave.state == WAIT_PRM and slave.master is None


def test_set_prm_after_data_exchange_reparameterises(slave):
    m = Link(slave)
    m.start()
    m.req(S.SAP_SET_PRM, S.SetPrm(IDENT, 200).encode())
    assert slave.state == WAIT_CFG and slave.model.left == ["new parameters"]


def test_sdn_broadcast_has_no_reply_and_clear_reaches_model(slave):
    m = Link(slave)
    m.start()
    frame = F.Frame(F.SD2, F.BROADCAST, 2, F.request_fc(F.SDN_HIGH), b"\x02\x00", 58, 62)
    assert slave.handle(frame, 0.0) is None
    assert slave.model.left == ["clear"]


def test_power_cycle(slave):
    m = Link(slave)
    m.start()
    slave.power_cycle(1.0)
    assert slave.state == WAIT_PRM and m.diag(1.0).master == 0xFF
