"""What a parsed GSD file holds (reference §5): plain dataclasses, no parsing and no Set_Prm logic here.

Every value the parser read is kept in `Gsd.values` under its canonical keyword (lower case; the
Yaskawa spelling `MaxTsd_<baud>` is stored as `maxtsdr_<baud>`), with the line it came from in
`Gsd.value_lines`. Unknown keywords are kept there too (raw text) and listed in `Gsd.unknown`.
The properties below are the keywords a DP master needs, typed and with the standard's defaults.

Module selection (select_module, Gsd.find_module) is the model's own lookup: a Module object, an int
(1-based position in the file, as `pdrive gsd show` numbers them), or a string: the exact name (then
case-insensitive, surrounding blanks ignored), a position ("3"), or "PPOn" which picks the first module
whose name carries PPO number n ("PPO3", "PPO Type 3", "PPO-03, ..." all match "PPO3").

The model imports nothing of gsd/: the parser builds it, the interpreter (interp.py) reads it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Iterable

from profidrive_cli import UsageError
from profidrive_cli.dp.cfg import CfgModule, decode_cfg

# (GSD suffix, bit/s, default MaxTsdr in bit times when the file gives none: reference §5 / §4.1)
BAUDS: tuple[tuple[str, int, int], ...] = (
    ("9.6", 9_600, 60),
    ("19.2", 19_200, 60),
    ("31.25", 31_250, 60),
    ("45.45", 45_450, 60),
    ("93.75", 93_750, 60),
    ("187.5", 187_500, 60),
    ("500", 500_000, 100),
    ("1.5M", 1_500_000, 150),
    ("3M", 3_000_000, 250),
    ("6M", 6_000_000, 450),
    ("12M", 12_000_000, 800),
)
_BAUD_BY_KEY = {s.lower(): (s, bps, d) for s, bps, d in BAUDS}
_BAUD_BY_BPS = {bps: (s, bps, d) for s, bps, d in BAUDS}

# Set_Prm DU is at most 244 octets, 7 of them the standard part: User_Prm_Data <= 237 octets.
MAX_USER_PRM_LEN = 237

# Value range of each ExtUserPrmData type (Bit/BitArea ranges follow from the bit count).
INT_TYPES: dict[str, tuple[int, int, int]] = {   # name -> (octets, min, max)
    "Unsigned8": (1, 0, 0xFF),
    "Unsigned16": (2, 0, 0xFFFF),
    "Unsigned32": (4, 0, 0xFFFF_FFFF),
    "Signed8": (1, -0x80, 0x7F),
    "Signed16": (2, -0x8000, 0x7FFF),
    "Signed32": (4, -0x8000_0000, 0x7FFF_FFFF),
}


def baud_key(baud: int | str) -> tuple[str, int, int]:
    """9600 / '9.6' / '9.6k' / '1.5M' / '1500000' -> (GSD suffix, bit/s, default MaxTsdr)."""
    if isinstance(baud, bool):
        raise UsageError(f"unknown baud rate {baud!r}")
    if isinstance(baud, int):
        if baud in _BAUD_BY_BPS:
            return _BAUD_BY_BPS[baud]
        raise UsageError(f"unknown baud rate {baud} bit/s; DP rates: "
                         + ", ".join(s for s, _, _ in BAUDS))
    t = str(baud).strip().lower().replace("kbit/s", "").replace("bit/s", "").replace("bd", "")
    t = t.replace("_", "").replace(" ", "")
    if t.isdigit() and int(t) in _BAUD_BY_BPS:
        return _BAUD_BY_BPS[int(t)]
    if t.endswith("k") and t[:-1] and t[:-1].replace(".", "", 1).isdigit():
        t = t[:-1]
    if t.endswith("mbit"):
        t = t[:-3]
    if t in _BAUD_BY_KEY:
        return _BAUD_BY_KEY[t]
    raise UsageError(f"unknown baud rate {baud!r}; DP rates: " + ", ".join(s for s, _, _ in BAUDS))


@dataclass
class PrmText:
    """PrmText = ref ... Text(value) = "..." ... EndPrmText"""
    ref: int
    line: int
    texts: dict[int, str] = field(default_factory=dict)


@dataclass
class ExtUserPrmData:
    """ExtUserPrmData = ref "name" / type line / Prm_Text_Ref / Changeable / Visible / EndExtUserPrmData."""
    ref: int
    name: str
    line: int
    data_type: str = ""               # Bit, BitArea, Unsigned8/16/32, Signed8/16/32 ("" = type line missing)
    bit_lo: int | None = None         # Bit(n): n..n; BitArea(a-b): a..b (within one octet, 0..7)
    bit_hi: int | None = None
    default: int = 0
    min_value: int | None = None      # range form "a-b"
    max_value: int | None = None
    allowed: tuple[int, ...] | None = None   # list form "a,b,c"
    text_ref: int | None = None
    texts: dict[int, str] | None = None      # resolved PrmText (after parsing)
    changeable: bool = True
    visible: bool = True
    type_line: int = 0

    @property
    def is_bits(self) -> bool:
        return self.data_type in ("Bit", "BitArea")

    @property
    def size(self) -> int:
        """Octets this parameter occupies at its offset."""
        if self.is_bits:
            return 1
        return INT_TYPES[self.data_type][0] if self.data_type in INT_TYPES else 0

    def type_range(self) -> tuple[int, int]:
        if self.is_bits:
            assert self.bit_lo is not None and self.bit_hi is not None   # the parser sets both
            return 0, (1 << (self.bit_hi - self.bit_lo + 1)) - 1
        if self.data_type in INT_TYPES:
            _, lo, hi = INT_TYPES[self.data_type]
            return lo, hi
        return 0, 0

    def describe_type(self) -> str:
        if self.data_type == "Bit":
            return f"Bit({self.bit_lo})"
        if self.data_type == "BitArea":
            return f"BitArea({self.bit_lo}-{self.bit_hi})"
        return self.data_type or "?"

    def describe_allowed(self) -> str:
        if self.allowed is not None:
            return ",".join(str(v) for v in self.allowed)
        lo, hi = self.type_range()
        lo = lo if self.min_value is None else self.min_value
        hi = hi if self.max_value is None else self.max_value
        return f"{lo}-{hi}"

    def is_allowed(self, value: int) -> bool:
        lo, hi = self.type_range()
        if not lo <= value <= hi:
            return False
        if self.allowed is not None:
            return value in self.allowed
        if self.min_value is not None and value < self.min_value:
            return False
        if self.max_value is not None and value > self.max_value:
            return False
        return True

    def text_for(self, value: int) -> str | None:
        return self.texts.get(value) if self.texts else None


@dataclass
class PrmConst:
    offset: int
    data: bytes
    line: int


@dataclass
class PrmRef:
    offset: int
    ref: int
    line: int


@dataclass
class PrmBlock:
    """One user-parameter block: the device's (User_Prm_Data_Len / User_Prm_Data / Ext_User_Prm_Data_*)
    or a module's (Ext_Module_Prm_Data_Len / Ext_User_Prm_Data_*)."""
    length: int | None = None
    length_line: int = 0
    base: bytes | None = None
    base_line: int = 0
    consts: list[PrmConst] = field(default_factory=list)
    refs: list[PrmRef] = field(default_factory=list)

    @property
    def empty(self) -> bool:
        return not self.length and not self.base and not self.consts and not self.refs


