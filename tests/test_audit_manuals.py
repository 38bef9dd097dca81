"""`pdrive audit` and the profiles against the card manuals (issue 34, "Against the manuals"): each
case quotes the manual line it stands on (../shared/seeds/, spec ../shared/spec/); expected values
come from the manual or a hand calculation in the comment, never from the code under test.
The simulated plant (sim://): 3 fuji-g1, 4 fuji-pdp3, 5 toyo, 6 moeller, 7 yaskawa."""

from __future__ import annotations

import pytest

import profidrive_cli as pdrive


def audit(url: str, station: int, **kw):
    with pdrive.open_bus(url) as bus:
        (res,) = bus.audit([station], **kw)
    return res


# -- the comm-loss reaction time is the watchdog plus the card's delay -----------------------------

@pytest.mark.parametrize("station", [3, 4, 5, 6, 7])
def test_a_watchdog_alone_above_the_process_limit_is_an_error_on_every_family(station):
    # every family's factory reaction acts when the DP watchdog expires (Fuji o27 = 0, Moeller
    # P002 = 0, Toyo protection 18, Yaskawa F6-01 = 1): the drive runs on its last command for the
    # watchdog itself. Hand calculation: --watchdog 3000 ms is WD_Fact_1 x WD_Fact_2 x 10 ms =
    # 150 x 2 x 10 ms = 3.0 s (bus reference: the watchdog is the two factors times 10 ms), above a
    # 2.8 s limit: an error, whatever the card's delay is (0 here)
    res = audit("sim://?timing=virtual", station, watchdog_ms=3000, max_reaction_s=2.8)
    errs = [f for f in res.findings if f.rule == "comm_loss.delay"]
    assert [f.severity for f in errs] == ["error"], res.findings
    assert "3 s" in errs[0].why and "2.8 s" in errs[0].why
    # the same reaction within the limit: 3.0 s <= 3.5 s
    res = audit("sim://?timing=virtual", station, watchdog_ms=3000, max_reaction_s=3.5)
    assert not [f for f in res.findings if f.rule == "comm_loss.delay"]


def test_the_watchdog_counts_as_the_set_prm_gives_it():
    # OPC-PDP3 Table 9.1 (L6478-6559): o27 = 11 decelerates after the o28 time. --watchdog 2561 ms:
    # ceil(2561 / 10) = 257 units of 10 ms; 257 is prime and above 255, so the Set_Prm's factors
    # hold 129 x 2 = 258 units = 2.58 s at the least. Reaction 2.58 + o28 0.2 = 2.78 s, above a
    # 2.77 s limit (with the 2.561 s asked for it would be 2.761 s, within it)
    res = audit("sim://?timing=virtual&set=4:o27=11,o28=0.2", 4, watchdog_ms=2561, max_reaction_s=2.77)
    assert res.watchdog_s == pytest.approx(2.58)
    (f,) = [f for f in res.findings if f.rule == "comm_loss.delay"]
    assert f.severity == "error" and "2.78 s" in f.why


def test_o28_2_5_against_2_8_is_an_error_the_watchdog_counted():
    # the case: watchdog 500 ms (pdrive's default; 50 x 1 x 10 ms) + o28 2.5 s = 3.0 s on
    # the last command, above --max-reaction 2.8; the fix: o28 at most 2.8 - 0.5 = 2.3 s
    res = audit("sim://?timing=virtual&set=3:o27=11,o28=2.5", 3, max_reaction_s=2.8)
    (f,) = [f for f in res.findings if f.rule == "comm_loss.delay"]
    assert f.severity == "error" and f.check == {"param": "o28", "max": 2.3}


# -- parameter groups as the manuals list them ----------------------------------------------------

