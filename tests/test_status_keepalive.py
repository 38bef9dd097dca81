"""`pdrive status` reads the drive while holding the bus, so the Bus's keep-alive thread never talks
to the master meanwhile (api/bus.py: "the master is only ever used by one thread at a time").

It did: status_cmd read drive.session.status() without the bus lock. On a busy machine (load 8-20,
the read slower than the keep-alive's 0.1 s) the keep-alive thread sent its Data_Exchange in the
middle of the read, the two threads' requests and replies crossed, and `pdrive status --port
socket://...` ended in a traceback (TypeError in Master._await; tests/test_socket_families.py, 1
run in 3 at load 8). Here the read is made slow on purpose, so the old code fails every time."""

import threading

from click.testing import CliRunner

from profidrive_cli.api import bus as api_bus
from profidrive_cli.cli.main import cli
from profidrive_cli.dp import poller
from profidrive_cli.session import Motion


def test_the_keepalive_thread_keeps_off_the_master_while_status_reads(monkeypatch):
    main = threading.current_thread()
    reading = [False]
    foreign = threading.Event()
    step = poller.Master.step

    def watched_step(self, st):
        if reading[0] and threading.current_thread() is not main:
            foreign.set()
        return step(self, st)

    status = Motion.status

    def slow_status(self):
        reading[0] = True
        try:
            sample = status(self)
            # a read as slow as a busy machine makes it: ten keep-alive periods in which the thread
            # would step in (it ends at once if it does)
            foreign.wait(10 * api_bus.KEEP_S)
            return sample
        finally:
            reading[0] = False

    monkeypatch.setattr(poller.Master, "step", watched_step)
    monkeypatch.setattr(Motion, "status", slow_status)
    r = CliRunner().invoke(cli, ["status", "3", "--port", "sim://", "--json"])
    assert r.exit_code == 0, r.output
    assert '"station": 3' in r.output
    assert not foreign.is_set(), "the keep-alive thread used the master during the status read"
