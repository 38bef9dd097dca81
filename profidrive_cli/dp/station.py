"""The master's view of one DP slave: the start-up state machine (reference §3), sans-IO.

    Slave_Diag -> Set_Prm -> Chk_Cfg -> Slave_Diag (until ready) -> Data_Exchange

Prm_Req, Cfg_Fault, Prm_Fault and Stat_Diag are honoured; DH/RDH in Data_Exchange -> read the
diagnosis; RS -> start over (counted as a re-parameterisation when the station had reached
Data_Exchange; retried start-up steps are not).

Silence in Data_Exchange (MAX_SILENT requests without a valid reply) -> Slave_Diag first, as a real
master does: a station that still reports data exchange with us (master address = ours, ident ours,
no Prm_Req, no Not_Ready / Cfg_Fault / Prm_Fault / Non_Existent / Master_Lock, WD_On as we set it;
reference §3.3/§3.6) has kept its parameters, its watchdog never expired: Data_Exchange resumes
without Set_Prm/Chk_Cfg (which would trip a drive) and it is not a re-parameterisation. Otherwise
(watchdog expired, power cycle, another master) the start-up runs again as after RS.
next_request(now) says what to send; on_outcome(request, outcome, now) takes what came back.
"""

from __future__ import annotations

from dataclasses import dataclass

from profidrive_cli.dp import services as S
from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.master import NO_ANSWER, Outcome, StationCounters

# states
START, PRM, CFG, CHECK, DATA_EXCH = "start", "set_prm", "chk_cfg", "check", "data_exchange"
CFG_FAULT, PRM_FAULT, LOCKED, ABSENT, RELEASED = ("cfg_fault", "prm_fault", "locked", "absent",
                                                  "released")
STATE_WORDS = {
    START: "reading diagnosis", PRM: "sending parameters", CFG: "sending configuration",
    CHECK: "waiting until ready", DATA_EXCH: "data exchange", CFG_FAULT: "configuration fault",
    PRM_FAULT: "parameter fault", LOCKED: "locked by another master", ABSENT: "no answer",
    RELEASED: "released",
}

FAULT_RETRY_S = 1.0          # wait before starting over after Cfg_Fault / Prm_Fault / lock
MAX_SILENT = 3               # Data_Exchange requests without answer (after retries) before start over
MAX_CHECK_DIAGS = 20         # Slave_Diag reads waiting for "ready" before starting over


@dataclass
class SlaveConfig:
    ident: int
    cfg: bytes
    user_prm: bytes = b""
    wd_ms: float | None = 500.0
    min_tsdr: int = 11
    group: int = 0
    sync: bool = False
    freeze: bool = False

    def set_prm(self) -> S.SetPrm:
        return S.SetPrm(ident=self.ident, wd_ms=self.wd_ms, lock=True, min_tsdr=self.min_tsdr,
                        group=self.group, user_prm=self.user_prm, sync=self.sync, freeze=self.freeze)


@dataclass
class DpRequest:
    service: str
    function: int
    dsap: int | None
    ssap: int | None
    data: bytes = b""
    expect: int = 255         # longest reply in octets (for the timeout)


@dataclass
class Event:
    kind: str                 # "state", "inputs", "diag", "error"
    text: str = ""
    data: object = None


