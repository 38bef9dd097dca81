"""The monitor's loop (issue 37: monitor/service.py) on a scripted line: a Link whose clock is virtual and
whose reads hand out telegrams at chosen times, that is pulled (LinkLost) and comes back after a few
tries, and a history that fills up. What must hold: a pulled adapter and a full disk are events,
never the end; the run ends only on its duration or when asked (Stopped, SIGTERM's exception), and
then the open capture is written and the run closed in the history."""

from __future__ import annotations

import pytest

from profidrive_cli import BusError
from profidrive_cli.fdl import frames as F
from profidrive_cli.link.base import Link, LinkLost
from profidrive_cli.monitor.engine import Monitor
from profidrive_cli.monitor.model import StoreNote
from profidrive_cli.monitor.service import LiveBox, Stopped, run

M = 2


def req_dx(da, fcb):
    return F.encode(F.make(da, M, F.request_fc(F.SRD_HIGH, fcb, True), bytes(4)))


def rep(sa):
    return F.encode(F.make(M, sa, F.response_fc(F.DL), bytes(4)))


class ScriptedLine(Link):
    """Reads hand out (t, octets) in order on a virtual clock; at `lost_at` the port goes away, and
    reopen() fails `fails` times before it is back; `stop_at`: a read at or after it raises
    Stopped (as SIGTERM's handler does inside a read)."""

    is_simulator = False
    name = "scripted"

    def __init__(self, timed, lost_at=None, fails=0, stop_at=None):
        self.timed = list(timed)
        self.clock = 0.0
        self.lost_at, self.fails, self.stop_at = lost_at, fails, stop_at
        self.reopens = 0
        self.closed = False

    def now(self) -> float:
        return self.clock

    def sleep(self, seconds: float) -> None:
        self.clock += seconds

    def write(self, data: bytes) -> None:
        raise BusError("a tap cannot talk")

    def flush_input(self) -> None:
        pass

    def read(self, deadline: float) -> bytes:
        if self.stop_at is not None and self.clock >= self.stop_at:
            raise Stopped()
        if self.lost_at is not None and self.clock >= self.lost_at:
            self.lost_at = None
            raise LinkLost("scripted: adapter pulled", "scripted")
        # telegrams the adapter did not hear while it was away are gone
        while self.timed and self.timed[0][0] < self.clock - 1e-9:
            self.timed.pop(0)
        if self.timed and self.timed[0][0] <= deadline:
            t, data = self.timed.pop(0)
            self.clock = max(self.clock, t)
            return data
        self.clock = max(self.clock, deadline)
        return b""

    def reopen(self) -> None:
        self.reopens += 1
        if self.fails > 0:
            self.fails -= 1
            raise LinkLost("scripted: not back yet", "scripted")

    def close(self) -> None:
        self.closed = True


def rounds(t0, n, period=0.1, stations=(3, 5), silent=()):
    out, fcb, t = [], False, t0
    for _ in range(n):
        for i, a in enumerate(stations):
            out.append((t + 0.01 * i, req_dx(a, fcb)))
            if a not in silent:
                out.append((t + 0.01 * i + 0.002, rep(a)))
        fcb = not fcb
        t += period
    return out


class FakeHistory:
    """What the service asks of monitor/store.py History, recorded; `full_from` writes: from that
    one on, writes return a "full" note once and keep the rows queued; `room_at`: a "room" note."""

    def __init__(self, full_at=None, room_at=None):
        self.writes = []
        self.captures = []
        self.runs = []
        self.full_at, self.room_at = full_at, room_at
        self.n = 0

    def begin_run(self, t, port, baud):
        self.runs.append(("begin", t, port))
        return []

    def end_run(self, t, reason):
        self.runs.append(("end", t, reason))
        return []

    def write(self, *, samples=(), bus=None, stations=(), events=()):
        self.n += 1
        self.writes.append((list(samples), bus, list(stations), list(events)))
        if self.n == self.full_at:
            return [StoreNote("full", "disk full in /x: database or disk is full; the history waits "
                                      "in memory")]
        if self.n == self.room_at:
            return [StoreNote("room", "disk has room again in /x")]
        return []

    def save_capture(self, t, hint, packets, start_wall):
        name = f"{len(self.captures) + 1:06d}-{hint}.pcap"
        self.captures.append((name, len(packets)))
        return name, []

    def status(self):
        return {"path": "/x", "bytes": 0, "max_bytes": 1, "full": False, "removed": 0}

    def events(self):
        return [e for w in self.writes for e in w[3]]


