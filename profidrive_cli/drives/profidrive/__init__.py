"""PROFIdrive V2 core: PPO areas, CTW/STW, the state machine, N2 scaling, the PKW channel, PNU 9xx.

The package's face: it re-exports the public names of its modules, one concern each --
    ppo.py       words <-> octets (word order), PPO layouts and areas
    words.py     CTW/STW bits, the state machine (State, Target, next_control_word)
    scaling.py   N2 scaling (percent, Hz)
    pkw.py       PKE/PKW encoding, AK tables, the sans-IO PkwChannel
    pnu.py       the PNU 9xx numbers and their request sequences
    config.py    the profile's `profidrive:` section (ProfidriveConfig, config(profile))
    params.py    parameter addressing (ParamRef, resolve_code) and value formatting
    drive.py     ProfidriveDrive (the Drive interface) and make_drive
    describe.py  the generic decoder (describe_* and decode_area); ppo_drive_object (sniff --station)
Sans-IO except for `ProfidriveDrive`, which couples the codec with a CyclicChannel (the channel does
the waiting; nothing here sleeps). The family codecs (moeller, fuji, toyo) build on this package
(import it, not its modules); the API below is meant to stay stable.

Public API
----------
Words and layouts
    words_to_bytes(words, word_order="big") -> bytes
    bytes_to_words(data, word_order="big") -> list[int]
    PPO_TYPES: {n: (pkw: bool, pzd_words: int)}            PPO1..5
    PpoLayout(name, pkw, pzd_out, pzd_in, word_order)       .output_len / .input_len (octets)
    ppo_layout(profile, layout_name) -> PpoLayout           from the profile's layouts (cfg sizes)
    PpoArea(pkw: tuple[4 words] | None, pzd: list[int])     PZD1 = CTW/STW, PZD2 = MRV/MAV, PZD3..
    encode_area(layout, area) -> bytes
    decode_area_bytes(layout, data) -> PpoArea

Control and status words
    Ctw, Stw: IntFlag with the generic PROFIdrive bit names
    CTW_NAMES, STW_NAMES: {bit: text}; ctw_names(profile) / stw_names(profile) add the vendor names
    bit_list(word, names) -> list[str]                      names of the set bits
    State (str Enum): S1..S5, FAULT;  state_from_status(stw, moving=None) -> State
    Target (str Enum): READY (= OFF1 stop), SWITCHED_ON, OPERATE, OFF1, OFF2, OFF3, DISABLE, ACK
    next_control_word(status_word, target, extra_bits=0, *, previous=None, moving=None) -> int
    target_reached(status_word, target, moving=None) -> bool
    command_from_control_word(ctw) -> str                   what a control word asks for (decoders)

N2 scaling (0x4000 = 100 %, two's complement for reverse)
    n2_from_percent(pct) -> word;  n2_to_percent(word) -> float
    n2_from_hz(hz, fmax) -> word;  n2_to_hz(word, fmax) -> float
    to_signed16(word) -> int

PKW channel
    encode_pke(ak, pnu, spm=0) -> int;  decode_pke(pke) -> (ak, spm, pnu)
    PkwFrame(ak, pnu, subindex=0, value=0, spm=0, ind_low=0)   .words() / PkwFrame.from_words(words)
    REQUEST_TEXT, RESPONSE_TEXT, POSITIVE_RESPONSES, ERROR_RESPONSES, GENERIC_ERRORS
    PkwResult(request, response, error, error_text, timed_out)  .ok / .value
    PkwChannel(timeout=2.0, zero_after_error=False, zero_between_identical=False,
               error_texts=None, max_zero_cycles=20)
        .submit(request, now=None)  .outputs() -> 4 words  .feed(input_words, now) -> PkwResult | None
        .busy  .cancel()
    read_request(pnu, subindex=0, array=False) -> PkwFrame
    write_request(pnu, value, subindex=0, array=False, long=False) -> PkwFrame

PNU 9xx helpers
    PNU_PZD_SETPOINT 915, PNU_PZD_ACTUAL 916, PNU_NODE_ADDRESS 918, PNU_EDIT_RIGHTS 927,
    PNU_CONTROL_RIGHTS 928, PNU_FAULT_NUMBER 947, PNU_BAUD 963, PNU_DEVICE_ID 964, PNU_PROFILE 965,
    PNU_CONTROL_WORD 967, PNU_STATUS_WORD 968, PNU_SAVE 971
    pzd_map_read(direction, slot) / pzd_map_write(direction, slot, pnu) -> PkwFrame
        direction "setpoint" (915, master->drive) or "actual" (916, drive->master); slot 1 = PZD3
    fault_memory_requests(cfg) -> list[(position label, PkwFrame)]
    save_requests(pnu=971) -> [write 0, write 1]            the 0->1 edge
    decode_baud(code, cfg) -> str;  decode_device_id(word, cfg) -> str;  baud_code_for(codes, baud)

Per-card configuration (the profile's `profidrive:` section, validated with file:line errors)
    ProfidriveConfig.from_profile(profile);  config(profile) -> ProfidriveConfig (cached)
    a family module may define profidrive_config(profile) -> ProfidriveConfig instead (own keys)
    keys (all optional):
      labels: {control: STW, status: ZSW, reference: HSW, actual: HIW}   the card's own word names
      ctw_bits / stw_bits: {bit: name}          vendor names for bits (usually 8..15); null = unused
      held_ctw_bits: [4, 5, 6]                  held at 1 in every control word (extra_bits)
      array_pnus: [915, 916, 947]               PNUs addressed with the array AKs 6/7/8
      pzd_map: {setpoint: 915, actual: 916}
      pkw: {timeout_s, zero_after_error, zero_between_identical, max_zero_cycles,
            requests: [supported AKs], errors: {number: text}, error_numbers: {role: number}}
            roles: unknown_pnu read_only out_of_range bad_subindex not_array wrong_type stop_only
                   no_rights bad_request (the numbers the card answers with; the sim uses them too)
      fault_memory: {pnu: 947, subindexes: [1, 9, ...], positions: [labels]}
      save: {pnu: 971}                          absent = no save command
      baud_codes: {code: text};  device_ids: {word: text}
      ramps: {accel: CODE, decel: CODE, quick_decel: CODE};  jog_reference: CODE

Drive
    ProfidriveDrive(channel, profile, layout=None)  -- the Drive interface (drives/base.py);
    subclass hooks: resolve_param, raw_to_value, value_to_raw, check_value, start_hint,
    write_refused_message, status_extras; see the class docstring.
    Beyond the Drive interface: request(frame), read_raw / write_raw(pnu, ...), card_info(),
    set_pzd(n, raw), pzd_mapping(direction), map_pzd(direction, slot, pnu), jog(on), extra_bits
    decode_area(profile, layout, direction, data, *, max_hz=None) -> dict   (generic PPO decoder)
    ppo_drive_object(direction, area, *, state_without_status_word=None) -> dict
        a decoded area in the common words of `sniff --station` (ProfidriveDrive.normalise_area);
        pkw_drive_param(direction, pkw) -> dict: its PKW channel as the `param` there
    speed_plan(profile, layout, direction, max_hz=None) -> speedplan.SpeedWord | None
        where the N2 reference / actual word sits and its drive-object fields (sniff --station's
        fast path: the rest of an area is decoded once per its octets, this word each time)
    make_drive(channel, profile, layout=None) -> ProfidriveDrive  (so `family: profidrive` works)
"""

