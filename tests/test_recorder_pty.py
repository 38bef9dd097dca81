"""Issue 27's "done when": `pdrive sniff --ring 10 --trigger 'lost(*)'` on a `pdrive sim --plc`
line where a station is unplugged writes one capture holding the seconds before and after, and
one event line. Over a socat pty pair, so that the recorder listens (end B) before the PLC's first
telegram (end A): the unplug (sim URL unplug=3@4, 4 s after that first telegram) is then always
inside what it heard. Bounds are generous (a loaded machine): the capture must hold at least 2 s
before the event and at least 1.5 s (of --after 3) after it."""

import errno
import os
import select
import signal
import subprocess
import time

import pytest

from conftest import pdrive_cmd, stop_pty_sim
from profidrive_cli.dp.capture import read_pcap
from profidrive_cli.fdl import frames as F

AFTER_S = 3.0


def _readline(p, timeout):
    """A line of p's stdout within timeout seconds ('' if none)."""
    end = time.monotonic() + timeout
    buf = b""
    fd = p.stdout.fileno()
    while time.monotonic() < end:
        r, _, _ = select.select([fd], [], [], 0.2)
        if r:
            ch = os.read(fd, 1)
            if not ch:
                break
            buf += ch
            if ch == b"\n":
                return buf.decode()
    return buf.decode()


