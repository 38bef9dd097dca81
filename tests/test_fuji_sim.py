"""Simulated Fuji drives (OPC-G1-PDP, OPC-PDP3) driven through the Drive interface over DirectChannel.

Also: the manual's chapter-7 PPO3 sequence byte for byte against the model, the card's PKW error
numbers, the control-source rules, o27/o28 communication loss, o30, y97 and o32.
"""

import pytest

from profidrive_cli.drives import make_drive
from conftest import drive_on_bus
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.base import DriveError, ParamError
from profidrive_cli.drives.profile import load_profile
from profidrive_cli.sim import plant
from profidrive_cli.sim.direct import DirectChannel
from profidrive_cli.sim.fuji import FujiModel, make_model

NAMES = ["fuji-g1", "fuji-pdp3"]
BOTH = pytest.mark.parametrize("name", NAMES)


def setup(name, layout="ppo1", **opts):
    prof = load_profile(name)
    model = make_model(prof, **opts)
    ch = DirectChannel(model, prof.layouts[layout].cfg)
    return prof, model, ch, make_drive(ch, prof, layout)


def fast(drive):
    drive.write_param("F07", 1.0)
    drive.write_param("F08", 1.0)


# ---------------------------------------------------------------------------------------------
# the whole story through the Drive interface
# ---------------------------------------------------------------------------------------------

@BOTH
@pytest.mark.parametrize("layout", ["ppo1", "ppo2"])
def test_s1_run_stop_trip_acknowledge_history(name, layout):
    prof, model, ch, d = setup(name, layout)
    assert isinstance(model, FujiModel)
    st = d.status()
    assert st.state.startswith("S1") and st.flags["R/L (PROFIBUS commands active)"]
    fast(d)
    assert d.max_frequency() == 60.0
    d.set_speed_hz(45.0)
    st = d.start()
    assert st.state.startswith("S4") and st.running
    st = d.cycles_until(lambda s: s.flags["FAR (frequency arrival)"], 5, "FAR")
    assert st.speed_hz == pytest.approx(45.0, abs=0.01)
    st = d.stop()
    assert st.state.startswith("S2") and st.stopped
    d.set_speed(-25.0)
    d.start()
    st = d.cycles_until(lambda s: s.flags["FAR (frequency arrival)"], 5, "FAR")
    assert st.speed_percent == pytest.approx(-25.0, abs=0.01)
    model.trip("OL3", ch.now())
    st = d.status()
    assert st.fault and st.state == "fault" and st.fault_code == "OL3"    # narrowed by M16
    assert not st.running and st.speed_percent == 0.0
    with pytest.raises(DriveError, match="fault"):
        d.start()
    st = d.reset_fault()
    assert st.state.startswith("S1") and not st.fault
    hist = d.fault_history()
    # the empty slots (PNU947 0000 / M17-M19 0: "no alarm", manual Table 10.1) are left out
    assert [r.position for r in hist] == ["latest"]
    assert hist[0].raw == 0x2212 and hist[0].codes == ["OL3"] and hist[0].meanings == ["Motor 3 overloaded"]
    d.set_speed(10.0)
    assert d.start().state.startswith("S4")       # runs again after the acknowledge
    d.stop()


@BOTH
def test_seeded_history_reads_names(name):
    prof, model, ch, d = setup(name)
    model.seed_faults(["Er5", "OH4", "OC1"])
    hist = d.fault_history()
    assert [(r.position, r.raw, r.codes) for r in hist] == [
        ("latest", 0x7511, ["Er5"]), ("last", 0x4310, ["OH4"]), ("2nd last", 0x2301, ["OC1"])]   # 3rd: empty
    assert d.read_param("M17").raw == 20 and d.read_param("PNU947[9]").raw == 0x4310


