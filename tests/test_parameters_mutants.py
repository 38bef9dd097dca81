"""session/parameters.py (Parameters) sans-bus: where pdrive decides whether a parameter write is
allowed -- a dangerous parameter refused without allow_dangerous, a value the parameter cannot hold
exactly refused, a stop-only parameter refused while the motor turns.

A fake station (the Host Parameters reads: profile, address, ident, layout, master.link, drive,
fmax_hz, need_drive, warn) holds a fake Drive that records what Parameters asks of it
(param_info, value_problem, params_at, cycle, read_resolved, write_resolved, take_notes,
save_support, save). The profile is the real Fuji OPC-G1-PDP one (profiles/fuji-opc-g1-pdp.yaml,
its lines quoted below; the card manual's figures in ../shared/spec/fuji-opc-g1-pdp.md). Expected
words are the module's documented refusals, written out by hand. Written for mutation testing
(tools/mutation/run.py session/parameters.py): in-process only.
"""

from __future__ import annotations

import copy
from types import SimpleNamespace

import pytest

import profidrive_cli.session.backup as backup
import profidrive_cli.session.dumpfile as dumpfile
import profidrive_cli.session.restore as restore
from profidrive_cli import PdriveError, UsageError
from profidrive_cli.drives.base import DriveError, DriveStatus, ParamInfo, ParamValue
from profidrive_cli.drives.profile import ParamDef, load_profile
from profidrive_cli.session.parameters import Parameters, WritePlan

FUJI = load_profile("fuji-opc-g1-pdp")

# profiles/fuji-opc-g1-pdp.yaml:116-117: H03 data initialisation, access stop, dangerous, its danger text
H03_DANGER = ("resets the inverter's function codes to their factory values (every setting made at "
              "commissioning is lost)")
# profiles/fuji-opc-g1-pdp.yaml:166-167: PNU970, dangerous, its danger text
PNU970_DANGER = ("a 1 then 0 resets the inverter's function codes to their factory values (every "
                 "setting made at commissioning is lost)")
# profiles/fuji-opc-g1-pdp.yaml:111: F03 "Maximum frequency 1 (100 % of MRV/MAV)", Hz, 0.1, 25..500, access stop
F03_NAME = "Maximum frequency 1 (100 % of MRV/MAV)"
# the default refusal words when the profile gives no `danger:` text (drives/values.py DEFAULT_DANGER)
DEFAULT_DANGER = "initialises data or runs the motor on its own (marked dangerous in the profile)"


def status(state="S4 operation", running=False, speed=0.0):
    return DriveStatus(state=state, running=running, fault=False, flags={}, speed_percent=speed,
                       speed_hz=None)


def info_of(code, access=None, param=True):
    p = FUJI.param(code)
    return ParamInfo(p.code, p.name, p.unit, p if param else None, access or p.access)


def raw_info(code="PNU970", access="raw"):
    """A parameter reached by its raw PNU (no profile entry: ParamInfo.param is None)."""
    return ParamInfo(code, f"raw {code}", "", None, access)


class Drive:
    """What Parameters uses of drives.base.Drive, recorded."""

    def __init__(self, st=None, problems=None, hits=None, hits_error=None, notes=None,
                 support="command", unknown=None):
        self.st = st or status()
        self.problems = problems or {}      # value -> the exact-value refusal
        self.hits = hits or []              # params_at's answer
        self.hits_error = hits_error        # params_at raises it
        self.notes = notes
        self.support = support
        self.unknown = unknown              # param_info's UsageError words for a code not in FUJI
        self.log: list[tuple] = []

    def param_info(self, code):
        self.log.append(("param_info", code))
        p = FUJI.param(code)
        if p is None:
            raise UsageError(self.unknown or f"drive: no code {code}")
        return ParamInfo(p.code, p.name, p.unit, p, p.access)

    def value_problem(self, info, value):
        self.log.append(("value_problem", info.code, value))
        return self.problems.get(value)

    def params_at(self, info):
        self.log.append(("params_at", info.code))
        if self.hits_error is not None:
            raise self.hits_error
        return self.hits

    def cycle(self):
        self.log.append(("cycle",))
        return self.st

    def read_resolved(self, info):
        self.log.append(("read", info.code))
        return ParamValue(info.code, info.name, 7, 7, info.unit)

    def write_resolved(self, info, value):
        self.log.append(("write", info.code, value))
        raw = int(value) if float(value).is_integer() else 0
        return ParamValue(info.code, info.name, raw, value, info.unit)

    def take_notes(self):
        self.log.append(("notes",))
        out, self.notes = self.notes, []
        return out

    def save_support(self):
        self.log.append(("save_support",))
        return self.support

    def save(self):
        self.log.append(("save",))

    def calls(self, name):
        return [c for c in self.log if c[0] == name]


