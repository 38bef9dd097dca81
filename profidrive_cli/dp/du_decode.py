"""A captured DP telegram's data unit in words, sans-IO: what `pdrive sniff` shows under a frame and
puts in its JSON `decoded` object (docs/json.md).

Set_Prm (reference §3.1: the 7 standard octets, the DP-V1 status octets, the rest of the user
parameters), Slave_Diag replies (§3.3 status octets, §3.4 every extended-diagnosis block with the
DP-V1 alarm/status headers of dp/dpv1.py), Chk_Cfg requests and Get_Cfg replies (§3.2 identifiers),
Global_Control and Set_Slave_Add. Other telegrams: None.

DP-V1's acyclic telegrams (SAP 51 MSAC_C1, 50 its alarm SAP, 49 MSAC_C2) have their own decoder,
decode_acyclic(): the MSAC_C1 PDU in words (dp/msac1.py: Read / Write / Alarm_Ack, a negative answer
with its error class and code); a poll (a request without data) and a reply without data named as
such; a class-2 telegram by its function only. What a data record holds (DS47: a PROFIdrive parameter
request or response) is read above dp/, where the drives' codecs are (bustools/dpv1view.py).
"""

from __future__ import annotations

from typing import Any

from profidrive_cli.dp import msac1 as M
from profidrive_cli.dp import services as S
from profidrive_cli.dp.capture import ACYCLIC_SAPS, acyclic_service
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


def decode_acyclic(sap: int, is_request: bool, du: bytes) -> tuple[dict[str, Any], M.Msac1Pdu | None]:
    """A DP-V1 acyclic telegram (capture.acyclic_sap() gave `sap`) in words: (its `decoded` object,
    the PDU when it is an MSAC_C1 one that decodes). The object: `msac` {service, sap, kind, then
    msac1's Msac1Pdu.to_dict(): function, slot, index, length, data | error, error_text | slot,
    alarm_type, specifier; `problem` when the PDU is malformed} and `text` [one line]. kind: request,
    poll (a request without data), response, ack (a reply without data: not ready yet)."""
    service = ACYCLIC_SAPS[sap].split()[0]
    kind = ("request" if du else "poll") if is_request else ("response" if du else "ack")
    m: dict[str, Any] = {"service": service, "sap": sap, "kind": kind}
    d: dict[str, Any] = {"msac": m}
    if not du:
        d["text"] = [f"{service} poll: the master asks for the answer" if is_request
                     else f"{service} reply without data: no answer yet"]
        return d, None
    fn = du[0] & 0x7F
    if sap == M.SAP_C2 or fn not in (M.READ, M.WRITE, M.ALARM_ACK):
        # class 2 (Initiate, Abort, ...), or a function class 1 does not define: named, not decoded
        m["function"] = M.FUNCTIONS.get(fn, f"function 0x{fn:02X}")
        m["data"] = du[1:].hex(" ")
        d["text"] = [f"{acyclic_service(sap, is_request, du)}: {du.hex(' ')}"]
        return d, None
    try:
        pdu = M.decode_pdu(du, is_request)
    except M.Msac1Error as e:
        m["function"] = M.FUNCTIONS[fn]
        m["problem"] = str(e)
        d["text"] = [f"{acyclic_service(sap, is_request, du)}: malformed PDU: {e}: {du.hex(' ')}"]
        return d, None
    m.update(pdu.to_dict())
    # (the data's octets are on the frame's line: not again here)
    words = pdu.describe() if pdu.error is not None or pdu.alarm is not None else \
        f"{pdu.name} slot {pdu.slot} index {pdu.index} length {pdu.length}"
    d["text"] = [f"{service} {'request' if is_request else 'response'}: {words}"]
    return d, pdu


__all__ = ["DECODED_SERVICES", "decode_du", "decode_acyclic", "ext_block"]
