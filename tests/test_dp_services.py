"""DP-V0 services: Set_Prm, Slave_Diag (+ ext blocks), Global_Control, cfg identifiers."""

import pytest

from profidrive_cli.dp import services as S
from profidrive_cli.dp.cfg import CfgError, decode_cfg, io_sizes, parse_hex


def test_set_prm_golden_6_and_7():
    p = S.SetPrm.decode(bytes.fromhex("800101000F8401"))
    assert (p.lock, p.wd_ms, p.ident, p.group, p.min_tsdr) == (True, None, 0x0F84, 1, 0)
    p = S.SetPrm.decode(bytes.fromhex("B81E01000A350100000082000000"))
    assert p.lock and p.sync and p.freeze and p.wd_ms == 300.0
    assert p.user_prm == bytes.fromhex("00000082000000")
    assert p.encode() == bytes.fromhex("B81E01000A350100000082000000")


def test_set_prm_golden_14_watchdog_1950ms():
    du = bytes.fromhex("B80D0F0B80E000C00000112100000000000001000000000000000020010018")
    p = S.SetPrm.decode(du)
    assert p.wd_ms == 13 * 15 * 10 and p.min_tsdr == 11 and p.ident == 0x80E0
    assert p.user_prm[:3] == bytes.fromhex("C00000")
    assert p.encode() == du


def test_set_prm_encode_arms_watchdog():
    du = S.SetPrm(ident=0x00CA, wd_ms=500).encode()
    assert du[0] & 0x08 and du[0] & 0x80          # WD_On + Lock_Req
    assert du[1] * du[2] * 10 == 500
    assert du[4:6] == b"\x00\xca"


@pytest.mark.parametrize("ms,expect", [(10, 10), (300, 300), (1950, 1950), (5, 10), (655, 660),
                                       (650000, 650250)])
def test_watchdog_factors_round_up(ms, expect):
    f1, f2 = S.watchdog_factors(ms)
    assert 1 <= f1 <= 255 and 1 <= f2 <= 255
    assert f1 * f2 * 10 == expect


def test_diag_golden_5_and_9():
    d = S.SlaveDiag.decode(bytes.fromhex("060500FF0F84"))
    assert d.flags() == ["Station_Not_Ready", "Cfg_Fault", "Prm_Req"]
    assert not d.ready and d.master == 0xFF
    assert "configuration fault" in d.state_words()
    d = S.SlaveDiag.decode(bytes.fromhex("000C00020A35"))
    assert d.ready and d.has("WD_On") and d.master == 2 and d.ident == 0x0A35
    assert d.state_words(2) == "ready"
    assert d.state_words(1) == "locked by master 2"


def test_stat_diag_is_not_ready():
    d = S.SlaveDiag.decode(bytes.fromhex("000E00010000"))
    assert not d.ready and "static diagnosis" in d.state_words(1)


def test_ext_diag_blocks_vector():
    blocks = S.decode_ext_diag(bytes.fromhex("44 00 01 00 88 41 21 04 10 20 30"))
    assert [b.kind for b in blocks] == ["identifier", "channel", "device"]
    assert blocks[0].modules == [8]
    ch = blocks[1]
    assert (ch.module, ch.channel, ch.direction, ch.width, ch.error) == (8, 1, "input", "bit",
                                                                       "short circuit")
    assert blocks[2].raw[1:] == bytes.fromhex("102030")


def test_ext_diag_truncated_does_not_raise():
    assert S.decode_ext_diag(b"\x0A\x01")[0].kind == "reserved"
    assert S.decode_ext_diag(b"\x88\x41")[0].kind == "reserved"


def test_global_control_golden_12():
    gc = S.GlobalControl.decode(b"\x00\x00")
    assert gc.describe() == "operate (no command), all groups"
    assert S.GlobalControl(S.GC_CLEAR, 0x01).encode() == b"\x02\x01"
    assert "Clear_Data" in S.GlobalControl(S.GC_CLEAR, 1).describe()


def test_set_slave_add_roundtrip():
    s = S.SetSlaveAdd(5, 0x00CA, True)
    assert s.encode() == bytes.fromhex("0500CA01")
    assert S.SetSlaveAdd.decode(s.encode()) == s


@pytest.mark.parametrize("hexstr,sizes", [
    ("F3 F1", (12, 12)), ("00 F1", (4, 4)), ("72", (6, 6)), ("5F 6F", (32, 32)),
    ("55 65", (12, 12)), ("E9 DF D1", (36, 20)), ("EF DF D6", (46, 32)), ("C0 01 7D", (124, 2)),
    ("43 00 00 1F C1", (1, 0)), ("F3 C3 C1 C1 FD 01 61", (12, 12)), ("11", (2, 0)), ("22", (0, 3)),
])
def test_cfg_sizes(hexstr, sizes):
    assert io_sizes(parse_hex(hexstr)) == sizes


def test_cfg_words():
    mods = decode_cfg(parse_hex("C0 01 7D"))
    assert mods[0].describe() == "2 bytes out, 62 words in"
    assert decode_cfg(b"\xF3")[0].describe() == "4 words in+out, consistent"
    assert decode_cfg(b"\x00")[0].describe() == "empty slot"


@pytest.mark.parametrize("bad", ["C0", "C0 01", "43 00 00", "0F"])
def test_cfg_errors(bad):
    with pytest.raises(CfgError):
        decode_cfg(parse_hex(bad))


def test_parse_hex_forms():
    assert parse_hex("0xF3,0xF1") == b"\xf3\xf1" == parse_hex("f3f1") == parse_hex("F3 F1")
    with pytest.raises(ValueError):
        parse_hex("F3 G1")
    with pytest.raises(ValueError):
        parse_hex("F3F")
