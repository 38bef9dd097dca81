"""drives/profidrive/scaling.py: the refusals say what is wrong (issue 20 mutation survivors)."""

import math

import pytest

from profidrive_cli.drives.profidrive import scaling as sc


def test_nan_reference_is_refused_in_words():
    with pytest.raises(ValueError) as e:
        sc.n2_from_percent(math.nan)
    assert str(e.value) == "reference is NaN"


@pytest.mark.parametrize("fmax", [0.0, -50.0])
def test_max_frequency_must_be_positive(fmax):
    with pytest.raises(ValueError) as e:
        sc.n2_from_hz(10.0, fmax)
    assert str(e.value) == f"max frequency must be > 0, got {fmax}"


def test_n2_from_hz_hand_values():
    # 0x4000 = fmax (reference §6.1 N2): 12.5 Hz of 50 Hz = 25 % = 0x1000; -50 Hz = 0xC000
    assert sc.n2_from_hz(12.5, 50.0) == 0x1000
    assert sc.n2_from_hz(-50.0, 50.0) == 0xC000
