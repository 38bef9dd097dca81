"""DP-V1 class-1 acyclic PDUs (dp/msac1.py) and the master's call (dp/acyclic.py), sans-IO.

Expected octets: the PDU layouts of a public profichip VPC3+ header (DPV1_READ_PDU / DPV1_WRITE_PDU:
function, slot, index, length, data; DPV1_NEG_RES_PDU: function | 0x80, Error_Decode, Error_Code_1,
Error_Code_2; DPV1_FC_READ 0x5E, DPV1_FC_WRITE 0x5F, DPV1_ERRCL_ACCESS 0xB0 + DPV1_ERRCL_ACC_STATE 5),
and the Toshiba E6581738 DP-V1 example: a Write of data record 47 in slot 0 carrying 14 octets has
the header 5F 00 2F 0E."""

import pytest

from profidrive_cli import BusError
from profidrive_cli.dp import msac1 as M
from profidrive_cli.dp.acyclic import C1Call, C1Error, C1Timeout
from profidrive_cli.fdl import frames as F

TOSHIBA_DS47 = bytes.fromhex("01 02 01 01 10 01 03 9F 00 00 06 01 00 00")


def test_pdus_have_the_published_layouts():
    assert M.read_request(0, 47, 240) == bytes.fromhex("5E 00 2F F0")
    assert M.write_request(0, 47, TOSHIBA_DS47) == bytes.fromhex("5F 00 2F 0E") + TOSHIBA_DS47
    assert M.write_response(0, 47, 14) == bytes.fromhex("5F 00 2F 0E")
    assert M.read_response(1, 2, b"\x01\x02") == bytes.fromhex("5E 01 02 02 01 02")
    assert M.error_response(M.READ, 0xB5) == bytes.fromhex("DE 80 B5 00")
    assert M.error_response(M.WRITE, 0xB2) == bytes.fromhex("DF 80 B2 00")


@pytest.mark.parametrize("octets, is_request, text", [
    ("5E 00 2F F0", True, "Read slot 0 index 47 length 240"),
    ("5F 00 2F 02 AA BB", True, "Write slot 0 index 47 length 2: aa bb"),
    ("5F 00 2F 02", False, "Write slot 0 index 47 length 2"),
    ("5E 03 01 01 07", False, "Read slot 3 index 1 length 1: 07"),
    ("DE 80 B5 00", False, "Read error: DPV1 access: state conflict (80 B5 00)"),
    ("DF 80 B0 00", False, "Write error: DPV1 access: invalid index (80 B0 00)"),
    ("DE 80 A9 00", False, "Read error: DPV1 application: feature not supported (80 A9 00)"),
    ("DE 80 C2 00", False, "Read error: DPV1 resource: resource busy (80 C2 00)"),
    ("DE 80 D3 07", False, "Read error: DPV1 user-specific error (80 D3 07)"),
    ("DE FE 00 00", False, "Read error: FMS error (FE 00 00)"),
    ("5C 01 02 09", True, "Alarm_Ack slot 1 alarm type 2 specifier 0x09"),
])
def test_pdus_decode_in_words(octets, is_request, text):
    pdu = M.decode_pdu(bytes.fromhex(octets), is_request)
    assert pdu.describe() == text
    assert pdu.encode() == bytes.fromhex(octets)


@pytest.mark.parametrize("octets, is_request, words", [
    ("", True, "empty"),
    ("5E 00 2F", True, "header of 4"),
    ("5F 00 2F 03 01 02", True, "length 3 but 2 data octets"),
    ("5E 00 2F 02 01 02", True, "2 octets after a Read request header"),
    ("5F 00 2F 01 01", False, "1 octets after a Write response header"),
    ("DE 80 B5", False, "error response of 3 octets"),
    ("DE 80 B5 00", True, "error bit set in a request"),
])
def test_malformed_pdus_say_what(octets, is_request, words):
    with pytest.raises(M.Msac1Error, match=words):
        M.decode_pdu(bytes.fromhex(octets), is_request)


def test_a_read_or_write_carries_at_most_240_octets():
    M.read_request(0, 47, 240)
    with pytest.raises(M.Msac1Error, match="at most 240"):
        M.read_request(0, 47, 241)
    with pytest.raises(M.Msac1Error, match="at most 240"):
        M.write_request(0, 47, bytes(241))
    with pytest.raises(M.Msac1Error, match="slot 255"):
        M.read_request(255, 47, 1)


def _reply(data: bytes, status: int = F.DL) -> F.Frame:
    # the slave's answer: SAPs swapped (from its SAP 51 to the master's 51)
    return F.Frame(F.SD2, 2, 9, F.response_fc(status), data, M.SAP_C1, M.SAP_C1)


def test_a_call_sends_the_pdu_then_polls_until_data_comes():
    call = C1Call(9, M.read_request(0, 47, 240), now=0.0, timeout_s=0.01)
    assert call.request() == bytes.fromhex("5E 00 2F F0")
    assert call.feed(F.SC_FRAME, 0.001) is None                 # acknowledged, not ready
    assert call.request() == b""                                # the poll: SAPs, no DU
    assert call.feed(F.SC_FRAME, 0.002) is None
    assert call.request() == b""
    pdu = call.feed(_reply(bytes.fromhex("5E 00 2F 02 12 34")), 0.003)
    assert pdu is not None and pdu.data == b"\x12\x34"
    assert call.polls == 2


