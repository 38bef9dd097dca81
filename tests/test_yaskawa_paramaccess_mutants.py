"""drives/yaskawa/paramaccess.py: request checks, texts and the handshake machine's edges, the cases
mutation testing found untested (issue 20).

Expected values from ../shared/spec/yaskawa-profibus-dp.md §4 (area layout: FC, start MSB/LSB, data
quantity = 2 x registers, data words MSB first, HS byte bit 7; response HS byte: HS bit 7, STATUS
bits 6-5, WD bits 4-1 (E9); error = FC | 0x80 (E5) with the code in the low byte of data 1; Table
3.15 error codes) and hand-stepped cycles of the documented phases align -> load -> wait -> idle.
"""

import pytest

from profidrive_cli import UsageError
from profidrive_cli.drives.base import DriveError
from profidrive_cli.drives.yaskawa import FORMATS
from profidrive_cli.drives.yaskawa.paramaccess import (FC_READ, FC_WRITE, ParamAccess, ParamArea,
                                                       ParamRequest, decode_hs, encode_param_area,
                                                       error_text)

EXT1, EXT2, BASIC = FORMATS["extended1"], FORMATS["extended2"], FORMATS["basic"]


def h(text):
    return bytes.fromhex(text)


def resp(fmt, pa: str, hs_byte: int) -> bytes:
    return h(pa).ljust(fmt.param_len - 1, b"\0") + bytes([hs_byte])


def test_error_texts():
    assert error_text(0x21) == \
        "0x21 data content error: the value is outside the parameter's lower/upper limit"
    assert error_text(0x05) == "0x05 unknown (0x05): not in the manual's table"


def test_decode_hs_fields():
    assert decode_hs(0xFF) == (1, 3, 15)
    assert decode_hs(0x1E) == (0, 0, 15)
    assert decode_hs(0x01) == (0, 0, 0)          # bit 0 is not part of WD


@pytest.mark.parametrize("req, fmt, exc, text", [
    (ParamRequest.read(0x100), BASIC, DriveError, "yaskawa basic: this layout has no parameter access"),
    (ParamRequest.read(0x10000), EXT1, UsageError, "register 0x10000 is not a 16-bit register number"),
    (ParamRequest.read(-1), EXT1, UsageError, "register 0x-1 is not a 16-bit register number"),
    (ParamRequest.read(0x100, 5), EXT1, UsageError,
     "yaskawa extended1: 5 registers requested, this layout carries 1..4 per request"),
    (ParamRequest.read(0x100, 0), EXT1, UsageError,
     "yaskawa extended1: 0 registers requested, this layout carries 1..4 per request"),
    (ParamRequest.read(0xFFFE, 3), EXT1, UsageError, "registers 0xFFFE+3 run past 0xFFFF"),
    (ParamRequest(FC_WRITE, 0x100, 2, (1,)), EXT1, UsageError, "write request: one value per register"),
    (ParamRequest.write(0x100, [0x10000]), EXT1, UsageError, "value 65536 does not fit a 16-bit register"),
    (ParamRequest.write(0x100, [-1]), EXT1, UsageError, "value -1 does not fit a 16-bit register"),
    (ParamRequest(0x06, 0x100, 1), EXT1, UsageError, "function code 0x06: only 03h (read) and 10h (write)"),
])
def test_request_checks(req, fmt, exc, text):
    with pytest.raises(exc) as e:
        req.check(fmt)
    assert str(e.value) == text


def test_request_checks_accept_the_edges():
    ParamRequest.read(0xFFFD, 3).check(EXT1)                 # last register 0xFFFF
    ParamRequest.read(0, 4).check(EXT1)
    ParamRequest.write(0xFFFF, [0xFFFF]).check(EXT2)
    ParamRequest.write(0, [0]).check(EXT2)


def test_describe():
    assert ParamRequest.read(0x0100).describe() == "read 0x0100"
    assert ParamRequest.read(0x0100, 3).describe() == "read 0x0100..0x0102"
    assert ParamRequest.write(0x0100, [1, 0xABCD]).describe() == "write 0x0100..0x0101 := 0x0001, 0xABCD"


def test_encode_read_and_write_areas():
    assert encode_param_area(EXT1, ParamRequest.read(0x0180, 4), 1) == \
        h("03 01 80 08") + bytes(11) + b"\x80"
    assert encode_param_area(EXT2, ParamRequest.write(0xABCD, [0x1234]), 0) == \
        h("10 AB CD 02 12 34 00 00")


def test_parse_response_area():
    a = ParamArea.parse(EXT1, resp(EXT1, "90 01 00 02 AB 21", 0x60))
    assert (a.function, a.start, a.quantity, a.hs_byte) == (0x90, 0x0100, 2, 0x60)
    assert a.data == [0xAB21, 0, 0, 0] and a.is_error and a.error_code == 0x21
    ok = ParamArea.parse(EXT2, resp(EXT2, "03 00 37 02 12 34", 0xE0))
    assert not ok.is_error and ok.data == [0x1234]


