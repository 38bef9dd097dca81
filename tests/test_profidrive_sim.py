"""The generic simulated PROFIdrive drive (sim/profidrive_model.py) and the generic Drive, with a
small synthetic profile (family `profidrive`), over sim.direct.DirectChannel."""

from __future__ import annotations

import textwrap

import pytest

from profidrive_cli.drives import decode_area, make_drive
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.base import DriveError, ParamError
from profidrive_cli.drives.profidrive import PkwFrame, State
from profidrive_cli.drives.profile import load_profile_file
from profidrive_cli.sim.direct import DirectChannel
from profidrive_cli.sim.profidrive_model import ProfidriveModel

PROFILE = textwrap.dedent("""\
    profile: generic-test
    family: profidrive
    title: Generic PROFIdrive test drive
    identity: {ident: 0x1234}
    layouts:
      ppo1: {cfg: "F3 F1", pkw: true}
      ppo2: {cfg: "F3 F5", pkw: true}
      ppo3: {cfg: "F1"}
    default_layout: ppo1
    max_frequency: {param: FMAX, default_hz: 50.0}
    profidrive:
      ramps: {accel: ACC, decel: DEC, quick_decel: QDEC}
      jog_reference: JOG
      fault_memory: {pnu: 947, subindexes: [1, 9, 17, 25]}
      save: {pnu: 971}
      pkw: {zero_between_identical: true}
    parameters:
      - {code: FMAX, name: Max frequency, pnu: 10, unit: Hz, scale: 0.01, min: 25, max: 400, access: stop, default: 50}
      - {code: ACC, name: Acceleration time, pnu: 11, unit: s, scale: 0.1, min: 0.1, max: 3600, default: 2.0}
      - {code: DEC, name: Deceleration time, pnu: 12, unit: s, scale: 0.1, min: 0.1, max: 3600, default: 4.0}
      - {code: QDEC, name: Quick-stop time, pnu: 13, unit: s, scale: 0.1, min: 0.1, max: 3600, default: 0.5}
      - {code: JOG, name: Jog frequency, pnu: 14, unit: Hz, scale: 0.01, min: 0, max: 50, default: 5}
      - {code: LONG, name: A 32-bit value, pnu: 15, size: 32, min: 0, max: 100000, default: 70000}
      - {code: RO1, name: Read-only value, pnu: 16, access: ro, default: 7}
      - {code: NEG, name: Signed value, pnu: 17, signed: true, min: -100, max: 100, default: -5}
    alarms:
      - {number: 1, code: OC, meaning: Overcurrent}
      - {number: 2, code: OV, meaning: Overvoltage}
      - {number: 2, code: OV2, meaning: Overvoltage while braking}
    """)


@pytest.fixture()
def prof(tmp_path):
    p = tmp_path / "generic-test.yaml"
    p.write_text(PROFILE)
    return load_profile_file(p)


def rig(prof, layout="ppo1", **kw):
    model = ProfidriveModel(prof, **kw)
    ch = DirectChannel(model, prof.layouts[layout].cfg)
    return model, ch, make_drive(ch, prof, layout)


def exchange(model, ch, ctw, ref=0x2000, pkw=(0, 0, 0, 0)):
    lay = pd.ppo_layout(model.profile, model.layout)
    out = pd.encode_area(lay, pd.PpoArea(pkw if lay.pkw else None, [ctw, ref]))
    return pd.decode_area_bytes(lay, ch.exchange(out), "response")


def test_seeded_store_and_generic_drive(prof):
    model, ch, drive = rig(prof)
    assert type(drive) is pd.ProfidriveDrive
    assert model.values["FMAX"] == 5000 and model.values["NEG"] == 0xFFFB
    assert drive.read_param("NEG").value == -5
    assert drive.read_param("LONG").value == 70000
    assert drive.write_param("LONG", 99999).value == 99999
    assert drive.write_param("NEG", -100).value == -100
    assert drive.max_frequency() == 50.0


