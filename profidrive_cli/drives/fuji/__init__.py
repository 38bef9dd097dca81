"""Fuji Electric OPC-G1-PDP (FRENIC-MEGA) and OPC-PDP3 (FRENIC): the PROFIdrive core plus the dialect.

Dialect (profiles/fuji-opc-g1-pdp.yaml, profiles/fuji-opc-pdp3.yaml; keys function_codes,
ppo_select, parameter_channel, storage, comm_loss, zero_data, fault_history, baud_codes):
  * the card's words: CTW/STW, MRV/MAV, PCV = PCA (RC|SPM|PNU), IND, PVA(H)/PVA(L), PCD1-4
  * every inverter function code through the PKW channel: PNU = 0x100 + group code, subindex = the
    code's number (F26 -> PNU 0x104, IND 0x1A00), non-array request IDs 1/2; codes not in the profile
    are reached raw by name ("C05"); PROFIdrive PNUs 915/916/947 use the array IDs 6/7/9
  * request IDs 1, 2, 6, 7, 9; response IDs 1, 4, 6, 7; 16-bit values in PVA(L) only
  * error numbers 0-4, 11 (running), 17, 101 (link priority), 104 (busy: retried until the timeout)
  * CTW bit 10 = PCD valid, bit 11 = reverse (direction = sign of MRV XOR bit 11);
    STW bit 8 FAR, 9 R/L, 10 FDT (E31); MRV/MAV: 0x4000 = F03
  * o30 selects the PPO (power cycle); o27/o28 the reaction to a communication loss (trip Er5);
    y97 (OPC-PDP3) RAM vs EEPROM storage, save = write 2 and wait for 1
  * fault memory PNU947 subindexes 1, 9, 17, 25 (PROFIdrive malfunction codes, several alarms per
    code) and M16-M19 (the exact alarm code): the history lists every candidate, narrowed by M16-M19

Package API (re-exported here; import the package, not its modules): make_drive, decode_area,
speed_plan,
param_value, profidrive_config, fuji_config, parse_function_code, function_code_name,
pcd_assignment, pcd_assignment_code, alarm_candidates, alarm_by_mcode, alarm_text, mcode_of,
ppo_for_o30, o30_for_layout, comm_loss_action, comm_loss_text, FujiDrive, FujiConfig, CommLossAction,
FORMATTERS (value texts by `format:`) and PARSERS (typed texts, o40 "041A"), fuji/formats.py.
Modules: config.py (the profile's Fuji keys -> FujiConfig, the core's ProfidriveConfig), codes.py
(function codes, PCD words, alarms, o30, o27), drive.py (FujiDrive), describe.py (decode_area).
"""

from __future__ import annotations

from profidrive_cli.drives.fuji.codes import (alarm_by_mcode, alarm_candidates, alarm_text,
                                              comm_loss_action, comm_loss_text,
                                              function_code_name, mcode_of, o30_for_layout,
                                              param_value, parse_function_code, pcd_assignment,
                                              pcd_assignment_code, ppo_for_o30)
from profidrive_cli.drives.fuji.config import (FAMILY_PARAM_KEYS, FORMATS, FUJI_CTW_BITS,
                                               FUJI_STW_BITS, STOP_ACTIONS, CommLossAction,
                                               FujiConfig, fuji_config, parse_int_set,
                                               profidrive_config)
from profidrive_cli.drives.fuji.describe import decode_area, speed_plan
from profidrive_cli.drives.fuji.formats import FORMATTERS, PARSERS
from profidrive_cli.drives.fuji.drive import FujiDrive, make_drive

__all__ = ["FujiConfig", "FujiDrive", "make_drive", "decode_area", "speed_plan", "param_value", "fuji_config",
           "profidrive_config", "parse_function_code", "function_code_name", "pcd_assignment",
           "pcd_assignment_code", "alarm_candidates", "alarm_by_mcode", "alarm_text", "ppo_for_o30",
           "o30_for_layout", "comm_loss_action", "comm_loss_text", "mcode_of", "CommLossAction",
           "parse_int_set", "FAMILY_PARAM_KEYS", "FORMATS", "STOP_ACTIONS", "FUJI_CTW_BITS",
           "FUJI_STW_BITS", "FORMATTERS", "PARSERS"]
