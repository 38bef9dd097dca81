"""Families answer family questions as class facts, from the profile and layout alone: whether the
card can jog (Drive.jog_refusal_for) and which status flags its decode can set
(Drive.status_flag_names). Neither builds a Drive on a fake channel nor runs the simulator.

Held against the connected drive: for every shipped profile and layout the class fact agrees with a
Drive's own supports_jog / jog_refusal(), and every flag a decoded status carries is named."""

from __future__ import annotations

import pytest

from profidrive_cli.drives import drive_class, make_drive
from profidrive_cli.drives.profile import all_profiles, load_profile
from profidrive_cli.sim.direct import DirectChannel
from profidrive_cli.sim.plant import make_model

CASES = [(p.name, layout) for p in all_profiles() for layout in p.layouts]


class _Counting:
    """A channel that counts exchanges: the class facts must not need one."""

    def __init__(self):
        self.exchanges = 0

    def exchange(self, outputs: bytes) -> bytes:
        self.exchanges += 1
        raise AssertionError("a class fact sent a telegram")

    def now(self) -> float:
        return 0.0


@pytest.mark.parametrize("name,layout", CASES)
def test_jog_refusal_for_agrees_with_the_connected_drive(name, layout):
    prof = load_profile(name)
    fact = drive_class(prof).jog_refusal_for(prof, layout)
    ch = _Counting()
    d = make_drive(ch, prof, layout)
    assert fact == (None if d.supports_jog else d.jog_refusal()), (name, layout)
    assert ch.exchanges == 0


@pytest.mark.parametrize("name,layout", CASES)
def test_every_flag_a_decoded_status_carries_is_named(name, layout):
    prof = load_profile(name)
    names = drive_class(prof).status_flag_names(prof, layout)
    d = make_drive(DirectChannel(make_model(prof), prof.layouts[layout].cfg), prof, layout)
    seen = set(d.cycle().flags)
    assert seen <= set(names), (name, layout, sorted(seen - set(names)))
    assert len(names) == len(set(names)), names


def test_the_yaskawa_status_word_bits_are_the_manuals():
    # yaskawa-profibus-dp.md, status word (spec 2.5): bit 0 running ... bit 15 zero-servo complete
    prof = load_profile("yaskawa")
    names = drive_class(prof).status_flag_names(prof, "basic")
    assert names[:8] == ["running", "zero_speed", "reverse", "reset_signal", "frequency_agree", "ready",
                         "alarm", "fault"]
    assert len(names) == 16


def test_the_moeller_extra_flag_is_named_and_fuji_has_none():
    moeller = load_profile("moeller")
    assert "bus gives commands" in drive_class(moeller).status_flag_names(moeller, "ppo1")
    fuji = load_profile("fuji-g1")
    assert "bus gives commands" not in drive_class(fuji).status_flag_names(fuji, "ppo1")


def test_toyo_names_its_fault_flags_in_toyo_mode_and_the_zsw_in_profidrive_mode():
    prof = load_profile("toyo")
    toyo_mode = drive_class(prof).status_flag_names(prof, "toyo")
    assert any(n.startswith("fault: ") for n in toyo_mode)
    assert "jogging" not in toyo_mode                     # mode 1 has no ZSW (jog is a status flag)
    profidrive = drive_class(prof).status_flag_names(prof, "ppo1")
    assert "jogging" in profidrive


def _label_or_error(fn, code):
    try:
        return fn(code)
    except Exception as e:                       # noqa: BLE001 - the same refusal either way
        return (type(e).__name__, str(e))


#: raw addresses and short forms every family is asked about, besides each profile's own codes
RAW_CODES = ["PNU918", "P918", "PNU947[3]", "REG0x0180", "REG384", "F07", "E31", "A038", "C1-01",
             "TB01[0,1]", "FH[3]", "nonsense", ""]


@pytest.mark.parametrize("name", sorted({p.name for p in all_profiles()}))
def test_param_label_for_agrees_with_the_connected_drive(name):
    # checklist validation asks the class (no Drive built on a fake channel); a connected drive's
    # param_label must give the same label, or the same refusal
    prof = load_profile(name)
    cls = drive_class(prof)
    ch = _Counting()
    d = make_drive(ch, prof, prof.default_layout)
    for code in list(prof.parameters) + RAW_CODES:
        fact = _label_or_error(lambda c: cls.param_label_for(prof, c), code)
        conn = _label_or_error(d.param_info, code)        # how a write resolves it on the bus
        if isinstance(conn, tuple):
            assert isinstance(fact, tuple), (name, code, fact, conn)      # refused both ways
        else:
            assert fact == (conn.code, conn.param), (name, code)
    assert ch.exchanges == 0
