"""The API's safe stop that nothing can skip (api/bus.py, session/signals.py):

- two open buses share the signal handlers: each keeps its protection until it is closed, in any
  closing order (SIGTERM after the first close still stops the second bus's drive);
- an on_message callback that raises during the stop does not skip any drive: it is raised after
  the stop;
- leaving the `with` sends the stop command of every started drive in the same bus cycle;
- a bus the script never closes stops its drives at interpreter exit (also after an uncaught
  exception) or when it is garbage collected, with a ResourceWarning;
- the keep-alive period is the smaller of its two bounds (0.1 s and a fifth of the DP watchdog).

Every drive is seen stopped by the simulator itself (the station's model frequency, its control word).
"""

from __future__ import annotations

import gc
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import profidrive_cli as pdrive
from profidrive_cli.session.signals import SessionTerminated, SignalGuard

SIM = "sim://?timing=virtual"
ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.usefixtures("no_config_at_all")


def _model(bus, address):
    return bus.master.link.bus.slave(address).model


def _run_script(tmp_path, text, *args, signal_after_line=None, timeout=60):
    """Run `text` as a script; with signal_after_line: SIGTERM once it printed that line."""
    script = tmp_path / "rig.py"
    script.write_text(text)
    p = subprocess.Popen([sys.executable, *args, str(script)], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, cwd=tmp_path,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        if signal_after_line is not None:
            line = p.stdout.readline().strip()
            assert line == signal_after_line, line + p.stderr.read()
            p.send_signal(signal.SIGTERM)
        out, err = p.communicate(timeout=timeout)
    finally:
        if p.poll() is None:
            p.kill()
    return p.returncode, out, err


# -- signals: one protection per bus --------------------------------------------------------------

@pytest.mark.parametrize("first_closed", [0, 1])
def test_two_guards_each_keep_sigterm_until_closed_in_any_order(first_closed):
    before = signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGINT)
    guards = [SignalGuard(), SignalGuard()]
    for g in guards:
        g.install()
    try:
        first, second = guards[first_closed], guards[1 - first_closed]
        first.guard()                                # its close: stop, then restore
        first.restore()
        h = signal.getsignal(signal.SIGTERM)
        assert callable(h)                           # not SIG_DFL: the second is still open
        with pytest.raises(SessionTerminated):
            h(signal.SIGTERM, None)
        assert signal.getsignal(signal.SIGINT) is before[1]   # Ctrl-C: the caller's own again
        second.guard()
        second.restore()
    finally:
        for g in guards:
            g.restore()
    assert (signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGINT)) == before


def test_a_signal_during_one_stop_hurries_it_and_reaches_the_bus_still_open():
    before = signal.getsignal(signal.SIGTERM)
    g1, g2 = SignalGuard(), SignalGuard()
    g1.install()
    g2.install()
    try:
        g1.guard()
        signal.getsignal(signal.SIGTERM)(signal.SIGTERM, None)
        assert g1.hurry and not g2.hurry             # the stop under way coasts, nothing raised
        with pytest.raises(SessionTerminated):       # ... and once it is done, the open bus ends
            g1.restore()
        assert callable(signal.getsignal(signal.SIGTERM))
    finally:
        g2.guard()
        g2.restore()
        g1.restore()
    assert signal.getsignal(signal.SIGTERM) is before


@pytest.mark.parametrize("order", ["ab", "ba"])
def test_sigterm_after_the_first_bus_closed_stops_the_second_bus_drive(tmp_path, order):
    # real-time simulators, one per bus; ramps of 0.5 s to 60 Hz (F07/F08) keep the test short
    code, out, err = _run_script(tmp_path, (
        "import time\n"
        "import profidrive_cli as pdrive\n"
        "a, b = pdrive.open_bus('sim://'), pdrive.open_bus('sim://')\n"
        f"first, second = (a, b) if {order!r} == 'ab' else (b, a)\n"
        "sim = second.master.link.bus\n"
        "try:\n"
        "    with second:\n"
        "        drives = [a.drive(3), b.drive(3)]\n"
        "        for d in drives:\n"
        "            d.set_param('F07', 0.5)\n"
        "            d.set_param('F08', 0.5)\n"
        "            d.run(hz=20)\n"
        "        for d in drives:\n"
        "            d.run(hz=20, wait=True, timeout=20)\n"
        "        first.close()\n"
        "        print('RUNNING', sim.slave(3).model.freq > 19, flush=True)\n"
        "        time.sleep(30)\n"
        "finally:\n"
        "    r = second.drives[0]._station.motion.stop_report if second.drives else \\\n"
        "        drives[1 if second is b else 0]._station.motion.stop_report\n"
        "    print('STOP', r.how, r.stopped, sim.slave(3).model.freq, flush=True)\n"),
        signal_after_line="RUNNING True")
    assert "STOP normal True 0.0" in out, out + err
    assert "SessionTerminated" in err and code != 0


