"""The asyncio face's promises, one test each (written against the mutation run of aio/__init__.py):
every argument reaches the sync API, every call runs in the bus's own single worker thread, a
cancellation never swallows itself, a cancelled run(wait=True) ends the wait at once and stops the
drive even when cancelled again meanwhile, SIGTERM cancels the task that opened the bus (in process,
with a safety net), and the handler goes when the bus closes."""

from __future__ import annotations

import asyncio
import os
import signal
import threading
import time

import pytest

from profidrive_cli import UsageError
from profidrive_cli import aio

pytestmark = pytest.mark.usefixtures("no_config_at_all")

VIRTUAL = "sim://?timing=virtual"


def test_open_bus_hands_every_argument_to_the_sync_api(monkeypatch):
    seen = {}

    class FakeBus:
        closed = False
        port = "x"

        def close(self, exc=None):
            seen["closed_with"] = exc

    def fake_open_bus(port, **kw):
        seen.update(kw, port=port, thread=threading.current_thread().name)
        return FakeBus()
    monkeypatch.setattr(aio, "_open_bus", fake_open_bus)
    cb = print

    async def main():
        async with aio.open_bus("p", baud="1.5M", master_address=1, retries=3, slot_time=300,
                                rs485=True, echo=True, allow_real_port_writes=True,
                                handle_signals=False, on_message=cb, env={"A": "1"}):
            pass
    asyncio.run(main())
    assert seen == {"port": "p", "baud": "1.5M", "master_address": 1, "retries": 3, "slot_time": 300,
                    "rs485": True, "echo": True, "allow_real_port_writes": True,
                    # the sync bus's own signal handling is off: its thread is no main thread
                    "handle_signals": False, "on_message": cb, "env": {"A": "1"},
                    "thread": seen["thread"], "closed_with": None}
    assert seen["thread"].startswith("pdrive-aio")
    d = aio.open_bus()._kwargs
    # the sync open_bus's defaults (api/bus.py)
    assert (d["rs485"], d["echo"], d["allow_real_port_writes"]) == (False, "auto", False)


def test_every_call_runs_in_the_one_worker_thread_of_its_bus():
    names: list[str] = []

    async def main():
        async with aio.open_bus(VIRTUAL) as bus:
            drive = await bus.drive(3)
            real = drive.sync.status

            def spy():
                names.append(threading.current_thread().name)
                return real()
            drive.sync.status = spy
            await asyncio.gather(*(drive.status() for _ in range(6)))
            assert bus._pool._max_workers == 1
    asyncio.run(main())
    assert len(names) == 6 and len(set(names)) == 1 and names[0].startswith("pdrive-aio")


def test_a_cancelled_call_finishes_then_raises_cancelled():
    finished = []

    async def main():
        async with aio.open_bus(VIRTUAL) as bus:
            drive = await bus.drive(3)
            real = drive.sync.status

            def slow():
                time.sleep(0.3)
                finished.append(True)
                return real()
            drive.sync.status = slow
            task = asyncio.create_task(drive.status())
            await asyncio.sleep(0.05)
            task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task
            assert finished == [True]           # the call ran to its end first
    asyncio.run(main())


def _slow_ramp_run(cancel_twice: bool):
    """Station 3 with a 60 s acceleration time (F07, fuji-opc-g1-pdp.yaml: 0.1 s steps): 40 Hz would
    take 40 s, so a run cancelled after 0.3 s that still reached it did not end its wait."""
    returned = []

    async def main():
        async with aio.open_bus("sim://") as bus:
            drive = await bus.drive(3)
            await drive.set_param("F07", 60.0)
            real = drive.sync._run

            def spy(*a):
                st = real(*a)
                returned.append(st)
                return st
            drive.sync._run = spy
            real_stop = drive.sync.stop
            stops = []

            def stop_spy(**kw):
                stops.append(kw)
                if cancel_twice:
                    time.sleep(0.2)             # the task is cancelled again meanwhile
                return real_stop(**kw)
            drive.sync.stop = stop_spy
            task = asyncio.create_task(drive.run(hz=40, wait=True, timeout=120))
            await asyncio.sleep(0.3)
            task.cancel()
            if cancel_twice:
                await asyncio.sleep(0.05)
                task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task
            st = await drive.status()
            return st, stops
    st, stops = asyncio.run(main())
    assert len(returned) == 1 and returned[0].actual_hz < 40.0      # the wait ended early
    assert stops and st.stopped and not st.running


def test_a_cancelled_run_ends_its_wait_and_stops():
    _slow_ramp_run(cancel_twice=False)


def test_a_run_cancelled_twice_still_stops():
    _slow_ramp_run(cancel_twice=True)


