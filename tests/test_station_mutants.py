"""dp/station.py driven directly (sans-IO) with hand-built replies: the start-up machine's
decisions, counters and events, one case per gap mutation testing found (issue 20).

Expected values come from the reference (/work/shared/spec/profibus-dp-reference.md §2, §3):
Set_Prm octets (§3.1 and golden frame 7 of §2.4), Slave_Diag octets (§3.3), the start-up order (§3) and the
response function codes (§2).
"""

import pytest

from profidrive_cli.dp import services as S
from profidrive_cli.dp.station import (ABSENT, CFG, CFG_FAULT, CHECK, DATA_EXCH, FAULT_RETRY_S, LOCKED,
                                       MAX_CHECK_DIAGS, MAX_SILENT, PRM, PRM_FAULT, START, SlaveConfig,
                                       StationMachine)
from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.master import Outcome

IDENT = 0x1234
CFG_2IO = bytes([0x31])        # 2 bytes in + 2 bytes out (reference §3.2)
US = 2                         # our master address


def machine(wd_ms=500.0, cfg=CFG_2IO):
    return StationMachine(3, SlaveConfig(ident=IDENT, cfg=cfg, wd_ms=wd_ms), US)


def reply(data: bytes, status=F.DL) -> Outcome:
    return Outcome("reply", F.Frame(F.SD2, US, 3, F.response_fc(status), data))


def sc() -> Outcome:
    return Outcome("reply", F.Frame(F.SC))


def diag(st1, st2, master, ident=IDENT, st3=0) -> Outcome:
    # octets 0..5 of Slave_Diag (reference §3.3), built by hand
    return reply(bytes([st1, st2, st3, master, ident >> 8, ident & 0xFF]))


# st1/st2 of the reference §3.3 table
NOT_PARAMETERISED = (0x02, 0x05, 0xFF)     # Not_Ready; Prm_Req + always 1; master 0xFF
EXCHANGING = (0x00, 0x0C, US)              # always 1 + WD_On, parameterised by us


def bring_to_dx(sm, now=0.0):
    """Slave_Diag -> Set_Prm -> Chk_Cfg -> Slave_Diag(ready) -> Data_Exchange, by hand."""
    sm.on_outcome(sm.next_request(now), diag(*NOT_PARAMETERISED), now)
    assert sm.state == PRM
    sm.on_outcome(sm.next_request(now), sc(), now)
    assert sm.state == CFG
    sm.on_outcome(sm.next_request(now), sc(), now)
    assert sm.state == CHECK
    sm.on_outcome(sm.next_request(now), diag(*EXCHANGING), now)
    assert sm.state == DATA_EXCH


# -- Set_Prm from SlaveConfig -------------------------------------------------------------------

def test_set_prm_octets_match_the_festo_capture():
    """Reference §2.4 golden frame 7 (Festo CPV, ident 0x0A35): `B8 1E 01 00 0A 35 01` + user prm:
    station status 0xB8 = Lock_Req (bit 7) + Sync_Req (bit 5) + Freeze_Req (bit 4) + WD_On (bit 3),
    watchdog 30 x 10 ms = 300 ms, min TSDR 0, group 0x01."""
    user = bytes.fromhex("00000082000000")
    cfg = SlaveConfig(ident=0x0A35, cfg=b"\x31", user_prm=user, wd_ms=300.0, min_tsdr=0, group=0x01,
                      sync=True, freeze=True)
    du = cfg.set_prm().encode()
    assert du[0] == 0xB8
    assert du[1] * du[2] == 30                     # 30 x 10 ms; how 30 is split is not fixed
    assert du[3:7] == bytes.fromhex("000A3501")
    assert du[7:] == user


def test_set_prm_without_sync_freeze_is_lock_and_watchdog_only():
    # 0x88 = Lock_Req + WD_On (reference §3.1 bits); min TSDR 11 is what masters send (§3.1)
    du = SlaveConfig(ident=0x0F84, cfg=b"\x31", wd_ms=10.0, group=0x01).set_prm().encode()
    assert du == bytes.fromhex("88 01 01 0B 0F 84 01")


# -- restart --------------------------------------------------------------------------------------

