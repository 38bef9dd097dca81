"""fdl/master.py sans-IO: octets, FCB, deadlines, retries and counters of the request/reply engine,
against the reference (/work/shared/spec/profibus-dp-reference.md): the golden frames of §2.4, the
FCB rules of §2.3 (first SRD: FCV 0 FCB 1 = FC 0x6D; then FCV 1 with FCB toggling 0x5D / 0x7D; a
retry repeats the FCB; after a request with no valid reply the sequence restarts), the response
status codes of §2.2 (RS 3, RR 2, UE 1, DH 0x0A, RDH 0x0D) and the times of §1.1 / §4 (11 bit per
character, TSYN 33 bit, TSL 100 bit at 19.2k). Times are worked by hand in bit times at 19 200 bit/s.
Written for mutation testing (tools/mutation/run.py fdl/master.py); the fast path keeps its
behaviour (dx_request / dx_feed give what request / feed give).
"""

import pytest

from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.master import (MORE, NO_ANSWER, REPLY, FdlMaster, Outcome, StationCounters,
                                       format_counters)
from profidrive_cli.fdl.timing import BusParams
from profidrive_cli.link.parity import LineOctets

BAUD = 19200
BIT = 1 / BAUD

# §2.4 golden frame 13: Get_Cfg request DA 8+ext, SA 1+ext, FC 0x5D, DSAP 59, SSAP 62; the reply
GET_CFG_REQ = bytes.fromhex("68 05 05 68 88 81 5D 3B 3E DF 16")
GET_CFG_REP = bytes.fromhex("68 08 08 68 81 88 08 3E 3B 00 10 10 AA 16")
# golden frame 4: Slave_Diag request DA 10+ext, SA 2+ext, FC 0x6D (first of a sequence)
DIAG_REQ = bytes.fromhex("68 05 05 68 8A 82 6D 3C 3E F3 16")
# golden frame 10: SD1 reply from station 8 to 2 with FC 0x03 (RS)
RS_REPLY = bytes.fromhex("10 02 08 03 0D 16")


def master(address=2, retries=1, latency=0.0, **kw):
    return FdlMaster(BusParams.for_baud(BAUD, retries=retries, link_latency=latency, **kw), address)


def fc_of(out):
    """The FC octet of a telegram: SD1 / SD3 carry it at 3, SD2 after LE LEr SD DA SA at 6."""
    return out[6] if out[0] == F.SD2 else out[3]


def sd1_reply(da, sa, status):
    return F.encode(F.Frame(F.SD1, da, sa, F.response_fc(status)))


def dl_reply(da, sa, data, status=F.DL):
    return F.encode(F.Frame(F.SD2, da, sa, F.response_fc(status), bytes(data)))


# -- counters ----------------------------------------------------------------------------------------

def test_format_counters():
    assert format_counters(StationCounters()) == "0 req"
    c = StationCounters(requests=12, retries=1, illegal=1)
    assert format_counters(c) == "12 req, 1 retry, 1 illegal"
    c = StationCounters(requests=3, retries=2, no_answer=1, illegal=4, rs=1, rr=2, ue=3, dh=5, reparams=6)
    assert format_counters(c) == ("3 req, 2 retry, 1 no answer, 4 illegal, 1 RS, 2 RR, 3 UE, 5 DH, "
                                  "6 reparam")
    assert format_counters({"requests": 5, "rs": 1, "diag_reads": 9}) == "5 req, 1 RS"
    assert format_counters(None) == "0 req" and format_counters({}) == "0 req"


def test_counters_as_dict_includes_extra():
    c = StationCounters(requests=2)
    c.extra["latency_ms"] = 3
    d = c.as_dict()
    assert d["requests"] == 2 and d["latency_ms"] == 3 and "extra" not in d
    assert set(d) >= {"requests", "retries", "no_answer", "illegal", "rs", "rr", "ue", "reparams",
                      "diag_reads", "data_exchanges", "dh"}
    assert all(d[k] == 0 for k in ("retries", "no_answer", "illegal", "rs", "rr", "ue", "reparams",
                                   "diag_reads", "data_exchanges", "dh"))


