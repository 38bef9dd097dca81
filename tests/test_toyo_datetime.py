"""Toyo date/time words (used by the VF66 when J-14 = 1) carry the host's clock.

Manual (/work/shared/seeds/002_e31e7b20f4f4e720.txt) L588-591: "J-14 通信からの日時データ選択 0:日時データなし
1:日時データあり" (date/time data from the network: 0 none, 1 present); PPO2 output frame L1137-1143:
"+14 月 日 (L) <- 日の設定1~31 [Day]", "+15 月 日 (H) <- 月の設定1~12 [Month]", "+16 時 分 (L) <- 分の設定
0~59 [Minute]", "+17 時 分 (H) <- 時の設定0~23 [Hour]". PPO2 = 4 PKW words (+0..+7), then CTW, speed,
torque, month/day, hour/minute: day at +14, month +15, minute +16, hour +17 (little-endian words).
Hand calculation: 25 December, 13:45 -> +14..+17 = 25, 12, 45, 13.
"""

from datetime import datetime

import pytest

from profidrive_cli.drives import make_drive
from profidrive_cli.drives.profile import load_profile
from profidrive_cli.drives.toyo.drive import date_words
from profidrive_cli.sim.direct import DirectChannel
from profidrive_cli.sim.toyo import make_model

XMAS = datetime(2026, 12, 25, 13, 45, 30)


class Recorder(DirectChannel):
    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        self.outs = []

    def exchange(self, outputs: bytes) -> bytes:
        self.outs.append(bytes(outputs))
        return super().exchange(outputs)


def toyo(layout, j14=1):
    prof = load_profile("toyo")
    model = make_model(prof, defaults={"J-14": j14})
    ch = Recorder(model, prof.layouts[layout].cfg)
    d = make_drive(ch, prof, layout)
    d.clock = lambda: XMAS
    return model, ch, d


def test_date_words_by_hand():
    assert date_words(XMAS) == {"month_day": 12 << 8 | 25, "hour_minute": 13 << 8 | 45}
    assert date_words(datetime(2027, 1, 1, 0, 0)) == {"month_day": 0x0101, "hour_minute": 0}


def test_ppo2_bytes_14_to_17_carry_day_month_minute_hour():
    model, ch, d = toyo("ppo2")
    d.cycle()
    assert list(ch.outs[-1][14:18]) == [25, 12, 45, 13]
    assert model.net_clock == (12, 25, 13, 45) and model.bad_clock == 0


@pytest.mark.parametrize("layout", ["ppo2", "ppo4", "ppo5", "toyo"])
def test_every_layout_with_date_words_sends_a_valid_date(layout):
    model, ch, d = toyo(layout)
    for _ in range(3):
        d.cycle()
    assert model.net_clock == (12, 25, 13, 45) and model.bad_clock == 0


def test_the_host_clock_by_default():
    prof = load_profile("toyo")
    model = make_model(prof, defaults={"J-14": 1})
    d = make_drive(DirectChannel(model, prof.layouts["ppo2"].cfg), prof, "ppo2")
    before = datetime.now()
    d.cycle()
    after = datetime.now()
    assert model.bad_clock == 0
    month, day, hour, minute = model.net_clock
    assert (month, day) in {(before.month, before.day), (after.month, after.day)}
    assert (hour, minute) in {(before.hour, before.minute), (after.hour, after.minute)}


def test_sim_counts_an_invalid_date():
    model, ch, d = toyo("ppo2")
    d.words_out.update({"month_day": 0, "hour_minute": 0})      # month 0 / day 0: not a date
    d.cycle()
    assert model.net_clock is None and model.bad_clock == 1
