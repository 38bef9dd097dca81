"""Issue 38, a line of drives at the wire's pace: session/together.py (several stations' blocking
jobs at once, one bus round carrying a request to each) on a scripted master, then on the simulated
bus through the API (Bus.read_params) and the CLI (fleet dump).

The scripted master's clock moves only with its exchanges (10 ms each), so the rounds and the
keep-alives are the same whatever the threads' timing; expected sequences are written out by hand
from the module's rules: a round opens when every running job has posted, carries the posted
stations in address order, then a keep-alive (outputs None) for each held station not posted whose
last request is a quarter of its DP watchdog old (dp.poller.keep_within).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import threading
import time
from types import SimpleNamespace

import pytest

from profidrive_cli import BusError, UsageError
from profidrive_cli.link.base import LinkLost
from profidrive_cli.session.cycle import MeteredChannel
from profidrive_cli.session.together import Stopped, run_together


class Clock:
    def __init__(self, tick: float = 0.0) -> None:
        self.t = 0.0
        self.tick = tick

    def now(self) -> float:
        self.t += self.tick
        return self.t


class Script:
    """The part of dp.poller.Master a run uses: exchange, last_request, stations, link.now."""

    def __init__(self, addresses, wd_ms=None, step=0.01, tick=0.0, baud=1500000):
        self.link = Clock(tick)
        self.params = SimpleNamespace(baud=baud)
        self.stations = {a: SimpleNamespace(config=SimpleNamespace(wd_ms=wd_ms), in_data_exchange=True,
                                            output_len=12, input_len=12)
                         for a in addresses}
        self.log: list[tuple[int, bytes | None]] = []
        self.last: dict[int, float] = {}
        self.fail: dict[int, BaseException] = {}
        self.step = step
        self.on_bus = 0
        self.most_on_bus = 0

    def exchange(self, a, outputs=None):
        self.on_bus += 1
        self.most_on_bus = max(self.most_on_bus, self.on_bus)
        time.sleep(0.0005)                  # a telegram's time: another thread could come in now
        self.on_bus -= 1
        self.link.t += self.step
        self.log.append((a, outputs))
        self.last[a] = self.link.t
        if a in self.fail:
            raise self.fail[a]
        return bytes([a]) + (outputs or b"")

    def last_request(self, a):
        return self.last.get(a)


class Own:
    """A station's own inner channel (what the run replaces, then puts back)."""

    def now(self):
        return 0.0

    def exchange(self, outputs):
        raise AssertionError("the station's own channel was used during the run")


def channels(addresses):
    return {a: MeteredChannel(Own()) for a in addresses}


def counting(ch, n, tag):
    """A job: n exchanges with outputs tag+i; returns the inputs it got."""
    return lambda: [ch.exchange(bytes([tag, i])) for i in range(n)]


def test_rounds_carry_every_running_station_once_in_address_order():
    m = Script([3, 4, 5])
    chs = channels([3, 4, 5])
    own = {a: c.inner for a, c in chs.items()}
    out = run_together(m, chs, {5: counting(chs[5], 2, 50), 3: counting(chs[3], 3, 30),
                                4: counting(chs[4], 1, 40)})
    # by hand: round 1 = 3, 4, 5; round 2 = 3, 5 (4 has ended); round 3 = 3
    assert m.log == [(3, bytes([30, 0])), (4, bytes([40, 0])), (5, bytes([50, 0])),
                     (3, bytes([30, 1])), (5, bytes([50, 1])),
                     (3, bytes([30, 2]))]
    assert list(out) == [5, 3, 4]                           # the jobs' order
    assert out[3].value == [bytes([3, 30, i]) for i in range(3)]
    assert out[5].value == [bytes([5, 50, 0]), bytes([5, 50, 1])]
    assert all(o.ok for o in out.values())
    assert {a: c.inner for a, c in chs.items()} == own      # each station's own channel again
    assert {a: c.cycles for a, c in chs.items()} == {3: 3, 4: 1, 5: 2}
    assert m.most_on_bus == 1                               # never two threads on the bus


def test_a_station_waiting_for_its_turn_is_kept_by_its_watchdog_rule():
    # watchdog 100 ms: kept once its last request is 25 ms old; each exchange takes 10 ms
    m = Script([3, 4], wd_ms=100)
    chs = channels([3, 4])
    out = run_together(m, chs, {3: counting(chs[3], 6, 30), 4: counting(chs[4], 1, 40)})
    assert out[3].ok and out[4].ok
    # by hand: r1 3@10 4@20; r2 3@30 (4 last 20: 10 old); r3 3@40 (20 old); r4 3@50, 30 old ->
    # 4 kept @60; r5 3@70; r6 3@80 (4: 20 old); end of 3's job
    assert m.log == [(3, bytes([30, 0])), (4, bytes([40, 0])), (3, bytes([30, 1])),
                     (3, bytes([30, 2])), (3, bytes([30, 3])), (4, None),
                     (3, bytes([30, 4])), (3, bytes([30, 5]))]


