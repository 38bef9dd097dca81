"""Frame count bit, slave side and master restarts, exact (reference §2.3).

FC octets of SRD high (function 0x0D) requests: FCV=0 FCB=1 -> 0x6D (a new sequence), FCV=1 FCB=0 ->
0x5D, FCV=1 FCB=1 -> 0x7D (bit 6 = request, bit 5 = FCB, bit 4 = FCV).
"""

from profidrive_cli.fdl.fcb import MasterFcb, SlaveFcb
from profidrive_cli.fdl.frames import SRD_HIGH

START, FCB0, FCB1 = 0x6D, 0x5D, 0x7D


def test_fc_octets_of_srd_high_from_the_bit_layout():
    assert SRD_HIGH == 0x0D
    assert START == 0x40 | 0x20 | 0x0D and FCB0 == 0x40 | 0x10 | 0x0D and FCB1 == 0x40 | 0x30 | 0x0D


def test_master_sequence_restart_after_failure_and_reset():
    m = MasterFcb()
    assert m.fc(SRD_HIGH) == START
    assert m.fc(SRD_HIGH) == START            # a retry repeats it
    m.confirm()
    assert m.fc(SRD_HIGH) == FCB0
    m.confirm()
    assert m.fc(SRD_HIGH) == FCB1
    m.failed()                                # no valid reply after all retries
    assert m.fc(SRD_HIGH) == START
    m.confirm()
    m.confirm()
    m.reset()
    assert m.fc(SRD_HIGH) == START


def test_slave_would_repeat_only_the_same_fcb_from_the_same_master_with_a_reply_kept():
    s = SlaveFcb()
    assert not s.would_repeat(2, FCB1)        # fresh: nothing to repeat
    assert not s.is_repeat(2, START)          # a new sequence: execute
    assert not s.would_repeat(2, FCB1)        # no reply remembered yet
    s.remember(b"reply")
    assert not s.would_repeat(2, START)       # FCV=0 is never a repetition
    assert not s.would_repeat(2, FCB0)        # the other FCB: a new request
    assert s.would_repeat(2, FCB1)            # the same FCB (START carried FCB=1) from master 2
    assert not s.would_repeat(3, FCB1)        # another master
    # would_repeat changes nothing: is_repeat gives the same answers afterwards
    assert s.is_repeat(2, FCB1)
    assert not s.is_repeat(2, FCB0)
    s.remember(b"second")
    assert s.would_repeat(2, FCB0) and not s.would_repeat(2, FCB1)


def test_slave_without_a_kept_reply_executes_a_repeated_fcb():
    s = SlaveFcb()
    assert not s.is_repeat(2, FCB0)           # FCV=1 without a start: execute, FCB taken
    assert not s.is_repeat(2, FCB0)           # nothing was answered: nothing to resend
    s.reset()
    assert s.master is None and s.last_fcb is None and s.last_reply is None
    assert not s.would_repeat(2, FCB0)


def test_slave_start_of_a_new_sequence_forgets_the_kept_reply():
    s = SlaveFcb()
    s.is_repeat(2, START)
    s.remember(b"r1")
    assert s.is_repeat(2, FCB1)               # master repeats (its reply was lost)
    assert not s.is_repeat(2, START)          # the master restarts after a failure: execute
    assert s.last_reply is None
    assert not s.would_repeat(2, FCB1)
