"""One DP-V1 class-1 acyclic call (MSAC_C1 Read or Write) as the master runs it, sans-IO.

The master sends the request PDU in an SRD to DSAP 51 from SSAP 51 (high priority with the frame count
bit, as its other DP services), then polls with the same SAPs and an empty DU until the slave answers
with data; the short acknowledgement SC (or a reply without data) means "not ready yet". The call is
bounded by the slave's C1_Response_Timeout (GSD, in 10 ms units), counted as the slave counts it: from
the acknowledgement of the request, not from the moment the master decided to ask (at 19.2k the
request telegram alone takes longer than a 10 ms timeout). It fails with C1Timeout only when a poll
sent at or after that deadline still finds no answer: a master stalled past the deadline (a loaded
machine) asks once more before it gives up, so a slave that answered in time is never called late.
A DP-V1 slave leaves data exchange when its class-1 connection times out (IEC 61158-6's MSAC1S machine
stops with the cyclic one), so the poller restarts the station's start-up then.

C1Call holds the state; dp/poller.py's Master.c1_call does the waiting and keeps the other stations'
cycles (and this station's) going between the polls.
"""

from __future__ import annotations

from profidrive_cli import BusError
from profidrive_cli.dp import msac1 as M
from profidrive_cli.fdl import frames as F


#: polls in a row without any reply (each after its FDL retries) that end a call: the slave is gone
#: or the line is broken, not late with its answer
SILENT_POLLS = 3


class C1Error(BusError):
    """A negative MSAC_C1 answer: .function, .decode, .code1, .code2 (msac1.error_text says them)."""

    def __init__(self, message: str, pdu: M.Msac1Pdu):
        super().__init__(message)
        self.pdu = pdu
        self.function = pdu.function
        self.decode, self.code1, self.code2 = pdu.error or (0, 0, 0)

    @property
    def busy(self) -> bool:
        """'state conflict' or 'resource busy': the slave asks to be asked again."""
        return self.decode == 0x80 and self.code1 in (M.STATE_CONFLICT, M.RESOURCE_BUSY)


class C1Timeout(BusError):
    """No MSAC_C1 answer within C1_Response_Timeout."""


class C1Call:
    """One Read or Write: request() is the DU of the next SRD (the PDU first, then empty polls),
    feed() takes what came back and says whether the call is over."""

    def __init__(self, address: int, pdu: bytes, now: float, timeout_s: float):
        self.address = address
        self.pdu = bytes(pdu)
        self.request_pdu = M.decode_pdu(self.pdu, is_request=True)
        self.deadline = now + timeout_s        # until the request is acknowledged: its own bound
        self.timeout_s = timeout_s
        self.sent = False
        self.polls = 0
        self.asked_at = now
        self.silent = 0                        # polls in a row that got no reply at all

    def request(self, now: float | None = None) -> bytes:
        """The DU of the next telegram, sent at `now` (the master's clock; None: the call's last)."""
        if now is not None:
            self.asked_at = now
        if self.sent:
            self.polls += 1
            return b""
        return self.pdu

    def feed(self, frame: F.Frame | None, now: float) -> M.Msac1Pdu | None:
        """The answer PDU (a negative one raises C1Error), or None: poll again. A request that got
        no reply at all is sent again (the FDL retries are spent by then); the deadline holds."""
        what = f"station {self.address}: DP-V1 {self.request_pdu.describe()}"
        if frame is not None and frame.sd != F.SC:
            status = frame.fc & 0x0F
            if status == F.RS:
                raise BusError(f"{what}: SAP 51 not enabled (RS): the slave is not DP-V1, or its "
                               "Set_Prm did not set DPV1_Enable, or it is not in data exchange")
            if status in F.NEGATIVE:
                raise BusError(f"{what}: answered {F.describe_fc(frame.fc)}")
        if frame is not None:
            if not self.sent:
                self.sent = True
                self.deadline = now + self.timeout_s       # the slave's clock starts at its ack
            if frame.sd != F.SC and frame.data:
                if frame.dsap != M.SAP_C1 and frame.ssap != M.SAP_C1:
                    raise BusError(f"{what}: the answer came from SAP {frame.ssap}, not 51")
                try:
                    pdu = M.decode_pdu(frame.data, is_request=False)
                except M.Msac1Error as e:
                    raise BusError(f"{what}: bad answer: {e}") from None
                if pdu.function != self.request_pdu.function:
                    raise BusError(f"{what}: answered with {pdu.name}")
                if pdu.error is not None:
                    raise C1Error(f"{what}: {M.error_text(*pdu.error)}", pdu)
                return pdu
        if frame is None and self.sent:
            # a poll lost on the line (its FDL retries spent) says nothing of the slave's answer:
            # asked again, whatever the deadline, up to SILENT_POLLS in a row
            self.silent += 1
            if self.silent >= SILENT_POLLS:
                raise C1Timeout(f"{what}: no reply to {self.silent} polls in a row")
            return None
        self.silent = 0
        late = self.asked_at >= self.deadline if self.sent else now >= self.deadline
        if late:
            raise C1Timeout(f"{what}: no answer within {self.timeout_s * 1000:g} ms "
                            "(C1_Response_Timeout)")
        return None


__all__ = ["SILENT_POLLS", "C1Call", "C1Error", "C1Timeout"]
