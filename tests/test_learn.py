"""Replay (issue 29): `pdrive sim --learn CAPTURE` / `sim://?learn=PATH` builds a plant whose slaves
answer as the captured ones did (sim/learn.py).

Two captures: the real ET200S start-up of pyprofibus issue #26 (../shared/testdata/external/, read from
there, never copied; its octets hand-decoded below from the .txt beside it and the bus reference
../shared/spec/profibus-dp-reference.md), and a capture made here of the simulated default plant
brought up by the built-in PLC (sim/plc.py) with one plain I/O station added, whose inputs the test
chooses (so the expected replay is known without the code under test).
"""

from __future__ import annotations

import json
import os
import subprocess
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from conftest import SHARED, pdrive_cmd, stop_pty_sim
from profidrive_cli import UsageError
from profidrive_cli.cli.main import cli
from profidrive_cli.sim.learn import InputReplay, learn, load_plans
from profidrive_cli.sim.model import SlaveModel

EXTERNAL = Path(os.environ.get("PDRIVE_EXTERNAL_TESTDATA", Path(SHARED) / "testdata" / "external"))
ET200S = EXTERNAL / "pyprofibus26-et200s-startup.raw"

# pyprofibus26-et200s-startup.txt, the Set_Prm: DU b8 1e 01 00 80 6a 01 | user data from octet 7 on
ET_USER_PRM = bytes.fromhex("40 01 00 11 21 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 20 01 00 20 08 00 20 08 00")
# the Slave_Diag replies' 29 octets of extended diagnosis: identifier block 0x49 (9 octets: 0x40 | 9),
# device block 0x14 (20 octets) starting 0x82 (txt lines 8 and 14)
ET_EXT = bytes.fromhex("49" + "00" * 8 + "14 82" + "00" * 18)
# Chk_Cfg 00 10 20: an empty slot, 0x10 = input 1 octet, 0x20 = output 1 octet (ref: identifier
# octet bits 5-4 direction 01 in / 10 out, bits 3-0 length - 1)
ET_CFG = bytes.fromhex("00 10 20")


def _need(path: Path) -> Path:
    if not path.exists():
        pytest.skip(f"{path} not present (../shared/testdata/external/)")
    return path


def _run(*args: str):
    r = CliRunner().invoke(cli, list(args))
    return r.exit_code, r.output


def _json(*args: str):
    code, text = _run(*args, "--json")
    assert code == 0, text
    return json.loads(text)


# =============================================================================================
# the ET200S of pyprofibus #26
# =============================================================================================


def test_et200s_plan_is_the_captured_station():
    (plan,) = load_plans(_need(ET200S)).values()
    assert plan.address == 5                            # SA of the replies (txt: station 5)
    assert plan.ident == 0x806A                         # diag octets 4..5: 80 6A
    assert plan.user_prm == ET_USER_PRM
    # Set_Prm station status 0xB8: Lock_Req, Sync_Req, Freeze_Req, WD_On (ref 221-225): accepted
    # (the next diagnosis has neither Prm_Fault nor Not_Supported), so Sync and Freeze are offered
    assert plan.sync and plan.freeze
    assert plan.chk_cfg == ET_CFG                       # acknowledged; next diag: no Cfg_Fault, no Prm_Req
    # the last Slave_Diag reply: st1 0x02 st2 0x0C st3 0x00 master 2 ident 0x806A + the blocks
    assert plan.diag == bytes.fromhex("02 0c 00 02 80 6a") + ET_EXT
    assert plan.get_cfg is None and plan.exchanges == []


def test_scan_and_diag_of_the_learned_et200s():
    url = f"sim://?learn={_need(ET200S)}"
    scan = _json("scan", "--port", url)
    assert [(s["station"], s["ident_hex"]) for s in scan["stations"]] == [(5, "0x806A")]
    d = _json("diag", "5", "--port", url)
    assert d["ident_hex"] == "0x806A"
    # before any Set_Prm the station answers as the ET200S did to the first Slave_Diag (txt line 8):
    # 02 05 00 FF 80 6A + the blocks -- st1 0x02 Station_Not_Ready (its Ext_Diag bit 0x08 clear, as
    # captured, though the blocks follow), st2 0x05 Prm_Req + the fixed bit 2, master none
    assert (d["diag"]["st1"], d["diag"]["st2"], d["diag"]["st3"], d["diag"]["master"]) == (0x02, 0x05, 0, None)
    assert d["diag"]["ext"] == ET_EXT.hex(" ")
    # no Get_Cfg in the capture: the accepted configuration
    assert [m["octets"] for m in d["cfg"]] == ["00", "10", "20"]