def test_master_address_bounds():
    assert FdlMaster(BusParams(), 0).address == 0 and FdlMaster(BusParams(), 125).address == 125
    assert FdlMaster(BusParams()).address == 2
    for bad in (-1, 126):
        with pytest.raises(ValueError) as e:
            FdlMaster(BusParams(), bad)
        assert str(e.value) == f"master address {bad} outside 0..125"


# -- requests: octets, FCB, deadlines ------------------------------------------------------------

def test_golden_get_cfg_request_octets_and_reply():
    fm = master(address=1)
    fm.request(8, F.SRD_HIGH, b"", 59, 62)                    # first request: FC 0x6D
    fm.feed(sd1_reply(1, 8, F.OK), 0.0)
    out, _ = fm.request(8, F.SRD_HIGH, b"", 59, 62, now=1.0)  # second: FCV 1, FCB 0 -> 0x5D
    assert out == GET_CFG_REQ
    res = fm.feed(GET_CFG_REP, 1.01)
    assert res.kind == REPLY and res.frame.data == bytes.fromhex("00 10 10")
    assert (res.frame.dsap, res.frame.ssap) == (62, 59)
    assert not fm.busy


def test_golden_first_request_of_a_sequence():
    fm = master(address=2)
    out, _ = fm.request(10, F.SRD_HIGH, b"", 60, 62)
    assert out == DIAG_REQ


def test_fcb_sequence_and_restart():
    fm = master()
    fcs = []
    for i in range(4):
        out, _ = fm.request(5, F.SRD_HIGH, b"\x00", now=float(i))
        fcs.append(out[6])
        assert fm.feed(sd1_reply(2, 5, F.OK), i + 0.01).kind == REPLY
    assert fcs == [0x6D, 0x5D, 0x7D, 0x5D]
    out, _ = fm.request(5, F.SRD_HIGH, b"\x00", now=10.0)         # FC 0x7D, no reply at all:
    assert out[6] == 0x7D
    assert fm.expire(10.5)[0] == out                              # the retry repeats the FCB
    assert fm.expire(11.0).kind == NO_ANSWER
    out, _ = fm.request(5, F.SRD_HIGH, b"\x00", now=12.0)        # restart: FCV 0, FCB 1
    assert out[6] == 0x6D


def test_fcb_per_station_and_reset():
    fm = master()
    fm.request(5, F.SRD_HIGH, now=0.0)
    fm.feed(sd1_reply(2, 5, F.OK), 0.0)
    out, _ = fm.request(6, F.SRD_HIGH, now=0.0)
    assert fc_of(out) == 0x6D                                     # station 6 starts its own
    fm.feed(sd1_reply(2, 6, F.OK), 0.0)
    assert fc_of(fm.request(5, F.SRD_HIGH, now=0.0)[0]) == 0x5D
    fm.feed(sd1_reply(2, 5, F.OK), 0.0)
    fm.reset_station(5)
    assert fc_of(fm.request(5, F.SRD_HIGH, now=0.0)[0]) == 0x6D
    fm.feed(sd1_reply(2, 5, F.OK), 0.0)
    fm.reset_station(99)                                          # unknown: nothing happens


@pytest.mark.parametrize("function,fc", [(F.FDL_STATUS, 0x49), (F.SRD_LOW, 0x6C), (F.SDA_LOW, 0x63),
                                         (F.SDA_HIGH, 0x65), (F.IDENT, 0x4E)])
def test_fcb_only_for_srd_and_sda(function, fc):
    # SRD / SDA: the first of a sequence, FCV 0 FCB 1; the rest FCV 0 FCB 0 always (§2.3 rules 1, 4)
    fm = master()
    assert fc_of(fm.request(34, function, now=0.0)[0]) == fc
    fm.feed(sd1_reply(2, 34, F.OK), 0.0)
    second = fc_of(fm.request(34, function, now=1.0)[0])
    assert second == (fc if function in (F.FDL_STATUS, F.IDENT) else (fc & 0x0F) | 0x50)