def test_state_machine_by_words(prof):
    model, ch, _ = rig(prof, layout="ppo3")
    a = exchange(model, ch, 0x0000)
    assert model.state is State.S1 and a.word1 == 0x0040           # no bit 10: stays in S1
    exchange(model, ch, 0x047F)
    assert model.state is State.S1                 # S1 needs ON = 0 first
    exchange(model, ch, 0x0406)
    assert model.state is State.S2
    exchange(model, ch, 0x0407)
    assert model.state is State.S3
    exchange(model, ch, 0x040F)
    assert model.state is State.S4                 # bits 4-6 = 0: running at 0 Hz
    for _ in range(50):
        exchange(model, ch, 0x040F)
    assert model.freq == 0.0
    for _ in range(150):
        a = exchange(model, ch, 0x047F)
    assert model.freq == pytest.approx(25.0) and a.word1 & 0x0107 == 0x0107
    # RFG freeze holds the output while the reference changes
    for _ in range(50):
        exchange(model, ch, 0x045F, ref=0x4000)
    assert model.freq == pytest.approx(25.0)
    # setpoint inhibit ramps to 0 but stays in operation
    for _ in range(250):                              # DEC = 4 s for 50 Hz
        exchange(model, ch, 0x043F)
    assert model.freq == 0.0 and model.state is State.S4
    # RFG disabled forces the output to 0 at once
    for _ in range(150):
        exchange(model, ch, 0x047F)
    exchange(model, ch, 0x046F)
    assert model.freq == 0.0 and model.state is State.S4
    # disable operation coasts to S3
    for _ in range(150):
        exchange(model, ch, 0x047F)
    exchange(model, ch, 0x0477)
    assert model.freq == 0.0 and model.state is State.S3


def test_off1_ramp_and_return_to_operation(prof):
    model, ch, _ = rig(prof, layout="ppo3")
    exchange(model, ch, 0x0406)
    for _ in range(150):
        exchange(model, ch, 0x047F)
    a = exchange(model, ch, 0x047E)
    assert model.state is State.S5 and a.word1 & 0x7 == 0x3
    assert pd.state_from_status(a.word1, moving=True) is State.S5
    exchange(model, ch, 0x047F)                          # ON again while ramping: back to S4
    assert model.state is State.S4
    for _ in range(250):
        exchange(model, ch, 0x047E)
    assert model.state is State.S2 and model.freq == 0.0


def test_off3_and_off2(prof):
    model, ch, drive = rig(prof)
    drive.set_speed(100)
    drive.start()
    drive.cycles_until(lambda s: s.flags["at setpoint"], 5, "speed")
    t0 = ch.now()
    assert drive.stop("quick").state == State.S1.value
    assert 0.45 < ch.now() - t0 < 0.6
    drive.start()
    drive.cycles_until(lambda s: s.flags["at setpoint"], 5, "speed")
    st = drive.stop("coast", wait=False)
    assert model.freq == 0.0 and st.state == State.S1.value
    assert not st.flags["no OFF2"]


def test_comm_loss_default_ramp(prof):
    model, ch, drive = rig(prof)
    drive.set_speed(100)
    drive.start()
    drive.cycles_until(lambda s: s.flags["at setpoint"], 5, "speed")
    model.on_leave_data_exchange(ch.now(), "watchdog")
    assert model.state is State.S5
    ch.advance(5.0)
    assert model.state is State.S2 and model.freq == 0.0


def test_clear_outputs(prof):
    model, ch, drive = rig(prof)
    drive.set_speed(50)
    drive.start()
    model.clear_outputs(ch.now())
    assert model.ctw_in == 0 and model.state is State.S4      # generic: bit 10 = 0 keeps the command


@pytest.mark.parametrize("req,ak,value", [
    (PkwFrame(1, 99), 7, 0),                         # unknown PNU
    (PkwFrame(2, 16, 0, 3), 7, 1),                   # read-only
    (PkwFrame(2, 11, 0, 0), 7, 2),                   # below the limit
    (PkwFrame(6, 947, 60), 7, 3),                    # subindex out of range
    (PkwFrame(1, 947, 1), 7, 3),                     # array read without the array request
    (PkwFrame(6, 11, 1), 7, 4),                      # not an array
    (PkwFrame(4, 11), 7, 18),                        # unsupported request: "other error" here
    (PkwFrame(9, 947), 6, 25),                       # number of elements
    (PkwFrame(1, 15), 2, 70000),                     # 32-bit value answers AK 2
    (PkwFrame(1, 11), 1, 20),
    (PkwFrame(1, 965), 1, 2),
])
def test_pkw_server(prof, req, ak, value):
    model, ch, _ = rig(prof)
    resp = model.pkw_answer(req)
    assert (resp.ak, resp.pnu, resp.value) == (ak, req.pnu, value)