def test_moeller_groups_follow_the_manuals_lists():
    from profidrive_cli.drives.profile import load_profile
    m = load_profile("moeller")
    # DE6-NET-DP manual L872-874: "Level of 1st / 2nd / 3rd electronic thermal protection" (b012,
    # b212, b312) listed together; L1007-1009 their characteristic (b013, b213, b313)
    for code in ("b012", "b212", "b312", "b013", "b213", "b313"):
        assert m.group_of(code) == "protection", code
    # L828-830: "1st / 2nd / 3rd Base frequency" (A003, A203, A303): the motor's
    for code in ("A003", "A203", "A303"):
        assert m.group_of(code) == "motor", code
    # not protection: L1015 "Selection of display" (b037), L1014 software lock (b031), L903 display
    # time of warning (b034), L822 frequency matching (b007), L1024 reduced-voltage start (b036),
    # L1033 action at stop (b091), L1034 cooling fan (b092)
    for code in ("b037", "b031", "b034", "b007", "b036", "b091", "b092"):
        assert m.group_of(code) == "application", code
    # L294-307: A001 = 2 and A002 = 1 make the card control frequency and commands: the bus settings,
    # restored with `--only communication` as Fuji's y98 and Yaskawa's b1-01 / b1-02
    assert m.group_of("A001") == "communication" and m.group_of("A002") == "communication"


def test_yaskawa_communication_group_holds_the_option_specific_b1_settings():
    from profidrive_cli.drives.profile import load_profile
    # SI-P1 manual L147 (installation step 12): "Set parameters b1-01 and b1-02 to their appropriate
    # values. Refer to Table 1.4 - Option Specific Parameter Settings"; L263-282: 3 = Option PCB
    y = load_profile("yaskawa")
    assert y.group_of("b1-01") == "communication" and y.group_of("b1-02") == "communication"
    assert y.group_of("F6-01") == "communication" and y.group_of("b1-03") == "application"


def test_restore_only_protection_leaves_the_moeller_display_selection(sim, capsys, monkeypatch, tmp_path):
    # b037 "Selection of display" (L1015) is no protection setting: `--only protection` must not
    # restore it; b212 (L873, the 2nd motor's thermal level) is one and is restored
    import json
    from conftest import run_main
    port, dump = "sim://", tmp_path / "d.yaml"
    assert run_main(capsys, monkeypatch, "param", "dump", "6", "-o", dump, "--port", port).exit_code == 0
    for code, value in (("b037", "1"), ("b212", "50")):       # changed after the dump
        r = run_main(capsys, monkeypatch, "param", "set", "6", code, value, "--port", port)
        assert r.exit_code == 0, r.stderr
    r = run_main(capsys, monkeypatch, "param", "restore", "6", dump, "--only", "protection", "--json",
                 "--port", port)
    assert r.exit_code == 0, r.stderr
    rows = {x["code"]: x for x in json.loads(r.stdout)["rows"]}
    assert rows["b212"]["result"] == "applied", rows["b212"]
    assert rows["b037"]["result"] == "skipped" and rows["b037"]["why"] == "out of scope"


# -- the lines the rules cite -----------------------------------------------------------------------

def _rules(name):
    from profidrive_cli.drives import drive_class
    from profidrive_cli.drives.profile import load_profile
    prof = load_profile(name)
    return {r.id: r for r in drive_class(prof).audit_rules(prof)}


def test_yaskawa_rules_cite_the_bus_fault_line_not_ope05_or_cpf23():
    # SI-P1 manual L341: "| BUS | Option PCB communications error | Communication is not established
    # between PROFIBUS-DP Master and the drive"; L343 is OPE05 (command selection fault), L348
    # CPF23 (the option card's own watchdog timer fault, not the master's DP watchdog)
    rules = _rules("yaskawa-si-p1")
    for rid in ("comm_loss.reaction", "watchdog.cycle"):
        m = rules[rid].manual
        assert "L341" in m and "L343" not in m and "L348" not in m and "CPF23" not in m, m


def test_toyo_c00_note_cites_table_3_5_and_c00_and_no_commloss_test():
    # PBUS66-Z manual L2769 / L2773 (Table 3.5 notes 1, 2): "c-00 が 0 ... の場合 ... 通常の停止と同じ
    # 動作となります" (with c-00 = 0 OFF2 / OFF3 act as the normal stop); L612-620: C-00 multi-function
    # input location, 0 terminal block (factory), 1 digital communication option. L4059-4062 is
    # protection 18 (communication timeout), which the comm-loss test exercises: not OFF2 / OFF3
    res = audit("sim://?timing=virtual", 5)
    (f,) = [f for f in res.findings if f.rule == "comm_loss.note"]
    assert "C-00" in f.why
    assert "L2769-2773" in f.manual and "L612-620" in f.manual and "L4059" not in f.manual
    assert "run `pdrive commloss-test`" not in f.fix and "C-00 = 1" in f.fix