def test_fdl_status_request_is_golden_frame_1_and_keeps_no_fcb():
    fm = master(address=2)
    out, _ = fm.request(34, F.FDL_STATUS, now=0.0)
    assert out == bytes.fromhex("10 22 02 49 6D 16")
    res = fm.feed(bytes.fromhex("10 02 22 00 24 16"), 0.0)           # golden frame 2
    assert res.kind == REPLY and res.frame.fc == 0x00
    assert fc_of(fm.request(34, F.FDL_STATUS, now=1.0)[0]) == 0x49   # still FCV 0 FCB 0
    fm.feed(bytes.fromhex("10 02 22 00 24 16"), 1.0)
    assert fc_of(fm.request(34, F.SRD_HIGH, now=2.0)[0]) == 0x6D      # the SRD sequence untouched


def test_send_no_reply_is_golden_frame_12():
    fm = master(address=1)
    out = fm.send_no_reply(127, F.SDN_HIGH, b"\x00\x00", 58, 62)
    assert out == bytes.fromhex("68 07 07 68 FF 81 46 3A 3E 00 00 3E 16")
    assert not fm.busy and fm.counters == {}


def test_request_deadline_counters_and_busy():
    fm = master(latency=0.002)
    assert not fm.busy
    out, deadline = fm.request(5, F.SRD_HIGH, b"\x01\x02", now=10.0)
    assert len(out) == 11 and fm.busy
    # request 11 chars (121 bit) + TSL 100 bit + latency
    assert deadline == pytest.approx(10.0 + 221 * BIT + 0.002) and fm.deadline == deadline
    assert fm.counters_for(5).requests == 1
    assert fm.counters_for(7).requests == 0 and 7 in fm.counters


def test_sent_restarts_the_timeout_from_the_write():
    fm = master()
    out, d0 = fm.request(5, F.SRD_HIGH, b"", now=0.0)
    d = fm.sent(1.0)
    assert d == pytest.approx(1.0 + (6 * 11 + 100) * BIT) and fm.deadline == d
    fm.feed(sd1_reply(2, 5, F.OK), 1.01)
    assert fm.sent(5.0) == d                                      # nothing pending: unchanged


def test_attempt_and_request_caps():
    fm = master(retries=2, latency=0.001)
    # 11 request chars, TSL 100, the reply of expect + 9 octets (at most 255), TSYN 33, latency
    assert fm.attempt_cap(11, 12) == pytest.approx((121 + 100 + 21 * 11 + 33) * BIT + 0.001)
    assert fm.attempt_cap(11, 250) == pytest.approx((121 + 100 + 255 * 11 + 33) * BIT + 0.001)
    assert fm.attempt_cap(11, 246) == pytest.approx((121 + 100 + 255 * 11 + 33) * BIT + 0.001)
    assert fm.attempt_cap(11, 245) == pytest.approx((121 + 100 + 254 * 11 + 33) * BIT + 0.001)
    assert fm.attempt_cap(11) == fm.attempt_cap(11, 255)
    assert fm.request_cap(11, 12) == pytest.approx(3 * fm.attempt_cap(11, 12))
    assert fm.request_cap(11) == pytest.approx(3 * fm.attempt_cap(11, 255))


# -- replies -------------------------------------------------------------------------------------

@pytest.mark.parametrize("status,counter", [(F.RS, "rs"), (F.RR, "rr"), (F.UE, "ue"), (F.DH, "dh"),
                                            (F.RDH, "dh"), (F.DL, None), (F.OK, None), (F.NR, None)])
def test_reply_status_counters(status, counter):
    fm = master()
    fm.request(8, F.SRD_HIGH, now=0.0)
    res = fm.feed(sd1_reply(2, 8, status), 0.0)
    assert res.kind == REPLY and res.frame.fc & 0x0F == status
    c = fm.counters_for(8).as_dict()
    for k in ("rs", "rr", "ue", "dh"):
        assert c[k] == (1 if k == counter else 0), k


