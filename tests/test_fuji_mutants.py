"""The Fuji dialect (drives/fuji/codes.py, formats.py, drive.py) against the spec
(/work/shared/spec/fuji-opc-g1-pdp.md and fuji-opc-pdp3.md, from the manuals): function-code
addressing (PNU 0x100 + group code, subindex = number; F26 -> 0x041A, L243), the alarm table (§7:
M16-M19 decimal codes, PNU947 hex codes, shared codes listed as candidates), PNU963 baud codes (§6),
o27/o28 communication-loss actions (§8, Table 9.1), the error numbers of a refused write, y97 storage
(OPC-PDP3). Written for mutation testing (tools/mutation/run.py drives/fuji/...).
"""

import pytest

from profidrive_cli import UsageError
from profidrive_cli.drives import make_drive
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.base import DriveError, DriveStatus
from profidrive_cli.drives.fuji import codes, formats
from profidrive_cli.drives.fuji.config import FUJI_STW_BITS
from profidrive_cli.drives.profile import load_profile
from profidrive_cli.sim.direct import DirectChannel
from profidrive_cli.sim.plant import make_model

G1 = load_profile("fuji-opc-g1-pdp")
PDP3 = load_profile("fuji-opc-pdp3")


def drive(profile=G1, layout="ppo1"):
    model = make_model(profile)
    ch = DirectChannel(model, profile.layouts[layout].cfg)
    return make_drive(ch, profile, layout), model


# -- function codes --------------------------------------------------------------------------------

@pytest.mark.parametrize("text,parsed", [
    ("F26", ("F26", 0x04, 0x104, 26)),
    ("f26", ("F26", 0x04, 0x104, 26)),
    (" F3 ", ("F03", 0x04, 0x104, 3)),
    ("y98", ("y98", 0x0F, 0x10F, 98)),
    ("Y98", ("y98", 0x0F, 0x10F, 98)),
    ("o27", ("o27", 0x0A, 0x10A, 27)),
    ("S255", ("S255", 0x02, 0x102, 255)),
    ("M0", ("M00", 0x03, 0x103, 0)),
    ("d1", ("d01", 0x14, 0x114, 1)),
    ("W101", ("W101", 0x10, 0x110, 101)),        # no group W1 on the G1: W, number 101
])
def test_parse_function_code_g1(text, parsed):
    assert codes.parse_function_code(G1, text) == parsed


@pytest.mark.parametrize("text", ["F256", "Q01", "FF1", "F", "26", "F2.6", "PNU918", "REG0x0100", ""])
def test_parse_function_code_refuses_the_rest_g1(text):
    assert codes.parse_function_code(G1, text) is None


@pytest.mark.parametrize("text,parsed", [
    ("J101", ("J101", 0x24, 0x124, 1)),          # two digits after J1: group J1 (L329-330)
    ("j101", ("J101", 0x24, 0x124, 1)),
    ("W117", ("W117", 0x17, 0x117, 17)),
    ("o101", ("o101", 0x21, 0x121, 1)),
    ("y100", ("y100", 0x0F, 0x10F, 100)),         # three digits: one-letter group y
    ("J1", ("J01", 0x0E, 0x10E, 1)),
    ("J12", ("J12", 0x0E, 0x10E, 12)),
])
def test_parse_function_code_two_character_groups_pdp3(text, parsed):
    assert codes.parse_function_code(PDP3, text) == parsed


def test_two_character_group_letter_without_group():
    # "Q101": neither Q1 nor Q is a group
    assert codes.parse_function_code(PDP3, "Q101") is None
    assert codes.parse_function_code(PDP3, "Qx1") is None
    assert codes.parse_function_code(PDP3, "W1256") is None      # W1 + 256... no: W 1256 > 255


