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


def test_master_restarts_the_sequence_after_a_failed_transaction():
    """Reference §2.3: FCB toggles only after a valid reply, a retry repeats it, and a (re)start
    begins with FCV=0, FCB=1. A request that got no valid reply after all retries is such a
    restart: the next request is 0x6D (SRD high, FCV=0, FCB=1), not a repetition of 0x5D."""
    from profidrive_cli.fdl.master import NO_ANSWER, REPLY, FdlMaster
    from profidrive_cli.fdl.timing import BusParams

    fm = FdlMaster(BusParams.for_baud(19200, retries=1), address=2)
    sc = b"\xE5"
    out, _ = fm.request(3, F.SRD_HIGH, b"\x01\x02", now=0.0)
    assert out[6] == 0x6D                   # SD2: 68 LE LEr 68 DA SA FC ...
    assert fm.feed(sc, 0.001).kind == REPLY
    out, _ = fm.request(3, F.SRD_HIGH, b"\x03\x04", now=1.0)
    assert out[6] == 0x5D                   # FCV=1, FCB=0
    retry, _ = fm.expire(2.0)
    assert retry[6] == 0x5D                 # the retry repeats the FCB
    assert fm.expire(3.0).kind == NO_ANSWER
    out, _ = fm.request(3, F.SRD_HIGH, b"\x05\x06", now=4.0)
    assert out[6] == 0x6D                   # restart: FCV=0, FCB=1
    assert fm.feed(sc, 4.001).kind == REPLY
    out, _ = fm.request(3, F.SRD_HIGH, b"\x07\x08", now=5.0)
    assert out[6] == 0x5D                   # and the sequence goes on from there
    # the FDL status probe carries no FCB and is not affected (rule 4)
    out, _ = fm.request(4, F.FDL_STATUS, now=6.0)
    assert out[3] == 0x49


def test_slave_takes_the_restart_after_a_lost_reply_as_a_new_telegram():
    s = SlaveFcb()
    assert not s.is_repeat(2, 0x6D)
    s.remember(b"r1")
    assert not s.is_repeat(2, 0x5D)        # executed; its reply is lost on the way
    s.remember(b"r2")
    assert s.is_repeat(2, 0x5D)            # the master's retry: answered from the cache
    assert not s.is_repeat(2, 0x6D)        # the master gave up and restarts: a new telegram
    s.remember(b"r3")
    assert not s.is_repeat(2, 0x5D)        # next one toggles: new again
