"""Yaskawa SI-P1 Drive over sim.direct.DirectChannel onto the simulated drive (sim/yaskawa.py):
run, stop, faults and reset, parameters by native name through the handshake, the manual's error
replies, BUS on communication loss; plus profile validation of the family keys."""

from __future__ import annotations

from dataclasses import replace

import pytest

from profidrive_cli import UsageError
from profidrive_cli.datafile import DataFileError
from profidrive_cli.drives import decode_area as generic_decode_area
from profidrive_cli.drives import make_drive as generic_make_drive
from profidrive_cli.drives.base import DriveError, ParamError
from profidrive_cli.drives.profile import load_profile, load_profile_file
from profidrive_cli.drives.yaskawa import (FORMATS, YaskawaDrive, decode_area, encode_param_area,
                                           family_config, ParamRequest)
from profidrive_cli.sim.direct import DirectChannel
from profidrive_cli.sim.yaskawa import make_model


@pytest.fixture(scope="module")
def prof():
    return load_profile("yaskawa")


def rig(prof, layout="extended1", period=0.01, **options):
    model = make_model(prof, **options)
    ch = DirectChannel(model, prof.layouts[layout].cfg, period=period)
    return model, ch, generic_make_drive(ch, prof, layout)


# --- motion ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("layout", ["extended1", "extended2", "basic"])
def test_runs_to_set_speed_and_stops(prof, layout):
    model, ch, d = rig(prof, layout)
    assert isinstance(d, YaskawaDrive)
    d.set_speed(50.0)
    st = d.start()
    assert st.running and st.flags["remote"]
    t0 = ch.now()
    st = d.cycles_until(lambda s: s.flags["frequency_agree"], 20.0, "frequency agree")
    # E1-04 = 60 Hz, C1-01 = 10 s: 30 Hz after about 5 s; feedback is 0.1 Hz/count
    assert st.speed_hz == pytest.approx(30.0, abs=0.05)
    assert st.speed_percent == pytest.approx(50.0, abs=0.1)
    assert 4.5 < ch.now() - t0 < 5.5
    assert st.flags["mfo1"] and not st.flags["zero_speed"]
    t1 = ch.now()
    st = d.stop("normal")
    assert not st.running and st.flags["zero_speed"] and st.stopped
    assert 4.5 < ch.now() - t1 < 5.5            # C1-02 = 10 s for 60 Hz: 5 s from 30 Hz


def test_reverse_and_reference_change(prof):
    model, ch, d = rig(prof)
    d.set_speed(-25.0)
    d.start()
    st = d.cycles_until(lambda s: s.flags["frequency_agree"], 20.0, "agree")
    assert st.flags["reverse"] and st.speed_hz == pytest.approx(-15.0, abs=0.05)
    assert model.out_hz == pytest.approx(-15.0)
    d.set_speed(25.0)                          # through zero to forward
    st = d.cycles_until(lambda s: s.flags["frequency_agree"] and not s.flags["reverse"], 20.0, "fwd")
    assert st.speed_hz == pytest.approx(15.0, abs=0.05)


def test_coast_stop_is_base_block(prof):
    model, ch, d = rig(prof)
    d.set_speed(100.0)
    d.start()
    d.cycles_until(lambda s: s.flags["frequency_agree"], 20.0, "agree")
    t = ch.now()
    st = d.stop("coast")
    assert ch.now() - t < 0.1 and st.stopped
    assert d.command_word() & 0x8000              # external base block held ...
    assert not st.flags["ready"]
    st = d.start()                                # ... until the next start clears it
    assert st.running and not d.command_word() & 0x8000


def test_quick_stop_refused_without_fast_stop_input(prof):
    model, ch, d = rig(prof)
    with pytest.raises(DriveError, match="no fast-stop bit"):
        d.stop("quick")


