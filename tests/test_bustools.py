"""profidrive_cli/bustools/: the bus-level tools stand beside session/ (tests/test_layering.py PLAN), so
the extcap capture keeps its own SIGTERM handling instead of session's SignalGuard. Wireshark stops an
extcap capture with SIGTERM (as tests/test_wireshark.py does end to end); the capture then ends
quietly with what it wrote, and the handler from before is back afterwards."""

from __future__ import annotations

import os
import signal

from profidrive_cli.bustools import extcap


class _Link:
    """A link that returns one SD1 telegram per read and sends SIGTERM to this process on the third."""

    def __init__(self) -> None:
        self.reads = 0
        self.closed = False

    def read(self, deadline: float) -> bytes:
        self.reads += 1
        if self.reads == 3:
            os.kill(os.getpid(), signal.SIGTERM)
        return _SD1

    def close(self) -> None:
        self.closed = True


# FDL status request to 3 from 2 (SD1: 10 DA SA FC FCS 16; FCS = (3 + 2 + 0x49) mod 256 = 0x4E)
_SD1 = bytes([0x10, 0x03, 0x02, 0x49, 0x4E, 0x16])


def test_sigterm_ends_the_capture_quietly_and_the_old_handler_comes_back(tmp_path):
    calls = []

    def before(signum, frame):
        calls.append(signum)
    old = signal.signal(signal.SIGTERM, before)
    try:
        link = _Link()
        n = extcap.capture(link, str(tmp_path / "out.pcap"))
        assert link.closed
        assert link.reads == 3 and n >= 2          # two telegrams before the signal (three if read)
        assert calls == []                         # the capture's handler took the signal
        assert signal.getsignal(signal.SIGTERM) is before
        data = (tmp_path / "out.pcap").read_bytes()
        assert data[:4] == bytes.fromhex("d4c3b2a1") or data[:4] == bytes.fromhex("a1b2c3d4")
    finally:
        signal.signal(signal.SIGTERM, old)
