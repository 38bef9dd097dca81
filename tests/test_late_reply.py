"""A late reply must not shift every later reply by one (seen over `pdrive sim --pty`: a slave late
with its first answer answered the retry too; the master took the late SC as the retry's, and each
request after it got the reply to the one before -- a DP-V1 Write request got a Slave_Diag reply).

Two rules hold it (dp/poller.py, fdl/master.py): what is in the input after the reply to a repeated
request is dropped before the next request; a reply whose SAPs are not the request's swapped
(IEC 61158-4) is a late reply to another service, not this one's.
"""

from __future__ import annotations

from profidrive_cli.dp.poller import Master
from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.master import REPLY, FdlMaster
from profidrive_cli.fdl.timing import BusParams
from profidrive_cli.link.base import Link

SLAVE = 9
SC = bytes([F.SC])


def _diag_reply() -> bytes:
    # Slave_Diag reply: from SAP 60 to the master's SAP 62, six octets of diagnosis
    return F.encode(F.Frame(F.SD2, 2, SLAVE, F.response_fc(F.DL), bytes.fromhex("000C00028158"), 62, 60))


class ScriptedLink(Link):
    """A virtual clock and a slave script: reply_for(n, request) -> [(delay_s, octets)] after the
    n-th request written (from the end of its write)."""

    name = "scripted"

    def __init__(self, reply_for):
        self.t = 0.0
        self.inbox: list[tuple[float, bytes]] = []
        self.writes: list[bytes] = []
        self.reply_for = reply_for

    def now(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        self.t += max(0.0, seconds)

    def write(self, data: bytes) -> None:
        self.writes.append(bytes(data))
        for delay, octets in self.reply_for(len(self.writes), bytes(data)):
            self.inbox.append((self.t + delay, octets))
        self.inbox.sort(key=lambda x: x[0])

    def read(self, deadline: float) -> bytes:
        if not self.inbox or self.inbox[0][0] > deadline:
            self.t = max(self.t, deadline)
            return b""
        self.t = max(self.t, self.inbox[0][0])
        out = b""
        while self.inbox and self.inbox[0][0] <= self.t:
            out += self.inbox.pop(0)[1]
        return out

    def flush_input(self) -> None:
        self.inbox = [x for x in self.inbox if x[0] > self.t]


def test_the_reply_after_a_repeated_request_is_dropped_before_the_next_request():
    """Request 1 (Set_Prm) is answered late, after its retry has gone, just before the retry's own
    SC; the next request (Slave_Diag) must get its diag reply, not the retry's SC left in the input."""
    def script(n, request):
        if n == 1:
            return []                               # no answer in the slot time: the master repeats
        if n == 2:
            # the late answer to the first attempt 0.5 ms after the retry, then the retry's own
            # SC 2 ms after it (before the line's idle time TID1, 37 bits = 1.9 ms, is over)
            return [(0.0005, SC), (0.0020, SC)]
        return [(0.001, _diag_reply())]
    params = BusParams.for_baud(19200, retries=1)
    link = ScriptedLink(script)
    m = Master(link, params)
    # the premise: the first attempt timed out and was repeated, and the late SC was taken
    first = m.transact(SLAVE, F.SRD_HIGH, bytes(7), 61, 62)
    assert first.kind == REPLY and first.frame.sd == F.SC and first.retries == 1
    assert len(link.writes) == 2
    diag = m.transact(SLAVE, F.SRD_HIGH, b"", 60, 62)
    assert diag.kind == REPLY and diag.frame is not None and diag.frame.sd != F.SC, diag
    assert diag.frame.data == bytes.fromhex("000C00028158")


def test_a_reply_from_other_saps_is_not_this_requests_reply():
    """A Slave_Diag reply (SAP 60 -> 62) waiting in the input when a DP-V1 Write request (SAP 51 ->
    51) is answered: the engine counts it illegal and takes the SC behind it."""
    fm = FdlMaster(BusParams.for_baud(19200, retries=1), 2)
    fm.request(SLAVE, F.SRD_HIGH, bytes.fromhex("5F002F0A"), 51, 51, now=0.0)
    out = fm.feed(_diag_reply() + SC, 0.001)
    assert out is not None and out.kind == REPLY and out.frame.sd == F.SC and out.illegal == 1
    # the SAPs swapped are the request's own: taken
    fm.request(SLAVE, F.SRD_HIGH, b"", 60, 62, now=1.0)
    out = fm.feed(_diag_reply(), 1.001)
    assert out is not None and out.kind == REPLY and out.frame.dsap == 62 and out.illegal == 0
