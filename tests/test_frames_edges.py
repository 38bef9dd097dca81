"""fdl/frames.py at its edges, written against the survivors of a mutation run
(tools/mutation/run.py fdl/frames.py): FC octets built from the reference §2.2 bit table, the
address and length limits of §2, a telegram that does not start at the front of the buffer (the
master's receiver parses at an offset), and the receiver's error details (which octet, how many
to drop: always one, so a real start delimiter inside garbage is found)."""

import pytest

from profidrive_cli.fdl import frames as F


# §2.2 request FC: bit 6 request, bit 5 FCB, bit 4 FCV, bits 3..0 function
@pytest.mark.parametrize("function,fcb,fcv,fc", [
    (13, False, False, 0x4D),       # SRD high
    (13, False, True, 0x5D),        # first SRD with FCV (golden frames 6, 7: 0x5D)
    (13, True, True, 0x7D),         # FCB toggled (golden frame 14: 0x7D)
    (13, True, False, 0x6D),
    (9, False, False, 0x49),        # FDL status (§2.2: FC 0x49)
    (6, False, False, 0x46),        # SDN high: Global_Control (FC 0x46)
    (0x1D, False, False, 0x4D),     # only bits 3..0 of the function are used
])
def test_request_fc_bits(function, fcb, fcv, fc):
    assert F.request_fc(function, fcb=fcb, fcv=fcv) == fc
    assert F.is_request(fc)


# §2.2 response FC: bits 5..4 station type, bits 3..0 status, bit 6 clear
@pytest.mark.parametrize("status,station_type,fc", [
    (8, 0, 0x08), (0, 0, 0x00), (10, 0, 0x0A), (0, 2, 0x20), (0, 3, 0x30), (13, 1, 0x1D),
    (0x18, 0, 0x08),                # only the status's bits 3..0
    (8, 7, 0x38),                   # only the station type's two bits
])
def test_response_fc_bits(status, station_type, fc):
    assert F.response_fc(status, station_type) == fc
    assert not F.is_request(fc)


def test_describe_fc_reserved_codes_and_clock_value():
    assert F.describe_fc(0x41) == "reserved function 1, FCB=0 FCV=0"
    assert F.describe_fc(0xC0) == "CV clock value, FCB=0 FCV=0"     # §2.2: CV is FC 0xC0
    assert F.describe_fc(0x40) == "time event, FCB=0 FCV=0"          # bit 7 clear: TE
    assert F.describe_fc(0xC3) == "SDA low, FCB=0 FCV=0"             # bit 7 with another function
    assert F.describe_fc(0x05) == "reserved status 5 (slave)"
    assert F.describe_fc(0x7D) == "SRD high, FCB=1 FCV=1"


def test_frame_encode_method_is_encode():
    f = F.make(3, 2, 0x5D, b"")
    assert f.encode() == bytes.fromhex("10 03 02 5D 62 16")
    assert f.encode(force_sd2=True) == bytes.fromhex("68 03 03 68 03 02 5D 62 16")
    assert F.make(3, 2, 0x5D, bytes(1)).sd == F.SD2
    assert F.encode(F.Frame(F.SC)) == b"\xE5"


def test_address_limits():
    assert F.encode(F.make(127, 127, 0x46, b"\x00"))[4:6] == b"\x7F\x7F"     # 127 = broadcast
    for da, sa in ((128, 2), (3, 128), (-1, 2), (3, -1)):
        with pytest.raises(ValueError, match=f"address out of range: DA {da} SA {sa}"):
            F.encode(F.make(da, sa, 0x5D, b"\x00"))
    with pytest.raises(ValueError) as e:
        F.encode(F.Frame(F.SD2, 3, 2, 0x5D, b"\x00", dsap=61, ssap=None))
    assert str(e.value) == "a DP telegram carries both SAPs or none"


def test_longest_telegram_le_249():
    """§2: LE 4..249; 246 DU octets after DA SA FC -> LE 249 is the longest telegram."""
    raw = F.encode(F.make(3, 2, 0x5D, bytes(246)))
    assert raw[1] == raw[2] == 249 and len(raw) == 255
    f, used = F.parse(raw)
    assert used == 255 and len(f.data) == 246
    with pytest.raises(ValueError, match=r"telegram too long: 247 DU octets \(max 246\)"):
        F.encode(F.make(3, 2, 0x5D, bytes(247)))


GOOD_SD2 = bytes.fromhex("68 05 05 68 8A 82 6D 3C 3E F3 16")     # Slave_Diag request (golden-frame shape)