def test_rs_reply_is_golden_frame_10():
    fm = master()
    fm.request(8, F.SRD_HIGH, now=0.0)
    res = fm.feed(RS_REPLY, 0.0)
    assert res == Outcome(REPLY, res.frame, 0, 0) and res.frame.fc == 0x03
    assert fm.counters_for(8).rs == 1


def test_short_confirmation():
    fm = master()
    fm.request(8, F.SRD_HIGH, b"\x01", now=0.0)
    res = fm.feed(bytes([F.SC]), 0.0)
    assert res.kind == REPLY and res.frame.sd == F.SC
    assert fc_of(fm.request(8, F.SRD_HIGH, now=1.0)[0]) == 0x5D    # the SC confirmed the FCB


def test_a_reply_from_another_station_is_illegal_and_the_right_one_taken():
    fm = master()
    fm.request(8, F.SRD_HIGH, now=0.0)
    assert fm.feed(sd1_reply(2, 9, F.OK), 0.0) is None             # from station 9
    assert fm.feed(sd1_reply(3, 8, F.OK), 0.0) is None             # to master 3
    assert fm.feed(F.encode(F.Frame(F.SD1, 8, 2, 0x49)), 0.0) is None   # a request, not a reply
    assert fm.feed(F.encode(F.token(8, 2)), 0.0) is None           # a token
    res = fm.feed(sd1_reply(2, 8, F.OK), 0.0)
    assert res.kind == REPLY and res.illegal == 4 and res.retries == 0
    assert fm.counters_for(8).illegal == 4


def test_noise_before_a_reply_counts_once():
    fm = master()
    fm.request(8, F.SRD_HIGH, now=0.0)
    assert fm.feed(b"\x00\x01\x02", 0.0) is None
    assert fm.feed(b"\x03", 0.0) is None
    res = fm.feed(sd1_reply(2, 8, F.OK), 0.0)
    assert res.kind == REPLY and res.illegal == 1


def test_a_reply_in_pieces_moves_the_deadline_by_the_rest():
    fm = master()
    _, d0 = fm.request(8, F.SRD_HIGH, now=0.0, expect_octets=20)
    rep = dl_reply(2, 8, bytes(12))
    assert fm.feed(rep[:3], 0.001) is None
    assert fm.missing() == len(rep) - 3 and fm.telegram_octets() == len(rep)
    # the rest of the longest reply: expect + 9 octets from now, capped by the attempt
    assert fm.deadline == pytest.approx(0.001 + 29 * 11 * BIT)
    res = fm.feed(rep[3:], 0.01)
    assert res.kind == REPLY and res.frame.data == bytes(12)
    assert fm.missing() == 0 and fm.telegram_octets() == 0


def test_missing_is_zero_when_idle_or_spoilt():
    fm = master()
    assert fm.missing() == 0 and fm.telegram_octets() == 0
    fm.request(8, F.SRD_HIGH, now=0.0)
    assert fm.missing() == 0
    fm.feed(b"\x68\x05\x06\x68", 0.0)                              # LE != LEr: broken
    assert fm.missing() == 0


def test_a_broken_reply_spoils_the_attempt_until_the_line_is_idle():
    fm = master(latency=0.001)
    fm.request(8, F.SRD_HIGH, now=0.0)
    bad = bytearray(sd1_reply(2, 8, F.OK))
    bad[4] ^= 0xFF                                                 # wrong FCS
    assert fm.feed(bytes(bad), 0.002) is None
    idle = (33 + 11) * BIT + 0.001                                 # TSYN + one character + latency
    assert fm.deadline == pytest.approx(max(0.002 + idle, (66 + 100) * BIT + 0.001))
    # the good reply after it is not taken in this attempt
    assert fm.feed(sd1_reply(2, 8, F.OK), 0.004) is None
    assert fm.deadline == pytest.approx(max(0.004 + idle, (66 + 100) * BIT + 0.001))
    retry, d = fm.expire(0.02)
    assert retry == fm._pending and d == pytest.approx(0.02 + (66 + 100) * BIT + 0.001)
    res = fm.feed(sd1_reply(2, 8, F.OK), 0.021)
    assert (res.kind, res.retries, res.illegal) == (REPLY, 1, 1)
    c = fm.counters_for(8)
    assert (c.retries, c.illegal, c.no_answer, c.requests) == (1, 1, 0, 1)


