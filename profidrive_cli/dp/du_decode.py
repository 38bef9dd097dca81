"""A captured DP telegram's data unit in words, sans-IO: what `pdrive sniff` shows under a frame and
puts in its JSON `decoded` object (docs/json.md).

Set_Prm (reference §3.1: the 7 standard octets, the DP-V1 status octets, the rest of the user
parameters), Slave_Diag replies (§3.3 status octets, §3.4 every extended-diagnosis block with the
DP-V1 alarm/status headers of dp/dpv1.py), Chk_Cfg requests and Get_Cfg replies (§3.2 identifiers),
Global_Control and Set_Slave_Add. Other telegrams: None.
"""

from __future__ import annotations

from typing import Any

from profidrive_cli.dp import services as S
from profidrive_cli.dp.cfg import CfgError, decode_cfg
from profidrive_cli.dp.dpv1 import dpv1_block, dpv1_status

#: Station_Status bit -> name (reference §3.1 Station_Status table)
_STATION_STATUS = ((7, "Lock_Req"), (6, "Unlock_Req"), (5, "Sync_Req"), (4, "Freeze_Req"), (3, "WD_On"))


def _set_prm(du: bytes) -> dict[str, Any]:
    p = S.SetPrm.decode(du)
    st = du[0]
    user = bytes(du[7:])
    dv1 = dpv1_status(user)
    base = dv1.wd_base_ms if dv1 is not None else 10
    f1, f2 = du[1], du[2]
    wd_ms = f1 * f2 * base if st & 0x08 else None
    flags = [n for b, n in _STATION_STATUS if st >> b & 1]
    d: dict[str, Any] = {
        "station_status": flags, "wd_fact_1": f1, "wd_fact_2": f2, "watchdog_ms": wd_ms,
        "min_tsdr": du[3], "ident": f"0x{p.ident:04X}", "group": du[6], "user_prm": user.hex(" ")}
    wd = (f"watchdog {wd_ms:g} ms ({f1} x {f2} x {base} ms)" if wd_ms is not None
          else "watchdog off")
    tsdr = f"min TSDR {du[3]}" + (" (keep the slave's)" if du[3] == 0 else " bit times")
    text = [f"Set_Prm: {', '.join(flags) or 'no Station_Status bit'}; {wd}; {tsdr}; ident "
            f"0x{p.ident:04X}; group 0x{du[6]:02X}"]
    rest = user
    if dv1 is not None:
        d["dpv1_status"] = dv1.to_dict()
        text.append(dv1.describe())
        rest = user[3:]
    if rest:
        text.append(("further user prm: " if dv1 is not None else "user prm: ") + rest.hex(" "))
    d["text"] = text
    return d


def ext_block(b: S.ExtDiagBlock) -> dict[str, Any]:
    """One extended-diagnosis block in words: sniff's `decoded.blocks[]` and `pdrive diag`'s ext lines
    (one decoder for both); its text is the Wireshark dissector's (profibus.diag.block), a DP-V1
    alarm / status block decoded by dp/dpv1.py."""
    d: dict[str, Any] = {"kind": b.kind, "raw": b.raw.hex(" ")}
    text = b.describe()
    if b.kind == "identifier":
        d["modules"] = b.modules
    elif b.kind == "channel":
        d.update(module=b.module, channel=b.channel, direction=b.direction, width=b.width,
                 error=b.error)
    elif b.kind == "device":
        v1 = dpv1_block(b.raw)
        if v1 is not None:
            d["dpv1"] = v1.to_dict()
            text = f"device-related: {v1.describe()}"
    d["text"] = text
    return d


def _slave_diag(du: bytes) -> dict[str, Any]:
    g = S.SlaveDiag.decode(du)
    blocks = [ext_block(b) for b in g.ext_blocks()]
    master = None if g.master == 0xFF else g.master
    text = [f"Slave_Diag: st1 0x{g.st1:02X} st2 0x{g.st2:02X} st3 0x{g.st3:02X} "
            f"[{', '.join(g.flags()) or 'no flag'}]; master "
            f"{'none' if master is None else master}; ident 0x{g.ident:04X}"]
    text += ["ext diag: " + b["text"] for b in blocks]
    return {"flags": g.flags(), "master": master, "ident": f"0x{g.ident:04X}", "blocks": blocks,
            "text": text}


def _cfg(name: str, du: bytes) -> dict[str, Any]:
    try:
        mods = [m.describe() for m in decode_cfg(du)]
    except CfgError as e:
        return {"cfg": [], "text": [f"{name}: {e}"]}
    return {"cfg": mods, "text": [f"{name}: " + ("; ".join(mods) or "no identifier")]}


#: the services decode_du has a decoder for (any other: None, without a call)
DECODED_SERVICES = frozenset(("Set_Prm", "Slave_Diag reply", "Chk_Cfg", "Get_Cfg reply",
                              "Global_Control", "Set_Slave_Add"))


def decode_du(service: str, du: bytes) -> dict[str, Any] | None:
    """The DU of a telegram of `service` (as dp.capture names it) in words: a JSON-ready dict with
    a `text` list (the lines sniff prints), or None for a service without a decoder here or a DU
    too short for it (the frame line shows its octets anyway)."""
    try:
        if service == "Set_Prm":
            return _set_prm(du)
        if service == "Slave_Diag reply":
            return _slave_diag(du)
        if service in ("Chk_Cfg", "Get_Cfg reply") and du:
            return _cfg(service.split()[0], du)
        if service == "Global_Control":
            return {"text": ["Global_Control: " + S.GlobalControl.decode(du).describe()]}
        if service == "Set_Slave_Add":
            a = S.SetSlaveAdd.decode(du)
            return {"text": [f"Set_Slave_Add: new address {a.new_address}, ident 0x{a.ident:04X}"
                             + (", no further change" if a.no_add_chg else "")]}
    except S.ServiceError:
        return None
    return None


__all__ = ["DECODED_SERVICES", "decode_du", "ext_block"]
