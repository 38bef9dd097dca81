"""Master side of FDL request/reply cycles, sans-IO.

    fm = FdlMaster(params, address=2)
    out, deadline = fm.request(da, function, data, dsap, ssap, now)   # octets to send
    ... fm.feed(octets, now) -> Outcome | None     (None: keep waiting until deadline)
    ... fm.expire(now)       -> (retry octets, new deadline) or Outcome(no answer)

The engine keeps the FCB per station (reference §2.3), repeats the same FCB on a retry, restarts the
sequence (FCV=0, FCB=1) after a request that got no valid reply at all, checks that a reply comes from
the addressed station and is addressed to us, and counts what it saw.

Octets the link flags as received with a parity or framing error (LineOctets.errors, link/parity.py)
spoil the attempt like a telegram that broke: one illegal frame plus one retry.

Receiving: octets that cannot start a telegram (line noise before a reply) are skipped and counted
once per run as one illegal frame; the reply that follows is taken. A telegram that starts and then
breaks (FCS, length, end delimiter) spoils the rest of the attempt: everything up to the deadline is
dropped (reference §2: resynchronise on an idle line) and the request is repeated. So each corrupt
reply costs exactly one illegal frame plus one retry, a reply from the wrong station the same, a
missing or late reply one retry, and noise before a good reply one illegal frame only.

Every attempt has a hard cap (attempt_cap: the request, slot time, longest reply, TSYN and the
latency margin), so a request takes at most (1 + retries) times that (request_cap): a babbling line
that keeps sending octets cannot push the deadline out for ever; at the cap the attempt has failed,
its noise counted as illegal, and after the last retry the request counts as not answered.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Final, Literal

from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.fast import DxTemplate, dx_template
from profidrive_cli.fdl.fcb import MasterFcb
from profidrive_cli.fdl.timing import BusParams

REPLY, NO_ANSWER = "reply", "no answer"
MORE: Final = "more"       # dx_feed(): the beginning of the expected reply, wait for the rest

#: FCS + ED for every FCS value (the fast path's request tail)
_TAILS = tuple(bytes((i, F.ED)) for i in range(256))
#: the Data_Exchange request's FC by MasterFcb state (MasterFcb.fc, as dx_request reads it inline):
#: the first after a (re)start, then FCB set / clear, FCV set
_DX_FC_FIRST: Final = F.request_fc(F.SRD_HIGH, fcb=True, fcv=False)
_DX_FC_FCB: Final = F.request_fc(F.SRD_HIGH, fcb=True, fcv=True)
_DX_FC_NO_FCB: Final = F.request_fc(F.SRD_HIGH, fcb=False, fcv=True)
_ED: Final = F.ED


@dataclass
class Outcome:
    kind: str                      # REPLY or NO_ANSWER
    frame: F.Frame | None = None   # the reply (SC frames included)
    retries: int = 0
    illegal: int = 0               # corrupt frames / foreign replies seen during this request


@dataclass
class StationCounters:
    """What the master saw of one station.

    requests      requests sent (a retry is not a new request)
    retries       repeats after a missing, late, corrupt or foreign reply
    no_answer     requests that got no valid reply after all retries
    illegal       corrupt telegrams, noise runs, replies from another station
    rs/rr/ue      negative replies: service not activated / no resources / user error
    dh            Data_Exchange replies announcing new diagnosis (DH/RDH): one per event
    reparams      start-ups re-run after the station had reached Data_Exchange (RS, silence,
                  Prm_Req, link restored)
    """
    requests: int = 0
    retries: int = 0
    no_answer: int = 0
    illegal: int = 0
    rs: int = 0
    rr: int = 0
    ue: int = 0
    reparams: int = 0
    diag_reads: int = 0
    data_exchanges: int = 0
    dh: int = 0
    extra: dict[str, int] = field(default_factory=dict)

    def as_dict(self) -> dict[str, int]:
        d = {k: v for k, v in self.__dict__.items() if k != "extra"}
        d.update(self.extra)
        return d


#: short names for the compact one-line form, in display order
_BRIEF = (("retries", "retry"), ("no_answer", "no answer"), ("illegal", "illegal"), ("rs", "RS"),
          ("rr", "RR"), ("ue", "UE"), ("dh", "DH"), ("reparams", "reparam"))


def format_counters(c: "StationCounters | dict[str, int] | None") -> str:
    """'12 req, 1 retry, 1 illegal' — requests always, the error counters when not zero."""
    d = c.as_dict() if isinstance(c, StationCounters) else dict(c or {})
    parts = [f"{d.get('requests', 0)} req"]
    parts += [f"{d[k]} {name}" for k, name in _BRIEF if d.get(k)]
    return ", ".join(parts)


class FdlMaster:
    def __init__(self, params: BusParams, address: int = F.DEFAULT_MASTER):
        if not 0 <= address <= 125:
            raise ValueError(f"master address {address} outside 0..125")
        self.params = params
        self.address = address
        self._fcb: dict[int, MasterFcb] = {}
        self.counters: dict[int, StationCounters] = {}
        self._pending: bytes | None = None
        self._saps: tuple[int, int] | None = None
        self._da = 0
        self._uses_fcb = False
        self._retries_left = 0
        self._retries = 0
        self._illegal = 0
        self._in_garbage = False
        self._spoilt = False
        self._rx = F.Receiver()
        self.deadline = 0.0
        self._timeout = 0.0
        self._cap = 0.0               # the most one attempt may take, whatever arrives
        self._hard = float("inf")     # the end of the attempt in progress (its start + _cap)
        self._expect = 255
        self._dx: DxTemplate | None = None           # the fast path's template for the request
        self._dx_cache: dict[tuple[int, int, int, int, int], DxTemplate] = {}
        self._dx_params: BusParams | None = None     # the params the cached templates' times are for

    def counters_for(self, da: int) -> StationCounters:
        c = self.counters.get(da)
        if c is None:
            c = self.counters[da] = StationCounters()
        return c

    def reset_station(self, da: int) -> None:
        """Station (re)initialised: its next request starts a new FCB sequence."""
        self._fcb.pop(da, None)

    @property
    def busy(self) -> bool:
        """A request is waiting for its reply."""
        return self._pending is not None

    def missing(self) -> int:
        """Octets still to come for the reply being received (0: none started)."""
        if self._pending is None or self._spoilt or not len(self._rx):
            return 0
        return F.missing(self._rx.buf)

    def telegram_octets(self) -> int:
        """Length of the reply telegram being received, as far as its start delimiter and length
        octet tell (0: none started)."""
        rest = self.missing()
        return len(self._rx.buf) + rest if rest else 0

    def abort(self) -> None:
        """Forget the request in progress (the link went away under it)."""
        self._pending = None
        self._rx.reset()
        self._in_garbage = self._spoilt = False

    def request(self, da: int, function: int, data: bytes = b"", dsap: int | None = None,
                ssap: int | None = None, now: float = 0.0, expect_octets: int = 255) -> tuple[bytes, float]:
        uses_fcb = function in (F.SRD_LOW, F.SRD_HIGH, F.SDA_LOW, F.SDA_HIGH)
        if uses_fcb:
            fcb = self._fcb.get(da)
            if fcb is None:
                fcb = self._fcb[da] = MasterFcb()
            fc = fcb.fc(function)
        else:
            fc = F.request_fc(function)
        frame = F.Frame(F.SD2, da, self.address, fc, bytes(data), dsap, ssap)
        self._pending = F.encode(frame)
        #: a reply with SAPs must carry ours swapped (IEC 61158-4: its DSAP our SSAP, its SSAP our
        #: DSAP); one that does not is a late reply to an earlier request
        self._saps = (ssap, dsap) if dsap is not None and ssap is not None else None
        self._dx = None
        self._da = da
        self._uses_fcb = uses_fcb
        self._retries_left = self.params.retries
        self._retries = 0
        self._illegal = 0
        self._in_garbage = False
        self._spoilt = False
        self._rx.reset()
        # the first reply octet must start within the slot time after our last octet; once octets
        # arrive, the deadline moves out by the wire time of the rest of the longest reply
        self._timeout = (self.params.chars(len(self._pending)) + self.params.slot_seconds
                         + self.params.link_latency)
        self._expect = expect_octets
        self._cap = self.attempt_cap(len(self._pending), expect_octets)
        self._hard = now + self._cap
        self.deadline = now + self._timeout
        self.counters_for(da).requests += 1
        return self._pending, self.deadline

    # -- the Data_Exchange fast path (fdl/fast.py) ---------------------------------------------------
    def dx_request(self, da: int, outputs: bytes, now: float, n_in: int) -> bytes:
        """request(da, SRD_HIGH, outputs, None, None, now, n_in + 9) from a precomputed template:
        the same octets, FCB, deadlines and counters, without building a Frame. Returns the octets
        (the deadline is self.deadline). The reply goes to dx_feed() first."""
        fcb = self._fcb.get(da)
        if fcb is None:
            fcb = self._fcb[da] = MasterFcb()
        # fcb.fc(F.SRD_HIGH), inline (the per-cycle path)
        fc = (_DX_FC_FCB if fcb._fcb else _DX_FC_NO_FCB) if fcb._started else _DX_FC_FIRST
        p = self.params
        if self._dx_params is not p:
            self._dx_cache.clear()
            self._dx_params = p
        key = (da, fc, len(outputs), n_in, self.address)
        t = self._dx_cache.get(key)
        if t is None:
            t = self._dx_cache[key] = dx_template(self.address, da, fc, len(outputs), n_in)
            t.request_len = n = len(t.head) + len(outputs) + 2
            t.timeout = p.chars(n) + p.slot_seconds + p.link_latency
            t.cap = self.attempt_cap(n, n_in + 9)
        self._pending = out = t.head + outputs + _TAILS[(t.head_fcs + sum(outputs)) & 0xFF]
        self._dx = t
        self._saps = None
        self._da = da
        self._uses_fcb = True
        self._retries_left = p.retries
        self._retries = self._illegal = 0
        self._in_garbage = self._spoilt = False
        if self._rx.buf:
            self._rx.reset()
        self._timeout = t.timeout
        self._expect = n_in + 9
        self._cap = t.cap
        self._hard = now + t.cap
        self.deadline = now + t.timeout
        c = self.counters.get(da)
        if c is None:
            c = self.counters[da] = StationCounters()
        c.requests += 1
        return out

    def dx_feed(self, data: bytes, now: float) -> bytes | Literal["more"] | None:
        """The fast check of a Data_Exchange reply (after dx_request). Returns

            the input octets   the octets so far are exactly the DL reply the template expects
                               (length, header, FCS, ED; no octet flagged by the UART): the request
                               is done as feed() would finish it (FCB confirmed, counters)
            MORE               a true beginning of that reply: kept as feed() would keep it (the
                               same receive buffer and deadline), wait for the rest
            None               nothing taken: give `data` to feed(), which finds the same state
                               as if it had had every octet of this attempt
        """
        t = self._dx
        if (t is None or self._pending is None or self._spoilt
                or (type(data) is not bytes and getattr(data, "errors", None))):
            return None
        buf = self._rx.buf
        got = bytes(buf) + data if buf else data
        head = t.reply_head
        if len(got) != t.reply_len:
            if len(got) < t.reply_len and head.startswith(got[:len(head)]):
                # what feed() does with the beginning of a telegram: keep it, wait for the rest
                buf += data
                self._extend(now + self.params.chars(self._expect + 9) + self.params.link_latency)
                return MORE
            return None
        end = t.reply_data_end
        if not got.startswith(head) or got[end + 1] != _ED:
            return None
        inputs = got[len(head):end]
        if (t.reply_fcs + sum(inputs)) & 0xFF != got[end]:
            return None
        if buf:
            buf.clear()
        da = self._da
        fcb = self._fcb[da]                 # fcb.confirm(), inline (the per-cycle path)
        fcb._started = True
        fcb._fcb = not fcb._fcb
        if self._retries or self._illegal:
            c = self.counters[da]
            c.retries += self._retries
            c.illegal += self._illegal
        self._pending = None
        self._in_garbage = False
        return bytes(inputs)

    def sent(self, now: float) -> float:
        """The request (or its retry) was handed to the link at `now`: the reply timeout counts
        from here (a write that took long must not eat the slot time). Returns the deadline."""
        if self._pending is not None:
            self._hard = now + self._cap
            self.deadline = min(now + self._timeout, self._hard)
        return self.deadline

    def attempt_cap(self, request_octets: int, expect_octets: int = 255) -> float:
        """The most one attempt may take, whatever arrives (a babbling line must not hold the
        master): the request, the slot time, the longest reply, TSYN and the link's latency margin.
        Then the attempt has failed (its noise counted as illegal) and the request is repeated or,
        after the last retry, counts as not answered."""
        p = self.params
        reply = min(expect_octets + 9, 255)
        return p.chars(request_octets) + p.slot_seconds + p.chars(reply) + p.tsyn + p.link_latency

    def request_cap(self, request_octets: int, expect_octets: int = 255) -> float:
        """The most a whole request may take: (1 + retries) attempts (plus the idle times the
        poller keeps between them)."""
        return (1 + self.params.retries) * self.attempt_cap(request_octets, expect_octets)

    def _extend(self, t: float) -> None:
        """Keep waiting until at least `t`, never beyond the cap of the attempt in progress."""
        self.deadline = min(max(self.deadline, t), self._hard)

    def send_no_reply(self, da: int, function: int, data: bytes = b"", dsap: int | None = None,
                      ssap: int | None = None) -> bytes:
        """SDN (e.g. Global_Control broadcast): FCB/FCV 0, nothing to wait for."""
        return F.encode(F.Frame(F.SD2, da, self.address, F.request_fc(function), bytes(data), dsap, ssap))

    def feed(self, data: bytes, now: float) -> Outcome | None:
        if self._pending is None:
            return None
        errors = getattr(data, "errors", None)
        if errors:
            # octets the UART flagged (parity / framing error, link/parity.py): what is complete
            # before the first one still counts; from there on the attempt is spoilt
            res = self.feed(bytes(data[:errors[0]]), now)
            if res is not None or self._pending is None:
                return res
            self._line_error(now)
            return None
        if self._spoilt:
            # a telegram broke in this attempt: drop everything until the line is idle again
            self._extend(now + self._idle_wait())
            return None
        self._rx.feed(data)
        while True:
            r = self._rx.next()
            if r is None:
                if len(self._rx):
                    self._extend(now + self.params.chars(self._expect + 9) + self.params.link_latency)
                return None
            if isinstance(r, F.FrameError):
                if r.kind == F.FrameError.GARBAGE:
                    # octets that cannot start a telegram (noise): skip them, one count per run
                    if not self._in_garbage:
                        self._illegal += 1
                        self._in_garbage = True
                    continue
                # a telegram started and broke: its remaining octets could fake a start
                # delimiter, so nothing more is taken in this attempt (the retry repeats it)
                if not self._in_garbage:
                    self._illegal += 1
                self._spoilt = True
                self._rx.reset()
                self._extend(now + self._idle_wait())
                return None
            self._in_garbage = False
            if r.sd == F.SC:
                return self._done(r)
            if r.sd == F.SD4 or r.is_request or r.da != self.address or r.sa != self._da:
                self._illegal += 1          # token, another master's request, a foreign reply
                continue
            if r.dsap is not None and self._saps is not None and (r.dsap, r.ssap) != self._saps:
                self._illegal += 1          # a late reply to another service of this station
                continue
            return self._done(r)

    def _line_error(self, now: float) -> None:
        """A character arrived with a parity or framing error: the telegram it belongs to is
        corrupt, treated like one that broke (one illegal frame, nothing more taken in this
        attempt, then the retry)."""
        if self._spoilt:
            self._extend(now + self._idle_wait())
            return
        if not (self._in_garbage and not len(self._rx)):
            self._illegal += 1          # (a noise run already counted is not counted twice)
        self._spoilt = True
        self._rx.reset()
        self._extend(now + self._idle_wait())

    def _idle_wait(self) -> float:
        """How long the line must stay quiet after garbage before a retry: TSYN and one character,
        plus what the link adds."""
        return self.params.tsyn + self.params.chars(1) + self.params.link_latency

    def _done(self, frame: F.Frame) -> Outcome:
        if self._uses_fcb:
            self._fcb[self._da].confirm()
        c = self.counters_for(self._da)
        c.retries += self._retries
        c.illegal += self._illegal
        if frame.sd != F.SC:
            st = frame.fc & 0x0F
            if st == F.RS:
                c.rs += 1
            elif st == F.RR:
                c.rr += 1
            elif st == F.UE:
                c.ue += 1
            elif st in (F.DH, F.RDH):
                c.dh += 1
        self._pending = None
        return Outcome(REPLY, frame, self._retries, self._illegal)

    def expire(self, now: float) -> tuple[bytes, float] | Outcome | None:
        """Deadline passed without a valid reply: (octets, deadline) to retry, or the NO_ANSWER outcome."""
        if self._pending is None:
            return None
        if self._retries_left > 0:
            self._retries_left -= 1
            self._retries += 1
            self._rx.reset()
            self._in_garbage = False
            self._spoilt = False
            self._hard = now + self._cap
            self.deadline = now + self._timeout
            return self._pending, self.deadline
        if self._uses_fcb:
            # failed transaction: the next request to this station restarts the FCB sequence
            self._fcb[self._da].failed()
        c = self.counters_for(self._da)
        c.retries += self._retries
        c.illegal += self._illegal
        c.no_answer += 1
        self._pending = None
        return Outcome(NO_ANSWER, None, self._retries, self._illegal)
