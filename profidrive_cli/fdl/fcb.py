"""Frame count bit handling (reference §2.3), master side and slave side."""

from __future__ import annotations

from profidrive_cli.fdl.frames import FC_FCB, FC_FCV, request_fc


class MasterFcb:
    """Per-station FCB/FCV for SRD/SDA requests.

    First request after (re)start: FCV=0, FCB=1. Then FCV=1 and FCB toggles after every request that
    got a valid reply. A retry repeats the same FCB (call fc() again without confirm()).

    A transaction that failed (no valid reply after all retries) is a restart (failed()): the next
    request starts a new sequence with FCV=0, FCB=1 (reference §2.3 rule 1). Keeping the FCB instead
    (rule 2 only toggles after a valid reply) would make the next, different request look like a
    repetition to a slave that did execute the lost one: it would answer from its repeat cache
    without executing it.
    """

    __slots__ = ("_started", "_fcb")

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self._started = False
        self._fcb = True

    def fc(self, function: int) -> int:
        if not self._started:
            return request_fc(function, fcb=True, fcv=False)
        return request_fc(function, fcb=self._fcb, fcv=True)

    def failed(self) -> None:
        """The request got no valid reply after all retries: the next one restarts the sequence."""
        self.reset()

    def confirm(self) -> None:
        """The request just sent got a valid reply: the next one uses the other FCB."""
        self._started = True
        self._fcb = not self._fcb


class SlaveFcb:
    """Slave side: tells a new telegram from a repetition of the last one (same master)."""

    __slots__ = ("master", "last_fcb", "last_reply")

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.master: int | None = None
        self.last_fcb: bool | None = None
        self.last_reply: bytes | None = None

    def is_repeat(self, sa: int, fc: int) -> bool:
        """True when this request repeats the last one: resend last_reply without executing."""
        fcv = bool(fc & FC_FCV)
        fcb = bool(fc & FC_FCB)
        if not fcv:
            if fcb:          # FCV=0, FCB=1: start of a new sequence
                self.master, self.last_fcb, self.last_reply = sa, fcb, None
            return False
        repeat = (self.master == sa and self.last_fcb == fcb and self.last_reply is not None)
        if not repeat:
            self.master, self.last_fcb = sa, fcb
        return repeat

    def would_repeat(self, sa: int, fc: int) -> bool:
        """is_repeat() without changing anything (for whoever looks at a request before the slave)."""
        return (bool(fc & FC_FCV) and self.master == sa and self.last_fcb == bool(fc & FC_FCB)
                and self.last_reply is not None)

    def remember(self, reply: bytes) -> None:
        self.last_reply = reply
