"""fdl/timing.py against the reference's own numbers (/work/shared/spec/profibus-dp-reference.md), not
against itself: baud-rate names, the slot-time bounds (§4.2: max TSDR + 15 <= TSL <= 16 383), the
retry limit (<= 15), the bit / character / TSYN times (§1.1: 11 bit per character, TSYN 33 bit), the
reply timeout and the message cycle (§4.2: request × 11 + TSDR + reply × 11 + TID1) and the frame
lengths (§2: SD1 6 octets, SD3 14, SD2 LE + 6 with LE = 3 + SAPs + data). Written for mutation
testing (tools/mutation/run.py fdl/timing.py).
"""

import pytest

from profidrive_cli.fdl.timing import (BAUD_NAMES, BAUD_RATES, BusParams, frame_octets, parse_baud,
                                       transaction_wire_time, wire_time_data_exchange)


@pytest.mark.parametrize("text,baud", [
    ("9600", 9600), ("19200", 19200), ("19.2k", 19200), ("19.2K", 19200), (" 45.45k ", 45450),
    ("93.75k", 93750), ("187_500", 187500), ("187.5k", 187500), ("500k", 500000), ("1.5M", 1500000),
    ("1.5m", 1500000), ("3M", 3000000), ("6M", 6000000), ("12M", 12000000), ("12000000", 12000000),
    (500000, 500000), ("9.6k", 9600)])
def test_parse_baud_accepts_the_dp_rates_in_any_spelling(text, baud):
    assert parse_baud(text) == baud


@pytest.mark.parametrize("text", ["19201", "abc", "", "12G", "1.5", "k", 1234, "115200", "12M5"])
def test_parse_baud_refuses_the_rest_listing_the_rates(text):
    with pytest.raises(ValueError) as e:
        parse_baud(text)
    assert str(e.value) == (f"{text!r} is not a PROFIBUS-DP baud rate (9.6k, 19.2k, 45.45k, 93.75k, "
                            f"187.5k, 500k, 1.5M, 3M, 6M, 12M)")


def test_the_ten_dp_rates_and_their_names():
    assert BAUD_RATES == (9600, 19200, 45450, 93750, 187500, 500000, 1500000, 3000000, 6000000, 12000000)
    assert [BAUD_NAMES[b] for b in BAUD_RATES] == ["9.6k", "19.2k", "45.45k", "93.75k", "187.5k", "500k",
                                                  "1.5M", "3M", "6M", "12M"]


@pytest.mark.parametrize("baud,lowest", [(19200, 75), (500000, 115), (12000000, 815)])
def test_slot_time_bounds(baud, lowest):
    # §4.2: max TSDR + 15 <= TSL <= 16 383 (max TSDR 60 at 19.2k, 100 at 500k, 800 at 12M)
    assert BusParams.for_baud(baud, slot_time=lowest).tsl == lowest
    assert BusParams.for_baud(baud, slot_time=16383).tsl == 16383
    for bad in (lowest - 1, 16384):
        with pytest.raises(ValueError) as e:
            BusParams.for_baud(baud, slot_time=bad)
        assert str(e.value) == f"slot time {bad} outside {lowest}..16383 bit times at {BAUD_NAMES[baud]}"


def test_retries_bounds_and_default():
    assert BusParams.for_baud(19200).retries == 1                     # §4.2: typical 1
    assert BusParams.for_baud(19200, retries=15).retries == 15
    assert BusParams.for_baud(19200, retries=0).retries == 0          # no retry at all (pdrive's choice)
    for bad in (16, -1):
        with pytest.raises(ValueError) as e:
            BusParams.for_baud(19200, retries=bad)
        assert str(e.value) == f"retries {bad} outside 0..15"


def test_for_baud_keeps_the_other_fields():
    p = BusParams.for_baud(3000000, slot_time=1000, retries=3, link_latency=0.002)
    assert (p.baud, p.tsl, p.min_tsdr, p.max_tsdr, p.tqui, p.tset, p.retries, p.link_latency) == \
        (3000000, 1000, 11, 250, 3, 4, 3, 0.002)
    assert BusParams.for_baud(19200).link_latency == 0.0
    assert BusParams() == BusParams.for_baud(19200)                   # the defaults are 19.2k's


@pytest.mark.parametrize("baud,t_bit_us,char_us,tsyn_us,tsl_us", [
    # §1.1 table (rounded there; compared to its precision)
    (9600, 104.17, 1145.8, 3437.5, 10417), (19200, 52.08, 572.9, 1718.8, 5208),
    (93750, 10.67, 117.3, 352.0, 1067),
    (12000000, 0.0833, 0.917, 2.75, 8.33)])      # the table rounds TSL at 12M to 8 µs: 100 / 12 = 8.33
