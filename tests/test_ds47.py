"""The PROFIdrive DS47 parameter request/response codec (drives/profidrive/ds47.py), sans-IO.

Expected octets come from published examples (the DS47 part of each; the DP-V1 header in front of it
is dp/msac1.py's business) or from a hand calculation written out beside the test:

  - Toshiba E6581738 (PDP003Z, PROFIBUS DP-V1) 6.2 "Example 2": change PNU 927 to 0, its positive
    response and its negative response (length 0x08); the four octets of the negative response's
    error block from the same example in Toshiba E6582051 (PNE001Z) 6.2.3; E6581738 6.4 "Example 4"
    (PNU 1000, subindex 0x0130, format 0x42) and E6582051 6.4.3 (its negative response).
  - SINAMICS Function Manual 06/2012 (6SL3097-4AB10-0BP4) 9.2: the multi-parameter change request
    (reference 0x40, axis 2, p1055 p1056 p1058 p1059) and its response.
  - ABB FPBA-01 user manual, DP-V1 examples 1a, 1b (read), 2a, 2b (change), 3 (read PNU 918 and its
    response); ABB RPBA-01 manual: the positive response to example 1b.
  - Lenze EDS84DMOTPBUS (8400 motec PROFIBUS) "Parameter data transfer": a read response (Integer16,
    0x002B = 43) and the negative read response layout (0x81, format 0x44, 1 value: the error code;
    Lenze i550: 2 values with the additional information). Lenze prints the reference as 0xXX and
    the error code as a placeholder: the values put in here are ours and said so.
  - Yaskawa Sigma-7 PROFINET manual 15.3: PNU 964's published example values.
"""

from __future__ import annotations

import struct

import pytest

from profidrive_cli.drives.profidrive import ds47 as D
from profidrive_cli.drives.profidrive.ds47 import (
    Ds47Error, ParamAddress, ParamFault, ParamRequest, ParamResponse, ParamValues)


def h(text: str) -> bytes:
    return bytes.fromhex(text)


# -- published examples --------------------------------------------------------------------------

# Toshiba E6581738 6.2.1: Write DS47 "5F 00 2F 0E" + these 14 octets
TOSHIBA_CHANGE = h("01 02 01 01  10 01 03 9F 00 00  06 01 00 00")
TOSHIBA_POSITIVE = h("01 02 01 01")                     # 6.2.1 read response, length 0x04
TOSHIBA_NEGATIVE = h("01 82 01 01  44 01 00 01")        # 6.2.2 (length 0x08) / E6582051 6.2.3


def test_toshiba_example_2_change_request_octets():
    req = D.change_request(1, 1, [(ParamAddress(927), ParamValues(D.FORMAT_UNSIGNED16, (0,)))])
    assert req.encode() == TOSHIBA_CHANGE
    assert ParamRequest.decode(TOSHIBA_CHANGE) == req
    assert req.describe() == "ref 1 change axis 1: PNU927[0] (1 element) = Unsigned16 0"


def test_toshiba_example_2_responses():
    pos = ParamResponse.decode(TOSHIBA_POSITIVE)
    assert (pos.reference, pos.response_id, pos.axis, pos.count, pos.items) == (1, 0x02, 1, 1, ())
    assert pos.ok and pos.encode() == TOSHIBA_POSITIVE
    neg = ParamResponse.decode(TOSHIBA_NEGATIVE)
    assert (neg.reference, neg.response_id, neg.axis, neg.count) == (1, 0x82, 1, 1)
    assert not neg.ok
    assert neg.items == (ParamFault(1),)
    assert neg.items[0].text == "0x01 parameter value cannot be changed"
    assert neg.encode() == TOSHIBA_NEGATIVE
    # the simulator's answers to the same request give the published octets
    req = ParamRequest.decode(TOSHIBA_CHANGE)
    assert D.answer(req, []).encode() == TOSHIBA_POSITIVE
    assert D.answer(req, [req.values[0]]).encode() == TOSHIBA_POSITIVE
    assert D.answer(req, [ParamFault(1)]).encode() == TOSHIBA_NEGATIVE