def test_function_code_name_and_pcd_words():
    assert codes.function_code_name(G1, 0x104, 26) == "F26"
    assert codes.function_code_name(G1, 0x10F, 98) == "y98"
    assert codes.function_code_name(G1, 0x10F, 5) == "y05"
    assert codes.function_code_name(G1, 0x101, 1) is None        # no group 0x01
    assert codes.function_code_name(G1, 947, 1) is None          # a PROFIdrive PNU
    assert codes.function_code_name(G1, 0x0FF, 1) is None
    assert codes.pcd_assignment(G1, "F26") == 0x041A              # L243
    assert codes.pcd_assignment(G1, "M09") == 0x0309
    with pytest.raises(UsageError) as e:
        codes.pcd_assignment(G1, "PNU918")
    assert str(e.value) == "PNU918 is not a function code of fuji-opc-g1-pdp"
    assert codes.pcd_assignment_code(G1, 0x041A) == "F26"
    assert codes.pcd_assignment_code(G1, 0) is None
    assert codes.pcd_assignment_code(G1, 0x0100) is None


# -- alarms ----------------------------------------------------------------------------------------

def test_alarm_text_and_candidates():
    assert codes.alarm_text(G1, 0) == "no alarm"
    assert codes.alarm_text(G1, 0x2301) == "OC1 (Overcurrent while accelerating)"
    assert codes.alarm_text(G1, 0x4310) == ("one of OH1 (Heat sink too hot) or OH4 (Motor thermistor "
                                            "(PTC/NTC) protection)")
    assert codes.alarm_text(G1, 0x1234) == "unknown malfunction code 0x1234"
    assert [a.code for a in codes.alarm_candidates(G1, 0x2212)] == ["OL2", "OL3", "OL4"]


def test_alarm_by_mcode_and_mcode_of():
    assert codes.alarm_by_mcode(G1, 1).code == "OC1"
    assert codes.alarm_by_mcode(G1, 35).code == "Er5"
    assert codes.alarm_by_mcode(G1, 254).code == "Err"
    assert codes.alarm_by_mcode(G1, 4) is None                   # not in the table
    assert codes.mcode_of(G1, "OL3") == 44 and codes.mcode_of(G1, "XX") is None


# -- PPO selection (o30) ---------------------------------------------------------------------------

@pytest.mark.parametrize("o30,layout", [(0, "ppo1"), (1, "ppo1"), (6, "ppo1"), (255, "ppo1"), (2, "ppo2"),
                                        (5, "ppo2"), (3, "ppo3"), (4, "ppo4")])
def test_ppo_for_o30(o30, layout):
    assert codes.ppo_for_o30(G1, o30) == layout


def test_o30_for_layout():
    assert codes.o30_for_layout(G1, "ppo1") == 1          # its own number when listed
    assert codes.o30_for_layout(G1, "ppo2") == 2
    assert codes.o30_for_layout(G1, "ppo4") == 4
    assert codes.o30_for_layout(G1, "nope") is None


# -- communication loss (o27 / o28) ----------------------------------------------------------------

@pytest.mark.parametrize("o27,o28,text", [
    (0, 2.0, "o27 = 0: coast to a stop at once, then trip Er5"),
    (7, 0.0, "o27 = 7: coast to a stop at once, then trip Er5"),
    (1, 2.5, "o27 = 1: coast to a stop after o28 = 2.5 s, then trip Er5"),
    (2, 2.5, "o27 = 2: coast to a stop after o28 = 2.5 s unless the link returns within 2.5 s, then trip Er5"),
    (3, 0.0, "o27 = 3: a communication loss is ignored (no Er5)"),
    (14, 0.0, "o27 = 14: a communication loss is ignored (no Er5)"),
    (10, 1.0, "o27 = 10: decelerate with F08 at once, then trip Er5"),
    (11, 1.0, "o27 = 11: decelerate with F08 after o28 = 1 s, then trip Er5"),
    (12, 1.0, "o27 = 12: decelerate with F08 after o28 = 1 s unless the link returns within 1 s, then trip Er5"),
    (99, 1.0, "o27 = 99: coast to a stop at once, then trip Er5"),       # outside the table: factory
])
def test_comm_loss_text(o27, o28, text):
    assert codes.comm_loss_text(G1, o27, o28) == text