# -- callbacks never skip a stop -------------------------------------------------------------------

def test_on_message_raising_during_the_stop_skips_no_drive():
    armed = []

    def on_message(text):
        armed.append(text) if armed else None
        if armed:
            raise RuntimeError("the display is gone")
    with pytest.raises(RuntimeError, match="the display is gone"):
        with pdrive.open_bus(SIM, on_message=on_message) as bus:
            d3, d4 = bus.drive(3), bus.drive(4)
            d3.run(hz=30, wait=True, timeout=30)
            d4.run(hz=30, wait=True, timeout=30)
            armed.append("armed")                    # from here every message raises
    assert _model(bus, 3).freq == 0.0 and _model(bus, 4).freq == 0.0
    assert d3._station.motion.stop_report.stopped and d4._station.motion.stop_report.stopped
    assert len(armed) >= 3                           # the stop of each drive was said (and raised)
    assert bus.master.link.bus.slave(3).state != "Data_Exch"   # released


def test_on_message_error_is_noted_on_the_exception_that_ends_the_with():
    armed = []

    def on_message(text):
        if armed:
            raise RuntimeError("logger broken")
    with pytest.raises(ValueError) as ei:           # the exception that ended the work stays
        with pdrive.open_bus(SIM, on_message=on_message) as bus:
            d3, d4 = bus.drive(3), bus.drive(4)
            d3.run(hz=30, wait=True, timeout=30)
            d4.run(hz=30, wait=True, timeout=30)
            armed.append(True)
            raise ValueError("rig failed")
    assert _model(bus, 3).freq == 0.0 and _model(bus, 4).freq == 0.0
    if sys.version_info >= (3, 11):                 # (notes: Python 3.11 on)
        assert "on_message raised RuntimeError: logger broken (after the stop)" in ei.value.__notes__


# -- the stop of every drive together --------------------------------------------------------------

def test_leaving_the_with_sends_every_stop_command_in_the_same_cycle():
    log: list[tuple[int, int]] = []                  # (station, control word) per Data_Exchange

    def spy(slave):
        orig = slave._data_exchange

        def data_exchange(req, now):
            reply = orig(req, now)
            log.append((slave.address, slave.model.ctw_in))
            return reply
        slave._data_exchange = data_exchange

    with pdrive.open_bus(SIM) as bus:
        d3, d4 = bus.drive(3), bus.drive(4)
        d3.run(hz=30, wait=True, timeout=30)
        d4.run(hz=30, wait=True, timeout=30)
        assert _model(bus, 3).freq == pytest.approx(30, abs=0.3)
        assert _model(bus, 4).freq == pytest.approx(30, abs=0.3)
        running = {a: _model(bus, a).ctw_in for a in (3, 4)}
        for a in (3, 4):
            spy(bus.master.link.bus.slave(a))
    first_stop = {}
    for i, (a, ctw) in enumerate(log):
        if ctw != running[a]:
            first_stop.setdefault(a, i)
    assert set(first_stop) == {3, 4}, log[:20]
    # one round = one Data_Exchange per station: the two stop commands are neighbours, with no
    # other exchange of either station between them
    assert abs(first_stop[3] - first_stop[4]) == 1, log[:20]
    assert _model(bus, 3).freq == 0.0 and _model(bus, 4).freq == 0.0
    assert d3._station.motion.stop_report.how == d4._station.motion.stop_report.how == "normal"


def test_a_failure_of_the_stop_together_still_stops_every_drive_one_by_one(monkeypatch):
    from profidrive_cli.session.group import Group

    def broken(*a, **k):
        raise RuntimeError("a bug in the group stop")
    monkeypatch.setattr(Group, "stop_all", broken)
    with pytest.raises(RuntimeError, match="a bug in the group stop"):
        with pdrive.open_bus(SIM) as bus:
            d3, d4 = bus.drive(3), bus.drive(4)
            d3.run(hz=30, wait=True, timeout=30)
            d4.run(hz=30, wait=True, timeout=30)
    assert _model(bus, 3).freq == 0.0 and _model(bus, 4).freq == 0.0
    assert d3._station.motion.stop_report.stopped and d4._station.motion.stop_report.stopped


# -- a bus never closed ----------------------------------------------------------------------------

@pytest.mark.parametrize("ending", ["", "raise RuntimeError('the rig script failed')\n"])
def test_an_unclosed_bus_stops_its_drive_at_exit_with_a_resource_warning(tmp_path, ending):
    code, out, err = _run_script(tmp_path, (
        "import atexit\n"
        "seen = {}\n"
        "def after():                  # registered before pdrive's: runs after it (LIFO)\n"
        "    r = seen['drive']._station.motion.stop_report\n"
        "    print('AFTER', r and r.how, seen['sim'].slave(3).model.freq, flush=True)\n"
        "atexit.register(after)\n"
        "import profidrive_cli as pdrive\n"
        "bus = pdrive.open_bus('sim://?timing=virtual')\n"
        "seen['sim'] = bus.master.link.bus\n"
        "seen['drive'] = d = bus.drive(3)\n"
        "d.run(hz=30, wait=True, timeout=30)\n"
        "print('RUNNING', seen['sim'].slave(3).model.freq > 29, flush=True)\n" + ending),
        "-W", "always::ResourceWarning")
    assert "RUNNING True" in out, out + err
    assert "AFTER normal 0.0" in out, out + err
    assert "ResourceWarning" in err and "was never closed" in err, err
    assert ("the rig script failed" in err) == bool(ending)


