"""drives/moeller.py: the cases mutation testing found untested (issue 20).

Expected values from ../shared/spec/moeller-de6-net-dp.md and the profile's rows: the node address
from the two rotary switches (right = tens, 0..9 each), PNU 964 (bit 15 = DF, 0x12C = the "6"
series), the direction rule (sign of HSW XOR STW bit 11), DF6 limits (df6: false, df6_max), and hand
calculations of the wire widths (bytes 1/2/4, two's complement).
"""

from types import SimpleNamespace

import pytest

from profidrive_cli.drives import make_drive
from profidrive_cli.drives import moeller as mo
from profidrive_cli.drives.base import ParamError
from profidrive_cli.drives.profidrive.params import ParamRef
from profidrive_cli.drives.profile import ParamDef, load_profile
from profidrive_cli.sim.direct import DirectChannel
from profidrive_cli.sim.moeller import make_model


@pytest.fixture(scope="module")
def prof():
    return load_profile("moeller")


def rig(prof, layout="ppo1", **opts):
    model = make_model(prof, **opts)
    ch = DirectChannel(model, prof.layouts[layout].cfg)
    return model, make_drive(ch, prof, layout)


@pytest.mark.parametrize("right, left, addr", [(0, 0, 0), (9, 9, 99), (0, 9, 9), (9, 0, 90)])
def test_address_switch_edges(right, left, addr):
    assert mo.address_from_switches(right, left) == addr


@pytest.mark.parametrize("right, left", [(-1, 0), (10, 0), (0, -1), (0, 10)])
def test_address_switch_limits(right, left):
    with pytest.raises(ValueError) as e:
        mo.address_from_switches(right, left)
    assert str(e.value) == "switch positions are 0..9"


def test_device_names():
    assert mo.device_name(0x0001) == "DV model 1"
    assert mo.device_name(0x8001) == "DF model 1"
    assert mo.device_name(0x812D) == "DF model 301"


@pytest.mark.parametrize("ctw, hsw, text", [
    (0x047F, 0x0000, "forward"), (0x0C7F, 0x0000, "reverse"),     # no sign: bit 11 alone
    (0x047F, 0x0001, "forward"), (0x047F, 0xFFFF, "reverse"), (0x0C7F, 0x0001, "reverse"),
])
def test_direction_at_zero_and_one_count(ctw, hsw, text):
    assert mo.direction_text(ctw, hsw) == text


def test_fault_text_lists_every_alarm_of_a_number():
    two = SimpleNamespace(alarms_for=lambda n: [SimpleNamespace(code="E60", meaning="a"),
                                                SimpleNamespace(code="E60b", meaning="b")])
    assert mo.fault_text(two, 60) == "E60 a / E60b b"


def P(**kw):
    return ParamDef(code="X1", name="Test", **kw)


def test_in_ranges_edges_with_float_noise_only():
    p = P(extra={"ranges": [[1, 48], [255, 255]]})
    assert mo.in_ranges(p, 1) and mo.in_ranges(p, 48) and mo.in_ranges(p, 255)
    assert mo.in_ranges(p, 48 + 1e-10) and mo.in_ranges(p, 1 - 1e-10)
    assert not mo.in_ranges(p, 0.5) and not mo.in_ranges(p, 48.5) and not mo.in_ranges(p, 254.5)
    q = P(min=0.01, max=3600.0)
    assert mo.in_ranges(q, 0.01) and mo.in_ranges(q, 3600.0)
    assert not mo.in_ranges(q, 0.005) and not mo.in_ranges(q, 3600.5)
    assert mo.in_ranges(P(min=0), 10**9) and mo.in_ranges(P(max=0), -10**9)
    assert not mo.in_ranges(P(max=0), 0.5)


