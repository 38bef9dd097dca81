"""The Data_Exchange fast path: one cycle of a station already in data exchange, sans Frame objects.

    Master.step(st) -> exchange_fast(master, st)   when master.fast_dx and st.dx_ready(now)

The request comes from a template per FCB state (FdlMaster.dx_request: header + outputs + FCS/ED,
fdl/fast.py); a reply that is exactly the expected DL telegram is taken by one prefix compare and
its length, FCS and ED (FdlMaster.dx_feed; a reply in pieces is collected as the general engine
collects it), the FCB, counters and inputs updated in place (StationMachine.took_inputs). Anything
else - no reply, a corrupt or foreign one, noise, DH/RDH, RS, an SC, another length, octets the UART
flagged - goes to the general engine unchanged (FdlMaster.feed/expire in Master._await,
StationMachine.on_outcome), so retries, illegal frames, no-answer, the FCB restart after a failure
and the per-attempt cap are counted exactly as before. Waiting is the poller's (Master._await):
the same reads, sleeps and deadlines; on a link without µs timing the wait for the reply is one
sleep to its wire end plus the lag the link's replies have had (Master.reply_lag, learned here). Master.fast_dx = False sends every request the general way
(the tests compare the two).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Callable, Literal, Protocol

from profidrive_cli.dp.station import Event, StationMachine
from profidrive_cli.fdl.timing import frame_octets
from profidrive_cli.link.base import LinkLost

if TYPE_CHECKING:
    from profidrive_cli.dp.station import DpRequest
    from profidrive_cli.fdl.master import FdlMaster, Outcome
    from profidrive_cli.fdl.timing import BusParams
    from profidrive_cli.link.base import Link


class FastMaster(Protocol):
    """What the fast path uses of dp.poller.Master (which imports this module)."""

    link: Link
    fdl: FdlMaster
    reply_lag: float
    _await_reads: int
    _line_free_at: float
    on_event: Callable[[int, Event], object] | None

    def _await(self, da: int, dx: bool,
               first: tuple[bytes, float, bytes | Literal["more"] | None] | None = None
               ) -> Outcome | bytes: ...

    def _wait_idle(self) -> None: ...

    def _sent(self, out: bytes) -> None: ...

    def _link_lost(self, e: LinkLost) -> LinkLost: ...

    def on_outcome(self, st: StationMachine, req: DpRequest, res: Outcome) -> None: ...


def exchange_fast(m: FastMaster, st: StationMachine) -> bool:
    """One Data_Exchange for `st` on dp.poller.Master `m`; True (a request was sent)."""
    link = m.link
    da = st.address
    try:
        if link.instant:
            out = m.fdl.dx_request(da, st.outputs, link.now(), st.input_len)
            link.write(out)
            res = _reply(m, link, da)
        elif link.us_timing:
            m._wait_idle()
            out = m.fdl.dx_request(da, st.outputs, link.now(), st.input_len)
            link.write(out)
            m._sent(out)
            res = _reply(m, link, da)
        else:
            # a port without µs timing (pty, USB adapter, TCP): one sleep until the whole reply
            # can be there (request, min TSDR, reply on the wire, and the lag this link's replies
            # have had), then one read, instead of waking for its first octet and again for the rest
            m._wait_idle()
            fdl = m.fdl
            out = fdl.dx_request(da, st.outputs, link.now(), st.input_len)
            link.write(out)
            m._sent(out)
            p = fdl.params
            now = link.now()
            link.sleep(min(p.chars(len(out) + frame_octets(st.input_len)) + p.min_tsdr / p.baud
                           + m.reply_lag, fdl.deadline - now))
            res = _reply(m, link, da)
            if type(res) is bytes:
                _learn_lag(m, p)
    except LinkLost as e:
        raise m._link_lost(e) from None
    if type(res) is bytes:
        st.took_inputs(res)
        if m.on_event is not None:
            m.on_event(da, Event("inputs", "", res))
    else:
        # res is an Outcome here: mypy narrows `type(res) is bytes` in the if branch only, and an
        # isinstance() would add a call to the benchmarked path
        m.on_outcome(st, st.dx_request(), res)  # type: ignore[arg-type]
    return True


def _reply(m: FastMaster, link: Link, da: int) -> Outcome | bytes:
    """The reply to the Data_Exchange just sent: the first read and its fast check here (the whole
    expected reply in one read: the inputs, with what Master._await does then), anything else
    carried on by Master._await from that read."""
    fdl = m.fdl
    chunk = link.read(fdl.deadline)
    now = link.now()
    got = fdl.dx_feed(chunk, now) if chunk else None
    if type(got) is bytes:
        if not link.instant:
            m._line_free_at = now + fdl.params.tid1_seconds
        m._await_reads = 1
        return got
    return m._await(da, True, (chunk, now, got))


#: the learned reply lag moves by these steps per exchange: down while replies are whole at the
#: first read, up when one needed another read. Their ratio makes it the 95th percentile of the lag
#: (one reply in twenty read in two parts); a single very late reply moves it by one step only.
LAG_DOWN_S = 0.000002
LAG_UP_S = 19 * LAG_DOWN_S


def _learn_lag(m: FastMaster, p: BusParams) -> None:
    """The lag a link adds to replies (a pty's other end, a USB adapter's latency timer, a TCP
    converter), as the fast path's wait for a reply learns it (at most the latency margin of the
    bus parameters, which the reply deadline allows for anyway)."""
    if m._await_reads == 1:
        if m.reply_lag > 0.0:
            m.reply_lag = max(0.0, m.reply_lag - LAG_DOWN_S)
    else:
        m.reply_lag = min(m.reply_lag + LAG_UP_S, p.link_latency)
