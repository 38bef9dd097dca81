"""Chk_Cfg / Get_Cfg identifiers (dp/cfg.py) decoded field by field from the reference §3.2 rules
and its real examples (Janitza UMG96S, Siemens ET200M, SINAMICS G120 telegram 353), written
against the survivors of a mutation run (tools/mutation/run.py dp/cfg.py).

Special format, worked by hand: identifier bits 7..6 say which length octets follow (01 input,
10 output, 11 output then input), bits 3..0 the number of manufacturer octets (15 reserved); a
length octet is bits 5..0 = length - 1, bit 6 words, bit 7 consistency over the whole length."""

import pytest

from profidrive_cli.dp.cfg import CfgError, CfgModule, decode_cfg, parse_hex


def h(text):
    return bytes.fromhex(text)


def test_compact_examples():
    assert decode_cfg(h("11 22 71 F3 F1")) == [
        CfgModule(raw=h("11"), inputs=2),                                        # 2 bytes in
        CfgModule(raw=h("22"), outputs=3),                                       # 3 bytes out
        CfgModule(raw=h("71"), inputs=4, outputs=4, words=True),                 # 2 words in+out
        CfgModule(raw=h("F3"), inputs=8, outputs=8, words=True, consistent=True),
        CfgModule(raw=h("F1"), inputs=4, outputs=4, words=True, consistent=True),
    ]


def test_janitza_two_bytes_out_62_words_in():
    (m,) = decode_cfg(h("C0 01 7D"))
    assert m == CfgModule(raw=h("C0 01 7D"), inputs=124, outputs=2, words=True, consistent=False,
                          special=True, manufacturer=b"", in_words=True, out_words=False)
    assert m.describe() == "2 bytes out, 62 words in"


def test_et200m_one_byte_in_and_three_manufacturer_octets():
    mods = decode_cfg(h("43 00 00 1F C1"))
    assert mods == [CfgModule(raw=h("43 00 00 1F C1"), inputs=1, outputs=0, words=False,
                              consistent=False, special=True, manufacturer=h("00 1F C1"),
                              in_words=False, out_words=None)]
    assert mods[0].describe() == "1 byte in, manufacturer data 00 1f c1"


def test_sinamics_telegram_353():
    pkw, pzd = decode_cfg(h("F3 C3 C1 C1 FD 01 61"))
    assert pkw == CfgModule(raw=h("F3"), inputs=8, outputs=8, words=True, consistent=True)
    assert pzd == CfgModule(raw=h("C3 C1 C1 FD 01 61"), inputs=4, outputs=4, words=True,
                            consistent=True, special=True, manufacturer=h("FD 01 61"),
                            in_words=True, out_words=True)
    assert pzd.describe() == "2 words in+out, consistent, manufacturer data fd 01 61"


@pytest.mark.parametrize("raw,consistent", [("C0 81 01", True), ("C0 01 81", True),
                                            ("C0 01 01", False), ("40 80", True), ("80 80", True)])
def test_special_consistency_from_either_length_octet(raw, consistent):
    (m,) = decode_cfg(h(raw))
    assert m.consistent is consistent


def test_units_may_differ_per_direction():
    (m,) = decode_cfg(h("C0 41 01"))              # 2 words out, 2 bytes in
    assert (m.outputs, m.out_words, m.inputs, m.in_words) == (4, True, 2, False)
    assert m.describe() == "2 words out, 2 bytes in"
    (m,) = decode_cfg(h("80 40"))                 # 1 word out
    assert m.describe() == "1 word out" and m.words


def test_empty_slot_and_fourteen_manufacturer_octets():
    assert decode_cfg(h("00 F1"))[0].describe() == "empty slot"
    (m,) = decode_cfg(bytes([0x0E]) + bytes(range(14)))
    assert m.manufacturer == bytes(range(14)) and len(m.raw) == 15
    assert m.consistent is False and (m.inputs, m.outputs) == (0, 0)     # no length octets


@pytest.mark.parametrize("raw,message", [
    ("0F", "identifier 0x0F at octet 0: manufacturer count 15 is reserved"),
    ("F1 4F 00", "identifier 0x4F at octet 1: manufacturer count 15 is reserved"),
    ("80", "identifier 0x80 at octet 0: output length octet missing"),
    ("F1 40", "identifier 0x40 at octet 1: input length octet missing"),
    ("C0 01", "identifier 0xC0 at octet 0: input length octet missing"),
    ("F1 02 AA", "identifier 0x02 at octet 1: 2 manufacturer octets announced, 1 present"),
    ("F1 C3 01 01 AA", "identifier 0xC3 at octet 1: 3 manufacturer octets announced, 1 present"),
])
def test_bad_identifiers_say_which_and_where(raw, message):
    with pytest.raises(CfgError) as e:
        decode_cfg(h(raw))
    assert str(e.value) == message


@pytest.mark.parametrize("text,octets", [("F3 F1", "F3F1"), ("f3f1", "F3F1"), ("0xF3,0xF1", "F3F1"),
                                         ("F3:F1", "F3F1"), (" 5f 6f ", "5F6F"), ("", "")])
def test_parse_hex_forms(text, octets):
    assert parse_hex(text) == h(octets)


@pytest.mark.parametrize("text,message", [("F3 F", "odd number of hex digits in 'F'"),
                                          ("ZZ", "not hex: 'ZZ'")])
def test_parse_hex_errors(text, message):
    with pytest.raises(ValueError) as e:
        parse_hex(text)
    assert str(e.value) == message