def test_sim_url_trip_and_faults_options():
    bus = plant.build_bus("sim://?stations=3:fuji-g1,4:fuji-pdp3&trip=3:OC1&faults=4:Er5,OL2")
    models = {a: s.model for a, s in bus.slaves.items()}
    assert models[3].state is pd.State.FAULT and models[3].alarm_log[0] == (0x2301, "OC1")
    assert models[4].alarm_log == [(0x7511, "Er5"), (0x2212, "OL2")]


@BOTH
def test_ppo3_without_parameter_channel(name):
    prof, model, ch, d = setup(name, "ppo3")
    assert not d.has_param_channel
    d.set_speed(100.0)
    st = d.start()
    assert st.state.startswith("S4")
    st = d.cycles_until(lambda s: s.speed_hz == 60.0, 10, "60 Hz")     # F03 from the profile
    with pytest.raises(DriveError, match="no parameter channel"):
        d.read_param("F03")
    model.trip("Er5", ch.now())
    st = d.status()
    assert st.fault and st.fault_code is None
    assert d.reset_fault().state.startswith("S1")


def test_jog_is_refused():
    prof, model, ch, d = setup("fuji-g1")
    with pytest.raises(DriveError, match="no jog"):
        d.jog()


# ---------------------------------------------------------------------------------------------
# the manual's chapter 7 bytes against the model (PPO3, F03 = 60 Hz, y98 = 3)
# ---------------------------------------------------------------------------------------------

def _run(ch, req, n=1):
    out = None
    for _ in range(n):
        out = ch.exchange(bytes.fromhex(req))
    return out.hex(" ").upper()


@BOTH
def test_chapter7_sequence_bytes(name):
    prof = load_profile(name)
    model = make_model(prof, o30=3, defaults={"E31": 60.0})
    ch = DirectChannel(model, bytes.fromhex("F1"))
    assert _run(ch, "00000000") == "02 40 00 00"                   # 1 power on, S1
    assert _run(ch, "047E4000") == "02 31 00 00"                   # 2 ready, S2
    assert _run(ch, "047F4000").startswith("02 37")                # 3 run forward, S4
    assert _run(ch, "047F4000", 800) == "07 37 40 00"              # at 60 Hz: FAR and FDT (E31 = 60)
    assert _run(ch, "047E4000")[3:5] == "33"                       # 4 stop: S5 while decelerating
    assert _run(ch, "047E4000", 800) == "02 31 00 00"              # stopped: S2
    assert _run(ch, "0C7F2000", 500) == "03 37 E0 00"              # 5 reverse by bit 11, 30 Hz
    assert _run(ch, "047E4000", 500) == "02 31 00 00"
    assert _run(ch, "047FE000", 500) == "03 37 E0 00"              # 6 reverse by a negative MRV
    model.trip("OC3", ch.now())
    assert _run(ch, "04001000") == "02 08 00 00"                   # tripped (bit 3)
    assert _run(ch, "04801000") == "02 40 00 00"                   # 7 alarm reset edge: S1
    assert _run(ch, "04001000") == "02 40 00 00"                   # 8 release the reset bit
    assert _run(ch, "047E4000") == "02 31 00 00"                   # and restart from step 2


@BOTH
def test_no_s4_without_bits_4_to_6_or_bit_10(name):
    prof = load_profile(name)
    model = make_model(prof, o30=3)
    ch = DirectChannel(model, bytes.fromhex("F1"))
    _run(ch, "047E4000")
    assert _run(ch, "043F4000") == "02 33 00 00"       # bit 6 = 0: stays S3 (no running state)
    assert _run(ch, "044F4000") == "02 33 00 00"       # bit 5 = 0
    assert _run(ch, "047F4000").startswith("02 37")
    _run(ch, "047E4000", 800)
    model2 = make_model(prof, o30=3)
    ch2 = DirectChannel(model2, bytes.fromhex("F1"))
    assert _run(ch2, "007E4000") == "02 40 00 00"      # bit 10 = 0: CTW ignored, stays S1
    assert _run(ch2, "007F4000") == "02 40 00 00"