def test_noise_then_a_broken_telegram_counts_once():
    fm = master()
    fm.request(8, F.SRD_HIGH, now=0.0)
    fm.feed(b"\x00\x00", 0.0)
    bad = bytearray(sd1_reply(2, 8, F.OK))
    bad[4] ^= 0xFF
    fm.feed(bytes(bad), 0.0)
    fm.expire(1.0)
    res = fm.feed(sd1_reply(2, 8, F.OK), 1.0)
    # the noise run and the telegram that broke right after it are one corrupt event (the
    # engine's rule, FdlMaster.feed: "not counted twice"), then one retry
    assert (res.illegal, res.retries) == (1, 1)


def test_the_spoilt_deadline_never_passes_the_attempt_cap():
    fm = master()
    fm.request(8, F.SRD_HIGH, now=0.0, expect_octets=12)
    cap = fm.attempt_cap(6, 12)
    bad = bytearray(sd1_reply(2, 8, F.OK))
    bad[4] ^= 0xFF
    fm.feed(bytes(bad), 0.0)
    for t in (0.01, 0.02, 0.03, 0.04, 0.05):
        fm.feed(b"\x55", t)                                        # babble
    assert fm.deadline == pytest.approx(cap)


def test_line_error_octets_spoil_the_attempt():
    fm = master()
    fm.request(8, F.SRD_HIGH, now=0.0)
    rep = sd1_reply(2, 8, F.OK)
    assert fm.feed(LineOctets(rep, (2,)), 0.0) is None
    assert fm.feed(rep, 0.001) is None                             # spoilt until the retry
    fm.expire(0.05)
    res = fm.feed(rep, 0.06)
    assert (res.retries, res.illegal) == (1, 1)


def test_a_complete_reply_before_the_flagged_octet_counts():
    fm = master()
    fm.request(8, F.SRD_HIGH, now=0.0)
    rep = sd1_reply(2, 8, F.OK)
    res = fm.feed(LineOctets(rep + b"\x00", (len(rep),)), 0.0)
    assert res.kind == REPLY and res.illegal == 0


def test_line_error_after_noise_is_not_counted_twice():
    fm = master()
    fm.request(8, F.SRD_HIGH, now=0.0)
    fm.feed(b"\x00", 0.0)                                          # noise: 1
    fm.feed(LineOctets(b"\x00", (0,)), 0.0)                        # flagged noise: still 1
    fm.feed(LineOctets(b"\x10", (0,)), 0.001)                      # spoilt already
    fm.expire(0.05)
    res = fm.feed(sd1_reply(2, 8, F.OK), 0.06)
    assert res.illegal == 1


def test_no_answer_after_every_retry():
    fm = master(retries=2)
    out, _ = fm.request(8, F.SRD_HIGH, b"\x07", now=0.0)
    r1 = fm.expire(0.1)
    r2 = fm.expire(0.2)
    assert r1[0] == out and r2[0] == out
    assert r2[1] == pytest.approx(0.2 + (len(out) * 11 + 100) * BIT)
    res = fm.expire(0.3)
    assert res == Outcome(NO_ANSWER, None, 2, 0)
    c = fm.counters_for(8)
    assert (c.requests, c.retries, c.no_answer) == (1, 2, 1)
    assert not fm.busy and fm.expire(0.4) is None and fm.feed(b"\x10", 0.4) is None


def test_no_answer_without_retries():
    fm = master(retries=0)
    fm.request(8, F.FDL_STATUS, now=0.0)
    assert fm.expire(0.1).kind == NO_ANSWER