def test_toshiba_example_4_word_format_and_limit_error():
    # E6581738 6.4.1: PNU 1000 (0x03E8) with the inverter parameter 0x0130 as subindex, format 0x42
    octets = h("01 02 01 01  10 01 03 E8 01 30  42 01 00 07")
    req = D.change_request(1, 1, [(ParamAddress(1000, 0x0130), ParamValues(D.FORMAT_WORD, (7,)))])
    assert req.encode() == octets
    assert ParamRequest.decode(octets) == req
    # E6582051 6.4.3: set 256, refused with error number 0x0002
    neg = ParamResponse.decode(h("01 82 01 01  44 01 00 02"))
    assert neg.items == (ParamFault(2),)
    assert neg.items[0].text == "0x02 low or high limit exceeded"


# SINAMICS Function Manual 06/2012, 9.2: p1055 = 1055 = 0x041F, p1056 = 0x0420, p1058 = 0x0422,
# p1059 = 0x0423; values offset 28 (4 + 4 x 6), the last at offset 50 (52 octets in all)
SINAMICS_CHANGE = h(
    "40 02 02 04"
    "10 01 04 1F 00 00  10 01 04 20 00 00  10 01 04 22 00 00  10 01 04 23 00 00"
    "07 01 02 D2 04 04  07 01 02 D2 04 05  08 01 43 96 00 00  08 01 44 16 00 00")


def test_sinamics_multi_parameter_change_request():
    # hand check of the FloatingPoint values: 0x43960000 = 2^8 x 1.171875 = 300.0, 0x44160000 = 600.0
    assert struct.unpack(">f", h("43960000"))[0] == 300.0
    assert struct.unpack(">f", h("44160000"))[0] == 600.0
    req = D.change_request(0x40, 2, [
        (ParamAddress(1055), ParamValues(D.FORMAT_UNSIGNED32, (0x02D20404,))),
        (ParamAddress(1056), ParamValues(D.FORMAT_UNSIGNED32, (0x02D20405,))),
        (ParamAddress(1058), ParamValues(D.FORMAT_FLOAT, (300.0,))),
        (ParamAddress(1059), ParamValues(D.FORMAT_FLOAT, (600.0,))),
    ])
    assert len(SINAMICS_CHANGE) == 52
    assert req.encode() == SINAMICS_CHANGE
    assert ParamRequest.decode(SINAMICS_CHANGE) == req
    res = ParamResponse.decode(h("40 02 02 04"))      # "Request reference mirrored = 40 hex ..."
    assert (res.reference, res.response_id, res.axis, res.count, res.ok) == (0x40, 2, 2, 4, True)
    assert D.answer(req, []) == res


def test_abb_fpba01_read_requests():
    # example 1a: drive parameter 12.04 as PNU 0x0C subindex 4
    assert D.read_request(5, 1, [ParamAddress(0x0C, 4)]).encode() == h("05 01 01 01 10 01 00 0C 00 04")
    # example 1b: 12.04, 20.08, 30.19 in one request
    octets = h("06 01 01 03  10 01 00 0C 00 04  10 01 00 14 00 08  10 01 00 1E 00 13")
    req = ParamRequest.decode(octets)
    assert req.addresses == (ParamAddress(12, 4), ParamAddress(20, 8), ParamAddress(30, 19))
    assert req.encode() == octets
    # example 3: PROFIdrive PNU 918 (0x0396) with number of elements 0
    octets = h("09 01 01 01  10 00 03 96 00 00")
    req = ParamRequest.decode(octets)
    assert req.addresses == (ParamAddress(918, 0, elements=0),)
    assert req.describe() == "ref 9 read axis 1: PNU918[0] (0 elements)"
    assert req.encode() == octets


