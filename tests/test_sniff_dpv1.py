"""`pdrive sniff` on DP-V1 acyclic telegrams (issue 39, "Dissector and sniff"): one DS47 parameter read
as a master runs it, a negative answer, a published change request, an alarm acknowledgement and a
class-2 Initiate, against lines and objects written by hand from the octets.

The telegrams (bus reference ../shared/spec/profibus-dp-reference.md §2): SD2 LE LEr SD2 DA SA FC DSAP
SSAP DU FCS ED, DA / SA with bit 7 set (SAPs follow), LE = 3 + 2 + len(DU), FCS = sum(DA .. DU) mod
256. The master 2 sends its class-1 request to the slave 5's SAP 51 from its own SAP 51 (0x33) in an
SRD high (FC 0x40 | FCB 0x20 | FCV 0x10 | 13 = 0x7D, FCB=0: 0x5D); the slave answers SC (E5) while
it works, the master polls with the same SAPs and no data, the slave answers DL (FC 0x08) with the
SAPs swapped and the answer PDU.

MSAC_C1 PDUs (a public profichip VPC3+ header, section "11 DPV1"; the TMG i-tec DPC1 stack): Read
0x5E / Write 0x5F slot index length [data], a negative answer function | 0x80, Error_Decode 0x80
(DPV1), Error_Code_1 = class << 4 | code: 0xB5 = class 0xB access, code 5 state conflict.

DS47 (PROFIdrive profile, base mode parameter access): request reference, request ID (1 request, 2
change), axis, number of parameters; per parameter attribute (0x10 value), number of elements, PNU
(2 octets), subindex (2 octets); a change request then format, number of values, values. A response:
reference, response ID (1 request parameter +), axis, number of parameters, then format, number of
values, values. Here: request 1 reads PNU 964 = 0x03C4 subindex 0 of axis 1; its answer is format
0x42 (Word), one value 0x002A = 42. The Toshiba E6581738 manual's change request sets PNU 0x039F =
927 subindex 0 to 0 (format 0x06 Unsigned16, one value 0x0000) in a Write of 14 octets (0x0E).

A raw file carries no times: every line is at 0.000000.
"""

from __future__ import annotations

import json

import pytest

from conftest import run_main


def h(text: str) -> bytes:
    return bytes.fromhex(text)


# FCS by hand, e.g. 85+82+7D+33+33+5F+00+2F+0A+01+01+01+01+10+01+03+C4+00+00 = 0x35E -> 0x5E
WRITE_964 = h("68 13 13 68 85 82 7D 33 33 5F 00 2F 0A 01 01 01 01 10 01 03 C4 00 00 5E 16")
SC = h("E5")
POLL_0 = h("68 05 05 68 85 82 5D 33 33 CA 16")            # 85+82+5D+33+33 = 0x1CA
WRITE_RES = h("68 09 09 68 82 85 08 33 33 5F 00 2F 0A 0D 16")   # 0x20D
READ_REQ = h("68 09 09 68 85 82 7D 33 33 5E 00 2F F0 67 16")    # 0x367
READ_RES = h("68 11 11 68 82 85 08 33 33 5E 00 2F 08 01 01 01 01 42 01 00 2A 7B 16")  # 0x27B
READ_REQ_AGAIN = READ_REQ                                  # FCB 1 again after the poll's 0
ERROR_RES = h("68 09 09 68 82 85 08 33 33 DE 80 B5 00 88 16")   # 0x388
# Toshiba E6581738: 01 02 01 01 10 01 03 9F 00 00 06 01 00 00 in a Write 5F 00 2F 0E; 0x345
WRITE_927 = h("68 17 17 68 85 82 7D 33 33 5F 00 2F 0E 01 02 01 01 10 01 03 9F 00 00 06 01 00 00 45 16")
# Alarm_Ack to the slave's alarm SAP 50 from 51: slot 0, alarm type 1, specifier 0x08; 0x22E
ALARM_ACK = h("68 09 09 68 85 82 5D 32 33 5C 00 01 08 2E 16")
# a class-2 master 1 opens a connection: Initiate (0x57) to SAP 49 from its SAP 48; 0x258
INITIATE = h("68 0B 0B 68 85 81 6D 31 30 57 00 00 00 01 2C 58 16")

