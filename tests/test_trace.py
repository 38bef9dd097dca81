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
    p = _pdrive("scan", "--port", "sim://?stations=3:fuji-g1", "--to", "4", "--trace", str(path))
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