def test_abb_read_responses():
    # FPBA-01 example 3: station number 3 as a Word
    res = ParamResponse.decode(h("09 01 01 01  42 01 00 03"))
    assert (res.reference, res.response_id, res.axis, res.count) == (9, 0x01, 1, 1)
    assert res.items == (ParamValues(D.FORMAT_WORD, (3,)),)
    assert res.describe() == "ref 9 read ok axis 1: Word 0x0003"
    # RPBA-01: the answer to example 1b, 0x190 (400), 0x384 (900), 0x1F4 (500)
    octets = h("06 01 01 03  42 01 01 90  42 01 03 84  42 01 01 F4")
    res = ParamResponse.decode(octets)
    assert [i.values for i in res.items] == [(400,), (900,), (500,)]
    assert res.encode() == octets
    req = ParamRequest.decode(h("06 01 01 03  10 01 00 0C 00 04  10 01 00 14 00 08  10 01 00 1E 00 13"))
    assert D.answer(req, res.items) == res


def test_abb_fpba01_change_requests():
    # example 2a: 12.02 := 600 (0x0258) as a Word
    octets = h("07 02 01 01  10 01 00 0C 00 02  42 01 02 58")
    req = D.change_request(7, 1, [(ParamAddress(12, 2), ParamValues(D.FORMAT_WORD, (600,)))])
    assert req.encode() == octets and ParamRequest.decode(octets) == req
    # example 2b: 12.02 := 300, 20.08 := 500 (the manual's DP-V1 length octet says 0x14 for these
    # 24 octets, a slip in its header; the DS47 octets are these)
    octets = h("08 02 01 02  10 01 00 0C 00 02  10 01 00 14 00 08  42 01 01 2C  42 01 01 F4")
    req = ParamRequest.decode(octets)
    assert req.values == (ParamValues(0x42, (300,)), ParamValues(0x42, (500,)))
    assert req.encode() == octets


def test_lenze_read_responses():
    # EDS84DMOTPBUS: response to a read, reference 0xXX (0x05 here), axis 0, Integer16 0x002B = 43
    res = ParamResponse.decode(h("05 01 00 01  03 01 00 2B"))
    assert res.items == (ParamValues(D.FORMAT_INTEGER16, (43,)),)
    # Integer16 is signed: 0xFFD5 is -43 (two's complement, by hand: 0x10000 - 0xFFD5 = 0x2B)
    assert ParamResponse.decode(h("05 01 00 01  03 01 FF D5")).items[0] == ParamValues(3, (-43,))
    # the negative read response: 0x81, format 0x44, 1 value (the error code; 0x0000 picked here)
    neg = ParamResponse.decode(h("05 81 00 01  44 01 00 00"))
    assert neg.items == (ParamFault(0),) and not neg.ok
    assert neg.items[0].text == "0x00 impermissible parameter number"
    # i550: 2 values, error code then additional information (0x0011 and 0x0003 picked here)
    neg = ParamResponse.decode(h("05 81 00 01  44 02 00 11 00 03"))
    assert neg.items == (ParamFault(0x11, 3),)
    assert neg.items[0].text == "0x11 request cannot be executed because of operating state"
    assert neg.encode() == h("05 81 00 01  44 02 00 11 00 03")


# -- hand calculations ---------------------------------------------------------------------------

def test_odd_value_octets_are_padded_to_a_word():
    # VisibleString "abc": format 09, 3 values, 61 62 63, pad 00; then Unsigned8 0x2A: 05 01 2A 00
    req = D.change_request(3, 0, [
        (ParamAddress(100, 0, 3), ParamValues(D.FORMAT_VISIBLE_STRING, b"abc")),
        (ParamAddress(101), ParamValues(D.FORMAT_UNSIGNED8, (0x2A,))),
    ])
    octets = h("03 02 00 02  10 03 00 64 00 00  10 01 00 65 00 00  09 03 61 62 63 00  05 01 2A 00")
    assert req.encode() == octets
    assert ParamRequest.decode(octets) == req
    assert req.describe() == ("ref 3 change axis 0: PNU100[0] (3 elements) = VisibleString 'abc'; "
                              "PNU101[0] (1 element) = Unsigned8 42")
    # a missing pad after the very last block is accepted on decode
    assert ParamRequest.decode(octets[:-1]) == req
    # an even number of value octets has no pad: Integer8 -1, -2 -> 02 02 FF FE
    res = ParamResponse(1, D.RESPONSE_READ, 1, 1, (ParamValues(D.FORMAT_INTEGER8, (-1, -2)),))
    assert res.encode() == h("01 01 01 01  02 02 FF FE")


