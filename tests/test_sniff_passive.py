"""The passive PROFIdrive view (`pdrive sniff --station`) and the passive live list (`--live`) on
hand-built telegrams; expected values from the specs' worked examples and bit tables
(/work/shared/spec), hand calculations where noted. Sniff never writes to the port."""

import json

import pytest
from click.testing import CliRunner

from profidrive_cli import UsageError
from profidrive_cli.bustools.passive import PassiveDecoder, parse_station, watch_list
from profidrive_cli.bustools.passive_live import LiveList
from profidrive_cli.dp.capture import Capture
from profidrive_cli.fdl import frames as F

MASTER = 2


def req(da, data, fcb=True, fcv=True, dsap=None, ssap=None, function=F.SRD_HIGH):
    return F.encode(F.Frame(F.SD2, da, MASTER, F.request_fc(function, fcb, fcv), bytes(data),
                            dsap, ssap))


def rep(sa, data, status=F.DL):
    return F.encode(F.Frame(F.SD2, MASTER, sa, status, bytes(data)))


def frames(*telegrams, t0=0.0, dt=0.01):
    """Captured frames, the i-th arriving at t0 + i * dt."""
    cap = Capture()
    out = []
    for i, tg in enumerate(telegrams):
        out += cap.feed(tg, t0 + i * dt)
    return out


def decode_all(specs, *telegrams):
    dec = PassiveDecoder(watch_list(specs))
    return [dec.decode(c) for c in frames(*telegrams)]


# -- --station: the drive's view of its outputs and inputs --------------------------------------

def test_fuji_ppo1_read_y98_and_running_in_words():
    # fuji-opc-g1-pdp.md §5.6 example 2a / TV12: read y98 -> value 3; CTW 0x047F goes to S4,
    # STW 0x0337 = S4 running (state table, §3); MRV/MAV 0x2000 = 50 % of F03 = 60 Hz -> 30 Hz
    out_area = bytes.fromhex("11 0F 62 00 00 00 00 00 04 7F 20 00")
    in_area = bytes.fromhex("11 0F 62 00 00 00 00 03 03 37 20 00")
    r, a = decode_all(["3=fuji-g1"], req(3, out_area), rep(3, in_area))
    assert r["station"] == 3 and r["direction"] == "request" and r["layout"] == "ppo1"
    assert "enable operation" in r["control"]
    assert r["reference_hz"] == 30.0
    assert r["param"]["request"] == "read" and r["param"]["text"] == "read y98"
    assert a["direction"] == "response" and a["state"].startswith("S4")
    assert a["actual_hz"] == 30.0
    assert a["param"]["text"] == "y98 = 3"
    assert "read y98" in r["text"] and "30.00 Hz" in r["text"]


def test_fuji_pkw_write_and_its_error_answer():
    # TV9 write F26 = 15 (RC 2), TV11 answer RC 7 error 2 (value out of range)
    r, a = decode_all(["3=fuji-g1"], req(3, bytes.fromhex("21 04 1A 00 00 00 00 0F 04 7F 20 00")),
                      rep(3, bytes.fromhex("71 04 1A 00 00 00 00 02 03 37 20 00")))
    assert r["param"]["request"] == "write" and r["param"]["text"].startswith("write F26 = 15")
    assert a["param"]["error"] == 2 and a["param"]["text"].startswith("F26: error 2")


def test_moeller_example_1_write_f002_and_operation():
    # moeller-de6-net-dp.md TV-1b: write F002 = 4.00 s (AK 3, PNU 23, PWE 400 x 0.01 s);
    # STW 0x047F "operation enabled"; ZSW 0x0337 = S4 "Operation"; HSW/HIW 0x2000 = 50 % of A004
    # (profile default 50 Hz) = 25 Hz
    r, a = decode_all(["6=moeller:ppo1"], req(6, bytes.fromhex("30 17 00 00 00 00 01 90 04 7F 20 00")),
                      rep(6, bytes.fromhex("20 17 00 00 00 00 01 90 03 37 20 00")))
    assert r["param"]["text"] == "write F002 = 4.00 s"
    assert "enable operation" in r["control"] and r["reference_hz"] == 25.0
    assert a["state"].startswith("S4") and "operation enabled" in a["status"]
    assert a["actual_hz"] == 25.0
    assert a["param"]["text"] == "F002 = 4.00 s"