@BOTH
def test_refuses_to_run_without_y98(name):
    prof, model, ch, d = setup(name, bus_control=False)
    st = d.status()
    assert not st.flags["R/L (PROFIBUS commands active)"]
    with pytest.raises(DriveError, match="y98 = 3"):
        d.start(timeout=0.5)
    d.stop(wait=False)
    d.write_param("y98", 1)                            # reference from the bus, run from the inverter
    with pytest.raises(DriveError):
        d.start(timeout=0.5)
    d.write_param("y98", 3)
    d.set_speed(10.0)
    assert d.start().state.startswith("S4")


# ---------------------------------------------------------------------------------------------
# PKW dialect
# ---------------------------------------------------------------------------------------------

@BOTH
def test_pkw_error_numbers(name):
    prof, model, ch, d = setup(name)
    # unknown function code -> error 0 (the sim knows the profile's codes only)
    with pytest.raises(ParamError) as e:
        d.read_param("C05")
    assert e.value.number == 0
    # out of range (card check: the raw request bypasses the codec's range check) -> 2
    res = d.request(pd.write_request(0x104, 17, 26))
    assert res.error == 2
    assert d.request(pd.write_request(0x104, 15, 26)).ok and d.read_param("F26").value == 15
    # read-only -> 1
    assert d.request(pd.write_request(0x110, 5, 0x5A)).error == 1
    # PNU947 without the array request -> 3; array request on a function code -> 4
    assert d.request(pd.read_request(947, 1)).error == 3
    assert d.request(pd.read_request(0x104, 3, array=True)).error == 4
    assert d.request(pd.PkwFrame(9, 947, 0)).value == 32
    assert d.request(pd.read_request(947, 33, array=True)).error == 3
    # stop-only while running -> 11, with the codec's message
    fast(d)
    d.set_speed(20.0)
    d.start()
    with pytest.raises(ParamError, match="while the inverter runs") as e:
        d.write_param("F03", 50.0)
    assert e.value.number == 11
    d.stop()
    assert d.write_param("F03", 50.0).value == 50.0
    assert d.max_frequency() == 50.0


@BOTH
def test_pnu927_blocks_writes_not_reads(name):
    prof, model, ch, d = setup(name)
    assert d.write_param("PNU927", 0).raw == 0
    with pytest.raises(ParamError, match="PNU927") as e:
        d.write_param("F07", 3.0)
    assert e.value.number == 1
    assert d.read_param("F07").value == 6.0
    d.write_param("PNU927", 1)
    assert d.write_param("F07", 3.0).value == 3.0


@BOTH
def test_busy_104_is_retried(name):
    prof, model, ch, d = setup(name)
    model.busy_next = 3
    assert d.write_param("F08", 2.5).value == 2.5
    assert model.busy_next == 0
    assert [r.value & 0xFFFF for q, r in model.pkw_log if r.ak == 7][:3] == [104, 104, 104]


@BOTH
def test_profidrive_pnus(name):
    prof, model, ch, d = setup(name, address=7, baud_code=10)
    assert d.read_param("PNU918").raw == 7
    assert d.read_param("PNU965").raw == 2
    assert d.read_param("PNU963").raw == 10
    assert d.read_param("W90").raw == 100
    d.status()
    assert d.read_param("PNU968").raw == model.stw
    assert d.read_param("PNU967").raw == d.last_ctw


@BOTH
def test_pcd_words_follow_o40_o48_and_pnu915_916(name):
    from profidrive_cli.drives import fuji
    prof, model, ch, d = setup(name, "ppo2")
    d.map_pzd("actual", 1, fuji.pcd_assignment(prof, "F03"))     # PNU916[1] = 0x0403
    d.map_pzd("actual", 2, fuji.pcd_assignment(prof, "M16"))     # PNU916[2] = 0x0310
    assert d.read_param("o48").raw == 0x0403 and d.read_param("o49").raw == 0x0310
    d.write_param("o40", fuji.pcd_assignment(prof, "F07"))       # o40 = PNU915[1]
    assert d.read_raw(915, 1, array=True) == 0x0407
    d.set_pzd(3, 25)                                             # PCD1 request = F07 raw 25 = 2.5 s
    model.trip("Er7", ch.now())
    st = d.status()
    assert st.raw["pzd3"] == 600 and st.raw["pzd4"] == 37          # F03 60.0 Hz, M16 = Er7 (37)
    assert d.read_param("F07").value == 2.5


