"""Issue 35, "left running": days of simulated traffic in virtual time through the sans-IO
recorder (bustools/recorder.py), the CLI's writer (cli/sniff_ring.py _Writer) and the store
(bustools/ringstore.py) on a disk in memory that fills and frees (another program takes the space),
goes read-only, and whose bound removes old captures. Checked throughout: memory flat (the
process's live object count and the ring's length at every simulated 6 hours), the recorder's own
files within --max-disk after every write, and every capture accounted for (captures closed =
written + not written; one error event per capture not written, one trigger event per event).

The suite runs SOAK_DAYS (4) simulated days (about 7 s of CPU at rest); a longer run by hand:
    PDRIVE_SOAK_DAYS=30 python -m pytest -q tests/test_recorder_soak.py
"""

from __future__ import annotations

import gc
import os

from profidrive_cli.fdl import frames as F

from test_recorder import M, dx_round, frames, req_dx, rep
from test_recorder_disk import FakeDisk

from profidrive_cli.bustools.recorder import Recorder
from profidrive_cli.bustools.ringstore import Store, check_pattern
from profidrive_cli.bustools.triggers import TriggerSet, parse
from profidrive_cli.cli.sniff_ring import _Writer, pcap_size

SOAK_DAYS = max(1.0, float(os.environ.get("PDRIVE_SOAK_DAYS", "4")))   # a fault cycle is 12 h
ROUND_S = 1.0            # stations 5 and 6 exchanged once a second: 4 telegrams
EVENT_EVERY_S = 600      # every 10 minutes station 5 is silent for 6 rounds (lost, then back)
FCS_EVERY_S = 3600       # and every hour a telegram with a wrong checksum (a bus-wide event)
RING_S, AFTER_S = 5.0, 2.0
CHECK_EVERY_S = 6 * 3600


class _Counting(_Writer):
    """The CLI's writer with its lines counted instead of printed."""

    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        self.said: dict[str, int] = {}

    def _emit(self, obj, line):
        key = obj["event"] + {True: " full", False: " clear"}.get(obj.get("full"), "")
        key += " failed" if obj.get("error") and obj["event"] == "removed" else ""
        self.said[key] = self.said.get(key, 0) + 1


def _templates():
    """The round's Captured telegrams, decoded once (each round reuses them at its own times), as a
    master sends them (fdl/fcb.py, reference §2.3): the FCB toggles after every answered request (a
    template per FCB, by the round's parity); a request to a station that did not answer the one
    before restarts the sequence (FCV = 0, FCB = 1), so a listener counts each silent round as a
    round of its own and not as a retry of the one before."""
    good = [frames(*dx_round(0.0, 5, 6, fcb=b)) for b in (False, True)]
    restart = F.encode(F.make(5, M, F.request_fc(F.SRD_HIGH, True, False), b"\x00\x00"))
    silent = [frames((0.0, restart), (0.002, req_dx(6, b)), (0.003, rep(6))) for b in (False, True)]
    bad = bytearray(rep(6))
    bad[-2] ^= 0x01
    fcs = [frames((0.0, req_dx(5, b)), (0.001, rep(5)), (0.002, req_dx(6, b)), (0.003, bytes(bad)))
           for b in (False, True)]
    return good, silent, fcs


def _disk_state(disk, t):
    """The faults by the simulated hour (of each 12): in hour 5 another program fills what the
    file system has left (the recorder's oldest captures make room for its new ones), in hour 6
    it takes all of it (nothing the recorder can remove helps: the disk is full), in hour 9 the
    file system is read-only; the rest of the time it has room."""
    hour = int(t // 3600) % 12
    if t % 3600 == 0:
        disk.other = (disk.capacity - disk.used() if hour == 5 else disk.capacity if hour == 6
                      else 0)
    disk.read_only = hour == 9


def test_days_of_traffic_with_a_disk_that_fills_frees_and_fails(tmp_path):
    from dataclasses import replace
    good, silent, fcs = _templates()
    one_capture = pcap_size([(0.0, c.raw) for c in good[0]] * int((RING_S + AFTER_S) / ROUND_S + 2))
    max_bytes = 40 * one_capture                    # room for about 40 captures
    disk = FakeDisk(capacity=3 * max_bytes)
    pattern = check_pattern(str(tmp_path / "ev-{n}-{station}-{trigger}.pcap"))
    store = Store(pattern, max_bytes=max_bytes, keep_s=86400.0, disk=disk)
    tset = TriggerSet(parse("lost(*),back(*),fcs"))
    rec = Recorder(tset, RING_S, AFTER_S)
    w = _Counting(pattern, 147, True, tset, store)
    w.start = disk.clock                             # the wall clock of t = 0
    start = disk.clock
    closed = events = 0
    counts, rings = [], []
    worst_used = 0

    def write(done):
        nonlocal closed, events, worst_used
        for d in done:
            closed += 1
            events += len(d.events)
            w.write(d)
            own = sum(size for name, (size, _) in disk.files_.items() if pattern.owns(name))
            worst_used = max(worst_used, own)

    rounds = int(SOAK_DAYS * 86400 / ROUND_S)
    gc.collect()
    for i in range(rounds):
        t = i * ROUND_S
        disk.clock = start + t
        _disk_state(disk, t)
        phase = t % EVENT_EVERY_S
        batch = (silent if 300 <= phase < 306 else fcs if t % FCS_EVERY_S == 30 else good)[i % 2]
        write(rec.feed([replace(c, t=t + c.t) for c in batch]))
        write(rec.tick(t + ROUND_S - 0.001))
        if t % CHECK_EVERY_S == 0:
            gc.collect()
            counts.append(len(gc.get_objects()))
            rings.append(len(rec.ring))
    write(rec.close())

    days = rounds * ROUND_S / 86400
    # every 10 minutes: lost(5) then back(5) (2 events; the back comes 6 s after the lost, outside
    # its 2 s window: 2 captures); every hour one fcs (1 capture)
    expected_events = int(days * 86400 / EVENT_EVERY_S) * 2 + int(days * 24)
    assert events == rec.events == w.said["trigger"]
    assert abs(events - expected_events) <= 3, (events, expected_events)
    # every capture accounted for: written or an error event with its reason
    assert closed == rec.captures == store.written + store.failed
    assert w.said.get("error", 0) == store.failed > 0
    assert w.said["removed"] == store.removed > 0
    # the disk was full (hour 6 of each 12) and had room again: one pair each time (the last
    # one may end full); a read-only file system refuses removals too: said, not counted
    fulls = int(days * 2 - 0.25) + 1
    assert w.said["disk full"] == fulls and w.said.get("disk clear", 0) in (fulls - 1, fulls)
    assert w.said["removed failed"] > 0 and store.written > store.failed
    assert worst_used <= max_bytes
    # memory flat: after the first check (start-up), the live objects vary by less than 500 (a
    # capture in flight is 5 + 2 s of 4 telegrams: ~30 packets, about a hundred objects; anything
    # kept per capture -- a path, an event -- would add 312 a day) and the ring holds 5 s
    assert max(counts[1:]) - min(counts[1:]) < 500, counts
    assert max(rings) <= RING_S / ROUND_S * 4 + 4, rings
    print(f"\n{days:g} simulated days: {rounds * 4} telegrams, {events} events, {closed} captures "
          f"({store.written} written, {store.failed} not), {store.removed} removed, own files at most "
          f"{worst_used} of {max_bytes} bytes; live objects {min(counts)}..{max(counts)}")
