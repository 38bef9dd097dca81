"""-v / -vv logging and --trace FILE.pcap on bus commands."""

import logging
import os
import subprocess
import sys
import time

from profidrive_cli.dp.capture import LINKTYPE_USER0, read_pcap


def _pdrive(*args):
    return subprocess.run([sys.executable, "-m", "profidrive_cli", *args], capture_output=True,
                          text=True, stdin=subprocess.DEVNULL, timeout=120)


def test_vv_shows_every_telegram_of_diag():
    p = _pdrive("diag", "3", "--port", "sim://?stations=3:fuji-g1", "-vv")
    assert p.returncode == 0, p.stderr
    lines = [ln for ln in p.stderr.splitlines() if " -> SD" in ln or " <- SD" in ln]
    # diag = Slave_Diag request + reply, Get_Cfg request + reply (reference §3: SAP 60 and 59)
    assert len(lines) == 4, p.stderr
    assert "-> SD2" in lines[0] and "[62->60]" in lines[0] and "Slave_Diag" in lines[0]
    assert "<- SD" in lines[1] and "Slave_Diag reply" in lines[1]
    assert "[62->59]" in lines[2] and "Get_Cfg" in lines[2]
    assert "Get_Cfg reply" in lines[3] and lines[3].rstrip().endswith("f3 f1")
    # stdout is the command's output alone
    assert "-> SD" not in p.stdout


def test_v_shows_service_steps_not_telegrams():
    p = _pdrive("status", "3", "--port", "sim://?stations=3:fuji-g1", "-v")
    assert p.returncode == 0, p.stderr
    assert "station 3: sending parameters" in p.stderr
    assert "station 3: data exchange" in p.stderr
    assert " -> SD" not in p.stderr


def test_no_v_no_log():
    p = _pdrive("status", "3", "--port", "sim://?stations=3:fuji-g1")
    assert p.returncode == 0
    assert "sending parameters" not in p.stderr


def test_trace_pcap_records_the_scan_with_wall_clock_times(tmp_path):
    path = tmp_path / "scan.pcap"
    t0 = time.time()
    # --quick: one pass, one FDL status per address (the full scan's second pass is checked below)
    p = _pdrive("scan", "--port", "sim://?stations=3:fuji-g1", "--to", "4", "--quick", "--trace", str(path))
    assert p.returncode == 0, p.stderr
    linktype, pkts = read_pcap(path.read_bytes())
    assert linktype == LINKTYPE_USER0       # 147: the link type the shipped Wireshark dissector binds
    raws = [r for _, r in pkts]
    # FDL status to address 0 from master 2: SD1 DA SA FC=0x49 FCS ED (FCS = 0x00+0x02+0x49)
    assert raws[0] == bytes.fromhex("10 00 02 49 4B 16")
    # to station 3 and its reply; nothing answers at 0, 1 and 4 (one attempt each, no retry)
    assert bytes.fromhex("10 03 02 49 4E 16") in raws
    fdl_status_reqs = [r for r in raws if r[0] == 0x10 and r[3] == 0x49]
    assert [r[1] for r in fdl_status_reqs] == [0, 1, 3, 4]
    assert all(t0 - 5 <= t <= time.time() + 5 for t, _ in pkts)
    assert sorted(os.listdir(tmp_path)) == ["scan.pcap"]


def test_trace_pcap_records_the_scans_warm_up_pass(tmp_path):
    # without --quick: the same first pass, then a second pass over the silent addresses, and more
    # passes over those asked before the line carried 10 telegrams (dp/scan.py WAKE_TELEGRAMS; a
    # slave in baud-rate search, issues 26 and 38). By hand: the quick pass asks 0, 1, 3, 4 (after
    # 0..3 telegrams); 0, 1, 4 are silent and asked after 4, 5, 6, again after 7, 8, 9, and once
    # more after 10, 11, 12: then each has been asked after 10 telegrams or more.
    path = tmp_path / "scan.pcap"
    p = _pdrive("scan", "--port", "sim://?stations=3:fuji-g1", "--to", "4", "--trace", str(path))
    assert p.returncode == 0, p.stderr
    _, pkts = read_pcap(path.read_bytes())
    fdl_status_reqs = [r for _, r in pkts if r[0] == 0x10 and r[3] == 0x49]
    assert [r[1] for r in fdl_status_reqs] == [0, 1, 3, 4] + [0, 1, 4] * 3


def test_trace_to_missing_directory_is_one_line_exit_2(tmp_path):
    p = _pdrive("scan", "--port", "sim://", "--trace", str(tmp_path / "no" / "x.pcap"))
    assert p.returncode == 2
    assert len(p.stderr.strip().splitlines()) == 1 and "does not exist" in p.stderr
    assert not (tmp_path / "no").exists()