def test_a_late_job_is_waited_for_until_a_keep_alive_is_due():
    # station 4's job posts only after 3 has made 5 exchanges; both have watchdogs of 100 ms (kept
    # when 25 ms old); the clock runs on while the master waits (1 ms each time it is read), as a
    # real line's does
    m = Script([3, 4], wd_ms=100, tick=0.001)
    m.last = {3: 0.0, 4: 0.0}                # both in data exchange since t = 0
    chs = channels([3, 4])
    go = threading.Event()

    def three():
        got = [chs[3].exchange(bytes([30, i])) for i in range(5)]
        go.set()
        return got

    def four():
        go.wait(60)
        return chs[4].exchange(bytes([40]))
    out = run_together(m, chs, {3: three, 4: four})
    assert out[3].ok and out[4].value == bytes([4, 40])
    # 4 never posted before 3's fifth exchange: it was kept with its last outputs meanwhile
    fours = [o for a, o in m.log if a == 4]
    assert fours[-1] == bytes([40]) and fours[:-1] and all(o is None for o in fours[:-1])
    # 3's own five in order; after its job ended it is kept the same way while 4 is late
    threes = [o for a, o in m.log if a == 3]
    assert threes[:5] == [bytes([30, i]) for i in range(5)] and all(o is None for o in threes[5:])


def test_a_bus_error_goes_to_its_own_job_only():
    m = Script([3, 4, 5])
    m.fail[4] = BusError("station 4: no answer")
    chs = channels([3, 4, 5])
    out = run_together(m, chs, {a: counting(chs[a], 2, a) for a in (3, 4, 5)})
    assert isinstance(out[4].error, BusError) and "no answer" in str(out[4].error)
    assert out[3].value == [bytes([3, 3, 0]), bytes([3, 3, 1])]
    assert out[5].ok


def endless(chs, seen):
    """Jobs of 100 exchanges each that note what ended them in seen[address]."""
    def job(a):
        def run():
            try:
                return [chs[a].exchange(b"x") for _ in range(100)]
            except BaseException as e:
                seen[a] = e
                raise
        return run
    return job


def test_a_lost_link_ends_every_job_and_is_raised():
    m = Script([3, 4, 5])
    chs = channels([3, 4, 5])
    own = {a: c.inner for a, c in chs.items()}
    m.fail[5] = LinkLost("gone", "sim://")
    seen = {}
    job = endless(chs, seen)
    with pytest.raises(LinkLost):
        run_together(m, chs, {a: job(a) for a in (3, 4, 5)})
    # every job ended by the lost link: none ran on; the channels are the stations' own again
    assert set(seen) == {3, 4, 5} and all(isinstance(e, LinkLost) for e in seen.values())
    assert len(m.log) == 3
    assert {a: c.inner for a, c in chs.items()} == own
    assert not [t for t in threading.enumerate() if t.name.startswith("pdrive-station-")]


def test_an_interrupt_in_the_callers_thread_stops_every_job():
    m = Script([3, 4])
    chs = channels([3, 4])
    seen = {}
    job = endless(chs, seen)

    def done(a, outcome):
        raise KeyboardInterrupt

    def short():
        return chs[3].exchange(b"y")
    with pytest.raises(KeyboardInterrupt):
        run_together(m, chs, {3: short, 4: job(4)}, on_done=done)
    assert isinstance(seen[4], Stopped)
    assert not [t for t in threading.enumerate() if t.name.startswith("pdrive-station-")]


def test_on_done_comes_between_rounds_as_each_job_ends():
    m = Script([3, 4])
    chs = channels([3, 4])
    order = []

    def done(a, outcome):
        order.append((a, len(m.log), outcome.value))
    run_together(m, chs, {3: counting(chs[3], 3, 30), 4: counting(chs[4], 1, 40)}, on_done=done)
    # 4 ends after round 1 (2 exchanges so far), 3 after round 3 (2 + 1 + 1)
    assert order == [(4, 2, [bytes([4, 40, 0])]), (3, 4, [bytes([3, 30, i]) for i in range(3)])]