class Host:
    def __init__(self, drive=None, profile=FUJI, fmax_hz=60.0, link=None):
        self.profile = profile
        self.address = 3
        self.ident = 0xFD01
        self.layout = "ppo1"
        self.drive = drive
        self.fmax_hz = fmax_hz
        self.master = SimpleNamespace(link=link if link is not None else SimpleNamespace(name="COM3"))
        self.warnings: list[str] = []

    @property
    def motion(self):                       # the station's Motion: here the fake itself (fmax_hz)
        return self

    def need_drive(self):
        if self.drive is None:
            raise DriveError("no drive")
        return self.drive

    def warn(self, text):
        self.warnings.append(text)


def params(drive=None, **kw):
    d = drive if drive is not None else Drive()
    return Parameters(Host(d, **kw)), d


# -- the station ----------------------------------------------------------------------------------

def test_the_station_face():
    p, d = params()
    assert (p.profile, p.address, p.ident, p.layout, p.port) == (FUJI, 3, 0xFD01, "ppo1", "COM3")
    assert p.need_drive() is d
    p.warn("careful")
    assert p.host.warnings == ["careful"]
    assert Parameters.load_dump is dumpfile.load_dump


def test_a_link_without_a_name_is_the_empty_port_name():
    p = Parameters(Host(Drive(), link=SimpleNamespace()))
    assert p.port == ""


def test_no_profile_yet_is_said_in_words():
    h = Host(Drive())
    h.profile = None
    with pytest.raises(PdriveError) as e:
        _ = Parameters(h).profile
    assert str(e.value) == "Parameters: the station is not identified yet"


# -- preflight: the profile alone, before the drive is connected ------------------------------------

def test_preflight_refuses_a_dangerous_entry_without_allow():
    p = Parameters(Host(None))              # no drive connected: the profile alone
    with pytest.raises(UsageError) as e:
        p.preflight("H03", "1")
    assert str(e.value) == (f"H03 is dangerous: writing it {H03_DANGER}; nothing was written "
                            f"(add --allow-dangerous, and confirm, to write it)")
    with pytest.raises(UsageError, match="H03 +is dangerous: writing it resets"):
        p.preflight(" H03 ", "1")           # the code is stripped to find the entry


def test_preflight_with_allow_returns_the_danger_for_the_question():
    p = Parameters(Host(None))
    assert p.preflight("H03", "1", allow_dangerous=True) == H03_DANGER
    assert p.preflight("H03", "0x1", allow_dangerous=True) == H03_DANGER
    # notation that is not a number: left to plan(), the danger still returned
    assert p.preflight("H03", "one", allow_dangerous=True) == H03_DANGER


def test_preflight_passes_a_value_the_entry_holds():
    p = Parameters(Host(None))
    assert p.preflight("F07", "2.5") is None      # 0..6000 s in 0.1 s steps (yaml:112)
    assert p.preflight("H81", "0xFFFF") is None   # 0..65535 (yaml:120)
    assert p.preflight("H81", "0x0") is None


def test_preflight_refuses_a_decimal_value_the_entry_cannot_hold():
    p = Parameters(Host(None))
    # F07: 0.1 s steps (yaml:112): 2.55 s lies between 2.5 and 2.6
    with pytest.raises(UsageError) as e:
        p.preflight("F07", "2.55")
    assert str(e.value) == "F07 = 2.55 s cannot be held exactly: resolution 0.1 s; nearest 2.5 s or 2.6 s"
    # F03: 25..500 Hz (yaml:111)
    with pytest.raises(UsageError) as e:
        p.preflight("F03", "501")
    assert str(e.value) == f"F03 ({F03_NAME}): 501 Hz is outside 25..500 Hz; nearest 500 Hz"
    with pytest.raises(UsageError) as e:
        p.preflight("F03", "-1")
    assert str(e.value) == f"F03 ({F03_NAME}): -1 Hz is outside 25..500 Hz; nearest 25 Hz"
    with pytest.raises(UsageError, match="^F03 = 60.05 Hz cannot be held exactly"):
        p.preflight(" F03", "60.05")


