"""Simulated Toyo VF66 + PBUS66-Z (mode 0 PPO1/PPO2/PPO5, mode 1) through the Drive interface over DirectChannel."""

from pathlib import Path

import pytest

from profidrive_cli import UsageError
from profidrive_cli.drives import make_drive
from conftest import drive_on_bus
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives import toyo
from profidrive_cli.drives.base import DriveError, ParamError
from profidrive_cli.drives.profile import load_profile
from profidrive_cli.sim import plant
from profidrive_cli.sim.direct import DirectChannel
from profidrive_cli.sim.toyo import ToyoModel, make_model
from test_toyo_vectors import variant

ROOT = Path(__file__).resolve().parent.parent
PROFILE_PATH = ROOT / "profiles" / "toyo-pbus66z.yaml"


class Recorder(DirectChannel):
    """DirectChannel that keeps every output / input area."""

    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        self.log: list[tuple[bytes, bytes]] = []

    def exchange(self, outputs: bytes) -> bytes:
        inputs = super().exchange(outputs)
        self.log.append((bytes(outputs), inputs))
        return inputs


def setup(layout="ppo1", prof=None, **opts):
    prof = prof or load_profile("toyo")
    opts.setdefault("accel_s", 1.0)
    opts.setdefault("decel_s", 1.0)
    model = make_model(prof, **opts)
    ch = Recorder(model, prof.layouts[layout].cfg)
    return prof, model, ch, make_drive(ch, prof, layout)


def pkw_of(prof, area: bytes) -> tuple:
    return tuple(pd.bytes_to_words(area[:8], prof.word_order))


# ---------------------------------------------------------------------------------------------
# the whole story, each mode
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("layout", ["ppo1", "ppo2", "ppo5"])
def test_mode0_run_stop_trip_acknowledge_history(layout):
    prof, model, ch, d = setup(layout)
    assert isinstance(model, ToyoModel) and model.mode == 0
    st = d.status()
    assert st.state.startswith("S1")
    d.set_speed_hz(45.0)
    st = d.start()
    assert st.state.startswith("S4") and st.running
    st = d.cycles_until(lambda s: s.flags["speed setpoint reached"], 5, "speed reached")
    assert st.speed_hz == pytest.approx(45.0, abs=0.01)
    assert d.read_param("motor-speed").value == 75.0
    st = d.stop()
    assert st.state.startswith("S2") and st.stopped
    d.set_speed(-30.0)                                  # mode 0: reverse = negative speed command
    d.start()
    st = d.cycles_until(lambda s: s.flags["speed setpoint reached"], 5, "speed reached")
    assert st.speed_percent == pytest.approx(-30.0, abs=0.01)
    model.trip("OC", ch.now())
    st = d.status()
    assert st.fault and st.state == "fault" and st.fault_code == "OC"
    assert st.flags["fault"] and not st.running
    if layout == "ppo5":
        assert st.flags["fault: overcurrent"]
    with pytest.raises(DriveError, match="fault"):
        d.start()
    st = d.reset_fault()
    assert st.state.startswith("S1") and st.flags["switch-on inhibited"]
    hist = d.fault_history()
    assert [(r.position, r.raw, r.codes) for r in hist] == [("newest", 1, ["OC"])]
    assert "Overcurrent" in hist[0].meanings[0] and "V/f" in hist[0].meanings[0]
    d.set_speed(10.0)
    assert d.start().state.startswith("S4")            # OFF1 first, then runs again
    d.stop()
    outs = [pd.bytes_to_words(o, "little")[4 if prof.layouts[layout].pkw else 0] for o, _ in ch.log]
    assert 0x0406 in outs and 0x047F in outs           # OFF1 pattern, then RUN (D8 / M8)