def test_negative_change_response_has_zero_for_the_parameters_changed():
    # hand calculation after SINAMICS G120X table 6-17: parameter 1 changed (40 00), parameter 2
    # refused with 0x14 and the subindex 0x0003 (44 02 00 14 00 03)
    req = D.change_request(0x21, 1, [
        (ParamAddress(1082), ParamValues(D.FORMAT_FLOAT, (50.0,))),
        (ParamAddress(2000, 3), ParamValues(D.FORMAT_UNSIGNED16, (7,))),
    ])
    res = D.answer(req, [req.values[0], ParamFault(0x14, 3)])
    assert res.response_id == 0x82 and not res.ok
    assert res.items == (ParamValues(D.FORMAT_ZERO, ()), ParamFault(0x14, 3))
    assert res.encode() == h("21 82 01 02  40 00  44 02 00 14 00 03")
    assert ParamResponse.decode(res.encode()) == res
    assert res.describe() == ("ref 33 change negative axis 1: Zero; "
                              "error 0x14 value impermissible (additional information 3)")


def test_answer_mirrors_reference_and_axis():
    req = D.read_request(0x7B, 3, [ParamAddress(964, 0, 6), ParamAddress(947, 0, 8)])
    res = D.answer(req, [ParamValues(D.FORMAT_UNSIGNED16, (1, 2, 3, 4, 5, 6)),
                         ParamValues(D.FORMAT_UNSIGNED16, (0,) * 8)])
    assert (res.reference, res.axis, res.response_id, res.count) == (0x7B, 3, 0x01, 2)
    res = D.answer(req, [ParamFault(0), ParamValues(D.FORMAT_UNSIGNED16, (0,) * 8)])
    assert (res.reference, res.axis, res.response_id) == (0x7B, 3, 0x81)
    # a read response may mix values and errors
    assert ParamResponse.decode(res.encode()) == res
    with pytest.raises(Ds47Error):
        D.answer(req, [ParamFault(0)])              # one item for two parameters


def test_device_identification_pnu_964():
    # Yaskawa Sigma-7's published values: manufacturer 0x0111, type 0x0251, version 0201 (decimal),
    # year 2019, day/month 1501, 1 drive object. As a read response (format 06, 6 values), by hand:
    # 201 = 0x00C9, 2019 = 0x07E3, 1501 = 0x05DD
    octets = h("01 01 01 01  06 06  01 11  02 51  00 C9  07 E3  05 DD  00 01")
    res = ParamResponse.decode(octets)
    item = res.items[0]
    assert isinstance(item, ParamValues) and not isinstance(item.values, bytes)
    ident = D.device_identification([int(v) for v in item.values])
    assert ident == {"manufacturer_id": 0x0111, "drive_unit_type": 0x0251, "firmware_version": "2.01",
                     "firmware_year": 2019, "firmware_day": 15, "firmware_month": 1,
                     "firmware_date": "2019-01-15", "drive_objects": 1, "more": ()}
    # five values (no number of drive objects), one past the sixth, a day/month that is no date
    ident = D.device_identification([42, 1, 470, 2016, 3113, 1, 7])
    assert ident["drive_objects"] == 1 and ident["more"] == (7,)
    assert (ident["firmware_day"], ident["firmware_month"], ident["firmware_date"]) == (31, 13, None)
    assert D.device_identification([42, 1, 470, 2016, 3112])["drive_objects"] is None
    with pytest.raises(Ds47Error, match="at least 5 values"):
        D.device_identification([42, 1, 470, 2016])
    assert (D.PNU_DEVICE_ID, D.PNU_FAULT_NUMBER, D.PNU_FAULT_CODE) == (964, 947, 945)