def test_preflight_reads_hex_numbers_as_hex():
    p = Parameters(Host(None))
    H81 = "H81 (Light-alarm selection 1 (bit set))"          # 0..65535 (yaml:120)
    with pytest.raises(UsageError) as e:
        p.preflight("H81", "0x10000")      # 65536
    assert str(e.value) == f"{H81}: 65536 is outside 0..65535; nearest 65535"
    with pytest.raises(UsageError) as e:
        p.preflight("H81", "0X10000")      # the prefix in capitals too
    assert str(e.value) == f"{H81}: 65536 is outside 0..65535; nearest 65535"
    with pytest.raises(UsageError) as e:
        p.preflight("H81", "-0x1")         # a negative hex number: -1
    assert str(e.value) == f"{H81}: -1 is outside 0..65535; nearest 0"
    with pytest.raises(UsageError) as e:
        p.preflight("F03", "0x1F5")        # 501 Hz, not 0x1F5 read as a float
    assert str(e.value) == f"F03 ({F03_NAME}): 501 Hz is outside 25..500 Hz; nearest 500 Hz"


def test_preflight_leaves_notation_that_is_not_a_number_to_plan():
    p = Parameters(Host(None))
    assert p.preflight("o40", "041A") is None        # the card's notation (spec fuji-opc-g1-pdp.md:243)
    assert p.preflight("o40", "F26") is None
    assert p.preflight("H81", "0xZZ") is None
    assert p.preflight("F07", "fast") is None


def test_preflight_refuses_infinity_and_nan():
    p = Parameters(Host(None))
    with pytest.raises(UsageError, match=r"^F07 \(Acceleration time 1\): inf is not a value a parameter can hold$"):
        p.preflight("F07", "inf")
    with pytest.raises(UsageError, match=r"^F07 \(Acceleration time 1\): nan is not a value"):
        p.preflight("F07", "nan")


def test_preflight_sees_the_entry_behind_a_raw_pnu():
    # Fuji: PNU = 0x100 + group code, subindex = the function-code number (spec fuji-opc-g1-pdp.md:489);
    # group H = 0x108 = 264 (spec :499), F = 0x104 = 260 (spec :495): PNU264[3] is H03, PNU260[3] is F03.
    # Before, preflight looked up the code text only: PNU264[3] passed without the danger words, so
    # the question before a write on a real port did not say DANGEROUS (plan() refused it later).
    p = Parameters(Host(None))
    with pytest.raises(UsageError) as e:
        p.preflight("PNU264[3]", "1")
    assert str(e.value) == (f"PNU264[3] is dangerous: writing it {H03_DANGER}; nothing was written "
                            f"(add --allow-dangerous, and confirm, to write it)")
    assert p.preflight("PNU264[3]", "1", allow_dangerous=True) == H03_DANGER
    with pytest.raises(UsageError) as e:
        p.preflight("PNU260[3]", "501")
    assert str(e.value) == f"F03 ({F03_NAME}): 501 Hz is outside 25..500 Hz; nearest 500 Hz"
    assert p.preflight("PNU260[3]", "50") is None


def test_entry_of():
    p = Parameters(Host(None))
    assert p.entry_of("H03") is FUJI.param("H03")
    assert p.entry_of("h03") is FUJI.param("H03")
    assert p.entry_of("PNU264[3]") is FUJI.param("H03")
    assert p.entry_of("PNU999") is None          # a raw PNU no entry has
    assert p.entry_of("zz") is None              # not a code of the family: plan() says why


