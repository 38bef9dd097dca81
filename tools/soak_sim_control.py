"""Soak `pdrive sim --listen --control` (issue 35): the simulator with its control port, for a stretch of
wall time, under slow clients, idle clients, bad bodies, clients that leave early and fault commands,
while a master asks a station for its FDL status on the bus port throughout.

At the end: every bus request answered (the longest gap between two answers), the simulator's RSS
(/proc/PID/status VmRSS) after a warm-up and at the end, its stderr (no traceback), its counters.

    python tools/soak_sim_control.py                   # 600 s (PDRIVE_SOAK_S overrides), prints JSON
    PDRIVE_SOAK_S=3600 python tools/soak_sim_control.py

tests/test_sim_soak.py runs the same soak for ~30 s; tests/test_sim_server_limits.py uses its
helpers (start_sim, fdl_status, http). Linux (reads /proc); binds 127.0.0.1 only.
"""

from __future__ import annotations

import json
import os
import random
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent

#: FDL status request from master 2 to station 3 (SD1 DA SA FC FCS ED, FC 0x49 = Request FDL Status
#: with FCV=0) and the reply a passive station gives (FC 0x00: slave, OK; FCS = 2+3+0 = 5)
FDL_STATUS_3 = bytes((0x10, 3, 2, 0x49, (3 + 2 + 0x49) & 0xFF, 0x16))
FDL_STATUS_3_REPLY = bytes((0x10, 2, 3, 0x00, (2 + 3 + 0x00) & 0xFF, 0x16))

#: a command line that runs pdrive with RLIMIT_NOFILE lowered first (soft and hard) when asked
_RUN = ("import resource, sys\n"
        "n = int(sys.argv[1])\n"
        "if n: resource.setrlimit(resource.RLIMIT_NOFILE, (n, n))\n"
        "sys.argv = ['pdrive'] + sys.argv[2:]\n"
        "from profidrive_cli.cli.main import main\n"
        "main()\n")


