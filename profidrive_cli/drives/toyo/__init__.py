"""Toyo Denki VF66 with the PBUS66-Z option: the PROFIdrive core plus the card's dialect (family package).

Dialect (profiles/toyo-pbus66z.yaml, keys layouts[out/in], fields, bits, parameter_channel,
traceback, fault_history, plch, speed_full_scale, voltage_class, diag_word_order):
  * little-endian words on the bus, as the manual's frame tables show (profile `word_order`)
  * J-08 mode 0 (PROFIdrive-compatible, PPO1-5, control word STW / status word ZSW) and mode 1 (Toyo
    original frame: run-command word, multi-function input words, status and fault flag words);
    the layout name says which (ppo1..ppo5 = mode 0; toyo, toyo_plch = mode 1)
  * speed words: 20000 = A-00 (not 0x4000), signed; mode 0 reverse = negative speed command, mode 1
    reverse = run-command bit 2
  * control word bits 8/9 = jog 1 (forward) / jog 2 (reverse) with bits 4-6 = 0; no direction bit
  * PKW: tasks 1 (read), 2 (write), 6 (read with subindex); responses 0 (busy), 1, 4, 7; IND is one
    16-bit word (fault history 1-6; traceback recording << 8 | point); PNU bit 10 = 2nd setting
    block; after an error answer task 0 is sent once before the next request (zero_after_error)
  * monitors PNU 677-698 (by name: dc-voltage, motor-speed, ...), traceback PNU 700-715 (TB00-TB15),
    fault history PNU 720 (protection code, inverter mode, setting block)
  * Slave_Diag device block: 0 or 9 octets, words high byte first

Modules:

    config    the profile's Toyo keys (toyo_config, file:line) and the core's config (profidrive_config)
    codec     speed words, bit tables, run-command / control-word meaning, fault-history and traceback words
    params    parameter value scaling (param_value), PKW frames, addressing (resolve_param -> ParamRef)
    describe  decode_area, the per-word and PKW text, decode_diag
    drive     ToyoDrive (the PROFIdrive core's drive with this dialect) and make_drive

This __init__ is the family's face: what the family registry (drives/registry.py: make_drive,
decode_area; the core: profidrive_config, param_value), sim/toyo.py and users need.
"""

from profidrive_cli.drives.toyo.codec import (RECORDING_TEXT, bit_names, ctw_command, decode_history_word,
                                              decode_traceback_ind, history_word, protection, run_cmd_fields,
                                              speed_percent, speed_word, traceback_ind)
from profidrive_cli.drives.toyo.config import ToyoConfig, ToyoLayout, input_words, profidrive_config, toyo_config
from profidrive_cli.drives.toyo.describe import (decode_area, decode_diag, describe_pkw, describe_word,
                                                 speed_plan)
from profidrive_cli.drives.toyo.drive import ToyoDrive, make_drive
from profidrive_cli.drives.toyo.formats import FORMATTERS
from profidrive_cli.drives.toyo.params import (_TB_RE, _toyo_frame, effective_scale, param_at, param_value,
                                               value_from_wire, wire_from_value)

# _toyo_frame (a PKW frame with the card's 16-bit IND) stays reachable here for the tests that build raw frames

#: codes a profile may name besides its parameters (drives/profile.py checks monitors and trip records
#: with it): the traceback points TBcc[r,p]
ADDRESS_FORMS = _TB_RE

__all__ = ["ToyoConfig", "ToyoDrive", "make_drive", "decode_area", "speed_plan", "param_value", "profidrive_config",
           "toyo_config", "speed_word", "speed_percent", "history_word", "decode_history_word",
           "traceback_ind", "decode_traceback_ind", "decode_diag", "protection", "describe_pkw",
           "ctw_command", "run_cmd_fields", "value_from_wire", "wire_from_value", "ToyoLayout",
           "RECORDING_TEXT", "bit_names", "describe_word", "effective_scale", "param_at", "_toyo_frame",
           "FORMATTERS", "input_words", "ADDRESS_FORMS"]
