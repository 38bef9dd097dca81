"""A safe stop that nothing can skip: a --trace or --log file that fails in the middle of a
Data_Exchange (disk full), or any exception of a recorder or callback, is kept and reported after
the stop -- never raised from inside the cycle (issue: "Stops that never run").

Each command runs in this process on the simulated bus (the `sim` fixture keeps the plant, so the
stations are inspected afterwards). The file fails with ENOSPC on its first write once a simulated
motor turns (or after N frames where nothing turns). The simulated slave records every time it
leaves data exchange: the drive must have left it released by pdrive (Set_Prm with Unlock_Req,
after the stop) at standstill and out of operation -- not by its DP watchdog.
"""

import errno
import os

import pytest

from conftest import run_main
from profidrive_cli.outfile import OutputFile
from profidrive_cli.sim.slave import DATA_EXCH, SimSlave


def pdrive(capsys, monkeypatch, *args):
    """pdrive's own entry point in this process: exit code, stdout, stderr."""
    return run_main(capsys, monkeypatch, *args)


class _DiskFull:
    """A file object whose writes fail with ENOSPC from the first one for which `due()` is true."""

    def __init__(self, f, due):
        self._f, self._due, self.failed_at = f, due, None

    def write(self, data):
        if self.failed_at is None and self._due():
            self.failed_at = _motors(self._buses)
        if self.failed_at is not None:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return self._f.write(data)

    def __getattr__(self, name):
        return getattr(self._f, name)


def _motors(buses) -> dict:
    """{address: output frequency in Hz} of every simulated drive."""
    return {a: s.model.freq for b in buses.values() for a, s in b.slaves.items()
            if getattr(s.model, "freq", None) is not None}


@pytest.fixture
def disk_full(monkeypatch, sim):
    """disk_full(what, due): the OutputFile named `what` ("trace file", "--log") fails on its first
    write once due() is true; returns the list of such files (their .failed_at: the motors then)."""
    made = []

    def arm(what, due):
        real_open = OutputFile.open

        def open_(self):
            f = real_open(self)
            if self.what == what:
                self.file = _DiskFull(self.file, due)
                self.file._buses = sim
                made.append(self.file)
            return self.file
        monkeypatch.setattr(OutputFile, "open", open_)
        return made
    return arm


@pytest.fixture
def leaves(monkeypatch):
    """[(address, reason, output Hz, drive state, max Hz)] each time a simulated slave leaves data
    exchange."""
    got = []
    real = SimSlave._leave

    def _leave(self, now, reason, to=None):
        if self.state == DATA_EXCH:
            m = self.model
            got.append((self.address, reason, m.freq, getattr(m.state, "name", str(m.state)),
                        m.max_frequency()))
        return real(self, now, reason) if to is None else real(self, now, reason, to)
    monkeypatch.setattr(SimSlave, "_leave", _leave)
    return got


def _turning(sim, addresses):
    return lambda: any(_motors(sim).get(a, 0.0) != 0.0 for a in addresses)


def _after_frames(n):
    count = [0]

    def due():
        count[0] += 1
        return count[0] > n
    return due


def _one_line_about(r, words: str):
    assert "Traceback" not in r.stderr and "AttributeError" not in r.stderr, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if words in ln]
    assert len(lines) == 1, r.stderr
    assert "No space left on device" in lines[0], lines[0]
    return lines[0]


def _stopped_by_pdrive(leaves, addresses):
    """Every station left data exchange once, released by pdrive with its motor stopped; none by
    its watchdog."""
    assert not [x for x in leaves if x[1] == "watchdog"], leaves
    for a in addresses:
        mine = [x for x in leaves if x[0] == a]
        assert mine and mine[-1][1] == "released by master", leaves
        assert _at_rest(mine[-1]), mine