def test_preflight_sees_the_marks_of_an_entry_the_family_cannot_address():
    # a user profile's dangerous entry without a register: the family cannot reach it (the Yaskawa
    # codec says "the profile gives no address for it"), yet its danger words still come before
    # anything is asked
    yaskawa = load_profile("yaskawa-si-p1")
    prof = copy.copy(yaskawa)
    prof.parameters = dict(yaskawa.parameters)
    prof.parameters["X01"] = ParamDef("X01", "no address", extra={"dangerous": True})
    p = Parameters(Host(None, profile=prof))
    assert p.entry_of("X01") is prof.parameters["X01"]
    with pytest.raises(UsageError) as e:
        p.preflight("X01", "1")
    assert str(e.value).startswith(f"X01 is dangerous: writing it {DEFAULT_DANGER}; nothing was written")


def test_preflight_of_a_code_the_profile_does_not_list_checks_nothing():
    p = Parameters(Host(None))
    assert p.preflight("PNU999", "1.5") is None
    assert p.preflight("PNU999", "0x10000") is None
    assert p.preflight("PNU999", "x") is None
    assert p.preflight("zz", "1") is None


# -- info / parse / read ----------------------------------------------------------------------------

def test_info_strips_the_code_and_asks_the_drive_once():
    p, d = params()
    i = p.info("  F07 ")
    assert (i.code, i.name, i.unit, i.access) == ("F07", "Acceleration time 1", "s", "rw")
    assert d.calls("param_info") == [("param_info", "F07")]


def test_info_of_an_empty_code():
    p, d = params()
    for code in ("", "   "):
        with pytest.raises(UsageError) as e:
            p.info(code)
        assert str(e.value) == "empty parameter code"
    assert d.calls("param_info") == []


def test_info_names_the_closest_codes_of_the_family():
    p, _ = params()
    with pytest.raises(UsageError) as e:
        p.info("F077")
    # F07 is the closest (difflib ratio 2*3/7); the family of fuji-opc-g1-pdp is fuji (yaml:5)
    assert str(e.value).startswith("unknown parameter 'F077' for fuji-opc-g1-pdp; closest fuji codes: F07")
    assert e.value.__cause__ is None and e.value.__suppress_context__


def test_info_names_the_family_a_code_belongs_to():
    p, _ = params()
    with pytest.raises(UsageError) as e:
        p.info("C1-01")              # Yaskawa's acceleration time (profiles/yaskawa-si-p1.yaml)
    msg = str(e.value)
    assert msg.startswith("C1-01 is a yaskawa code (")
    assert "station 3 is fuji-opc-g1-pdp (Fuji FRENIC-MEGA, OPC-G1-PDP, family fuji)" in msg


def test_info_passes_on_the_drives_words_for_a_code_nobody_has():
    p, _ = params(Drive(unknown="PNU 0x9999 is not a parameter of this card"))
    with pytest.raises(UsageError) as e:
        p.info("qqqqqqqq")
    assert str(e.value) == "PNU 0x9999 is not a parameter of this card"


def test_info_lets_a_drive_error_through():
    class Lost(Drive):
        def param_info(self, code):
            raise DriveError("link lost")
    p, _ = params(Lost())
    with pytest.raises(DriveError, match="^link lost$"):
        p.info("F07")


def test_parse_by_code_and_by_info_uses_the_cards_notation():
    p, d = params()
    # o40 = (group << 8) | number: F26 -> 0x041A (spec fuji-opc-g1-pdp.md:243, :521)
    assert p.parse("o40", "041A") == 0x041A
    assert d.calls("param_info") == [("param_info", "o40")]
    d.log.clear()
    assert p.parse(info_of("o40"), "F26") == 0x041A
    assert d.calls("param_info") == []
    assert p.parse("F07", "2.5") == 2.5
    assert p.parse("F07", 3) == 3


def test_read_and_read_info_fill_the_cards_text():
    p, d = params()
    v = p.read(" PNU963 ")          # baud-rate code 7 = 1.5M (yaml:106; spec fuji-opc-g1-pdp.md:587)
    assert (v.code, v.raw) == ("PNU963", 7) and "1.5M" in (v.text or "")
    assert d.calls("param_info") == [("param_info", "PNU963")]
    assert d.calls("read") == [("read", "PNU963")]
    w = p.read_info(info_of("F07"))
    assert w.text is None and w.value == 7


