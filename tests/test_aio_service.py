"""The asyncio face under a service manager (issue 34): the documented service (docs/api.md, "A
service: aio.run and systemd") stopped by SIGTERM exits 143 and by SIGINT 130, without a traceback,
its drive stopped; a cancelled run says its stop through on_message; a keep-alive that falls behind
its station's watchdog is seen (a warning at once, the drive's next call raising)."""

from __future__ import annotations

import asyncio
import logging
import os
import queue
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

import profidrive_cli as pdrive
from profidrive_cli import aio

ROOT = Path(__file__).resolve().parent.parent

#: the tests must not see the developer's own config files or PDRIVE_* settings
pytestmark = pytest.mark.usefixtures("no_config_at_all")

#: a child's whole life: start-up, the run to 10 Hz (1 s at F07 = 6.0 s per 60 Hz, the Fuji
#: factory value), the stop (1 s at F08 = 6.0 s) -- seconds at rest, far more at load 20
CHILD_S = 180


def _service_script() -> str:
    """The service file of docs/api.md (the ```python service.py block), as documented."""
    text = (ROOT / "docs" / "api.md").read_text(encoding="utf-8")
    [code] = re.findall(r"^```python service\.py\n(.*?)^```", text, flags=re.S | re.M)
    assert "pdrive.aio.run(main())" in code
    return code


def _run_and_signal(tmp_path: Path, signum: int) -> tuple[int, str, str]:
    """Start the documented service, wait for its "running" line, send `signum`; its exit code and
    its output."""
    script = tmp_path / "service.py"
    script.write_text(_service_script())
    env = {k: v for k, v in os.environ.items() if not k.startswith("PDRIVE_")}
    env["PYTHONPATH"] = str(ROOT)
    p = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path)
    try:
        assert p.stdout is not None
        lines = []
        for line in p.stdout:               # ends at EOF when the child dies first
            lines.append(line)
            if line.strip() == "running":
                break
        if not lines or lines[-1].strip() != "running":
            p.kill()
            rest, err = p.communicate(timeout=CHILD_S)
            pytest.fail("no 'running' line:\n" + "".join(lines) + rest + err)
        p.send_signal(signum)
        out, err = p.communicate(timeout=CHILD_S)
    finally:
        if p.poll() is None:
            p.kill()
            p.communicate()
    return p.returncode, "".join(lines) + out, err


@pytest.mark.skipif(os.name != "posix", reason="signals to a child process")
@pytest.mark.parametrize("signum,code", [
    (signal.SIGTERM, 143),              # 128 + 15, as the pdrive commands exit after SIGTERM
    (signal.SIGINT, 130),               # 128 + 2, after Ctrl-C
])
def test_the_documented_service_stops_its_drive_and_exits_128_plus_the_signal(
        tmp_path: Path, signum: int, code: int) -> None:
    rc, out, err = _run_and_signal(tmp_path, signum)
    assert "Traceback" not in err, err
    assert rc == code, (rc, out, err)
    # the safe stop on the way out of `async with` (on_message=print): from 10 Hz, a normal stop
    assert re.search(r"^station 3: stopped \(normal stop, [0-9.]+ s\)$", out, re.M), out + err


def test_aio_run_without_a_signal_returns_what_main_returns() -> None:
    async def main() -> int:
        await asyncio.sleep(0)
        return 7
    assert aio.run(main()) == 7


def test_aio_run_without_a_signal_raises_what_main_raises() -> None:
    async def main() -> None:
        raise pdrive.UsageError("bad")
    with pytest.raises(pdrive.UsageError, match="bad"):
        aio.run(main())


@pytest.mark.skipif(os.name != "posix", reason="SIGTERM")
def test_under_aio_run_the_bus_leaves_the_signals_to_it_and_a_caught_cancel_still_exits_143() -> None:
    """In process: SIGTERM while main sleeps inside the bus; main catches the CancelledError and
    returns, the exit is still 143; the bus installed no SIGTERM handler of its own; the handler
    from before aio.run is back afterwards."""
    assert threading.current_thread() is threading.main_thread()
    hit: list[str] = []
    seen: list[str] = []

    def safety(*a: object) -> None:
        hit.append("safety net")
    before = signal.signal(signal.SIGTERM, safety)
    try:
        async def main() -> str:
            try:
                async with aio.open_bus("sim://?timing=virtual", on_message=seen.append) as bus:
                    assert bus._sigterm_task is None        # aio.run's, not the bus's
                    drive = await bus.drive(3)
                    await drive.run(hz=10, wait=True, timeout=30)
                    os.kill(os.getpid(), signal.SIGTERM)
                    await asyncio.sleep(30)                 # cancelled by the SIGTERM long before
            except asyncio.CancelledError:
                return "caught"
            return "not cancelled"
        with pytest.raises(SystemExit) as e:
            aio.run(main())
        assert e.value.code == 143
        assert hit == []
        assert signal.getsignal(signal.SIGTERM) is safety
        assert any(re.match(r"station 3: stopped \(normal stop, [0-9.]+ s\)$", m) for m in seen), seen
    finally:
        signal.signal(signal.SIGTERM, before)