def test_raw_pnu_values_keep_their_width(prof):
    _, drive = rig(prof)
    ref16 = ParamRef("PNU999", "", 999, 0, False, 16, None)
    ref32 = ParamRef("PNU999", "", 999, 0, False, 32, None)
    assert drive.value_to_raw(ref16, -1) == 0xFFFF
    assert drive.value_to_raw(ref16, 0x12345) == 0x2345
    assert drive.value_to_raw(ref32, -1) == 0xFFFFFFFF
    assert drive.value_to_raw(ref16, 7.0) == 7
    # a raw PNU is checked as a raw 16-bit value
    assert drive.check_value(ref16, 2.5) == \
        "PNU999 = 2.5 cannot be held exactly: raw values are whole numbers; nearest 2 or 3"
    assert drive.check_value(ref16, 70000) == "PNU999: 70000 does not fit 16 bits"


def test_df6_maximum_message_and_edge(prof):
    _, df6 = rig(prof, device="DF6")
    ref = df6.resolve_param("C001")                 # ranges 1..48, 255; df6_max 39
    assert df6.check_value(ref, 39) is None
    assert df6.check_value(ref, 40) == \
        "C001 (Selection of function in intelligent input 1): 40 is above the DF6 maximum 39"
    a004 = df6.resolve_param("F002")                # no df6 keys: not checked against the device
    assert df6.check_value(a004, 5.0) is None


def test_df6_maximum_with_unit():
    p = ParamDef(code="Y1", name="Y", unit="Hz", scale=0.01, min=0, max=400, size=16,
                 extra={"bytes": 2, "df6_max": 120})
    drive = SimpleNamespace(pkw=object(), device=lambda: "DF6")
    ref = ParamRef("Y1", "Y", 1, 0, False, 16, p)
    assert mo.MoellerDrive.check_value(drive, ref, 130) == "Y1 (Y): 130 Hz is above the DF6 maximum 120 Hz"
    assert mo.MoellerDrive.check_value(drive, ref, 120) is None
    # without a parameter channel the device cannot be asked: no DF6 check
    nopkw = SimpleNamespace(pkw=None, device=lambda: pytest.fail("must not ask the device"))
    assert mo.MoellerDrive.check_value(nopkw, ref, 130) is None
    # a parameter without df6 keys never asks the device
    plain = ParamDef(code="Z1", name="Z", scale=1, min=0, max=10, extra={"bytes": 2})
    asks = SimpleNamespace(pkw=object(), device=lambda: pytest.fail("must not ask the device"))
    assert mo.MoellerDrive.check_value(asks, ParamRef("Z1", "Z", 2, 0, False, 16, plain), 5) is None


def test_comm_loss_setting_reads_both_slots(prof):
    _, drive = rig(prof)
    got = drive.comm_loss_setting()
    assert set(got) == {"P002", "P001"}
    assert all(v is not None and v.code in ("P002", "P001") for v in got.values())


def test_bus_control_check_names_missing_rights(prof):
    model, drive = rig(prof)
    model.control_rights = 0                         # PNU 928 = 0 (spec: process-data rights)
    assert drive.bus_control_check() == ["PNU 928 = 0: no process-data control rights"]


# -- wire values ----------------------------------------------------------------------------------

def test_value_from_wire_widths_and_sign():
    u1 = P(scale=1, extra={"bytes": 1})
    s1 = P(scale=1, signed=True, extra={"bytes": 1})
    assert mo.value_from_wire(u1, 0xFF) == 255 and mo.value_from_wire(u1, 0x1FF) == 255
    assert mo.value_from_wire(s1, 0x80) == -128 and mo.value_from_wire(s1, 0x7F) == 127
    assert mo.value_from_wire(s1, 0x40) == 64
    # no `bytes`: the size says it (32 bits = 4 octets)
    assert mo.value_from_wire(P(scale=1, size=32), 0xFFFFFFFF) == 4294967295
    assert mo.value_from_wire(P(scale=1, size=32, signed=True), 0xFFFFFFFF) == -1
    assert mo.value_from_wire(P(scale=0.01, size=32, signed=True), 0xFFFFFF9C) == -1.0


def test_wire_from_value_widths():
    assert mo.wire_from_value(P(scale=1, size=32), -1) == 0xFFFFFFFF
    assert mo.wire_from_value(P(scale=1, extra={"bytes": 1}), -1) == 0xFF
    assert mo.wire_from_value(P(scale=0.01, extra={"bytes": 4}, size=32), 4.0) == 400
    assert mo.wire_from_value(P(scale=0, extra={"bytes": 2}), 7.9) == 7