def test_quick_stop_with_programmed_input(prof):
    p = replace(prof)
    family_config(p).fast_stop_input = 5
    model, ch, d = rig(p, fast_stop_input=5, C1_09=1.0)
    d.set_speed(100.0)
    d.start()
    d.cycles_until(lambda s: s.flags["frequency_agree"], 20.0, "agree")
    t = ch.now()
    st = d.stop("quick")
    assert st.stopped and 0.9 < ch.now() - t < 1.2    # C1-09 = 1 s for 60 Hz
    assert not d.command_word() & (1 << 4)           # MFI 5 released after the stop


def test_no_run_from_bus_unless_b1_02_is_3(prof):
    model, ch, d = rig(prof, b1_02=1)
    d.set_speed(50.0)
    with pytest.raises(DriveError, match="b1-02 = 3"):
        d.start(timeout=0.5)
    assert not d.status().flags["remote"] and model.out_hz == 0.0


def test_reference_from_d1_01_unless_b1_01_is_3(prof):
    model, ch, d = rig(prof, b1_01=1, d1_01=10.0)
    d.set_speed(50.0)                                # ignored: b1-01 = 1
    d.start()
    st = d.cycles_until(lambda s: s.flags["frequency_agree"], 20.0, "agree")
    assert st.speed_hz == pytest.approx(10.0, abs=0.05)


def test_forward_and_reverse_together_stops_with_alarm(prof):
    model, ch, d = rig(prof)
    out = bytearray(d.output_image())
    out[0:2] = b"\x00\x03"
    inp = ch.exchange(bytes(out))
    assert inp[1] & 0x40 and not inp[1] & 0x01        # alarm, not running


# --- faults ---------------------------------------------------------------------------------------

def test_external_fault_trip_and_reset(prof):
    model, ch, d = rig(prof)
    d.set_speed(50.0)
    d.start()
    d.external_fault(True)
    st = d.cycles_until(lambda s: s.fault, 1.0, "fault")
    assert st.state == "fault" and not st.running and model.out_hz == 0.0
    assert d.status().fault_code == "EF0"
    with pytest.raises(DriveError, match="in fault"):
        d.start()
    st = d.reset_fault()
    assert not st.fault and st.flags["ready"]
    assert not d.command_word() & 0x0200             # the reset bit was a pulse
    assert d.fault_history()[0].codes == ["EF0"]


def test_reset_needs_the_cause_gone(prof):
    model, ch, d = rig(prof)
    d.status()
    out = bytearray(d.output_image())
    out[0:2] = b"\x01\x00"                           # external fault bit held
    ch.exchange(bytes(out))
    out[0:2] = b"\x03\x00"                           # + fault reset: EF0 cause still present
    inp = ch.exchange(bytes(out))
    assert inp[1] & 0x80                              # still in fault
    out[0:2] = b"\x00\x00"
    ch.exchange(bytes(out))
    out[0:2] = b"\x02\x00"                           # reset edge with the cause gone
    inp = ch.exchange(bytes(out))
    assert not inp[1] & 0x80 and inp[1] & 0x08       # fault cleared, reset signal shown


def test_bus_fault_when_master_stops_talking(prof):
    model, ch, d = rig(prof)
    d.set_speed(50.0)
    d.start()
    d.cycles_until(lambda s: s.speed_hz > 5, 5.0, "speed")
    ch.advance(2.0)                                  # no Data_Exchange for longer than comm_timeout
    assert model.fault == "BUS" and model.out_hz == 0.0
    st = d.status()
    assert st.fault and st.fault_code == "BUS"
    st = d.reset_fault()
    assert not st.fault
    assert [r.codes for r in d.fault_history()] == [["BUS"]]


def test_bus_fault_on_leave_data_exchange(prof):
    model, ch, d = rig(prof)
    d.set_speed(10.0)
    d.start()
    model.on_leave_data_exchange(ch.now(), "watchdog")
    assert model.fault == "BUS"