def test_the_window_is_what_a_quarter_second_round_carries():
    from profidrive_cli.session.together import MAX_JOBS, window
    # by hand (reference §1, §4.1: 11 bit a character, min TSDR 11, TID1 37): a PPO1 Data_Exchange
    # is 2 x 21 x 11 + 11 + 37 = 510 bit: 26.6 ms at 19.2k (9 in 0.25 s), 53.1 ms at 9.6k (4),
    # 0.34 ms at 1.5M (all, up to MAX_JOBS)
    twelve = list(range(3, 15))
    assert window(Script(twelve, baud=19200), twelve) == 9
    assert window(Script(twelve, baud=9600), twelve) == 4
    assert window(Script(twelve, baud=1500000), twelve) == 12
    many = list(range(0, 100))
    assert window(Script(many, baud=1500000), many) == MAX_JOBS
    assert window(Script([3], baud=9600), [3]) == 1
    # with a 500 ms watchdog the round stays within its keep rule, a quarter of it (125 ms): at
    # 19.2k 4 PPO1 stations (106 ms; a fifth would make 133 ms), so none is due before its turn
    assert window(Script(twelve, baud=19200, wd_ms=500), twelve) == 4


def test_no_more_jobs_run_at_once_than_the_window():
    twelve = list(range(3, 15))
    m = Script(twelve, baud=9600)                         # a window of 4 (above)
    chs = channels(twelve)
    at_once = {"now": 0, "most": 0}
    lock = threading.Lock()

    def job(a):
        def run():
            with lock:
                at_once["now"] += 1
                at_once["most"] = max(at_once["most"], at_once["now"])
            try:
                return [chs[a].exchange(bytes([a, i])) for i in range(3)]
            finally:
                with lock:
                    at_once["now"] -= 1
        return run
    out = run_together(m, chs, {a: job(a) for a in twelve})
    assert all(o.ok for o in out.values()) and at_once["most"] == 4
    # each station's three exchanges, in order; the first round carries the first four stations
    for a in twelve:
        assert [o for x, o in m.log if x == a] == [bytes([a, i]) for i in range(3)]
    assert [a for a, _ in m.log[:4]] == [3, 4, 5, 6]


def test_no_jobs_and_a_missing_channel():
    assert run_together(Script([]), {}, {}) == {}
    with pytest.raises(ValueError, match="no channel for station"):
        run_together(Script([3]), {}, {3: lambda: None})


# -- on the simulated bus -------------------------------------------------------------------------

LINE = "sim://?stations=3:fuji-g1,4:fuji-g1,5:fuji-g1&set=4:F07=5"


def test_read_params_reads_each_drive_as_param_does():
    import profidrive_cli as pdrive
    with pdrive.open_bus(LINE) as bus:
        got = bus.read_params([3, 4, 5], ["F07", "F08"])
        assert sorted(got) == [3, 4, 5] and all(sorted(v) == ["F07", "F08"] for v in got.values())
        # the plant's values: F07 6.0 s (the Fuji factory value) but station 4 set to 5 s
        assert [got[a]["F07"].value for a in (3, 4, 5)] == [6.0, 5.0, 6.0]
        # drives read_params opened are closed again; the same reads one by one agree
        assert bus.drives == []
        for a in (3, 4, 5):
            d = bus.drive(a)
            assert d.param("F07") == got[a]["F07"] and d.param("F08") == got[a]["F08"]


def test_read_params_per_station_codes_keeps_an_opened_drive_open():
    import profidrive_cli as pdrive
    with pdrive.open_bus(LINE) as bus:
        d4 = bus.drive(4)
        got = bus.read_params({3: ["F07"], 4: ["F08", "F07"]})
        assert list(got[4]) == ["F08", "F07"] and got[4]["F07"].value == 5.0
        assert bus.drives == [d4] and d4.status().station == 4


def test_read_params_bad_input_reads_nothing():
    import profidrive_cli as pdrive
    with pdrive.open_bus(LINE) as bus:
        for args, words in ((([3], None), "which codes"), (({3: ["F07"]}, ["F07"]), "not both"),
                            (({3: "F07"},), "list of strings"), (([3], [7]), "list of strings")):
            with pytest.raises(UsageError, match=words):
                bus.read_params(*args)
        with pytest.raises(UsageError, match="NOPE99"):
            bus.read_params([3, 4], ["F07", "NOPE99"])
        assert bus.drives == []


def test_read_params_a_station_that_cannot_be_read_is_named_the_others_are_kept():
    import profidrive_cli as pdrive
    from profidrive_cli.api import ParamsError
    with pdrive.open_bus(LINE) as bus:
        d = bus.drive(5)
        bus.simulator.unplug(5)
        with pytest.raises(ParamsError) as e:
            bus.read_params({3: ["F07"], 5: ["F07"]})
        assert set(e.value.errors) == {5} and "station 5" in str(e.value)
        assert e.value.partial[3]["F07"].value == 6.0
        del d


