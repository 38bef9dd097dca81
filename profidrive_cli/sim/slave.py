"""A simulated DP-V0 slave at telegram level (reference §3.6), sans-IO.

handle(frame, now) takes one request Frame addressed to this station and returns the reply octets
(or None when no reply is due, e.g. SDN). It answers in each state what a real slave answers,
refusals included: RS for services not enabled in the current state, Prm_Fault / Cfg_Fault in the
next diagnosis for rejected Set_Prm / Chk_Cfg, the cached reply for an FCB repetition.

DP-V1 class-1 acyclic services (MSAC_C1, dp/msac1.py) on SAP 51, for a station whose model has a C1
server (sim/model.py SlaveModel.c1_server), whose last accepted Set_Prm set DPV1_Enable
(DPV1_Status_1 bit 7, the first user-parameter octet: dp/dpv1.py) and which is in data exchange with
the master that parameterised it; otherwise SAP 51 is answered RS (SAP not enabled), as a DP-V0
slave answers it. On the wire (the same as dp/acyclic.py, the master side):

  * the master sends the request PDU (Read 5E / Write 5F) in an SRD to DSAP 51 from SSAP 51 (high
    priority, the frame count bit as in its other DP services); the station answers at once with
    the short acknowledgement SC (E5) and hands the PDU to its C1 server;
  * the master then polls with an SRD on the same SAPs and an empty DU; the station answers SC while
    the answer is not ready (or nothing is pending), then the answer PDU (the response or an error
    response DE/DF 80 code1 code2) in a reply with data (DL), the SAPs swapped as every SAP reply;
  * a request PDU that does not decode (msac1.Msac1Error) is answered, on the next poll, with an
    error PDU: access "invalid parameter" (80 B8 00) for a Read or Write function, application
    "feature not supported" (80 A9 00) for any other function (Alarm_Ack belongs on SAP 50; the
    class-2 functions on SAP 49); so is a well-formed PDU of another function;
  * a new request while one is pending replaces it (the old one is forgotten, never answered);
  * a Set_Prm (accepted or not), the watchdog's expiry, leaving data exchange for any reason and a
    power cycle drop what is pending (the C1 server's c1_drop).
A poll whose reply was lost is repeated with the same frame count bit and gets the cached reply (the
FDL repetition), so an answer is not lost with its telegram.
"""

from __future__ import annotations

from bisect import bisect_left, bisect_right
from typing import TYPE_CHECKING

from profidrive_cli.dp import msac1 as M1
from profidrive_cli.dp import services as S
from profidrive_cli.dp.dpv1 import dpv1_status
from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.fcb import SlaveFcb
from profidrive_cli.sim.model import SlaveModel, ticks_always

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.sim.lazy import LazyModel

WAIT_PRM, WAIT_CFG, DATA_EXCH = "Wait_Prm", "Wait_Cfg", "Data_Exch"
DEFAULT_MIN_TSDR = 11        # bit times, until a Set_Prm says otherwise


class TickLog:
    """The times the bus ran its clock (SimBus.tick), the latest KEEP of them at least.

    sim/bus.py runs a station's clock only when a request addresses it or when it is due (its
    watchdog, its model's next_due); a station that was not run at some of these ticks makes up for
    them from here when it next runs (SimSlave.tick), so that it ends where a station run at every
    tick would be."""

    #: kept: at least what a model replays (sim/lazy.py REPLAY_TICKS, Toyo's 100 traceback points)
    KEEP = 256

    def __init__(self) -> None:
        self.times: list[float] = []
        self.last = float("-inf")

    def add(self, t: float) -> None:
        if t <= self.last:
            return                  # the same tick again (or a clock that went back): nothing new
        times = self.times
        times.append(t)
        self.last = t
        if len(times) > 2 * self.KEEP:
            del times[:-self.KEEP]

    def between(self, after: float, upto: float, inclusive: bool = True) -> list[float]:
        """The ticks after `after` up to `upto` (the latest KEEP of them, in order)."""
        times = self.times
        lo = bisect_right(times, after)
        hi = bisect_right(times, upto, lo) if inclusive else bisect_left(times, upto, lo)
        return times[max(lo, hi - self.KEEP):hi]