def test_a_dropped_bus_stops_its_drive_when_collected_with_a_resource_warning():
    bus = pdrive.open_bus(SIM)
    sim = bus.master.link.bus
    d = bus.drive(3)
    d.run(hz=30, wait=True, timeout=30)
    assert sim.slave(3).model.freq > 29
    with pytest.warns(ResourceWarning, match="was never closed"):
        del bus, d                                   # (a session would hold its bus: none kept)
        deadline = time.monotonic() + 30             # (the keep-alive thread may hold it a moment)
        while sim.slave(3).state == "Data_Exch" and time.monotonic() < deadline:
            gc.collect()
            time.sleep(0.01)
    assert sim.slave(3).model.freq == 0.0
    assert sim.slave(3).state != "Data_Exch"         # released


def test_a_closed_bus_is_not_kept_alive_and_not_warned_about(recwarn):
    import weakref
    with pdrive.open_bus(SIM) as bus:
        bus.drive(3).status()
    ref = weakref.ref(bus)
    del bus
    gc.collect()
    assert ref() is None
    assert not [w for w in recwarn if issubclass(w.category, ResourceWarning)
                and "never closed" in str(w.message)]


# -- the keep-alive period: the smaller of 0.1 s and a fifth of the DP watchdog --------------------

@pytest.mark.parametrize("watchdog_ms,period_s", [
    (60, 0.012),        # 60 ms / 5 = 12 ms < 100 ms
    (200, 0.04),        # 200 ms / 5 = 40 ms < 100 ms
    (500, 0.1),         # 500 ms / 5 = 100 ms = 100 ms
    (2000, 0.1),        # 2000 ms / 5 = 400 ms > 100 ms: 100 ms
])
def test_keep_alive_period_is_the_smaller_bound(watchdog_ms, period_s):
    with pdrive.open_bus(SIM) as bus:
        bus.drive(3, watchdog_ms=watchdog_ms)
        assert bus._keep_s() == pytest.approx(period_s)


def _gaps_while_working_on_4(watchdog_3_ms, watchdog_4_ms=500):
    """Station 3 at 20 Hz with its DP watchdog, parameter reads of station 4 for 1 s: the largest gap
    between two Data_Exchanges station 3 received (virtual clock) and its watchdog expiries. At
    1.5 Mbit/s a request and its reply take well under 1 ms, so the gaps are the keep-alive's."""
    times: list[float] = []
    with pdrive.open_bus(SIM, baud="1.5M") as bus:
        d4 = bus.drive(4, watchdog_ms=watchdog_4_ms)
        d3 = bus.drive(3, watchdog_ms=watchdog_3_ms)
        d3.run(hz=20, wait=True, timeout=30)
        slave = bus.master.link.bus.slave(3)
        orig = slave._data_exchange

        def data_exchange(req, now):
            times.append(now)
            return orig(req, now)
        slave._data_exchange = data_exchange
        t0 = bus.master.link.now()
        for _ in range(500):                         # 1 s on the virtual clock (many periods)
            d4.param("F07")
            if bus.master.link.now() - t0 > 1.0:
                break
        slave._data_exchange = orig
        expired = slave.stats["watchdog_expired"]
        freq = _model(bus, 3).freq
    return max(b - a for a, b in zip(times, times[1:])), expired, freq


def test_a_short_watchdog_is_kept_by_a_fifth_of_it():
    # 60 ms watchdog: the period is 60 / 5 = 12 ms (the 0.1 s bound would let it expire); a call on
    # station 4 checks after each of its own exchanges (at least 50 a second: 20 ms apart), so
    # station 3 waits at most 12 + 20 = 32 ms, never the watchdog out
    gap, expired, freq = _gaps_while_working_on_4(60)
    assert expired == 0 and freq == pytest.approx(20.0, abs=0.2)
    assert gap < 0.060


def test_a_long_watchdog_is_kept_every_tenth_of_a_second():
    # 2000 ms watchdogs (both: the shortest one counts): the period is min(0.1, 2000 ms / 5 = 0.4 s)
    # = 0.1 s; between two checks at most
    # one more exchange of station 4 (at most 1 / 50 Hz = 20 ms paced): 0.12 s, well below the
    # 0.4 s the other bound would allow
    gap, expired, _ = _gaps_while_working_on_4(2000, 2000)
    assert expired == 0
    assert gap < 0.2