# -- round trips over every format ---------------------------------------------------------------

SAMPLES = {
    0x01: (0, 1), 0x02: (-128, 127, 0), 0x03: (-32768, 32767), 0x04: (-2**31, 2**31 - 1),
    0x05: (0, 255), 0x06: (0, 65535, 3), 0x07: (0, 2**32 - 1), 0x08: (0.5, -1.25, 300.0),
    0x09: b"MOVIDRIVE", 0x0A: b"\x00\xff\x10", 0x0C: (2**48 - 1, 0), 0x32: (2**56 - 1,),
    0x41: (0xA5,), 0x42: (0xBEEF, 1), 0x43: (0xDEADBEEF,),
    **{f: (0, 0x7FFF, 0xFFFF) for f in (0x21, 0x23, 0x24, 0x25, 0x26, 0x28, 0x29, 0x2B)},
    **{f: (0, 2**32 - 1) for f in (0x22, 0x27, 0x2A, 0x2C, 0x34, 0x36)},
    0x35: (2**48 - 1,),
}


def test_every_format_has_a_sample():
    assert set(SAMPLES) == set(D.FORMATS) - {0x0D, 0x40, 0x44}


@pytest.mark.parametrize("fmt", sorted(SAMPLES), ids=lambda f: f"0x{f:02X}")
def test_round_trip_every_format(fmt):
    block = ParamValues(fmt, SAMPLES[fmt])
    req = D.change_request(9, 1, [(ParamAddress(2000, 1, len(SAMPLES[fmt])), block),
                                  (ParamAddress(2001), ParamValues(D.FORMAT_WORD, (1,)))])
    assert ParamRequest.decode(req.encode()) == req
    res = D.answer(D.read_request(9, 1, req.addresses), [block, ParamFault(0x16, 2)])
    assert ParamResponse.decode(res.encode()) == res
    assert block.format_name == D.FORMATS[fmt]
    assert block.describe().startswith(D.FORMATS[fmt])


def test_round_trip_read_request_attributes():
    req = D.read_request(255, 255, [ParamAddress(0xFFFF, 0xFFFF, 234, D.ATTR_DESCRIPTION),
                                    ParamAddress(0, 0, 0, D.ATTR_TEXT),
                                    ParamAddress(964, 0, 1, 0x80)])
    assert ParamRequest.decode(req.encode()) == req
    assert req.describe() == ("ref 255 read axis 255: PNU65535[65535] description (234 elements), "
                              "PNU0[0] text (0 elements), PNU964[0] attribute 0x80 (1 element)")


# -- malformed input -----------------------------------------------------------------------------