@dataclass
class DiagArea:
    """Unit_Diag_Area = first-last with Value(v) = "text" ... Unit_Diag_Area_End (bit numbers as Unit_Diag_Bit)."""
    first_bit: int
    last_bit: int
    line: int
    values: dict[int, str] = field(default_factory=dict)


@dataclass
class UnitDiagType:
    """UnitDiagType = n ... EndUnitDiagType: X_Unit_Diag_* texts that apply when the device-related block's
    first octet (DP-V1 status/alarm type) is n."""
    type_value: int
    line: int
    bits: dict[int, str] = field(default_factory=dict)
    not_bits: dict[int, str] = field(default_factory=dict)
    areas: list[DiagArea] = field(default_factory=list)


@dataclass
class Slot:
    """SlotDefinition: Slot(n) = "name" default-module-ref allowed-refs"""
    number: int
    name: str
    default: int | None
    allowed: tuple[int, ...]
    line: int


@dataclass
class Module:
    name: str
    cfg: bytes
    line: int
    index: int                      # 1-based position in the file (what `pdrive gsd show` numbers)
    reference: int | None = None    # module reference number (bare number line / Module_Reference)
    prm: PrmBlock = field(default_factory=PrmBlock)
    f_prm: PrmBlock = field(default_factory=PrmBlock)   # PROFIsafe F_Ext_* (appended after prm)
    x_prm: PrmBlock = field(default_factory=PrmBlock)   # DXB X_Ext_* (not part of Set_Prm; kept)
    info_text: str | None = None
    channel_diag: dict[int, str] = field(default_factory=dict)
    data_areas: list[dict[str, Any]] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)
    end_line: int = 0

    @cached_property
    def cfg_modules(self) -> list[CfgModule]:
        return decode_cfg(self.cfg)

    @property
    def inputs(self) -> int:
        return sum(m.inputs for m in self.cfg_modules)

    @property
    def outputs(self) -> int:
        return sum(m.outputs for m in self.cfg_modules)

    @property
    def display_name(self) -> str:
        return self.name.strip()

    def describe_cfg(self) -> str:
        return "; ".join(m.describe() for m in self.cfg_modules)