# -- profile validation: one line saying what and where -------------------------------------------

from pathlib import Path

from profidrive_cli.datafile import DataFileError
from profidrive_cli.drives.profile import load_profile_file

SRC = Path(__file__).resolve().parent.parent / "profiles" / "moeller-de6-net-dp.yaml"
F002 = 'pnu: 23, unit: "s", scale: 0.01, min: 0.01, max: 3600.0, access: "rw", bytes: 4, size: 32}'
A001 = '"A001", name: "Selection of frequency command destination", pnu: 189, min: 0, max: 5, access: "stop", bytes: 1, format: "code"'


def _load(tmp_path, old, new):
    text = SRC.read_text(encoding="utf-8")
    assert old in text
    dst = tmp_path / "moeller-test.yaml"
    dst.write_text(text.replace(old, new, 1), encoding="utf-8")
    return dst, load_profile_file(dst, check_sections=False)


@pytest.mark.parametrize("old, new, msg, marker", [
    (F002, F002.replace(", bytes: 4", ""), "F002: missing 'bytes' (1, 2 or 4)", '"F002"'),
    (F002, F002.replace(", size: 32", ""), "F002: bytes 4 needs size 32, got 16", '"F002"'),
    (A001, A001.replace("bytes: 1", "bytes: 2, size: 32"), "A001: bytes 2 needs size 16, got 32", '"A001"'),
    # a format the profile loader knows (drives/formats.py) but the Moeller card does not use
    (A001, A001.replace('"code"', '"fcode"'),
     "A001: format must be one of code, hex, bits, baud, alarm947, got 'fcode'", '"A001"'),
    ("ctw_reverse_bit: 11", "ctw_reverse_bit: 16", "'ctw_reverse_bit' must be an integer 11..15, got 16",
     "ctw_reverse_bit"),
    ("ctw_reverse_bit: 11", "ctw_reverse_bit: 10", "'ctw_reverse_bit' must be an integer 11..15, got 10",
     "ctw_reverse_bit"),
    ("ctw_reverse_bit: 11", "ctw_reverse_bit: true",
     "'ctw_reverse_bit' must be an integer 11..15, got True", "ctw_reverse_bit"),
    ("ctw_reverse_bit: 11", "ctw_reverse_bit: 1.5",
     "'ctw_reverse_bit' must be an integer 11..15, got 1.5", "ctw_reverse_bit"),
    (A001, A001 + ", ranges: [[5, 1]]", "A001: ranges must be a list of [min, max]", '"A001"'),
    (A001, A001 + ", ranges: [[0, 1, 2]]", "A001: ranges must be a list of [min, max]", '"A001"'),
    (A001, A001 + ', ranges: [[0, "x"]]', "A001: ranges must be a list of [min, max]", '"A001"'),
    (A001, A001 + ", ranges: []", "A001: ranges must be a list of [min, max]", '"A001"'),
    (A001, A001 + ", ranges: [0, 1]", "A001: ranges must be a list of [min, max]", '"A001"'),
    (A001, A001 + ", df6: 1", "A001: df6 must be true or false", '"A001"'),
    (A001, A001 + ', df6_max: "x"', "A001: df6_max must be a number", '"A001"'),
    (A001, A001 + ", flavour: x",
     "A001: unknown key(s) flavour (Moeller keys: array, bytes, df6, df6_max, format, note, ranges)",
     '"A001"'),
    ("sim_defaults: {A001: 2,", "sim_defaults: {Z999: 1, A001: 2,",
     "sim_defaults: Z999 is not a parameter of this profile", "sim_defaults"),
    ("A001: 2, A002: 1, A004: 50", "A001: 2, A002: x, A004: 50", "sim_defaults: A002 must be a number",
     "sim_defaults"),
    ("A001: 2, A002: 1, A004: 50", "A001: 2, A002: true, A004: 50", "sim_defaults: A002 must be a number",
     "sim_defaults"),
    ("comm_loss: {param: P002, other_param: P001, alarm: E70}", "comm_loss: 5",
     "comm_loss must be a mapping", "comm_loss"),
    ("comm_loss: {param: P002, other_param: P001, alarm: E70}",
     "comm_loss: {param: P002, other_param: Q001, alarm: E70}",
     "moeller.comm_loss.other_param: Q001 is not a parameter of this profile", "comm_loss"),
    ("frequency: {param: A001, bus_value: 2}", "frequency: 7",
     "control_source.frequency must be {param, bus_value}", "frequency"),
    ("ctw_reverse_bit: 11", "ctw_reverse_bit: 12.5",
     "'ctw_reverse_bit' must be an integer 11..15, got 12.5", "ctw_reverse_bit"),
    ("commands: {param: A002, bus_value: 1}", "commands: {param: A002, bus_value: true}",
     "'bus_value' must be an integer 0..255, got True", "commands:"),
    ("df6_device_id: 0x812C", "df6_device_id: 0x10000",
     "'df6_device_id' must be an integer 0..65535, got 65536", "df6_device_id"),
    ("commands: {param: A002, bus_value: 1}", "commands: {param: A002, bus_value: 256}",
     "'bus_value' must be an integer 0..255, got 256", "commands:"),
    ("commands: {param: A002, bus_value: 1}", "commands: {param: A999, bus_value: 1}",
     "moeller.control_source.commands.param: A999 is not a parameter of this profile", "commands:"),
])
def test_profile_errors_say_what_and_where(tmp_path, old, new, msg, marker):
    path, prof = _load(tmp_path, old, new)
    with pytest.raises(DataFileError) as e:
        mo.moeller_config(prof)
    assert e.value.message == msg
    line = path.read_text(encoding="utf-8").splitlines()[e.value.line - 1]
    assert marker in line
    assert str(e.value).startswith(f"{path}:{e.value.line}:")