def test_comm_loss_action_outside_the_table_is_the_factory_coast():
    a = codes.comm_loss_action(G1, 99)
    assert (a.stop, a.delayed, a.recover, a.trip) == ("coast", False, False, True) and 99 in a.values


def test_param_value_masks_to_16_bits():
    f26 = G1.param("F26")
    assert codes.param_value(G1, f26, 0x10002) == f26.from_raw(2)


# -- value formats ---------------------------------------------------------------------------------

def test_fcode_text():
    o40 = G1.param("o40") or PDP3.param("o40")
    assert formats.fcode_text(G1, o40, 0, 0) == "0x0000 (not assigned)"
    assert formats.fcode_text(G1, o40, 0x1041A, 0) == "0x041A (F26)"
    assert formats.fcode_text(G1, o40, 0x0100, 0) == "0x0100 (no such function code)"


def test_alarm_code_text():
    m16 = G1.param("M16")
    assert formats.alarm_code_text(G1, m16, 0, 0) == "0 (no alarm)"
    assert formats.alarm_code_text(G1, m16, 1, 1) == "1 (OC1 Overcurrent while accelerating)"
    assert formats.alarm_code_text(G1, m16, 4, 4) == "4 (alarm code not in the manual's table)"


def test_alarm947_text():
    p = G1.param("PNU947")
    assert formats.alarm947_text(G1, p, 0x12301, 0) == "0x2301 (OC1 (Overcurrent while accelerating))"
    assert formats.alarm947_text(G1, p, 0, 0) == "0x0000 (no alarm)"


def test_baud_text():
    p = PDP3.param("PNU963") or G1.param("PNU963")
    assert formats.baud_text(PDP3, p, 10, 10) == "10 (12M)"
    assert formats.baud_text(PDP3, p, 2, 2) == "2 (19.2k)"
    assert formats.baud_text(PDP3, p, 11, 11) == "11 (not in the manual table)"
    assert set(formats.FORMATTERS) == {"fcode", "alarm", "alarm947", "baud"}
    assert formats.FORMATTERS["baud"] is formats.baud_text and formats.FORMATTERS["alarm"] is formats.alarm_code_text


# -- the drive -------------------------------------------------------------------------------------

def ref(label="F26"):
    return pd.ParamRef(label, "", 0x104, 26, False, 16, None)


@pytest.mark.parametrize("error,text", [
    (1, "F26: the card refused the write (error 1: parameter cannot be written (read-only or "
        "write-protected)); either the code is read-only or PNU927 = 0 blocks parameter writes "
        "(write PNU927 = 1)"),
    (11, "F26 cannot be changed while the inverter runs or a run-command input is on (error 11); stop it first"),
    (101, "F26: link priority error (error 101): another command source (y99, LE/LOC terminals) has priority"),
    (104, "F26: the card stayed busy (error 104); try again"),
])
def test_write_refused_messages(error, text):
    d, _ = drive()
    res = pd.PkwResult(None, None, error=error,
                       error_text="parameter cannot be written (read-only or write-protected)")
    assert d.write_refused_message(ref(), 1, res) == text


def test_jog_is_refused_with_the_reason():
    d, _ = drive()
    assert d.supports_jog is False
    with pytest.raises(DriveError) as e:
        d.jog()
    assert str(e.value) == ("fuji-opc-g1-pdp: CTW bits 8 and 9 are not used by this card; there is no "
                            "jog over PROFIBUS (use run with a low speed instead)")


def test_start_hint_names_r_l():
    d, _ = drive()
    base = ("the card takes CTW/MRV only with y98 = 3 (run and frequency from PROFIBUS), CTW bits "
            "4, 5, 6 and 10 = 1, and no higher-priority source (H30, y99, LE/LOC terminals)")
    st = DriveStatus("S1", False, False, {FUJI_STW_BITS[9]: True}, 0.0, 0.0)
    assert d.start_hint(st) == base
    st = DriveStatus("S1", False, False, {}, 0.0, 0.0)
    assert d.start_hint(st) == base
    st = DriveStatus("S1", False, False, {FUJI_STW_BITS[9]: False}, 0.0, 0.0)
    assert d.start_hint(st) == "STW bit 9 (R/L) is 0: PROFIBUS is not the command source; " + base