def _at_rest(leave) -> bool:
    """Not in operation (S4: a run command in force) and at standstill as pdrive counts it
    (drives/base.py DriveStatus.stopped: |speed| < 0.05 % of the maximum frequency; the model
    may still be a few mHz into its last ramp step when its status word says so)."""
    _, _, hz, state, fmax = leave
    return state != "S4" and abs(hz) < 0.0005 * fmax


TRACE = "trace file /dev/full"          # what the failed trace is called in its one line


# -- --trace ------------------------------------------------------------------------------------


def test_run_with_a_trace_that_fails_mid_run_stops_the_drive(capsys, monkeypatch, sim, disk_full,
                                                            leaves):
    files = disk_full("trace file", _turning(sim, [3]))
    r = pdrive(capsys, monkeypatch, "run", "3", "--hz", "30", "--duration", "1", "--port", "sim://",
               "--trace", "/dev/full", "--json")
    assert r.exit_code == 1, r.stdout + r.stderr      # README: a write that fails is exit 1
    assert files[0].failed_at[3] != 0.0                # it failed while the drive turned
    _one_line_about(r, TRACE)
    import json
    end = [json.loads(x) for x in r.stdout.splitlines() if '"event": "end"' in x][-1]
    assert end["stopped"] is True and end["stop"]["how"] == "normal", end
    _stopped_by_pdrive(leaves, [3])


def test_multi_drive_run_with_a_failing_trace_stops_both(capsys, monkeypatch, sim, disk_full, leaves):
    files = disk_full("trace file", _turning(sim, [3, 4]))
    r = pdrive(capsys, monkeypatch, "run", "3,4", "--hz", "20", "--duration", "1", "--port",
               "sim://", "--trace", "/dev/full", "--json")
    assert r.exit_code == 1, r.stdout + r.stderr
    assert any(files[0].failed_at[a] != 0.0 for a in (3, 4))
    _one_line_about(r, TRACE)
    import json
    end = [json.loads(x) for x in r.stdout.splitlines() if '"event": "end"' in x][-1]
    assert end["stopped"] is True and all(s["stopped"] for s in end["stations"]), end
    _stopped_by_pdrive(leaves, [3, 4])


@pytest.mark.parametrize("address", [5, 6], ids=["toyo", "moeller"])
def test_jog_with_a_failing_trace_stops_the_drive(capsys, monkeypatch, sim, disk_full, leaves,
                                                  address):
    files = disk_full("trace file", _turning(sim, [address]))
    r = pdrive(capsys, monkeypatch, "jog", address, "--duration", "1", "--port", "sim://",
               "--trace", "/dev/full", "--json")
    assert r.exit_code == 1, r.stdout + r.stderr
    assert files[0].failed_at[address] != 0.0
    _one_line_about(r, TRACE)
    import json
    end = [json.loads(x) for x in r.stdout.splitlines() if '"event": "end"' in x][-1]
    assert end["stopped"] is True, end
    _stopped_by_pdrive(leaves, [address])


def test_commloss_test_with_a_failing_trace_ends_stopped(capsys, monkeypatch, sim, disk_full, leaves):
    files = disk_full("trace file", _turning(sim, [6]))
    r = pdrive(capsys, monkeypatch, "commloss-test", "6", "--hz", "10", "--port", "sim://",
               "--trace", "/dev/full")
    assert r.exit_code == 1, r.stdout + r.stderr
    assert files[0].failed_at[6] != 0.0
    _one_line_about(r, TRACE)
    assert "PASS" in r.stdout                           # the test itself went through
    # the watchdog expiry is the test's own break; the end is pdrive's: released, motor stopped
    mine = [x for x in leaves if x[0] == 6]
    assert mine[-1][1] == "released by master" and _at_rest(mine[-1]), leaves