def test_abort_forgets_the_request():
    fm = master()
    fm.request(8, F.SRD_HIGH, now=0.0)
    fm.feed(b"\x68\x05", 0.0)
    fm.abort()
    assert not fm.busy and fm.missing() == 0 and fm.expire(1.0) is None


# -- the fast path gives what the general path gives -------------------------------------------------

def test_dx_request_is_request_and_dx_feed_is_feed():
    a, b = master(latency=0.001), master(latency=0.001)
    for i in range(3):
        outs = bytes([i, 2 * i, 3, 4])
        oa, da = a.request(8, F.SRD_HIGH, outs, now=float(i), expect_octets=4 + 9)
        ob = b.dx_request(8, outs, float(i), 4)
        assert ob == oa and b.deadline == pytest.approx(da) and b._hard == pytest.approx(a._hard)
        rep = dl_reply(2, 8, bytes([9, 8, 7, i]))
        assert a.feed(rep, i + 0.01).frame.data == b.dx_feed(rep, i + 0.01) == bytes([9, 8, 7, i])
    assert a.counters_for(8).as_dict() == b.counters_for(8).as_dict()


def test_dx_feed_in_pieces_and_what_it_leaves():
    fm = master()
    fm.dx_request(8, b"\x01\x02", 0.0, 2)
    rep = dl_reply(2, 8, b"\x05\x06")
    assert fm.dx_feed(rep[:4], 0.001) == MORE
    # request 11 octets + TSL, or from now the rest of the longest reply (2 + 9 + 9 octets)
    assert fm.deadline == pytest.approx(max((11 * 11 + 100) * BIT, 0.001 + 20 * 11 * BIT))
    assert fm.dx_feed(rep[4:], 0.002) == b"\x05\x06"
    fm.dx_request(8, b"\x01\x02", 1.0, 2)
    assert fm.dx_feed(sd1_reply(2, 8, F.RS), 1.0) is None          # another telegram: feed() decides
    assert fm.feed(sd1_reply(2, 8, F.RS), 1.0).kind == REPLY
    fm.dx_request(8, b"\x01\x02", 2.0, 2)
    bad = bytearray(dl_reply(2, 8, b"\x05\x06"))
    bad[-2] ^= 1                                                   # FCS
    assert fm.dx_feed(bytes(bad), 2.0) is None
    bad = bytearray(dl_reply(2, 8, b"\x05\x06"))
    bad[-1] = 0x17                                                 # ED
    assert fm.dx_feed(bytes(bad), 2.0) is None
    assert fm.dx_feed(LineOctets(dl_reply(2, 8, b"\x05\x06"), (3,)), 2.0) is None
    assert fm.dx_feed(dl_reply(2, 9, b"\x05\x06"), 2.0) is None     # another station
    fm.abort()
    assert fm.dx_feed(dl_reply(2, 8, b"\x05\x06"), 2.0) is None     # nothing pending


def test_dx_feed_after_a_retry_counts_it():
    fm = master()
    fm.dx_request(8, b"\x01", 0.0, 1)
    fm.expire(0.1)
    assert fm.dx_feed(dl_reply(2, 8, b"\x03"), 0.11) == b"\x03"
    c = fm.counters_for(8)
    assert (c.requests, c.retries, c.illegal) == (1, 1, 0)
    fm.dx_request(8, b"\x01", 1.0, 1)
    fm.feed(b"\x00", 1.0)                                          # noise: one illegal
    assert fm.dx_feed(dl_reply(2, 8, b"\x04"), 1.01) == b"\x04"
    assert (c.requests, c.retries, c.illegal) == (2, 1, 1)


def test_dx_templates_follow_new_params():
    fm = master()
    for i in range(3):                                  # FC 0x6D, 0x5D, 0x7D: three templates
        fm.dx_request(8, b"\x01", 0.0, 1)
        assert fm.dx_feed(dl_reply(2, 8, b"\x03"), 0.0) == b"\x03"
    fm.params = BusParams.for_baud(9600)
    fm.dx_request(8, b"\x01", 0.0, 1)                  # FC 0x5D again: its template is re-timed
    assert fm.deadline == pytest.approx((10 * 11 + 100) / 9600)