# -- danger_of / check_dangerous --------------------------------------------------------------------

def test_danger_of_a_profile_entry():
    p, d = params()
    assert p.danger_of(info_of("H03")) == H03_DANGER
    assert p.danger_of(info_of("PNU970")) == PNU970_DANGER
    assert p.danger_of(info_of("F07")) is None
    assert d.calls("params_at") == []          # the entry alone says it
    q = Parameters(Host(None))
    assert q.danger_of(info_of("H03")) == H03_DANGER   # no drive needed for an entry


def test_danger_of_a_raw_address_through_params_at():
    f07, h03, p970 = FUJI.param("F07"), FUJI.param("H03"), FUJI.param("PNU970")
    p, d = params(Drive(hits=[f07, h03, p970]))
    assert p.danger_of(raw_info()) == H03_DANGER          # the first dangerous entry there
    assert d.calls("params_at") == [("params_at", "PNU970")]
    p, _ = params(Drive(hits=[p970, h03]))
    assert p.danger_of(raw_info()) == PNU970_DANGER
    p, _ = params(Drive(hits=[f07]))
    assert p.danger_of(raw_info()) is None
    p, _ = params(Drive(hits=[]))
    assert p.danger_of(raw_info()) is None


def test_danger_of_a_dangerous_entry_without_its_own_words():
    bare = SimpleNamespace(extra={"dangerous": True})
    p, _ = params(Drive(hits=[bare]))
    assert p.danger_of(raw_info()) == DEFAULT_DANGER


def test_danger_of_a_raw_address_is_none_when_it_cannot_be_told():
    p = Parameters(Host(None))
    assert p.danger_of(raw_info()) is None                 # no drive
    for err in (UsageError("no such PNU"), DriveError("no reply")):
        p, d = params(Drive(hits_error=err))
        assert p.danger_of(raw_info()) is None
        assert d.calls("params_at") == [("params_at", "PNU970")]
    p, _ = params(Drive(hits_error=RuntimeError("bug")))
    with pytest.raises(RuntimeError):
        p.danger_of(raw_info())


def test_check_dangerous():
    p, _ = params()
    with pytest.raises(UsageError) as e:
        p.check_dangerous(info_of("H03"))
    assert str(e.value) == ("H03 (Data initialisation (same function as PNU970)) is dangerous: writing it "
                            f"{H03_DANGER}; nothing was written (add --allow-dangerous to write it)")
    assert p.check_dangerous(info_of("H03"), allow_dangerous=True) is None
    assert p.check_dangerous(info_of("H03"), True) is None
    assert p.check_dangerous(info_of("F07")) is None


# -- stopped_for --------------------------------------------------------------------------------------

def test_stopped_for_a_parameter_that_is_not_stop_only_needs_no_cycle():
    p, d = params(Drive(st=status(running=True, speed=50.0)))
    assert p.stopped_for(info_of("F07")) is None
    assert p.stopped_for(info_of("F03", access="rw")) is None
    assert d.calls("cycle") == []


def test_stopped_for_while_running_names_the_state_and_the_hz():
    # speed 50 % of fmax 60 Hz = 30 Hz
    p, d = params(Drive(st=status("S4 operation", running=True, speed=50.0)))
    assert p.stopped_for(info_of("F03")) == (
        f"F03 ({F03_NAME}) can only be changed while the motor is stopped "
        "(the drive is S4 operation, 30 Hz); stop it first")
    assert d.calls("cycle") == [("cycle",)]
    # 12.3456 % of the station's fmax 50 Hz = 6.1728 Hz, shown to 3 decimals (Sample.actual_hz): 6.173
    p, _ = params(Drive(st=status("S4 operation", running=True, speed=12.3456)), fmax_hz=50.0)
    assert p.stopped_for(info_of("F03")).endswith("(the drive is S4 operation, 6.173 Hz); stop it first")