from __future__ import annotations

from profidrive_cli.drives.profidrive.config import (ERROR_ROLES, ProfidriveConfig, config,
                                                     ctw_names, stw_names)
from profidrive_cli.drives.profidrive.describe import (check_direction, decode_area,
                                                       describe_control_word, describe_n2,
                                                       describe_pkw, describe_status_word,
                                                       pkw_drive_param, ppo_drive_object,
                                                       speed_plan)
from profidrive_cli.drives.profidrive.drive import ProfidriveDrive, make_drive
from profidrive_cli.drives.profidrive.params import (ParamRef, decimals_for, format_value,
                                                     param_for, param_index, resolve_code)
from profidrive_cli.drives.profidrive.pkw import (ARRAY_REQUESTS, ERROR_RESPONSES, GENERIC_ERRORS,
                                                  IDLE, POSITIVE_RESPONSES, REQUEST_TEXT,
                                                  RESPONSE_TEXT, WRITE_REQUESTS, PkwBusy,
                                                  PkwChannel, PkwFrame, PkwRequest, PkwResponse,
                                                  PkwResult, decode_pke, encode_pke, matches,
                                                  read_request, write_request)
from profidrive_cli.drives.profidrive.pnu import (PNU_BAUD, PNU_CONTROL_RIGHTS, PNU_CONTROL_WORD,
                                                  PNU_DEVICE_ID, PNU_EDIT_RIGHTS,
                                                  PNU_FAULT_NUMBER, PNU_NODE_ADDRESS, PNU_PROFILE,
                                                  PNU_PZD_ACTUAL, PNU_PZD_SETPOINT, PNU_SAVE,
                                                  PNU_STATUS_WORD, baud_code_for, decode_baud,
                                                  decode_device_id, default_fault_positions, fault_memory_requests,
                                                  pzd_map_pnu, pzd_map_read, pzd_map_write,
                                                  save_requests)
