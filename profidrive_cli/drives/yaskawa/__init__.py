"""Yaskawa PROFIBUS-DP option SI-P1 (GPD515/G5, F7, P7, G7): codec and Drive (the family package).

Spec: ../shared/spec/yaskawa-profibus-dp.md ("spec §x" below). The card is not PROFIdrive: it has its own
3/16/6-word messages, a Yaskawa run-command word and status word, and parameter access to the drive's
MEMOBUS registers through a handshake byte, because the drive needs 10-15 ms per request.

Layouts (names fixed in docs/architecture.md), bytes each way:

    basic      cfg 72     6 bytes: out command, reference, torque ref   in status, speed feedback, current
    extended1  cfg 5F 6F  32 bytes: fast I/O 0-15, parameter access 16-31 (up to 4 registers)
    extended2  cfg 55 65  12 bytes: fast I/O 0-3,  parameter access 4-11  (1 register)

Parameter-access area (offsets inside the area; 16 bytes in extended1, 8 in extended2):

    0 function code (00 none, 03 read, 10 write; replies 83/90 = error)   1-2 start register MSB, LSB
    3 data quantity in bytes (2 per register)    4.. data words MSB first    last byte: handshake
    command HS byte: bit 7 = HS (toggled to submit)
    response HS byte: bit 7 = HS (echo), bits 6-5 STATUS (00 idle, 01 sending, 10 waiting, 11 done),
                      bits 4-1 watchdog counter (about every 64 ms)

Modules (each sans-IO except drive.py):

    codec        layouts (AreaFormat, FORMATS), word packing, run-command / status words, FrequencyScale
    paramaccess  the parameter-access area (ParamRequest, ParamArea) and the ParamAccess handshake machine
    config       the profile's yaskawa keys (family_config, file:line), LED table, register names/codes
    describe     decode_area: captured areas -> named fields and text (pdrive decode)
    drive        YaskawaDrive (couples the above with a CyclicChannel) and make_drive

This __init__ is the family's face: the names other layers and the family registry
(drives/__init__.py: make_drive, decode_area; checklist: parse_register_code) use.

Decisions on the manual's errata are in the profile's `decisions:` list; the ones that shape code are
repeated where they apply ("E<n>" = the spec's errata number, §10).
"""

from profidrive_cli.drives.yaskawa.codec import (COMMAND_BITS, FORMATS, MFO_BITS, SIGNED_WORDS, STATUS_BITS,
                                                 AreaFormat, FrequencyScale, decode_bits, decode_command,
                                                 decode_status, encode_command, mfi_bit, pack_words,
                                                 unpack_words)
from profidrive_cli.drives.yaskawa.config import (YaskawaConfig, family_config, led_diagnosis,
                                                  parse_register_code, register_name)
from profidrive_cli.drives.yaskawa.describe import decode_area, speed_plan
from profidrive_cli.drives.yaskawa.drive import FAMILY, YaskawaDrive, make_drive
from profidrive_cli.drives.yaskawa.paramaccess import (ERROR_CODES, FC_NONE, FC_READ, FC_WRITE,
                                                       FUNCTION_NAMES, ParamAccess, ParamArea, ParamRequest,
                                                       ParamResult, decode_hs, encode_param_area, error_text)

__all__ = ["COMMAND_BITS", "ERROR_CODES", "FAMILY", "FC_NONE", "FC_READ", "FC_WRITE", "FORMATS",
           "FUNCTION_NAMES", "MFO_BITS", "SIGNED_WORDS", "STATUS_BITS", "AreaFormat", "FrequencyScale",
           "ParamAccess", "ParamArea", "ParamRequest", "ParamResult", "YaskawaConfig", "YaskawaDrive",
           "decode_area", "speed_plan", "decode_bits", "decode_command", "decode_hs", "decode_status", "encode_command",
           "encode_param_area", "error_text", "family_config", "led_diagnosis", "make_drive", "mfi_bit",
           "pack_words", "parse_register_code", "register_name", "unpack_words"]
