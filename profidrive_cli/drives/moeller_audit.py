"""Moeller's rules for `pdrive audit` (MoellerDrive.audit_rules), each citing its line of the
DE6-NET-DP manual AWB8240-1418GB (../shared/seeds/003_f2e14cc27342d73f.txt; spec
../shared/spec/moeller-de6-net-dp.md).
"""

from __future__ import annotations

from typing import Any

from profidrive_cli.drives.audit import (AuditRule, comm_loss_rule, max_frequency_rule,
                                         not_applicable, ramp_rules, source_rule, watchdog_rule)

MANUAL = "DE6-NET-DP manual AWB8240-1418GB"


def audit_rules(profile: Any) -> list[AuditRule]:
    return [
        comm_loss_rule(f"{MANUAL} L357-363 (action at communication error: 0 = trip E6x/E7x, 1 = "
                       f"continue on the last command), L1100-1101 (P001, P002)",
                       "set P002 = 0 (the inverter trips E7x when the master is lost; the card sits "
                       "in slot 2; P002 is written only while the inverter is stopped)",
                       {"param": "P002", "expect": 0}, needs=("P002",)),
        watchdog_rule(f"{MANUAL} L357-363 (the trip follows the communication cut-off, which the "
                      f"master's DP watchdog detects; the manual gives no time of its own)"),
        source_rule("source.frequency", "A001", [2], "the frequency reference",
                    "set A001 = 2 (operator): the card gives the reference as the operator source",
                    f"{MANUAL} L294-307 (A001 = 2, A002 = 1 for frequency and commands; the card "
                    f"controls frequency only or commands only with one of them), L958",
                    partner=("A002", [1], "the run command")),
        source_rule("source.commands", "A002", [1], "the run command",
                    "set A002 = 1 (terminal): the card gives the run commands as the terminal source",
                    f"{MANUAL} L294-307 (frequency only: A001 = 2, A002 not 1; commands only: A002 = "
                    f"1, A001 not 2; with frequency only the direction comes from the command source, "
                    f"note 1), L959", partner=("A001", [2], "the frequency reference")),
        *ramp_rules("F002", "F003", "F203",
                    f"{MANUAL} L523-527 (OFF1 stops on F003), L794, L797 (F002, F003)",
                    f"{MANUAL} L531 (OFF3: quick stop on the 2nd deceleration time F203), L798"),
        max_frequency_rule("A004", "A003", f"{MANUAL} L603 (100 % = A004), L828 (A003 1st base "
                           f"frequency), L832 (A004 1st maximum frequency)"),
        not_applicable("save_mode", "no storage setting to read: every bus write is lost at "
                       "power-off unless PNU 971 stores it (write 0, then 1: `pdrive param set "
                       "--save`)", f"{MANUAL} L417, L712"),
    ]