def _b(v: Any) -> bool:
    return bool(v) if isinstance(v, int) else False


@dataclass
class Gsd:
    path: str
    encoding: str = "ascii"
    values: dict[str, Any] = field(default_factory=dict)
    value_lines: dict[str, int] = field(default_factory=dict)
    prm_texts: dict[int, PrmText] = field(default_factory=dict)
    ext_user_prm_data: dict[int, ExtUserPrmData] = field(default_factory=dict)
    prm: PrmBlock = field(default_factory=PrmBlock)
    modules: list[Module] = field(default_factory=list)
    unit_diag_bits: dict[int, str] = field(default_factory=dict)
    unit_diag_not_bits: dict[int, str] = field(default_factory=dict)
    unit_diag_areas: list[DiagArea] = field(default_factory=list)
    unit_diag_types: dict[int, UnitDiagType] = field(default_factory=dict)
    channel_diag: dict[int, str] = field(default_factory=dict)
    slots: list[Slot] = field(default_factory=list)
    unknown: list[tuple[str, int]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    start_line: int = 0            # line of #Profibus_DP
    end_line: int = 0              # number of the last line of the file

    # ---- generic access
    def get(self, keyword: str, default: Any = None) -> Any:
        return self.values.get(keyword.lower(), default)

    def _int(self, key: str, default: int | None = None) -> int | None:
        v = self.values.get(key)
        return v if isinstance(v, int) and not isinstance(v, bool) else default

    def _str(self, key: str) -> str | None:
        v = self.values.get(key)
        return v if isinstance(v, str) else None

    # ---- identity
    @property
    def vendor_name(self) -> str | None:
        return self._str("vendor_name")

    @property
    def model_name(self) -> str | None:
        return self._str("model_name")

    @property
    def revision(self) -> str | None:
        return self._str("revision")

    @property
    def ident_number(self) -> int | None:
        return self._int("ident_number")

    @property
    def ident(self) -> int | None:
        """Alias of ident_number."""
        return self.ident_number

    @property
    def gsd_revision(self) -> int | None:
        return self._int("gsd_revision")

    @property
    def protocol_ident(self) -> int | None:
        return self._int("protocol_ident")

    @property
    def station_type(self) -> int | None:
        return self._int("station_type")

    @property
    def hardware_release(self) -> str | None:
        return self._str("hardware_release")

    @property
    def software_release(self) -> str | None:
        return self._str("software_release")

    @property
    def slave_family_text(self) -> str | None:
        v = self.values.get("slave_family")
        return None if v is None else str(v)

    @property
    def slave_family(self) -> int | None:
        """Main family number of `Slave_Family = n@sub@sub` (1 = drives)."""
        t = self.slave_family_text
        if t is None:
            return None
        head = t.split("@", 1)[0].strip()
        return int(head) if head.isdigit() else None

    @property
    def title(self) -> str:
        parts = [p.strip() for p in (self.vendor_name, self.model_name) if p and p.strip()]
        return " ".join(parts) or self.path

    # ---- features
    freeze_mode_supp = property(lambda self: _b(self.values.get("freeze_mode_supp")))
    sync_mode_supp = property(lambda self: _b(self.values.get("sync_mode_supp")))
    auto_baud_supp = property(lambda self: _b(self.values.get("auto_baud_supp")))
    set_slave_add_supp = property(lambda self: _b(self.values.get("set_slave_add_supp")))
    fail_safe = property(lambda self: _b(self.values.get("fail_safe")))
    dpv1_slave = property(lambda self: _b(self.values.get("dpv1_slave")))
    modular_station = property(lambda self: _b(self.values.get("modular_station")))
    min_slave_intervall = property(lambda self: self._int("min_slave_intervall"))
    max_module = property(lambda self: self._int("max_module"))
    max_input_len = property(lambda self: self._int("max_input_len"))
    max_output_len = property(lambda self: self._int("max_output_len"))
    max_data_len = property(lambda self: self._int("max_data_len"))
    max_diag_data_len = property(lambda self: self._int("max_diag_data_len"))
    user_prm_data_len = property(lambda self: self._int("user_prm_data_len"))
    max_user_prm_data_len = property(lambda self: self._int("max_user_prm_data_len"))

    @property
    def user_prm_data(self) -> bytes | None:
        v = self.values.get("user_prm_data")
        return v if isinstance(v, bytes) else None

    # ---- baud rates
    def baud_supported(self, baud: int | str) -> bool:
        suffix, _, _ = baud_key(baud)
        return _b(self.values.get(f"{suffix.lower()}_supp"))

    def supported_bauds(self) -> list[str]:
        return [s for s, _, _ in BAUDS if _b(self.values.get(f"{s.lower()}_supp"))]

    def max_tsdr(self, baud: int | str) -> int:
        """MaxTsdr_<baud> in bit times; the standard's default (reference §5) when the file gives none."""
        suffix, _, default = baud_key(baud)
        v = self.values.get(f"maxtsdr_{suffix.lower()}")
        return v if isinstance(v, int) and not isinstance(v, bool) else default

    def max_tsdr_table(self) -> list[dict[str, Any]]:
        rows = []
        for s, bps, default in BAUDS:
            v = self.values.get(f"maxtsdr_{s.lower()}")
            given = isinstance(v, int) and not isinstance(v, bool)
            rows.append({"baud": s, "bps": bps, "supported": _b(self.values.get(f"{s.lower()}_supp")),
                         "max_tsdr": v if given else default, "default": not given})
        return rows

    # ---- modules
    def find_module(self, selector: int | str | Module) -> Module:
        return select_module(self, selector)


# ---------------------------------------------------------------- module selection
_PPO_SEL = re.compile(r"\s*ppo[\s_-]*(?:type[\s_-]*)?0*(\d+)\s*\Z", re.I)


def _ppo_pattern(n: int) -> re.Pattern[str]:
    return re.compile(r"ppo[\s_-]*(?:type[\s_-]*)?0*" + str(n) + r"(?!\d)", re.I)


def select_module(gsd: Gsd, selector: int | str | Module) -> Module:
    if isinstance(selector, Module):
        return selector
    mods = gsd.modules
    if not mods:
        raise UsageError(f"{gsd.path}: the GSD defines no modules")
    if isinstance(selector, bool) or not isinstance(selector, (int, str)):
        raise UsageError(f"bad module selector {selector!r}")
    if isinstance(selector, int):
        if 1 <= selector <= len(mods):
            return mods[selector - 1]
        raise UsageError(f"module number {selector} out of range 1..{len(mods)} ({gsd.title})")
    sel = selector
    for m in mods:
        if m.name == sel:
            return m
    key = sel.strip().casefold()
    for m in mods:
        if m.name.strip().casefold() == key:
            return m
    if key.isascii() and key.isdigit():
        return select_module(gsd, int(key))
    pm = _PPO_SEL.match(sel)
    if pm:
        pat = _ppo_pattern(int(pm.group(1)))
        for m in mods:
            if pat.search(m.name):
                return m
    prefix = [m for m in mods if m.name.strip().casefold().startswith(key)] if key else []
    if len(prefix) == 1:
        return prefix[0]
    names = ", ".join(f"{m.index}: {m.display_name!r}" for m in mods[:12])
    more = f" ... ({len(mods)} modules)" if len(mods) > 12 else ""
    amb = f" ({len(prefix)} names start with it)" if len(prefix) > 1 else ""
    raise UsageError(f"no module {selector!r} in {gsd.title}{amb}; modules: {names}{more}")


def select_modules(gsd: Gsd, selection: Iterable[int | str | Module] | None) -> list[Module]:
    sel = list(selection or [])
    if not sel:
        if not gsd.modular_station and len(gsd.modules) == 1:
            return [gsd.modules[0]]
        if len(gsd.modules) == 1:
            return [gsd.modules[0]]
        names = ", ".join(f"{m.index}: {m.display_name!r}" for m in gsd.modules[:12])
        raise UsageError(f"choose the module(s) for {gsd.title}: {names}")
    mods = [select_module(gsd, s) for s in sel]
    mm = gsd.max_module
    if gsd.modular_station and mm is not None and len(mods) > mm:
        raise UsageError(f"{len(mods)} modules chosen but {gsd.title} takes at most {mm} (Max_Module)")
    return mods
