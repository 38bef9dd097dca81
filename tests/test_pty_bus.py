"""A real serial path: pdrive sim on one end of a pty, a master on the other (pdrive or not)."""

import json
import os
import signal
import subprocess
import time

import pytest
import serial

from conftest import like_hardware, pdrive_cmd


def _start_sim(args):
    p = subprocess.Popen(pdrive_cmd() + ["sim", "--json"] + args, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, preexec_fn=like_hardware)
    line = p.stdout.readline()
    if not line:
        p.kill()
        pytest.fail("pdrive sim printed nothing: " + p.stderr.read())
    return p, json.loads(line)


def _stop(p):
    p.send_signal(signal.SIGINT)
    try:
        return p.wait(timeout=10)
    except subprocess.TimeoutExpired:
        p.kill()
        raise


def test_scan_through_socat_pty_pair(socat_pair):
    a, b = socat_pair
    sim, info = _start_sim(["--port", a])
    try:
        # the default plant (sim/plant.py); the sim names a station by its profile or an alias
        from profidrive_cli.drives.profile import load_profile
        assert {s["station"]: load_profile(s["family"]).name for s in info["stations"]} == {
            3: "fuji-opc-g1-pdp", 4: "fuji-opc-pdp3", 5: "toyo-pbus66z",
            6: "moeller-de6-net-dp", 7: "yaskawa-si-p1"}
        r = subprocess.run(pdrive_cmd() + ["scan", "--port", b, "--json"], capture_output=True,
                           text=True, timeout=120)
        assert r.returncode == 0, r.stderr
        got = {s["station"]: s["ident_hex"] for s in json.loads(r.stdout)["stations"]}
        assert got == {3: "0xFD01", 4: "0xFD02", 5: "0x0BE7", 6: "0xFD06", 7: "0x00CA"}
        r = subprocess.run(pdrive_cmd() + ["io", "7", "--port", b, "--cfg", "5F 6F", "--count", "2",
                                           "--json"], capture_output=True, text=True, timeout=60)
        assert r.returncode == 0, r.stderr
        assert len(r.stdout.splitlines()) == 2
    finally:
        assert _stop(sim) == 0


# -- a master that is not pdrive: hand-built standard frames ------------------------------------

def _sd2(da, sa, fc, dsap=None, ssap=None, data=b""):
    body = bytes([da | (0x80 if dsap is not None else 0), sa | (0x80 if ssap is not None else 0), fc])
    if dsap is not None:
        body += bytes([dsap, ssap])
    body += data
    return bytes([0x68, len(body), len(body), 0x68]) + body + bytes([sum(body) & 0xFF, 0x16])


def _du(r):
    """DU octets after the SAPs of an SD2 or SD3 reply with SAPs."""
    return r[9:-2] if r[0] == 0x68 else r[6:-2]


#: how long a reply may take to come back through the pty from `pdrive sim --pty`: the simulator
#: answers within min TSDR of the whole request, but on a machine at load 20 its process may not run
#: for a second or more. Generous: _read_reply returns as soon as the telegram is whole.
REPLY_TIMEOUT_S = 10.0


def _read_reply(ser, timeout=REPLY_TIMEOUT_S):
    end = time.monotonic() + timeout
    buf = b""
    while time.monotonic() < end:
        buf += ser.read(ser.in_waiting or 1)
        if buf[:1] == b"\xE5":
            return buf
        if buf[:1] == b"\x10" and len(buf) >= 6:
            return buf
        if buf[:1] == b"\x68" and len(buf) >= 4 and len(buf) >= buf[1] + 6:
            return buf
        if buf[:1] == b"\xA2" and len(buf) >= 14:
            return buf
    return buf


def test_third_party_master_reaches_data_exchange_over_pty():
    sim, info = _start_sim(["--pty"])
    try:
        ser = serial.Serial(info["port"], 19200, parity=serial.PARITY_EVEN, timeout=0.05)
        M, S = 1, 7
        # FDL status
        ser.write(bytes([0x10, S, M, 0x49, (S + M + 0x49) & 0xFF, 0x16]))
        assert _read_reply(ser) == bytes([0x10, M, S, 0x00, (M + S) & 0xFF, 0x16])
        # Slave_Diag (FCV=0, FCB=1)
        ser.write(_sd2(S, M, 0x6D, 60, 62))
        r = _read_reply(ser)
        assert _du(r) == bytes.fromhex("020500FF00CA")
        # Set_Prm: 0x88 = Lock_Req + WD_On, WD 250x4x10 ms = 10 s, min TSDR 11, ident 0x00CA,
        # group 0 (watchdog = WD_Fact_1 x WD_Fact_2 x 10 ms: shared/spec/profibus-dp-reference.md
        # L209). Each request below must come within the watchdog of the one before, or the slave
        # falls back to Wait_Prm (and answers Chk_Cfg with RS): 10 s, one REPLY_TIMEOUT_S, is more
        # than this process is ever held up between two requests (it was 100 ms: at load 20 the
        # watchdog ran out between Set_Prm and Chk_Cfg)
        ser.write(_sd2(S, M, 0x5D, 61, 62, bytes.fromhex("88FA040B00CA00")))
        assert _read_reply(ser) == b"\xE5"
        ser.write(_sd2(S, M, 0x7D, 62, 62, bytes.fromhex("5F6F")))       # Chk_Cfg Extended Data 1
        assert _read_reply(ser) == b"\xE5"
        ser.write(_sd2(S, M, 0x5D, 60, 62))
        r = _read_reply(ser)
        assert _du(r) == bytes.fromhex("000C000100CA")                  # ready, WD_On, master 1
        fcb = 0x7D
        for _ in range(3):
            ser.write(_sd2(S, M, fcb, data=bytes(32)))
            r = _read_reply(ser)
            assert r[0] == 0x68 and r[1] == 3 + 32 and (r[6] & 0x0F) == 0x08   # DL with 32 octets
            fcb ^= 0x20
        ser.close()
    finally:
        assert _stop(sim) == 0


def test_sim_listen_tcp():
    sim, info = _start_sim(["--listen", "127.0.0.1:0"])
    try:
        r = subprocess.run(pdrive_cmd() + ["scan", "--port", info["port"], "--to", "5", "--json"],
                           capture_output=True, text=True, timeout=60)
        assert r.returncode == 0, r.stderr
        assert [s["station"] for s in json.loads(r.stdout)["stations"]] == [3, 4, 5]
    finally:
        assert _stop(sim) == 0
