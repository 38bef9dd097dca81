"""UART parity errors (issue 12 finding 9): the kernel's PARMRK escaping undone by a pure function,
a flagged character turning the telegram it belongs to into one illegal frame plus one retry, and
the marking port over a real pty (0xFF octets escaped by the line discipline)."""

import os
import pty
import termios

import pytest

from profidrive_cli.dp.poller import Master
from profidrive_cli.dp.station import SlaveConfig
from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.master import REPLY, FdlMaster
from profidrive_cli.fdl.timing import BusParams
from profidrive_cli.link import parity as P
from profidrive_cli.link import serial_link
from profidrive_cli.link.parity import LineOctets, unmark_parity
from profidrive_cli.sim.plant import build_bus

pytestmark = pytest.mark.skipif(P.ParityMarkingSerial is None, reason="POSIX only")


# -- the unescaping -------------------------------------------------------------------------------

def test_doubled_mark_is_one_real_ff():
    assert unmark_parity(b"\x68\xFF\xFF\x16") == (b"\x68\xFF\x16", (), b"")


def test_marked_octet_is_flagged_at_its_position():
    # 0xFF 0x00 X: X arrived with a parity error; it stays in place, flagged
    assert unmark_parity(b"\x10\x02\xFF\x00\x43\x03") == (b"\x10\x02\x43\x03", (2,), b"")
    # a break (0xFF 0x00 0x00) and a flagged 0xFF (0xFF 0x00 0xFF)
    assert unmark_parity(b"\xFF\x00\x00\xFF\x00\xFF\xE5") == (b"\x00\xFF\xE5", (0, 1), b"")


def test_plain_octets_pass_unchanged():
    data = bytes(range(0, 255))
    assert unmark_parity(data) == (data, (), b"")


def test_marks_split_across_reads_at_every_point():
    raw = b"\x01\xFF\xFF\x02\xFF\x00\x33\xFF\xFF\xFF\x00\x00\x04"
    want, want_err = b"\x01\xFF\x02\x33\xFF\x00\x04", (3, 5)
    for cut in range(len(raw) + 1):
        a, ea, carry = unmark_parity(raw[:cut])
        b, eb, rest = unmark_parity(raw[cut:], carry)
        assert rest == b"" and a + b == want, cut
        assert ea + tuple(len(a) + i for i in eb) == want_err, cut
    # three single-octet reads of one mark
    out, errs, carry = b"", (), b""
    for octet in (b"\xFF", b"\x00", b"\x7E"):
        o, e, carry = unmark_parity(octet, carry)
        errs += tuple(len(out) + i for i in e)
        out += o
    assert (out, errs, carry) == (b"\x7E", (0,), b"")


# -- the FDL master ------------------------------------------------------------------------------

def _good_reply():
    return F.encode(F.Frame(F.SD2, 2, 3, F.response_fc(F.DL), bytes([1, 2, 3, 0xFF, 5, 6])))


def test_flagged_octet_anywhere_in_a_reply_is_one_illegal_and_one_retry():
    good = _good_reply()
    for k in range(len(good)):
        fm = FdlMaster(BusParams.for_baud(19200, retries=1))
        fm.request(3, F.SRD_HIGH, b"\x00\x01", now=0.0, expect_octets=len(good))
        # the octet value is even right (the parity bit itself flipped): still refused
        assert fm.feed(LineOctets(good, (k,)), 0.001) is None, k
        retry = fm.expire(1.0)
        assert isinstance(retry, tuple), k
        out = fm.feed(good, 1.001)
        assert out.kind == REPLY and (out.retries, out.illegal) == (1, 1), k
        c = fm.counters[3]
        assert (c.retries, c.illegal, c.no_answer) == (1, 1, 0), k


def test_flagged_octet_after_a_complete_reply_does_not_spoil_it():
    good = _good_reply()
    fm = FdlMaster(BusParams.for_baud(19200, retries=1))
    fm.request(3, F.SRD_HIGH, b"\x00\x01", now=0.0, expect_octets=len(good))
    out = fm.feed(LineOctets(good + b"\x00", (len(good),)), 0.001)
    assert out.kind == REPLY and (out.retries, out.illegal) == (0, 0)


# -- through SerialLink and the poller: a fake marking port in front of the simulated bus ---------

