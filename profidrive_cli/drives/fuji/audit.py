"""Fuji's rules for `pdrive audit` (FujiDrive.audit_rules), each citing its card manual's line:
OPC-G1-PDP = INR-SI47-1329a-JE (../shared/seeds/001_02ee17c3305f1f71.txt, English part), OPC-PDP3 =
the bilingual 2016 manual (../shared/seeds/000_59efe766ba1d441f.txt, English part); specs
../shared/spec/fuji-opc-g1-pdp.md and fuji-opc-pdp3.md.
"""

from __future__ import annotations

from typing import Any

from profidrive_cli.drives.audit import (AuditRule, comm_loss_rule, not_applicable, ramp_rules,
                                         save_mode_rule, source_rule, watchdog_rule, zero_data_rule)

#: the manual lines per card (profile name -> what -> citation)
LINES: dict[str, dict[str, str]] = {
    "fuji-opc-g1-pdp": {
        "manual": "OPC-G1-PDP manual INR-SI47-1329a-JE",
        "o27": "L2760-2778 (Table 9.1: o27 = 3, 13-15 keep the current operation, no er5; o28 delay), "
               "L2781-2784 (H81 light alarm)",
        "watchdog": "L2983 (er5 soon after start: the master's watchdog time too short), L2732-2733",
        "y98": "L1846-1869 (Table 5.2: y98 = 3 recommended), L2987-2988 (y98 not 3; y99, LE, LOC have priority)",
        "ramps": "L2756 (o27 forced deceleration on F08); F07 is the FRENIC's acceleration time (not in the card manual)",
        "quick": "L2243 (CTW bit 2 OFF3 stops on the deceleration time of H56)",
        "fmax": "L1932 (F03 = 60: maximum frequency in Hz)",
    },
    "fuji-opc-pdp3": {
        "manual": "OPC-PDP3 manual (2016)",
        "o27": "L6478-6559 (Table 9.1: o27 = 3, 13-15 keep the current operation, no er5; o28 delay), "
               "L6557-6559 (light alarm)",
        "watchdog": "L6883 (er5 right after start: the master's watchdog time too short)",
        "y98": "L4183-4206 (y98: 1 frequency from PROFIBUS, 2 run command from PROFIBUS, 3 both; "
               "3 recommended), L6894 (y98 not 3)",
        "ramps": "F08: the o27 forced-deceleration time (Table 9.1, L6478-6559); F07 is the FRENIC's "
                 "acceleration time (not in the card manual)",
        "quick": "L5126 (OFF3 stops on the deceleration time of H56)",
        "fmax": "L4473 (F03 = 60: maximum frequency in Hz)",
        "y97": "L4288 (y97 communication data storage), L4325-4333 (*6: with 1 the data is deleted at "
               "power-off; 2 saves it)",
        "o32": "L6566-6578 (Chapter 10, Table 10.1: o32 = 0, the factory default, keeps the current "
               "operation ignoring all-zero data, which some masters send when the PLC stops; 1 coasts "
               "to a stop, state S1)",
    },
}


def audit_rules(profile: Any) -> list[AuditRule]:
    lines = LINES.get(profile.name, LINES["fuji-opc-g1-pdp"])
    m = lines["manual"]

    def cite(key: str) -> str:
        return f"{m} {lines[key]}"

    rules = [
        comm_loss_rule(cite("o27"),
                       "set o27 = 0 (coast and trip er5 at once, the factory setting) or 10 "
                       "(decelerate on F08, then er5); 1/2 and 11/12 act after the o28 delay",
                       {"param": "o27", "expect": 0}, needs=("o27", "o28"), delay_code="o28"),
        watchdog_rule(cite("watchdog")),
        source_rule("source.y98", "y98", [3], "the run command and the frequency reference",
                    "set y98 = 3 (run and frequency commands from PROFIBUS), as the manual recommends",
                    cite("y98"), split={1: "y98 = 1, the frequency from PROFIBUS, the run command from "
                                           "the inverter", 2: "y98 = 2, the run command from PROFIBUS, "
                                           "the frequency from the inverter"}),
        source_rule("source.y99", "y99", [0], "with y99 set, the loader's link has priority: the run "
                    "command or the reference", "set y99 = 0 (the loader link takes nothing over)",
                    cite("y98"), severity="warning"),
        *ramp_rules("F07", "F08", "H56", cite("ramps"), cite("quick")),
        not_applicable("max_frequency", "the card manual names F03 (maximum frequency, 100 % on the bus) "
                       "but no motor rating: the motor's rated frequency is in the FRENIC manual, not "
                       "in the source", cite("fmax")),
    ]
    if "o32" in lines and profile.param("o32") is not None:
        rules.append(zero_data_rule(
            "o32", cite("o32"), "set o32 = 1 (coast to a stop and shift to S1 on all-zero data), or 2 "
            "(the same when the last control word had bit 10 = 1); then "
            "`pdrive commloss-test --mode clear`", {"param": "o32", "min": 1, "max": 2}))
    if "y97" in lines and profile.param("y97") is not None:
        rules.append(save_mode_rule(
            "y97", [1], 0, "y97 = 1: what the bus writes goes to RAM only and is lost when the "
            "inverter is switched off",
            "set y97 = 0 (writes go to non-volatile memory), or store the RAM with y97 = 2 "
            "(`pdrive param set --save`) before switching off", cite("y97")))
    else:
        rules.append(not_applicable("save_mode", "the OPC-G1-PDP manual documents no storage "
                                    "selection (y97 is the OPC-PDP3's): every write goes to the "
                                    "inverter's memory", f"{m} (Tables 5.1, 5.2: L1801-1877)"))
    return rules