# ---------------------------------------------------------------------------------------------
# o30, communication loss, y97, o32
# ---------------------------------------------------------------------------------------------

@BOTH
def test_o30_selects_the_accepted_ppo(name):
    prof = load_profile(name)
    m = make_model(prof, o30=3)
    assert not m.check_cfg(bytes.fromhex("F3F1"))       # ERR LED: o30 says PPO3
    assert m.check_cfg(bytes.fromhex("F1"))
    m = make_model(prof)                                # default: follow the master, set o30
    assert m.check_cfg(bytes.fromhex("F3F5")) and m.values["o30"] == 2
    assert m.check_cfg(bytes.fromhex("F5")) and m.values["o30"] == 4
    assert m.check_cfg(bytes.fromhex("F3F1")) and m.values["o30"] == 1
    assert not m.check_cfg(bytes.fromhex("F3F9"))       # no PPO5 on these cards


def _running(name, **defaults):
    prof, model, ch, d = setup(name, defaults=defaults)
    fast(d)
    d.set_speed(50.0)
    d.start()
    d.cycles_until(lambda s: s.flags["FAR (frequency arrival)"], 5, "FAR")
    return prof, model, ch, d


@BOTH
def test_comm_loss_o27_0_coasts_and_trips_er5(name):
    prof, model, ch, d = _running(name)
    model.on_leave_data_exchange(ch.now(), "watchdog")
    assert model.state is pd.State.FAULT and model.freq == 0.0
    st = d.status()
    assert st.fault_code == "Er5"
    d.reset_fault()
    assert d.fault_history()[0].codes == ["Er5"]


@BOTH
def test_comm_loss_o27_3_keeps_running(name):
    prof, model, ch, d = _running(name, o27=3)
    model.on_leave_data_exchange(ch.now(), "watchdog")
    ch.advance(5.0)
    assert model.state is pd.State.S4 and model.freq == pytest.approx(30.0)


@BOTH
def test_comm_loss_o27_2_recovers_within_o28(name):
    prof, model, ch, d = _running(name, o27=2, o28=2.0)
    model.on_leave_data_exchange(ch.now(), "watchdog")
    ch.advance(1.0)
    d.status()                                          # the link is back within o28
    ch.advance(3.0)
    assert d.status().state.startswith("S4")


@BOTH
def test_comm_loss_o27_1_trips_after_o28_even_if_back(name):
    prof, model, ch, d = _running(name, o27=1, o28=2.0)
    model.on_leave_data_exchange(ch.now(), "watchdog")
    ch.advance(1.0)
    assert d.status().state.startswith("S4")
    ch.advance(1.5)
    assert d.status().fault_code == "Er5"


@BOTH
def test_comm_loss_o27_11_ramps_with_f08_then_trips(name):
    prof, model, ch, d = _running(name, o27=11, o28=0.5)
    d.write_param("F08", 2.0)
    model.on_leave_data_exchange(ch.now(), "watchdog")
    ch.advance(0.4)
    assert model.state is pd.State.S4
    ch.advance(0.2)
    assert model.state is pd.State.S5
    ch.advance(0.5)                                     # 30 Hz at 60 Hz / 2 s: 1 s to stop
    assert model.state is pd.State.S5 and 0 < model.freq < 30.0
    st = d.status()                                     # the master is back: the forced stop goes on
    assert st.state.startswith("S5")
    ch.advance(1.0)
    st = d.status()
    assert st.fault and st.fault_code == "Er5"


@BOTH
def test_no_er5_before_the_first_exchange(name):
    prof = load_profile(name)
    model = make_model(prof)
    model.on_leave_data_exchange(0.0, "watchdog")
    assert model.state is pd.State.S1