# -- where each factory default comes from --------------------------------------------------------

@pytest.mark.parametrize("new,words", [
    ("default: 0.0, default_source: ''}", "'default_source' must be a text"),
    ("default_source: F7}", "'default_source' needs a 'default:'"),
])
def test_a_bad_default_source_is_refused_with_file_and_line(tmp_path, new, words):
    from profidrive_cli.datafile import DataFileError
    from profidrive_cli.drives.profile import load_profile, load_profile_file
    src = load_profile("yaskawa").path.read_text(encoding="utf-8")
    old = "default: 0.0, default_source: F7}"           # d1-01's entry (the F7's 0.0 Hz)
    assert src.count(old) == 1
    bad = src.replace(old, new)
    path = tmp_path / "y.yaml"
    path.write_text(bad, encoding="utf-8")
    n = 1 + src.splitlines().index(next(x for x in src.splitlines() if old in x))
    with pytest.raises(DataFileError) as e:
        load_profile_file(path)
    assert words in str(e.value) and f"{path}:{n}" in str(e.value)


def _main(capsys, monkeypatch, *args):
    from conftest import run_main
    return run_main(capsys, monkeypatch, *args)


def test_toyo_diff_defaults_says_nothing_was_compared_and_exits_1(capsys, monkeypatch):
    # PBUS66-Z manual L4201: "注１：ＶＦ６６インバータの設定データ番号については別途お問い合わせください"
    # (the VF66's setting-data numbers: ask Toyo): no setting can be read, so none is compared with
    # a factory value; "0 changed" with exit 0 would claim the drive is at its defaults
    r = _main(capsys, monkeypatch, "param", "diff", "5", "--defaults", "--port", "sim://")
    assert r.exit_code == 1, r.stdout + r.stderr
    assert "nothing compared with the factory defaults" in r.stdout and "0 changed" not in r.stdout
    r = _main(capsys, monkeypatch, "param", "diff", "5", "--defaults", "--port", "sim://", "--json")
    import json
    d = json.loads(r.stdout)
    assert r.exit_code == 1 and d["compared"] == 0 and d["nothing_compared"]


def test_diff_defaults_names_each_factory_values_source(capsys, monkeypatch):
    # OPC-PDP3 function-code table (fuji-opc-pdp3.md L825-829: o32 0, y97 0, y98 0) gives the card's
    # own codes; E31 and F07 are the FRENIC's (not in the card manual: the profile's default_source)
    import json
    r = _main(capsys, monkeypatch, "param", "diff", "4", "--defaults", "--port", "sim://?set=4:E31=40",
              "--json")
    d = json.loads(r.stdout)
    src = {x["code"]: x["default_source"] for x in d["rows"]}
    assert src["E31"] == "FRENIC" and src["F07"] == "FRENIC" and src["o32"] == "card manual"
    assert src["S01"] is None                                   # a command: no factory value
    assert d["compared"] >= 1 and d["nothing_compared"] is None
    r = _main(capsys, monkeypatch, "param", "diff", "4", "--defaults", "--port", "sim://?set=4:E31=40")
    assert "factory value not from the card manual (FRENIC): F03, F07, F08" in r.stdout
    # Yaskawa: every default is the F7 drive's (SI-P1 manual: none published)
    r = _main(capsys, monkeypatch, "param", "diff", "7", "--defaults", "--port", "sim://", "--json")
    assert {x["default_source"] for x in json.loads(r.stdout)["rows"]} <= {"F7", None}


# -- a stopped PLC's all-zero data (OPC-PDP3 o32) ----------------------------------------------------

def test_pdp3_o32_factory_zero_is_a_warning_and_1_is_not():
    # OPC-PDP3 manual L6566-6578 (Table 10.1): "Some master node equipment sends all-zero data to all
    # slaves if a PLC application error occurs or the application program stops"; "0 Keep the
    # current operation, ignoring all-zero data. Factory default"; "1 Coast to a stop and shift to
    # S1 state"
    res = audit("sim://?timing=virtual", 4)                  # o32 = 0, the factory default
    (f,) = [f for f in res.findings if f.rule == "comm_loss.zero_data"]
    assert (f.severity, f.code, f.value) == ("warning", "o32", "0")
    assert "L6566-6578" in f.manual and f.check == {"param": "o32", "min": 1, "max": 2}
    res = audit("sim://?timing=virtual&set=4:o32=1", 4)
    assert not [f for f in res.findings if f.rule == "comm_loss.zero_data"]