def test_bus_fault_when_stopped_depends_on_option(prof):
    model, ch, d = rig(prof)                                   # default: only while running
    d.status()
    model.on_leave_data_exchange(ch.now(), "watchdog")
    assert model.fault is None
    model, ch, d = rig(prof, bus_fault="always")
    d.status()
    ch.advance(2.0)
    assert model.fault == "BUS"
    with pytest.raises(ValueError):
        make_model(prof, bus_fault="sometimes")


def test_no_bus_fault_when_bus_is_not_the_source(prof):
    model, ch, d = rig(prof, b1_01=1, b1_02=1, bus_fault="always")
    d.status()
    model.on_leave_data_exchange(ch.now(), "watchdog")
    assert model.fault is None


def test_trip_and_fault_history_and_clear_log(prof):
    model, ch, d = rig(prof)
    model.seed_faults(["CPF21", "EF0"])
    model.trip("BUS", ch.now())
    st = d.status()
    assert st.fault_code == "BUS"
    hist = d.fault_history()
    assert [(r.position, r.codes[0]) for r in hist] == [
        ("current", "BUS"), ("last", "BUS"), ("2nd last", "CPF21"), ("3rd last", "EF0")]
    assert "communication" in hist[0].meanings[0]
    d.reset_fault()
    d.clear_error_log()
    assert d.fault_history() == []
    with pytest.raises(ValueError, match="unknown fault"):
        model.trip("OC1", ch.now())


def test_ope_trip_sets_ope_bit(prof):
    model, ch, d = rig(prof)
    model.trip("OPE06", ch.now())
    st = d.status()
    assert st.flags["ope_error"] and not st.fault and st.state == "OPE setting error"


# --- parameters through the handshake -------------------------------------------------------------

@pytest.mark.parametrize("layout", ["extended1", "extended2"])
def test_e1_04_read_and_write_by_native_name(prof, layout):
    model, ch, d = rig(prof, layout)
    v = d.read_param("E1-04")
    assert (v.code, v.value, v.raw, v.unit) == ("E1-04", 60.0, 600, "Hz")
    v = d.write_param("E1-04", 50.0)
    assert v.value == 50.0 and model.param("E1-04") == 50.0
    assert d.max_frequency() == 50.0
    d.set_speed(50.0)                                # now 25 Hz
    d.start()
    st = d.cycles_until(lambda s: s.flags["frequency_agree"], 20.0, "agree")
    assert st.speed_hz == pytest.approx(25.0, abs=0.05)


@pytest.mark.parametrize("layout", ["extended1", "extended2"])
def test_e1_04_write_out_of_range_refused_by_drive(prof, layout):
    model, ch, d = rig(prof, layout)
    with pytest.raises(UsageError, match=r"500 Hz is outside 40..400 Hz"):
        d.write_param("E1-04", 500.0)                  # the profile's range: refused before sending
    with pytest.raises(UsageError, match=r"resolution 0.1 Hz; nearest 50 Hz or 50.1 Hz"):
        d.write_param("E1-04", 50.05)                  # never rounded (issue 12)
    with pytest.raises(ParamError) as e:
        d.write_param("REG0x0303", 5000)               # raw register, 500.0 Hz: the drive judges it
    assert e.value.number == 0x21                      # the manual's data content fault
    assert "data content error" in str(e.value)
    assert model.param("E1-04") == 60.0


def test_stop_only_parameter_refused_while_running(prof):
    model, ch, d = rig(prof)
    d.set_speed(20.0)
    d.start()
    with pytest.raises(ParamError) as e:
        d.write_param("E1-04", 50.0)
    assert e.value.number == 0x22 and "only while the drive is stopped" in str(e.value)
    assert d.write_param("C1-01", 5.0).value == 5.0      # run-time writable