def test_rs_in_data_exchange_starts_over_with_both_events():
    sm = machine()
    bring_to_dx(sm)
    ev = sm.on_outcome(sm.next_request(5.0), reply(b"", status=F.RS), 5.0)
    assert sm.state == START
    assert [(e.kind, e.text, e.data) for e in ev] == [
        ("state", "starting over: station left data exchange (RS)", START),
        ("error", "station left data exchange (RS)", None)]
    assert sm.last_error == "station left data exchange (RS)"
    # no delay after RS: the diagnosis is read at once
    assert sm.wait_until == 5.0
    assert sm.next_request(5.0).service == "Slave_Diag"


def test_after_rs_a_silent_diag_does_not_resume_without_set_prm():
    """RS means the station left data exchange (reference §3.6): the start-up runs again, even when
    the diagnosis read after a lost reply still looks like data exchange with us."""
    sm = machine()
    bring_to_dx(sm)
    sm.on_outcome(sm.next_request(0.0), reply(b"", status=F.RS), 0.0)
    assert sm.state == START
    req = sm.next_request(0.0)
    sm.on_outcome(req, Outcome("no answer"), 0.0)
    assert sm.state == ABSENT
    sm.on_outcome(sm.next_request(0.0), diag(*EXCHANGING), 0.0)
    assert sm.state == PRM
    assert sm.counters.reparams == 1


# -- outputs --------------------------------------------------------------------------------------

def test_set_outputs_length_error_names_station_and_sizes():
    sm = machine()
    with pytest.raises(ValueError, match=r"^station 3: outputs must be 2 octets, got 3$"):
        sm.set_outputs(b"\x00\x01\x02")
    sm.set_outputs(b"\x0A\x0B")
    assert sm.outputs == b"\x0A\x0B"


# -- Slave_Diag replies that are no diagnosis ------------------------------------------------------

def test_sc_to_slave_diag_is_one_illegal_reply_and_changes_nothing():
    sm = machine()
    ev = sm.on_outcome(sm.next_request(0.0), sc(), 0.0)
    assert ev == [] and sm.state == START
    assert sm.counters.illegal == 1 and sm.counters.diag_reads == 0
    sm.on_outcome(sm.next_request(0.0), sc(), 0.0)
    assert sm.counters.illegal == 2


def test_empty_diag_reply_is_one_illegal_reply_without_a_decode_error():
    sm = machine()
    sm.on_outcome(sm.next_request(0.0), reply(b""), 0.0)
    assert sm.counters.illegal == 1 and sm.last_error == "" and sm.state == START


def test_short_diag_reply_is_one_illegal_reply_saying_why():
    sm = machine()
    sm.on_outcome(sm.next_request(0.0), reply(bytes(5)), 0.0)
    assert sm.counters.illegal == 1 and sm.counters.diag_reads == 0
    assert sm.last_error == "Slave_Diag reply needs 6 octets, got 5"
    sm.on_outcome(sm.next_request(0.0), reply(bytes(5)), 0.0)
    assert sm.counters.illegal == 2


def test_each_diag_read_counts_once():
    sm = machine()
    sm.on_outcome(sm.next_request(0.0), diag(*NOT_PARAMETERISED), 0.0)
    assert sm.counters.diag_reads == 1 and sm.counters.illegal == 0
    bring_to_dx(machine())
    sm2 = machine()
    bring_to_dx(sm2)
    assert sm2.counters.diag_reads == 2          # the first one and the one that said "ready"


# -- what to send ---------------------------------------------------------------------------------

def test_requests_of_each_step_on_the_wire():
    """Services, SAPs (reference §3: Slave_Diag 60, Set_Prm 61, Chk_Cfg 62, master SAP 62), SRD
    high (function 13, §2.2) and the longest reply in octets (DpRequest.expect): SC (1 octet) for
    Set_Prm and Chk_Cfg, an SD2 frame of 9 + N octets (SD2 LE LEr SD2 DA SA FC, N data, FCS ED)
    for Data_Exchange with N input octets."""
    sm = machine()
    r = sm.next_request(0.0)
    assert (r.service, r.function, r.dsap, r.ssap, r.data) == ("Slave_Diag", 13, 60, 62, b"")
    sm.on_outcome(r, diag(*NOT_PARAMETERISED), 0.0)
    r = sm.next_request(0.0)
    assert (r.service, r.function, r.dsap, r.ssap, r.expect) == ("Set_Prm", 13, 61, 62, 1)
    # Lock_Req + WD_On, 500 ms = 50 x 10 ms, min TSDR 11, ident 0x1234, group 0 (§3.1)
    assert r.data[0] == 0x88 and r.data[1] * r.data[2] == 50
    assert r.data[3:] == bytes.fromhex("0B 12 34 00")
    sm.on_outcome(r, sc(), 0.0)
    r = sm.next_request(0.0)
    assert (r.service, r.function, r.dsap, r.ssap, r.data, r.expect) == \
        ("Chk_Cfg", 13, 62, 62, CFG_2IO, 1)
    sm.on_outcome(r, sc(), 0.0)
    sm.on_outcome(sm.next_request(0.0), diag(*EXCHANGING), 0.0)
    sm.set_outputs(b"\x01\x02")
    r = sm.next_request(0.0)
    assert (r.service, r.function, r.dsap, r.ssap, r.data, r.expect) == \
        ("Data_Exchange", 13, None, None, b"\x01\x02", 2 + 9)


