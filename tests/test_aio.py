"""The asyncio face (profidrive_cli.aio, docs/api.md "asyncio"): the sync API's surface as coroutines,
the loop free while the bus works, and cancellation as a safe stop -- a cancelled run(wait=True)
stops its drive, a cancelled task leaves its `async with` through the stop of every drive, SIGTERM
cancels the task that opened the bus."""

from __future__ import annotations

import asyncio
import os
import re
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import profidrive_cli as pdrive
from profidrive_cli import aio

ROOT = Path(__file__).resolve().parent.parent

#: the tests must not see the developer's own config files or PDRIVE_* settings
pytestmark = pytest.mark.usefixtures("no_config_at_all")


def _blocks() -> list[str]:
    text = (ROOT / "docs" / "api.md").read_text(encoding="utf-8")
    return [m.group(1) for m in re.finditer(r"^```python\n(.*?)^```", text, flags=re.S | re.M)
            if "aio.open_bus" in m.group(1)]


def test_the_asyncio_examples_print_what_their_comments_say(capsys: pytest.CaptureFixture[str]) -> None:
    first, cancel = _blocks()
    exec(compile(first.replace('"sim://"', '"sim://?timing=virtual"'), "docs/api.md", "exec"), {})
    out = capsys.readouterr().out.splitlines()
    # the comments of the example: the default plant 3..7, 20 Hz reached, F07 of the Fuji profile
    # (fuji-opc-g1-pdp.yaml: F07 "Acceleration time 1", factory 6.0 s), a normal stop that stopped
    assert out == ["[3, 4, 5, 6, 7]", "20 Hz", "Acceleration time 1 6.0 s", "True"], out
    exec(compile(cancel.replace('"sim://"', '"sim://?timing=virtual"'), "docs/api.md", "exec"), {})
    out = capsys.readouterr().out
    assert re.search(r"^station 4: stopped \(normal stop, [0-9.]+ s\)$", out, re.M), out


def test_pdrive_aio_is_the_subpackage() -> None:
    assert pdrive.aio is aio and aio.open_bus is pdrive.aio.open_bus


def test_a_cancelled_run_stops_its_drive() -> None:
    """Real time (the plain sim://): the Fuji station 3 ramps to 40 Hz in 4 s at its factory
    acceleration (F07 = 6.0 s for 60 Hz, fuji-opc-g1-pdp.yaml), so a run cancelled 0.3 s after it
    began is still waiting for the reference -- and even if the worker had not started it yet, the
    cancelled run ends in the stop."""
    async def main() -> tuple[bool, bool]:
        async with aio.open_bus("sim://") as bus:
            drive = await bus.drive(3)
            task = asyncio.create_task(drive.run(hz=40, wait=True, timeout=60))
            await asyncio.sleep(0.3)
            task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task
            st = await drive.status()
            return st.stopped, st.running
    stopped, running = asyncio.run(main())
    assert stopped and not running


def test_the_loop_runs_while_the_bus_waits() -> None:
    ticks = 0

    async def ticker() -> None:
        nonlocal ticks
        while True:
            await asyncio.sleep(0.01)
            ticks += 1

    async def main() -> None:
        t = asyncio.create_task(ticker())
        async with aio.open_bus("sim://") as bus:
            drive = await bus.drive(3)
            # 0 -> 10 Hz at 6 s per 60 Hz: about 1 s of waiting in the worker thread
            await drive.run(hz=10, wait=True, timeout=60)
            assert ticks >= 3, ticks           # the loop went on meanwhile (loose: any load)
            await drive.stop()
        t.cancel()
    asyncio.run(main())


def test_parameters_and_faults_as_coroutines() -> None:
    async def main() -> None:
        async with aio.open_bus("sim://?timing=virtual") as bus:
            drive = await bus.drive(3)
            assert (drive.station, drive.profile, drive.ident_hex) == (3, "fuji-opc-g1-pdp", "0xFD01")
            assert drive.fmax_hz == 60.0          # F03 factory 60.0 Hz (fuji-opc-g1-pdp.yaml)
            back = await drive.set_param("F07", 5.0)
            assert (back.code, back.value) == ("F07", 5.0)
            assert (await drive.param("F07")).value == 5.0
            f = await drive.faults()
            assert f.station == 3 and not f.fault
            assert (await bus.drive(3)) is drive   # the same station twice: the same AsyncDrive
            with pytest.raises(pdrive.UsageError):
                await drive.set_param("F07", 5.05)  # F07 has 0.1 s steps: refused, not rounded
    asyncio.run(main())


def test_await_open_bus_and_close() -> None:
    async def main() -> bool:
        bus = await aio.open_bus("sim://?timing=virtual")
        try:
            assert [s.station for s in await bus.scan(3, 4)] == [3, 4]
        finally:
            await bus.close()
        return bus.closed
    assert asyncio.run(main())


SCRIPT = textwrap.dedent("""\
    import asyncio, sys
    import profidrive_cli as pdrive

    async def main():
        async with pdrive.aio.open_bus("sim://", on_message=print) as bus:
            drive = await bus.drive(3)
            await drive.run(hz=10, wait=True, timeout=60)
            print("running", flush=True)
            await asyncio.sleep(3600)

    try:
        asyncio.run(main())
    except asyncio.CancelledError:
        print("cancelled", flush=True)
        sys.exit(3)
    """)


@pytest.mark.skipif(os.name != "posix", reason="SIGTERM to a child process")
def test_sigterm_cancels_the_task_and_the_drive_stops(tmp_path: Path) -> None:
    script = tmp_path / "svc.py"
    script.write_text(SCRIPT)
    env = {k: v for k, v in os.environ.items() if not k.startswith("PDRIVE_")}
    env["PYTHONPATH"] = str(ROOT)
    p = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True, env=env)
    try:
        assert p.stdout is not None
        lines = []
        for line in p.stdout:
            lines.append(line)
            if line.strip() == "running":
                break
        assert lines and lines[-1].strip() == "running", "".join(lines) + (p.stderr.read() if p.stderr else "")
        p.send_signal(signal.SIGTERM)
        out, err = p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 3, err
    assert re.search(r"^station 3: stopped \(normal stop, [0-9.]+ s\)$", out, re.M), out + err
    assert out.rstrip().endswith("cancelled") and "Traceback" not in err
