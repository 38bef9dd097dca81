"""The simulated Moeller drive, driven only through the codec / Drive over sim.direct.DirectChannel."""

from __future__ import annotations

import pytest

from profidrive_cli import UsageError
from profidrive_cli.drives import make_drive
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.base import DriveError, ParamError
from profidrive_cli.drives.moeller import MoellerDrive
from profidrive_cli.drives.profile import load_profile
from profidrive_cli.sim.direct import DirectChannel
from profidrive_cli.sim.moeller import MoellerModel, make_model


@pytest.fixture(scope="module")
def prof():
    return load_profile("moeller")


def rig(prof, layout="ppo1", **opts):
    model = make_model(prof, **opts)
    ch = DirectChannel(model, prof.layouts[layout].cfg)
    drive = make_drive(ch, prof, layout)
    return model, ch, drive


def h(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", ""))


def test_make_model(prof):
    m = make_model(prof, address=6, device="DV6")
    assert isinstance(m, MoellerModel) and m.ident == 0xFD06 and m.node_address == 6
    assert m.real_cfg() == bytes.fromhex("F3F1")
    assert set(m.cfgs) == {"ppo1", "ppo2", "ppo3", "ppo4", "ppo5"}
    with pytest.raises(ValueError):
        make_model(prof, device="DX9")


def test_full_cycle_s1_run_stop_trip_ack_history(prof):
    """S1 -> operation at a set speed -> stop -> trip -> acknowledge -> fault history with names."""
    model, ch, drive = rig(prof)
    assert isinstance(drive, MoellerDrive)
    st = drive.status()
    assert st.state == "S1 switching on inhibited" and not st.running
    assert drive.max_frequency() == 50.0                       # A004 read over PKW
    drive.set_speed(60.0)
    st = drive.start()
    assert st.state == "S4 operation" and st.running
    st = drive.cycles_until(lambda s: s.flags["at setpoint"], 10, "set speed")
    assert st.speed_percent == pytest.approx(60.0, abs=0.01)       # N2 steps of 1/16384
    assert st.speed_hz == pytest.approx(30.0, abs=0.01)
    assert st.raw["status_word"] == 0x0337 and model.freq == pytest.approx(30.0, abs=0.01)
    st = drive.stop("normal")
    assert st.state == "S2 ready for switching on" and st.stopped and model.freq == 0.0
    assert st.raw["status_word"] == 0x0331                    # the manual's "ready" word
    model.trip("E05", ch.now())
    st = drive.status()
    assert st.fault and st.state == "fault" and st.fault_code == "E05"
    st = drive.reset_fault()
    assert not st.fault and st.state == "S1 switching on inhibited"
    hist = drive.fault_history()
    # acknowledged: no current fault; the slots reading 0 ("No fault", manual Table 8) are left out
    assert [r.position for r in hist] == ["last"]
    assert (hist[0].raw, hist[0].codes) == (5, ["E05"])
    assert "overload" in hist[0].meanings[0]
    # and it runs again after the acknowledgement
    assert drive.start().state == "S4 operation"


def test_control_words_on_the_wire(prof):
    """The drive sends the manual's sequence: 0x0406 then 0x047F; stop 0x047E; ack edge on bit 7."""
    model, ch, drive = rig(prof)
    seen = []
    orig = ch.exchange

    def spy(out):
        seen.append(int.from_bytes(out[8:10], "big"))
        return orig(out)
    ch.exchange = spy
    drive.set_speed(10)
    drive.start()
    assert seen[-2:] == [0x0406, 0x047F] and 0x0406 in seen
    drive.stop()
    assert seen[-1] == 0x047E
    model.trip("E07", ch.now())
    seen.clear()
    drive.reset_fault()
    assert 0x0486 in seen and seen[0] == 0x047E        # last word without bit 7, then the edge


def test_tv1_replay_exact(prof):
    """The manual's example 1 octets against the simulated card."""
    model = make_model(prof)
    ch = DirectChannel(model, prof.layouts["ppo1"].cfg)
    inp = ch.exchange(h("30 17 00 00 00 00 01 90 04 06 20 00"))
    # phase A: assert PKW and ZSW only (the manual's HIW there is ambiguous)
    assert inp[:10] == h("20 17 00 00 00 00 01 90 03 31")
    assert model.param_value("F002") == 4.0
    for _ in range(400):
        inp = ch.exchange(h("30 17 00 00 00 00 01 90 04 7F 20 00"))
    assert inp == h("20 17 00 00 00 00 01 90 03 37 20 00")
    assert model.pkw_log[0][0].pnu == 23 and len(model.pkw_log) == 1      # executed once


def test_tv2_tv3_replay_exact(prof):
    model = make_model(prof)
    ch = DirectChannel(model, prof.layouts["ppo2"].cfg)
    inp = ch.exchange(h("73 94 01 00 00 00 00 3D 04 06 20 00 00 00 00 00 00 00 00 00"))
    assert inp[:10] == h("43 94 01 00 00 00 00 3D 03 31") and inp[12:14] == h("01 F4")
    for _ in range(400):
        inp = ch.exchange(h("73 94 01 00 00 00 00 3D 04 7F 20 00 00 00 00 00 00 00 00 00"))
    assert inp == h("43 94 01 00 00 00 00 3D 03 37 20 00 01 F4 00 00 00 00 00 00")
    for _ in range(3):
        inp = ch.exchange(h("73 93 01 00 00 00 00 3E 04 7F 20 00 00 4B 00 00 00 00 00 00"))
    assert inp == h("43 93 01 00 00 00 00 3E 03 37 20 00 01 F4 00 00 00 00 00 00")
    # A004 is writable only when stopped: the cyclic 75 waits (decision), then applies at standstill
    assert model.param_value("A004") == 50
    for _ in range(600):
        ch.exchange(h("00 00 00 00 00 00 00 00 04 7E 20 00 00 4B 00 00 00 00 00 00"))
    assert model.freq == 0.0 and model.param_value("A004") == 75


def test_parameters_read_write(prof):
    model, ch, drive = rig(prof)
    assert str(drive.read_param("F002")) == "F002 = 5.0 s"
    assert drive.write_param("F002", 4.0).value == 4.0
    assert model.values["F002"] == 400
    assert drive.write_param("A113", -20).value == -20          # signed 1-octet value
    assert model.values["A113"] == 0xEC
    v = drive.read_param("PNU23")
    assert (v.code, v.value) == ("F002", 4.0)
    assert drive.read_param("PNU964").raw == 0x812C and drive.device() == "DF6"
    assert drive.read_param("PNU965").value == 2


def test_write_checks_before_sending(prof):
    model, ch, drive = rig(prof)
    drive.status()
    n = len(model.pkw_log)
    with pytest.raises(ParamError, match=r"outside 0.01..3600 s"):
        drive.write_param("F002", 0)
    with pytest.raises(ParamError, match="read-only"):
        drive.write_param("d001", 1)
    with pytest.raises(ParamError, match="outside 1..48, 255"):
        drive.write_param("C001", 100)
    assert len(model.pkw_log) == n          # nothing went out


def test_df6_limits(prof):
    _, _, df6 = rig(prof, device="DF6")
    with pytest.raises(ParamError, match="DF6 maximum 39"):
        df6.write_param("C001", 45)
    with pytest.raises(ParamError, match="does not exist on a DF6"):
        df6.write_param("H020", 1.0)
    _, _, dv6 = rig(prof, device="DV6")
    assert dv6.write_param("C001", 45).value == 45
    assert dv6.device() == "DV6"


def test_stop_only_refused_while_running(prof):
    model, ch, drive = rig(prof)
    drive.set_speed(50)
    drive.start()
    with pytest.raises(DriveError) as ei:
        drive.write_param("A004", 60)
    msg = str(ei.value)
    assert "A004 (1st Maximum frequency) can only be changed while the motor is stopped" in msg
    assert "error 17" in msg and ei.value.number == 17
    drive.stop()
    assert drive.write_param("A004", 60).value == 60
    assert drive.max_frequency() == 60.0


def test_unknown_pnu_and_rights(prof):
    model, ch, drive = rig(prof)
    with pytest.raises(ParamError, match="error 0"):
        drive.read_param("PNU29")               # a gap in the cross-reference
    with pytest.raises(ParamError, match="error 0"):
        drive.read_param("PNU966")
    drive.write_param("PNU927", 0)
    with pytest.raises(ParamError, match="no parameter change rights"):
        drive.read_param("F002")
    assert drive.write_param("PNU927", 1).value == 1
    assert drive.read_param("F002").value == 5.0


def test_unsupported_request_refused_locally(prof):
    model, ch, drive = rig(prof)
    with pytest.raises(DriveError, match="does not support request AK 4"):
        drive.request(pd.PkwFrame(4, 23))
    # the card itself answers 106 to an unsupported task
    assert model.pkw_answer(pd.PkwFrame(8, 916, 1, 5)).value == 106


def test_identical_requests_and_latency(prof):
    model, ch, drive = rig(prof, pkw_latency=3)
    assert drive.read_param("F002").value == 5.0
    model.values["F002"] = 250
    assert drive.read_param("F002").value == 2.5         # a fresh task, not the stale echo
    drive.write_param("F002", 4.0)
    drive.write_param("F002", 4.0)
    assert sum(1 for req, _ in model.pkw_log if req.ak == 3) == 2


def test_refuses_to_run_without_bus_commands(prof):
    # A002 != 1: the card's commands are not used
    model, ch, drive = rig(prof)
    drive.write_param("A002", 3)
    drive.set_speed(50)
    with pytest.raises(DriveError) as ei:
        drive.start(timeout=0.5)
    assert "A002 = 1" in str(ei.value)
    assert model.state is pd.State.S2 or model.state is pd.State.S1
    assert model.freq == 0.0
    # CTW bit 12 (commands invalid) does the same with A002 = 1
    model, ch, drive = rig(prof)
    drive.extra_bits = 1 << 12
    with pytest.raises(DriveError):
        drive.start(timeout=0.5)
    assert model.freq == 0.0 and model.status_word() & 0x1000       # ZSW mirrors bit 12


def test_bit10_zero_ignored(prof):
    model = make_model(prof)
    ch = DirectChannel(model, prof.layouts["ppo3"].cfg)
    for _ in range(50):
        inp = ch.exchange(h("00 7F 20 00"))             # run bits but no bit 10
    assert model.state is pd.State.S1 and inp[:2] == h("00 40")
    for _ in range(3):
        ch.exchange(h("04 06 20 00"))
    for _ in range(300):
        inp = ch.exchange(h("04 7F 20 00"))
    assert inp == h("03 37 20 00")
    # bit 10 drops while running: the run command is gone, the motor ramps down
    for _ in range(300):
        inp = ch.exchange(h("00 7F 20 00"))
    assert model.freq == 0.0 and model.state is pd.State.S2


def test_reference_only_from_bus(prof):
    """Bit 13 = 1: the reference stays at its last bus value."""
    model, ch, drive = rig(prof)
    drive.set_speed(40)
    drive.start()
    drive.cycles_until(lambda s: s.flags["at setpoint"], 10, "speed")
    drive.extra_bits = 1 << 13
    drive.set_speed(80)
    for _ in range(50):
        drive.cycle()
    assert model.freq == pytest.approx(20.0, abs=0.01)


def test_reverse(prof):
    model, ch, drive = rig(prof)
    drive.set_speed(-25)
    drive.start()
    st = drive.cycles_until(lambda s: s.flags["at setpoint"], 10, "speed")
    assert st.speed_percent == -25.0 and st.speed_hz == -12.5
    assert model.freq == pytest.approx(-12.5)
    drive.extra_bits = 1 << 11              # reverse bit with a negative reference: forward
    for _ in range(400):
        drive.cycle()
    assert model.freq == pytest.approx(12.5)


def test_quick_and_coast_stop(prof):
    model, ch, drive = rig(prof)
    drive.set_speed(100)
    drive.start()
    drive.cycles_until(lambda s: s.flags["at setpoint"], 10, "speed")
    t0 = ch.now()
    st = drive.stop("quick")
    assert st.state == "S1 switching on inhibited" and 0.9 < ch.now() - t0 < 1.2   # F203 = 1 s
    drive.start()
    drive.cycles_until(lambda s: s.flags["at setpoint"], 10, "speed")
    t0 = ch.now()
    st = drive.stop("coast")
    assert st.state == "S1 switching on inhibited" and ch.now() - t0 < 0.05
    drive.start()
    drive.cycles_until(lambda s: s.flags["at setpoint"], 10, "speed")
    t0 = ch.now()
    drive.stop("normal")
    assert 4.9 < ch.now() - t0 < 5.2                          # F003 = 5 s from 50 Hz
    with pytest.raises(UsageError, match="stop mode"):
        drive.stop("sideways")


def test_jog(prof):
    model, ch, drive = rig(prof)
    drive.set_speed(0)
    drive.start()
    drive.jog(True)
    for _ in range(200):
        drive.cycle()
    assert model.freq == 5.0                                  # A038 = 5.00 Hz
    drive.jog(False)
    for _ in range(200):
        drive.cycle()
    assert model.freq == 0.0


def test_pzd_mapping_through_the_drive(prof):
    model, ch, drive = rig(prof, layout="ppo2")
    drive.map_pzd("actual", 1, prof.param("d080").pnu)
    drive.map_pzd("actual", 2, prof.param("A038").pnu)
    assert drive.pzd_mapping("actual") == [352, 61, 0, 0]
    st = drive.status()
    assert st.raw["pzd3"] == 0 and st.raw["pzd4"] == 500
    model.trip("E01", ch.now())
    assert drive.status().raw["pzd3"] == 1                 # d080 trip counter
    with pytest.raises(ParamError):
        drive.map_pzd("actual", 3, prof.param("F002").pnu)   # 4-octet parameters cannot be mapped


def test_no_pkw_layout(prof):
    model, ch, drive = rig(prof, layout="ppo3")
    assert not drive.has_param_channel
    drive.set_speed(50)
    assert drive.start().state == "S4 operation"
    with pytest.raises(DriveError, match="no parameter channel"):
        drive.read_param("F002")
    assert drive.max_frequency() == 50.0


def test_seed_faults_and_trip_records(prof):
    model, ch, drive = rig(prof)
    model.seed_faults(["E01", "E12"])
    hist = drive.fault_history()
    assert [(r.position, r.codes) for r in hist] == [("last", ["E01"]), ("2nd last", ["E12"])]
    with pytest.raises(ValueError, match="unknown alarm"):
        model.seed_faults(["OC1"])
    drive.set_speed(50)
    drive.start()
    drive.cycles_until(lambda s: s.flags["at setpoint"], 10, "speed")
    model.trip("E07", ch.now())
    assert drive.read_param("d080").value == 1
    assert drive.read_param("PNU354").value == 0         # 00..05 (manual L1116): 00 = record 1 (d081)
    assert drive.read_param("d081").raw == 7
    assert drive.read_param("PNU356").value == 25.0        # frequency at the trip
    drive.reset_fault()
    assert [(r.position, r.codes) for r in drive.fault_history()] == [
        ("last", ["E07"]), ("2nd last", ["E01"]), ("3rd last", ["E12"])]


def test_fault_cause_still_present(prof):
    model, ch, drive = rig(prof)
    model.trip(9, ch.now())
    model.fault_cause_active = True
    with pytest.raises(DriveError, match="fault to clear"):
        drive.reset_fault(timeout=0.3)
    model.fault_cause_active = False
    assert not drive.reset_fault().fault
    with pytest.raises(DriveError, match="acknowledge"):
        model.trip("E01", ch.now())
        drive.start()


def test_comm_loss(prof):
    model, ch, drive = rig(prof)
    drive.set_speed(50)
    drive.start()
    model.on_leave_data_exchange(ch.now(), "watchdog")
    assert model.state is pd.State.FAULT and model.fault == 70          # P002 = 0: trip E70
    model, ch, drive = rig(prof)
    drive.write_param("P002", 1)
    drive.set_speed(50)
    drive.start()
    drive.cycles_until(lambda s: s.flags["at setpoint"], 10, "speed")
    model.on_leave_data_exchange(ch.now(), "watchdog")
    ch.advance(1.0)
    assert model.state is pd.State.S4 and model.freq == 25.0             # keeps running
    # a stopped drive does not trip when the master goes away
    model, ch, drive = rig(prof)
    drive.status()
    model.on_leave_data_exchange(ch.now(), "watchdog")
    assert model.state is pd.State.S1


def test_save(prof):
    model, ch, drive = rig(prof)
    drive.save()
    assert model.saves == 1
    drive.set_speed(50)
    drive.start()
    with pytest.raises(ParamError, match="error 17"):
        drive.save()


def test_bus_control_check(prof):
    _, _, drive = rig(prof)
    assert drive.bus_control_check() == []
    _, _, drive = rig(prof, bus_control=False)
    probs = drive.bus_control_check()
    assert len(probs) == 2 and "A001 = 1" in probs[0] and "A002 = 2" in probs[1]
    assert set(drive.comm_loss_setting()) == {"P002", "P001"}


def test_card_info(prof):
    _, _, drive = rig(prof, address=27, baud_code=8, device="DV6")
    info = drive.card_info()
    assert info == {"node_address": 27, "baud": "19.2 kbit/s", "device": "0x012C (DV6)",
                    "profile_version": 2, "edit_rights": 1, "control_rights": 1,
                    "control_word": "0x0000", "status_word": "0x0040"}