def test_constructor_checks_and_normalises():
    with pytest.raises(ValueError) as e:
        ParamAccess(BASIC)
    assert str(e.value) == "yaskawa basic: no parameter-access area"
    pa = ParamAccess(EXT2, settle_cycles=0, hs=3)
    assert pa.settle_cycles == 1 and pa.hs == 1 and pa.phase == "align" and not pa.busy
    assert pa.timeout == 1.0 and ParamAccess(EXT2).hs == 0


def test_one_request_at_a_time_and_area_length():
    pa = ParamAccess(EXT2)
    pa.submit(ParamRequest.read(0x37), 0.0)
    with pytest.raises(DriveError) as e:
        pa.submit(ParamRequest.read(0x38), 0.0)
    assert str(e.value) == "a parameter request is already in progress"
    with pytest.raises(ValueError) as e:
        pa.feed(b"\0\0\0", 0.0)
    assert str(e.value) == "parameter area is 3 octets, extended2 has 8"


def drive_to_wait(pa, fmt, now=0.0):
    """align (HS 0 = ours) -> load (one settle cycle) -> wait (our HS toggled to 1)."""
    assert pa.feed(resp(fmt, "", 0x00), now) is None          # aligned, idle
    assert pa.phase == "idle"
    pa.submit(ParamRequest.read(0x37), now)
    assert pa.phase == "load"
    assert pa.feed(resp(fmt, "", 0x00), now) is None          # settled once: toggle
    assert pa.phase == "wait" and pa.hs == 1


def test_read_completes_on_status_11_with_our_hs():
    pa = ParamAccess(EXT2)
    drive_to_wait(pa, EXT2)
    assert pa.outputs()[-1] == 0x80 and pa.outputs()[0] == FC_READ
    assert pa.feed(resp(EXT2, "03 00 37 02 12 34", 0x40), 0.1) is None     # STATUS 10: busy
    r = pa.feed(resp(EXT2, "03 00 37 02 12 34", 0xE0), 0.2)                # HS 1, STATUS 11
    assert r.ok and r.values == [0x1234] and r.request == ParamRequest.read(0x37)
    assert pa.phase == "idle" and not pa.busy
    assert pa.outputs() == bytes(7) + b"\x80"                                # 00h, HS held


def test_status_11_with_the_old_hs_is_not_the_answer():
    pa = ParamAccess(EXT2)
    drive_to_wait(pa, EXT2)
    assert pa.feed(resp(EXT2, "03 00 37 02 12 34", 0x60), 0.1) is None     # HS 0: stale
    assert pa.busy


def test_error_reply_text():
    pa = ParamAccess(EXT2)
    drive_to_wait(pa, EXT2)
    r = pa.feed(resp(EXT2, "83 00 00 00 00 02", 0xE0), 0.1)
    assert not r.ok and r.error_code == 0x02
    assert r.message == ("read 0x0037: read refused, error 0x02 address error: the drive has no "
                         "such register (the manual: start address above 600h)")
    pa2 = ParamAccess(EXT2)
    drive_to_wait(pa2, EXT2)
    r2 = pa2.feed(resp(EXT2, "85 00 00 00 00 01", 0xE0), 0.1)
    assert r2.message.startswith("read 0x0037: function 0x05 refused, error 0x01 function error")


def test_reply_for_another_register_is_refused():
    pa = ParamAccess(EXT2)
    drive_to_wait(pa, EXT2)
    r = pa.feed(resp(EXT2, "03 00 38 02 12 34", 0xE0), 0.1)
    assert not r.ok and r.message == ("read 0x0037: the reply (function 0x03, register 0x0038) "
                                      "does not match the request")
    pa2 = ParamAccess(EXT2)
    drive_to_wait(pa2, EXT2)
    r2 = pa2.feed(resp(EXT2, "10 00 37 02 12 34", 0xE0), 0.1)
    assert not r2.ok and "(function 0x10, register 0x0037)" in r2.message


def test_write_reply_has_no_values():
    pa = ParamAccess(EXT2)
    pa.feed(resp(EXT2, "", 0x00), 0.0)
    pa.submit(ParamRequest.write(0x37, [5]), 0.0)
    pa.feed(resp(EXT2, "", 0x00), 0.0)
    r = pa.feed(resp(EXT2, "10 00 37 02", 0xE0), 0.1)
    assert r.ok and r.values == []