# the answer to the read of PNU 964, negative: reference 1, 0x81 (read, negative), axis 1, 1 parameter,
# format 0x44 Error, 1 value: error number 0x0014 ("value impermissible", PROFIdrive error table);
# LE 3 + 2 + 12 = 0x11, 82+85+08+33+33+5E+00+2F+08+01+81+01+01+44+01+00+14 = 0x2E7
READ_RES_NEGATIVE = h("68 11 11 68 82 85 08 33 33 5E 00 2F 08 01 81 01 01 44 01 00 14 E7 16")
# a Read response whose length says 9 but carries 8 octets; 0x27B + 1 = 0x27C
BAD_LENGTH = h("68 11 11 68 82 85 08 33 33 5E 00 2F 09 01 01 01 01 42 01 00 2A 7C 16")
# a Write of index 47 with 2 octets: no DS47 header (4 octets); LE 3 + 2 + 6 = 0x0B,
# 85+82+7D+33+33+5F+00+2F+02+01+01 = 0x27C
SHORT_RECORD = h("68 0B 0B 68 85 82 7D 33 33 5F 00 2F 02 01 01 7C 16")

CAPTURE = [WRITE_964, SC, POLL_0, SC, WRITE_RES, READ_REQ, SC, POLL_0, READ_RES,
           READ_REQ_AGAIN, SC, POLL_0, ERROR_RES, WRITE_927, SC, ALARM_ACK, INITIATE]

T = "    0.000000  "
I = " " * 16
REQ1, REQ0, REP = "SRD high, FCB=1 FCV=1", "SRD high, FCB=0 FCV=1", "DL data low (slave)"
W10 = "Write slot 0 index 47 length 10"
R240 = "Read slot 0 index 47 length 240"
W14 = "Write slot 0 index 47 length 14"
#: the DS47 lines in the parameter codec's words (drives/profidrive/ds47.py describe(): "ref N",
#: read / change / read ok, the axis, PNU[subindex] and the elements; a value with its format, Word
#: in hex as a bit sequence)
DS47_READ_964 = "DS47 parameter request: ref 1 read axis 1: PNU964[0] (1 element)"
DS47_ANSWER_42 = "DS47 parameter response: ref 1 read ok axis 1: Word 0x002A"
DS47_CHANGE_927 = "DS47 parameter request: ref 1 change axis 1: PNU927[0] (1 element) = Unsigned16 0"

#: the whole text output: each frame's line, the decoded lines under it
TEXT = [
    T + f"SD2    2 -> 5   [51->51]  {REQ1}  MSAC_C1 Write request  "
        "5f 00 2f 0a 01 01 01 01 10 01 03 c4 00 00",
    I + f"MSAC_C1 request: {W10}",
    I + DS47_READ_964,
    T + "SC   short acknowledge",
    I + f"MSAC_C1: station 5 took the request ({W10}); the master polls for the answer",
    T + f"SD2    2 -> 5   [51->51]  {REQ0}  MSAC_C1 poll  ",
    I + f"MSAC_C1 poll: the master asks station 5 for the answer to {W10}",
    T + "SC   short acknowledge",
    I + f"MSAC_C1: station 5 has no answer yet ({W10}); the master polls again",
    T + f"SD2    5 -> 2   [51->51]  {REP}  MSAC_C1 Write response  5f 00 2f 0a",
    I + f"MSAC_C1 response: {W10}",
    T + f"SD2    2 -> 5   [51->51]  {REQ1}  MSAC_C1 Read request  5e 00 2f f0",
    I + f"MSAC_C1 request: {R240}",
    T + "SC   short acknowledge",
    I + f"MSAC_C1: station 5 took the request ({R240}); the master polls for the answer",
    T + f"SD2    2 -> 5   [51->51]  {REQ0}  MSAC_C1 poll  ",
    I + f"MSAC_C1 poll: the master asks station 5 for the answer to {R240}",
    T + f"SD2    5 -> 2   [51->51]  {REP}  MSAC_C1 Read response  5e 00 2f 08 01 01 01 01 42 01 00 2a",
    I + "MSAC_C1 response: Read slot 0 index 47 length 8",
    I + DS47_ANSWER_42,
    T + f"SD2    2 -> 5   [51->51]  {REQ1}  MSAC_C1 Read request  5e 00 2f f0",
    I + f"MSAC_C1 request: {R240}",
    T + "SC   short acknowledge",
    I + f"MSAC_C1: station 5 took the request ({R240}); the master polls for the answer",
    T + f"SD2    2 -> 5   [51->51]  {REQ0}  MSAC_C1 poll  ",
    I + f"MSAC_C1 poll: the master asks station 5 for the answer to {R240}",
    T + f"SD2    5 -> 2   [51->51]  {REP}  MSAC_C1 Read error response  de 80 b5 00",
    I + f"MSAC_C1 response: Read error: DPV1 access: state conflict (80 B5 00) (to {R240})",
    T + f"SD2    2 -> 5   [51->51]  {REQ1}  MSAC_C1 Write request  "
        "5f 00 2f 0e 01 02 01 01 10 01 03 9f 00 00 06 01 00 00",
    I + f"MSAC_C1 request: {W14}",
    I + DS47_CHANGE_927,
    T + "SC   short acknowledge",
    I + f"MSAC_C1: station 5 took the request ({W14}); the master polls for the answer",
    T + f"SD2    2 -> 5   [51->50]  {REQ0}  MSAC_C1 Alarm_Ack request  5c 00 01 08",
    I + "MSAC_C1 request: Alarm_Ack slot 0 alarm type 1 specifier 0x08",
    T + "SD2    1 -> 5   [48->49]  SRD high, FCB=1 FCV=0  MSAC_C2 Initiate request  57 00 00 00 01 2c",
    I + "MSAC_C2 Initiate request: 57 00 00 00 01 2c",
]