def test_a_negative_answer_is_a_c1_error_and_state_conflict_is_busy():
    call = C1Call(9, M.read_request(0, 47, 240), 0.0, 1.0)
    call.request()
    with pytest.raises(C1Error, match="state conflict") as e:
        call.feed(_reply(bytes.fromhex("DE 80 B5 00")), 0.1)
    assert e.value.busy and e.value.code1 == 0xB5
    call = C1Call(9, M.read_request(0, 47, 240), 0.0, 1.0)
    call.request()
    with pytest.raises(C1Error, match="invalid index") as e:
        call.feed(_reply(bytes.fromhex("DE 80 B0 00")), 0.1)
    assert not e.value.busy


def test_no_answer_within_the_c1_response_timeout_is_a_timeout():
    call = C1Call(9, M.write_request(0, 47, TOSHIBA_DS47), 0.0, 0.01)   # C1_Response_Timeout = 1
    call.request(0.0)
    assert call.feed(F.SC_FRAME, 0.0) is None          # acknowledged at 0: the 10 ms start here
    call.request(0.005)
    assert call.feed(F.SC_FRAME, 0.005) is None
    call.request(0.0101)                               # a poll sent after 0 + 10 ms, still nothing
    with pytest.raises(C1Timeout, match="within 10 ms"):
        call.feed(F.SC_FRAME, 0.0101)
    call = C1Call(9, M.write_request(0, 47, TOSHIBA_DS47), 0.0, 0.01)
    call.request(0.0)
    assert call.feed(None, 0.009) is None          # silence: sent again (request() still the PDU)
    assert call.request(0.009) == M.write_request(0, 47, TOSHIBA_DS47)
    with pytest.raises(C1Timeout):                 # never acknowledged: 10 ms from the first try
        call.feed(None, 0.0101)


def test_the_timeout_counts_from_the_acknowledgement_not_from_the_decision_to_ask():
    """At 19.2k the request telegram (DU 4 + 12 octets, 9 more of frame, 11 bits each) takes
    25 * 11 / 19200 = 14.3 ms, longer than a 10 ms C1_Response_Timeout: the slave's clock starts at
    its acknowledgement, and so does the master's."""
    call = C1Call(9, M.write_request(0, 47, TOSHIBA_DS47), 0.0, 0.01)
    call.request(0.0)
    assert call.feed(F.SC_FRAME, 0.0143) is None       # the ack, 14.3 ms after the decision
    call.request(0.020)                                # a poll within 10 ms of the ack
    assert call.feed(F.SC_FRAME, 0.0235) is None       # not ready: no timeout yet (< 24.3 ms sent)
    call.request(0.024)
    pdu = call.feed(_reply(bytes.fromhex("5F 00 2F 0C")), 0.0275)
    assert pdu is not None and pdu.name.startswith("Write")


def test_a_master_stalled_past_the_deadline_asks_once_more_before_it_gives_up():
    """A loaded machine may sleep through the deadline: the poll sent after it takes the answer the
    slave readied in time; only a poll sent at or after the deadline that finds nothing is a timeout."""
    call = C1Call(9, M.read_request(0, 47, 240), 0.0, 0.01)
    call.request(0.0)
    assert call.feed(F.SC_FRAME, 0.001) is None
    call.request(0.005)                                # sent before 11 ms ...
    assert call.feed(F.SC_FRAME, 5.0) is None          # ... its SC read 5 s later: not late yet
    call.request(5.0)
    pdu = call.feed(_reply(bytes.fromhex("5E 00 2F 02 12 34")), 5.001)
    assert pdu is not None and pdu.data == b"\x12\x34"


def test_a_slave_without_dpv1_answers_rs_and_the_call_says_why():
    call = C1Call(9, M.read_request(0, 47, 240), 0.0, 1.0)
    call.request()
    with pytest.raises(BusError, match="SAP 51 not enabled.*DPV1_Enable"):
        call.feed(_reply(b"", F.RS), 0.1)


def test_an_answer_to_another_function_is_refused():
    call = C1Call(9, M.read_request(0, 47, 240), 0.0, 1.0)
    call.request()
    with pytest.raises(BusError, match="answered with Write"):
        call.feed(_reply(bytes.fromhex("5F 00 2F 02")), 0.1)


def test_a_poll_lost_on_the_line_is_asked_again_even_past_the_deadline():
    """A poll whose telegrams were all lost (noise, its FDL retries spent) says nothing of the
    slave's answer: it is asked again, past the deadline too; SILENT_POLLS (3) in a row end the call."""
    from profidrive_cli.dp.acyclic import SILENT_POLLS
    call = C1Call(9, M.read_request(0, 47, 240), 0.0, 0.01)
    call.request(0.0)
    assert call.feed(F.SC_FRAME, 0.001) is None             # acknowledged: deadline 11 ms
    call.request(0.020)                                      # past it ...
    assert call.feed(None, 0.021) is None                    # ... lost: asked again
    call.request(0.022)
    pdu = call.feed(_reply(bytes.fromhex("5E 00 2F 02 12 34")), 0.023)
    assert pdu is not None and pdu.data == b"\x12\x34"
    call = C1Call(9, M.read_request(0, 47, 240), 0.0, 1.0)
    call.request(0.0)
    assert call.feed(F.SC_FRAME, 0.001) is None
    for k in range(SILENT_POLLS - 1):
        call.request(0.002 + k * 0.001)
        assert call.feed(None, 0.0025 + k * 0.001) is None
    call.request(0.01)
    with pytest.raises(C1Timeout, match="no reply to 3 polls in a row"):
        call.feed(None, 0.011)
    assert SILENT_POLLS == 3