def test_recorder_writes_one_capture_around_an_unplugged_station(socat_pair, tmp_path):
    a, b = socat_pair
    events = tmp_path / "events"
    events.mkdir()
    rec = subprocess.Popen(pdrive_cmd() + ["sniff", "--port", b, "--ring", "10", "--after", str(AFTER_S),
                                           "--trigger", "lost(*)", "--out", str(events)],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    sim = None
    try:
        # the recorder says what it records once its port is open
        line = rec.stderr.readline().decode()
        assert line.startswith("recording: ring 10 s, 3 s after each event, triggers lost(*)"), line
        sim = subprocess.Popen(pdrive_cmd() + ["sim", "--plc", "--port", a, "--plant",
                                               "sim://?unplug=3@4", "--json"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        # the event line comes once the capture is written: 4 s + the loss + 3 s after
        event = _readline(rec, 60)
        assert "lost(*)  station 3 stopped answering" in event, event
        rec.send_signal(signal.SIGTERM)           # systemd's stop: ends cleanly
        rest, errs = rec.communicate(timeout=30)
    finally:
        if rec.poll() is None:
            rec.kill()
            rec.wait()
        if sim is not None:
            stop_pty_sim(sim)
    assert rec.returncode == 0, errs
    assert rest.decode().strip() == ""            # one event line, nothing else on stdout
    assert "1 event(s), 1 capture(s)" in errs.decode()
    files = list(events.iterdir())
    assert len(files) == 1 and files[0].suffix == ".pcap", files
    assert str(files[0]) in event
    linktype, pkts = read_pcap(files[0].read_bytes())
    assert linktype == 147
    assert f"({len(pkts)} telegrams," in event
    frames = [(t, F.parse(raw)) for t, raw in pkts]
    frames = [(t, r[0]) for t, r in frames if r is not None and not isinstance(r, F.FrameError)]
    # the event's time: the last answer of station 3 lies before it, requests to it after it
    answers3 = [t for t, f in frames if f.sd not in (F.SC, F.SD4) and not f.is_request and f.sa == 3]
    assert answers3, "the capture holds station 3's answers from before it was unplugged"
    t_last = max(answers3)
    after3 = [t for t, f in frames if f.sd not in (F.SC, F.SD4) and f.is_request and f.da == 3
              and t > t_last]
    assert len(after3) >= 4                       # LOST_AFTER unanswered requests and more
    t0, t1 = pkts[0][0], pkts[-1][0]
    assert t_last - t0 >= 2.0                     # seconds before (the PLC ran ~4 s before)
    assert t1 - t_last >= 1.5                     # and after
    assert t1 - t_last <= AFTER_S + 5.0           # the after window is bounded
    # the others kept exchanging data after station 3 went
    assert {f.sa for t, f in frames if t > t_last and f.sd not in (F.SC, F.SD4)
            and not f.is_request} >= {4, 5, 6, 7}


def _wait_for_traffic(port, timeout):
    """True once octets arrive on `port` (the PLC on the other end runs)."""
    fd = os.open(port, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY)
    try:
        r, _, _ = select.select([fd], [], [], timeout)
        return bool(r)
    finally:
        os.close(fd)


@pytest.mark.parametrize("fault, code, good", [("full", errno.ENOSPC, 0), ("read-only", errno.EROFS, 2)])
def test_recorder_runs_its_whole_duration_through_captures_it_cannot_write(
        socat_pair, tmp_path, capsys, monkeypatch, fault, code, good):
    """Issue 35: `sniff --ring 1 --after 0.5 --trigger 'cycle>1ms'` on a full disk ended with exit 1
    at its first event; a folder made read-only mid-run after 12 captures. The fault is injected
    where the pcap is written (test_recorder_disk.failing_outfile: every write from the
    (good+1)-th capture on raises OSError(code)). The recorder runs its whole --duration, prints an
    error event for each capture it could not write besides that capture's trigger events, and
    ends with exit 1 only then."""
    import json

    from conftest import run_main
    from test_json_contract import assert_stream
    from test_recorder_disk import failing_outfile

    from profidrive_cli.bustools import ringstore
    a, b = socat_pair
    events = tmp_path / "events"
    events.mkdir()
    # an earlier run's capture 41 (the unit restarted it): this run numbers on from 42, and its
    # file stays as it was
    earlier = events / "pdrive-20261204-031208-41-lostall.pcap"
    earlier.write_bytes(b"earlier")
    sim = subprocess.Popen(pdrive_cmd() + ["sim", "--plc", "--port", a, "--json"],
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        assert _wait_for_traffic(b, 60), "the PLC sent nothing"
        monkeypatch.setattr(ringstore, "OutputFile", failing_outfile(code, after=good))
        # every cycle is over 1 ms: an event opens a window at once, a capture closes every 0.5 s
        # (--after), so 4 s of listening give several captures (bounds: at least good + 2)
        t0 = time.monotonic()
        r = run_main(capsys, monkeypatch, "sniff", "--port", b, "--ring", "1", "--after", "0.5",
                     "--trigger", "cycle>1ms", "--out", events, "--duration", "4", "--json")
        elapsed = time.monotonic() - t0
    finally:
        stop_pty_sim(sim)
    assert r.exit_code == 1, r.output
    assert elapsed >= 4.0                           # it listened to its end
    lines = [json.loads(x) for x in r.stdout.splitlines()]
    kinds = assert_stream(lines, "sniff")
    assert kinds[-1] == "error" and "could not be written" in lines[-1]["error"]
    errors = [d for d in lines[:-1] if d["event"] == "error"]
    triggers = [d for d in lines if d["event"] == "trigger"]
    written = sorted({d["capture"] for d in triggers if d["written"]})
    lost = sorted({d["capture"] for d in triggers if not d["written"]})
    assert len(written) == good and len(lost) >= 2, kinds
    # one error event per capture not written, for that capture's path, with the reason
    assert sorted(e["path"] for e in errors) == lost
    assert {e["reason"] for e in errors} == {os.strerror(code)}
    assert [d["full"] for d in lines if d["event"] == "disk"] == ([True] if fault == "full" else [])
    assert min(e["capture"] for e in errors) > 41 + good
    assert sorted(str(p) for p in events.iterdir() if p != earlier) == written   # nothing half-written
    assert earlier.read_bytes() == b"earlier"
    assert f"{len(lost)} capture(s) could not be written" in r.stderr
