"""DP-V0 services (dp/services.py) at their edges, from the reference §3.1 (Set_Prm), §3.3
(Slave_Diag bits), §3.5 (Global_Control) and Set_Slave_Add (SAP 55: new address, ident high/low,
No_Add_Chg), written against the survivors of a mutation run (tools/mutation/run.py dp/services.py).
Octets are worked by hand from those tables."""

import pytest

from profidrive_cli.dp import services as S


# §3.1 octet 0: bit 7 Lock_Req, bit 6 Unlock_Req, bit 5 Sync_Req, bit 4 Freeze_Req, bit 3 WD_On
@pytest.mark.parametrize("lock,unlock,status", [(True, False, 0x88), (False, True, 0x48),
                                                (False, False, 0x08), (True, True, 0xC8)])
def test_set_prm_lock_bits_both_ways(lock, unlock, status):
    p = S.SetPrm(ident=0x00CA, wd_ms=500, lock=lock, unlock=unlock)
    du = p.encode()
    assert du == bytes([status, 50, 1, 11, 0x00, 0xCA, 0x00])
    q = S.SetPrm.decode(du)
    assert (q.lock, q.unlock, q.sync, q.freeze, q.wd_ms) == (lock, unlock, False, False, 500.0)


def test_set_prm_watchdog_off_sends_factors_1_1():
    """WD_On clear: the factors are still sent, and must not be 0 (§3.1): 1 x 1."""
    du = S.SetPrm(ident=0x0F84, wd_ms=None, group=1).encode()
    assert du == bytes.fromhex("80 01 01 0B 0F 84 01")
    assert S.SetPrm.decode(du).wd_ms is None


def test_set_prm_decode_takes_7_header_octets_then_user_data():
    q = S.SetPrm.decode(bytes.fromhex("88 32 01 0B 00 CA 00 AA BB"))
    assert q.user_prm == bytes.fromhex("AA BB") and q.group == 0 and q.ident == 0x00CA
    with pytest.raises(S.ServiceError, match="Set_Prm needs 7 octets, got 6"):
        S.SetPrm.decode(bytes(6))


@pytest.mark.parametrize("ms", [650250, 650251, 10 ** 6])
def test_watchdog_beyond_650_s(ms):
    if ms == 650250:
        assert S.watchdog_factors(ms) == (255, 255)
    else:
        with pytest.raises(ValueError, match=f"watchdog {ms} ms exceeds 650 s"):
            S.watchdog_factors(ms)


# §3.3 bits
def test_slave_diag_flags_and_has_every_status_octet():
    d = S.SlaveDiag(st1=0x08, st2=0x0C | 0x40, st3=0x80, master=2, ident=0x00CA)
    # st2 bit 2 "always 1" and bit 6 "reserved" are not flags
    assert d.flags() == ["Ext_Diag", "WD_On", "Ext_Diag_Overflow"]
    assert d.has("Ext_Diag_Overflow") and d.has("WD_On") and not d.has("Prm_Req")
    assert not S.SlaveDiag(0, 0x04, 0x7F, 2, 1).has("Ext_Diag_Overflow")
    with pytest.raises(KeyError, match="nosuch"):
        d.has("nosuch")
    assert S.SlaveDiag(0, 0x80 | 0x04, 0, 2, 1).flags() == ["Deactivated"]


@pytest.mark.parametrize("st1,st2,master,own,words", [
    (0x04, 0x04, 2, 2, "configuration fault"),
    (0x40, 0x05, 0xFF, 2, "parameter fault, waiting for parameters"),
    (0x02, 0x05, 0xFF, 2, "waiting for parameters"),
    (0x00, 0x06, 2, 2, "static diagnosis"),
    (0x10, 0x04, 2, 2, "function not supported"),
    (0x00, 0x04, 2, 2, "ready"),
    (0x02, 0x04, 2, 2, "not ready"),
    (0x08, 0x04, 2, 2, "ready, extended diagnosis"),
    (0x00, 0x04, 5, 2, "locked by master 5"),
    (0x00, 0x04, 0xFF, 2, "ready"),                      # 0xFF: nobody's
    (0x80, 0x04, 5, None, "locked by master 5"),          # Master_Lock set by the master
])
def test_state_words(st1, st2, master, own, words):
    assert S.SlaveDiag(st1, st2, 0, master, 0x00CA).state_words(own) == words


def test_slave_diag_too_short():
    with pytest.raises(S.ServiceError, match="Slave_Diag reply needs 6 octets, got 5"):
        S.SlaveDiag.decode(bytes(5))