def test_stopped_for_while_coasting_not_yet_stopped():
    # run command off, still 10 % of 60 Hz = 6 Hz
    p, _ = params(Drive(st=status("S3 ready", running=False, speed=10.0)))
    assert p.stopped_for(info_of("H03")) == (
        "H03 (Data initialisation (same function as PNU970)) can only be changed while the motor is "
        "stopped (the drive is S3 ready, 6 Hz); stop it first")
    # reverse: -10 % is 6 Hz the other way
    p, _ = params(Drive(st=status("S3 ready", running=False, speed=-10.0)))
    assert "(the drive is S3 ready, -6 Hz)" in p.stopped_for(info_of("F03"))


def test_stopped_for_without_a_speed_figure_says_no_hz():
    p, _ = params(Drive(st=status("S4 operation", running=True, speed=0.0)))
    assert p.stopped_for(info_of("F03")) == (
        f"F03 ({F03_NAME}) can only be changed while the motor is stopped "
        "(the drive is S4 operation); stop it first")
    p, _ = params(Drive(st=status("S4 operation", running=True, speed=None)))
    assert p.stopped_for(info_of("F03")).endswith("(the drive is S4 operation); stop it first")


def test_stopped_for_a_stopped_drive():
    p, d = params(Drive(st=status("S2 ready", running=False, speed=0.0)))
    assert p.stopped_for(info_of("F03")) is None
    assert d.calls("cycle") == [("cycle",)]
    p, _ = params(Drive(st=status("S2 ready", running=False, speed=0.04)))   # below 0.05 %: stopped
    assert p.stopped_for(info_of("F03")) is None
    p, _ = params(Drive(st=status("S2 ready", running=False, speed=None)))
    assert p.stopped_for(info_of("F03")) is None


# -- plan ---------------------------------------------------------------------------------------------

def test_plan_of_a_typed_value():
    p, d = params()
    plan = p.plan(" F07 ", " 2.5 ")
    assert plan == WritePlan(code="F07", info=info_of("F07"), value=2.5, text="2.5", danger=None,
                             allowed=False, stop_only=False)
    assert isinstance(plan.value, float) and not plan.dangerous
    assert d.calls("value_problem") == [("value_problem", "F07", 2.5)]
    assert d.calls("param_info") == [("param_info", "F07")]
    assert d.calls("write") == [] and d.calls("cycle") == []


def test_plan_of_a_number_keeps_it():
    p, _ = params()
    plan = p.plan("F07", 3)
    assert plan.value == 3 and isinstance(plan.value, int) and plan.text == "3"
    plan = p.plan("o40", "F26")                   # the card's notation: 0x041A (spec :243)
    assert (plan.value, plan.text) == (0x041A, "F26")


def test_plan_keeps_the_code_as_given():
    # Profile.param finds "f07" as F07 (drives/profile.py); the plan says the code as the user typed it
    p, _ = params()
    plan = p.plan(" f07 ", "2.5")
    assert (plan.code, plan.info.code) == ("f07", "F07")


def test_plan_passes_a_number_as_given_to_the_drives_check():
    # a number is not parsed again: the drive's exact-value check sees it as given (a bool included,
    # which drives/values.py value_problem refuses as "not a number")
    p, d = params(Drive(problems={True: "F07 (Acceleration time 1): True is not a number"}))
    with pytest.raises(UsageError) as e:
        p.plan("F07", True)
    assert str(e.value) == "F07 (Acceleration time 1): True is not a number"
    assert d.calls("value_problem")[0][2] is True


def test_plan_with_the_info_given_does_not_resolve_again():
    p, d = params()
    info = info_of("F03")
    plan = p.plan(info, 50)
    assert (plan.code, plan.info, plan.value, plan.text) == ("F03", info, 50, "50")
    assert plan.stop_only and plan.allowed is False
    assert d.calls("param_info") == []


def test_plan_refuses_a_read_only_parameter():
    p, d = params()
    with pytest.raises(UsageError) as e:
        p.plan("W90", "1")            # yaml:142, access ro
    assert str(e.value) == "W90 (PROFIBUS card software version (V1.23 reads 123)) is read-only"
    assert d.calls("value_problem") == []


def test_plan_of_a_raw_address_has_no_profile_entry_to_be_read_only_by():
    p, d = params()
    plan = p.plan(raw_info("PNU999"), 5)
    assert (plan.code, plan.value, plan.danger, plan.stop_only) == ("PNU999", 5, None, False)
    assert d.calls("params_at") == [("params_at", "PNU999")]