@pytest.mark.parametrize("state", [START, CHECK, CFG_FAULT, PRM_FAULT, LOCKED, ABSENT])
def test_every_waiting_state_reads_the_diagnosis(state):
    sm = machine()
    sm.state = state
    assert sm.next_request(0.0).service == "Slave_Diag"


def test_released_station_gets_nothing():
    sm = machine()
    sm.state = "released"
    assert sm.next_request(100.0) is None


def test_fault_waits_exactly_fault_retry_s():
    sm = machine()
    bring_to_dx(sm)
    sm.restart([], "test", 0.0)
    bring_to_dx_until_check(sm, 10.0)
    ev = sm.on_outcome(sm.next_request(10.0), diag(0x04, 0x04, US), 10.0)     # Cfg_Fault
    assert sm.state == CFG_FAULT
    assert FAULT_RETRY_S == 1.0
    assert sm.wait_until == 11.0
    assert sm.next_request(10.999) is None
    assert sm.next_request(11.0).service == "Slave_Diag"
    assert ("state", "configuration fault", CFG_FAULT) in [(e.kind, e.text, e.data) for e in ev]
    assert sm.last_error == "configuration fault: the station refuses the configuration"


def bring_to_dx_until_check(sm, now):
    sm.on_outcome(sm.next_request(now), diag(*NOT_PARAMETERISED), now)
    sm.on_outcome(sm.next_request(now), sc(), now)
    sm.on_outcome(sm.next_request(now), sc(), now)
    assert sm.state == CHECK


# -- check: waiting until ready ------------------------------------------------------------------

def test_prm_fault_in_check():
    sm = machine()
    bring_to_dx_until_check(sm, 3.0)
    sm.on_outcome(sm.next_request(3.0), diag(0x40, 0x04, US), 3.0)        # st1 bit 6 Prm_Fault
    assert sm.state == PRM_FAULT and sm.wait_until == 4.0
    assert sm.last_error == "parameter fault: the station refuses Set_Prm"


def test_prm_req_in_check_sends_parameters_again():
    sm = machine()
    bring_to_dx_until_check(sm, 0.0)
    sm.on_outcome(sm.next_request(0.0), diag(0x00, 0x05, US), 0.0)       # st2 Prm_Req
    assert sm.state == PRM


def test_ready_clears_the_last_error():
    sm = machine()
    sm.on_outcome(sm.next_request(0.0), diag(*NOT_PARAMETERISED, ident=0x1111), 0.0)
    assert sm.last_error == "station reports ident 0x1111, configured 0x1234"
    sm.on_outcome(sm.next_request(0.0), sc(), 0.0)
    sm.on_outcome(sm.next_request(0.0), sc(), 0.0)
    ev = sm.on_outcome(sm.next_request(0.0), diag(*EXCHANGING), 0.0)
    assert sm.state == DATA_EXCH and sm.last_error == ""
    assert [(e.kind, e.data) for e in ev][-1] == ("state", DATA_EXCH)