def test_pkw_stop_only_and_rights(prof):
    model, ch, drive = rig(prof)
    drive.set_speed(50)
    drive.start()
    assert model.pkw_answer(PkwFrame(2, 10, 0, 6000)).value == 17
    with pytest.raises(DriveError, match="only be changed while the motor is stopped"):
        drive.write_param("FMAX", 60)
    drive.stop()
    drive.write_param("PNU927", 0)
    resp = model.pkw_answer(PkwFrame(1, 11))
    assert resp.ak == 8 and resp.value == 11
    with pytest.raises(ParamError, match="no parameter change rights"):
        drive.write_param("ACC", 3.0)
    drive.write_param("PNU927", 1)
    assert drive.write_param("ACC", 3.0).value == 3.0


def test_pkw_task_executed_once(prof):
    model, ch, _ = rig(prof)
    req = PkwFrame(2, 11, 0, 30).words()
    for _ in range(5):
        a = exchange(model, ch, 0, pkw=req)
    assert a.pkw == (0x1000 | 11, 0, 0, 30) and len(model.pkw_log) == 1
    assert exchange(model, ch, 0, pkw=(0, 0, 0, 0)).pkw == (0, 0, 0, 0)
    exchange(model, ch, 0, pkw=req)
    assert len(model.pkw_log) == 2


def test_fault_history_candidates(prof):
    model, ch, drive = rig(prof)
    model.trip("OV", ch.now())
    st = drive.status()
    assert st.fault and st.fault_code == "OV/OV2"
    drive.reset_fault()
    model.seed_faults(["1"])
    hist = drive.fault_history()
    # the slots reading 0 (no fault: nothing acknowledged pending, 3rd last never used) left out
    assert [(r.position, r.codes) for r in hist] == [("last", ["OC"]), ("2nd last", ["OV", "OV2"])]
    assert hist[1].meanings == ["Overvoltage", "Overvoltage while braking"]
    model.seed_faults([42])
    assert drive.fault_history()[0].codes == ["?42"]


def test_trip_while_running_coasts(prof):
    model, ch, drive = rig(prof)
    drive.set_speed(50)
    drive.start()
    drive.cycles_until(lambda s: s.flags["at setpoint"], 5, "speed")
    model.trip(1, ch.now())
    st = drive.status()
    assert st.fault and model.freq == 0.0 and st.running is False
    with pytest.raises(ValueError):
        model.trip("XYZ", ch.now())


def test_save_edge(prof):
    model, ch, drive = rig(prof)
    before = dict(model.values)
    drive.save()
    drive.save()
    assert model.saves == 2
    assert model.values == before       # saving stores what is there: no value changes
    assert model.pkw_answer(PkwFrame(2, 971, 0, 1)).ak == 1 and model.saves == 2   # no edge


def test_generic_decode(prof):
    d = decode_area(prof, "ppo1", "request", bytes.fromhex("200B00000000001E047F2000"))
    assert d["pkw"]["code"] == "ACC" and d["pkw"]["value_text"] == "3.0 s"
    assert d["control_word"]["label"] == "CTW" and d["reference"]["label"] == "MRV"
    d = decode_area(prof, "ppo1", "response", bytes.fromhex("73B3010000000002023800 00".replace(" ", "")))
    assert d["pkw"]["error"] == 2
    d = decode_area(prof, "ppo1", "response", bytes.fromhex("43B3010000000002023800 00".replace(" ", "")))
    assert d["pkw"]["alarms"] == ["OV", "OV2"] and d["status_word"]["state"] == "fault"