def test_toyo_mode0_ppo1_run_frame():
    # toyo-vf66-pbus66z.md D20: `00 00 00 00 00 00 00 00 7F 04 10 27` = STW 0x047F (RUN),
    # speed 10000 of 20000 counts = 50 % of A-00 (60 Hz) = 30 Hz
    (r,) = decode_all(["5=toyo"], req(5, bytes.fromhex("00 00 00 00 00 00 00 00 7F 04 10 27")))
    assert r["command"] == "RUN" and r["reference_hz"] == 30.0
    assert "param" not in r                  # PKW idle (task ID 0)


def test_toyo_mode1_status_flag_gives_the_state():
    # toyo-vf66-pbus66z.md §3.4/3.5: mode 1 inputs (little-endian words after the PKW): status flag
    # bit 1 "running normally" (Table 3.9), motor speed 10000 of 20000 counts = 30 Hz at A-00 60 Hz
    lay_len = 8 + 2 * 14
    area = bytearray(lay_len)
    area[8:10] = (0x0002).to_bytes(2, "little")
    area[16:18] = (10000).to_bytes(2, "little")
    (a,) = decode_all(["5=toyo:toyo"], rep(5, area))
    assert a["state"] == "running" and a["actual_hz"] == 30.0
    area[10:12] = (0x0001).to_bytes(2, "little")        # fault flag 1 bit 0: overcurrent
    (a,) = decode_all(["5=toyo:toyo"], rep(5, area))
    assert a["state"].startswith("fault") and "overcurrent" in a["state"]


def test_yaskawa_forward_run_and_running():
    # yaskawa-profibus-dp.md: command bit 0 Forward Run (D1: 0x0001), reference 1 count = 0.01 Hz
    # (3000 -> 30.00 Hz); status bit 0 Running; output frequency 0.1 Hz per count (300 -> 30.0 Hz)
    out_area = bytearray(32)
    out_area[0:4] = bytes.fromhex("00 01 0B B8")
    in_area = bytearray(32)
    in_area[0:2] = bytes.fromhex("00 01")
    in_area[10:12] = (300).to_bytes(2, "big")       # extended1 inputs: word 5 = output frequency
    r, a = decode_all(["7=yaskawa"], req(7, out_area), rep(7, in_area))
    assert r["layout"] == "extended1"
    assert r["command"] == "forward run" and r["reference_hz"] == 30.0
    assert a["state"] == "running" and a["actual_hz"] == 30.0


def test_max_frequency_learnt_from_a_pkw_answer_on_the_wire():
    # after the drive answers F03 = 50.0 Hz (PWE 500 x 0.1), MRV 0x2000 (50 %) is 25 Hz, not 30
    f03 = "11 04 03 00 00 00 01 F4"
    r1, a, r2 = decode_all(["3=fuji-g1"], req(3, bytes.fromhex("00" * 8 + "04 7F 20 00")),
                           rep(3, bytes.fromhex(f03 + "03 37 20 00")),
                           req(3, bytes.fromhex("00" * 8 + "04 7F 20 00"), fcb=False))
    assert r1["reference_hz"] == 30.0
    assert a["param"]["text"] == "F03 = 50.0 Hz"
    assert r2["reference_hz"] == 25.0


def test_layout_from_the_chk_cfg_seen_on_the_wire():
    # Moeller PPO2 (Chk_Cfg F3 F5, 20 octets each way): spec TV-2a's OUT area
    chk = req(6, b"\xF3\xF5", dsap=62, ssap=62)
    out2 = bytes.fromhex("73 94 01 00 00 00 00 3D 04 06 20 00 00 00 00 00 00 00 00 00")
    _, r = decode_all(["6=moeller"], chk, req(6, out2))
    assert r["layout"] == "ppo2"
    assert r["param"]["text"].startswith("write PNU916[1] = 61 (A038")


