"""Yaskawa's rules for `pdrive audit` (YaskawaDrive.audit_rules), each citing its line: the SI-P1
PROFIBUS-DP Option Technical Manual TM.AFD.12 (../shared/seeds/004_1aa532435db44bda.txt; spec
../shared/spec/yaskawa-profibus-dp.md) and, where the option manual leaves a setting to the drive,
the F7 parameters the profile carries (profiles/yaskawa-si-p1.yaml, registers inferred).
"""

from __future__ import annotations

from typing import Any

from profidrive_cli.drives.audit import (AuditRule, comm_loss_rule, not_applicable, ramp_rules,
                                         source_rule, watchdog_rule)

MANUAL = "SI-P1 manual TM.AFD.12"
F7 = "the F7 drive's parameter (profiles/yaskawa-si-p1.yaml, default_source F7; not in the SI-P1 manual)"


def audit_rules(profile: Any) -> list[AuditRule]:
    return [
        comm_loss_rule(f"{MANUAL} L341 (BUS, option PCB communications error: communication is not "
                       f"established between the master and the drive); F6-01 is "
                       f"{F7}: 3 = alarm only, the drive keeps running",
                       "set F6-01 = 0 (ramp to stop on C1-02), 1 (coast to stop, the factory setting) "
                       "or 2 (fast stop on C1-09)", {"param": "F6-01", "min": 0, "max": 2},
                       needs=("F6-01",)),
        watchdog_rule(f"{MANUAL} L341 (BUS fault: communication with the master not established, "
                      f"which the master's DP watchdog detects; the manual gives no time of its own)"),
        source_rule("source.reference", "b1-01", [3], "the frequency reference",
                    "set b1-01 = 3 (option PCB: the PROFIBUS-DP option)",
                    f"{MANUAL} L263-272 (Table 1.5), L147 (installation step 12: set b1-01 and b1-02), "
                    f"L265 (different origins: e.g. b1-02 = 1 terminals with b1-01 = 3)",
                    partner=("b1-02", [3], "the run command")),
        source_rule("source.run", "b1-02", [3], "the run command",
                    "set b1-02 = 3 (option PCB): the run bits act only then",
                    f"{MANUAL} L274-282 (Table 1.6), L147, L265 (\"The run/stop and frequency "
                    f"reference commands may have different origins\": b1-02 = 1 with b1-01 = 3)",
                    partner=("b1-01", [3], "the frequency reference")),
        *ramp_rules("C1-01", "C1-02", "C1-09",
                    f"C1-01 / C1-02: {F7}, profile L99-102; {MANUAL} L656, L710 (the times' unit "
                    f"C1-10 named among the parameters others depend on)",
                    f"C1-09 fast-stop time: {F7}, profile L103"),
        not_applicable("max_frequency", "the SI-P1 manual names no motor rating; the drive's base "
                       "frequency is not in the profile (E1-04 is the F7's maximum output frequency)",
                       f"{MANUAL} L592-596 (frequency units)"),
        not_applicable("save_mode", "no storage setting to read: the drive stores written parameters "
                       "with its ENTER command (`pdrive param set --save`), named only in the write "
                       "fault's text", f"{MANUAL} L910-916 (error 0x22)"),
    ]