def test_bit_char_tsyn_and_slot_times(baud, t_bit_us, char_us, tsyn_us, tsl_us):
    p = BusParams(baud=baud, tsl=100)              # the table's TSL column is 100 bit at every rate
    assert p.t_bit * 1e6 == pytest.approx(t_bit_us, rel=5e-3)
    assert p.chars(1) * 1e6 == pytest.approx(char_us, rel=5e-3)
    assert p.chars(3) == pytest.approx(3 * 11 / baud)
    assert p.tsyn * 1e6 == pytest.approx(tsyn_us, rel=5e-3)
    assert p.slot_seconds * 1e6 == pytest.approx(tsl_us, rel=5e-3)


def test_tid2_is_max_tsdr():
    assert [BusParams.for_baud(b).tid2 for b in (19200, 1500000, 12000000)] == [60, 150, 800]


def test_reply_timeout_slot_plus_octets_plus_latency():
    p = BusParams.for_baud(19200, link_latency=0.004)
    # TSL 100 bit + 21 octets × 11 bit at 19.2k, + 4 ms
    assert p.reply_timeout(21) == pytest.approx((100 + 231) / 19200 + 0.004)
    # the default: a whole 255-octet telegram (§1.1: 146 ms at 19.2k) after the slot time
    assert BusParams.for_baud(19200).reply_timeout() == pytest.approx((100 + 255 * 11) / 19200)
    assert BusParams.for_baud(19200).reply_timeout() - 100 / 19200 == pytest.approx(0.146, abs=0.001)


def test_cycle_time_is_the_reference_message_cycle():
    p = BusParams.for_baud(19200)
    # §4.2 with max TSDR (60) by default: 21·11 + 60 + 21·11 + 37 = 559 bit
    assert p.cycle_time(21, 21) == pytest.approx(559 / 19200)
    # with the station's TSDR: 13·11 + 11 + 6·11 + 37 = 257 bit
    assert p.cycle_time(13, 6, 11) == pytest.approx(257 / 19200)
    assert p.cycle_time(13, 6, 0) == pytest.approx(246 / 19200)


def test_transaction_wire_time_answered_and_unanswered():
    p = BusParams.for_baud(19200)
    # answered: request + TSDR 11 (the default) + reply + TID1 37
    assert transaction_wire_time(p, 21, 21) == pytest.approx((231 + 11 + 231 + 37) / 19200)
    assert transaction_wire_time(p, 21, 21, tsdr_bits=60) == pytest.approx(559 / 19200)
    # unanswered: each attempt is the request + the slot time (100 bit)
    assert transaction_wire_time(p, 6, None) == pytest.approx((66 + 100) / 19200)
    assert transaction_wire_time(p, 6, None, attempts=2) == pytest.approx(2 * (66 + 100) / 19200)


@pytest.mark.parametrize("du,saps,octets", [
    (0, False, 6),        # SD1
    (8, False, 14),       # SD3: exactly 8 octets of data
    (6, True, 14),        # SD3: 2 SAPs + 6 data
    (0, True, 11),        # SD2, LE = 3 + 2: SAPs alone
    (1, False, 10),       # SD2, LE 4
    (12, False, 21),      # PPO1: LE 15 -> 21
    (7, False, 16), (9, False, 18), (244, True, 255)])
def test_frame_octets(du, saps, octets):
    assert frame_octets(du, saps) == octets


@pytest.mark.parametrize("baud,out,inp,tsdr,bits", [
    (19200, 12, 12, 11, 510),      # PPO1: 21 octets each way, 21·11 + 11 + 21·11 + 37
    (19200, 4, 4, 11, 334),        # PPO3: 13 octets
    (19200, 0, 8, 11, 6 * 11 + 11 + 14 * 11 + 37),     # SD1 request, SD3 reply
    (19200, 12, 12, 60, 559),
    (12000000, 12, 12, 11, 549),   # TID1 76 at 12M
])
def test_wire_time_data_exchange(baud, out, inp, tsdr, bits):
    assert wire_time_data_exchange(baud, out, inp, tsdr) == pytest.approx(bits / baud)


def test_wire_time_data_exchange_default_tsdr_is_min_tsdr():
    assert wire_time_data_exchange(19200, 12, 12) == pytest.approx(510 / 19200)
