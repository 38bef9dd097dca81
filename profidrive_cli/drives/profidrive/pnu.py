"""PROFIdrive PNU 9xx: the standard parameter numbers and the request sequences built on them.

Builds PkwFrames (PZD mapping 915/916, save 971, fault memory 947) and turns 963/964 codes into
text. Functions taking `cfg` read a ProfidriveConfig's fields (pzd_map, fault_memory_pnu,
fault_subindexes, fault_positions, baud_codes, device_ids); this module does not import config.py.
"""

from __future__ import annotations

import re
from typing import Protocol

from profidrive_cli.drives.profidrive.pkw import PkwFrame, read_request, write_request


class PnuConfig(Protocol):
    """The fields of a ProfidriveConfig these functions read (config.py imports this module)."""
    @property
    def pzd_map(self) -> tuple[int, int]: ...
    @property
    def fault_memory_pnu(self) -> int: ...
    @property
    def fault_subindexes(self) -> list[int]: ...
    @property
    def fault_positions(self) -> list[str]: ...
    @property
    def baud_codes(self) -> dict[int, str]: ...
    @property
    def device_ids(self) -> dict[int, str]: ...

PNU_PZD_SETPOINT = 915
PNU_PZD_ACTUAL = 916
PNU_NODE_ADDRESS = 918
PNU_EDIT_RIGHTS = 927
PNU_CONTROL_RIGHTS = 928
PNU_FAULT_NUMBER = 947
PNU_BAUD = 963
PNU_DEVICE_ID = 964
PNU_PROFILE = 965
PNU_CONTROL_WORD = 967
PNU_STATUS_WORD = 968
PNU_SAVE = 971


def pzd_map_pnu(direction: str, cfg: PnuConfig | None = None) -> int:
    sp, act = (cfg.pzd_map if cfg else (PNU_PZD_SETPOINT, PNU_PZD_ACTUAL))
    if direction in ("setpoint", "write", "out", "request"):
        return sp
    if direction in ("actual", "read", "in", "response"):
        return act
    raise ValueError(f"PZD map direction must be setpoint or actual, got {direction!r}")


def pzd_map_read(direction: str, slot: int, cfg: PnuConfig | None = None) -> PkwFrame:
    """Read which PNU travels in PZD(slot+2) (slot 1 = PZD3)."""
    return read_request(pzd_map_pnu(direction, cfg), slot, array=True)


def pzd_map_write(direction: str, slot: int, pnu: int,
                  cfg: PnuConfig | None = None) -> PkwFrame:
    """Map `pnu` into PZD(slot+2); pnu 0 frees the word."""
    return write_request(pzd_map_pnu(direction, cfg), pnu, slot, array=True)


def save_requests(pnu: int = PNU_SAVE) -> list[PkwFrame]:
    """Store to non-volatile memory: the 0 -> 1 edge on PNU 971 (two writes)."""
    return [write_request(pnu, 0), write_request(pnu, 1)]


def fault_memory_requests(cfg: PnuConfig) -> list[tuple[str, PkwFrame]]:
    return [(pos, read_request(cfg.fault_memory_pnu, sub, array=True))
            for pos, sub in zip(cfg.fault_positions, cfg.fault_subindexes)]


def baud_code_for(codes: dict[int, str], baud: int) -> int | None:
    """The card's PNU 963 code for `baud` bit/s from its table (texts like '19.2k', '1.5 Mbit/s'): Moeller
    0 = 12 Mbit/s ... 9 = 9.6 kbit/s (spec 6.3), Fuji 1 = 9.6k ... 10 = 12M; None when not listed."""
    for code, text in codes.items():
        m = re.fullmatch(r"\s*([\d.]+)\s*([kM])(?:bit/s)?\s*", str(text))
        if m and round(float(m.group(1)) * (1000 if m.group(2) == "k" else 1000000)) == baud:
            return code
    return None


def decode_baud(code: int, cfg: PnuConfig) -> str:
    return cfg.baud_codes.get(code, f"unknown baud-rate code {code}")


def decode_device_id(word: int, cfg: PnuConfig) -> str:
    return cfg.device_ids.get(word, f"unknown device 0x{word:04X}")


def _ordinal(n: int) -> str:
    suf = "th" if 10 <= n % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{suf}"


def default_fault_positions(n: int) -> list[str]:
    out = ["current", "last"]
    out += [f"{_ordinal(i)} last" for i in range(2, n)]
    return out[:n]