def test_param_restore_with_a_failing_trace_finishes_and_releases(capsys, monkeypatch, sim,
                                                                  disk_full, leaves, tmp_path):
    f = tmp_path / "ramps.yaml"
    f.write_text("parameters:\n  F07: 0.3\n  F08: 0.3\n")
    disk_full("trace file", _after_frames(12))     # start-up done, in the PKW exchanges
    r = pdrive(capsys, monkeypatch, "param", "restore", "3", f, "--port", "sim://", "--yes",
               "--trace", "/dev/full")
    assert r.exit_code == 1, r.stdout + r.stderr
    assert "2 applied" in r.stdout, r.stdout
    _one_line_about(r, TRACE)
    assert [x[:2] for x in leaves if x[0] == 3][-1] == (3, "released by master"), leaves


# -- --log ---------------------------------------------------------------------------------------


def test_run_with_a_log_that_fails_mid_run_stops_the_drive(capsys, monkeypatch, sim, disk_full, leaves):
    files = disk_full("--log", _turning(sim, [3]))
    r = pdrive(capsys, monkeypatch, "run", "3", "--hz", "30", "--duration", "1", "--port", "sim://",
               "--log", "/dev/full", "--json")
    assert r.exit_code == 1, r.stdout + r.stderr
    assert files[0].failed_at[3] != 0.0
    # the error line after the stop (the live view also said "logging stopped" when it happened)
    _one_line_about(r, "pdrive: --log /dev/full: write failed")
    _stopped_by_pdrive(leaves, [3])


# -- the session itself: callbacks and log columns -----------------------------------------------


def _session(**kw):
    from profidrive_cli.cli.common import BusOptions
    from profidrive_cli.session import DriveStation
    m = BusOptions("sim://", "19200", 2, None, None, False, False, 0, False).open_master()
    return DriveStation(m, 3, handle_signals=False, cycle_hz=0, **kw)


def _turn(s, sim):
    s.motion.start(50.0)
    for _ in range(200):
        if _motors(sim)[3] != 0.0:
            return
        s.motion.poll()
    raise AssertionError("the simulated drive never turned")


def test_a_sample_callback_that_raises_during_the_stop_does_not_skip_it(sim, leaves):
    """A closed stdout under --json (BrokenPipeError from the live view) while the drive stops."""
    calls = []

    def broken(sample):
        calls.append(sample)
        raise BrokenPipeError(32, "Broken pipe")
    s = _session()
    with pytest.raises(BrokenPipeError):           # said after the stop and the release
        with s:
            _turn(s, sim)
            s.on_sample = broken
    assert len(calls) == 1                          # not called again once it raised
    assert s.motion.stop_report.how == "normal" and s.motion.stop_report.stopped, s.motion.stop_report
    _stopped_by_pdrive(leaves, [3])


def test_a_message_callback_that_raises_during_the_stop_does_not_skip_it(sim, leaves):
    def broken(text):
        raise BrokenPipeError(32, "Broken pipe")
    s = _session()
    with pytest.raises(BrokenPipeError):
        with s:
            _turn(s, sim)
            s.on_message = broken                   # "stopped (normal stop, ...)" raises
    assert s.motion.stop_report.stopped and any(m.startswith("stopped") for m in s.messages)
    _stopped_by_pdrive(leaves, [3])


def test_a_log_column_that_raises_ends_logging_not_the_run(sim, leaves, tmp_path):
    """run --monitor's columns beside each exchange: an exception there (not an OSError) stops the
    log; the run and its stop go on; the session raises the log's error after the stop (exit 1)."""
    from profidrive_cli.outfile import OutputWriteError
    n = [0]

    def row():
        n[0] += 1
        if _motors(sim).get(3):
            raise ValueError("no such monitor")
        return [n[0]]
    log = tmp_path / "run.csv"
    s = _session(log_csv=str(log))
    s.log_extra = (["m"], row)
    with pytest.raises(OutputWriteError) as e:
        with s:
            _turn(s, sim)
            for _ in range(5):
                s.motion.poll()
    assert f"--log {log}: logging failed: ValueError: no such monitor" in str(e.value)
    assert s.motion.stop_report.stopped
    _stopped_by_pdrive(leaves, [3])
    assert not log.exists()                         # no half log: the temporary file is gone
    assert os.listdir(tmp_path) == []