# §3.5
def test_global_control_octets_and_words():
    g = S.GlobalControl.decode(bytes.fromhex("22 05"))
    assert (g.command, g.group) == (0x22, 0x05)
    assert g.encode() == bytes.fromhex("22 05")
    assert g.describe() == "Clear_Data + Sync, groups 1,3"
    assert S.GlobalControl(0x00, 0x80).describe() == "operate (no command), groups 8"
    assert S.GlobalControl(0x08, 0).describe() == "Freeze, all groups"
    for n in (1, 3):
        with pytest.raises(S.ServiceError, match=f"Global_Control needs 2 octets, got {n}"):
            S.GlobalControl.decode(bytes(n))


def test_set_slave_add_octets():
    a = S.SetSlaveAdd(new_address=9, ident=0x80E0, no_add_chg=True, extra=b"\x01")
    assert a.encode() == bytes.fromhex("09 80 E0 01 01")
    assert S.SetSlaveAdd(9, 0x80E0).encode() == bytes.fromhex("09 80 E0 00")
    b = S.SetSlaveAdd.decode(bytes.fromhex("09 80 E0 01 AA BB"))
    assert (b.new_address, b.ident, b.no_add_chg, b.extra) == (9, 0x80E0, True, bytes.fromhex("AA BB"))
    with pytest.raises(S.ServiceError, match="Set_Slave_Add needs 4 octets, got 3"):
        S.SetSlaveAdd.decode(bytes(3))


# §3.4 extended diagnosis blocks, worked by hand from the header/body tables
def test_ext_diag_blocks_field_by_field():
    ident, chan, dev = S.decode_ext_diag(bytes.fromhex("44 00 01 00 88 41 21 04 10 20 30"))
    assert (ident.kind, ident.raw, ident.modules) == ("identifier", bytes.fromhex("44 00 01 00"), [8])
    assert (chan.kind, chan.raw, chan.module, chan.channel, chan.direction, chan.width, chan.error) == (
        "channel", bytes.fromhex("88 41 21"), 8, 1, "input", "bit", "short circuit")
    assert (dev.kind, dev.raw) == ("device", bytes.fromhex("04 10 20 30"))
    # identifier bit field: LSB first, octet by octet -> modules 0, 7, 9, 15
    (b,) = S.decode_ext_diag(bytes.fromhex("43 81 82"))
    assert b.modules == [0, 7, 9, 15]


@pytest.mark.parametrize("octets,direction,width,error", [
    ("81 C5 C9", "input/output", "2 words", "error"),                           # 0xC5: 11, ch 5; 0xC9: 110, 9
    ("81 85 A5", "output", "word", "overtemperature"),
    ("81 05 0F", "?", "invalid width", "reserved error 15"),                    # dir 00, width 000
    ("81 45 F0", "input", "invalid width", "manufacturer-specific error 16"),   # width 111
    ("81 45 3F", "input", "bit", "manufacturer-specific error 31"),
])
def test_channel_block_words(octets, direction, width, error):
    (c,) = S.decode_ext_diag(bytes.fromhex(octets))
    assert (c.module, c.channel, c.direction, c.width, c.error) == (1, 5, direction, width, error)


@pytest.mark.parametrize("octets,kinds,last_raw", [
    ("C1 00", ["reserved"], "C1 00"),                   # bits 7..6 = 11: stop parsing
    ("02 AA C1 00 02 BB", ["device", "reserved"], "C1 00 02 BB"),
    ("81 05", ["reserved"], "81 05"),                   # channel block cut short
    ("05 01 02", ["reserved"], "05 01 02"),             # length 5, 3 present
    ("00 01", ["reserved"], "00 01"),                   # length 0 is no block
    ("01 02 AA", ["device", "device"], "02 AA"),        # length 1: the header alone
])
def test_ext_diag_stops_at_reserved_or_truncated(octets, kinds, last_raw):
    blocks = S.decode_ext_diag(bytes.fromhex(octets))
    assert [b.kind for b in blocks] == kinds
    assert blocks[-1].raw == bytes.fromhex(last_raw)


def test_slave_diag_keeps_the_octets_after_six_as_ext():
    d = S.SlaveDiag.decode(bytes.fromhex("08 0C 00 02 00 CA 44 00 01 00"))
    assert (d.st1, d.st2, d.master, d.ident) == (0x08, 0x0C, 2, 0x00CA)
    assert d.ext == bytes.fromhex("44 00 01 00")
    assert [b.modules for b in d.ext_blocks()] == [[8]]