def test_comm_loss_without_the_other_slot(tmp_path):
    _, prof = _load(tmp_path, "comm_loss: {param: P002, other_param: P001, alarm: E70}",
                    "comm_loss: {param: P002, alarm: E70}")
    mc = mo.moeller_config(prof)
    assert (mc.comm_loss_param, mc.comm_loss_other_param, mc.comm_loss_alarm) == ("P002", None, "E70")
    _, prof = _load(tmp_path, A001, A001 + ", ranges: [[2, 2]]")
    assert mo.moeller_config(prof).frequency_param == "A001"


def test_edge_bits_15_and_bus_value_255_are_accepted(tmp_path):
    _, prof = _load(tmp_path, "ctw_reverse_bit: 11", "ctw_reverse_bit: 15")
    assert mo.moeller_config(prof).reverse_bit == 15
    _, prof = _load(tmp_path, "commands: {param: A002, bus_value: 1}",
                    "commands: {param: A002, bus_value: 255}")
    assert mo.moeller_config(prof).commands_bus_value == 255


def test_raw_pnu_rows_need_no_bytes(tmp_path):
    # a PNUnnn row is a plain word: `bytes` may be left out; a named row must have it
    _, prof = _load(tmp_path, F002, F002 + '\n  - {code: "PNU999", name: "Raw", pnu: 999, access: "ro"}')
    assert "bytes" not in prof.param("PNU999").extra
    assert mo.moeller_config(prof).df6_device_id == 0x812C


def test_validation_of_a_profile_without_a_path_names_it():
    from dataclasses import replace
    bad = ParamDef(code="X9", name="X", line=7)
    prof = replace(load_profile("moeller"), path=None)
    prof = replace(prof, parameters={**prof.parameters, "X9": bad})
    with pytest.raises(DataFileError) as e:
        mo.moeller_config(prof)
    assert str(e.value).startswith("<profile>:7:") and "X9: missing 'bytes' (1, 2 or 4)" in str(e.value)


# -- status flag and decoder ----------------------------------------------------------------------