class StationMachine:
    def __init__(self, address: int, config: SlaveConfig, master_address: int,
                 counters: StationCounters | None = None):
        from profidrive_cli.dp.cfg import io_sizes
        self.address = address
        self.config = config
        self.master_address = master_address
        self.state = START
        self.counters = counters or StationCounters()
        self.input_len, self.output_len = io_sizes(config.cfg)
        self.outputs = bytes(self.output_len)
        self.inputs = bytes(self.input_len)
        self.last_diag: S.SlaveDiag | None = None
        self.last_error = ""
        self.wait_until = 0.0
        self._diag_due = False
        self._silent = 0
        self._checks = 0
        self._was_in_dx = False        # reached Data_Exchange since the last start-up began
        self._may_resume = False       # silent in Data_Exchange: resume if the diag still says so
        self.fresh_inputs = False      # set when a Data_Exchange delivered inputs

    # -- helpers ------------------------------------------------------------------------------
    def _goto(self, state: str, events: list[Event], text: str = "") -> None:
        if state != self.state:
            self.state = state
            if state == DATA_EXCH:
                self._was_in_dx = True
            events.append(Event("state", text or STATE_WORDS[state], state))

    def _still_exchanging(self, d: S.SlaveDiag) -> bool:
        """The diagnosis says the station is still in Data_Exchange with us, on our parameters."""
        bad1 = ("Station_Non_Existent", "Station_Not_Ready", "Cfg_Fault", "Prm_Fault", "Master_Lock")
        return (d.master == self.master_address and d.ident == self.config.ident
                and not any(d.has(b) for b in bad1) and not d.has("Prm_Req")
                and d.has("WD_On") == (self.config.wd_ms is not None))

    def restart(self, events: list[Event], why: str, now: float = 0.0, delay: float = 0.0) -> None:
        self._may_resume = False
        self.last_error = why
        self.wait_until = now + delay
        self._goto(START, events, f"starting over: {why}")
        events.append(Event("error", why))

    @property
    def in_data_exchange(self) -> bool:
        return self.state == DATA_EXCH

    def set_outputs(self, data: bytes) -> None:
        if len(data) != self.output_len:
            raise ValueError(f"station {self.address}: outputs must be {self.output_len} octets, "
                             f"got {len(data)}")
        self.outputs = bytes(data)

    # -- the Data_Exchange fast path (dp/dx_fast.py) ----------------------------------------------
    def dx_ready(self, now: float) -> bool:
        """next_request(now) would be a Data_Exchange (in data exchange, no diagnosis due)."""
        return self.state == DATA_EXCH and not self._diag_due and now >= self.wait_until

    def dx_request(self) -> DpRequest:
        """The Data_Exchange request next_request() gives in data exchange."""
        return DpRequest("Data_Exchange", F.SRD_HIGH, None, None, self.outputs, self.input_len + 9)

    def took_inputs(self, data: bytes) -> None:
        """A DL reply with exactly input_len octets: what on_outcome() does with it, in place
        (the caller emits the "inputs" event when someone listens)."""
        self._silent = 0
        self.counters.data_exchanges += 1
        self.inputs = data
        self.fresh_inputs = True

    # -- what to send ---------------------------------------------------------------------------
    def next_request(self, now: float) -> DpRequest | None:
        if now < self.wait_until or self.state == RELEASED:
            return None
        if self.state in (START, CHECK, CFG_FAULT, PRM_FAULT, LOCKED, ABSENT) or \
                (self.state == DATA_EXCH and self._diag_due):
            return DpRequest("Slave_Diag", F.SRD_HIGH, S.SAP_SLAVE_DIAG, S.SAP_MASTER, b"", 250)
        if self.state == PRM:
            return DpRequest("Set_Prm", F.SRD_HIGH, S.SAP_SET_PRM, S.SAP_MASTER,
                             self.config.set_prm().encode(), 1)
        if self.state == CFG:
            return DpRequest("Chk_Cfg", F.SRD_HIGH, S.SAP_CHK_CFG, S.SAP_MASTER, self.config.cfg, 1)
        return self.dx_request()

    # -- what came back -------------------------------------------------------------------------
    def on_outcome(self, req: DpRequest, out: Outcome, now: float) -> list[Event]:
        ev: list[Event] = []
        if out.kind == NO_ANSWER:
            if self.state == DATA_EXCH:
                self._silent += 1
                if self._silent >= MAX_SILENT:
                    # read the diagnosis before deciding: the station may still be in data exchange
                    self._silent = 0
                    self._may_resume = True
                    self.last_error = "station stopped answering"
                    self._goto(ABSENT, ev, "no answer: reading the diagnosis")
                    ev.append(Event("error", self.last_error))
            elif self.state != ABSENT:
                self.last_error = f"no answer to {req.service}"
                self._goto(ABSENT, ev)
            return ev
        self._silent = 0
        f = out.frame
        assert f is not None                # a REPLY carries its frame (fdl/master.py Outcome)
        if req.service == "Slave_Diag":
            return self._on_diag(f, now, ev)
        if req.service in ("Set_Prm", "Chk_Cfg"):
            if f.sd == F.SC or (f.fc & 0x0F) == F.OK:
                if req.service == "Set_Prm":
                    self._goto(CFG, ev)
                else:
                    self._checks = 0
                    self._goto(CHECK, ev)
            elif req.service == "Chk_Cfg" and (f.fc & 0x0F) == F.RS:
                # a slave that found a fault in the Set_Prm it acknowledged stays in Wait_Prm, where
                # the Chk_Cfg SAP is not enabled (RS): the diagnosis says why (Prm_Fault or
                # Cfg_Fault, reference §3.3), so read it (CHECK) rather than blame the Chk_Cfg
                self.last_error = f"Chk_Cfg refused: {F.describe_fc(f.fc)}"
                ev.append(Event("error", self.last_error))
                self._checks = 0
                self._goto(CHECK, ev)
            else:
                self.restart(ev, f"{req.service} refused: {F.describe_fc(f.fc)}", now)
            return ev
        # Data_Exchange
        status = F.OK if f.sd == F.SC else f.fc & 0x0F
        if status in (F.DL, F.DH, F.OK):
            data = f.data if f.sd != F.SC else b""
            if len(data) != self.input_len:
                self.counters.illegal += 1
                self.last_error = f"inputs of {len(data)} octets, configured {self.input_len}"
                ev.append(Event("error", self.last_error))
                return ev
            self.counters.data_exchanges += 1
            self.inputs = data
            self.fresh_inputs = True
            ev.append(Event("inputs", "", data))
            if status == F.DH:
                self._diag_due = True
            return ev
        if status in (F.RDL, F.RDH):
            self._diag_due = status == F.RDH
            return ev
        if status == F.RS:
            self.restart(ev, "station left data exchange (RS)", now)
            return ev
        if status == F.RR:
            return ev               # no resources: simply try again next cycle
        self.restart(ev, f"Data_Exchange answered {F.describe_fc(f.fc)}", now)
        return ev

    def _on_diag(self, f: F.Frame, now: float, ev: list[Event]) -> list[Event]:
        if f.sd == F.SC or not f.data:
            self.counters.illegal += 1
            return ev
        try:
            d = S.SlaveDiag.decode(f.data)
        except S.ServiceError as e:
            self.counters.illegal += 1
            self.last_error = str(e)
            return ev
        self.counters.diag_reads += 1
        self._diag_due = False
        self.last_diag = d
        ev.append(Event("diag", d.state_words(self.master_address), d))
        locked_elsewhere = (d.has("Master_Lock") or
                            (d.master not in (0xFF, self.master_address) and not d.has("Prm_Req")))
        if self.state == ABSENT and self._may_resume:
            self._may_resume = False
            if self._still_exchanging(d):
                self.last_error = ""
                self._diag_due = d.has("Stat_Diag")    # keep reading it as in Data_Exchange
                self._goto(DATA_EXCH, ev, "data exchange resumed (the station kept it)")
                return ev
        if self.state in (START, CFG_FAULT, PRM_FAULT, LOCKED, ABSENT):
            if locked_elsewhere:
                self.last_error = f"locked by master {d.master}"
                self.wait_until = now + FAULT_RETRY_S
                self._goto(LOCKED, ev)
                return ev
            if d.ident != self.config.ident:
                self.last_error = (f"station reports ident 0x{d.ident:04X}, "
                                   f"configured 0x{self.config.ident:04X}")
            if self._was_in_dx:
                self.counters.reparams += 1
                self._was_in_dx = False
            self._goto(PRM, ev)
            return ev
        if self.state == CHECK:
            if d.has("Cfg_Fault"):
                self.last_error = "configuration fault: the station refuses the configuration"
                self.wait_until = now + FAULT_RETRY_S
                self._goto(CFG_FAULT, ev)
            elif d.has("Prm_Fault"):
                self.last_error = "parameter fault: the station refuses Set_Prm"
                self.wait_until = now + FAULT_RETRY_S
                self._goto(PRM_FAULT, ev)
            elif d.has("Prm_Req"):
                self._goto(PRM, ev)
            elif d.ready:
                self.last_error = ""
                self._goto(DATA_EXCH, ev)
            else:
                self._checks += 1
                if self._checks > MAX_CHECK_DIAGS:
                    self.restart(ev, "station never became ready", now)
            return ev
        if self.state == DATA_EXCH and (d.has("Prm_Req") or not d.ready and not d.has("Stat_Diag")):
            self.restart(ev, "station needs parameters again", now)
        return ev