def test_a_cancelled_run_says_its_stop_through_on_message() -> None:
    """The run of station 3 to 40 Hz takes 40 s at F07 = 60 s (set here; 0.1 s steps,
    fuji-opc-g1-pdp.yaml), so the run cancelled 0.3 s after it began is still waiting. Its
    CancelledError carries no StopResult: the stop's line comes through on_message, in the words
    of the stop on close."""
    seen: list[str] = []

    async def main() -> None:
        async with aio.open_bus("sim://", on_message=seen.append) as bus:
            drive = await bus.drive(3)
            await drive.set_param("F07", 60.0)
            task = asyncio.create_task(drive.run(hz=40, wait=True, timeout=120))
            await asyncio.sleep(0.3)
            task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task
            n = len(seen)
            assert (await drive.status()).stopped
            assert len(seen) == n                   # said once, by the stop itself
    asyncio.run(main())
    assert any(re.match(r"station 3: stopped \(normal stop, [0-9.]+ s\)$", m) for m in seen), seen


# -- the keep-alive that falls behind ------------------------------------------------------------

def _wait_for(pred, what: str, limit_s: float = 60.0) -> None:
    """Real time for the keep-alive thread (it wakes every 50 ms): generous for load 20."""
    end = time.monotonic() + limit_s
    while not pred():
        if time.monotonic() > end:
            pytest.fail(f"not seen within {limit_s:g} s: {what}")
        time.sleep(0.02)


@pytest.mark.parametrize("stall_s", [2.0])
def test_a_keep_alive_late_past_the_watchdog_warns_and_the_next_call_raises(
        stall_s: float, caplog: pytest.LogCaptureFixture) -> None:
    """The keep-alive thread stalled deterministically: the bus's virtual clock jumps `stall_s`
    (2 s) while nothing is sent -- as a thread that got no CPU or GIL for 2 s sees it. Station 3
    (DP watchdog 1 s, the API default) then had no Data_Exchange for 2 s: its watchdog ran out and
    the Fuji card, running, reacted with o27 = 0 (factory): coast and trip Er5 (OPC-G1-PDP; sim/fuji.py).
    The keep-alive's next pass must say so at once, and the drive's next call raise."""
    seen: list[str] = []
    caplog.set_level(logging.WARNING, logger="profidrive_cli.api")
    with pdrive.open_bus("sim://?timing=virtual", on_message=seen.append) as bus:
        drive = bus.drive(3)
        assert drive._station.watchdog_ms == 1000
        drive.run(hz=10, wait=True, timeout=30)
        with bus._lock:                               # no call and no keep-alive meanwhile
            bus.master.link.sleep(stall_s)
        _wait_for(lambda: any("fell behind" in m for m in seen), "the keep-alive's warning")
        [line] = [m for m in seen if "fell behind" in m]
        # the gap: the stall plus at most the keep period before it (0.1 s, KEEP_S)
        m = re.match(r"warning: station 3: the keep-alive fell behind by ([0-9.]+) s against a "
                     r"watchdog of 1 s; the station had left data exchange", line)
        assert m and stall_s <= float(m.group(1)) <= stall_s + 0.1 + 0.05, line
        assert any("fell behind" in r.getMessage() for r in caplog.records)
        assert any("fell behind" in w for w in drive.warnings)
        with pytest.raises(pdrive.DriveError, match=r"station 3: the keep-alive fell behind by "
                                                    r"[0-9.]+ s against a watchdog of 1 s"):
            drive.status()
        st = drive.status()                           # once: the next call works, and shows it
        assert st.fault and st.fault_code == "Er5", st


def test_the_master_keeping_a_station_while_it_brings_up_others_is_no_miss() -> None:
    """Stations 4..7 brought up one after the other at 9.6 kbit/s while station 3 runs: 3.4 s on
    the bus's virtual clock in which no call and no keep-alive pass exchanges with station 3 --
    the master keeps it (dp.poller.Master.keep: a quarter of its 1 s watchdog at the latest). Its
    watchdog was never at risk: no warning, and its next call answers."""
    seen: list[str] = []
    with pdrive.open_bus("sim://?timing=virtual", baud="9600", on_message=seen.append) as bus:
        d3 = bus.drive(3)
        d3.run(hz=10, wait=True, timeout=30)
        t0 = bus.master.link.now()
        for a in (4, 5, 6, 7):
            bus.drive(a)
        assert bus.master.link.now() - t0 > 1.0                # longer than the watchdog
        time.sleep(0.3)                                       # keep-alive passes (every 50 ms)
        assert d3.status().running
        assert bus.master.link.bus.slave(3).stats["watchdog_expired"] == 0
    assert not [m for m in seen if "keep-alive" in m], seen


