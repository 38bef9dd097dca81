"""FCB/FCV rules (reference §2.3), checked against the S7 capture sequence."""

from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.fcb import MasterFcb, SlaveFcb


def test_master_sequence_matches_capture():
    fcb = MasterFcb()
    seq = []
    for _ in range(5):            # diag, Get_Cfg, Set_Prm, Chk_Cfg, diag
        seq.append(fcb.fc(F.SRD_HIGH))
        fcb.confirm()
    assert seq == [0x6D, 0x5D, 0x7D, 0x5D, 0x7D]


def test_retry_repeats_fcb_and_reset_restarts():
    fcb = MasterFcb()
    fcb.fc(F.SRD_HIGH)
    fcb.confirm()
    first = fcb.fc(F.SRD_HIGH)
    assert fcb.fc(F.SRD_HIGH) == first      # no confirm: a retry carries the same FCB
    fcb.reset()
    assert fcb.fc(F.SRD_HIGH) == 0x6D


def test_slave_detects_repetition():
    s = SlaveFcb()
    assert not s.is_repeat(2, 0x6D)        # FCV=0 FCB=1: new sequence
    s.remember(b"r1")
    assert not s.is_repeat(2, 0x5D)
    s.remember(b"r2")
    assert s.is_repeat(2, 0x5D)            # same FCB again: repetition
    assert s.last_reply == b"r2"
    assert not s.is_repeat(2, 0x7D)        # toggled: new telegram
    s.remember(b"r3")
    assert not s.is_repeat(1, 0x7D)        # same FCB from another master is not a repeat