def test_pdp3_y97_save():
    prof, model, ch, d = setup("fuji-pdp3")
    assert d.storage_mode().startswith("EEPROM")
    d.set_storage("ram")
    assert d.read_param("y97").raw == 1
    d.save()
    assert model.saves == 1 and d.read_param("y97").raw == 1
    # a write during the save answers 104 and is retried until the save is done
    d.write_raw_code("y97", 2)
    assert d.write_param("F07", 4.0).value == 4.0
    assert any(r.ak == 7 and r.value == 104 for _, r in model.pkw_log)


def test_g1_has_no_separate_save():
    prof, model, ch, d = setup("fuji-g1")
    with pytest.raises(DriveError, match="y97"):
        d.save()


@pytest.mark.parametrize("o32,stops", [(0, False), (1, True), (3, False)])
def test_pdp3_o32_all_zero_data(o32, stops):
    prof = load_profile("fuji-pdp3")
    model = make_model(prof, o30=3, defaults={"o32": o32, "F07": 0.5})
    ch = DirectChannel(model, bytes.fromhex("F1"))
    _run(ch, "047E4000")
    _run(ch, "047F4000", 100)
    assert model.state is pd.State.S4
    _run(ch, "00000000")
    assert (model.state is pd.State.S1) == stops


def test_pdp3_o32_2_depends_on_previous_bit10():
    prof = load_profile("fuji-pdp3")
    model = make_model(prof, o30=3, defaults={"o32": 2, "F07": 0.5})
    ch = DirectChannel(model, bytes.fromhex("F1"))
    _run(ch, "047E4000")
    _run(ch, "047F4000", 100)
    _run(ch, "007F4000")                     # bit 10 = 0: ignored, keeps running
    _run(ch, "00000000")
    assert model.state is pd.State.S4
    _run(ch, "047F4000")
    _run(ch, "00000000")                     # previous CTW had bit 10: coast to S1
    assert model.state is pd.State.S1 and model.freq == 0.0


def test_comm_loss_setting_and_ppo_setting_texts():
    prof, model, ch, d = setup("fuji-g1", defaults={"o27": 12, "o28": 4.0})
    assert d.comm_loss_setting() == ("o27 = 12: decelerate with F08 after o28 = 4 s unless the link returns "
                                     "within 4 s, then trip Er5")
    assert d.ppo_setting() == "o30 = 0: PPO1"


# ---------------------------------------------------------------------------------------------
# the same over the simulated bus (sim://, master, Data_Exchange)
# ---------------------------------------------------------------------------------------------

def test_over_sim_bus_both_cards():
    from profidrive_cli.dp.poller import Master
    from profidrive_cli.fdl.timing import BusParams
    from profidrive_cli.link import open_link

    link = open_link("sim://?stations=3:fuji-g1,4:fuji-pdp3&baud=1500000&trip=3:OC1&trip=4:OL4"
                     "&faults=4:Er5", 1500000)
    try:
        m = Master(link, BusParams.for_baud(1500000, retries=1))
        for addr, name, layout, code in ((3, "fuji-g1", "ppo1", "OC1"), (4, "fuji-pdp3", "ppo2", "OL4")):
            prof = load_profile(name)
            d = drive_on_bus(m, addr, prof, layout)
            st = d.status()
            assert st.fault and st.fault_code == code
            assert not d.reset_fault().fault
            hist = d.fault_history()
            assert hist[0].codes == [code]
            if addr == 4:
                assert hist[1].codes == ["Er5"]
            d.write_param("F07", 0.3)
            d.write_param("F08", 0.3)
            d.set_speed(50.0)
            assert d.start().state.startswith("S4")
            st = d.cycles_until(lambda s: s.flags["FAR (frequency arrival)"], 10, "FAR")
            assert st.speed_hz == pytest.approx(30.0, abs=0.01)
            assert d.stop().state.startswith("S2")
    finally:
        link.close()