def test_stations_not_given_stay_undecoded_and_other_services_too():
    out_area = bytes.fromhex("00" * 8 + "04 7F 20 00")
    got = decode_all(["3=fuji-g1"], req(4, out_area), req(3, b"\x88\x01\x01\x0b\xfd\x01\x00",
                                                          dsap=61, ssap=62))
    assert got == [None, None]


def test_an_area_of_the_wrong_length_says_so():
    (r,) = decode_all(["3=fuji-g1:ppo1"], req(3, bytes(6)))
    assert "error" in r and "6" in r["error"]


@pytest.mark.parametrize("text", ["3", "x=fuji-g1", "200=fuji-g1", "3=", "=fuji-g1"])
def test_bad_station_options_are_refused(text):
    with pytest.raises(UsageError):
        parse_station(text)


def test_unknown_profile_or_layout_is_refused():
    with pytest.raises(UsageError):
        watch_list(["3=fuji-g1:ppo9"])
    with pytest.raises(UsageError) as e:
        watch_list(["3=no-such-drive"])
    assert "no-such-drive" in str(e.value)


# -- --live: the passive live list ---------------------------------------------------------------

def bring_up(addr, ident):
    prm = bytes([0x88, 1, 1, 11, ident >> 8, ident & 0xFF, 0])
    return [req(addr, prm, fcb=True, fcv=False, dsap=61, ssap=62), F.encode(F.Frame(F.SC)),
            req(addr, b"\xF3\xF1", fcb=False, fcv=True, dsap=62, ssap=62), F.encode(F.Frame(F.SC))]


def test_live_list_states_ident_cycle_and_counters():
    ll = LiveList()
    seq = []
    t = 0.0
    for tg in bring_up(3, 0xFD01):
        seq.append((tg, t))
        t += 0.001
    area = bytes(12)
    states = []
    fcb = True
    for i in range(4):                     # four Data_Exchange cycles, 20 ms apart
        t = 0.1 + 0.02 * i
        seq += [(req(3, area, fcb=fcb), t), (rep(3, area), t + 0.002)]
        fcb = not fcb
    cap = Capture()
    for tg, tt in seq:
        for c in cap.feed(tg, tt):
            ll.feed(c)
            states.append(ll.station(3).state)
    assert "parameterising" in states and "configuring" in states
    s = ll.snapshot(1.0)["stations"][0]
    assert s["station"] == 3 and s["ident"] == 0xFD01 and s["ident_hex"] == "0xFD01"
    assert s["state"] == "data exchange" and s["exchanges"] == 4
    assert s["cycle_s"]["min"] == pytest.approx(0.02) and s["cycle_s"]["max"] == pytest.approx(0.02)
    assert s["counters"] == {"retries": 0, "no_answer": 0, "illegal": 0, "reparams": 0}
    # a repeated request (same FCB, FCV 1) after no answer: one no_answer, one retry
    for c in frames(req(3, area, fcb=fcb), req(3, area, fcb=fcb), rep(3, area), t0=0.2):
        ll.feed(c)
    s = ll.snapshot(1.0)["stations"][0]
    assert s["counters"]["no_answer"] == 1 and s["counters"]["retries"] == 1
    assert s["state"] == "data exchange"
    # a corrupt reply (FCS wrong) counts as illegal for the station and as an fcs error on the bus
    bad = bytearray(rep(3, area))
    bad[-2] ^= 0xFF
    for c in frames(req(3, area, fcb=not fcb), bytes(bad), t0=0.3):
        ll.feed(c)
    snap = ll.snapshot(1.0)
    assert snap["stations"][0]["counters"]["illegal"] == 1 and snap["errors"].get("fcs") == 1
    # the station answers with high priority (diagnosis pending): state diagnosis
    for c in frames(req(3, area, fcb=fcb), rep(3, area, status=F.DH), t0=0.4):
        ll.feed(c)
    assert ll.station(3).state == "diagnosis"
    # Set_Prm again after data exchange: one re-parameterisation
    for c in frames(*bring_up(3, 0xFD01)[:2], t0=0.5):
        ll.feed(c)
    assert ll.station(3).counters["reparams"] == 1 and ll.station(3).state == "parameterising"
    assert snap["masters"] == [MASTER]