def test_raw_register_access_and_errors(prof):
    model, ch, d = rig(prof)
    v = d.read_param("REG0x0180")
    assert (v.code, v.raw, v.value) == ("REG0x0180", 3, 3) and "b1-01" in v.name
    assert d.read_param("REG384").raw == 3                    # decimal form
    with pytest.raises(ParamError) as e:
        d.read_param("REG0x1000")
    assert e.value.number == 0x02
    with pytest.raises(ParamError) as e:
        d.write_param("REG0x0037", 1)                          # read-only monitor
    assert e.value.number == 0x22
    assert d.read_registers(0x0200, 2) == [100, 100]           # C1-01, C1-02 in one request
    assert ch.model.regs[0x0181] == 3


def test_extended2_splits_multi_register_reads(prof):
    model, ch, d = rig(prof, "extended2")
    n = ch.cycles
    assert d.read_registers(0x0200, 2) == [100, 100]           # two one-register requests
    one = ch.cycles
    d.read_registers(0x0200, 1)
    assert ch.cycles - one < one - n


def test_save_sends_enter_and_is_refused_while_running(prof):
    model, ch, d = rig(prof)
    d.write_param("C1-01", 2.5)
    d.save()
    assert model.stored[0x0200] == 25
    d.start()
    with pytest.raises(ParamError) as e:
        d.save()
    assert e.value.number == 0x22


def test_processing_delay_costs_cycles(prof):
    fast = rig(prof, processing_ms=12)
    slow = rig(prof, processing_ms=100)
    counts = []
    for model, ch, d in (fast, slow):
        d.status()
        n = ch.cycles
        d.read_param("E1-04")
        counts.append(ch.cycles - n)
    assert counts[0] <= 6 and counts[1] >= 10


def test_option_acts_only_on_hs_change(prof):
    model = make_model(prof)
    ch = DirectChannel(model, prof.layouts["extended2"].cfg)
    fmt = FORMATS["extended2"]
    req = encode_param_area(fmt, ParamRequest.read(0x0303), 0)     # HS unchanged (0)
    for _ in range(10):
        inp = ch.exchange(bytes(4) + req)
    assert inp[4] == 0 and inp[11] & 0x60 == 0                     # nothing done, STATUS idle
    req = encode_param_area(fmt, ParamRequest.read(0x0303), 1)     # toggle
    seen = []
    for _ in range(6):
        inp = ch.exchange(bytes(4) + req)
        seen.append(inp[11] & 0xE0)
    assert seen[:3] == [0x80, 0xA0, 0xC0] and seen[-1] == 0xE0     # ack, sending, waiting, done
    assert inp[4:10] == bytes.fromhex("03 03 03 02 02 58")          # E1-04 = 600 (60.0 Hz)


def test_watchdog_counter_runs(prof):
    model, ch, d = rig(prof)
    wds = set()
    for _ in range(40):
        wds.add(ch.exchange(d.output_image())[31] >> 1 & 0x0F)
    assert len(wds) >= 5


def test_bad_data_quantity_and_function(prof):
    model = make_model(prof)
    ch = DirectChannel(model, prof.layouts["extended2"].cfg)
    for fc_area, code in ((bytes.fromhex("03 03 03 04 00 00 00"), 0x03),
                          (bytes.fromhex("06 03 03 02 00 00 00"), 0x01)):
        hs = 0x80 if model._cmd_hs == 0 else 0x00
        for _ in range(6):
            inp = ch.exchange(bytes(4) + fc_area + bytes([hs]))
        assert inp[11] & 0x60 == 0x60 and inp[4] & 0x80 and inp[9] == code


# --- basic layout ---------------------------------------------------------------------------------

def test_basic_layout_has_no_parameter_channel(prof):
    model, ch, d = rig(prof, "basic")
    assert not d.has_param_channel
    for call in (lambda: d.read_param("E1-04"), lambda: d.write_param("E1-04", 50),
                 lambda: d.fault_history(), lambda: d.save()):
        with pytest.raises(DriveError, match="no parameter access"):
            call()
    assert d.max_frequency() == 60.0


