"""The Set_Prm watchdog factors around every rounding boundary, from the DP rule (reference §3.1):
watchdog = WD_Fact_1 × WD_Fact_2 × 10 ms, each factor 1..255, 10 ms .. 650 s. A requested time is
rounded UP to what the factors can hold (a watchdog shorter than asked would drop a station that
is within its time), WD_Fact_2 stays 1 while WD_Fact_1 alone can hold it (up to 2550 ms), and the
factors land in octets 1 and 2 of the Set_Prm DU, with WD_On (bit 3) in octet 0.

Worked by hand: 654 ms -> 65.4 units -> 66 -> (66, 1) = 660 ms; 2551 ms -> 256 units, more than
255: 128 × 2 = 256 -> 2560 ms; 2570 ms -> 257 units (a prime above 255): the least product >= 257
is 129 × 2 = 258 -> 2580 ms; 650 000 ms -> 65 000 units: 255 × 255 = 65 025 -> 650 250 ms."""

import pytest
from hypothesis import given
from hypothesis import strategies as st

from profidrive_cli.dp import services as S

# requested ms -> (WD_Fact_1, WD_Fact_2)
CASES = [
    (10, (1, 1)),          # the smallest: 1 × 1 × 10 ms, not 1 × 2
    (1, (1, 1)),           # below 10 ms: the least the factors can hold
    (11, (2, 1)),          # 20 ms
    (19, (2, 1)), (20, (2, 1)), (21, (3, 1)),
    (500, (50, 1)),
    (650, (65, 1)),
    (651, (66, 1)), (654, (66, 1)), (655, (66, 1)), (660, (66, 1)),
    (2540, (254, 1)), (2541, (255, 1)), (2550, (255, 1)),
    (2551, (128, 2)), (2560, (128, 2)),
    (2570, (129, 2)),      # 257 units: 258 = 129 × 2
    (5100, (255, 2)),
    (650000, (255, 255)), (650250, (255, 255)),
]


@pytest.mark.parametrize("ms,factors", CASES)
def test_watchdog_factors_round_up(ms, factors):
    assert S.watchdog_factors(ms) == factors


@pytest.mark.parametrize("ms,factors", [(10, (1, 1)), (654, (66, 1)), (2551, (128, 2)),
                                        (650000, (255, 255))])
def test_factors_land_in_set_prm_octets_1_and_2(ms, factors):
    du = S.SetPrm(ident=0x00CA, wd_ms=ms).encode()
    assert du[0] & 0x08                       # WD_On
    assert (du[1], du[2]) == factors
    assert S.SetPrm.decode(du).wd_ms == factors[0] * factors[1] * 10


def test_above_650_s_is_refused():
    with pytest.raises(ValueError, match="650"):
        S.watchdog_factors(650251)


@given(st.integers(min_value=10, max_value=650250))
def test_never_shorter_and_within_one_fact2_step(ms):
    """Rounded up, never down; and the factors hold the time to within one step of WD_Fact_2 × 10
    ms (WD_Fact_1 rounded up once WD_Fact_2 is chosen), with WD_Fact_2 = 1 up to 2550 ms."""
    f1, f2 = S.watchdog_factors(ms)
    assert 1 <= f1 <= 255 and 1 <= f2 <= 255
    armed = f1 * f2 * 10
    assert ms <= armed < ms + 10 * f2 + 10
    if ms <= 2550:
        assert f2 == 1


def test_the_shortest_representable_watchdog_not_below_the_request():
    """10 ms x WD_Fact_1 x WD_Fact_2 (each 1..255): the armed watchdog is the smallest product that
    is not shorter than asked. 5101 ms: 511 units = 7 x 73 exactly (5110 ms), not 3 x 171 (5130 ms)."""
    import bisect
    from profidrive_cli.dp.services import watchdog_factors
    assert watchdog_factors(5101) in ((73, 7), (7, 73))
    products = sorted({a * b for a in range(1, 256) for b in range(1, 256)})
    for units in list(range(1, 3000)) + list(range(3000, 65026, 37)) + [65024, 65025]:
        f1, f2 = watchdog_factors(units * 10)
        assert 1 <= f1 <= 255 and 1 <= f2 <= 255
        best = products[bisect.bisect_left(products, units)]
        assert f1 * f2 == best, (units, f1, f2, best)