@pytest.mark.parametrize("octets, message", [
    ("", "octet 0: short header"),
    ("01 01 01", "octet 3: short header"),
    ("00 01 01 01 10 01 00 01 00 00", "octet 0: request reference 0 outside 1..255"),
    ("01 03 01 01 10 01 00 01 00 00", "octet 1: request id 0x03"),
    ("01 01 01 00", "octet 3: number of parameters 0 outside 1..39"),
    ("01 01 01 28", "octet 3: number of parameters 40 outside 1..39"),
    # the count says 2, one address follows
    ("01 01 01 02 10 01 00 01 00 00", "octet 10: the address of parameter 2 of 2 needs 6 octets, 0 left"),
    # the count says 1, two addresses follow
    ("01 01 01 01 10 01 00 01 00 00 10 01 00 02 00 00", "octet 10: 6 octet(s) after the last parameter"),
    ("01 01 01 01 11 01 00 01 00 00", "octet 4: attribute 0x11 is reserved"),
    ("01 01 01 01 10 EB 00 01 00 00", "octet 5: number of elements 235 outside 0..234"),
    # change request without its value block, with a block running past the end
    ("01 02 01 01 10 01 00 01 00 00", "octet 10: the block of parameter 1 of 1"),
    ("01 02 01 01 10 01 00 01 00 00 07 01 00 00",
     "octet 12: 1 Unsigned32 value(s) of parameter 1 of 1 need 4 octets, 2 left"),
    # a reserved format, an unknown one, TimeDifference without a size
    ("01 02 01 01 10 01 00 01 00 00 0B 01 00 00", "octet 10: format 0x0B is reserved"),
    ("01 02 01 01 10 01 00 01 00 00 45 01 00 00", "octet 10: format 0x45 is reserved"),
    ("01 02 01 01 10 01 00 01 00 00 0D 01 00 00 00 00",
     "octet 10: format 0x0D TimeDifference is not supported"),
    ("01 02 01 01 10 01 00 01 00 00 44 01 00 00",
     "octet 10: parameter 1 of 1 has a 0x44 Error block; a change request carries values"),
    ("01 02 01 01 10 01 00 01 00 00 42 EB", "octet 11: 235 values"),
])
def test_malformed_requests_name_the_octet(octets, message):
    with pytest.raises(Ds47Error) as ei:
        ParamRequest.decode(h(octets))
    assert message in str(ei.value)


@pytest.mark.parametrize("octets, message", [
    ("01 01", "octet 2: short header"),
    ("01 03 01 01", "octet 1: response id 0x03"),
    ("01 02 01 01 44 01 00 01", "octet 4: a positive change response is the header alone, 4 octet(s) follow"),
    ("01 01 01 02 42 01 00 03", "octet 8: the block of parameter 2 of 2"),
    ("01 01 01 01 42 01 00 03 42 01 00 04", "octet 8: 4 octet(s) after the last block"),
    ("01 01 01 01 42 02 00 03", "octet 6: 2 Word value(s) of parameter 1 of 1 need 4 octets, 2 left"),
    ("01 81 01 01 44 03 00 01 00 00 00 00",
     "octet 5: the error block of parameter 1 of 1 carries 1 or 2 values, not 3"),
    ("01 81 01 01 44 02 00 01", "octet 6: the error block of parameter 1 of 1 needs 4 octets, 2 left"),
    ("01 82 01 01 40 01 00 00", "octet 5: the Zero block of parameter 1 of 1 carries no values, not 1"),
    ("01 01 01 01 00 01 00", "octet 4: format 0x00 is reserved"),
])
def test_malformed_responses_name_the_octet(octets, message):
    with pytest.raises(Ds47Error) as ei:
        ParamResponse.decode(h(octets))
    assert message in str(ei.value)


def test_ds47_error_is_a_value_error():
    assert issubclass(Ds47Error, ValueError)


# -- the 240-octet limit and the other ranges on encode ------------------------------------------

def test_39_parameters_fit_40_do_not():
    # 4 + 39 x 6 = 238 octets
    addrs = [ParamAddress(900 + i) for i in range(39)]
    assert len(D.read_request(1, 1, addrs).encode()) == 238
    with pytest.raises(Ds47Error, match="octet 3: number of parameters 40 outside 1..39"):
        D.read_request(1, 1, addrs + [ParamAddress(999)])


def test_a_request_over_240_octets_is_refused():
    # 4 + 6 + 2 + 228 = 240 fits; one octet more (and its pad) does not
    fits = D.change_request(1, 1, [(ParamAddress(5, 0, 228), ParamValues(D.FORMAT_OCTET_STRING, bytes(228)))])
    assert len(fits.encode()) == 240
    with pytest.raises(Ds47Error, match="octet 240: the request takes 242 octets"):
        D.change_request(1, 1, [(ParamAddress(5, 0, 229), ParamValues(D.FORMAT_OCTET_STRING, bytes(229)))])
    with pytest.raises(Ds47Error, match="octet 240"):
        ParamRequest.decode(fits.encode() + bytes(2))