# --- captured areas -------------------------------------------------------------------------------

def test_decode_captured_areas(prof):
    model, ch, d = rig(prof)
    captured = []
    real = ch.exchange

    def tap(out):
        inp = real(out)
        captured.append((out, inp))
        return inp
    ch.exchange = tap
    d.read_param("E1-04")
    out, inp = captured[-1]
    req = generic_decode_area(prof, "extended1", "request", out)
    resp = decode_area(prof, "extended1", "response", inp)
    assert req["parameter_access"]["start_register"] == 0x0303
    assert resp["parameter_access"]["values"] == [600]
    assert resp["parameter_access"]["handshake"]["hs"] == req["parameter_access"]["handshake"]["hs"]
    assert any("E1-04" in line for line in resp["text"])


def test_sim_options_as_url_strings(prof):
    model = make_model(prof, b1_02="1", processing_ms="20", comm_timeout="0", E1_04="50",
                       fast_stop_input="none")
    assert model.param("b1-02") == 1 and model.param("E1-04") == 50.0
    assert model.processing == pytest.approx(0.02) and model.fast_stop_input is None
    with pytest.raises(ValueError, match="unknown option"):
        make_model(prof, colour="red")


def test_sim_rejects_foreign_cfg(prof):
    model = make_model(prof)
    assert not model.check_cfg(bytes.fromhex("F3 F1"))
    assert model.check_cfg(bytes.fromhex("55 65")) and model.layout == "extended2"
    assert model.ident == 0x00CA


# --- profile family keys --------------------------------------------------------------------------

def _broken(tmp_path, prof, old, new):
    text = prof.path.read_text(encoding="utf-8")
    assert old in text
    text = text.replace(old, new, 1)
    p = tmp_path / "yaskawa-broken.yaml"
    p.write_text(text, encoding="utf-8")
    line = text[:text.index(new)].count("\n") + 1
    return load_profile_file(p, check_sections=False), line


@pytest.mark.parametrize("old,new,msg", [
    ("fast_stop_input: null", "fast_stop_input: 2", "fast_stop_input"),
    ("reference_unit_hz: 0.01", "reference_unit_hz: fast", "reference_unit_hz"),
    ('cfg: "55 65"', 'cfg: "55 66"', "cfg must be 55 65"),
    ("register_source: printed, access: ro}", "register_source: guessed, access: ro}", "register_source"),
    ("{pwr: green, com: green, err: \"off\", wd: green-flash", "{pwr: green, com: blue, err: \"off\", wd: green-flash",
     "'com'"),
    ("{position: last, param: U3-01}", "{position: last, param: U9-99}", "U9-99"),
])
def test_family_keys_validated_with_line(tmp_path, prof, old, new, msg):
    p, line = _broken(tmp_path, prof, old, new)
    with pytest.raises(DataFileError) as e:
        family_config(p)
    assert msg in e.value.message and e.value.line == line
    assert str(e.value).startswith(f"{p.path}:{line}:")


def test_profile_marks_register_sources(prof):
    src = {c: p.extra.get("register_source") for c, p in prof.parameters.items()}
    assert src["PWR"] == "printed"
    assert src["E1-04"] == src["b1-01"] == src["b1-02"] == "inferred"
    # every parameter with a register says where the register comes from; A1-03 and T1-01 are in the
    # profile only to be marked dangerous (no register published: see the decisions)
    assert all(s in ("printed", "inferred", "external") for c, s in src.items()
               if prof.parameters[c].register is not None)
    assert sorted(c for c, p in prof.parameters.items() if p.register is None) == ["A1-03", "T1-01"]
    assert prof.param("E1-04").access == "stop" and prof.max_frequency_param == "E1-04"
    assert {a.code for a in prof.alarms} >= {"BUS", "EF0", "OPE05", "OPE06", "CPF20", "CPF23"}
    assert len(prof.raw["decisions"]) >= 10