def test_plan_refuses_a_dangerous_parameter_without_allow():
    p, d = params()
    with pytest.raises(UsageError) as e:
        p.plan("H03", "1")
    assert str(e.value) == ("H03 (Data initialisation (same function as PNU970)) is dangerous: writing it "
                            f"{H03_DANGER}; nothing was written (add --allow-dangerous to write it)")
    assert d.calls("value_problem") == []
    # by its raw PNU: the profile entries there say it (PNU970, yaml:166)
    p, _ = params(Drive(hits=[FUJI.param("PNU970")]))
    with pytest.raises(UsageError, match=r"^PNU970 \(raw PNU970\) is dangerous: writing it a 1 then 0"):
        p.plan(raw_info(), 1)


def test_plan_of_a_dangerous_parameter_with_allow():
    p, _ = params()
    plan = p.plan("H03", "1", allow_dangerous=True)
    assert plan == WritePlan(code="H03", info=info_of("H03"), value=1, text="1", danger=H03_DANGER,
                             allowed=True, stop_only=True)
    assert plan.dangerous


def test_plan_refuses_a_value_the_drive_says_it_cannot_hold():
    words = "F07 = 2.55 s cannot be held exactly: resolution 0.1 s; nearest 2.5 s or 2.6 s"
    p, d = params(Drive(problems={2.55: words}))
    with pytest.raises(UsageError) as e:
        p.plan("F07", "2.55")
    assert str(e.value) == words
    assert d.calls("value_problem") == [("value_problem", "F07", 2.55)]


def test_plan_of_text_that_is_not_a_number():
    p, d = params()
    with pytest.raises(UsageError) as e:
        p.plan("F07", "fast")
    assert str(e.value) == "F07: expected a number 0..6000 s, got 'fast'"
    assert d.calls("value_problem") == []


# -- execute / write ------------------------------------------------------------------------------------

def test_execute_writes_the_resolved_parameter_and_returns_the_read_back():
    p, d = params()
    plan = p.plan("F07", "2.5")
    d.log.clear()
    v = p.execute(plan)
    assert (v.code, v.value, v.unit) == ("F07", 2.5, "s")
    assert d.log == [("write", "F07", 2.5)]                  # no cycle, no second resolve or check


def test_execute_fills_the_cards_text_of_the_read_back():
    p, d = params()
    v = p.execute(p.plan("o40", "041A"))
    assert v.raw == 0x041A and "F26" in (v.text or "")      # spec fuji-opc-g1-pdp.md:243


def test_execute_refuses_a_stop_only_parameter_while_running():
    p, d = params(Drive(st=status("S4 operation", running=True, speed=25.0)))   # 25 % of 60 Hz = 15 Hz
    plan = p.plan("F03", "50")
    with pytest.raises(DriveError) as e:
        p.execute(plan)
    assert str(e.value) == (f"F03 ({F03_NAME}) can only be changed while the motor is stopped "
                            "(the drive is S4 operation, 15 Hz); stop it first")
    assert d.calls("write") == []
    with pytest.raises(DriveError, match="stop it first"):
        p.write("F03", "50")
    assert d.calls("write") == []


def test_execute_without_the_running_check():
    p, d = params(Drive(st=status("S4 operation", running=True, speed=25.0)))
    plan = p.plan("F03", "50")
    d.log.clear()
    assert p.execute(plan, check_running=False).value == 50
    assert d.log == [("write", "F03", 50)]
    d.log.clear()
    assert p.write("F03", 50, check_running=False).value == 50
    assert d.calls("cycle") == [] and d.calls("write") == [("write", "F03", 50)]


def test_execute_a_stop_only_parameter_on_a_stopped_drive():
    p, d = params(Drive(st=status("S2 ready", running=False, speed=0.0)))
    plan = p.plan("F03", "50")
    d.log.clear()
    assert p.execute(plan).value == 50
    assert d.log == [("cycle",), ("write", "F03", 50)]