def said():
    lines = []
    return lines, lambda obj, line: lines.append((obj, line))


def test_a_pulled_adapter_is_two_events_and_the_listening_goes_on():
    # 3 and 5 answer for 2 s; the adapter is pulled at 2.05 s and back after 3 failed tries (one
    # every retry_s = 1 s on the line's clock: from 2.05 s, the 4th try at 6.05 s succeeds); then 3
    # and 5 answer again until 9 s. Duration 10 s.
    line = ScriptedLine(rounds(0.0, 20) + rounds(6.5, 25), lost_at=2.05, fails=3)
    hist = FakeHistory()
    lines, say = said()
    eng = Monitor(baud=187_500, wall0=0.0, interval_s=5.0, ring_s=1.0, after_s=0.5)
    box = LiveBox()
    s = run(line, eng, hist, say=say, duration=10.0, retry_s=1.0, box=box)
    assert s.ended == "duration"
    assert s.adapter_losses == 1
    adapter = [e for e in hist.events() if e.kind == "adapter"]
    assert [e.text.split(":")[0].split(" after")[0] for e in adapter] == ["adapter lost", "adapter back"]
    assert "after 4 tries" in adapter[1].text
    assert line.reopens == 4
    # the second stretch was heard: station 3's exchanges in the samples add up to both stretches'
    # (20 before the pull, 25 after)
    ex3 = sum(smp.counts["exchanges"] for w in hist.writes for smp in w[0] if smp.station == 3)
    assert ex3 == 45
    assert box.get()["adapter"] == "connected"
    assert hist.runs[0][0] == "begin" and hist.runs[-1][:1] == ("end",)
    assert line.closed


def test_a_full_disk_is_an_event_and_the_monitor_goes_on():
    line = ScriptedLine(rounds(0.0, 40))
    hist = FakeHistory(full_at=2, room_at=4)
    lines, say = said()
    eng = Monitor(baud=187_500, wall0=0.0, interval_s=1.0, ring_s=1.0, after_s=0.5)
    s = run(line, eng, hist, say=say, duration=5.0)
    assert s.ended == "duration"
    disk = [e for e in hist.events() if e.kind == "disk"]
    assert [e.text.split(" ")[1] for e in disk] == ["full", "has"]
    assert any("disk full" in ln for _, ln in lines)
    # sampling went on after the full disk: samples up to the end (t = 5)
    assert max(smp.t for w in hist.writes for smp in w[0]) >= 4.0


def test_stopped_ends_the_run_and_writes_the_open_capture():
    # station 5 silent from 1 s on: lost after 4 rounds (about 1.4 s); the capture's window (after_s
    # = 30 s) is still open when SIGTERM's Stopped comes at 3 s: it is written on the way out
    line = ScriptedLine(rounds(0.0, 10) + rounds(1.0, 30, silent=(5,)), stop_at=3.0)
    hist = FakeHistory()
    lines, say = said()
    eng = Monitor(baud=187_500, wall0=0.0, interval_s=100.0, ring_s=5.0, after_s=30.0)
    s = run(line, eng, hist, say=say, duration=None)
    assert s.ended == "stopped"
    assert len(hist.captures) == 1 and hist.captures[0][0].endswith("-lost-5.pcap")
    lost = [e for e in hist.events() if e.kind == "lost"]
    assert [(e.station, e.capture) for e in lost] == [(5, hist.captures[0][0])]
    assert hist.runs[-1] == ("end", pytest.approx(3.0, abs=0.5), "stopped")


def test_the_duration_ends_a_run_while_the_adapter_is_away():
    line = ScriptedLine(rounds(0.0, 5), lost_at=0.3, fails=10**6)
    hist = FakeHistory()
    lines, say = said()
    eng = Monitor(baud=187_500, wall0=0.0, interval_s=5.0, ring_s=1.0, after_s=0.5)
    s = run(line, eng, hist, say=say, duration=8.0, retry_s=1.0)
    assert s.ended == "duration"
    assert [e.text.split(":")[0] for e in hist.events() if e.kind == "adapter"] == ["adapter lost"]