@pytest.mark.parametrize("prefix", [b"\x00", b"\x10\x03", bytes(7)])
def test_parse_at_an_offset(prefix):
    buf = prefix + GOOD_SD2 + b"\x77"
    f, used = F.parse(buf, len(prefix))
    assert used == len(GOOD_SD2) and (f.da, f.sa, f.fc, f.dsap, f.ssap) == (10, 2, 0x6D, 60, 62)
    assert f.data == b""                                  # LE 5 = DA SA FC DSAP SSAP; F3 is the FCS
    # every prefix of the telegram at that offset is a valid beginning: more octets are needed
    for n in range(1, len(GOOD_SD2)):
        assert F.parse(prefix + GOOD_SD2[:n], len(prefix)) is F.NEED_MORE, n
    assert F.parse(buf, len(buf)) is F.NEED_MORE


@pytest.mark.parametrize("raw,detail", [
    ("68 03", "LE 3 outside 4..249"),                  # known bad after two octets
    ("68 FA", "LE 250 outside 4..249"),
    ("68 04", None),                                   # LE 4 and 249 are fine so far
    ("68 F9", None),
    ("68 05 06", "LE != LEr"),                         # known bad after three octets
    ("68 05 05", None),
    ("68 05 06 68 8A 82 6D 3C 3E F3 16", "LE 5 != LEr 6"),
    ("68 FA FA 68", "LE 250 outside 4..249"),
    ("68 05 05 10 8A 82 6D 3C 3E F3 16", "second SD2 missing"),
])
def test_sd2_header_errors_name_the_octet_and_drop_one(raw, detail):
    for prefix in (b"", b"\xE5\x00"):
        r = F.parse(prefix + bytes.fromhex(raw), len(prefix))
        if detail is None:
            assert r is F.NEED_MORE
        else:
            assert isinstance(r, F.FrameError) and r.kind == F.FrameError.LENGTH
            assert r.detail == detail and r.used == 1


def test_fc_defaults():
    assert F.request_fc(F.SRD_HIGH) == 0x4D          # FCB and FCV clear unless asked
    assert F.response_fc(F.DL) == 0x08               # station type: slave unless asked


def test_sd2_second_delimiter_checked_as_soon_as_it_arrives():
    r = F.parse(bytes.fromhex("68 05 05 10"))
    assert isinstance(r, F.FrameError) and r.detail == "second SD2 missing" and r.used == 1


@pytest.mark.parametrize("raw,kind,detail", [
    ("77", F.FrameError.GARBAGE, "0x77 is no start delimiter"),
    ("10 22 02 49 6C 16", F.FrameError.FCS, "FCS 0x6C wrong"),                 # sum is 0x6D
    ("10 22 02 49 6D 00", F.FrameError.ED, "end delimiter 0x00"),
    ("10 A2 02 49 ED 16", F.FrameError.SAP, "DSAP announced but missing"),     # DA ext, no DU
    ("10 22 82 49 ED 16", F.FrameError.SAP, "SSAP announced but missing"),     # SA ext, no DU
    ("68 04 04 68 A2 82 49 3C A9 16", F.FrameError.SAP, "SSAP announced but missing"),  # DSAP only
])
def test_receiver_errors_say_what_and_drop_one_octet(raw, kind, detail):
    r = F.parse(bytes.fromhex(raw))
    assert isinstance(r, F.FrameError)
    assert (r.kind, r.detail, r.used) == (kind, detail, 1)


# F.missing: octets still to come for the telegram at buf[pos]; §2 lengths: SD1 6, SD3 14, SD4 3,
# SD2 LE + 6 (7 at least while LE is unknown); 1 for anything else; 0 for nothing
@pytest.mark.parametrize("raw,pos,left", [
    ("", 0, 0), ("10", 0, 5), ("10 03 02", 0, 3), ("A2", 0, 13), ("DC 03", 0, 1), ("DC", 0, 2),
    ("68", 0, 6), ("68 05", 0, 9), ("68 05 05 68 8A 82 6D 3C 3E F3", 0, 1), ("E5", 0, 1),
    ("77", 0, 1), ("00 00 10", 2, 5), ("00 68 05", 1, 9), ("00 00", 2, 0),
    ("10 03 02 49 4E 16", 0, 1),                     # complete: still at least 1
])
def test_missing_octets(raw, pos, left):
    assert F.missing(bytes.fromhex(raw), pos) == left
    if pos == 0:
        assert F.missing(bytes.fromhex(raw)) == left          # the telegram starts at the front