def test_write_plans_then_executes():
    p, d = params()
    v = p.write(" F07 ", "2.5")
    assert v.value == 2.5
    assert [c[0] for c in d.log] == ["param_info", "value_problem", "write"]
    with pytest.raises(UsageError, match="is dangerous"):
        p.write("H03", 1)
    d.log.clear()
    p2, d2 = params(Drive(st=status("S2 ready")))
    assert p2.write("H03", 0, allow_dangerous=True).value == 0
    assert d2.calls("write") == [("write", "H03", 0)]


# -- notes and saving ------------------------------------------------------------------------------------

def test_notes_are_the_drives_and_none_without_a_drive():
    p, d = params(Drive(notes=["o30 takes effect after a power cycle"]))
    assert p.notes() == ["o30 takes effect after a power cycle"]
    assert Parameters(Host(None)).notes() == []


def test_save_support_is_the_drives():
    for how in ("command", "automatic", "unsupported"):
        p, _ = params(Drive(support=how))
        assert p.save_support() == how


def test_save_with_a_command():
    p, d = params(Drive(support="command"))
    assert p.save() == "saved to non-volatile memory"
    assert d.calls("save") == [("save",)]


def test_save_where_every_write_is_stored():
    p, d = params(Drive(support="automatic"))
    assert p.save() == ("fuji-opc-g1-pdp: every parameter write is stored by the card itself "
                        "(no separate save)")
    assert d.calls("save") == []


def test_save_where_the_card_has_no_save_command():
    p, d = params(Drive(support="unsupported"))
    with pytest.raises(DriveError) as e:
        p.save()
    assert str(e.value) == ("fuji-opc-g1-pdp: this card has no save command; the value is written but "
                            "may be lost at power-off")
    assert d.calls("save") == []


# -- dump / compare / restore: delegations ----------------------------------------------------------------

@pytest.fixture
def delegated(monkeypatch):
    calls = []

    def rec(name):
        def f(*a):
            calls.append((name,) + a)
            return name
        return f
    monkeypatch.setattr(backup, "dump_plan", rec("dump_plan"))
    monkeypatch.setattr(backup, "dump", rec("dump"))
    monkeypatch.setattr(backup, "compare", rec("compare"))
    monkeypatch.setattr(backup, "factory_diff", rec("factory_diff"))
    monkeypatch.setattr(restore, "restore_problems", rec("restore_problems"))
    monkeypatch.setattr(restore, "restore", rec("restore"))
    return calls


def test_delegations_with_their_defaults(delegated):
    p, _ = params()
    doc, rows = {"_path": "x.yaml"}, []
    assert p.dump_plan() == "dump_plan"
    assert p.dump() == "dump"
    assert p.compare(doc) == "compare"
    assert p.restore_problems(doc, rows) == "restore_problems"
    assert p.restore(doc) == "restore"
    assert p.factory_diff() == "factory_diff" and delegated.pop() == ("factory_diff", p, None)
    # issue 28: dump's `changed` (False) and restore's scopes (only, exclude: none) are passed on too
    assert delegated == [("dump_plan", p), ("dump", p, None, False), ("compare", p, doc, None, False, True),
                         ("restore_problems", p, doc, rows, False),
                         ("restore", p, doc, False, None, False, (), ())]


def test_delegations_pass_every_argument(delegated):
    p, _ = params()
    doc, rows = {"_path": "x.yaml"}, []

    def prog(i, n, code):
        pass
    p.dump(prog)
    p.compare(doc, prog, True, False)
    p.restore_problems(doc, rows, True)
    p.restore(doc, True, prog, True)
    p.compare(doc, progress=prog, allow_dangerous=True, check_identity=False)
    p.restore(doc, dry_run=True, progress=prog, allow_dangerous=True)
    p.dump(prog, changed=True)                                      # issue 28: --changed, the scopes
    p.restore(doc, True, prog, True, ("application",), ("motor",))
    p.factory_diff(prog)
    assert delegated == [("dump", p, prog, False), ("compare", p, doc, prog, True, False),
                         ("restore_problems", p, doc, rows, True),
                         ("restore", p, doc, True, prog, True, (), ()),
                         ("compare", p, doc, prog, True, False), ("restore", p, doc, True, prog, True, (), ()),
                         ("dump", p, prog, True),
                         ("restore", p, doc, True, prog, True, ("application",), ("motor",)),
                         ("factory_diff", p, prog)]