def test_mode1_run_stop_trip_reset_history():
    prof, model, ch, d = setup("toyo")
    assert model.mode == 1 and model.values["J-08"] == 1
    st = d.status()
    assert st.state == "stopped"
    d.set_speed(50.0)
    st = d.start()
    assert st.state == "running" and st.flags["running"] and st.flags["normal run command"]
    st = d.cycles_until(lambda s: s.speed_hz == 30.0, 5, "30 Hz")
    assert d.read_param("output-frequency").value == 50.0
    st = d.stop()
    assert st.state == "stopped" and st.stopped
    d.set_speed(-25.0)                                  # mode 1: reverse = run-command bit 2
    st = d.start()
    st = d.cycles_until(lambda s: s.speed_percent == -25.0, 5, "reverse")
    assert st.flags["reverse command"]
    out_words = pd.bytes_to_words(ch.log[-1][0], "little")
    assert out_words[4] & 0x5 == 0x5 and out_words[6] == 5000      # run + reverse, speed positive
    model.trip("OL", ch.now())
    st = d.status()
    assert st.fault and st.fault_code == "OL" and st.flags["fault: overload"]
    with pytest.raises(DriveError, match="run"):
        d.reset_fault()                                 # run bit still set: refused (safety)
    d.stop(wait=False)
    st = d.reset_fault()
    assert not st.fault and st.state == "stopped"
    assert [(r.raw, r.codes) for r in d.fault_history()] == [(7, ["OL"])]
    d.set_speed(10.0)
    assert d.start().state == "running"
    d.stop()
    with pytest.raises(DriveError, match="mode 1"):
        d.stop("quick")


def test_mode1_reset_then_run_bit_must_drop():
    prof = load_profile("toyo")
    model = make_model(prof, accel_s=0.5)
    ch = DirectChannel(model, prof.layouts["toyo"].cfg)
    le = lambda *ws: pd.words_to_bytes(ws, "little")
    run = le(0, 0, 0, 0, 0x0001, 0, 10000, 0, 0, 0)
    for _ in range(3):
        ch.exchange(le(0, 0, 0, 0, 0, 0, 10000, 0, 0, 0))
    for _ in range(100):
        ch.exchange(run)
    assert model.state is pd.State.S4
    model.trip("OV", ch.now())
    ch.exchange(le(0, 0, 0, 0, 0x0021, 0, 10000, 0, 0, 0))        # reset edge with run still on
    for _ in range(50):
        ch.exchange(run)
    assert model.state is pd.State.S1 and model.freq == 0.0           # waits for run = 0
    ch.exchange(le(0, 0, 0, 0, 0, 0, 10000, 0, 0, 0))
    for _ in range(10):
        ch.exchange(run)
    assert model.state is pd.State.S4


def test_seeded_history_and_sim_url():
    prof, model, ch, d = setup()
    model.seed_faults(["COMM", "EXT2", "7"])
    assert [r.codes for r in d.fault_history()] == [["COMM"], ["EXT2"], ["OL"]]
    bus = plant.build_bus("sim://?stations=5:toyo&trip=5:OV&faults=5:UV")
    m = bus.slaves[5].model
    assert m.state is pd.State.FAULT and [w & 0xFF for w in m.trip_log] == [6, 12]


# ---------------------------------------------------------------------------------------------
# PKW rules and errors
# ---------------------------------------------------------------------------------------------

def test_task_zero_once_after_an_error():
    prof, model, ch, d = setup()
    d.status()
    with pytest.raises(ParamError) as e:
        d.read_param("PNU699")
    assert e.value.number == 0
    n = len(ch.log)
    assert d.read_param("dc-voltage").value == 283.0
    sent = [pkw_of(prof, o) for o, _ in ch.log[n:]]
    assert sent[0][0] == 0                             # task 0 first
    assert any(w[0] >> 12 == 1 and w[0] & 0x3FF == 688 for w in sent[1:])


def test_busy_response_zero_is_waited_for():
    prof, model, ch, d = setup(pkw_latency=4)
    assert d.read_param("status-flag").raw == model.status_flag()
    answers = [pkw_of(prof, i)[0] >> 12 for _, i in ch.log]
    assert answers.count(0) >= 4 and answers[-1] == 1