@pytest.mark.parametrize("zsw, ctw, gives", [
    (0x0200, 0x047F, True),           # ZSW bit 9 control requested, STW bit 12 = 0
    (0x0200, 0x147F, False),          # STW bit 12 = 1: commands taken away from the bus
    (0x0000, 0x047F, False),          # the drive does not request control
    (0x0200, None, True),             # nothing sent yet: control word 0
])
def test_bus_gives_commands_flag(zsw, ctw, gives):
    me = SimpleNamespace(last_ctw=ctw, mc=mo.MoellerConfig())
    status = SimpleNamespace(flags={}, raw={})
    mo.MoellerDrive.status_extras(me, SimpleNamespace(word1=zsw), status)
    assert status.flags == {"bus gives commands": gives}
    assert status.raw == {"control_word": ctw or 0}


def test_decoder_uses_max_hz_and_the_profile_bits(prof, tmp_path):
    data = bytes(8) + bytes.fromhex("0C7F 2000")            # STW bit 11 set, HSW +50 %
    out = mo.decode_area(prof, "ppo1", "request", data, max_hz=100)
    assert out["reference"]["hz"] == 50.0
    assert out["control_word"]["direction"] == "reverse"
    assert out["control_word"]["bus_controls"] == "frequency and commands"
    assert out["text"][-2] == ("bus controls (with A001 = 2, A002 = 1): frequency and commands; "
                               "direction reverse (sign of HSW XOR STW bit 11)")
    assert out["text"][-1].startswith("summary:")
    # a profile that moves the bits: bit 15 reverses, bit 14 takes the commands away
    _load(tmp_path, "ctw_reverse_bit: 11\n", "ctw_reverse_bit: 15\n")
    text = (tmp_path / "moeller-test.yaml").read_text(encoding="utf-8")
    (tmp_path / "moeller-test.yaml").write_text(
        text.replace("ctw_commands_invalid_bit: 12", "ctw_commands_invalid_bit: 14"), encoding="utf-8")
    p2 = load_profile_file(tmp_path / "moeller-test.yaml", check_sections=False)
    out2 = mo.decode_area(p2, "ppo1", "request", bytes(8) + bytes.fromhex("C47F 2000"))
    assert out2["control_word"]["direction"] == "reverse"
    assert out2["control_word"]["bus_controls"] == "frequency only"
    assert "XOR STW bit 15" in out2["text"][-2]



def test_in_ranges_tolerance_is_inclusive():
    p = P(extra={"ranges": [[1, 48]]})
    assert mo.in_ranges(p, 1 - 1e-9) and mo.in_ranges(p, 48 + 1e-9)
    q = P(min=0.01, max=3600.0)
    assert mo.in_ranges(q, 0.01 - 1e-9) and mo.in_ranges(q, 3600.0 + 1e-9)


def test_control_source_entries_may_leave_out_param_or_bus_value(tmp_path):
    _, prof = _load(tmp_path, "frequency: {param: A001, bus_value: 2}", "frequency: {bus_value: 2}")
    assert mo.moeller_config(prof).frequency_param == "A001"
    _, prof = _load(tmp_path, "commands: {param: A002, bus_value: 1}", "commands: {param: A002}")
    assert mo.moeller_config(prof).commands_bus_value == 1
    _, prof = _load(tmp_path, "df6_device_id: 0x812C", "df6_device_id: 0")
    assert mo.moeller_config(prof).df6_device_id == 0


def test_block_style_error_points_at_the_key(tmp_path):
    path, prof = _load(tmp_path, "commands: {param: A002, bus_value: 1}",
                       "commands:\n      bus_value: 1\n      param: A999")   # the key, not the first line
    with pytest.raises(DataFileError) as e:
        mo.moeller_config(prof)
    assert path.read_text(encoding="utf-8").splitlines()[e.value.line - 1].strip().startswith("param: A999")


def test_section_errors_of_a_profile_without_a_path(tmp_path):
    from dataclasses import replace
    _, prof = _load(tmp_path, "ctw_reverse_bit: 11", "ctw_reverse_bit: 16")
    with pytest.raises(DataFileError) as e:
        mo.moeller_config(replace(prof, path=None))
    assert str(e.value).startswith("<profile>:")