def test_never_ready_starts_over_after_max_check_diags_and_counts_afresh():
    assert MAX_CHECK_DIAGS == 20
    sm = machine()
    bring_to_dx_until_check(sm, 0.0)
    not_ready = (0x02, 0x04, US)                  # Station_Not_Ready, parameterised by us
    for _ in range(MAX_CHECK_DIAGS):
        sm.on_outcome(sm.next_request(0.0), diag(*not_ready), 0.0)
    assert sm.state == CHECK
    ev = sm.on_outcome(sm.next_request(0.0), diag(*not_ready), 0.0)
    assert sm.state == START and sm.last_error == "station never became ready"
    assert ("error", "station never became ready") in [(e.kind, e.text) for e in ev]
    # the next Chk_Cfg starts the count again
    bring_to_dx_until_check(sm, 0.0)
    for _ in range(MAX_CHECK_DIAGS):
        sm.on_outcome(sm.next_request(0.0), diag(*not_ready), 0.0)
    assert sm.state == CHECK


# -- Set_Prm / Chk_Cfg answers --------------------------------------------------------------------

def test_positive_sd2_answer_to_set_prm_is_accepted():
    sm = machine()
    sm.on_outcome(sm.next_request(0.0), diag(*NOT_PARAMETERISED), 0.0)
    ev = sm.on_outcome(sm.next_request(0.0), reply(b"", status=F.OK), 0.0)
    assert sm.state == CFG
    assert [(e.kind, e.text, e.data) for e in ev] == [("state", "sending configuration", CFG)]


@pytest.mark.parametrize("service_index, status", [(0, F.RS), (0, F.UE), (1, F.UE)])
def test_negative_answer_to_set_prm_or_chk_cfg_starts_over(service_index, status):
    sm = machine()
    sm.on_outcome(sm.next_request(0.0), diag(*NOT_PARAMETERISED), 0.0)
    if service_index:
        sm.on_outcome(sm.next_request(0.0), sc(), 0.0)
    req = sm.next_request(0.0)
    fc = F.response_fc(status)
    sm.on_outcome(req, reply(b"", status=status), 0.0)
    assert sm.state == START
    assert sm.last_error == f"{req.service} refused: {F.describe_fc(fc)}"


def test_chk_cfg_refused_rs_reads_the_diagnosis_which_names_the_parameter_fault():
    # a slave that found its acknowledged Set_Prm faulty stays in Wait_Prm, where the Chk_Cfg SAP is
    # not enabled: RS (reference §3.3; the learned ET200S, tests/test_small_answers.py). The next
    # request is a Slave_Diag, and its Prm_Fault (st1 bit 6) is the reason given, not the Chk_Cfg.
    sm = machine()
    sm.on_outcome(sm.next_request(0.0), diag(*NOT_PARAMETERISED), 0.0)
    sm.on_outcome(sm.next_request(0.0), sc(), 0.0)                        # Set_Prm acknowledged
    req = sm.next_request(0.0)
    assert req.service == "Chk_Cfg"
    sm.on_outcome(req, reply(b"", status=F.RS), 0.0)
    assert sm.state == CHECK
    assert sm.last_error == f"Chk_Cfg refused: {F.describe_fc(F.response_fc(F.RS))}"
    assert sm.next_request(0.0).service == "Slave_Diag"
    sm.on_outcome(sm.next_request(0.0), diag(0x42, 0x05, 0xFF), 0.0)     # Prm_Fault + Not_Ready, Prm_Req
    assert sm.state == PRM_FAULT
    assert sm.last_error == "parameter fault: the station refuses Set_Prm"


# -- no answer ------------------------------------------------------------------------------------

def test_silence_in_data_exchange_counts_to_max_silent_and_a_reply_resets_it():
    assert MAX_SILENT == 3
    sm = machine()
    bring_to_dx(sm)
    dx = sm.next_request(0.0)
    for _ in range(MAX_SILENT - 1):
        assert sm.on_outcome(dx, Outcome("no answer"), 0.0) == []
    sm.on_outcome(dx, reply(b"\x00\x00"), 0.0)
    for _ in range(MAX_SILENT - 1):
        sm.on_outcome(dx, Outcome("no answer"), 0.0)
    assert sm.state == DATA_EXCH
    ev = sm.on_outcome(dx, Outcome("no answer"), 0.0)
    assert sm.state == ABSENT
    assert [(e.kind, e.text) for e in ev] == [("state", "no answer: reading the diagnosis"),
                                               ("error", "station stopped answering")]
    assert sm.last_error == "station stopped answering"
    # the count starts again after a resume
    sm.on_outcome(sm.next_request(0.0), diag(*EXCHANGING), 0.0)
    assert sm.state == DATA_EXCH
    for _ in range(MAX_SILENT - 1):
        sm.on_outcome(dx, Outcome("no answer"), 0.0)
    assert sm.state == DATA_EXCH


