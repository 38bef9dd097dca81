"""The DP master over a Link: one request/reply at a time, several stations in a cycle.

This is the only place in the protocol stack that waits: for replies (until the FDL deadline), for
the idle time the line needs before each request (TID1 after a reply, TID2 after a broadcast; the
slot time already covers TSYN after a request without reply) and for the cycle period. It waits on
the link's clock (Link.now/Link.sleep), so the virtual-time simulator runs it without real sleeping.
Everything it decides comes from the sans-IO pieces (fdl.master.FdlMaster, dp.station.StationMachine).

When the port goes away, every call raises LinkLost with the port and the counters; reconnect()
reopens the same port and brings every station back to data exchange.

Kept stations (keep()): before each request to another station -- a start-up step, a diagnosis, a
scan, an exchange of a station not yet kept -- once a kept station in data exchange has had no
request for keep_within() (a quarter of its watchdog, never later than its cycle period), every kept
station in data exchange gets one Data_Exchange with its last outputs (keep_alive()), so bringing
up station 4 never lets the watchdog of station 3 expire (pdrive run 3,4,5, the checklist's
`together`, the API's drives): one start-up request per keep round, as a PLC's bus cycle does.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from typing import Callable, Literal, overload

from profidrive_cli import BusError
from profidrive_cli.dp import msac1 as M1
from profidrive_cli.dp import services as S
from profidrive_cli.dp.acyclic import C1Call, C1Timeout
from profidrive_cli.dp.dx_fast import exchange_fast
from profidrive_cli.dp.station import (CFG_FAULT, DATA_EXCH, LOCKED, PRM_FAULT, RELEASED, STATE_WORDS,
                                       DpRequest, Event, SlaveConfig, StationMachine)
from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.master import MORE, REPLY, FdlMaster, Outcome, format_counters
from profidrive_cli.fdl.timing import BusParams
from profidrive_cli.link.base import Link, LinkLost

log = logging.getLogger("profidrive_cli.dp")

#: a kept station gets a Data_Exchange while the master is busy elsewhere once its last request is
#: this part of its DP watchdog old (the rest covers the request in progress and the other kept
#: stations' keep-alives before it)
KEEP_FRACTION = 0.25


def keep_within(wd_ms: float | None, period: float = 0.0) -> float | None:
    """How old a kept station's last request may get while the master talks to others: a quarter
    of its watchdog, never later than its cycle period (when it has one); None: neither."""
    bounds = [b for b in ((wd_ms or 0.0) / 1000.0 * KEEP_FRACTION, period or 0.0) if b > 0.0]
    return min(bounds) if bounds else None


class Master:
    def __init__(self, link: Link, params: BusParams, address: int = F.DEFAULT_MASTER):
        self.link = link
        latency = getattr(link, "latency", None)
        if latency is not None and latency != params.link_latency:
            # the link knows its own latency (the simulator: none): no margin for a USB adapter
            params = dataclasses.replace(params, link_latency=latency)
        self.fdl = FdlMaster(params, address)
        self.address = address
        self.stations: dict[int, StationMachine] = {}
        self._line_free_at = 0.0     # earliest start of the next request (TSYN / TID1 / TID2 kept)
        #: a request was repeated: the late reply to the attempt before it may still come after
        #: the one taken (a slave that answered both): dropped before the next request is sent
        self._flush_next = False
        self.on_event: Callable[[int, Event], object] | None = None    # for live views / logs
        #: stations in data exchange take the fast path (dp/dx_fast.py); False: the general
        #: engine for every request (same octets, counters and FCB states, only slower)
        self.fast_dx = True
        self._rr = 0
        #: seconds the link's replies have arrived after their wire time, learned by the fast path
        #: on links without µs timing (dp/dx_fast.py): its wait for a reply includes it
        self.reply_lag = 0.0
        self._await_reads = 0        # reads the last _await took until its outcome
        #: how often the port went away, and how often reconnect() brought it back
        self.link_losses = 0
        self.reconnects = 0
        #: stations kept in data exchange while the master talks to others (keep()):
        #: address -> the age of its last request at which it gets a keep-alive Data_Exchange
        self.kept: dict[int, float] = {}
        self._last_req: dict[int, float] = {}   # address -> when its last request went
        self._keeping = False
        #: keep-alive Data_Exchanges sent (each one is an exchange like any other: counters,
        #: inputs) and the link time they took
        self.keep_alives = 0
        self.keep_time = 0.0

    @property
    def params(self) -> BusParams:
        return self.fdl.params

    @params.setter
    def params(self, value: BusParams) -> None:
        self.fdl.params = value

    def counters(self) -> dict[int, dict[str, int]]:
        """{station address: counters dict} for every station the master has talked to."""
        return {a: c.as_dict() for a, c in sorted(self.fdl.counters.items())}

    # -- one FDL cycle -------------------------------------------------------------------------
    def _wait_idle(self) -> None:
        if self.link.instant:
            return
        now = self.link.now()
        while now < self._line_free_at:
            self.link.sleep(self._line_free_at - now)
            now = self.link.now()
        if self._flush_next:
            # what came after the reply to a repeated request is a late reply to its first attempt
            # (seen over a pty: a slave late with its first answer then answered the retry too, and
            # every later request took the reply to the one before it)
            self._flush_next = False
            self.link.flush_input()

    def _link_lost(self, e: LinkLost) -> LinkLost:
        """The port went away: forget the request in progress, say so with the counters."""
        self.fdl.abort()
        self.link_losses += 1
        counters = self.counters()
        shown = [a for a in counters if a in self.stations] or list(counters)
        detail = "; ".join(f"station {a}: {format_counters(counters[a])}" for a in shown[:8])
        if len(shown) > 8:
            detail += f"; {len(shown) - 8} more"
        msg = f"link lost: {e}" + (f" (counters: {detail})" if detail else "")
        return LinkLost(msg, getattr(e, "port", "") or self.link.name, counters)

    def transact(self, da: int, function: int, data: bytes = b"", dsap: int | None = None,
                 ssap: int | None = None, expect: int = 255) -> Outcome:
        """Send one request and wait for its reply, with the configured retries."""
        try:
            return self._transact(da, function, data, dsap, ssap, expect)
        except LinkLost as e:
            raise self._link_lost(e) from None

    def _sent(self, out: bytes) -> None:
        # timeouts and idle times count from when the write returned (a slow write must not eat
        # the slot time); after a request without reply the slot time keeps the line idle >= TSYN
        at = self.link.now()
        self.fdl.sent(at)
        self._line_free_at = at + self.fdl.params.chars(len(out)) + self.fdl.params.tsyn

    def _transact(self, da: int, function: int, data: bytes, dsap: int | None, ssap: int | None,
                  expect: int) -> Outcome:
        self._wait_idle()
        now = self.link.now()
        self._last_req[da] = now
        out, deadline = self.fdl.request(da, function, data, dsap, ssap, now, expect)
        self.link.write(out)
        if not self.link.instant:
            self._sent(out)
        return self._await(da)

    @overload
    def _await(self, da: int, dx: Literal[False] = False) -> Outcome: ...

    @overload
    def _await(self, da: int, dx: bool,
               first: tuple[bytes, float, bytes | Literal["more"] | None] | None = None
               ) -> Outcome | bytes: ...

    def _await(self, da: int, dx: bool = False,
               first: tuple[bytes, float, bytes | Literal["more"] | None] | None = None
               ) -> Outcome | bytes:
        """Wait for the reply to the request just sent (retrying it) until it has an outcome.
        dx: a request from FdlMaster.dx_request; its expected reply is taken by the fast check
        (then the input octets are returned), anything else by the general engine. first: the
        first read already made and given to the fast check (dx_fast.py: chunk, its time, what
        dx_feed said), carried on from there."""
        waited_for = 0       # length of the telegram whose rest was already waited for
        fdl = self.fdl
        reads = 0
        while True:
            res: Outcome | bytes | Literal["more"] | None
            if first is not None:
                chunk, now, res = first
                first = None
                fed = True
            else:
                chunk = self.link.read(fdl.deadline)
                now = self.link.now()
                fed = False
            reads += 1
            if chunk:
                if not fed:
                    res = fdl.dx_feed(chunk, now) if dx else None
                if res is None:
                    res = fdl.feed(chunk, now)
                elif res is MORE:
                    res = None
                if res is not None:
                    if not self.link.instant:        # (the instant simulator keeps no idle times)
                        self._line_free_at = now + fdl.params.tid1_seconds
                    self._await_reads = reads
                    # never MORE here (made None above): mypy narrows a Literal by ==, not by the
                    # `is` this per-cycle path keeps
                    return res  # type: ignore[return-value]
                rest = self.fdl.missing()
                if rest > 1 and not self.link.instant:
                    total = self.fdl.telegram_octets()
                    if total != waited_for:
                        # the rest of a telegram of known length cannot be there sooner: one wait
                        # for it instead of a wake-up per octet, and only one per telegram (a
                        # transport that delivers it in chunks, late, is then simply read: the
                        # next read wakes when the next chunk is there)
                        waited_for = total
                        self.link.sleep(min(self.fdl.params.chars(rest - 1),
                                            self.fdl.deadline - now))
                continue
            if now < self.fdl.deadline and not self.link.instant:
                continue
            # (the instant simulator answers at once: an empty read means no answer is coming)
            nxt = self.fdl.expire(now)
            if isinstance(nxt, Outcome):
                if log.isEnabledFor(logging.INFO) and da != F.BROADCAST and nxt.retries:
                    log.info("station %d: no valid reply after %d retr%s", da, nxt.retries,
                             "y" if nxt.retries == 1 else "ies")
                return nxt
            if log.isEnabledFor(logging.INFO):
                log.info("station %d: retry (no valid reply in time)", da)
            self.link.flush_input()
            self._wait_idle()
            waited_for = 0
            assert nxt is not None, "expire() with no request pending"      # (one is, here)
            out, deadline = nxt
            self.link.write(out)
            self._sent(out)
            self._flush_next = True

    def send_sdn(self, da: int, dsap: int, data: bytes) -> None:
        try:
            self._wait_idle()
            frame = self.fdl.send_no_reply(da, F.SDN_HIGH, data, dsap, S.SAP_MASTER)
            self.link.write(frame)
            now = self.link.now()
        except LinkLost as e:
            raise self._link_lost(e) from None
        # TID2 = max TSDR after an unacknowledged telegram
        p = self.fdl.params
        self._line_free_at = now + p.chars(len(frame)) + p.tid2 / p.baud

    # -- single services (scan, diag, io) ------------------------------------------------------
    def fdl_status(self, da: int) -> F.Frame | None:
        """FDL status request (live-list probe): the reply frame, or None when nobody answered."""
        self.keep_alive(da)
        res = self.transact(da, F.FDL_STATUS, expect=6)
        return res.frame if res.kind == REPLY else None

    def slave_diag(self, da: int, wake: bool = False) -> S.SlaveDiag | None:
        """The station's diagnosis; None when it does not answer. wake: first contact with a
        station (diag, io, a drive command's start-up): when it is silent, FDL status probes up to
        dp/scan.py's WARMUP_PROBES wake a slave still searching the baud rate, then one more ask."""
        self.keep_alive(da)
        res = self.transact(da, F.SRD_HIGH, b"", S.SAP_SLAVE_DIAG, S.SAP_MASTER, 250)
        if wake and res.kind != REPLY:
            from profidrive_cli.dp.scan import wake as wake_up
            if wake_up(self, da)[0] is not None:
                res = self.transact(da, F.SRD_HIGH, b"", S.SAP_SLAVE_DIAG, S.SAP_MASTER, 250)
        f = res.frame
        if res.kind != REPLY or f is None or f.sd == F.SC:
            return None
        if (f.fc & 0x0F) not in (F.DL, F.DH):
            raise BusError(f"station {da}: Slave_Diag answered {F.describe_fc(f.fc)}")
        try:
            return S.SlaveDiag.decode(f.data)
        except S.ServiceError as e:
            raise BusError(f"station {da}: {e}") from None

    def get_cfg(self, da: int) -> bytes | None:
        self.keep_alive(da)
        res = self.transact(da, F.SRD_HIGH, b"", S.SAP_GET_CFG, S.SAP_MASTER, 250)
        f = res.frame
        if res.kind != REPLY or f is None or f.sd == F.SC:
            return None
        if (f.fc & 0x0F) not in (F.DL, F.DH):
            return None
        return f.data

    def global_control(self, command: int = 0, group: int = 0, da: int = F.BROADCAST) -> None:
        self.send_sdn(da, S.SAP_GLOBAL_CONTROL, S.GlobalControl(command, group).encode())

    # -- cyclic operation -----------------------------------------------------------------------
    def add_station(self, address: int, config: SlaveConfig) -> StationMachine:
        if not 0 <= address <= 125:
            raise BusError(f"station address {address} outside 0..125")
        self.fdl.reset_station(address)
        st = StationMachine(address, config, self.address, self.fdl.counters_for(address))
        self.stations[address] = st
        return st

    def _emit(self, address: int, events: list[Event]) -> None:
        if log.isEnabledFor(logging.INFO):
            for e in events:
                if e.kind != "inputs":
                    log.info("station %d: %s%s", address, e.text or e.kind,
                             "" if e.kind == "state" else f" ({e.kind})")
        if self.on_event:
            for e in events:
                self.on_event(address, e)

    def step(self, st: StationMachine) -> bool:
        """One request for one station (if it wants one now). True if something was sent.
        Anything but the cycle of a kept station in data exchange lets the kept ones that are
        due have their keep-alive first (keep_alive)."""
        if self.kept and not (st.address in self.kept and st.in_data_exchange):
            self.keep_alive(st.address)
        now = self.link.now()
        if self.fast_dx and st.dx_ready(now):
            self._last_req[st.address] = now
            return exchange_fast(self, st)
        req = st.next_request(now)
        if req is None:
            return False
        if req.service in ("Set_Prm",):
            self.fdl.reset_station(st.address) if st.state == "start" else None
        res = self.transact(st.address, req.function, req.data, req.dsap, req.ssap, req.expect)
        self.on_outcome(st, req, res)
        return True

    def on_outcome(self, st: StationMachine, req: DpRequest, res: Outcome) -> None:
        """Hand a request's outcome to the station's machine; its events to the listeners."""
        ev = st.on_outcome(req, res, self.link.now())
        if any(e.kind == "state" and e.data == "start" for e in ev):
            self.fdl.reset_station(st.address)
        self._emit(st.address, ev)

    def poll(self) -> int:
        """One pass: one request to every station that wants one. Returns how many were sent."""
        n = 0
        for st in list(self.stations.values()):
            n += self.step(st)
        return n

    def bring_up(self, address: int, timeout: float = 5.0, fail_fast: bool = False) -> StationMachine:
        """Run the start-up of one station until Data_Exchange; BusError in words otherwise.
        fail_fast: give up at the first Cfg_Fault / Prm_Fault / lock instead of retrying."""
        st = self.stations[address]
        end = self.link.now() + timeout
        kept0 = self.keep_time
        while not st.in_data_exchange:
            # the time the kept stations' keep-alives took is not this station's start-up time
            if self.link.now() - (self.keep_time - kept0) > end or \
                    (fail_fast and st.state in (CFG_FAULT, PRM_FAULT, LOCKED)):
                why = st.last_error or STATE_WORDS.get(st.state, st.state)
                if st.last_diag is not None and st.state != "absent":
                    why += f" (diagnosis: {st.last_diag.state_words(self.address)})"
                raise BusError(f"station {address} did not reach data exchange: {why}")
            if not self.step(st):
                self.link.sleep(min(0.01, max(0.0, st.wait_until - self.link.now())))
        return st

    # -- kept stations ---------------------------------------------------------------------------
    def keep(self, address: int, period: float = 0.0) -> None:
        """Keep `address` in data exchange while the master talks to other stations: once its last
        request is keep_within(its watchdog, period) old, the next request to another station waits
        for one Data_Exchange of it (its last outputs). period: its cycle period (0: none)."""
        within = keep_within(self.stations[address].config.wd_ms, period)
        if within is None:
            self.kept.pop(address, None)
        else:
            self.kept[address] = within

    def unkeep(self, address: int) -> None:
        self.kept.pop(address, None)

    def last_request(self, address: int) -> float | None:
        """When the last request to `address` went (the link's clock; what restarts its DP
        watchdog), None: none yet."""
        return self._last_req.get(address)

    def keep_alive(self, busy: int | None = None) -> int:
        """When a kept station in data exchange (other than `busy`) is due -- its last request is
        its keep_within() old -- a keep round: one Data_Exchange (its last outputs) for every kept
        station in data exchange other than `busy`, the oldest first. Returns how many went.

        Rounds rather than each station when due: the stations stay in the order of their last
        requests, so none waits longer than max(keep_within, the round's own time) plus the one
        request in progress (a station due alone would wait for the others' keep-alives too).
        LinkLost is raised; a station that answers otherwise goes through its machine (RS:
        start-up again) and is seen by its own next exchange."""
        if not self.kept or self._keeping:
            return 0
        now = self.link.now()
        never = float("-inf")
        kept = sorted((self._last_req.get(a, never), a) for a in self.kept
                      if a != busy and a in self.stations and self.stations[a].in_data_exchange)
        if not any(now - t >= self.kept[a] for t, a in kept):
            return 0
        self._keeping = True
        n = 0
        try:
            for _, a in kept:
                st = self.stations[a]
                if st.in_data_exchange:
                    n += self.step(st)
        finally:
            self._keeping = False
            self.keep_alives += n
            self.keep_time += self.link.now() - now
        return n

    def exchange(self, address: int, outputs: bytes | None = None) -> bytes:
        """One Data_Exchange with a station in data exchange; restarts it if it dropped out."""
        st = self.stations[address]
        if outputs is not None:
            if type(outputs) is bytes and len(outputs) == st.output_len:
                st.outputs = outputs
            else:
                st.set_outputs(outputs)
        if self.fast_dx and st.state == DATA_EXCH and (not self.kept or address in self.kept):
            # the cycle of a station in data exchange, as step() decides it (a kept station's own
            # cycle lets no keep-alive go first): the fast path when its Data_Exchange is due
            now = self.link.now()
            if not st._diag_due and now >= st.wait_until:
                st.fresh_inputs = False
                self._last_req[address] = now
                exchange_fast(self, st)
                if st.fresh_inputs and st.state == DATA_EXCH:
                    return st.inputs
                if st.state == "absent" or not (st.in_data_exchange or st.fresh_inputs):
                    self.bring_up(address)
                    self.step(st)
                return st.inputs
        if not st.in_data_exchange:
            self.bring_up(address)
        st.fresh_inputs = False
        self.step(st)
        if st.state == "absent" or not (st.in_data_exchange or st.fresh_inputs):
            # dropped out during this cycle: try to come back once, then report
            self.bring_up(address)
            self.step(st)
        return st.inputs

    def release(self, address: int) -> None:
        """Leave data exchange cleanly: Set_Prm with Unlock_Req (station back to Wait_Prm, outputs
        to their safe state). Best effort: no exception if the station does not answer."""
        st = self.stations.get(address)
        self.unkeep(address)
        if st is None:
            return
        prm = st.config.set_prm()
        prm.lock, prm.unlock = False, True
        try:
            self.transact(address, F.SRD_HIGH, prm.encode(), S.SAP_SET_PRM, S.SAP_MASTER, 1)
        except BusError:
            pass
        st.state = RELEASED

    def reconnect(self, timeout: float = 10.0, interval: float = 0.25) -> None:
        """After LinkLost: reopen the same port (retrying every `interval` s until `timeout`), then
        run the start-up of every station again until it is back in data exchange.

        Raises LinkLost when the port does not come back in time, BusError naming the stations that
        did not reach data exchange. Each station that had been in data exchange counts one
        re-parameterisation; Master.reconnects counts the successful reopenings.
        """
        t_end = time.monotonic() + timeout
        last = None
        while True:
            try:
                self.link.reopen()
                break
            except BusError as e:          # LinkLost included: the port is not back yet
                last = e
            left = t_end - time.monotonic()
            if left <= 0:
                raise LinkLost(f"{self.link.name}: the port did not come back within {timeout:g} s"
                               + (f" ({last})" if last else ""), self.link.name,
                               self.counters()) from None
            time.sleep(min(interval, left))
        self.reconnects += 1
        self.fdl.abort()
        self._line_free_at = 0.0
        now = self.link.now()
        for a, st in self.stations.items():
            self.fdl.reset_station(a)
            if st.state == RELEASED:
                continue
            ev: list[Event] = []
            st.restart(ev, "link restored", now)
            self._emit(a, ev)
        failed = []
        for a, st in self.stations.items():
            if st.state == RELEASED:
                continue
            try:
                self.bring_up(a, timeout=max(0.5, t_end - time.monotonic()))
            except LinkLost:
                raise
            except BusError as e:
                failed.append(str(e))
        if failed:
            raise BusError("after reconnecting: " + "; ".join(failed))

    # -- DP-V1 class-1 acyclic calls (dp/acyclic.py) -----------------------------------------------
    def c1_call(self, address: int, pdu: bytes, timeout_s: float) -> M1.Msac1Pdu:
        """One MSAC_C1 Read or Write with a station in data exchange: the request, then polls until
        its answer, within timeout_s (the GSD's C1_Response_Timeout). Between the polls the kept
        stations' cycles go on (this one's too), so no watchdog runs out. A timeout restarts the
        station's start-up (a DP-V1 slave leaves data exchange with it) and raises C1Timeout; a
        negative answer raises C1Error."""
        call = C1Call(address, pdu, self.link.now(), timeout_s)
        while True:
            self.keep_alive()
            out = self.c1_step(call)
            if out is not None:
                return out

    def c1_step(self, call: C1Call) -> M1.Msac1Pdu | None:
        """One telegram of a class-1 call (its request, or a poll): the answer PDU when it came,
        None to poll again. The station must be in data exchange (one on its way back is brought
        up first); a timeout restarts its start-up and raises C1Timeout. c1_call loops on it, and a
        run of several stations at once (session/together.py) gives each call one step a round."""
        address = call.address
        st = self.stations.get(address)
        if st is None or st.state == RELEASED:
            raise BusError(f"station {address}: DP-V1 read/write needs the station in data exchange")
        if not st.in_data_exchange:
            # on its way back (a class-1 timeout or a lost station restarted it): its start-up first
            self.bring_up(address, timeout=5.0, fail_fast=True)
        res = self.transact(address, F.SRD_HIGH, call.request(self.link.now()), M1.SAP_C1, M1.SAP_C1)
        try:
            return call.feed(res.frame if res.kind == REPLY else None, self.link.now())
        except C1Timeout:
            ev: list[Event] = []
            st.restart(ev, "DP-V1 class-1 timeout", self.link.now())
            self._emit(address, ev)
            raise

    def c1_read(self, address: int, slot: int, index: int, length: int, timeout_s: float) -> bytes:
        """The data of a Read of (slot, index), at most `length` octets."""
        return self.c1_call(address, M1.read_request(slot, index, length), timeout_s).data

    def c1_write(self, address: int, slot: int, index: int, data: bytes, timeout_s: float) -> None:
        self.c1_call(address, M1.write_request(slot, index, data), timeout_s)

    def channel(self, address: int, period: float = 0.0) -> "StationChannel":
        return StationChannel(self, address, period)


class StationChannel:
    """drives.base.CyclicChannel for one station: exchange() = one Data_Exchange per period."""

    def __init__(self, master: Master, address: int, period: float = 0.0):
        self.master = master
        self.address = address
        self.period = period
        self._next: float | None = None
        self.cycles = 0

    def now(self) -> float:
        return self.master.link.now()

    def c1_read(self, slot: int, index: int, length: int, timeout_s: float) -> bytes:
        """drives.base.AcyclicChannel: a DP-V1 class-1 Read of this station."""
        return self.master.c1_read(self.address, slot, index, length, timeout_s)

    def c1_write(self, slot: int, index: int, data: bytes, timeout_s: float) -> None:
        self.master.c1_write(self.address, slot, index, data, timeout_s)

    def exchange(self, outputs: bytes) -> bytes:
        if self.period:
            now = self.now()
            # one sleep for the period and the line's idle time after the last reply (TID1),
            # not a second wake-up in the master for the rest of the idle time
            free = 0.0 if self.master.link.instant else self.master._line_free_at
            if self._next is None:
                # the first exchange goes as soon as the line is free, the next a period later
                self._next = max(now, free)
            until = max(self._next, free)
            if now < until:
                self.master.link.sleep(until - now)
            self._next = max(self._next + self.period, self.now())
        self.cycles += 1
        return self.master.exchange(self.address, outputs)