from profidrive_cli.drives.profidrive.ppo import (PKW_WORDS, PPO_TYPES, PpoArea, PpoLayout,
                                                  bytes_to_words, decode_area_bytes, encode_area,
                                                  ppo_layout, words_to_bytes)
from profidrive_cli.drives.profidrive.scaling import (N2_FULL, n2_from_hz, n2_from_percent,
                                                      n2_to_hz, n2_to_percent, to_signed16)
from profidrive_cli.drives.profidrive.words import (CTW_NAMES, CTW_ZERO_NAMES, DERIVED_BITS,
                                                    RUN_BITS, STW_NAMES, Ctw, State, Stw, Target,
                                                    bit_list, command_from_control_word,
                                                    next_control_word, state_from_status,
                                                    target_reached)

__all__ = ["ARRAY_REQUESTS", "CTW_NAMES", "CTW_ZERO_NAMES", "Ctw", "DERIVED_BITS",
           "ERROR_RESPONSES", "ERROR_ROLES", "GENERIC_ERRORS", "IDLE", "N2_FULL", "PKW_WORDS",
           "PNU_BAUD", "PNU_CONTROL_RIGHTS", "PNU_CONTROL_WORD", "PNU_DEVICE_ID",
           "PNU_EDIT_RIGHTS", "PNU_FAULT_NUMBER", "PNU_NODE_ADDRESS", "PNU_PROFILE",
           "PNU_PZD_ACTUAL", "PNU_PZD_SETPOINT", "PNU_SAVE", "PNU_STATUS_WORD",
           "POSITIVE_RESPONSES", "PPO_TYPES", "ParamRef", "PkwBusy", "PkwChannel", "PkwFrame",
           "PkwRequest", "PkwResponse", "PkwResult", "PpoArea", "PpoLayout", "ProfidriveConfig",
           "ProfidriveDrive", "REQUEST_TEXT", "RESPONSE_TEXT", "RUN_BITS", "STW_NAMES", "State",
           "Stw", "Target", "WRITE_REQUESTS", "bit_list", "bytes_to_words", "check_direction",
           "command_from_control_word", "config", "ctw_names", "decimals_for", "decode_area",
           "decode_area_bytes", "baud_code_for", "decode_baud", "decode_device_id", "decode_pke",
           "default_fault_positions", "describe_control_word", "describe_n2", "describe_pkw",
           "describe_status_word", "encode_area", "encode_pke", "fault_memory_requests",
           "format_value", "make_drive", "matches", "n2_from_hz", "n2_from_percent", "n2_to_hz",
           "n2_to_percent", "next_control_word", "param_for", "param_index", "pkw_drive_param",
           "ppo_drive_object", "ppo_layout", "speed_plan",
           "pzd_map_pnu", "pzd_map_read", "pzd_map_write", "read_request", "resolve_code",
           "save_requests", "state_from_status", "stw_names", "target_reached", "to_signed16",
           "words_to_bytes", "write_request"]