def test_library_user_configures_the_logger():
    """The trace goes through Python logging: a library user gets it with a handler of their own."""
    from profidrive_cli.dp.poller import Master
    from profidrive_cli.dp.trace import TraceLink
    from profidrive_cli.fdl.timing import BusParams
    from profidrive_cli.link import open_link
    records = []

    class H(logging.Handler):
        def emit(self, r):
            records.append(r.getMessage())
    lg = logging.getLogger("profidrive_cli.trace")
    h = H()
    lg.addHandler(h)
    old = lg.level
    lg.setLevel(logging.DEBUG)
    try:
        m = Master(TraceLink(open_link("sim://?stations=3:fuji-g1")), BusParams.for_baud(19200))
        assert m.fdl_status(3) is not None
        m.link.close()
    finally:
        lg.removeHandler(h)
        lg.setLevel(old)
    assert len(records) == 2 and "FDL status" in records[0] and "<-" in records[1]


def test_v_shows_retries_on_a_lossy_bus():
    # every reply of station 3 is dropped: each request is one try + 1 retry (sim default), logged
    p = _pdrive("diag", "3", "--port", "sim://?stations=3:fuji-g1&drop=1.0", "-v")
    assert p.returncode == 1
    assert "station 3: retry (no valid reply in time)" in p.stderr
    assert "station 3: no valid reply after 1 retry" in p.stderr


class _FailingRecorder:
    """A recorder that raises OSError(ENOSPC) after `n` frames (a full disk under --trace)."""

    def __init__(self, n):
        self.n, self.frames = n, []

    def write(self, t, raw):
        import errno
        if len(self.frames) >= self.n:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self.frames.append(raw)


def test_a_recorder_that_raises_never_breaks_an_exchange():
    """The recorder sits in the link's write and read path: its failure is kept, the telegrams go
    on (and the poller's exchanges with them)."""
    from profidrive_cli.dp.poller import Master
    from profidrive_cli.dp.station import SlaveConfig
    from profidrive_cli.dp.trace import TraceLink
    from profidrive_cli.fdl.timing import BusParams
    from profidrive_cli.link import open_link
    rec = _FailingRecorder(3)
    link = TraceLink(open_link("sim://?stations=3:fuji-g1"), rec)
    m = Master(link, BusParams.for_baud(19200))
    try:
        m.add_station(3, SlaveConfig(ident=0xFD01, cfg=bytes.fromhex("F3F1"), wd_ms=500))
        m.bring_up(3)                   # Slave_Diag, Set_Prm, Chk_Cfg, Slave_Diag: 8 telegrams
        for _ in range(5):
            m.exchange(3, bytes(12))
        assert m.stations[3].in_data_exchange
    finally:
        link.close()
    assert len(rec.frames) == 3
    assert isinstance(link.recorder_error, OSError) and link.recorder is None
    assert link.sent >= 9 and link.received >= 9       # every telegram still decoded and counted


def test_checklist_run_records_its_trace(tmp_path):
    """checklist run accepted --trace and wrote nothing; now the pcap has the run's telegrams."""
    ex = os.path.join(os.path.dirname(__file__), "..", "examples", "checklists", "moeller.yaml")
    path = tmp_path / "cl.pcap"
    p = _pdrive("checklist", "run", ex, "--yes", "--cycle-hz", "200", "--var", "accel_s=1",
                "--var", "decel_s=1", "--var", "hold_s=0.2", "--trace", str(path))
    assert p.returncode == 0, p.stderr
    _, pkts = read_pcap(path.read_bytes())
    # Set_Prm to station 6 (the checklist's Moeller) from master 2: SD2, DA 6 | 0x80, SA 2 | 0x80,
    # DSAP 61, SSAP 62 (reference §3: SAP 61 = Set_Prm, 62 = the master's)
    assert any(r[0] == 0x68 and r[4] == 0x86 and r[5] == 0x82 and r[7] == 61 and r[8] == 62
               for _, r in pkts)
    assert len(pkts) > 100                              # and the cycles of its run steps
    assert sorted(os.listdir(tmp_path)) == ["cl.pcap"]


def test_doctor_refuses_trace_before_opening_the_port(tmp_path):
    """doctor tests the port with raw octets, never DP telegrams through a master: --trace would
    write nothing, so it is refused (exit 2, one line, no file) instead of accepted silently."""
    path = tmp_path / "d.pcap"
    p = _pdrive("doctor", "--port", str(tmp_path / "no-such-port"), "--trace", str(path))
    assert p.returncode == 2, p.stderr
    assert len(p.stderr.strip().splitlines()) == 1 and "--trace" in p.stderr
    assert "no such port" not in p.stderr               # refused before the port was tried
    assert os.listdir(tmp_path) == []