class FakeMarkingPort(P.ParityMarkingSerial):
    """A ParityMarkingSerial whose 'kernel' is a SimBus: replies come PARMRK-escaped, and
    mark_next(k) delivers octet k of the next reply as 0xFF 0x00 X (parity error)."""

    def __init__(self):
        super().__init__()
        self.marks_parity = True
        self.bus = None
        self.sim = build_bus("sim://?stations=3:fuji-g1")
        self.raw = bytearray()
        self.marks: list[int] = []

    @property
    def in_waiting(self):
        return len(self.raw)

    def _read_raw(self, size):
        out = bytes(self.raw[:size])
        del self.raw[:size]
        return out

    def write(self, data):
        for r in self.sim.receive(bytes(data), 0.0):
            mark = self.marks.pop(0) if self.marks else None
            for i, b in enumerate(r.octets):
                if i == mark:
                    self.raw += bytes([0xFF, 0x00, b])
                elif b == 0xFF:
                    self.raw += b"\xFF\xFF"
                else:
                    self.raw.append(b)
        self.sim.outbox.clear()
        return len(data)

    def reset_input_buffer(self):
        self._carry = b""
        self.raw.clear()

    def close(self):
        pass


def test_marked_reply_reaches_the_master_as_one_illegal_and_one_retry(monkeypatch):
    port = FakeMarkingPort()
    monkeypatch.setattr(serial_link, "open_serial", lambda *a, **k: port)
    link = serial_link.SerialLink("/dev/ttyFAKE0", 19200)
    m = Master(link, BusParams.for_baud(19200, retries=1))
    model = port.sim.slave(3).model
    m.add_station(3, SlaveConfig(ident=model.ident, cfg=model.real_cfg(), wd_ms=500))
    m.bring_up(3)            # its first Slave_Diag carries master 0xFF: escaped, then unescaped
    assert m.stations[3].last_diag is not None
    c = m.fdl.counters[3]
    assert (c.illegal, c.retries) == (0, 0)
    for _ in range(3):
        m.exchange(3, bytes(12))
    port.marks.append(4)     # an octet inside the next reply arrives with a parity error
    m.exchange(3, bytes(12))
    assert m.stations[3].fresh_inputs
    assert (c.illegal, c.retries, c.no_answer) == (1, 1, 0)
    assert port.parity_errors == 1


# -- the real thing on a pty: the line discipline escapes 0xFF once PARMRK is on --------------------

def test_marking_port_on_a_pty_unescapes_real_ff_octets(monkeypatch):
    mfd, sfd = pty.openpty()
    name = os.ttyname(sfd)
    monkeypatch.setattr(serial_link, "_is_pty", lambda port: False)
    link = serial_link.SerialLink(name, 19200)
    try:
        ser = link.ser
        assert isinstance(ser, P.ParityMarkingSerial) and ser.marks_parity
        iflag = termios.tcgetattr(ser.fd)[0]
        assert iflag & termios.INPCK and iflag & termios.PARMRK
        assert not iflag & (termios.IGNPAR | termios.ISTRIP)
        os.write(mfd, b"\x68\xFF\x00\xFF\xFF\x16")
        got = b""
        while len(got) < 6:
            chunk = link.read(link.now() + 2.0)
            assert chunk, got
            got += chunk
        assert got == b"\x68\xFF\x00\xFF\xFF\x16"
    finally:
        link.close()
        os.close(mfd)
        os.close(sfd)


def test_ptys_and_urls_are_not_marked():
    mfd, sfd = pty.openpty()
    try:
        ser = serial_link.open_serial(os.ttyname(sfd), 19200)
        assert not isinstance(ser, P.ParityMarkingSerial)
        ser.close()
    finally:
        os.close(mfd)
        os.close(sfd)
    for url in ("loop://", "sim://"):
        ser = serial_link.open_serial(url, 19200)
        assert not isinstance(ser, P.ParityMarkingSerial)
        ser.close()


def test_simulated_station_drops_a_request_with_a_flagged_octet():
    """`pdrive sim --port` on a real device reads through the marking port too: a request with a
    parity error is not executed (a real station discards it), the next clean one is."""
    bus = build_bus("sim://?stations=3:fuji-g1")
    req = F.encode(F.Frame(F.SD2, 3, 2, F.request_fc(F.SRD_HIGH, fcb=True, fcv=False), b"", 60, 62))
    for k in range(len(req)):
        before = bus.slave(3).stats["requests"]
        assert bus.receive(LineOctets(req, (k,)), 0.0) == [], k
        assert bus.slave(3).stats["requests"] == before, k
    n_err = bus.stats.framing_errors
    assert n_err >= len(req)
    replies = bus.receive(req, 0.0)
    assert len(replies) == 1 and bus.slave(3).stats["requests"] == 1