def test_arguments_of_the_drive_calls_reach_the_sync_drive():
    async def main():
        async with aio.open_bus(VIRTUAL) as bus:
            assert [s.station for s in await bus.scan()] == [3, 4, 5, 6, 7]    # the defaults 0..126
            drive = await bus.drive(3, ppo=3)
            # PPO3 of the Fuji card (docs/architecture.md "Families": ppo3 = F1)
            assert (drive.layout, drive.family, drive.ident) == ("ppo3", "fuji", 0xFD01)
            calls = []
            drive.sync.set_param = lambda code, value, **kw: calls.append(("set", code, value, kw))
            drive.sync.stop = lambda **kw: calls.append(("stop", kw))
            drive.sync._run = lambda *a: calls.append(("run",) + a[:4])
            await drive.set_param("H03", 1, allow_dangerous=True)
            await drive.set_param("F07", 5.0)
            await drive.stop(timeout=7.5)
            await drive.stop()
            await drive.run(percent=25)
            await drive.run(10, wait=True, timeout=3)
            assert calls == [("set", "H03", 1, {"allow_dangerous": True}),
                             ("set", "F07", 5.0, {"allow_dangerous": False}),
                             ("stop", {"timeout": 7.5}), ("stop", {"timeout": None}),
                             ("run", None, 25, False, None), ("run", 10, None, True, 3)]
    asyncio.run(main())


def test_the_scan_range_defaults_reach_address_0():
    async def main():
        async with aio.open_bus("sim://?timing=virtual&stations=0:fuji-g1") as bus:
            return [s.station for s in await bus.scan()]
    assert asyncio.run(main()) == [0]


@pytest.mark.skipif(os.name != "posix", reason="SIGTERM")
def test_sigterm_cancels_the_opening_task_and_the_handler_goes_with_the_bus():
    assert threading.current_thread() is threading.main_thread()
    hit = []

    def safety(*a):
        hit.append("safety net")
    before = signal.signal(signal.SIGTERM, safety)
    try:
        async def opener():
            async with aio.open_bus(VIRTUAL) as bus:
                assert bus._sigterm_task is asyncio.current_task()
                drive = await bus.drive(3)
                await drive.run(hz=10, wait=True, timeout=30)
                os.kill(os.getpid(), signal.SIGTERM)
                await asyncio.sleep(30)             # cancelled by the SIGTERM long before
            return "not cancelled"

        async def main():
            t = asyncio.create_task(opener())
            try:
                return await t
            except asyncio.CancelledError:
                return "cancelled"
        assert asyncio.run(main()) == "cancelled"
        assert hit == []                            # the loop's handler took it, not the safety net
        # closed: the loop's handler is gone and the one from before is back (looked at, not sent:
        # were it SIG_DFL, a SIGTERM would end the test run instead of failing the test)
        assert signal.getsignal(signal.SIGTERM) is safety
    finally:
        signal.signal(signal.SIGTERM, before)


@pytest.mark.skipif(os.name != "posix", reason="SIGTERM")
def test_without_handle_signals_no_handler_is_installed():
    hit = []
    before = signal.signal(signal.SIGTERM, lambda *a: hit.append("previous"))
    try:
        async def main():
            async with aio.open_bus(VIRTUAL, handle_signals=False) as bus:
                assert bus._sigterm_task is None
                os.kill(os.getpid(), signal.SIGTERM)
                await asyncio.sleep(0)
        asyncio.run(main())
        assert hit == ["previous"]
    finally:
        signal.signal(signal.SIGTERM, before)


def test_a_bus_opened_outside_the_main_thread_installs_no_handler():
    out = []

    def worker():
        async def main():
            async with aio.open_bus(VIRTUAL) as bus:
                out.append(bus._sigterm_task)
        asyncio.run(main())
    t = threading.Thread(target=worker)
    t.start()
    t.join(60)
    assert out == [None]


def test_an_unopened_bus_says_so():
    with pytest.raises(UsageError, match="this bus is not open"):
        aio.open_bus(VIRTUAL).sync


def test_run_also_goes_to_the_worker_thread():
    names: list[str] = []

    async def main():
        async with aio.open_bus(VIRTUAL) as bus:
            drive = await bus.drive(3)
            real = drive.sync._run

            def spy(*a):
                names.append(threading.current_thread().name)
                return real(*a)
            drive.sync._run = spy
            await drive.run(hz=5)
            await drive.stop()
    asyncio.run(main())
    assert len(names) == 1 and names[0].startswith("pdrive-aio")


@pytest.mark.skipif(os.name != "posix", reason="SIGTERM")
def test_a_bus_without_handle_signals_leaves_the_handler_alone_on_close():
    def mine(*a):
        pass
    before = signal.signal(signal.SIGTERM, mine)
    try:
        async def main():
            async with aio.open_bus(VIRTUAL, handle_signals=False):
                pass
        asyncio.run(main())
        assert signal.getsignal(signal.SIGTERM) is mine
    finally:
        signal.signal(signal.SIGTERM, before)


def test_the_exception_that_ends_the_block_reaches_the_stop():
    """Leaving `async with` by an exception hands it to the sync close: an on_message error during
    the stop is then added to it as a note (docs/api.md), not raised in its place."""
    def display(text):
        raise RuntimeError("the display is gone")

    async def main():
        async with aio.open_bus(VIRTUAL, on_message=display) as bus:
            drive = await bus.drive(3)
            await drive.run(hz=10)
            raise ValueError("boom")
    with pytest.raises(ValueError, match="boom") as e:
        asyncio.run(main())
    notes = getattr(e.value, "__notes__", [])
    assert any("on_message raised RuntimeError: the display is gone" in n for n in notes), notes