def test_bus_control_check_texts_with_a_stub_drive():
    from profidrive_cli.drives.profidrive import PNU_CONTROL_RIGHTS, PNU_EDIT_RIGHTS
    good = {"A001": 2, "A002": 1}

    def rights(values):
        def read_raw(pnu):
            v = values[pnu]
            if isinstance(v, Exception):
                raise v
            return v
        return read_raw
    me = SimpleNamespace(mc=mo.MoellerConfig(), read_param=lambda c: SimpleNamespace(raw=good[c]),
                         read_raw=rights({PNU_EDIT_RIGHTS: 0, PNU_CONTROL_RIGHTS: 1}))
    assert mo.MoellerDrive.bus_control_check(me) == ["PNU 927 = 0: no parameter edit rights"]
    me.read_raw = rights({PNU_EDIT_RIGHTS: 1, PNU_CONTROL_RIGHTS: ParamError("PNU 928: refused")})
    assert mo.MoellerDrive.bus_control_check(me) == ["PNU 928: refused"]


@pytest.mark.parametrize("old, new, msg, marker", [
    ("moeller:\n", "moeller_x:\n", "missing section 'moeller'", None),
    ("moeller:\n", "moeller: 5\nmoeller_x:\n", "'moeller' must be a mapping", "moeller: 5"),
    ("  df6_device_id: 0x812C", "  df6_device_id: 0x812C\n  colour: blue",
     "moeller: unknown key 'colour' (known: comm_loss, control_source, ctw_commands_invalid_bit, "
     "ctw_reference_invalid_bit, ctw_reverse_bit, df6_device_id, sim_defaults)", "colour: blue"),
])
def test_section_errors_exact(tmp_path, old, new, msg, marker):
    path, prof = _load(tmp_path, old, new)
    with pytest.raises(DataFileError) as e:
        mo.moeller_config(prof)
    assert e.value.message == msg
    assert str(e.value).startswith(f"{path}:")
    if marker:
        assert path.read_text(encoding="utf-8").splitlines()[e.value.line - 1].strip().startswith(marker)
    else:
        assert e.value.line is not None


def test_two_unknown_parameter_keys_are_listed_sorted(tmp_path):
    _, prof = _load(tmp_path, A001, A001 + ", zeta: 1, alpha: 2")
    with pytest.raises(DataFileError) as e:
        mo.moeller_config(prof)
    assert e.value.message.startswith("A001: unknown key(s) alpha, zeta (Moeller keys:")


# -- jog and stop on the wire: CTW bit 8 = inching 1, bit 11 = REV (spec: CTW table; moeller.py
#    MoellerDrive.jog). Operation is bits 0-6 and 10 (0x047F); a normal stop drops bit 0 (OFF1).

def test_jog_control_words_forward_reverse_and_off(prof):
    _, d = rig(prof)
    d.status()
    d.jog(True, reverse=True)
    d.cycle()
    assert d.last_ctw == 0x0D7F                    # 0x047F | bit 8 | bit 11
    d.jog(False)
    d.cycle()
    assert d.last_ctw == 0x047F and d.extra_bits == 0
    d.jog(True, reverse=False)
    d.cycle()
    assert d.last_ctw == 0x057F                    # forward: bit 8 only
    d.jog(True, reverse=True)
    d.cycle()
    assert d.last_ctw == 0x0D7F
    d.jog(True, reverse=False)                     # reverse -> forward: bit 11 cleared
    d.cycle()
    assert d.last_ctw == 0x057F


def test_a_stop_ends_the_jog_and_its_direction(prof):
    _, d = rig(prof)
    d.status()
    d.jog(True, reverse=True)
    d.cycle()
    st = d.stop("normal", wait=False)
    d.cycle()
    assert d.last_ctw == 0x047E and d.extra_bits == 0           # OFF1, no bit 8, no bit 11
    assert st.running                                            # wait=False: returns at once


# -- the moeller section: whole-key errors and the defaults when keys are left out ----------------------
# Defaults from the spec / profile comments: A001 = 2 (operator) gives the reference, A002 = 1
# (terminal) the commands; STW/CTW bits 12, 13 (commands / reference invalid) and 11 (REV);
# comm loss P002 (slot 2) with its slot-1 twin P001, alarm E70; PNU 964 0x812C (DF, model 300).

