"""A simulated generic PROFIdrive V4 axis with DP-V1 parameter access (DS47), sans-IO.

    make_model(profile, address=0, delay_s=0.002, busy=0.0, c1_silent=0, defaults=None, ...)
        -> Dpv1AxisModel   (profiles/profidrive-dpv1.yaml; the options of ProfidriveModel besides)

Two parts, one owner each:

  * the cyclic drive is sim/profidrive_model.py's PROFIdrive model on the profile's layout without
    PKW words (standard telegram 1: STW1 and NSOLL_A out, ZSW1 and NIST_A in), so `pdrive status`,
    `run`, `stop` work on it as on the other families; the profile's parameters are its store.
  * Ds47Server, its class-1 server (sim/model.py C1Server; sim/slave.py does the wire: SAP 51, the
    short acknowledgement, the polls, what drops a pending request), serves data record 47 (the
    PROFIdrive base mode parameter access) in the profile's `profidrive.dpv1.slot`:
      - Write DS47 stores a parameter request (drives/profidrive/ds47.py ParamRequest), executed
        by the axis at once (its changes stay for the simulator's lifetime, also when the response
        is never read); the Write is answered `delay_s` after it arrived (5F slot 2F length);
      - Read DS47 gets the parameter response once it is ready, `busy_s` after the Write was
        answered, and only once; before that, and with no request executed since the last
        response was read, DP-V1 error "state conflict" (DE 80 B5 00): a PROFIdrive drive's
        "response not ready yet", which the master answers by reading again;
      - a Read shorter than the response gets its first `length` octets (the response is handed
        out then all the same): a DP-V1 Read returns at most the octets asked for, and the profile
        has no error for a short read (0x15 "response too long" is for a response over what the
        channel carries, 240 octets: ds47.answer gives that one);
      - another index: "invalid index" (80 B0 00); another slot: "invalid slot" (80 B2 00), the slot
        checked first; every answer, positive or negative, `delay_s` after its request;
      - a request that does not decode as a parameter request: the Write is acknowledged all the
        same (the record was written) and the next Read DS47 gets a negative response, reference and
        axis mirrored, response id 0x81 (0x82 when its request id is 0x02 change), one error block:
        0x21 "service not supported" for a request id other than 0x01/0x02, 0x16 "parameter
        address impermissible" for any other fault (counts, lengths, attributes, formats) -- the
        PROFIdrive way of refusing a request, as a response (our choice of numbers where the
        profile leaves it). A request too short to have a header to mirror (under 4 octets) is
        refused by the Write itself, "write length error" (80 B1 00), one with reference 0 with
        "invalid parameter" (80 B8 00);
      - a new Write before the response was read replaces the request (the old response is gone);
        the end of the class-1 connection (c1_drop: Set_Prm, watchdog, leaving data exchange)
        forgets a response not yet read;
      - fault injection: c1_silent -- no request is ever answered (every poll gets SC), so the
        master's C1_Response_Timeout runs out; busy_s -- that many seconds of "state conflict".

The parameter table (Dpv1AxisModel.ds47_execute): the profile's parameters with a PNU, nothing else.
Values in the data type the profile's entry implies: 16 bits Unsigned16 (0x06), or Integer16 (0x03)
for a signed one (`signed: true` or min < 0); `size: 32` Unsigned32 / Integer32 (0x07 / 0x04);
PNU 965 as Word (0x42). A change takes that data type or Word / Double word of the same width.
Errors (the PROFIdrive error numbers, ds47.ERRORS): 0x00 a PNU not in the table; 0x04 a subindex or
more than one element on a parameter that is no array; 0x03 subindex + elements past an array's end;
0x01 a read-only one (access: ro, PNU 918, 947, 964, 965); 0x0B any change but of PNU 927 while PNU
927 = 0; 0x17 another format; 0x18 a number of values other than the elements addressed; 0x02 a value
outside min..max; 0x11 a change of an `access: stop` parameter while the motor turns; 0x19 an axis
other than the profile's `dpv1.axis` (or 0, the device); attribute 0x20 (description) read 0x09,
changed 0x07, 0x30 (text) read 0x0F, changed 0x20, other attributes 0x16. PROFIdrive parameters:
PNU 918 the station address, 927 the parameter change rights, 947 the fault numbers (subindex 0 the
active fault, 8, 16, 24 the older ones: `profidrive.fault_memory`), 964 the device identification
(the profile's `values:`), 965 the profile number 0x0329 (PROFIdrive 3, version 4.1). The drive's own
P120 (output frequency) and P121 (operating hours) follow the drive when the profile has them.

Options, also from a sim:// URL through set= (SETTINGS below, sim/plant.py): set=9:busy=0.05 (seconds
of state conflict), set=9:c1_silent=1; `pdrive sim-ctl set 9 busy 0.05` while it runs.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, Protocol

from profidrive_cli.dp import msac1 as M1
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.profidrive import State
from profidrive_cli.drives.profidrive import ds47 as D
from profidrive_cli.drives.profidrive.config import Dpv1Config
from profidrive_cli.sim.motor import store
from profidrive_cli.sim.profidrive_model import ProfidriveModel

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import ParamDef, Profile

#: sim:// set= options the model takes beyond the profile's parameters (sim/plant.py): the values each
#: takes (busy: seconds of "state conflict" before a parameter response; c1_silent: 1 = never answer)
SETTINGS: dict[str, tuple[float, ...]] = {
    "busy": (0, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1, 2),
    "c1_silent": (0, 1),
}
#: how long after its request the DP-V1 answer is ready, by default (seconds of the bus's clock)
DEFAULT_DELAY_S = 0.002
#: PROFIdrive profile number (PNU 965): profile 3 (PROFIdrive), version 4.1 -> octets 3, 41
PROFILE_NUMBER = 0x0329

E_PNU, E_READ_ONLY, E_LIMIT, E_SUBINDEX, E_NO_ARRAY = 0x00, 0x01, 0x02, 0x03, 0x04
E_DESC_READ_ONLY, E_NO_DESCRIPTION, E_NO_RIGHTS, E_NO_TEXT = 0x07, 0x09, 0x0B, 0x0F
E_STATE, E_ADDRESS, E_FORMAT, E_VALUES, E_AXIS = 0x11, 0x16, 0x17, 0x18, 0x19
E_TEXT_READ_ONLY, E_SERVICE = 0x20, 0x21
#: the PROFIdrive parameters always read-only here (whatever the profile's access says)
READ_ONLY_PNUS = frozenset({pd.PNU_NODE_ADDRESS, pd.PNU_FAULT_NUMBER, pd.PNU_DEVICE_ID,
                            pd.PNU_PROFILE})


class ParamTable(Protocol):
    """What Ds47Server asks of its axis (Dpv1AxisModel)."""

    def ds47_execute(self, request: D.ParamRequest, now: float) -> D.ParamResponse: ...

    def ds47_refused(self, data: bytes) -> D.ParamResponse | None: ...


class Ds47Server:
    """The axis's class-1 server: data record 47 in `slot` (see the module doc). sans-IO."""

    def __init__(self, table: ParamTable, slot: int = 0, delay_s: float = DEFAULT_DELAY_S,
                 busy_s: float = 0.0, silent: bool = False):
        self.table = table
        self.slot = slot
        self.delay_s = delay_s
        self.busy_s = busy_s
        self.silent = silent
        #: the parameter response not yet read (its octets) and when it is ready
        self._response: bytes | None = None
        self._ready_at = 0.0
        #: counters a test can look at
        self.stats = {"writes": 0, "reads": 0, "state_conflicts": 0, "refused": 0}

    def c1_request(self, pdu: M1.Msac1Pdu, now: float) -> tuple[bytes, float] | None:
        if self.silent:
            return None
        fn = pdu.function
        at = now + self.delay_s
        if pdu.slot != self.slot:
            return M1.error_response(fn, 0xB2), at                    # invalid slot
        if pdu.index != D.INDEX:
            return M1.error_response(fn, 0xB0), at                    # invalid index
        if fn == M1.WRITE:
            return self._write(pdu, now, at)
        self.stats["reads"] += 1
        response = self._response
        if response is None or now < self._ready_at:
            self.stats["state_conflicts"] += 1
            return M1.error_response(fn, M1.STATE_CONFLICT), at
        self._response = None
        return M1.read_response(self.slot, D.INDEX, response[:pdu.length]), at

    def _write(self, pdu: M1.Msac1Pdu, now: float, at: float) -> tuple[bytes, float]:
        self.stats["writes"] += 1
        self._response = None                   # a new request replaces the one not yet read
        data = pdu.data
        try:
            request = D.ParamRequest.decode(data)
        except D.Ds47Error:
            refused = self.table.ds47_refused(data)
            if refused is None:
                self.stats["refused"] += 1
                return M1.error_response(M1.WRITE, 0xB1 if len(data) < 4 else 0xB8), at
            response = refused
        else:
            response = self.table.ds47_execute(request, now)
        self._response = response.encode()
        self._ready_at = at + self.busy_s
        return M1.write_response(self.slot, D.INDEX, len(data)), at

    def c1_drop(self, now: float) -> None:
        self._response = None