# -- the asyncio twin -------------------------------------------------------------------------------

def test_aio_read_params_and_its_cancellation():
    import asyncio

    from profidrive_cli import aio

    async def main():
        async with aio.open_bus(LINE + "&baud=9600&timing=wire", baud=9600) as bus:
            got = await bus.read_params([3, 4], ["F07"])
            assert [got[a]["F07"].value for a in (3, 4)] == [6.0, 5.0]
            # a long read (every setting of three drives, 9.6 kbit/s on the wire's time) cancelled
            # at once: CancelledError; the drives it opened are closed, the bus goes on
            codes = ["F07", "F08", "F03"] * 20
            t = asyncio.ensure_future(bus.read_params({3: codes, 4: codes, 5: codes}))
            await asyncio.sleep(0.2)
            t.cancel()
            with pytest.raises(asyncio.CancelledError):
                await t
            assert bus.sync.drives == []
            assert (await (await bus.drive(4)).param("F07")).value == 5.0
    asyncio.run(main())


# -- the CLI: SIGTERM while a line is read ------------------------------------------------------------

@pytest.mark.skipif(os.name != "posix", reason="SIGTERM to a child process over a pty")
def test_sigterm_during_fleet_dump_releases_every_station_and_leaves_whole_files(tmp_path):
    from conftest import pdrive_cmd, pty_sim_process
    from profidrive_cli.session.dumpfile import load_dump
    out_dir = tmp_path / "dumps"
    out_dir.mkdir()
    # 19.2 kbit/s on the wire's time: the Moeller drive's 231 settings take at least 330 exchanges
    # of 26.6 ms (bench_fleet.py's hand figure), about 9 s; the Toyo drive (no settings a dump can
    # hold) is written first, so its file says the jobs are running
    with pty_sim_process("--plant", "sim://?timing=wire&baud=19200") as port:
        p = subprocess.Popen(pdrive_cmd() + ["param", "fleet", "dump", "3,4,5,6,7", "-o", str(out_dir),
                                             "--port", port, "--baud", "19200", "--json"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL,
                             text=True)
        try:
            end = time.monotonic() + 120
            while not list(out_dir.glob("station-*.yaml")) and p.poll() is None and \
                    time.monotonic() < end:
                time.sleep(0.05)
            assert p.poll() is None, p.stderr.read()
            p.send_signal(signal.SIGTERM)
            out, err = p.communicate(timeout=120)
        finally:
            if p.poll() is None:
                p.kill()
                p.communicate()
        assert p.returncode == 143, err
        assert "Traceback" not in err
        # the station 6 dump was cut: no file, no partial one; every file there is whole
        files = sorted(out_dir.iterdir())
        assert "station-006.yaml" not in [f.name for f in files]
        assert all(f.name.startswith("station-") and f.suffix == ".yaml" for f in files), files
        for f in files:
            load_dump(str(f))
        # every station was released on the way out: none is left in data exchange
        r = subprocess.run(pdrive_cmd() + ["scan", "--from", "3", "--to", "7", "--port", port,
                                            "--baud", "19200", "--json"],
                           capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL)
        assert r.returncode == 0, r.stderr
        rows = [json.loads(line) for line in r.stdout.splitlines() if line.strip()]
        found = rows[-1]["stations"] if rows and "stations" in rows[-1] else rows
        states = {s["station"]: s.get("state") for s in found if s.get("station") in (3, 4, 5, 6, 7)}
        assert len(states) == 5 and not any("data exchange" in str(v) for v in states.values()), states


def test_the_dump_text_is_the_same_by_either_yaml_emitter(tmp_path, capsys, monkeypatch):
    # fleet dump writes with libyaml's emitter where PyYAML has it: the text of every family's
    # dump must be the one PyYAML's own emitter writes
    import yaml

    from conftest import run_main
    from profidrive_cli.session import dumpfile
    if not hasattr(yaml, "CSafeDumper"):
        pytest.skip("PyYAML without libyaml")
    docs = {}
    real = dumpfile.dump_text

    def keep(doc, output):
        docs[str(output)] = doc
        return real(doc, output)
    monkeypatch.setattr(dumpfile, "dump_text", keep)
    r = run_main(capsys, monkeypatch, "param", "fleet", "dump", "3,4,5,6,7", "-o", tmp_path,
                 "--port", "sim://")
    assert r.exit_code == 0, r.stderr
    assert len(docs) == 5
    written = {path: open(path, encoding="utf-8").read() for path in docs}
    monkeypatch.delattr(yaml, "CSafeDumper")
    for path, doc in docs.items():
        assert written[path] == real(doc, path)