CS = "  control_source:\n    frequency: {param: A001, bus_value: 2}     # 2 = operator\n" \
     "    commands: {param: A002, bus_value: 1}      # 1 = terminal\n"


@pytest.mark.parametrize("old, new, msg, marker", [
    (CS, "  control_source: 5\n", "control_source must be a mapping", "control_source"),
    ("  sim_defaults: {A001: 2,", "  sim_defaults: 5\n  xsim: {A001: 2,", None, None),
    ("comm_loss: {param: P002, other_param: P001, alarm: E70}",
     "comm_loss: {param: P002, other_param: P001, alarm: E99}",
     "comm_loss.alarm 'E99' is not in alarms", "comm_loss"),
    ("comm_loss: {param: P002, other_param: P001, alarm: E70}",
     "comm_loss: {param: P002, other_param: P001, alarm: 70}",
     "comm_loss.alarm 70 is not in alarms", "comm_loss"),
    ("comm_loss: {param: P002, other_param: P001, alarm: E70}",
     "comm_loss: {param: Q002, other_param: P001, alarm: E70}",
     "moeller.comm_loss.param: Q002 is not a parameter of this profile", "comm_loss"),
    ("ctw_commands_invalid_bit: 12", "ctw_commands_invalid_bit: 16",
     "'ctw_commands_invalid_bit' must be an integer 11..15, got 16", "ctw_commands_invalid_bit"),
    ("ctw_reference_invalid_bit: 13", "ctw_reference_invalid_bit: 10",
     "'ctw_reference_invalid_bit' must be an integer 11..15, got 10", "ctw_reference_invalid_bit"),
    ("ctw_reference_invalid_bit: 13", "ctw_reference_invalid_bit: 16",
     "'ctw_reference_invalid_bit' must be an integer 11..15, got 16", "ctw_reference_invalid_bit"),
])
def test_moeller_section_errors(tmp_path, old, new, msg, marker):
    if msg is None:                               # sim_defaults given as a number
        text = SRC.read_text(encoding="utf-8")
        i = text.index("  sim_defaults: {")
        j = text.index("\n\n", i)
        dst = tmp_path / "moeller-test.yaml"
        dst.write_text(text[:i] + "  sim_defaults: 5" + text[j:], encoding="utf-8")
        path, prof = dst, load_profile_file(dst, check_sections=False)
        msg, marker = "sim_defaults must be a mapping code: value", "sim_defaults"
    else:
        path, prof = _load(tmp_path, old, new)
    with pytest.raises(DataFileError) as e:
        mo.moeller_config(prof)
    assert e.value.message == msg
    line = path.read_text(encoding="utf-8").splitlines()[e.value.line - 1]
    assert marker in line
    assert str(e.value).startswith(f"{path}:{e.value.line}:")


def test_moeller_section_defaults(tmp_path):
    text = SRC.read_text(encoding="utf-8")
    for line in ("  ctw_commands_invalid_bit: 12\n", "  ctw_reference_invalid_bit: 13\n",
                 "  ctw_reverse_bit: 11\n", "  comm_loss: {param: P002, other_param: P001, alarm: E70}\n",
                 "  df6_device_id: 0x812C\n", CS):
        assert line in text
        text = text.replace(line, "", 1)
    dst = tmp_path / "moeller-defaults.yaml"
    dst.write_text(text, encoding="utf-8")
    mc = mo.moeller_config(load_profile_file(dst, check_sections=False))
    assert (mc.frequency_param, mc.frequency_bus_value, mc.commands_param, mc.commands_bus_value) == \
        ("A001", 2, "A002", 1)
    assert (mc.commands_invalid_bit, mc.reference_invalid_bit, mc.reverse_bit) == (12, 13, 11)
    assert (mc.comm_loss_param, mc.comm_loss_other_param, mc.comm_loss_alarm) == ("P002", "P001", "E70")
    assert mc.df6_device_id == 0x812C
    assert mc.sim_defaults["A004"] == 50 and mc.sim_defaults["PNU928"] == 1


