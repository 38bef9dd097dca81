"""Toyo's rules for `pdrive audit` (ToyoDrive.audit_rules), each citing its line of the PBUS66-Z
communication protocol manual (../shared/seeds/002_e31e7b20f4f4e720.txt; spec
../shared/spec/toyo-vf66-pbus66z.md). The VF66's own settings (b-10, b-11, C-00, A-00, the ramps)
have no published PNU: the bus reads none of them; what the card shows in its status word is used
instead.
"""

from __future__ import annotations

from typing import Any

from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.audit import (AuditContext, AuditRule, Finding, comm_loss_rule,
                                         not_applicable, watchdog_rule)

MANUAL = "PBUS66-Z manual"
#: ZSW bit 9 (Table 3.6): 1 = control requested (the master's commands valid), 0 = local operation
CONTROL_REQUESTED = int(pd.Stw.CONTROL_REQUESTED)
#: cycles to let the card answer a control word with bit 10 set (a few bus cycles)
PROBE_CYCLES = 5


def _control(ctx: AuditContext) -> list[Finding]:
    """PROFIdrive mode (J-08 = 0): with bit 10 of the control word set ("master control valid") and
    no run command (OFF1), ZSW bit 9 says whether the inverter takes the master's commands. The
    passive session sends control word 0 (bit 10 = 0: the card keeps its previous command), so the
    rule sends the ready word (ON = 0, nothing turns) for a few cycles, then goes back."""
    d: Any = ctx.drive
    if getattr(d, "mode", 0) != 0:
        return []                   # Toyo original mode: no ZSW; run command word only
    was = d.target
    st = d.last_seen()
    try:
        if was is None:
            d.target = pd.Target.READY
            for _ in range(PROBE_CYCLES):
                st = d.cycle()
                if int(st.raw.get("status_word", 0)) & CONTROL_REQUESTED:
                    break
    finally:
        if was is None:
            d.target = None
            d.cycle()
    if st is None or st.fault or int(st.raw.get("status_word", 0)) & CONTROL_REQUESTED:
        return []
    return [Finding("error", "source.control_requested", "ZSW bit 9",
                    f"0 (local operation), status word 0x{int(st.raw.get('status_word', 0)):04X}",
                    "the inverter does not take the master's commands (local operation): the run "
                    "command or the speed command does not come from the communication option",
                    "on the VF66 set J-00 = 4 (PBUS66-Z), b-11 = 3 (run command from the "
                    "communication option) and b-10 = 3 (speed command), or b-11 = b-10 = 0 with "
                    "b-09 = 2; the ST-F terminal must be on",
                    f"{MANUAL} L2834-2842 (Table 3.6 ZSW bit 9: control requested / local operation); "
                    f"inverter settings L423-617", None)]


def audit_rules(profile: Any) -> list[AuditRule]:
    return [
        comm_loss_rule(f"{MANUAL} L4059-4062 (protection 18, communication timeout error: trips); "
                       f"the manual names no setting for it",
                       "nothing to set: the card trips protection 18", None,
                       note=("C-00 has no PNU: check on the VF66's own keypad that C-00 = 1 (multi-"
                             "function input from the communication option). No pdrive command "
                             "proves it: `pdrive commloss-test` checks protection 18, not the "
                             "master's coast (OFF2) and quick stop (OFF3) the note is about",
                             f"{MANUAL} L2769-2773 (Table 3.5 notes 1, 2: with c-00 = 0 OFF2 and OFF3 "
                             f"act as the normal stop), L612-620 (C-00 multi-function input location: "
                             f"0 terminal block, the factory setting; 1 digital communication "
                             f"option)")),
        watchdog_rule(f"{MANUAL} L4059-4062 (protection 18 trips on a communication timeout with the "
                      f"master)"),
        AuditRule("source.control_requested", "source", "the master's commands valid (ZSW bit 9)",
                  f"{MANUAL} L2834-2842", _control),
        not_applicable("ramps", "the VF66's acceleration and deceleration times have no PNU in the "
                       "PBUS66-Z manual (the setting-data numbers are in the VF66 manual)",
                       f"{MANUAL} L4115-4197 (setting-data access by PNU)"),
        not_applicable("max_frequency", "A-00 (maximum speed, 20000 counts) and the motor rating have "
                       "no published PNU", f"{MANUAL} L790-830 (speed scaling: 20000 = A-00)"),
        not_applicable("save_mode", "no storage setting: every setting-data write goes to the "
                       "inverter's EEPROM (limited write cycles)", f"{MANUAL} L4155-4197"),
    ]