class Line:
    """What every station on one simulated line hears: how many valid telegrams went by -- SD1, SD2
    or SD3, complete and error-free, from any station to any station (requests, the stations'
    replies, broadcasts); not an SD4 token nor the one-octet SC, which a station in Baud_Search
    does not take a rate from (see SimSlave.baud_search).

    The bus counts (sim/bus.py); a station still searching the rate reads the count when a telegram
    addresses it. So every station is told of every telegram for one addition per telegram on the
    bus, whatever the number of stations."""

    __slots__ = ("telegrams",)

    def __init__(self) -> None:
        self.telegrams = 0


class SimSlave:
    def __init__(self, address: int, model: SlaveModel | LazyModel, set_slave_add_supported: bool = False,
                 response_bits: int | None = None):
        self.address = address
        self.model = model
        self.set_slave_add_supported = set_slave_add_supported
        self.fcb = SlaveFcb()
        self.powered = True
        #: the station's own response time in bit times (None: the bus default); it never answers
        #: earlier than the min TSDR from Set_Prm
        self.response_bits = response_bits
        #: counters a test can look at
        self.stats = {"requests": 0, "repeats": 0, "prm_rejected": 0, "cfg_rejected": 0,
                      "watchdog_expired": 0, "data_exchange": 0, "power_cycles": 0, "trips": 0,
                      "ignored_warmup": 0, "ignored_first_contact": 0, "c1_requests": 0,
                      "c1_answers": 0}
        #: Baud_Search (see baud_search()): the valid telegrams on the line this station misses while
        #: it searches the rate, and the seconds its search takes to reach the line's rate (0: no
        #: such condition); both set by the plant (sim://?warmup=3:4, warmup=3:0.5s)
        self.warmup = 0
        self.warmup_s = 0.0
        #: still searching the rate: nothing is executed or answered
        self.searching = False
        self._search_t0 = 0.0           # when the search began (the station's power-on)
        #: the line this station sits on (set by sim/bus.py; None: a station on its own, which
        #: hears only the telegrams handed to handle())
        self.line: Line | None = None
        self.joined_at_telegram = 0     # line.telegrams when the station joined the line
        self._heard_alone = 0           # telegrams handed to handle() while on no line
        #: the first-contact rule of a Siemens CBP2 drive board (sim://?firstcontact=3; kolod/profibus,
        #: profibus_debug/diagnostics.py): an SRD/SDA from a master the station keeps no frame count
        #: for (after power-on, or another master) is executed only when it starts a sequence, FCV=0
        #: with FCB=1 (reference §2.3 rule 1); FCV=1 and FCV=0/FCB=0 are ignored, no answer at all.
        #: FDL status (FCV=0/FCB=0 by rule 4) and SDN are answered as usual. Set by the plant.
        self.first_contact = False
        #: the bus's tick times (set by sim/bus.py; None: a station on its own, run only by tick())
        self.ticks: TickLog | None = None
        #: when the station's clock last ran (watchdog and model)
        self.ticked_at = float("-inf")
        #: the bus's bookkeeping: the time this station is queued for, on the bus or not
        self.queued: float | None = None
        self.plugged = False
        self.power_on(0.0)

    # -- Baud_Search ----------------------------------------------------------------------------
    def baud_search(self, telegrams: int = 0, seconds: float = 0.0, now: float = 0.0) -> None:
        """The station starts (at `now`, its power-on) still searching the baud rate.

        Baud_Search / Baud_Control as the DP slave ASICs implement them (the SPC3 described in the
        ProSoft MVI46-PDPS manual, "Automatic Baud Rate Identification"; the state names in Lenze's
        8400 motec PROFIBUS manual, code C13861; the profibus-dp-reference has only the GSD key
        Auto_Baud_supp, which the GSD files of gsd/ set to 1): after power-on the station listens
        at one rate after the other, highest first, each for a monitoring time; the first SD1, SD2
        or SD3 telegram it receives complete and error-free at a rate fixes that rate -- a
        telegram from any station to any station, not only one addressed to it -- and it goes to
        Baud_Control. Telegrams that go by while it listens at other rates are lost to it.

        Modelled as: the station misses the first `telegrams` valid telegrams on its line (they
        went by while it listened at other rates) and its search reaches the line's rate `seconds`
        after power-on; with both conditions met, the next valid telegram fixes the rate and, when
        it addresses the station, is executed and answered (a real ET200S left four FDL status
        requests unanswered and answered the 5th, with no other traffic on the line:
        ../shared/testdata/external/pyprofibus26-et200s-startup.txt: telegrams=4). Time alone
        fixes nothing: a silent line keeps a station searching, as on the ASIC (which would move
        on to the next rate after its monitoring time there; the model stays at the line's rate
        once its search reached it). Armed once by the
        plant: a power cycle of the fault injection does not re-arm it, and the fall-back of
        Baud_Control to Baud_Search (no telegram to the station within WD_Baud_Control_Val) is
        not modelled."""
        self.warmup = max(0, telegrams)
        self.warmup_s = max(0.0, seconds)
        self.searching = self.warmup > 0 or self.warmup_s > 0.0
        self._search_t0 = now
        self._heard_alone = 0
        self.joined_at_telegram = self.line.telegrams if self.line is not None else 0

    def join(self, line: Line) -> None:
        """The station is put on `line` (sim/bus.py): its count of telegrams heard starts here."""
        if self.line is not line:
            self.line = line
            self.joined_at_telegram = line.telegrams

    def telegrams_heard(self) -> int:
        """Valid telegrams on the line since the station joined it (on its own: those handed to
        handle() while it searched)."""
        line = self.line
        return line.telegrams - self.joined_at_telegram if line is not None else self._heard_alone

    def _rate_found(self, now: float) -> bool:
        """Baud_Search, at a valid telegram (not counted yet): True when this one fixes the rate."""
        if self.telegrams_heard() >= self.warmup and now - self._search_t0 >= self.warmup_s:
            self.searching = False
            return True
        if self.line is None:
            self._heard_alone += 1
        return False

    @property
    def reply_delay_bits(self) -> int:
        """TSDR this station keeps before its reply: its own time, at least min TSDR."""
        return max(self.response_bits or 0, self.min_tsdr)

    # -- state ------------------------------------------------------------------------------
    def power_on(self, now: float) -> None:
        self.state = WAIT_PRM
        self.master: int | None = None       # the master that parameterised us (lock holder)
        self.wd_s: float | None = None
        self.last_seen = now
        self.prm_fault = False
        self.cfg_fault = False
        self.not_supported = False
        self.diag_pending = False
        self.sync = self.freeze = False
        self._sync_mode_off()
        self.group = 0
        self.outputs = b""
        self.inputs = b""
        self.min_tsdr = DEFAULT_MIN_TSDR
        self.fcb.reset()
        #: DPV1_Enable in the last accepted Set_Prm: MSAC_C1 on SAP 51 enabled (with a C1 server)
        self.dpv1_enabled = False
        self._c1_drop(now)

    def power_cycle(self, now: float) -> None:
        """Power off and on: back to Wait_Prm, needs a new Set_Prm (fault injection)."""
        self.settle(now)
        self.stats["power_cycles"] += 1
        if self.state == DATA_EXCH:
            self.model.on_leave_data_exchange(now, "power cycle")
        self.power_on(now)

    def inject_trip(self, alarm: str, now: float) -> None:
        """The drive trips (model.trip) and the station flags new diagnosis: the next
        Data_Exchange reply is DH, so the master reads Slave_Diag (fault injection)."""
        self.settle(now)
        self.stats["trips"] += 1
        self.model.trip(alarm, now)
        self.diag_pending = True

    def _leave(self, now: float, reason: str, to: str = WAIT_PRM) -> None:
        if self.state == DATA_EXCH:
            self.model.on_leave_data_exchange(now, reason)
        self.state = to
        self._sync_mode_off()
        self._c1_drop(now)

    def _c1_drop(self, now: float) -> None:
        """Nothing pending on SAP 51 any more (a Set_Prm, the watchdog, leaving data exchange,
        power on): the answer not yet given is forgotten, and the C1 server told (c1_drop)."""
        #: the answer PDU of the pending MSAC_C1 request (None: none, or one never answered) and
        #: the time from which a poll gets it
        self._c1_answer: bytes | None = None
        self._c1_ready = 0.0
        server = self.model.c1_server
        if server is not None:
            server.c1_drop(now)

    def _sync_mode_off(self) -> None:
        """No Sync / Freeze command in force (power on, leaving data exchange)."""
        #: outputs the application uses while a Sync is in force (None: no Sync: the received ones)
        self.synced_outputs: bytes | None = None
        #: inputs sampled by the last Freeze (None: no Freeze in force: live inputs)
        self.frozen_inputs: bytes | None = None

    # -- the station's clock -----------------------------------------------------------------
    def watchdog_deadline(self) -> float | None:
        """When the watchdog runs out (expired at the first tick after it), None: not armed."""
        if self.wd_s is not None and self.state in (WAIT_CFG, DATA_EXCH):
            return self.last_seen + self.wd_s
        return None

    def next_due(self) -> float | None:
        """When the bus must next run this station's clock although nobody addresses it (None: only
        when addressed): its watchdog's expiry, or what its model asks (SlaveModel.next_due). A time
        at or before the last run means: at the next tick of the bus."""
        wd = self.watchdog_deadline()
        model = self.model
        own = self.ticked_at if ticks_always(model) else model.next_due(self.ticked_at)
        if own is None:
            return wd
        return own if wd is None or own < wd else wd

    def settle(self, upto: float) -> None:
        """Make up for the bus ticks up to `upto` this station was not run at (before something from
        outside acts on it: a trip, a power cycle, a command of sim/control.py)."""
        log = self.ticks
        if log is not None and log.last > self.ticked_at:
            self._catch_up(upto, True)

    def _catch_up(self, upto: float, inclusive: bool) -> None:
        missed = self.ticks.between(self.ticked_at, upto, inclusive)   # type: ignore[union-attr]
        if not missed:
            return
        wd = self.watchdog_deadline()
        if wd is not None and wd < missed[-1]:
            # the watchdog ran out at one of them (armed from outside the bus): tick by tick, as then
            for t in missed:
                self._tick(t)
            return
        model = self.model
        if ticks_always(model):
            for t in missed:
                model.tick(t)
        else:
            model.catch_up(missed, None if inclusive else upto)
        self.ticked_at = missed[-1]

    def tick(self, now: float) -> None:
        """Run the station's clock to `now`: the bus ticks it missed since it last ran (sim/bus.py
        runs it only when addressed or due), then the watchdog and the model at `now`."""
        log = self.ticks
        if log is not None and log.last > self.ticked_at:
            self._catch_up(now, False)
        self._tick(now)

    def _tick(self, now: float) -> None:
        """Watchdog: no telegram from our master within the watchdog time -> Wait_Prm."""
        self.ticked_at = now
        if (self.wd_s is not None and self.state in (WAIT_CFG, DATA_EXCH)
                and now - self.last_seen > self.wd_s):
            # the moment it expired, also when the clock is ticked late (a silent master on the
            # virtual clock): the drive's comm-loss reaction is timed from there
            expired = self.last_seen + self.wd_s
            self.stats["watchdog_expired"] += 1
            if self.state == DATA_EXCH:
                self.model.tick(expired)
            self._leave(expired, "watchdog")
            self.master = None
            self.wd_s = None
        self.model.tick(now)

    # -- diagnosis ---------------------------------------------------------------------------
    def diag(self) -> S.SlaveDiag:
        ext = self.model.ext_diag()
        st1 = 0
        if self.state != DATA_EXCH:
            st1 |= S.ST1["Station_Not_Ready"]
        if self.cfg_fault:
            st1 |= S.ST1["Cfg_Fault"]
        if self.prm_fault:
            st1 |= S.ST1["Prm_Fault"]
        if self.not_supported:
            st1 |= S.ST1["Not_Supported"]
        if ext:
            st1 |= S.ST1["Ext_Diag"]
        st2 = S.ST2_FIXED
        if self.state == WAIT_PRM:
            st2 |= S.ST2["Prm_Req"]
        if self.wd_s is not None:
            st2 |= S.ST2["WD_On"]
        # Sync_Mode / Freeze_Mode: a Sync / Freeze command is in force (set when the station
        # obeyed one, cleared by Unsync / Unfreeze and on leaving data exchange)
        if self.synced_outputs is not None:
            st2 |= S.ST2["Sync_Mode"]
        if self.frozen_inputs is not None:
            st2 |= S.ST2["Freeze_Mode"]
        room = max(0, self.model.max_diag_len - 6)
        st3 = S.ST3_OVERFLOW if len(ext) > room else 0
        master = self.master if self.master is not None and self.state != WAIT_PRM else 0xFF
        return S.SlaveDiag(st1, st2, st3, master, self.model.ident, ext[:room])

    # -- telegrams ---------------------------------------------------------------------------
    def _reply(self, req: F.Frame, status: int, data: bytes = b"", saps: bool = True) -> bytes:
        if saps and req.dsap is not None:
            f = F.Frame(F.SD2, req.sa, self.address, F.response_fc(status), data, req.ssap, req.dsap)
        else:
            f = F.Frame(F.SD2, req.sa, self.address, F.response_fc(status), data)
        return F.encode(f)

    def handle(self, req: F.Frame, now: float) -> bytes | None:
        if not self.powered:
            return None
        if self.searching and not self._rate_found(now):
            # still searching the rate: nothing is executed or answered
            if req.da == self.address:
                self.stats["ignored_warmup"] += 1
            return None
        self.tick(now)
        fn = req.function
        if fn == F.FDL_STATUS:
            return F.encode(F.Frame(F.SD1, req.sa, self.address, F.response_fc(F.OK)))
        if fn not in (F.SRD_LOW, F.SRD_HIGH, F.SDN_LOW, F.SDN_HIGH, F.SDA_LOW, F.SDA_HIGH):
            # ident / LSAP status / reserved functions: not offered by this station
            return F.encode(F.Frame(F.SD1, req.sa, self.address, F.response_fc(F.RS))) \
                if fn in F.NEEDS_REPLY else None
        if fn in (F.SDN_LOW, F.SDN_HIGH):
            self._sdn(req, now)
            return None
        if self.first_contact and self._refuses_first_contact(req):
            self.stats["ignored_first_contact"] += 1
            return None
        self.stats["requests"] += 1
        if self.fcb.is_repeat(req.sa, req.fc):
            self.stats["repeats"] += 1
            return self.fcb.last_reply
        reply = self._service(req, now)
        self.fcb.remember(reply)
        return reply

    def _refuses_first_contact(self, req: F.Frame) -> bool:
        """The CBP2 rule (first_contact): no frame count kept for this master and the request does
        not start a sequence (FCV=0, FCB=1)."""
        if self.fcb.master == req.sa:
            return False
        return bool(req.fc & F.FC_FCV) or not req.fc & F.FC_FCB

    def _from_own_master(self, req: F.Frame) -> bool:
        return self.master is not None and req.sa == self.master

    def _sdn(self, req: F.Frame, now: float) -> None:
        if req.dsap == S.SAP_GLOBAL_CONTROL and self._from_own_master(req):
            try:
                gc = S.GlobalControl.decode(req.data)
            except S.ServiceError:
                return
            if gc.group and not gc.group & self.group:
                return
            self.last_seen = now
            if gc.command & S.GC_CLEAR and self.state == DATA_EXCH:
                self.model.clear_outputs(now)
            if self.state == DATA_EXCH:
                self._sync_freeze(gc.command, now)

    def _sync_freeze(self, command: int, now: float) -> None:
        """Sync / Unsync / Freeze / Unfreeze (reference 3.5), obeyed only when Set_Prm asked for the
        mode (Sync_Req / Freeze_Req; a station without the mode refused that Set_Prm). Sync: the
        outputs received last take effect now and stay until the next Sync (outputs of Data_Exchange
        in between are kept, not applied); Unsync: back to applying each Data_Exchange's outputs
        (the ones received last take effect now). Freeze: the inputs are sampled now and every
        Data_Exchange answers them until the next Freeze; Unfreeze: live inputs again. Sync and
        Freeze in one command: the outputs take effect, then the inputs are sampled."""
        applied = None
        if self.sync and command & (S.GC_SYNC | S.GC_UNSYNC):
            self.synced_outputs = self.outputs if command & S.GC_SYNC and not \
                command & S.GC_UNSYNC else None
            applied = self.outputs
        if self.freeze and command & S.GC_UNFREEZE:
            self.frozen_inputs = None
        if applied is not None or (self.freeze and command & S.GC_FREEZE
                                   and not command & S.GC_UNFREEZE):
            live = self.model.data_exchange(self._applied_outputs(), now)
            if self.freeze and command & S.GC_FREEZE and not command & S.GC_UNFREEZE:
                self.frozen_inputs = live

    def _applied_outputs(self) -> bytes:
        return self.synced_outputs if self.synced_outputs is not None else self.outputs

    def _service(self, req: F.Frame, now: float) -> bytes:
        if self._from_own_master(req):
            self.last_seen = now
        if req.dsap is None:
            return self._data_exchange(req, now)
        if req.ssap is None:
            return self._reply(req, F.RS, saps=False)
        sap = req.dsap
        if sap == S.SAP_SLAVE_DIAG:
            d = self.diag()
            self.diag_pending = False
            return self._reply(req, F.DL, d.encode())
        if sap == S.SAP_GET_CFG:
            return self._reply(req, F.DL, self.model.real_cfg())
        if sap == S.SAP_SET_PRM:
            return self._set_prm(req, now)
        if sap == S.SAP_CHK_CFG:
            return self._chk_cfg(req, now)
        if sap == S.SAP_RD_INP and self.state == DATA_EXCH:
            return self._reply(req, F.DL, self.inputs)
        if sap == S.SAP_RD_OUTP and self.state == DATA_EXCH:
            return self._reply(req, F.DL, self.outputs)
        if sap == M1.SAP_C1:
            return self._msac_c1(req, now)
        if sap == S.SAP_SET_SLAVE_ADD and self.set_slave_add_supported and self.state == WAIT_PRM:
            try:
                ssa = S.SetSlaveAdd.decode(req.data)
            except S.ServiceError:
                return self._reply(req, F.RS)
            if ssa.ident != self.model.ident or not 0 <= ssa.new_address <= 125:
                return self._reply(req, F.RS)
            reply = F.encode(F.Frame(F.SC))
            self.address = ssa.new_address
            return reply
        return self._reply(req, F.RS)

    def _set_prm(self, req: F.Frame, now: float) -> bytes:
        sc = F.encode(F.Frame(F.SC))
        try:
            prm = S.SetPrm.decode(req.data)
        except S.ServiceError:
            self._reject_prm(now)
            return sc
        locked_by_other = (self.master is not None and req.sa != self.master
                           and self.state != WAIT_PRM)
        if locked_by_other:
            # another master holds the lock: not executed (it sees Master_Lock in our diag)
            return sc
        if prm.unlock:
            # released for other masters: drop the lock and wait for new parameters
            self._leave(now, "released by master")
            self.master, self.wd_s = None, None
            return sc
        ok = prm.ident == self.model.ident
        if prm.wd_ms is not None and 0 in (prm.wd_factors or (1, 1)):
            ok = False
        if (prm.sync and not getattr(self.model, "sync_supported", False)) or \
                (prm.freeze and not getattr(self.model, "freeze_supported", False)):
            self.not_supported = True
            ok = False
        else:
            self.not_supported = False
        if ok and not self.model.check_prm(prm.user_prm):
            ok = False
        if not ok:
            self._reject_prm(now)
            return sc
        self._leave(now, "new parameters", to=WAIT_CFG)
        self.state = WAIT_CFG
        self.prm_fault = False
        self.cfg_fault = False
        self.master = req.sa
        self.wd_s = prm.wd_ms / 1000.0 if prm.wd_ms is not None else None
        self.sync, self.freeze, self.group = prm.sync, prm.freeze, prm.group
        status = dpv1_status(prm.user_prm)
        self.dpv1_enabled = status is not None and bool(status.octets[0] & 0x80)
        if prm.min_tsdr:                    # 0 = keep the value in use
            self.min_tsdr = prm.min_tsdr
        self.last_seen = now
        return sc

    def _reject_prm(self, now: float) -> None:
        self.stats["prm_rejected"] += 1
        self._leave(now, "parameters rejected")
        self.prm_fault = True
        self.master = None
        self.wd_s = None

    def _chk_cfg(self, req: F.Frame, now: float) -> bytes:
        if self.state == WAIT_PRM or not self._from_own_master(req):
            return self._reply(req, F.RS)
        if self.model.check_cfg(req.data):
            if self.state != DATA_EXCH:
                self.outputs = bytes(self.model.output_len)
                self.inputs = bytes(self.model.input_len)
            self.state = DATA_EXCH
            self.cfg_fault = False
        else:
            self.stats["cfg_rejected"] += 1
            self._leave(now, "configuration rejected")
            self.cfg_fault = True
        return F.encode(F.Frame(F.SC))

    def _data_exchange(self, req: F.Frame, now: float) -> bytes:
        if self.state != DATA_EXCH or not self._from_own_master(req):
            return self._reply(req, F.RS, saps=False)
        if len(req.data) != self.model.output_len:
            # receive length mismatch: the station leaves data exchange and wants new parameters
            self._leave(now, "output length mismatch")
            return self._reply(req, F.RS, saps=False)
        self.stats["data_exchange"] += 1
        self.outputs = req.data
        live = self.model.data_exchange(self._applied_outputs(), now)
        self.inputs = live if self.frozen_inputs is None else self.frozen_inputs
        status = F.DH if self.diag_pending else F.DL
        if not self.inputs and status == F.DL:
            return F.encode(F.Frame(F.SC))
        return self._reply(req, status, self.inputs, saps=False)

    # -- DP-V1 class-1 acyclic services (SAP 51) ----------------------------------------------
    def _msac_c1(self, req: F.Frame, now: float) -> bytes:
        """An SRD to SAP 51: a request PDU (answered SC, handed to the C1 server) or a poll (empty
        DU: SC while the answer is not ready, then the answer PDU with DL). See the module doc."""
        server = self.model.c1_server if self.state == DATA_EXCH else None
        if (server is None or not self.dpv1_enabled or req.ssap != M1.SAP_C1
                or not self._from_own_master(req)):
            return self._reply(req, F.RS)
        du = bytes(req.data)
        if du:
            # a request: it replaces the pending one (whose answer is never given)
            self.stats["c1_requests"] += 1
            fn = du[0] & 0x7F
            try:
                pdu: M1.Msac1Pdu | None = M1.decode_pdu(du, is_request=True)
            except M1.Msac1Error:
                pdu = None
            if pdu is None or pdu.function not in (M1.READ, M1.WRITE):
                code = 0xB8 if pdu is None and fn in (M1.READ, M1.WRITE) else 0xA9
                self._c1_answer, self._c1_ready = M1.error_response(fn, code), now
            else:
                got = server.c1_request(pdu, now)
                self._c1_answer, self._c1_ready = got if got is not None else (None, now)
            return F.encode(F.SC_FRAME)
        answer = self._c1_answer
        if answer is None or now < self._c1_ready:
            return F.encode(F.SC_FRAME)           # a poll: not ready yet, or nothing pending
        self._c1_answer = None
        self.stats["c1_answers"] += 1
        return self._reply(req, F.DL, answer)
