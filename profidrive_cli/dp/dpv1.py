"""DP-V1 octets inside DP-V0 telegrams, sans-IO: the three DPV1_Status octets that open a DP-V1
slave's Set_Prm user parameters, and the DP-V1 alarm / status blocks inside the device-related
block of the extended diagnosis.

Sources: ../shared/spec/profibus-dp-reference.md §3.1 (lines 214, 234-240: DPV1_Status_1..3) and
§3.4 (line 305: the device-related block's DP-V1 header: Alarm_Type or Status_Type, slot, specifier);
for the bits the reference leaves out (DPV1_Status_1 bits 1, 0 Dis_Stop_Control, Dis_Start_Control;
DPV1_Status_3 bit 4 IsoM_Req; the Alarm_Type and Status_Type numbers; the alarm specifier's Add_Ack
and Seq_Nr; the two bits per module of Module_Status) a public profichip VPC3+ slave header
(`dp_sPRM_t`, `dp_STATUS_DIAG_t`, `E_DP_DIAG_MS`, `MSAC_C1_ALARM_ACK_PDU_t`, `STATUS_TYPE_*`).

Nothing in a telegram says whether the slave is DP-V1 (its GSD's `DPV1_Slave` does): the user
parameters are read as DPV1_Status octets only when their reserved bits are 0, a device-related block
as a DP-V1 block only when its second octet is a defined Alarm_Type or Status_Type.
"""

from __future__ import annotations

from dataclasses import dataclass, field

#: bit -> name, DPV1_Status_1 (user prm octet 0); bits 4, 3 reserved (reference line 238; VPC3 header)
STATUS_1_BITS: dict[int, str] = {7: "DPV1_Enable", 6: "Fail_Safe", 5: "Publisher_Enable",
                                 2: "WD_Base_1ms", 1: "Dis_Stop_Control", 0: "Dis_Start_Control"}
#: DPV1_Status_2 (user prm octet 1); bit 1 reserved (reference line 239)
STATUS_2_BITS: dict[int, str] = {7: "Enable_Pull_Plug_Alarm", 6: "Enable_Process_Alarm",
                                 5: "Enable_Diagnostic_Alarm", 4: "Enable_Manufacturer_Specific_Alarm",
                                 3: "Enable_Status_Alarm", 2: "Enable_Update_Alarm", 0: "Chk_Cfg_Mode"}
#: DPV1_Status_3 (user prm octet 2): bits 2..0 Alarm_Mode; bits 6, 5 reserved (reference line 240)
STATUS_3_BITS: dict[int, str] = {7: "Prm_Cmd", 4: "IsoM_Req", 3: "Prm_Structure"}
RESERVED_MASKS = (0x18, 0x02, 0x60)
#: Alarm_Mode code -> alarms the master can hold (reference line 240)
ALARM_MODE = {0: "1 alarm of each type", 1: "2 alarms in total", 2: "4 alarms in total",
              3: "8 alarms in total", 4: "12 alarms in total", 5: "16 alarms in total",
              6: "24 alarms in total", 7: "32 alarms in total"}

ALARM_TYPES = {1: "Diagnostic_Alarm", 2: "Process_Alarm", 3: "Pull_Alarm", 4: "Plug_Alarm",
               5: "Status_Alarm", 6: "Update_Alarm"}
STATUS_TYPES = {1: "Status_Message", 2: "Module_Status", 30: "Prm_Command_Ack",
                31: "H_Status_Message"}
ALARM_SPECIFIER = {0: "no further differentiation", 1: "error appears (slot disturbed)",
                   2: "error disappears (slot okay)", 3: "error disappears, slot still disturbed"}
STATUS_SPECIFIER = {0: "no further differentiation", 1: "status appears", 2: "status disappears",
                    3: "reserved"}
#: Module_Status: two bits per module, the first module in the lowest bits of the first octet
MODULE_STATUS = {0: "data valid", 1: "data invalid (module fault)",
                 2: "data invalid (wrong module)", 3: "data invalid (no module)"}