# -- counters add up over requests; each kind of bad telegram in one attempt counts ------------------

def test_counters_add_up_over_requests():
    fm = master()
    for i in range(2):
        fm.request(8, F.SRD_HIGH, now=float(i))
        fm.feed(b"\x00", i + 0.001)                                    # noise: 1 illegal
        fm.expire(i + 0.1)                                             # 1 retry
        fm.feed(sd1_reply(2, 8, F.OK), i + 0.11)
    for status in (F.RS, F.RR, F.UE, F.DH, F.RS, F.RR, F.UE, F.RDH):
        fm.request(8, F.SRD_HIGH, now=5.0)
        fm.feed(sd1_reply(2, 8, status), 5.0)
    c = fm.counters_for(8)
    assert (c.requests, c.retries, c.illegal, c.rs, c.rr, c.ue, c.dh) == (10, 2, 2, 2, 2, 2, 2)
    for i in range(2):
        fm.request(8, F.SRD_HIGH, now=10.0 + i)
        fm.feed(b"\x00", 10.0 + i)
        assert fm.expire(10.1 + i)[0]
        assert fm.expire(10.2 + i) == Outcome(NO_ANSWER, None, 1, 1)   # the noise is in the outcome
    assert (c.retries, c.illegal, c.no_answer) == (4, 4, 2)
    for i in range(2):
        fm.dx_request(8, b"\x01", 20.0 + i, 1)
        fm.feed(b"\x00", 20.0 + i)
        assert fm.dx_feed(dl_reply(2, 8, b"\x03"), 20.0 + i) == b"\x03"
    assert c.illegal == 6


def test_every_bad_telegram_of_one_attempt_counts():
    fm = master()
    fm.request(8, F.SRD_HIGH, now=0.0)
    fm.feed(b"\x00", 0.0)                                              # noise          1
    fm.feed(sd1_reply(2, 9, F.OK), 0.0)                                # foreign reply  2
    fm.feed(b"\x00", 0.0)                                              # noise again    3
    res = fm.feed(sd1_reply(2, 8, F.OK), 0.0)
    assert res.illegal == 3
    fm.request(8, F.SRD_HIGH, now=1.0)
    fm.feed(sd1_reply(2, 9, F.OK), 1.0)                                # foreign        1
    bad = bytearray(sd1_reply(2, 8, F.OK))
    bad[4] ^= 0xFF
    fm.feed(bytes(bad), 1.0)                                           # broken         2
    fm.expire(1.1)
    assert fm.feed(sd1_reply(2, 8, F.OK), 1.11).illegal == 2
    fm.request(8, F.SRD_HIGH, now=2.0)
    fm.feed(sd1_reply(2, 9, F.OK), 2.0)                                # foreign        1
    fm.feed(LineOctets(b"\x10", (0,)), 2.0)                            # flagged        2
    fm.expire(2.1)
    assert fm.feed(sd1_reply(2, 8, F.OK), 2.11).illegal == 2


def test_a_token_to_us_is_not_a_reply():
    fm = master()
    fm.request(8, F.SRD_HIGH, now=0.0)
    assert fm.feed(F.encode(F.token(2, 8)), 0.0) is None               # SD4 from station 8 to us
    res = fm.feed(sd1_reply(2, 8, F.OK), 0.0)
    assert res.illegal == 1


def test_a_foreign_and_the_right_reply_in_one_read():
    fm = master()
    fm.request(8, F.SRD_HIGH, now=0.0)
    res = fm.feed(sd1_reply(2, 9, F.OK) + sd1_reply(2, 8, F.OK), 0.0)
    assert res is not None and res.kind == REPLY and res.illegal == 1


def test_after_a_reply_nothing_is_missing():
    fm = master()
    fm.request(8, F.SRD_HIGH, now=0.0)
    res = fm.feed(sd1_reply(2, 8, F.OK) + b"\x68\x05", 0.0)
    assert res.kind == REPLY and not fm.busy
    assert fm.missing() == 0 and fm.telegram_octets() == 0