@pytest.fixture
def capture(tmp_path):
    path = tmp_path / "dpv1.raw"
    path.write_bytes(b"".join(CAPTURE))
    return path


def test_sniff_names_a_ds47_read_telegram_by_telegram(capture, capsys, monkeypatch):
    r = run_main(capsys, monkeypatch, "sniff", "--from-file", capture)
    assert r.exit_code == 0, r.stderr
    assert r.stdout.splitlines() == TEXT


def test_sniff_vv_prints_the_same_words(capture, capsys, monkeypatch):
    """-vv only adds the log (on stderr): the decoded lines are the same."""
    r = run_main(capsys, monkeypatch, "sniff", "--from-file", capture, "-vv")
    assert r.exit_code == 0, r.stderr
    assert r.stdout.splitlines() == TEXT


def test_the_json_decoded_objects(capture, capsys, monkeypatch):
    r = run_main(capsys, monkeypatch, "sniff", "--from-file", capture, "--json")
    assert r.exit_code == 0, r.stderr
    objs = [json.loads(x) for x in r.stdout.splitlines()]
    assert len(objs) == len(CAPTURE)
    assert [o["service"] for o in objs] == [
        "MSAC_C1 Write request", "short acknowledge", "MSAC_C1 poll", "short acknowledge",
        "MSAC_C1 Write response", "MSAC_C1 Read request", "short acknowledge", "MSAC_C1 poll",
        "MSAC_C1 Read response", "MSAC_C1 Read request", "short acknowledge", "MSAC_C1 poll",
        "MSAC_C1 Read error response", "MSAC_C1 Write request", "short acknowledge",
        "MSAC_C1 Alarm_Ack request", "MSAC_C2 Initiate request"]
    # every frame's text is the text output's lines under it
    text = [line[len(I):] for line in TEXT if line.startswith(I)]
    assert [t for o in objs for t in o["decoded"]["text"]] == text
    dec = [o["decoded"] for o in objs]
    c1 = {"service": "MSAC_C1", "sap": 51}
    assert dec[0]["msac"] == {**c1, "kind": "request", "function": "Write", "slot": 0, "index": 47,
                              "length": 10, "data": "01 01 01 01 10 01 03 c4 00 00"}
    assert dec[0]["ds47"] == {"kind": "request", "reference": 1, "request_id": 1,
                              "request": "read", "axis": 1, "count": 1,
                              "parameters": [{"pnu": 964, "subindex": 0, "elements": 1,
                                              "attribute": "value"}]}
    assert dec[1]["msac"] == {**c1, "kind": "ack", "station": 5, "request": W10}
    assert dec[2]["msac"] == {**c1, "kind": "poll", "station": 5, "request": W10}
    assert dec[3]["msac"] == {**c1, "kind": "ack", "station": 5, "request": W10}
    assert dec[4]["msac"] == {**c1, "kind": "response", "function": "Write", "slot": 0, "index": 47,
                              "length": 10, "data": ""}
    assert "ds47" not in dec[4]                   # a Write's answer carries no record
    assert dec[5]["msac"] == {**c1, "kind": "request", "function": "Read", "slot": 0, "index": 47,
                              "length": 240, "data": ""}
    assert "ds47" not in dec[5]
    assert dec[8]["msac"] == {**c1, "kind": "response", "function": "Read", "slot": 0, "index": 47,
                              "length": 8, "data": "01 01 01 01 42 01 00 2a"}
    # the response names PNU 964[0]: the request with reference 1 went by before it
    assert dec[8]["ds47"] == {"kind": "response", "reference": 1, "response_id": 1,
                              "response": "read ok", "axis": 1, "count": 1,
                              "parameters": [{"pnu": 964, "subindex": 0, "format": "Word",
                                              "values": [42]}]}
    assert dec[12]["msac"] == {**c1, "kind": "response", "function": "Read", "error": "80 B5 00",
                               "error_text": "DPV1 access: state conflict (80 B5 00)", "request": R240}
    assert "ds47" not in dec[12]
    assert dec[13]["ds47"] == {"kind": "request", "reference": 1, "request_id": 2,
                               "request": "change", "axis": 1, "count": 1,
                               "parameters": [{"pnu": 927, "subindex": 0, "elements": 1,
                                               "attribute": "value", "format": "Unsigned16",
                                               "values": [0]}]}
    assert dec[15]["msac"] == {"service": "MSAC_C1", "sap": 50, "kind": "request",
                               "function": "Alarm_Ack", "slot": 0, "alarm_type": 1, "specifier": 8}
    assert dec[16]["msac"] == {"service": "MSAC_C2", "sap": 49, "kind": "request",
                               "function": "Initiate", "data": "00 00 00 01 2c"}


