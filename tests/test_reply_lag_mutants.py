"""The learned reply lag of the fast Data_Exchange path (dp/dx_fast.py `_learn_lag`), by hand: it
moves down by LAG_DOWN_S (2 µs) after a reply read whole at the first read, never below 0, and up by
LAG_UP_S (19 × 2 µs = 38 µs) after a reply that needed another read, never above the bus parameters'
link latency margin. The ratio makes it the 95th percentile of the lag (one reply in twenty read in two
parts holds it still: 19 × 2 µs down = 38 µs up)."""

from types import SimpleNamespace

import pytest

from profidrive_cli.dp import dx_fast


def learn(lag, reads, latency=0.02):
    m = SimpleNamespace(reply_lag=lag, _await_reads=reads)
    dx_fast._learn_lag(m, SimpleNamespace(link_latency=latency))
    return m.reply_lag


def test_the_steps_are_2_us_down_and_38_us_up():
    assert dx_fast.LAG_DOWN_S == pytest.approx(2e-6)
    assert dx_fast.LAG_UP_S == pytest.approx(38e-6)


def test_a_whole_reply_lowers_the_lag_by_one_step():
    assert learn(10e-6, 1) == pytest.approx(8e-6)


def test_the_lag_never_goes_below_zero():
    assert learn(1e-6, 1) == 0.0
    assert learn(0.0, 1) == 0.0


def test_a_reply_in_two_or_more_reads_raises_it_by_one_up_step():
    assert learn(0.0, 2) == pytest.approx(38e-6)
    assert learn(10e-6, 3) == pytest.approx(48e-6)


def test_the_lag_is_capped_at_the_link_latency_margin():
    assert learn(0.01999, 2, latency=0.02) == 0.02
    assert learn(0.0, 2, latency=0.0) == 0.0


def test_twenty_replies_one_of_them_split_hold_the_lag_still():
    lag = 100e-6
    for i in range(20):
        lag = learn(lag, 2 if i == 0 else 1)
    assert lag == pytest.approx(100e-6)