# -- the times of the idle waits and extensions ---------------------------------------------------------

LAT = 0.001
IDLE = (33 + 11) * BIT + LAT                   # TSYN + one character + latency


def late_master():
    fm = master(latency=LAT)
    fm.request(8, F.SRD_HIGH, now=0.0, expect_octets=12)
    return fm


def broken():
    bad = bytearray(sd1_reply(2, 8, F.OK))
    bad[4] ^= 0xFF
    return bytes(bad)


def test_idle_wait_after_a_broken_telegram():
    # a broken reply at 9 ms: the line must be quiet TSYN + 1 char (+ latency) after it
    fm = late_master()
    fm.feed(broken(), 0.009)
    assert fm.deadline == pytest.approx(0.009 + IDLE)
    fm.feed(b"\x55", 0.012)                                            # more octets: again
    assert fm.deadline == pytest.approx(0.012 + IDLE)


def test_idle_wait_after_a_flagged_octet():
    fm = late_master()
    fm.feed(LineOctets(b"\x68\x05", (0,)), 0.009)
    assert fm.deadline == pytest.approx(0.009 + IDLE)
    fm.feed(LineOctets(b"\x00", (0,)), 0.012)                          # spoilt already
    assert fm.deadline == pytest.approx(0.012 + IDLE)


def test_a_started_reply_waits_for_the_rest_plus_latency():
    fm = late_master()
    rep = dl_reply(2, 8, bytes(12))
    fm.feed(rep[:3], 0.009)
    assert fm.deadline == pytest.approx(0.009 + 21 * 11 * BIT + LAT)  # expect 12 + 9 octets
    fm = master(latency=LAT)
    fm.dx_request(8, bytes(12), 0.0, 12)
    assert fm.dx_feed(rep[:3], 0.009) == MORE
    assert fm.deadline == pytest.approx(0.009 + 30 * 11 * BIT + LAT)  # expect 12 + 9, + 9 octets


def test_a_retry_gets_its_own_attempt_cap():
    fm = late_master()
    cap = fm.attempt_cap(6, 12)
    fm.expire(1.0)
    fm.feed(dl_reply(2, 8, bytes(12))[:3], 1.001)
    assert fm.deadline == pytest.approx(min(1.001 + 21 * 11 * BIT + LAT, 1.0 + cap))
    assert fm.deadline > 1.0


# -- defaults, the fast path's state ----------------------------------------------------------------------

def test_request_default_time_and_no_reply_without_data():
    fm = master()
    _, deadline = fm.request(8, F.SRD_HIGH)
    assert deadline == pytest.approx((6 * 11 + 100) * BIT)            # from t = 0
    # SDN without data is an SD1 telegram: 10 7F 01 46, FCS 7F + 01 + 46 = C6, 16
    assert FdlMaster(BusParams(), 1).send_no_reply(127, F.SDN_HIGH) == bytes.fromhex("10 7F 01 46 C6 16")


def test_dx_feed_is_only_for_dx_requests_and_plain_line_octets():
    fm = master()
    fm.request(8, F.SRD_HIGH, b"\x01", now=0.0)
    assert fm.dx_feed(dl_reply(2, 8, b"\x03"), 0.0) is None           # a general request
    assert fm.feed(dl_reply(2, 8, b"\x03"), 0.0).kind == REPLY
    fm.dx_request(8, b"\x01", 1.0, 1)
    assert fm.dx_feed(LineOctets(dl_reply(2, 8, b"\x03"), ()), 1.0) == b"\x03"   # nothing flagged
    assert not fm.busy


def test_noise_in_each_attempt_counts():
    fm = master()
    fm.request(8, F.SRD_HIGH, now=0.0)
    fm.feed(b"\x00", 0.001)                          # attempt 1: noise
    fm.expire(0.1)
    fm.feed(b"\x00", 0.101)                          # the retry: noise again, a new run
    res = fm.feed(sd1_reply(2, 8, F.OK), 0.102)
    assert (res.retries, res.illegal) == (1, 2)