def test_an_sc_after_anything_else_stays_a_plain_short_acknowledge(tmp_path, capsys, monkeypatch):
    """Only the telegram right after a request or poll is its acknowledgement: an SC after the
    answer, or after a Data_Exchange that came between, has no decoded line."""
    dx = h("68 05 05 68 05 02 7D 00 00 84 16")               # 05+02+7D+00+00 = 0x84
    path = tmp_path / "c.raw"
    path.write_bytes(READ_REQ + dx + SC + READ_RES + SC)
    r = run_main(capsys, monkeypatch, "sniff", "--from-file", path, "--json")
    assert r.exit_code == 0, r.stderr
    objs = [json.loads(x) for x in r.stdout.splitlines()]
    assert [o["service"] for o in objs] == ["MSAC_C1 Read request", "Data_Exchange",
                                            "short acknowledge", "MSAC_C1 Read response",
                                            "short acknowledge"]
    assert "decoded" not in objs[2] and "decoded" not in objs[4]
    # the answer still names its record: index 47 of a Read response
    assert objs[3]["decoded"]["ds47"]["parameters"] == [{"format": "Word", "values": [42]}]


def test_a_malformed_pdu_and_record_are_said_so(tmp_path, capsys, monkeypatch):
    path = tmp_path / "c.raw"
    path.write_bytes(BAD_LENGTH + SHORT_RECORD)
    r = run_main(capsys, monkeypatch, "sniff", "--from-file", path, "--json")
    assert r.exit_code == 0, r.stderr
    a, b = (json.loads(x)["decoded"] for x in r.stdout.splitlines())
    assert a["msac"]["problem"] == "octet 3: length 9 but 8 data octets follow"
    assert "malformed" in a["text"][0] and "ds47" not in a
    assert b["msac"]["length"] == 2 and b["ds47"]["kind"] == "request" and "problem" in b["ds47"]
    assert b["text"][1].startswith("DS47 parameter request, malformed")


def test_a_negative_parameter_response_names_its_error_and_parameter(tmp_path, capsys, monkeypatch):
    path = tmp_path / "c.raw"
    path.write_bytes(WRITE_964 + READ_RES_NEGATIVE)
    r = run_main(capsys, monkeypatch, "sniff", "--from-file", path, "--json")
    assert r.exit_code == 0, r.stderr
    dec = json.loads(r.stdout.splitlines()[1])["decoded"]
    assert dec["ds47"] == {"kind": "response", "reference": 1, "response_id": 0x81,
                           "response": "read negative", "axis": 1, "count": 1,
                           "parameters": [{"pnu": 964, "subindex": 0, "error": 0x14,
                                           "error_text": "0x14 value impermissible", "extra": None}]}
    assert dec["text"][1] == ("DS47 parameter response: ref 1 read negative axis 1: "
                              "error 0x14 value impermissible")