def test_error_answers():
    prof, model, ch, d = setup()
    f = toyo._toyo_frame
    assert d.request(f(2, 688, 0, 5)).error == 1               # monitor is write-protected
    assert d.request(f(6, 688, 1)).error == 102                # task 6 only for traceback / history
    assert d.request(f(1, 720)).error == 102
    assert d.request(f(6, 720, 7)).error == 3                  # history IND 1..6
    assert d.request(f(6, 720, 1)).error == 101                # empty history
    assert d.request(f(6, 708, toyo.traceback_ind(0, 100))).error == 3
    assert d.request(f(6, 708, toyo.traceback_ind(0, 5))).error == 101     # nothing recorded yet
    with pytest.raises(DriveError, match="does not support"):
        d.request(pd.PkwFrame(3, 688))                     # the codec knows tasks 1, 2, 6 only
    with pytest.raises(UsageError, match="does not publish its PNU"):
        d.read_param("A-00")
    with pytest.raises(ParamError, match="read-only"):
        d.write_param("dc-voltage", 1)
    assert d.fault_history() == []


def test_setting_data_with_a_pnu_added(tmp_path):
    prof = variant(tmp_path, **{
        "{code: A-00, name:": "{code: A-00, pnu: 5, name:",
        "{code: J-03, name:": "{code: J-03, pnu: 3, name:"})
    prof_, model, ch, d = setup(prof=prof)
    assert d.read_param("A-00").value == 60.0 and d.max_frequency() == 60.0
    assert d.write_param("A-00", 50.0).value == 50.0            # 500 on the wire (no decimal point)
    assert model.values["A-00"] == 500
    req = [pkw_of(prof, o) for o, _ in ch.log if pkw_of(prof, o)[0] >> 12 == 2]
    assert req[-1][0] == 0x2005 and req[-1][3] == 500
    assert d.request(toyo._toyo_frame(2, 0x400 | 3, 0, 127)).error == 2   # J-03 0..126, 2nd block (bit 10)
    assert d.request(toyo._toyo_frame(2, 0x400 | 3, 0, 5)).value == 5
    assert d.read_param("J-03").raw == 5
    d._fmax = None
    d.set_speed(20.0)
    d.start()
    with pytest.raises(ParamError, match="stopped") as e:
        d.write_param("A-00", 55.0)
    assert e.value.number == 1
    d.stop()


def test_traceback_recorded_at_a_trip():
    prof, model, ch, d = setup()
    d.set_speed(50.0)
    d.start()
    d.cycles_until(lambda s: s.flags["speed setpoint reached"], 5, "speed")
    for _ in range(20):
        d.status()
    model.trip("OS", ch.now())
    d.status()
    trace = d.read_traceback(8, 0, range(95, 100))          # output frequency, newest recording
    assert trace[0] == pytest.approx(50.0) and trace[-1] == 0.0
    assert d.read_param("TB12[0,99]").raw == 1 << 9         # fault flag 1: overspeed
    assert d.request(toyo._toyo_frame(6, 708, toyo.traceback_ind(1, 0))).error == 101


# ---------------------------------------------------------------------------------------------
# control source, jog, external faults, comm loss, diagnosis, modes
# ---------------------------------------------------------------------------------------------

def test_refuses_to_run_without_network_command_source():
    prof, model, ch, d = setup(bus_control=False)
    with pytest.raises(DriveError, match="b-11 = 3"):
        d.start(timeout=0.5)
    prof, model, ch, d = setup(bus_control=False, defaults={"b-09": 2})     # linked -> comm option
    d.set_speed(10.0)
    assert d.start().state.startswith("S4")


def test_bit10_zero_keeps_previous_command():
    prof = load_profile("toyo")
    model = make_model(prof, accel_s=0.2)
    ch = DirectChannel(model, prof.layouts["ppo3"].cfg)
    le = lambda *ws: pd.words_to_bytes(ws, "little")
    ch.exchange(le(0x0406, 10000))
    for _ in range(50):
        ch.exchange(le(0x047F, 10000))
    assert model.state is pd.State.S4
    for _ in range(50):
        ch.exchange(le(0x0000, 0))                       # bit 10 = 0: keep running at 50 %
    assert model.state is pd.State.S4 and model.freq == pytest.approx(30.0)
    ch.exchange(le(0x0478, 10000))                       # OFF1+OFF2+OFF3: OFF2 wins, coast to S1
    assert model.state is pd.State.S1 and model.freq == 0.0


