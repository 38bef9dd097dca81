"""DP-V0 services as typed values that encode to and decode from DU octets (reference §3).

The fixed headers (Set_Prm, Slave_Diag) are construct structs: they are not on the hot path (only
Data_Exchange is, and its DU is the raw output/input octets).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import functools
import struct
from typing import Any

# SAPs (slave DSAP / master SSAP)
SAP_SET_SLAVE_ADD = 55
SAP_RD_INP = 56
SAP_RD_OUTP = 57
SAP_GLOBAL_CONTROL = 58
SAP_GET_CFG = 59
SAP_SLAVE_DIAG = 60
SAP_SET_PRM = 61
SAP_CHK_CFG = 62
SAP_MASTER = 62

SERVICE_NAMES = {
    None: "Data_Exchange", SAP_SET_SLAVE_ADD: "Set_Slave_Add", SAP_RD_INP: "Rd_Inp",
    SAP_RD_OUTP: "Rd_Outp", SAP_GLOBAL_CONTROL: "Global_Control", SAP_GET_CFG: "Get_Cfg",
    SAP_SLAVE_DIAG: "Slave_Diag", SAP_SET_PRM: "Set_Prm", SAP_CHK_CFG: "Chk_Cfg",
}


def service_name(dsap: int | None, ssap: int | None, is_request: bool) -> str:
    """Which DP service a telegram belongs to (requests by DSAP, replies by SSAP)."""
    sap = dsap if is_request else ssap
    if not is_request and dsap is None and ssap is None:
        return "Data_Exchange"
    return SERVICE_NAMES.get(sap, f"SAP {sap}")


class ServiceError(ValueError):
    """DU octets that do not form the service (too short, bad values)."""


# ---------------------------------------------------------------------------------------------
# Set_Prm

@functools.cache
def _set_prm_header() -> Any:          # a construct Struct (construct has no type hints)
    """The fixed Set_Prm header layout (construct: built on first use, so importing dp/ stays cheap
    for commands that never build a Set_Prm)."""
    import construct as cs
    return cs.Struct(
        "station_status" / cs.BitStruct(
            "lock_req" / cs.Flag, "unlock_req" / cs.Flag, "sync_req" / cs.Flag,
            "freeze_req" / cs.Flag, "wd_on" / cs.Flag, "reserved" / cs.BitsInteger(3)),
        "wd_fact_1" / cs.Int8ub,
        "wd_fact_2" / cs.Int8ub,
        "min_tsdr" / cs.Int8ub,
        "ident" / cs.Int16ub,
        "group" / cs.Int8ub,
    )


#: the six standard Slave_Diag octets: st1, st2, st3, master address, ident (big-endian); a plain
#: struct, because `scan` decodes one per station and need not load construct for it
_DIAG_HEADER = struct.Struct(">BBBBH")


def watchdog_factors(ms: float) -> tuple[int, int]:
    """Watchdog time in ms -> (WD_Fact_1, WD_Fact_2) with 10 ms base, both 1..255: the shortest
    watchdog the factors can hold that is not shorter than asked (rounded up, never down), the
    smaller WD_Fact_2 on a tie (so up to 2550 ms WD_Fact_2 = 1)."""
    units = max(1, -(-int(round(ms)) // 10))        # ceil(ms / 10)
    if units > 255 * 255:
        raise ValueError(f"watchdog {ms} ms exceeds 650 s")
    best = None
    for f2 in range(1, 256):
        f1 = -(-units // f2)
        if f1 > 255:
            continue
        if f1 < 1:
            break
        if best is None or f1 * f2 < best[0] * best[1]:
            best = (f1, f2)
            if f1 * f2 == units:
                break
    if best is None:
        raise ValueError(f"watchdog {ms} ms not representable")
    return best


@dataclass
class SetPrm:
    ident: int
    wd_ms: float | None = 1000.0      # None = watchdog off
    lock: bool = True
    unlock: bool = False
    sync: bool = False
    freeze: bool = False
    min_tsdr: int = 11
    group: int = 0
    user_prm: bytes = b""
    wd_factors: tuple[int, int] | None = None   # explicit factors (decoded telegrams keep them)

    def encode(self) -> bytes:
        f1, f2 = self.wd_factors or (watchdog_factors(self.wd_ms) if self.wd_ms else (1, 1))
        octets: bytes = _set_prm_header().build(dict(   # construct (untyped)
            station_status=dict(lock_req=self.lock, unlock_req=self.unlock, sync_req=self.sync,
                                freeze_req=self.freeze, wd_on=self.wd_ms is not None, reserved=0),
            wd_fact_1=f1, wd_fact_2=f2, min_tsdr=self.min_tsdr, ident=self.ident,
            group=self.group)) + bytes(self.user_prm)
        return octets

    @classmethod
    def decode(cls, du: bytes) -> "SetPrm":
        if len(du) < 7:
            raise ServiceError(f"Set_Prm needs 7 octets, got {len(du)}")
        h = _set_prm_header().parse(du[:7])
        s = h.station_status
        wd = h.wd_fact_1 * h.wd_fact_2 * 10.0 if s.wd_on else None
        return cls(ident=h.ident, wd_ms=wd, lock=s.lock_req, unlock=s.unlock_req, sync=s.sync_req,
                   freeze=s.freeze_req, min_tsdr=h.min_tsdr, group=h.group, user_prm=bytes(du[7:]),
                   wd_factors=(h.wd_fact_1, h.wd_fact_2))

    def describe(self) -> str:
        lock = {(True, False): "lock", (False, True): "unlock", (True, True): "unlock",
                (False, False): "no lock change"}[(self.lock, self.unlock)]
        wd = f"watchdog {self.wd_ms:g} ms" if self.wd_ms else "watchdog off"
        extra = "".join([", sync" if self.sync else "", ", freeze" if self.freeze else ""])
        return (f"ident 0x{self.ident:04X}, {lock}, {wd}{extra}, min TSDR {self.min_tsdr}, "
                f"group 0x{self.group:02X}, user prm [{self.user_prm.hex(' ')}]")


# ---------------------------------------------------------------------------------------------
# Slave_Diag

ST1_BITS = ("Station_Non_Existent", "Station_Not_Ready", "Cfg_Fault", "Ext_Diag", "Not_Supported",
            "Invalid_Slave_Response", "Prm_Fault", "Master_Lock")
ST2_BITS = ("Prm_Req", "Stat_Diag", "always 1", "WD_On", "Freeze_Mode", "Sync_Mode", "reserved",
            "Deactivated")
ST3_BITS = ("reserved",) * 7 + ("Ext_Diag_Overflow",)

ST1_WORDS = {
    "Station_Non_Existent": "station does not exist (no answer)",
    "Station_Not_Ready": "not ready for data exchange",
    "Cfg_Fault": "configuration fault: Chk_Cfg does not match the station",
    "Ext_Diag": "extended diagnosis present",
    "Not_Supported": "a requested function is not supported",
    "Invalid_Slave_Response": "invalid response from the station",
    "Prm_Fault": "parameter fault: Set_Prm rejected (ident, length or values)",
    "Master_Lock": "locked by another master",
}
ST2_WORDS = {
    "Prm_Req": "needs parameters (Set_Prm + Chk_Cfg)",
    "Stat_Diag": "static diagnosis: keep reading diagnosis, no valid data",
    "WD_On": "watchdog on",
    "Freeze_Mode": "freeze mode",
    "Sync_Mode": "sync mode",
    "Deactivated": "deactivated by the master",
}

ST1 = {name: 1 << i for i, name in enumerate(ST1_BITS)}
ST2 = {name: 1 << i for i, name in enumerate(ST2_BITS) if name not in ("always 1", "reserved")}
ST2_FIXED = 0x04
ST3_OVERFLOW = 0x80


@dataclass
class ExtDiagBlock:
    kind: str               # "device", "identifier", "channel", "reserved"
    raw: bytes
    modules: list[int] = field(default_factory=list)       # identifier-related: modules with diag
    module: int | None = None                              # channel-related
    channel: int | None = None
    direction: str = ""
    width: str = ""
    error: str = ""

    def describe(self) -> str:
        if self.kind == "device":
            return f"device-related: {self.raw[1:].hex(' ') or '(empty)'}"
        if self.kind == "identifier":
            mods = ", ".join(str(m) for m in self.modules) or "none"
            return f"identifier-related: modules with diagnosis: {mods}"
        if self.kind == "channel":
            return (f"channel-related: module {self.module}, channel {self.channel} {self.direction}, "
                    f"{self.width}: {self.error}")
        return f"reserved block {self.raw.hex(' ')}"


CHANNEL_WIDTH = {1: "bit", 2: "2 bits", 3: "4 bits", 4: "byte", 5: "word", 6: "2 words"}
CHANNEL_ERROR = {1: "short circuit", 2: "undervoltage", 3: "overvoltage", 4: "overload",
                 5: "overtemperature", 6: "line break", 7: "upper limit exceeded",
                 8: "lower limit undershot", 9: "error"}
CHANNEL_DIR = {1: "input", 2: "output", 3: "input/output"}


def decode_ext_diag(data: bytes) -> list[ExtDiagBlock]:
    """Extended diagnosis blocks (reference §3.4); stops at a reserved header or truncation."""
    blocks: list[ExtDiagBlock] = []
    i = 0
    while i < len(data):
        h = data[i]
        typ = h >> 6
        if typ == 2:
            raw = bytes(data[i:i + 3])
            if len(raw) < 3:
                blocks.append(ExtDiagBlock("reserved", bytes(data[i:])))
                break
            et = raw[2] & 0x1F
            err = CHANNEL_ERROR.get(et, "manufacturer-specific error %d" % et if et >= 16
                                    else f"reserved error {et}")
            blocks.append(ExtDiagBlock(
                "channel", raw, module=h & 0x3F, channel=raw[1] & 0x3F,
                direction=CHANNEL_DIR.get(raw[1] >> 6, "?"),
                width=CHANNEL_WIDTH.get(raw[2] >> 5, "invalid width"), error=err))
            i += 3
            continue
        if typ == 3:
            blocks.append(ExtDiagBlock("reserved", bytes(data[i:])))
            break
        ln = h & 0x3F
        if ln < 1 or i + ln > len(data):
            blocks.append(ExtDiagBlock("reserved", bytes(data[i:])))
            break
        raw = bytes(data[i:i + ln])
        if typ == 1:
            mods = [bi * 8 + b for bi, octet in enumerate(raw[1:]) for b in range(8)
                    if octet >> b & 1]
            blocks.append(ExtDiagBlock("identifier", raw, modules=mods))
        else:
            blocks.append(ExtDiagBlock("device", raw))
        i += ln
    return blocks


@dataclass
class SlaveDiag:
    st1: int
    st2: int
    st3: int
    master: int          # 0xFF = not parameterised
    ident: int
    ext: bytes = b""

    def encode(self) -> bytes:
        return _DIAG_HEADER.pack(self.st1, self.st2, self.st3, self.master, self.ident) + self.ext

    @classmethod
    def decode(cls, du: bytes) -> "SlaveDiag":
        if len(du) < 6:
            raise ServiceError(f"Slave_Diag reply needs 6 octets, got {len(du)}")
        st1, st2, st3, master, ident = _DIAG_HEADER.unpack_from(du, 0)
        return cls(st1, st2, st3, master, ident, bytes(du[6:]))

    def has(self, name: str) -> bool:
        if name in ST1:
            return bool(self.st1 & ST1[name])
        if name in ST2:
            return bool(self.st2 & ST2[name])
        if name == "Ext_Diag_Overflow":
            return bool(self.st3 & ST3_OVERFLOW)
        raise KeyError(name)

    @property
    def ready(self) -> bool:
        """Ready for Data_Exchange (reference §3 ready condition, Stat_Diag honoured)."""
        bad = ST1["Station_Non_Existent"] | ST1["Station_Not_Ready"] | ST1["Cfg_Fault"] | ST1["Prm_Fault"]
        return not (self.st1 & bad) and not (self.st2 & (ST2["Prm_Req"] | ST2["Stat_Diag"]))

    def flags(self) -> list[str]:
        out = [n for i, n in enumerate(ST1_BITS) if self.st1 >> i & 1]
        out += [n for i, n in enumerate(ST2_BITS) if self.st2 >> i & 1 and n not in ("always 1", "reserved")]
        if self.st3 & ST3_OVERFLOW:
            out.append("Ext_Diag_Overflow")
        return out

    def state_words(self, own_master: int | None = None) -> str:
        """The DP state in a few words: 'data exchange', 'needs parameters', 'Cfg_Fault', ..."""
        parts = []
        if self.has("Master_Lock") or (own_master is not None and self.master not in (0xFF, own_master)
                                       and not self.has("Prm_Req")):
            parts.append(f"locked by master {self.master}")
        if self.has("Cfg_Fault"):
            parts.append("configuration fault")
        if self.has("Prm_Fault"):
            parts.append("parameter fault")
        if self.has("Prm_Req"):
            parts.append("waiting for parameters")
        if self.has("Stat_Diag"):
            parts.append("static diagnosis")
        if self.has("Not_Supported"):
            parts.append("function not supported")
        if not parts:
            parts.append("ready" if self.ready else "not ready")
        if self.has("Ext_Diag"):
            parts.append("extended diagnosis")
        return ", ".join(parts)

    def explain(self) -> list[str]:
        lines = []
        for i, n in enumerate(ST1_BITS):
            if self.st1 >> i & 1:
                lines.append(f"st1 bit {i} {n}: {ST1_WORDS[n]}")
        for i, n in enumerate(ST2_BITS):
            if self.st2 >> i & 1 and n != "always 1":
                lines.append(f"st2 bit {i} {n}" + (f": {ST2_WORDS[n]}" if n in ST2_WORDS else ""))
        if not self.st2 & ST2_FIXED:
            lines.append("st2 bit 2 is 0 (a slave always sets it): suspicious reply")
        if self.st3 & ST3_OVERFLOW:
            lines.append("st3 bit 7 Ext_Diag_Overflow: more diagnosis than fits")
        lines.append("master: " + ("none (not parameterised)" if self.master == 0xFF
                                   else f"station {self.master}"))
        lines.append(f"ident: 0x{self.ident:04X}")
        return lines

    def ext_blocks(self) -> list[ExtDiagBlock]:
        return decode_ext_diag(self.ext)


# ---------------------------------------------------------------------------------------------
# Global_Control, Set_Slave_Add

GC_CLEAR, GC_UNFREEZE, GC_FREEZE, GC_UNSYNC, GC_SYNC = 0x02, 0x04, 0x08, 0x10, 0x20
GC_NAMES = {GC_CLEAR: "Clear_Data", GC_UNFREEZE: "Unfreeze", GC_FREEZE: "Freeze",
            GC_UNSYNC: "Unsync", GC_SYNC: "Sync"}


@dataclass
class GlobalControl:
    command: int = 0
    group: int = 0

    def encode(self) -> bytes:
        return bytes((self.command, self.group))

    @classmethod
    def decode(cls, du: bytes) -> "GlobalControl":
        if len(du) != 2:
            raise ServiceError(f"Global_Control needs 2 octets, got {len(du)}")
        return cls(du[0], du[1])

    def describe(self) -> str:
        cmds = [n for b, n in GC_NAMES.items() if self.command & b] or ["operate (no command)"]
        grp = "all groups" if self.group == 0 else "groups " + ",".join(
            str(i + 1) for i in range(8) if self.group >> i & 1)
        return f"{' + '.join(cmds)}, {grp}"


@dataclass
class SetSlaveAdd:
    new_address: int
    ident: int
    no_add_chg: bool = False
    extra: bytes = b""

    def encode(self) -> bytes:
        return bytes((self.new_address, self.ident >> 8, self.ident & 0xFF,
                      1 if self.no_add_chg else 0)) + self.extra

    @classmethod
    def decode(cls, du: bytes) -> "SetSlaveAdd":
        if len(du) < 4:
            raise ServiceError(f"Set_Slave_Add needs 4 octets, got {len(du)}")
        return cls(du[0], du[1] << 8 | du[2], du[3] != 0, bytes(du[4:]))