def test_fault_record_narrowing():
    d, _ = drive()
    r = d.fault_record("latest", 0, 0)
    assert (r.raw, r.codes, r.meanings) == (0, [], ["no alarm"])
    r = d.fault_record("latest", 0x2212, 44)                  # M16 = 44 -> OL3 of OL2/OL3/OL4
    assert (r.codes, r.meanings) == (["OL3"], ["Motor 3 overloaded"])
    r = d.fault_record("latest", 0x2212, None)
    assert r.codes == ["OL2", "OL3", "OL4"]
    r = d.fault_record("latest", 0x2212, 1)                   # an M-code that contradicts PNU947
    assert r.codes == ["OL2", "OL3", "OL4"]
    r = d.fault_record("latest", 0x1234, None)
    assert (r.codes, r.meanings) == (["?0x1234"], ["unknown malfunction code 0x1234"])
    r = d.fault_record("latest", 0x1234, 35)                  # unknown PNU947 code, M-code known
    assert r.codes == ["Er5"]
    r = d.fault_record("latest", 0, 1)                        # PNU947 cleared, M16 still says OC1
    assert r.codes == ["OC1"]


def test_status_names_the_tripped_alarm_and_the_history():
    d, model = drive()
    model.trip("OL3", d.channel.now())
    st = d.status()
    assert st.fault and st.fault_code == "OL3"
    h = d.fault_history()
    assert [r.position for r in h] == ["latest"]           # the others read 0: no alarm (left out)
    assert h[0].codes == ["OL3"]


def test_comm_loss_and_ppo_setting_from_the_card():
    d, _ = drive()
    d.write_param("o27", 2)
    d.write_param("o28", 1.5)
    assert d.comm_loss_setting() == ("o27 = 2: coast to a stop after o28 = 1.5 s unless the link returns "
                                     "within 1.5 s, then trip Er5")
    assert d.ppo_setting() in ("o30 = 0: PPO1", "o30 = 1: PPO1")
    d.write_param("o30", 3)
    assert d.ppo_setting() == "o30 = 3: PPO3 (the master uses PPO1: power-cycle after changing o30)"
    assert d.notes == ["o30 takes effect after the inverter is switched off and on"]


def test_resolve_param_short_pnu_forms():
    d, _ = drive()
    assert d.resolve_param("P918").code == "PNU918"
    assert d.resolve_param("pnu 918").code == "PNU918"
    with pytest.raises(UsageError):
        d.resolve_param("P999")                    # only PNUs the profile lists get the short form
    r = d.resolve_param("F99")                     # a function code the profile does not list
    assert (r.code, r.pnu, r.subindex, r.param) == ("F99", 0x104, 99, None)
    r = d.resolve_param("F07")
    assert (r.code, r.pnu, r.subindex) == ("F07", 0x104, 7) and r.param is G1.param("F07")


def test_storage_g1_has_none():
    d, _ = drive()
    assert d.storage_mode() == "direct (every write is stored)"
    with pytest.raises(DriveError) as e:
        d.save()
    assert str(e.value) == ("fuji-opc-g1-pdp: PKW writes go straight to the inverter's memory; there is "
                            "no separate save (y97 is an OPC-PDP3 feature)")
    with pytest.raises(DriveError) as e:
        d.set_storage("ram")
    assert str(e.value) == "fuji-opc-g1-pdp: storage selection (y97) is an OPC-PDP3 feature"


def test_storage_pdp3_y97():
    d, model = drive(PDP3)
    assert d.storage_mode() == "EEPROM (non-volatile; limited write cycles)"     # y97 = 0
    d.set_storage("ram")
    assert d.read_param("y97").raw == 1
    assert d.storage_mode() == "RAM only (lost at power-off; save to keep)"
    with pytest.raises(UsageError) as e:
        d.set_storage("flash")
    assert str(e.value) == "storage must be ram or eeprom"
    d.save()
    assert d.read_param("y97").raw == 1                    # y97 reads 1 after a save
    d.set_storage("eeprom")
    assert d.read_param("y97").raw == 0