def test_no_answer_in_start_up_goes_absent_once():
    sm = machine()
    sm.on_outcome(sm.next_request(0.0), diag(*NOT_PARAMETERISED), 0.0)
    req = sm.next_request(0.0)
    ev = sm.on_outcome(req, Outcome("no answer"), 0.0)
    assert sm.state == ABSENT and sm.last_error == "no answer to Set_Prm"
    assert [(e.kind, e.text, e.data) for e in ev] == [("state", "no answer", ABSENT)]
    assert sm.on_outcome(sm.next_request(0.0), Outcome("no answer"), 0.0) == []
    assert sm.last_error == "no answer to Set_Prm"


# -- Data_Exchange answers ------------------------------------------------------------------------

@pytest.mark.parametrize("status", [F.DL, F.OK])
def test_inputs_delivered(status):
    sm = machine()
    bring_to_dx(sm)
    ev = sm.on_outcome(sm.next_request(0.0), reply(b"\xAB\xCD", status=status), 0.0)
    assert [(e.kind, e.text, e.data) for e in ev] == [("inputs", "", b"\xAB\xCD")]
    assert sm.inputs == b"\xAB\xCD" and sm.fresh_inputs
    assert sm.counters.data_exchanges == 1
    assert sm.next_request(0.0).service == "Data_Exchange"
    sm.on_outcome(sm.next_request(0.0), reply(b"\x01\x02", status=status), 0.0)
    assert sm.counters.data_exchanges == 2


def test_dh_delivers_inputs_and_reads_the_diagnosis_next():
    sm = machine()
    bring_to_dx(sm)
    sm.on_outcome(sm.next_request(0.0), reply(b"\x01\x02", status=F.DH), 0.0)
    assert sm.inputs == b"\x01\x02"
    assert sm.next_request(0.0).service == "Slave_Diag"
    sm.on_outcome(sm.next_request(0.0), diag(*EXCHANGING), 0.0)
    assert sm.next_request(0.0).service == "Data_Exchange"


def test_wrong_input_length_is_illegal_and_keeps_the_old_inputs():
    sm = machine()
    bring_to_dx(sm)
    ev = sm.on_outcome(sm.next_request(0.0), reply(b"\x01\x02\x03"), 0.0)
    assert sm.inputs == b"\x00\x00" and not sm.fresh_inputs
    assert sm.counters.illegal == 1 and sm.counters.data_exchanges == 0
    assert [(e.kind, e.text) for e in ev] == [("error", "inputs of 3 octets, configured 2")]
    ev = sm.on_outcome(sm.next_request(0.0), sc(), 0.0)      # SC: no inputs at all
    assert sm.counters.illegal == 2
    assert sm.last_error == "inputs of 0 octets, configured 2"


def test_sc_is_the_answer_of_a_station_without_inputs():
    sm = machine(cfg=bytes([0x21]))               # 2 bytes out only (§3.2: bits 5..4 = 10)
    bring_to_dx(sm)
    ev = sm.on_outcome(sm.next_request(0.0), sc(), 0.0)
    assert [(e.kind, e.data) for e in ev] == [("inputs", b"")]
    assert sm.counters.data_exchanges == 1 and sm.counters.illegal == 0


@pytest.mark.parametrize("status, diag_next", [(F.RDL, False), (F.RDH, True)])
def test_rdl_rdh_deliver_nothing(status, diag_next):
    sm = machine()
    bring_to_dx(sm)
    dx = sm.next_request(0.0)
    sm._diag_due = not diag_next          # the answer decides, not what was due before
    assert sm.on_outcome(dx, reply(b"\x01\x02", status=status), 0.0) == []
    assert sm.inputs == b"\x00\x00" and sm.counters.data_exchanges == 0
    assert sm.state == DATA_EXCH
    assert (sm.next_request(0.0).service == "Slave_Diag") is diag_next


def test_rr_is_tried_again_next_cycle():
    sm = machine()
    bring_to_dx(sm)
    assert sm.on_outcome(sm.next_request(0.0), reply(b"", status=F.RR), 0.0) == []
    assert sm.state == DATA_EXCH and sm.last_error == ""