def test_a_read_answer_too_long_becomes_error_0x15():
    # 117 Unsigned16 values: 4 + 2 + 234 = 240 fits; 118 take 242
    req = D.read_request(4, 1, [ParamAddress(980, 0, 118)])
    res = D.answer(req, [ParamValues(D.FORMAT_UNSIGNED16, tuple(range(117)))])
    assert len(res.encode()) == 240 and res.ok
    too_long = ParamResponse(4, D.RESPONSE_READ, 1, 1, (ParamValues(D.FORMAT_UNSIGNED16, tuple(range(118))),))
    with pytest.raises(Ds47Error, match="octet 240: the response takes 242 octets"):
        too_long.encode()
    res = D.answer(req, too_long.items)
    assert res.response_id == 0x81 and res.items == (ParamFault(0x15),)
    assert res.encode() == h("04 81 01 01  44 01 00 15")


@pytest.mark.parametrize("build, message", [
    (lambda: D.read_request(0, 1, [ParamAddress(1)]), "octet 0: request reference 0"),
    (lambda: D.read_request(256, 1, [ParamAddress(1)]), "octet 0: request reference 256"),
    (lambda: D.read_request(1, 256, [ParamAddress(1)]), "octet 2: axis 256"),
    (lambda: D.read_request(1, 1, []), "octet 3: number of parameters 0"),
    (lambda: D.read_request(1, 1, [ParamAddress(65536)]), "octet 6: parameter number 65536"),
    (lambda: D.read_request(1, 1, [ParamAddress(1, 65536)]), "octet 8: subindex 65536"),
    (lambda: D.read_request(1, 1, [ParamAddress(1, 0, 235)]), "octet 5: number of elements 235"),
    (lambda: D.read_request(1, 1, [ParamAddress(1, 0, 1, 0x40)]), "octet 4: attribute 0x40 is reserved"),
    (lambda: D.change_request(1, 1, [(ParamAddress(1), ParamValues(D.FORMAT_INTEGER16, (32768,)))]),
     "parameter 1 of 1, octet 12: 32768 does not fit Integer16 (-32768..32767)"),
    (lambda: D.change_request(1, 1, [(ParamAddress(1), ParamValues(D.FORMAT_UNSIGNED8, (-1,)))]),
     "-1 does not fit Unsigned8 (0..255)"),
    (lambda: D.change_request(1, 1, [(ParamAddress(1), ParamValues(D.FORMAT_WORD, (1.5,)))]),
     "Word value 1.5 is not an integer"),
    (lambda: D.change_request(1, 1, [(ParamAddress(1), ParamValues(D.FORMAT_FLOAT, (1e40,)))]),
     "does not fit FloatingPoint"),
    (lambda: D.change_request(1, 1, [(ParamAddress(1), ParamValues(D.FORMAT_VISIBLE_STRING, (65,)))]),
     "VisibleString values are octets (bytes)"),
    (lambda: D.change_request(1, 1, [(ParamAddress(1), ParamValues(D.FORMAT_WORD, b"\x00\x01"))]),
     "Word values are numbers, not bytes"),
    (lambda: D.change_request(1, 1, [(ParamAddress(1), ParamValues(D.FORMAT_WORD, (0,) * 235))]),
     "235 values, a block carries at most 234"),
    (lambda: D.change_request(1, 1, [(ParamAddress(1), ParamValues(D.FORMAT_ERROR, (1,)))]),
     "format 0x44 Error is a ParamFault"),
    (lambda: D.change_request(1, 1, [(ParamAddress(1), ParamValues(D.FORMAT_ZERO, ()))]),
     "a change request carries values"),
    (lambda: D.change_request(1, 1, [(ParamAddress(1), ParamValues(0x0D, (1,)))]),
     "format 0x0D TimeDifference is not supported"),
    (lambda: ParamRequest(1, D.REQUEST_CHANGE, 1, (ParamAddress(1),)).encode(),
     "one value block per parameter: 1 parameters, 0 blocks"),
    (lambda: ParamRequest(1, D.REQUEST_READ, 1, (ParamAddress(1),), (ParamValues(6, (1,)),)).encode(),
     "a read request carries no values"),
    (lambda: ParamResponse(1, D.RESPONSE_READ, 1, 1, (ParamFault(0),)).encode(),
     "an error block in a positive read response"),
    (lambda: ParamResponse(1, D.RESPONSE_CHANGE_NEGATIVE, 1, 1, (ParamValues(6, (1,)),)).encode(),
     "a negative change response carries Zero or Error blocks, not Unsigned16"),
    (lambda: ParamResponse(1, D.RESPONSE_READ, 1, 2, (ParamValues(6, (1,)),)).encode(),
     "octet 4: 2 parameters, 1 blocks"),
    (lambda: ParamResponse(1, D.RESPONSE_READ_NEGATIVE, 1, 1, (ParamFault(0x10000),)).encode(),
     "error number 65536 outside 0..65535"),
])
def test_encode_refuses_what_the_wire_cannot_carry(build, message):
    with pytest.raises(Ds47Error) as ei:
        build()
    assert message in str(ei.value)