# -- a user profile: a two-letter group, layouts not named after their PPO number -------------------

@pytest.fixture(scope="module")
def user_profile(tmp_path_factory):
    """The G1 profile with a group `Ab` (code 0x30) and the PPO2 / PPO4 layouts renamed ppo7 / pcd4
    (config.py allows one letter plus one character per group, and any layout name)."""
    import re
    from pathlib import Path

    from profidrive_cli.drives.profile import load_profile_file
    src = (Path(__file__).resolve().parents[1] / "profiles" / "fuji-opc-g1-pdp.yaml").read_text()
    t = src.replace("    d: {code: 0x14, name: Application functions 2}",
                    "    d: {code: 0x14, name: Application functions 2}\n"
                    "    Ab: {code: 0x30, name: Two-letter test group}", 1)
    t = re.sub(r"^profile: fuji-opc-g1-pdp", "profile: fuji-user", t, flags=re.M)
    t = t.replace("aliases: [fuji-g1]", "aliases: []")
    t = re.sub(r"^  ppo2:", "  ppo7:", t, flags=re.M)
    t = re.sub(r"^  ppo4:", "  pcd4:", t, flags=re.M).replace("[ppo2, ppo4]", "[ppo7, pcd4]")
    p = tmp_path_factory.mktemp("prof") / "fuji-user.yaml"
    p.write_text(t)
    return load_profile_file(p)


def test_two_letter_group(user_profile):
    assert codes.parse_function_code(user_profile, "Ab3") == ("Ab03", 0x30, 0x130, 3)
    assert codes.parse_function_code(user_profile, "aB12") == ("Ab12", 0x30, 0x130, 12)
    assert codes.parse_function_code(user_profile, "Ac3") is None
    assert codes.parse_function_code(user_profile, "Ab256") is None
    assert codes.function_code_name(user_profile, 0x130, 5) == "Ab05"


def test_o30_for_layouts_not_named_after_their_ppo(user_profile):
    assert codes.o30_for_layout(user_profile, "ppo7") == 2      # o30 [2, 5]: 7 is not one of them
    assert codes.o30_for_layout(user_profile, "pcd4") == 4      # o30 [4]
    assert codes.ppo_for_o30(user_profile, 5) == "ppo7"


# -- the drive, continued: faults in detail, the busy retry, the save, the addressing records -------

def test_current_alarm_reads_pnu947_index_1_as_an_array():
    d, model = drive()
    model.trip("OC1", d.channel.now())
    sent = []
    real = d.request

    def spy(frame, timeout=None):
        sent.append((frame.ak, frame.pnu, frame.subindex))
        return real(frame, timeout)
    d.request = spy
    rec = d.current_alarm()
    assert (rec.position, rec.raw, rec.codes, rec.meanings) == \
        ("latest", 0x2301, ["OC1"], ["Overcurrent while accelerating"])
    assert sent[0] == (6, 947, 1)             # §6: PNU947, the latest fault at index 1, AK 6 (array)


def test_current_alarm_without_a_parameter_channel_is_none():
    d, model = drive(layout="ppo3")
    model.trip("OC1", d.channel.now())
    assert d.current_alarm() is None
    st = d.status()
    assert st.fault and st.fault_code is None


def test_fault_records_keep_position_raw_and_every_meaning():
    d, _ = drive()
    r = d.fault_record("2nd last", 0x2212, None)
    assert (r.position, r.raw, r.codes, r.meanings) == (
        "2nd last", 0x2212, ["OL2", "OL3", "OL4"],
        ["Motor 2 overloaded", "Motor 3 overloaded", "Motor 4 overloaded"])
    r = d.fault_record("last", 0x1234, None)
    assert (r.position, r.raw) == ("last", 0x1234)