def test_comm_loss_with_defaults_inside(tmp_path):
    _, prof = _load(tmp_path, "comm_loss: {param: P002, other_param: P001, alarm: E70}",
                    "comm_loss: {other_param: P001}")
    mc = mo.moeller_config(prof)
    assert (mc.comm_loss_param, mc.comm_loss_other_param, mc.comm_loss_alarm) == ("P002", "P001", "E70")


def _block(tmp_path, old, new):
    text = SRC.read_text(encoding="utf-8")
    if old == "SIM":
        i = text.index("  sim_defaults: {")
        j = text.index("\n\n", i)
        text = text[:i] + new + text[j:]
    else:
        assert old in text
        text = text.replace(old, new, 1)
    dst = tmp_path / "moeller-block.yaml"
    dst.write_text(text, encoding="utf-8")
    return dst, load_profile_file(dst, check_sections=False)


@pytest.mark.parametrize("old, new, msg, marker", [
    (CS, "  control_source:\n    - 1\n", "control_source must be a mapping", "control_source:"),
    (CS, "  control_source:\n    commands: {param: A002, bus_value: 1}\n    frequency: 7\n",
     "control_source.frequency must be {param, bus_value}", "frequency: 7"),
    ("  comm_loss: {param: P002, other_param: P001, alarm: E70}\n",
     "  comm_loss:\n    param: P002\n    alarm: E99\n", "comm_loss.alarm 'E99' is not in alarms", "alarm: E99"),
    ("SIM", "  sim_defaults:\n    A001: 2\n    Z999: 1", "sim_defaults: Z999 is not a parameter of this profile",
     "Z999: 1"),
    ("SIM", "  sim_defaults:\n    A001: 2\n    A002: x", "sim_defaults: A002 must be a number", "A002: x"),
])
def test_block_style_section_errors_point_at_the_key(tmp_path, old, new, msg, marker):
    path, prof = _block(tmp_path, old, new)
    with pytest.raises(DataFileError) as e:
        mo.moeller_config(prof)
    assert e.value.message == msg
    assert marker in path.read_text(encoding="utf-8").splitlines()[e.value.line - 1]


def test_control_source_with_one_role_and_no_sim_defaults(tmp_path):
    _, prof = _block(tmp_path, CS, "  control_source:\n    commands: {param: A001, bus_value: 3}\n")
    mc = mo.moeller_config(prof)
    assert (mc.commands_param, mc.commands_bus_value) == ("A001", 3)
    assert (mc.frequency_param, mc.frequency_bus_value) == ("A001", 2)       # the default
    (tmp_path / "b").mkdir()
    _, prof = _block(tmp_path / "b", "SIM", "")                          # no sim_defaults at all
    assert mo.moeller_config(prof).sim_defaults == {}


def test_stop_keeps_the_callers_time_bound(prof):
    # F003 = 3600 s: the ramp down from 50 % takes far longer than the 2 s the caller allows
    # (a checklist `stop: {within: 2}`); the stop must give up after 2 s, not after its 30 s default
    from profidrive_cli.drives.base import DriveError
    _, d = rig(prof)
    d.status()
    d.write_param("F002", 0.5)
    d.write_param("F003", 3600.0)
    d.set_speed(50)
    d.start(timeout=5)
    for _ in range(200):
        d.cycle()
    t0 = d.channel.now()
    with pytest.raises(DriveError) as e:
        d.stop("normal", wait=True, timeout=2.0)
    assert "timed out after 2 s" in str(e.value)
    assert 2.0 <= d.channel.now() - t0 < 2.5


def test_control_source_not_a_mapping_points_at_its_key_not_the_section(tmp_path):
    # control_source moved after the CTW bits, so its line is not the section's first line
    text = SRC.read_text(encoding="utf-8").replace(CS, "", 1)
    text = text.replace("  ctw_reverse_bit: 11\n", "  ctw_reverse_bit: 11\n  control_source:\n    - 1\n", 1)
    dst = tmp_path / "moeller-cs.yaml"
    dst.write_text(text, encoding="utf-8")
    with pytest.raises(DataFileError) as e:
        mo.moeller_config(load_profile_file(dst, check_sections=False))
    assert e.value.message == "control_source must be a mapping"
    assert dst.read_text(encoding="utf-8").splitlines()[e.value.line - 1] == "  control_source:"
