"""drives/profidrive/words.py: the cases mutation testing found untested (issue 20).

Expected words from the bit tables of the reference §6.3/§6.4 (control word bits 0-10, status word
bits 0-10) and the state machine §6.5, computed by hand.
"""

import pytest

from profidrive_cli.drives.profidrive import words as w
from profidrive_cli.drives.profidrive.words import State, Target


def test_bit_list_covers_the_16_bits_of_a_word_only():
    # a PROFIdrive word is 16 bits: bit 16 of a wider int is not one of its bits
    assert w.bit_list(0x18001, {0: "a"}) == ["a", "bit 15"]


@pytest.mark.parametrize("ctw, text", [
    (0x0477, "switch on, operation disabled"),       # bits 0-2, 4-6, 10: bit 3 low
    (0x0407, "switch on, operation disabled"),
    (0x040F, "operate without enable ramp generator, unfreeze ramp generator, enable setpoint"),
    (0x0506, "ready (OFF1); jog 1"),                 # bit 8
    (0x0606, "ready (OFF1); jog 2"),                 # bit 9
    (0x07FF, "operate; fault acknowledge; jog 1; jog 2"),
])
def test_command_from_control_word_more(ctw, text):
    assert w.command_from_control_word(ctw) == text


@pytest.mark.parametrize("previous", [
    0x0407,        # switched on: operation (bit 3) was not enabled, no ramp can be running
    0x047D,        # OFF2 (bit 1 low): the drive coasts, there is no ramp to keep
    0x047B,        # OFF3 (bit 2 low): quick stop, no OFF1 ramp either
])
def test_off1_keeps_bit_3_only_after_a_word_that_ran_the_motor(previous):
    # status S3 (0x0333: bits 0, 1, 4, 5, 8, 9), no ramp to protect: plain B = 0x0406
    assert w.next_control_word(0x0333, "off1", previous=previous) == 0x0406
    assert w.next_control_word(0x0333, "off1", previous=0x047F) == 0x047E


@pytest.mark.parametrize("stw, state", [
    (0x0002, State.S3),     # bit 1 without bit 0: inconsistent, by the highest bit -> S3
    (0x0004, State.S4),     # bit 2 alone -> S4
    (0x0006, State.S4),
    (0x0005, State.S4),
])
def test_inconsistent_status_by_the_highest_bit(stw, state):
    assert w.state_from_status(stw) is state


@pytest.mark.parametrize("stw, target, moving, reached", [
    (0x0333, "off1", False, False),        # S3 is switched on, not stopped in S1/S2
    (0x0337, "disable", False, False),     # still S4
    (0x0333, "switched_on", True, False),  # S3 pattern while moving: S5 switching off
    (0x0333, "switched_on", False, True),
])
def test_target_reached_more(stw, target, moving, reached):
    assert w.target_reached(stw, target, moving) is reached


@pytest.mark.parametrize("word, target", [
    ("stop", Target.OFF1), ("normal", Target.OFF1), ("STOP", Target.OFF1),
    ("coast", Target.OFF2), ("quick", Target.OFF3),
    ("run", Target.OPERATE), ("operation", Target.OPERATE),
    ("acknowledge", Target.ACK), ("reset", Target.ACK), ("Ready", Target.READY),
])
def test_target_aliases(word, target):
    assert Target.parse(word) is target


def test_unknown_target_lists_the_known_ones():
    with pytest.raises(ValueError) as e:
        Target.parse("fly")
    assert str(e.value) == ("unknown target 'fly' (known: ready, switched_on, operate, off1, off2, "
                            "off3, disable, ack)")