def test_status_without_m16_lists_every_candidate():
    d, model = drive()
    model.trip("OL3", d.channel.now())
    d._mcode = lambda param: None             # M16 not readable: PNU947 0x2212 alone
    st = d.status()
    assert st.fault_code == "OL2/OL3/OL4"


def test_fault_history_error_names_the_index_and_number():
    d, _ = drive()
    real = d.request

    def refuse(frame, timeout=None):
        if frame.pnu == 947:
            return pd.PkwResult(frame, pd.PkwFrame(7, 947, frame.subindex, 3), error=3,
                                error_text="invalid subindex")
        return real(frame, timeout)
    d.request = refuse
    with pytest.raises(Exception) as e:
        d.fault_history()
    assert str(e.value) == "fault memory PNU 947[1]: error 3 (invalid subindex)"
    assert e.value.number == 3


def test_resolve_param_records():
    d, _ = drive()
    p = G1.param("F07")
    assert d.resolve_param("F07") == pd.ParamRef("F07", p.name, 0x104, 7, False, p.size, p)
    assert d.resolve_param("F99") == pd.ParamRef("F99", "", 0x104, 99, False, 16, None)


def test_busy_card_is_asked_again_until_it_takes_the_write():
    d, model = drive()
    model.busy_next = 3                        # error 104 three times, then the write is done
    d.write_param("F07", 2.5)
    assert d.read_param("F07").value == 2.5


def test_a_card_that_stays_busy_is_given_up_after_6_s():
    d, model = drive()
    model.busy_next = 10 ** 6
    t0 = d.channel.now()
    with pytest.raises(Exception) as e:
        d.write_param("F07", 2.5)
    took = d.channel.now() - t0
    assert str(e.value) == "F07 (Acceleration time 1): the card stayed busy (error 104); try again"
    # max(PKW timeout 2 s, 6 s): the busy retry lasts 6 s (a few cycles of slack)
    assert 6.0 < took < 6.5


def test_a_longer_timeout_keeps_asking_longer():
    d, model = drive()
    model.busy_next = 10 ** 6
    t0 = d.channel.now()
    res = d.request(pd.write_request(0x104, 25, 7), timeout=9.0)
    assert res.error == 104 and 9.0 < d.channel.now() - t0 < 9.5


def test_save_that_never_completes_times_out_after_the_save_time():
    d, model = drive(PDP3)
    from profidrive_cli.drives.base import ParamValue
    d.read_param = lambda code: ParamValue(code, code, 2, 2)          # y97 never back to 1
    t0 = d.channel.now()
    with pytest.raises(DriveError) as e:
        d.save(timeout=3.0)
    took = d.channel.now() - t0
    assert str(e.value) == "y97 did not return to 1 within 3 s: save not confirmed (do not switch off yet)"
    assert 6.0 < took < 6.5                   # max(3 s, save time 5 s + 1 s)
    t0 = d.channel.now()
    with pytest.raises(DriveError):
        d.save()
    assert 15.0 < d.channel.now() - t0 < 15.5  # the default: 15 s


def test_storage_mode_names_an_unknown_y97_value():
    d, _ = drive(PDP3)
    from profidrive_cli.drives.base import ParamValue
    d.read_param = lambda code: ParamValue(code, code, 2, 2)
    assert d.storage_mode() == "y97 = 2"


def test_a_refused_storage_write_says_why_with_the_error_number():
    from profidrive_cli.drives.base import ParamError
    d, model = drive(PDP3)
    model.busy_next = 10 ** 6
    with pytest.raises(ParamError) as e:
        d.set_storage("ram")
    assert str(e.value).endswith(": the card stayed busy (error 104); try again")
    assert str(e.value).startswith("y97") and e.value.number == 104


def test_other_refusals_use_the_profidrive_words():
    d, _ = drive()
    res = pd.PkwResult(None, None, error=2, error_text="value outside the setting range")
    assert d.write_refused_message(ref(), 5, res) == \
        "F26: the drive refused the value 5: error 2 (value outside the setting range)"