def test_settle_cycles_are_counted():
    pa = ParamAccess(EXT2, settle_cycles=3)
    pa.feed(resp(EXT2, "", 0x00), 0.0)
    pa.submit(ParamRequest.read(0x37), 0.0)
    pa.feed(resp(EXT2, "", 0x00), 0.0)
    pa.feed(resp(EXT2, "", 0x00), 0.0)
    assert pa.phase == "load" and pa.hs == 0
    pa.feed(resp(EXT2, "", 0x00), 0.0)
    assert pa.phase == "wait" and pa.hs == 1


def test_hs_moving_under_a_loaded_request_goes_back_to_align():
    pa = ParamAccess(EXT2, settle_cycles=2)
    pa.feed(resp(EXT2, "", 0x00), 0.0)
    pa.submit(ParamRequest.read(0x37), 0.0)
    pa.feed(resp(EXT2, "", 0x00), 0.0)                      # settled 1 of 2
    pa.feed(resp(EXT2, "", 0x80), 0.0)                      # the option's HS moved
    assert pa.phase == "align" and pa.outputs()[0] == 0     # 00h while realigning
    pa.feed(resp(EXT2, "", 0x80), 0.0)                      # take over HS 1
    assert pa.hs == 1 and pa.realignments == 1
    pa.feed(resp(EXT2, "", 0x80), 0.0)                      # aligned: load again, count from 0
    assert pa.phase == "load"
    pa.feed(resp(EXT2, "", 0x80), 0.0)
    assert pa.phase == "load"                               # 1 of 2 again
    pa.feed(resp(EXT2, "", 0x80), 0.0)
    assert pa.phase == "wait" and pa.hs == 0


def test_realignment_holds_two_cycles_against_a_late_echo():
    pa = ParamAccess(EXT2)
    pa.feed(resp(EXT2, "", 0x80), 0.0)                      # HS 1 != ours: take it over
    assert pa.hs == 1 and pa.realignments == 1
    pa.feed(resp(EXT2, "", 0x00), 0.0)                      # late echo of 0: held (1)
    pa.feed(resp(EXT2, "", 0x00), 0.0)                      # held (2)
    assert pa.hs == 1 and pa.realignments == 1
    pa.feed(resp(EXT2, "", 0x00), 0.0)                      # still 0: now realign
    assert pa.hs == 0 and pa.realignments == 2


def test_agreement_clears_the_hold():
    pa = ParamAccess(EXT2)
    pa.feed(resp(EXT2, "", 0x80), 0.0)                      # take over 1, hold 2
    pa.feed(resp(EXT2, "", 0x80), 0.0)                      # agrees: hold cleared, idle
    assert pa.phase == "idle"
    pa.feed(resp(EXT2, "", 0x00), 0.0)                      # moves: realign at once
    assert pa.hs == 0 and pa.realignments == 2


def test_a_running_request_is_left_to_finish_while_aligning():
    pa = ParamAccess(EXT2)
    pa.feed(resp(EXT2, "", 0xA0), 0.0)                      # HS 1, STATUS 01: in progress
    assert pa.hs == 0 and pa.realignments == 0 and pa.phase == "align"
    pa.feed(resp(EXT2, "", 0xC0), 0.0)                      # STATUS 10: still
    assert pa.hs == 0 and pa.realignments == 0


@pytest.mark.parametrize("steps, where", [
    (0, "waiting for the option's handshake to settle"),
    (1, "loading the request"),
    (2, "waiting for STATUS 11 with our HS"),
])
def test_timeout_texts_per_phase(steps, where):
    pa = ParamAccess(EXT2, timeout=0.5, settle_cycles=5)
    if steps == 0:
        pa.submit(ParamRequest.read(0x37), 0.0)
        pa.feed(resp(EXT2, "", 0xA0), 0.0)                  # option busy: stays in align
    else:
        pa.feed(resp(EXT2, "", 0x00), 0.0)
        pa.submit(ParamRequest.read(0x37), 0.0)
        if steps == 2:
            pa.settle_cycles = 1
            pa.feed(resp(EXT2, "", 0x00), 0.0)
            assert pa.phase == "wait"
    busy = 0xA0 if steps == 0 else 0x00                   # keeps each phase where it is
    assert pa.feed(resp(EXT2, "", busy | 0x02), 0.5) is None       # at the deadline: waiting
    r = pa.feed(resp(EXT2, "", busy | 0x04), 0.6)
    assert r is not None and r.timeout and not r.ok
    assert r.message == f"read 0x0037: no reply within 0.5 s ({where})"   # the WD counter moved
    assert pa.phase == "align" and not pa.busy