# -- names ---------------------------------------------------------------------------------------

def test_formats_and_errors_as_the_sources_number_them():
    for fmt, name in {0x01: "Boolean", 0x02: "Integer8", 0x03: "Integer16", 0x04: "Integer32",
                      0x05: "Unsigned8", 0x06: "Unsigned16", 0x07: "Unsigned32",
                      0x08: "FloatingPoint", 0x09: "VisibleString", 0x0A: "OctetString",
                      0x40: "Zero", 0x41: "Byte", 0x42: "Word", 0x43: "Double word",
                      0x44: "Error"}.items():
        assert D.FORMATS[fmt] == name
    assert D.ERRORS[0x00] == "impermissible parameter number"
    assert D.ERRORS[0x03] == "faulty subindex"
    assert D.ERRORS[0x17] == "illegal format"
    assert D.ERRORS[0x18] == "number of values inconsistent"
    assert D.ERRORS[0x19] == "axis/DO nonexistent"
    # 0x08, 0x0A, 0x0C..0x0E, 0x10, 0x12, 0x13 are not defined for DS47 (PROFIdrive V2 PKW numbers)
    assert not set(D.ERRORS) & {0x08, 0x0A, 0x0C, 0x0D, 0x0E, 0x10, 0x12, 0x13}
    assert D.error_text(0x11) == "0x11 request cannot be executed because of operating state"
    assert D.error_text(0x08) == "0x08 unknown error number"
    assert D.error_text(0x65) == "0x65 manufacturer-specific error"
    assert D.error_text(0x1234) == "0x1234 unknown error number"
    assert ParamValues(0x7F, ()).format_name == "format 0x7F"
    assert D.INDEX == 47 and (D.REQUEST_READ, D.REQUEST_CHANGE) == (1, 2)
    assert (D.ATTR_VALUE, D.ATTR_DESCRIPTION, D.ATTR_TEXT) == (0x10, 0x20, 0x30)


def test_describe_lines():
    assert D.read_request(1, 1, [ParamAddress(964)]).describe() == "ref 1 read axis 1: PNU964[0] (1 element)"
    res = ParamResponse(2, D.RESPONSE_READ, 1, 1, (ParamValues(D.FORMAT_UNSIGNED16, tuple(range(10))),))
    assert res.describe() == "ref 2 read ok axis 1: Unsigned16 0, 1, 2, 3, 4, 5, 6, 7 ... (10 values)"
    res = ParamResponse(2, D.RESPONSE_READ, 1, 1, (ParamValues(D.FORMAT_OCTET_STRING, b"\x01\xab"),))
    assert res.describe() == "ref 2 read ok axis 1: OctetString 01 ab"
    assert ParamResponse(5, D.RESPONSE_CHANGE, 0, 3, ()).describe() == "ref 5 change ok axis 0: 3 parameters"