class Dpv1AxisModel(ProfidriveModel):
    """The generic PROFIdrive V4 axis: the PROFIdrive drive model plus its DS47 parameter table.
    The family's sim model for every `profidrive` profile: without `profidrive.dpv1:` it is the
    PROFIdrive drive model alone (c1_server None)."""

    def __init__(self, profile: Profile, *, delay_s: float = DEFAULT_DELAY_S, busy_s: float = 0.0,
                 c1_silent: bool = False, **kw: Any):     # ProfidriveModel's keyword arguments
        kw.setdefault("profile_version", PROFILE_NUMBER)
        super().__init__(profile, **kw)
        dpv1 = self.cfg.dpv1 or Dpv1Config()
        self.axis = dpv1.axis
        #: the DS47 table: PNU -> the profile's parameter (the first with that PNU)
        self.table: dict[int, ParamDef] = {}
        for p in profile.parameters.values():
            if p.pnu is not None:
                self.table.setdefault(p.pnu, p)
        ident = self.table.get(pd.PNU_DEVICE_ID)
        values = ident.extra.get("values") if ident is not None else None
        self.device_identification: tuple[int, ...] = _words(values, f"{profile.name}: PNU964 values")
        self.run_seconds = 0.0
        #: the DS47 server; SAP 51 is served (c1_server) only for a profile with `profidrive.dpv1:`
        #: -- another profile of the family is a DP-V0 PROFIdrive card (PKW words, SAP 51 RS)
        self.ds47 = Ds47Server(self, dpv1.slot, float(delay_s), float(busy_s), bool(c1_silent))
        self.c1_server = self.ds47 if self.cfg.dpv1 is not None else None

    # -- the PROFIdrive parameters ---------------------------------------------------------------
    def read_special(self, pnu: int, sub: int) -> int | None:
        if pnu == pd.PNU_DEVICE_ID:
            ids = self.device_identification
            return ids[sub] if 0 <= sub < len(ids) else 0
        return super().read_special(pnu, sub)

    def next_due(self, now: float) -> float | None:
        """As the generic drive (tick() below adds only what follows the drive: the output frequency,
        the operating hours, which catch_up's one tick at the last missed time makes up)."""
        return super().next_due(now)

    def tick(self, now: float) -> None:
        last = self._last_tick
        super().tick(now)
        if last is not None and now > last and self.state in (State.S4, State.S5):
            self.run_seconds += now - last
        store(self, "P120", self.freq)
        store(self, "P121", self.run_seconds // 3600)

    # -- DS47 ------------------------------------------------------------------------------------
    def ds47_execute(self, request: D.ParamRequest, now: float) -> D.ParamResponse:
        """The response to a parameter request, every parameter of it executed in order."""
        items: list[D.ParamValues | D.ParamFault]
        if request.axis not in (0, self.axis):
            items = [D.ParamFault(E_AXIS)] * len(request.addresses)
        elif request.request_id == D.REQUEST_READ:
            items = [self._read(a) for a in request.addresses]
        else:
            items = [self._change(a, v) for a, v in zip(request.addresses, request.values)]
        return D.answer(request, items)

    def ds47_refused(self, data: bytes) -> D.ParamResponse | None:
        """The negative response to a request that does not decode (see the module doc); None
        when it has no header to mirror (under 4 octets, reference 0)."""
        if len(data) < 4 or data[0] == 0:
            return None
        rid = data[1]
        number = E_ADDRESS if rid in D.REQUEST_NAMES else E_SERVICE
        response_id = D.RESPONSE_CHANGE_NEGATIVE if rid == D.REQUEST_CHANGE else D.RESPONSE_READ_NEGATIVE
        return D.ParamResponse(data[0], response_id, data[2], 1, (D.ParamFault(number),))

    def _entry(self, a: D.ParamAddress, change: bool) -> ParamDef | D.ParamFault:
        """The parameter an address names, or the fault of its address."""
        p = self.table.get(a.pnu)
        if p is None:
            return D.ParamFault(E_PNU)
        if a.attribute != D.ATTR_VALUE:
            if a.attribute == D.ATTR_DESCRIPTION:
                return D.ParamFault(E_DESC_READ_ONLY if change else E_NO_DESCRIPTION)
            if a.attribute == D.ATTR_TEXT:
                return D.ParamFault(E_TEXT_READ_ONLY if change else E_NO_TEXT)
            return D.ParamFault(E_ADDRESS)
        n = max(1, a.elements)
        length = _array_len(p)
        if length is None:
            if a.subindex != 0 or n != 1:
                return D.ParamFault(E_NO_ARRAY)
        elif a.subindex + n > length:
            return D.ParamFault(E_SUBINDEX)
        return p

    def _format(self, p: ParamDef) -> int:
        if p.pnu == pd.PNU_PROFILE:
            return D.FORMAT_WORD
        signed = _signed(p)
        if p.size == 32:
            return D.FORMAT_INTEGER32 if signed else D.FORMAT_UNSIGNED32
        return D.FORMAT_INTEGER16 if signed else D.FORMAT_UNSIGNED16

    def _raw(self, p: ParamDef, sub: int) -> int:
        assert p.pnu is not None
        v = self.read_special(p.pnu, sub) if p.pnu >= 900 else None
        if v is None:
            v = self.values[p.code]
        return v & ((1 << p.size) - 1)

    def _read(self, a: D.ParamAddress) -> D.ParamValues | D.ParamFault:
        p = self._entry(a, change=False)
        if isinstance(p, D.ParamFault):
            return p
        fmt = self._format(p)
        raws = [self._raw(p, a.subindex + i) for i in range(max(1, a.elements))]
        if fmt in (D.FORMAT_INTEGER16, D.FORMAT_INTEGER32):
            raws = [r - (1 << p.size) if r >> (p.size - 1) & 1 else r for r in raws]
        return D.ParamValues(fmt, tuple(raws))

    def _change(self, a: D.ParamAddress, block: D.ParamValues) -> D.ParamValues | D.ParamFault:
        p = self._entry(a, change=True)
        if isinstance(p, D.ParamFault):
            return p
        assert p.pnu is not None
        if p.access == "ro" or p.pnu in READ_ONLY_PNUS:
            return D.ParamFault(E_READ_ONLY)
        if not self.edit_rights and p.pnu != pd.PNU_EDIT_RIGHTS:
            return D.ParamFault(E_NO_RIGHTS)
        own = self._format(p)
        if block.format not in (own, D.FORMAT_DWORD if p.size == 32 else D.FORMAT_WORD) \
                or isinstance(block.values, bytes):
            return D.ParamFault(E_FORMAT)
        n = max(1, a.elements)
        if len(block.values) != n:
            return D.ParamFault(E_VALUES)
        mask = (1 << p.size) - 1
        raws = [int(v) & mask for v in block.values]
        if not all(self.value_allowed(p, self.value_from_wire(p, r)) for r in raws):
            return D.ParamFault(E_LIMIT)
        if p.access == "stop" and self.running:
            return D.ParamFault(E_STATE)
        for i, raw in enumerate(raws):
            res = self.write_special(p.pnu, a.subindex + i, raw)
            if res:
                return D.ParamFault({"read_only": E_READ_ONLY, "stop_only": E_STATE}
                                    .get(res, E_LIMIT))
            if res is None:
                self.values[p.code] = raw
        return D.ParamValues(D.FORMAT_ZERO, ())

    # -- steering (sim/control.py) ---------------------------------------------------------------
    def set_value(self, code: str, value: float) -> None:
        """A profile parameter, or an option of SETTINGS: busy (s), c1_silent (0/1)."""
        key = code.lower()
        if key in SETTINGS:
            if value not in SETTINGS[key]:
                raise ValueError(f"{key} takes {' or '.join(f'{x:g}' for x in SETTINGS[key])}, "
                                 f"got {value:g}")
            if key == "busy":
                self.ds47.busy_s = float(value)
            else:
                self.ds47.silent = bool(value)
            return
        super().set_value(code, value)

    def snapshot(self) -> dict[str, object]:
        if self.c1_server is None:
            return super().snapshot()
        s = self.ds47
        return {**super().snapshot(), "dpv1": {"busy_s": s.busy_s, "c1_silent": s.silent,
                                               **s.stats}}


def _signed(p: ParamDef) -> bool:
    return p.signed or (p.min is not None and p.min < 0)


def _array_len(p: ParamDef) -> int | None:
    n = p.extra.get("array")
    return n if isinstance(n, int) and not isinstance(n, bool) and n > 0 else None


def _words(values: object, what: str) -> tuple[int, ...]:
    """A list of Unsigned16 values from the profile (() for none)."""
    if values is None:
        return ()
    if not isinstance(values, Sequence) or isinstance(values, (str, bytes)) or not all(
            isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 0xFFFF for v in values):
        raise ValueError(f"{what} must be a list of whole numbers 0..65535, got {values!r}")
    return tuple(int(v) for v in values)


def make_model(profile: Profile, **options: Any) -> Dpv1AxisModel:     # (the sim:// URL's options)
    """The axis for `profile`; options: address (PNU 918), delay_s, busy (s of state conflict),
    c1_silent (1: never answer), defaults (code -> value, sim/plant.py's set=, where busy and
    c1_silent may come too), and ProfidriveModel's."""
    if "address" in options:
        options["node_address"] = int(options.pop("address"))
    defaults: Mapping[str, float] = dict(options.pop("defaults", None) or {})
    own = {k: v for k, v in defaults.items() if k.lower() in SETTINGS}
    rest = {k: v for k, v in defaults.items() if k.lower() not in SETTINGS}
    for k, v in own.items():
        options[k.lower()] = v
    busy = float(options.pop("busy", options.pop("busy_s", 0.0)))
    silent = bool(int(float(options.pop("c1_silent", 0))))
    if busy < 0:
        raise ValueError(f"busy must be >= 0 s, got {busy:g}")
    return Dpv1AxisModel(profile, busy_s=busy, c1_silent=silent,
                         defaults=rest or None, **options)


__all__ = ["Ds47Server", "Dpv1AxisModel", "ParamTable", "SETTINGS", "make_model"]