def test_frozen_watchdog_is_named_after_more_than_0_2_s():
    pa = ParamAccess(EXT2, timeout=0.1)
    pa.feed(resp(EXT2, "", 0x02), 0.0)                      # WD 1, never changes
    pa.submit(ParamRequest.read(0x37), 0.0)
    r = None
    t = 0.0
    while r is None:
        t += 0.05
        r = pa.feed(resp(EXT2, "", 0x42), t)
    assert t < 0.2 + 1e-9 and "frozen" not in r.message   # timed out before 0.2 s of freeze
    pa2 = ParamAccess(EXT2, timeout=0.3)
    pa2.feed(resp(EXT2, "", 0x02), 0.0)
    pa2.submit(ParamRequest.read(0x37), 0.0)
    r2 = None
    t = 0.0
    while r2 is None:
        t += 0.05
        r2 = pa2.feed(resp(EXT2, "", 0x42), t)
    assert r2.message.endswith("; the handshake watchdog counter is frozen: the option CPU may have stopped")


def test_four_register_write_fills_data_1_to_4_msb_first():
    # spec §4 / E4: data words from byte 4 of the area (bytes 20-27 of the image), MSB first
    a = encode_param_area(EXT1, ParamRequest.write(0x0100, [0x1234, 0x5678, 0x9ABC, 0xDEF0]), 1)
    assert a == h("10 01 00 08 12 34 56 78 9A BC DE F0 00 00 00 80")


def test_failed_results_carry_request_and_ok_false():
    for area_text in ("83 00 00 00 00 02", "03 00 38 02 12 34"):
        pa = ParamAccess(EXT2)
        drive_to_wait(pa, EXT2)
        r = pa.feed(resp(EXT2, area_text, 0xE0), 0.1)
        assert r.ok is False and r.request == ParamRequest.read(0x37)
    pa = ParamAccess(EXT2, timeout=0.1)
    drive_to_wait(pa, EXT2)
    r = pa.feed(resp(EXT2, "", 0x02), 0.2)
    assert r.ok is False and r.timeout is True and r.request == ParamRequest.read(0x37)


def test_watchdog_frozen_note_needs_more_than_0_2_s_and_is_appended():
    pa = ParamAccess(EXT2, timeout=0.15)
    pa.feed(resp(EXT2, "", 0x02), 0.0)                       # WD 1 from t = 0
    pa.submit(ParamRequest.read(0x37), 0.0)
    r = pa.feed(resp(EXT2, "", 0xA2), 0.25)                  # frozen 0.25 s: noted
    assert r.message == ("read 0x0037: no reply within 0.15 s (waiting for the option's handshake "
                         "to settle); the handshake watchdog counter is frozen: the option CPU "
                         "may have stopped")
    pa2 = ParamAccess(EXT2, timeout=0.125)
    pa2.feed(resp(EXT2, "", 0x02), 0.0)
    pa2.submit(ParamRequest.read(0x37), 0.0)
    r2 = pa2.feed(resp(EXT2, "", 0xA2), 0.2)                 # exactly 0.2 s: not yet "frozen"
    assert r2.timeout and "frozen" not in r2.message


def test_a_slow_cycle_never_times_out_a_handshake_still_under_way():
    """Several stations at 9.6k: one round takes 0.3-0.4 s, so the handshake's few exchanges (align,
    settle, toggle, reply: spec §4.7) take longer than timeout_s = 1 s. With min_exchanges = 8
    (twice the 1 + 1 + 1 + 1 of settle_cycles = 1) the request completes; it times out only when
    both the time and the exchanges have run out."""
    pa = ParamAccess(EXT2, timeout=1.0, settle_cycles=1, min_exchanges=8)
    t = 0.0
    assert pa.feed(resp(EXT2, "", 0x00), t) is None           # aligned, idle
    pa.submit(ParamRequest.read(0x37), t)
    t += 0.4
    assert pa.feed(resp(EXT2, "", 0x00), t) is None           # settled once: toggle to HS 1
    assert pa.phase == "wait" and pa.hs == 1
    for _ in range(2):                                        # the option has not answered yet
        t += 0.4
        assert pa.feed(resp(EXT2, "", 0x00), t) is None       # at 0.8 and 1.2 s (> timeout 1 s)
    t += 0.4
    r = pa.feed(resp(EXT2, "03 00 37 02 12 34", 0xE0), t)     # HS 1, STATUS 11: done at 1.6 s
    assert r is not None and r.ok and r.values == [0x1234]
    # and a dead option still times out: after 1 s and 8 exchanges, not before
    pa2 = ParamAccess(EXT2, timeout=1.0, min_exchanges=8)
    pa2.feed(resp(EXT2, "", 0x00), 0.0)
    pa2.submit(ParamRequest.read(0x37), 0.0)
    results = [pa2.feed(resp(EXT2, "", 0xA0 | (2 * i % 32)), 0.4 * (i + 1)) for i in range(8)]
    assert results[:7] == [None] * 7
    assert results[7].timeout and results[7].message == (
        "read 0x0037: no reply within 1 s and 8 exchanges (waiting for the option's handshake to settle)")