# -- split control is a set-up the manuals offer -----------------------------------------------------

@pytest.mark.parametrize("station,preset,code", [
    # OPC-PDP3 manual L4183-4206 (y98: "1 PROFIBUS Inverter", "2 Inverter PROFIBUS": frequency /
    # run command source); OPC-G1-PDP Table 5.2 (L1846-1869) the same
    (3, "y98=1", "y98"),
    (4, "y98=2", "y98"),
    # DE6-NET-DP manual L294-307: "controls frequency only: A001 = 2, A002 not equal to 1";
    # "controls commands only: A001 not equal to 2, A002 = 1"
    (6, "A002=2", "A002"),
    (6, "A001=1", "A001"),
    # SI-P1 manual L265: "the run/stop command may be set to External Terminals (b1-02 = 1) while the
    # Frequency Reference may be set to Option PCB (PROFIBUS-DP Option) (b1-01 = 3)"
    (7, "b1-02=1", "b1-02"),
])
def test_split_control_is_a_warning_that_names_the_split(station, preset, code):
    res = audit(f"sim://?timing=virtual&set={station}:{preset}", station)
    assert res.errors == 0, res.findings
    (f,) = [f for f in res.findings if f.rule == "source.split"]
    assert f.severity == "warning" and f.code == code and "split control" in f.why


# -- PKW error numbers: the PROFIdrive V2 meanings ---------------------------------------------------

@pytest.mark.parametrize("number,words", [
    # PROFIdrive V2 meanings of the numbers V3 reserves, as the Lenze EDS82ZAFPC201 manual (8.2.3
    # "Error codes (PROFIdrive)") and SEW's PROFIBUS manuals print them
    (8, "PPO-Write requested in IR not available"),
    (10, "access group wrong"),
    (13, "text cannot be read in cyclic data transfer"),
    (14, "name cannot be read in cyclic data transfer"),
    (16, "no PPO-Write"),
    (19, "data cannot be read in cyclic interchange"),
])
def test_the_generic_pkw_table_has_the_v2_meanings(number, words):
    from profidrive_cli.drives import profidrive as pd
    assert words in pd.GENERIC_ERRORS[number]


def test_a_cards_own_pkw_error_table_still_wins():
    # DE6-NET-DP manual (spec 5.4): its own table names 17 "not possible in the present operating
    # state (writable only while stopped)" and has no 8; the generic V2 text fills 8 in
    from profidrive_cli.drives import profidrive as pd
    from profidrive_cli.drives.profile import load_profile
    c = pd.ProfidriveConfig.from_profile(load_profile("moeller"))
    assert c.error_text(17) == "not possible in the present operating state (writable only while stopped)"
    assert "PPO-Write requested in IR not available" in c.error_text(8)


# -- the simulated drives start as commissioned drives, not at range minimums ------------------------

def test_the_plain_simulated_moeller_has_no_maximum_frequency_warning():
    # DE6-NET-DP manual L828 / L832: A003 1st base frequency, A004 1st maximum frequency (30..400 Hz);
    # the manual publishes no factory setting, and a simulator at the range minimum (A003 = 30 Hz)
    # under A004 = 50 Hz made every plain audit warn. A 50 Hz motor: A003 = A004 = 50 Hz
    res = audit("sim://?timing=virtual", 6)
    assert not [f for f in res.findings if f.rule == "max_frequency.above_rating"], res.findings
    with pdrive.open_bus("sim://?timing=virtual") as bus:
        d = bus.drive(6)
        # L872 b012 "Level of 1st electronic thermal protection" 20.0..120.0 and L1028 b083
        # carrier frequency 0.5..15.0 kHz: not at their minimums
        assert d.param("A003").value == 50 and d.param("b012").value > 20.0 and d.param("b083").value > 0.5