def test_other_negative_answer_starts_over():
    sm = machine()
    bring_to_dx(sm)
    fc = F.response_fc(F.UE)
    sm.on_outcome(sm.next_request(0.0), reply(b"", status=F.UE), 0.0)
    assert sm.state == START
    assert sm.last_error == f"Data_Exchange answered {F.describe_fc(fc)}"


# -- diagnosis in each state ----------------------------------------------------------------------

def test_diag_event_carries_the_decoded_diagnosis():
    sm = machine()
    ev = sm.on_outcome(sm.next_request(0.0), diag(*NOT_PARAMETERISED), 0.0)
    d = ev[0].data
    assert ev[0].kind == "diag" and (d.st1, d.st2, d.master, d.ident) == (0x02, 0x05, 0xFF, IDENT)
    assert ev[0].text == S.SlaveDiag(0x02, 0x05, 0, 0xFF, IDENT).state_words(US)
    assert sm.last_diag == d


@pytest.mark.parametrize("st1, st2, master, locked", [
    (0x80, 0x04, US, True),          # Master_Lock
    (0x00, 0x04, 5, True),           # parameterised by master 5
    (0x00, 0x05, 5, False),          # master 5 but Prm_Req: free to take
    (0x02, 0x05, 0xFF, False),       # never parameterised
])
def test_locked_by_another_master(st1, st2, master, locked):
    sm = machine()
    sm.on_outcome(sm.next_request(7.0), diag(st1, st2, master), 7.0)
    if locked:
        assert sm.state == LOCKED and sm.wait_until == 8.0
        assert sm.last_error == f"locked by master {master}"
    else:
        assert sm.state == PRM and sm.wait_until == 0.0


@pytest.mark.parametrize("st1, st2, stays", [
    (0x00, 0x0C, True),              # ready
    (0x00, 0x0E, True),              # Stat_Diag: not ready but keep exchanging, keep reading diag
    (0x02, 0x0C, False),             # Not_Ready without Stat_Diag
    (0x00, 0x0D, False),             # Prm_Req
])
def test_diag_in_data_exchange(st1, st2, stays):
    sm = machine()
    bring_to_dx(sm)
    sm.on_outcome(sm.next_request(0.0), reply(b"\x00\x00", status=F.DH), 0.0)
    ev = sm.on_outcome(sm.next_request(0.0), diag(st1, st2, US), 0.0)
    if stays:
        assert sm.state == DATA_EXCH
    else:
        assert sm.state == START and sm.last_error == "station needs parameters again"
        assert ("error", "station needs parameters again") in [(e.kind, e.text) for e in ev]


def test_reparams_counted_once_per_start_up_after_data_exchange():
    sm = machine()
    bring_to_dx(sm)
    assert sm.counters.reparams == 0
    sm.on_outcome(sm.next_request(0.0), reply(b"", status=F.RS), 0.0)
    sm.on_outcome(sm.next_request(0.0), diag(*NOT_PARAMETERISED), 0.0)
    assert sm.counters.reparams == 1
    # a failed start-up step retried is not another re-parameterisation
    sm.on_outcome(sm.next_request(0.0), reply(b"", status=F.RS), 0.0)      # Set_Prm refused
    sm.on_outcome(sm.next_request(0.0), diag(*NOT_PARAMETERISED), 0.0)
    assert sm.counters.reparams == 1
    sm.on_outcome(sm.next_request(0.0), sc(), 0.0)
    sm.on_outcome(sm.next_request(0.0), sc(), 0.0)
    sm.on_outcome(sm.next_request(0.0), diag(*EXCHANGING), 0.0)
    assert sm.state == DATA_EXCH
    sm.on_outcome(sm.next_request(0.0), reply(b"", status=F.RS), 0.0)
    sm.on_outcome(sm.next_request(0.0), diag(*NOT_PARAMETERISED), 0.0)
    assert sm.counters.reparams == 2


# -- resume after silence: the diagnosis must say "still exchanging with us" ---------------------

def silent(sm):
    bring_to_dx(sm)
    dx = sm.next_request(0.0)
    for _ in range(MAX_SILENT):
        sm.on_outcome(dx, Outcome("no answer"), 0.0)
    assert sm.state == ABSENT