class Sim:
    """A running `pdrive sim --listen 127.0.0.1:0 --control 127.0.0.1:0 --json`."""

    def __init__(self, nofile: int = 0, plant: str | None = None) -> None:
        env = {k: v for k, v in os.environ.items() if not k.startswith("PDRIVE_")}
        env["PYTHONPATH"] = str(ROOT)
        args = ["sim", "--listen", "127.0.0.1:0", "--control", "127.0.0.1:0", "--json"]
        if plant:
            args += ["--plant", plant]
        self.p = subprocess.Popen([sys.executable, "-c", _RUN, str(nofile), *args],
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                  stdin=subprocess.DEVNULL, text=True, env=env)
        assert self.p.stdout is not None
        line = self.p.stdout.readline()
        if not line:
            self.p.wait(timeout=60)
            raise RuntimeError(f"pdrive sim did not start: {self.p.stderr.read() if self.p.stderr else ''}")
        info = json.loads(line)
        self.info = info
        host, _, port = info["port"].removeprefix("socket://").rpartition(":")
        self.bus = (host, int(port))
        self.control = ("127.0.0.1", int(info["control"].rpartition(":")[2]))
        self.stderr = ""

    @property
    def pid(self) -> int:
        return self.p.pid

    def alive(self) -> bool:
        return self.p.poll() is None

    def rss_kib(self) -> int:
        for line in Path(f"/proc/{self.pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
        raise RuntimeError("no VmRSS")

    def stop(self) -> str:
        """Ends the simulator (SIGTERM, then SIGKILL after 30 s); its stderr."""
        if self.p.poll() is None:
            self.p.terminate()
        try:
            _, self.stderr = self.p.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            self.p.kill()
            _, self.stderr = self.p.communicate(timeout=30)
        return self.stderr


def fdl_status(bus: tuple[str, int], timeout: float = 30.0) -> bytes:
    """One FDL status request to station 3 over a fresh connection to the bus port (its reply)."""
    with socket.create_connection(bus, timeout=timeout) as s:
        return ask(s, timeout)


def ask(s: socket.socket, timeout: float) -> bytes:
    """FDL status to station 3 on a connection to the bus port: the reply octets read until a whole
    SD1 telegram (6 octets), the end of the connection, or `timeout`."""
    s.settimeout(timeout)
    s.sendall(FDL_STATUS_3)
    got = b""
    end = time.monotonic() + timeout
    while len(got) < len(FDL_STATUS_3_REPLY) and time.monotonic() < end:
        try:
            chunk = s.recv(64)
        except socket.timeout:
            break
        if not chunk:
            break
        got += chunk
    return got


def http(control: tuple[str, int], method: str, path: str, body: bytes | str | None = None,
         headers: dict[str, str] | None = None, timeout: float = 60.0) -> tuple[int, Any]:
    """(status, the JSON answer or the raw octets) of one request to the control."""
    import http.client
    c = http.client.HTTPConnection(*control, timeout=timeout)
    try:
        c.request(method, path, body=body, headers=headers or {})
        r = c.getresponse()
        raw = r.read()
    finally:
        c.close()
    try:
        return r.status, json.loads(raw)
    except ValueError:
        return r.status, raw


def leave_early(control: tuple[str, int], request: bytes) -> None:
    """Send a request and reset the connection at once, before any answer."""
    import struct
    s = socket.create_connection(control, timeout=30)
    try:
        s.sendall(request)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    finally:
        s.close()


def soak(seconds: float, seed: int = 1) -> dict[str, Any]:
    """Run the soak for `seconds` of wall time; its figures (see the module's text)."""
    rnd = random.Random(seed)
    sim = Sim()
    stop = threading.Event()
    answers: list[float] = []
    wrong: list[bytes] = []
    counts = {"slow": 0, "idle": 0, "bad": 0, "early": 0, "commands": 0, "refused": 0}
    lock = threading.Lock()

    def count(k: str) -> None:
        with lock:
            counts[k] += 1

    def master() -> None:                # one connection, like a master that stays on the line
        s: socket.socket | None = None
        while not stop.is_set():
            try:
                s = s or socket.create_connection(sim.bus, timeout=10)
                got = ask(s, 10)
            except OSError:
                got = b""
            if got == FDL_STATUS_3_REPLY:
                answers.append(time.monotonic())
            else:
                if got:
                    wrong.append(got)
                if s is not None:
                    s.close()
                    s = None
            stop.wait(0.05)
        if s is not None:
            s.close()

    def idle() -> None:                  # connect, say nothing, hold it up to 15 s
        while not stop.is_set():
            try:
                s = socket.create_connection(sim.control, timeout=10)
            except OSError:
                stop.wait(0.5)
                continue
            count("idle")
            stop.wait(rnd.uniform(1, 15))
            s.close()

    def slow() -> None:                  # a request one octet a second
        req = b"GET /state HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n"
        while not stop.is_set():
            try:
                with socket.create_connection(sim.control, timeout=20) as s:
                    for b in req:
                        if stop.wait(1.0):
                            break
                        s.sendall(bytes((b,)))
                    count("slow")
            except OSError:
                stop.wait(0.5)           # (refused: the control is full)

    def hostile() -> None:               # bad bodies, early leavers, faults, trips
        bad = [("POST", "/trip", "[" * 60000), ("POST", "/trip", "{" * 5000 + "x"),
               ("POST", "/set", "\xff\xfe not json"), ("POST", "/trip", "[1,2,3]"),
               ("POST", "/nothing", "{}")]
        while not stop.is_set():
            k = rnd.randrange(4)
            try:
                if k == 0:
                    m, p, b = rnd.choice(bad)
                    status, _ = http(sim.control, m, p, b.encode("utf-8", "surrogateescape"))
                    count("bad" if status in (400, 404) else "refused")
                elif k == 1:
                    leave_early(sim.control, b"POST /state HTTP/1.0\r\nContent-Length: 2\r\n\r\n{}")
                    count("early")
                elif k == 2:
                    spec = rnd.choice(["drop=0.2,only=5", "noise=0.1,only=6,7", ""])
                    status, _ = http(sim.control, "POST", "/faults", json.dumps({"spec": spec}))
                    count("commands" if status == 200 else "refused")
                else:
                    cmd = rnd.choice(["trip", "clear"])
                    status, _ = http(sim.control, "POST", f"/{cmd}", json.dumps({"station": 4}))
                    count("commands" if status in (200, 400) else "refused")
            except OSError:
                count("refused")
            stop.wait(0.02)

    threads = [threading.Thread(target=f, daemon=True)
               for f in [master, hostile, hostile] + [idle] * 40 + [slow] * 4]
    alive = False
    try:
        t0 = time.monotonic()
        for t in threads:
            t.start()
        warm = min(5.0, seconds / 5)
        time.sleep(warm)
        rss0 = sim.rss_kib()
        time.sleep(max(0.0, seconds - warm))
        rss1 = sim.rss_kib()
        alive = sim.alive()
    finally:
        stop.set()
        for t in threads:
            t.join(timeout=30)
        # once the clients are gone the control answers again: a client still counted full while
        # its connection winds down gets 503, so ask for 30 s at most (the read timeout is 10 s)
        final = None
        end = time.monotonic() + 30
        while alive and final != 200 and time.monotonic() < end:
            try:
                final = http(sim.control, "GET", "/state", timeout=60)[0]
            except OSError:
                final = None
            if final != 200:
                time.sleep(0.5)
        stderr = sim.stop()
    times = [t0] + answers + [t0 + seconds]
    return {"seconds": seconds, "alive": alive, "rss_kib": [rss0, rss1], "answers": len(answers),
            "wrong": [w.hex() for w in wrong[:5]], "longest_gap_s": max(b - a for a, b in zip(times, times[1:])),
            "final_state": final, "clients": counts, "stderr": stderr}


if __name__ == "__main__":
    report = soak(float(os.environ.get("PDRIVE_SOAK_S", "600")))
    print(json.dumps(report, indent=1))
    bad = (not report["alive"] or "Traceback" in report["stderr"] or report["wrong"]
           or report["rss_kib"][1] - report["rss_kib"][0] > 32 * 1024)
    sys.exit(1 if bad else 0)