def test_live_list_a_station_that_never_answers():
    ll = LiveList()
    for c in frames(req(9, bytes(4), function=F.FDL_STATUS, fcb=False, fcv=False),
                    req(10, bytes(0), function=F.FDL_STATUS, fcb=False, fcv=False)):
        ll.feed(c)
    assert ll.station(9).state == "no answer" and ll.station(9).counters["no_answer"] == 1


def test_sniff_from_file_with_stations_and_live(tmp_path):
    from profidrive_cli.cli.main import cli
    raw = b"".join(bring_up(6, 0xFD06)) + req(6, bytes.fromhex("30 17 00 00 00 00 01 90 04 7F 20 00")) \
        + rep(6, bytes.fromhex("20 17 00 00 00 00 01 90 03 37 20 00"))
    f = tmp_path / "cap.raw"
    f.write_bytes(raw)
    r = CliRunner().invoke(cli, ["sniff", "--from-file", str(f), "--station", "6=moeller"])
    assert r.exit_code == 0, r.output
    # the frame lines (issue 26: a Set_Prm / Chk_Cfg / diag frame has its DU in words below it)
    from profidrive_cli.cli.sniff_view import DECODED_INDENT
    lines = [x for x in r.output.splitlines() if not x.startswith(DECODED_INDENT)]
    assert "write F002 = 4.00 s" in lines[4] and "25.00 Hz" in lines[4]
    assert "S4" in lines[5] and "F002 = 4.00 s" in lines[5]
    r = CliRunner().invoke(cli, ["sniff", "--from-file", str(f), "--station", "6=moeller", "--json"])
    objs = [json.loads(x) for x in r.output.splitlines()]
    assert all(o["event"] == "frame" for o in objs)
    assert [o.get("drive", {}).get("direction") for o in objs] == [None] * 4 + ["request", "response"]
    r = CliRunner().invoke(cli, ["sniff", "--from-file", str(f), "--live", "--json"])
    (o,) = [json.loads(x) for x in r.output.splitlines()]
    assert o["event"] == "live" and o["stations"][0]["state"] == "data exchange"
    assert o["stations"][0]["ident_hex"] == "0xFD06"
    r = CliRunner().invoke(cli, ["sniff", "--from-file", str(f), "--live"])
    assert r.exit_code == 0 and "data exchange" in r.output and "0xFD06" in r.output


def test_sniff_never_writes_to_the_port(monkeypatch):
    from profidrive_cli.cli.main import cli
    from profidrive_cli.link import serial_link
    written = []
    monkeypatch.setattr(serial_link.SerialLink, "write", lambda self, data: written.append(data))
    for extra in ([], ["--station", "3=fuji-g1"], ["--live"], ["--live", "--json"]):
        r = CliRunner().invoke(cli, ["sniff", "--port", "sim://", "--duration", "0.3", *extra])
        assert r.exit_code == 0, r.output
    assert written == []


def test_sniff_on_sim_points_to_the_plc():
    from profidrive_cli.cli.main import cli
    r = CliRunner().invoke(cli, ["sniff", "--port", "sim://", "--duration", "0.2"])
    assert r.exit_code == 0
    assert "pdrive sim --plc --pty" in r.output


def test_sniff_sends_nothing_down_a_real_byte_path(socat_pair):
    # sniff listens on one end of a pty pair; not one octet may come out of the other end
    import os
    import select
    import subprocess
    import time

    from conftest import pdrive_cmd
    a, b = socat_pair
    fd = os.open(b, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        p = subprocess.Popen(pdrive_cmd() + ["sniff", "--port", a, "--duration", "1.5", "--live",
                                             "--station", "3=fuji-g1"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        got = b""
        end = time.monotonic() + 20
        while p.poll() is None and time.monotonic() < end:
            r, _, _ = select.select([fd], [], [], 0.1)
            if r:
                got += os.read(fd, 4096)
        p.wait(timeout=10)
        assert p.returncode == 0, p.stderr.read()
        assert got == b""
    finally:
        os.close(fd)