@dataclass(frozen=True)
class Dpv1Status:
    """DPV1_Status_1..3: the first three user parameter octets of a DP-V1 slave's Set_Prm."""
    octets: bytes

    @property
    def flags(self) -> list[str]:
        out: list[str] = []
        for octet, names in zip(self.octets, (STATUS_1_BITS, STATUS_2_BITS, STATUS_3_BITS)):
            out += [names[b] for b in sorted(names, reverse=True) if octet >> b & 1]
        return out

    @property
    def alarm_mode(self) -> int:
        return self.octets[2] & 0x07

    @property
    def wd_base_ms(self) -> int:
        """The watchdog's time base: 1 ms with WD_Base_1ms, else 10 ms (reference line 209)."""
        return 1 if self.octets[0] & 0x04 else 10

    def describe(self) -> str:
        flags = ", ".join(self.flags) or "no bit set (DP-V0 compatibility mode)"
        return (f"DP-V1 status {self.octets.hex(' ')}: {flags}; Alarm_Mode {self.alarm_mode} "
                f"({ALARM_MODE[self.alarm_mode]})")

    def to_dict(self) -> dict[str, object]:
        return {"octets": self.octets.hex(" "), "flags": self.flags, "alarm_mode": self.alarm_mode,
                "alarm_mode_text": ALARM_MODE[self.alarm_mode]}


def dpv1_status(user_prm: bytes) -> Dpv1Status | None:
    """The DPV1_Status octets at the start of `user_prm`, or None: fewer than 3 octets, or a
    reserved bit set (then the octets are a DP-V0 slave's own parameters)."""
    if len(user_prm) < 3:
        return None
    head = bytes(user_prm[:3])
    if any(o & m for o, m in zip(head, RESERVED_MASKS)):
        return None
    return Dpv1Status(head)


@dataclass(frozen=True)
class Dpv1Block:
    """A DP-V1 alarm or status block: header (00 + length), type, slot, specifier, data."""
    block: str                 # "alarm" or "status"
    type: int                  # Alarm_Type / Status_Type without bit 7
    type_name: str
    slot: int
    specifier: int             # the whole specifier octet
    specifier_text: str
    data: bytes
    seq_nr: int | None = None          # alarm: specifier bits 7..3
    add_ack: bool | None = None        # alarm: specifier bit 2
    #: Module_Status: (module, state) of every module whose data are not valid
    module_status: list[tuple[int, str]] = field(default_factory=list)

    def describe(self) -> str:
        what = "status" if self.block == "status" else "alarm"
        octet1 = self.type | (0x80 if self.block == "status" else 0)
        s = (f"DP-V1 {what} block: {self.type_name} (0x{octet1:02X}), slot {self.slot}, specifier "
             f"{self.specifier} ({self.specifier_text})")
        if self.block == "alarm":
            s += f", Seq_Nr {self.seq_nr}" + (", Add_Ack" if self.add_ack else "")
        if self.block == "status" and self.type == 2:
            n = len(self.data) * 4
            bad = "; ".join(f"module {m}: {t}" for m, t in self.module_status)
            s += f"; {n} modules: " + (bad or "all data valid")
        elif self.data:
            s += f"; data {self.data.hex(' ')}"
        return s

    def to_dict(self) -> dict[str, object]:
        d: dict[str, object] = {"block": self.block, "type": self.type, "type_name": self.type_name,
                                "slot": self.slot, "specifier": self.specifier,
                                "specifier_text": self.specifier_text, "data": self.data.hex(" ")}
        if self.block == "alarm":
            d.update(seq_nr=self.seq_nr, add_ack=self.add_ack)
        if self.block == "status" and self.type == 2:
            d["module_status"] = [{"module": m, "state": t} for m, t in self.module_status]
        return d


def _type_name(code: int, known: dict[int, str]) -> str | None:
    if code in known:
        return known[code]
    if 32 <= code <= 126:
        return f"manufacturer-specific {code}"
    return None


def dpv1_block(raw: bytes) -> Dpv1Block | None:
    """A device-related block (`raw` from its header octet on) read as a DP-V1 alarm or status
    block; None when it is shorter than the 4-octet DP-V1 header or its type is not defined."""
    if len(raw) < 4 or raw[0] >> 6 != 0:
        return None
    is_status = bool(raw[1] & 0x80)
    code = raw[1] & 0x7F
    name = _type_name(code, STATUS_TYPES if is_status else ALARM_TYPES)
    if name is None:
        return None
    slot, spec, data = raw[2], raw[3], bytes(raw[4:])
    if is_status:
        mods = []
        if code == 2:
            mods = [(i * 4 + k, MODULE_STATUS[octet >> (2 * k) & 3])
                    for i, octet in enumerate(data) for k in range(4) if octet >> (2 * k) & 3]
        return Dpv1Block("status", code, name, slot, spec, STATUS_SPECIFIER[spec & 3], data,
                         module_status=mods)
    return Dpv1Block("alarm", code, name, slot, spec, ALARM_SPECIFIER[spec & 3], data,
                     seq_nr=spec >> 3, add_ack=bool(spec & 0x04))


__all__ = ["Dpv1Status", "Dpv1Block", "dpv1_status", "dpv1_block", "ALARM_TYPES", "STATUS_TYPES",
           "MODULE_STATUS", "ALARM_MODE"]