def test_mode0_jog():
    prof, model, ch, d = setup()
    d.jog(True)
    st = d.cycles_until(lambda s: s.speed_percent == 10.0, 5, "jog speed")
    assert st.state.startswith("S3")
    ctw = pd.bytes_to_words(ch.log[-1][0], "little")[4]
    assert ctw & 0x0170 == 0x0100                        # bit 8 with bits 4-6 = 0
    d.jog(False)
    st = d.cycles_until(lambda s: s.stopped, 5, "jog stop")
    d.jog(True, reverse=True)
    st = d.cycles_until(lambda s: s.speed_percent == -10.0, 5, "reverse jog")
    d.jog(False)


def test_external_fault_input_ppo5():
    prof, model, ch, d = setup("ppo5")
    d.status()
    d.words_out["mf_input2"] = 1 << 4                    # external fault 2 (86A operates)
    st = d.status()
    assert st.fault and st.fault_code == "EXT2"
    d.words_out["mf_input2"] = 0
    assert not d.reset_fault().fault


def test_comm_loss_trips_comm_while_running():
    prof, model, ch, d = setup("ppo5")
    d.set_speed(40.0)
    d.start()
    model.on_leave_data_exchange(ch.now(), "watchdog")
    assert model.state is pd.State.FAULT
    st = d.status()
    assert st.fault_code == "COMM" and st.flags["fault: communication timeout"] is True
    d.reset_fault()
    assert d.fault_history()[0].codes == ["COMM"]


def test_comm_loss_when_stopped_does_not_trip():
    prof, model, ch, d = setup()
    d.status()
    model.on_leave_data_exchange(ch.now(), "watchdog")
    assert model.state is not pd.State.FAULT and model.comm_error


def test_fan_failure_is_a_warning():
    prof, model, ch, d = setup("ppo5")
    d.set_speed(20.0)
    d.start()
    model.trip("FAN", ch.now())
    st = d.status()
    assert not st.fault and st.running and st.flags["alarm present"]
    assert d.read_param("mf-output").raw & 0x8000


def test_ext_diag_after_first_trip():
    prof, model, ch, d = setup()
    assert model.ext_diag() == b""
    model.trip("OC", ch.now())
    ext = model.ext_diag()
    assert ext[0] == 9 and len(ext) == 9
    dg = toyo.decode_diag(prof, ext)
    assert dg["fault_flag1"]["set"] == ["overcurrent"]
    assert ext[3:5] == b"\x00\x01"                       # fault flag 1, high byte first


def test_mode_fixed_by_j08():
    prof = load_profile("toyo")
    m = make_model(prof, mode=1)
    assert not m.check_cfg(prof.layouts["ppo1"].cfg)
    assert m.check_cfg(prof.layouts["toyo"].cfg)
    m = make_model(prof, mode=0)
    assert not m.check_cfg(prof.layouts["toyo_plch"].cfg)
    assert m.check_cfg(prof.layouts["ppo5"].cfg) and m.mode == 0


def test_big_endian_override_end_to_end(tmp_path):
    prof = variant(tmp_path, **{"word_order: little": "word_order: big"})
    prof_, model, ch, d = setup(prof=prof)
    d.set_speed(50.0)
    d.start()
    out = ch.log[-1][0]
    assert out[8:12] == bytes.fromhex("047F2710")
    assert d.read_param("dc-voltage").value == 283.0


def test_over_sim_bus_mode0_and_mode1():
    from profidrive_cli.dp.poller import Master
    from profidrive_cli.fdl.timing import BusParams
    from profidrive_cli.link import open_link

    link = open_link("sim://?stations=5:toyo,8:toyo&baud=1500000&trip=5:OV&trip=8:UV&faults=8:COMM", 1500000)
    try:
        m = Master(link, BusParams.for_baud(1500000, retries=1))
        prof = load_profile("toyo")
        for addr, layout, code in ((5, "ppo2", "OV"), (8, "toyo", "UV")):
            d = drive_on_bus(m, addr, prof, layout)
            st = d.status()
            assert st.fault and st.fault_code == code
            assert not d.reset_fault().fault
            hist = d.fault_history()
            assert hist[0].codes == [code]
            if addr == 8:
                assert hist[1].codes == ["COMM"]
            d.set_speed(10.0)
            d.start()
            st = d.cycles_until(lambda s: abs((s.speed_percent or 0) - 10.0) < 0.01, 10, "10 %")
            assert st.speed_hz == pytest.approx(6.0, abs=0.01)
            assert d.stop().stopped
    finally:
        link.close()