# --- several parameters at once (read_many: fleet dump, factory diff) ------------------------------

def _transactions(d, monkeypatch):
    """The MEMOBUS transactions the drive starts: (start register, count) each."""
    seen = []
    real = d._transact

    def counted(req):
        seen.append((req.start, req.count))
        return real(req)
    monkeypatch.setattr(d, "_transact", counted)
    return seen


def test_read_many_reads_runs_of_consecutive_registers_together(prof, monkeypatch):
    model, ch, d = rig(prof)
    codes = ["A1-02", "b1-01", "b1-02", "b1-03", "C1-01", "C1-02", "C1-09", "C1-10", "d1-01",
             "U3-01", "U3-02", "U3-03", "U3-04"]
    singles = {c: d.read_param(c) for c in codes}
    seen = _transactions(d, monkeypatch)
    got = list(d.read_many(codes))
    assert [c for c, _ in got] == codes
    assert {c: (v.code, v.raw, v.value, v.unit) for c, v in got} == \
        {c: (v.code, v.raw, v.value, v.unit) for c, v in singles.items()}
    # the profile's registers: A1-02 0x102; b1-01..03 0x180..0x182; C1-01/02 0x200/0x201;
    # C1-09/10 0x208/0x209; d1-01 0x280; U3-01..04 0x90..0x93 (4: the format's most, Table 3.5)
    assert seen == [(0x102, 1), (0x180, 3), (0x200, 2), (0x208, 2), (0x280, 1), (0x90, 4)]
    # a run longer than a request carries is cut at the format's limit (here made 2)
    monkeypatch.setattr(d, "fmt", replace(d.fmt, max_registers=2))
    seen.clear()
    got = dict(d.read_many(["b1-01", "b1-02", "b1-03", "U3-01", "U3-02", "U3-03", "U3-04"]))
    assert seen == [(0x180, 2), (0x182, 1), (0x90, 2), (0x92, 2)]
    assert got["U3-04"].raw == singles["U3-04"].raw


def test_read_many_gives_each_refusal_to_its_own_code(prof, monkeypatch):
    model, ch, d = rig(prof)
    seen = _transactions(d, monkeypatch)
    got = dict(d.read_many(["b1-03", "REG0x0183", "nonsense-code", "C1-01"]))
    # 0x182 and 0x183 run together; the simulated drive has no 0x183 (error 02, unknown register):
    # the run is read again one register at a time
    assert seen == [(0x182, 2), (0x182, 1), (0x183, 1), (0x200, 1)]
    assert got["b1-03"].raw == model.regs[0x0182]
    assert isinstance(got["REG0x0183"], ParamError) and got["REG0x0183"].number == 0x02
    assert isinstance(got["nonsense-code"], UsageError)
    assert got["C1-01"].value == pytest.approx(10.0)


def test_read_many_without_an_answer_is_that_error_for_the_whole_run(prof, monkeypatch):
    model, ch, d = rig(prof)

    def silent(req):
        raise DriveError("yaskawa: no answer to the parameter request")
    monkeypatch.setattr(d, "_transact", silent)
    got = list(d.read_many(["C1-01", "C1-02", "d1-01"]))
    assert [c for c, _ in got] == ["C1-01", "C1-02", "d1-01"]
    assert all(isinstance(e, DriveError) and "no answer" in str(e) for _, e in got)


def test_read_many_on_the_six_word_format_reads_one_at_a_time(prof, monkeypatch):
    model, ch, d = rig(prof, "extended2")
    seen = _transactions(d, monkeypatch)
    got = dict(d.read_many(["C1-01", "C1-02"]))
    assert seen == [(0x200, 1), (0x201, 1)]                     # Table 3.5: 1 register only
    assert got["C1-02"].value == pytest.approx(10.0)