def test_the_learned_et200s_accepts_exactly_the_captured_configuration():
    url = f"sim://?learn={_need(ET200S)}"
    code, text = _run("io", "5", "--port", url, "--cfg", ET_CFG.hex(" "), "--prm", ET_USER_PRM.hex(" "),
                      "--count", "2")
    assert code == 0, text
    assert "in: 00" in text                  # 1 input octet (0x10); no Data_Exchange captured: zeros
    # another configuration (1 octet in only): Cfg_Fault, as a slave refuses modules it has not got
    code, text = _run("io", "5", "--port", url, "--cfg", "10", "--prm", ET_USER_PRM.hex(" "))
    assert code == 1, text                 # a station problem: exit 1
    # other user data of another length (none): Prm_Fault
    code, text = _run("io", "5", "--port", url, "--cfg", ET_CFG.hex(" "))
    assert code == 1, text


def test_sim_learn_serves_the_et200s_on_a_pty():
    p = subprocess.Popen(pdrive_cmd() + ["sim", "--learn", str(_need(ET200S)), "--pty", "--json"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = p.stdout.readline()
        assert line, p.stderr.read()
        head = json.loads(line)
        assert head["stations"] == [{"station": 5, "family": "learned"}]
        r = subprocess.run(pdrive_cmd() + ["diag", "5", "--port", head["port"], "--json"],
                           capture_output=True, text=True, timeout=60)
        assert r.returncode == 0, r.stderr
        d = json.loads(r.stdout)
        assert d["ident_hex"] == "0x806A" and d["diag"]["ext"] == ET_EXT.hex(" ")
    finally:
        stop_pty_sim(p)


# =============================================================================================
# bad input
# =============================================================================================


@pytest.mark.parametrize("content, ext, words", [
    (b"\x00" * 30, ".pcap", "octet 0"),                       # not a pcap: file and offset
    (bytes.fromhex("10 05 02 49 50 16") * 3, ".raw", "no slave answers"),   # FDL status requests only
])
def test_bad_captures_are_one_line_exit_2(tmp_path, content, ext, words):
    f = tmp_path / f"cap{ext}"
    f.write_bytes(content)
    r = subprocess.run(pdrive_cmd() + ["sim", "--learn", str(f), "--pty"], capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 2 and r.stdout == ""
    assert len(r.stderr.strip().splitlines()) == 1 and str(f) in r.stderr and words in r.stderr
    assert "Traceback" not in r.stderr


def test_learn_and_plant_exclude_each_other():
    r = subprocess.run(pdrive_cmd() + ["sim", "--learn", "x.raw", "--plant", "sim://", "--pty"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "exclude each other" in r.stderr and r.stdout == ""
    with pytest.raises(UsageError):
        from profidrive_cli.sim.plant import build_bus
        build_bus(f"sim://?learn={ET200S}&stations=3:fuji-g1")


# =============================================================================================
# the inputs' replay (hand-made rows)
# =============================================================================================


def test_replay_keyed_where_outputs_repeat_and_decide_the_inputs():
    # an echo: outputs 01 -> inputs 11, 02 -> 12, each seen twice
    rows = [(0.0, b"\x01", b"\x11"), (0.1, b"\x02", b"\x12"), (0.2, b"\x01", b"\x11"), (0.3, b"\x02", b"\x12")]
    r = InputReplay(rows, 1)
    assert r.mode == "keyed"
    assert [r.answer(o, 5.0) for o in (b"\x02", b"\x02", b"\x01")] == [b"\x12", b"\x12", b"\x11"]


def test_replay_in_order_looping_on_the_captures_clock():
    # outputs constant, inputs changing: not a function of the outputs -> in order, on the capture's
    # clock: 0.0 s a0, 1.0 s a1, 2.0 s a2; period 3 s (span 2 s + one mean interval 1 s)
    rows = [(10.0, b"\x00", b"\xa0"), (11.0, b"\x00", b"\xa1"), (12.0, b"\x00", b"\xa2")]
    r = InputReplay(rows, 1)
    assert r.mode == "in order" and r.timed
    got = [r.answer(b"\x00", 100.0 + t) for t in (0.0, 0.5, 1.2, 2.9, 3.1, 4.5)]
    assert got == [b"\xa0", b"\xa0", b"\xa1", b"\xa2", b"\xa0", b"\xa1"]


def test_replay_without_times_is_one_per_exchange():
    rows = [(7.0, b"\x00", b"\xa0"), (7.0, b"\x00", b"\xa1")]       # a raw file: one time for all
    r = InputReplay(rows, 1)
    assert not r.timed
    assert [r.answer(b"\x00", t) for t in (0.0, 0.0, 0.0)] == [b"\xa0", b"\xa1", b"\xa0"]


def test_learn_pairs_replies_with_requests_only():
    # station 9 answers FDL status; a reply from 8 to nobody's request is not learnt
    req = bytes.fromhex("10 09 02 49 54 16")      # SD1 DA 9 SA 2 FC 0x49 FCS 0x54
    rep = bytes.fromhex("10 02 09 00 0b 16")      # SD1 DA 2 SA 9 FC 0x00 FCS 0x0B
    stray = bytes.fromhex("10 02 08 00 0a 16")
    plans = learn([(0.0, req), (0.001, rep), (0.002, stray)])
    assert list(plans) == [9] and plans[9].answers == 1 and plans[9].ident is None


# =============================================================================================
# a capture of the simulated default plant, run by the built-in PLC
# =============================================================================================

IO_ADDR, IO_IDENT = 9, 0x1234
IO_CFG = bytes.fromhex("11 21")        # 0x11: input, 2 octets; 0x21: output, 2 octets (ref bits 5-4, 3-0)


class _Counter(SlaveModel):
    """A plain I/O station for the capture: inputs k, 0xA5 on its k-th Data_Exchange."""

    def __init__(self):
        super().__init__(IO_IDENT, {"io": IO_CFG}, name="io")
        self.k = 0

    def data_exchange(self, outputs, now):
        self.k = (self.k + 1) % 256
        return bytes((self.k, 0xA5))


@pytest.fixture(scope="module")
def plc_capture(tmp_path_factory):
    """The default plant plus station 9 brought up by sim/plc.py's master, 40 cycles, every octet
    through the PLC's tap into a raw file; and `pdrive sniff --from-file RAW --pcap` of it."""
    from profidrive_cli.dp.station import SlaveConfig
    from profidrive_cli.sim.bus import SimBus
    from profidrive_cli.sim.plant import build_bus
    from profidrive_cli.sim.plc import Plc
    from profidrive_cli.sim.slave import SimSlave
    plant = build_bus("sim://")
    bus = SimBus(list(plant.slaves.values()) + [SimSlave(IO_ADDR, _Counter())])
    octets = bytearray()
    plc = Plc(bus, tap=octets.extend)
    plc.bring_up()
    plc.master.add_station(IO_ADDR, SlaveConfig(ident=IO_IDENT, cfg=IO_CFG, user_prm=b"", wd_ms=2000))
    plc.master.bring_up(IO_ADDR, timeout=3.0)
    try:
        for i in range(40):
            plc.cycle()
            plc.master.exchange(IO_ADDR, bytes((i % 7, 0)))
    finally:
        plc.shutdown()
        plc.master.release(IO_ADDR)
    d = tmp_path_factory.mktemp("learn")
    raw = d / "plant.raw"
    raw.write_bytes(bytes(octets))
    pcap = d / "plant.pcap"
    r = subprocess.run(pdrive_cmd() + ["sniff", "--from-file", str(raw), "--pcap", str(pcap)],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return raw, pcap


#: the default plant (docs/architecture.md "Families"): address -> ident
PLANT_IDENTS = {3: "0xFD01", 4: "0xFD02", 5: "0x0BE7", 6: "0xFD06", 7: "0x00CA"}


def _stations(url):
    return {s["station"]: s["ident_hex"] for s in _json("scan", "--port", url)["stations"]}


def _get_cfgs(url, addrs):
    return {a: [m["octets"] for m in _json("diag", str(a), "--port", url)["cfg"]] for a in addrs}


@pytest.mark.parametrize("which", [0, 1], ids=["raw", "pcap"])
def test_learned_plant_scans_as_the_captured_one(plc_capture, which):
    url = f"sim://?learn={plc_capture[which]}"
    assert _stations(url) == {**PLANT_IDENTS, IO_ADDR: f"0x{IO_IDENT:04X}"}
    # the same Get_Cfg as the plant the capture was made of (its default layouts: the PLC configures
    # each drive with the layout its Get_Cfg reports) and, for station 9, the captured Chk_Cfg
    want = _get_cfgs("sim://", list(PLANT_IDENTS))
    want[IO_ADDR] = ["11", "21"]
    assert _get_cfgs(url, list(want)) == want


def test_drive_stations_get_their_drive_models_the_io_station_replays(plc_capture):
    plans = load_plans(plc_capture[0])
    from profidrive_cli.sim.learn import learned_slaves
    from profidrive_cli.sim.plant import make_model
    fam = {s.address: s.model.family for s in learned_slaves(plans, make_model)}
    assert fam[IO_ADDR] == "learned"
    assert all(fam[a] != "learned" for a in PLANT_IDENTS)
    # the captured inputs of station 9: (k, A5) for its k-th Data_Exchange, k = 1, 2, ... (the
    # master's bring-up may have exchanged before the 40 cycles: the run starts at the first one)
    ins = [i for _, _, i in plans[IO_ADDR].exchanges]
    assert len(ins) >= 40 and all(i[1] == 0xA5 for i in ins)
    assert [i[0] for i in ins] == list(range(1, len(ins) + 1))


def test_io_on_the_learned_io_station_replays_the_captured_inputs(plc_capture):
    url = f"sim://?learn={plc_capture[0]}"
    code, text = _run("io", str(IO_ADDR), "--port", url, "--cfg", "11 21", "--count", "5", "--json")
    assert code == 0, text
    got = [bytes.fromhex(json.loads(line)["inputs"]) for line in text.splitlines()
           if line.startswith("{") and '"cycle"' in line]
    assert len(got) == 5
    # a raw capture has no times: one captured reply per Data_Exchange, in order (k, A5), k
    # consecutive (io's bring-up may take the first ones)
    ks = [g[0] for g in got]
    assert all(g[1] == 0xA5 for g in got) and ks == list(range(ks[0], ks[0] + 5))


def _opened(pid: int, path: str) -> bool:
    fds = f"/proc/{pid}/fd"
    try:
        return any(os.path.realpath(os.path.join(fds, fd)) == path for fd in os.listdir(fds))
    except OSError:
        return False


def test_sim_learn_of_a_pcap_sniffed_from_sim_plc(socat_pair, tmp_path):
    """`pdrive sniff --pcap` on one end of a pty pair, then `pdrive sim --plc --port` on the other
    (so the capture holds the PLC's bring-up), then the learned plant of that pcap: the default
    plant's stations and idents."""
    if not os.path.isdir("/proc/self/fd"):
        pytest.skip("needs /proc to see when sniff has opened its port")
    a, b = socat_pair
    pcap = tmp_path / "live.pcap"
    sniff = subprocess.Popen(pdrive_cmd() + ["sniff", "--port", b, "--duration", "600", "--pcap", str(pcap)],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    sim = None
    try:
        target = os.path.realpath(b)
        deadline = time.monotonic() + 120
        while not _opened(sniff.pid, target):        # sniff empties the port's buffer once opened
            assert sniff.poll() is None and time.monotonic() < deadline, sniff.stderr.read()
            time.sleep(0.05)
        time.sleep(0.5)
        sim = subprocess.Popen(pdrive_cmd() + ["sim", "--plc", "--port", a, "--json"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        assert json.loads(sim.stdout.readline())["plc"] is True
        # the bring-up at 19.2k: per station Set_Prm, Chk_Cfg, Slave_Diag and their replies, about 90
        # octets x 11 bit / 19200 bit/s = 52 ms, 0.26 s for five: 6 s leaves 20 times that
        time.sleep(6.0)
    finally:
        stop_pty_sim(sniff)      # SIGINT: sniff ends well and writes its pcap
        if sim is not None:
            stop_pty_sim(sim)
    assert sniff.returncode == 0, sniff.stderr.read()
    assert _stations(f"sim://?learn={pcap}") == PLANT_IDENTS


def test_the_builtin_plc_runs_the_learned_plant(plc_capture):
    """`sim --learn … --plc`: the PLC (sim/plc.py) brings up the learnt drive stations and cycles
    them; the learnt plain station it leaves alone (no drive profile), as on any plant."""
    from profidrive_cli.sim.plant import build_bus
    from profidrive_cli.sim.plc import Plc
    bus = build_bus(f"sim://?learn={plc_capture[0]}")
    plc = Plc(bus)
    try:
        plc.bring_up()
        assert sorted(plc.plans) == sorted(PLANT_IDENTS)
        for _ in range(3):
            plc.cycle()
        assert all(bus.slaves[a].stats["data_exchange"] >= 3 for a in PLANT_IDENTS)
    finally:
        plc.shutdown()