@pytest.mark.skipif(os.name != "posix", reason="SIGTERM")
def test_under_aio_run_a_second_signal_turns_the_stop_into_a_coast_stop() -> None:
    """Station 3 at 20 Hz with F08 = 60 s (deceleration time 1, fuji-opc-g1-pdp.yaml; 0.1 s steps):
    its normal stop would take 20 s. A second SIGTERM once the bus's stop began (the sync bus is
    closing) hurries it: a coast stop, said through on_message; exit 143 all the same."""
    assert threading.current_thread() is threading.main_thread()
    seen: list[str] = []
    late: list[int] = []
    # a safety net: a signal after aio.run put the handlers back must not end the test run
    before = signal.signal(signal.SIGTERM, lambda signum, frame: late.append(signum))
    try:
        async def main() -> None:
            async with aio.open_bus("sim://", on_message=seen.append) as bus:
                drive = await bus.drive(3)
                await drive.set_param("F07", 0.5)
                await drive.set_param("F08", 60.0)
                await drive.run(hz=20, wait=True, timeout=60)
                sync = bus.sync

                def second() -> None:
                    end = time.monotonic() + 60
                    while not sync.closed and time.monotonic() < end:
                        time.sleep(0.005)
                    os.kill(os.getpid(), signal.SIGTERM)
                threading.Thread(target=second, daemon=True).start()
                os.kill(os.getpid(), signal.SIGTERM)
                await asyncio.sleep(60)
        with pytest.raises(SystemExit) as e:
            aio.run(main())
        assert e.value.code == 143
        assert any(re.match(r"station 3: stopped by a coast stop after [0-9.]+ s \(.*second signal",
                            m) for m in seen), seen
        assert late == []
    finally:
        signal.signal(signal.SIGTERM, before)


STALLED = """\
import asyncio, sys
import profidrive_cli as pdrive


async def main():
    async with pdrive.aio.open_bus("sim://", on_message=lambda t: print(t, flush=True)) as bus:
        drive = await bus.drive(3)
        await drive.run(hz=10, wait=True, timeout=60)
        print("running", flush=True)
        await asyncio.to_thread(sys.stdin.readline)      # the test's go, after the stall
        try:
            await drive.status()
            print("no error", flush=True)
        except pdrive.DriveError as e:
            print("raised:", e, flush=True)
        print("fault:", (await drive.status()).fault_code, flush=True)

pdrive.aio.run(main())
"""


@pytest.mark.skipif(not hasattr(signal, "SIGSTOP"), reason="SIGSTOP")
def test_a_process_stopped_past_the_watchdog_is_told_when_it_goes_on(tmp_path: Path) -> None:
    """A real stall: the whole asyncio process stopped (SIGSTOP) for 3 s, three times its station's
    1 s watchdog (API default), the simulated plant in it included -- whose clock (monotonic) goes
    on, so its station 3 finds its watchdog run out at the next request: Er5 (o27 = 0, factory:
    coast and trip). Continued, the keep-alive's next pass says so at once; the sleeping script's
    next call raises."""
    script = tmp_path / "stalled.py"
    script.write_text(STALLED)
    env = {k: v for k, v in os.environ.items() if not k.startswith("PDRIVE_")}
    env["PYTHONPATH"] = str(ROOT)
    p = subprocess.Popen([sys.executable, str(script)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path)
    lines: list[str] = []
    try:
        assert p.stdout is not None and p.stdin is not None
        for line in p.stdout:
            lines.append(line)
            if line.strip() == "running":
                break
        assert lines and lines[-1].strip() == "running", "".join(lines)
        p.send_signal(signal.SIGSTOP)
        time.sleep(3.0)
        p.send_signal(signal.SIGCONT)
        # the warning comes before any go (a reader thread: without the warning, go after a bound)
        got: queue.Queue[str] = queue.Queue()
        reader = threading.Thread(target=lambda: [got.put(x) for x in p.stdout or ()], daemon=True)
        reader.start()
        end = time.monotonic() + 60
        while time.monotonic() < end and not any("fell behind" in x for x in lines):
            try:
                lines.append(got.get(timeout=0.5))
            except queue.Empty:
                pass
        p.stdin.write("go\n")
        p.stdin.flush()
        p.stdin.close()
        p.wait(timeout=CHILD_S)
        err = p.stderr.read() if p.stderr else ""
        reader.join(timeout=CHILD_S)
        out = "".join(got.queue)
    finally:
        if p.poll() is None:
            p.kill()
            p.communicate()
    text = "".join(lines) + out
    m = re.search(r"^warning: station 3: the keep-alive fell behind by ([0-9.]+) s against a "
                  r"watchdog of 1 s; the station had left data exchange", text, re.M)
    assert m and float(m.group(1)) >= 3.0, text + err
    assert re.search(r"^raised: station 3: the keep-alive fell behind by [0-9.]+ s", text, re.M), text
    assert "fault: Er5" in text and p.returncode == 0 and "Traceback" not in err, text + err