@pytest.mark.parametrize("st1, st2, master, ident, resumed", [
    (0x00, 0x0C, US, IDENT, True),
    (0x00, 0x0E, US, IDENT, True),           # Stat_Diag: resumed, diag read again next
    (0x01, 0x0C, US, IDENT, False),          # Station_Non_Existent
    (0x02, 0x0C, US, IDENT, False),          # Station_Not_Ready
    (0x04, 0x0C, US, IDENT, False),          # Cfg_Fault
    (0x40, 0x0C, US, IDENT, False),          # Prm_Fault
    (0x80, 0x0C, US, IDENT, False),          # Master_Lock
    (0x00, 0x0D, US, IDENT, False),          # Prm_Req
    (0x00, 0x04, US, IDENT, False),          # WD_On off though we set a watchdog
    (0x00, 0x0C, 0xFF, IDENT, False),        # not parameterised
    (0x00, 0x0C, US, 0x1111, False),         # another ident
])
def test_resume_only_when_the_station_kept_our_parameters(st1, st2, master, ident, resumed):
    sm = machine()
    silent(sm)
    ev = sm.on_outcome(sm.next_request(0.0), diag(st1, st2, master, ident), 0.0)
    if resumed:
        assert sm.state == DATA_EXCH and sm.last_error == "" and sm.counters.reparams == 0
        assert ("state", "data exchange resumed (the station kept it)") in \
            [(e.kind, e.text) for e in ev]
        assert (sm.next_request(0.0).service == "Slave_Diag") is bool(st2 & 0x02)
    else:
        assert sm.state != DATA_EXCH


def test_resume_without_watchdog_needs_wd_on_clear():
    sm = machine(wd_ms=None)
    silent(sm)
    sm.on_outcome(sm.next_request(0.0), diag(0x00, 0x0C, US), 0.0)     # WD_On: not our Set_Prm
    assert sm.state == PRM
    sm2 = machine(wd_ms=None)
    silent(sm2)
    sm2.on_outcome(sm2.next_request(0.0), diag(0x00, 0x04, US), 0.0)
    assert sm2.state == DATA_EXCH


def test_resume_is_decided_by_the_first_diagnosis_only():
    sm = machine()
    silent(sm)
    sm.on_outcome(sm.next_request(0.0), Outcome("no answer"), 0.0)
    sm.on_outcome(sm.next_request(0.0), diag(0x02, 0x05, 0xFF), 0.0)   # watchdog expired
    assert sm.state == PRM and sm.counters.reparams == 1


def test_first_contact_always_parameterises_even_a_station_that_looks_exchanging():
    """A station met for the first time is parameterised, whatever its diagnosis says: only a
    station *we* saw fall silent in Data_Exchange may be resumed (e.g. one left exchanging by an
    earlier pdrive run with another configuration must get our Set_Prm/Chk_Cfg)."""
    sm = machine()
    assert sm.last_diag is None
    sm.on_outcome(sm.next_request(0.0), Outcome("no answer"), 0.0)
    assert sm.state == ABSENT
    sm.on_outcome(sm.next_request(0.0), diag(*EXCHANGING), 0.0)
    assert sm.state == PRM


def test_a_refused_resume_is_not_tried_again_later():
    """Silent -> diag says Prm_Req -> start-up; if Set_Prm then gets no answer and the next
    diagnosis looks like data exchange, the start-up still has to run (Set_Prm never arrived)."""
    sm = machine()
    silent(sm)
    sm.on_outcome(sm.next_request(0.0), diag(0x00, 0x0D, US), 0.0)       # Prm_Req
    assert sm.state == PRM
    sm.on_outcome(sm.next_request(0.0), Outcome("no answer"), 0.0)
    assert sm.state == ABSENT
    sm.on_outcome(sm.next_request(0.0), diag(*EXCHANGING), 0.0)
    assert sm.state == PRM


def test_diag_event_words_name_the_other_master():
    # parameterised by master 5, no Master_Lock bit: locked for us (reference §3.3 octet 3)
    sm = machine()
    ev = sm.on_outcome(sm.next_request(0.0), diag(0x00, 0x04, 5), 0.0)
    assert "locked by master 5" in ev[0].text


def test_master_0xff_means_not_parameterised_not_locked():
    # 0xFF = not parameterised (reference §3.3); st1 Not_Ready, st2 without Prm_Req
    sm = machine()
    sm.on_outcome(sm.next_request(0.0), diag(0x02, 0x04, 0xFF), 0.0)
    assert sm.state == PRM
