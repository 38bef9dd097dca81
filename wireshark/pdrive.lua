-- pdrive.lua: PROFIBUS FDL / DP-V0 / PROFIdrive dissector for Wireshark, shipped with pdrive
-- (profidrive-cli). Install with `pdrive wireshark install`; read a capture with
--   tshark -X lua_script:pdrive.lua -r capture.pcap -V
--
-- Packets: one FDL telegram each (SD .. ED), link type DLT_USER0 (147) as `pdrive sniff --pcap` and
-- `--trace FILE.pcap` write them. Names are those of pdrive (dp/capture.py, dp/services.py):
-- services Set_Prm, Chk_Cfg, Slave_Diag, Get_Cfg, Global_Control, Data_Exchange, Rd_Inp, Rd_Outp,
-- Set_Slave_Add; replies "<service> reply"; "FDL status", "token", "short acknowledge"; DP-V1 acyclic
-- telegrams by their PDU ("MSAC_C1 Read request", "MSAC_C1 poll", "MSAC_C1 Read error response", ...),
-- the PDU in profibus.msac.*, data record 47 (the PROFIdrive parameter channel) in profidrive.ds47.*.
--
-- Data_Exchange areas are decoded as PROFIdrive PPO (PKW + STW/ZSW + HSW/HIW) by their length, or by
-- a station's layout when the station table `pdrive_stations.lua` (written by
-- `pdrive wireshark install --station 3=fuji-g1 ...`, derived from pdrive's profiles) lies next to this
-- file, or when the preference "profidrive.stations" names it ("3=fuji-g1:ppo1,6=moeller").
-- Reference: PROFIBUS-DP (EN 50170 / IEC 61158), PROFIdrive profile V2/V3.

local p_fdl = Proto("profibus", "PROFIBUS FDL / DP-V0 (pdrive)")
local p_pd = Proto("profidrive", "PROFIdrive cyclic data (pdrive)")

-- ------------------------------------------------------------------------------------------------
-- constants (fdl/frames.py, dp/services.py)

local SD1, SD2, SD3, SD4, SC, ED = 0x10, 0x68, 0xA2, 0xDC, 0xE5, 0x16
local SD_NAMES = { [SD1] = "SD1", [SD2] = "SD2", [SD3] = "SD3", [SD4] = "SD4", [SC] = "SC" }
local REQUEST_NAMES = {
  [0] = "time event", [3] = "SDA low", [4] = "SDN low", [5] = "SDA high", [6] = "SDN high", [7] = "MSRD",
  [9] = "FDL status request", [12] = "SRD low", [13] = "SRD high", [14] = "ident request",
  [15] = "LSAP status request",
}
local RESPONSE_NAMES = {
  [0] = "OK", [1] = "UE user error", [2] = "RR no resources", [3] = "RS SAP not enabled",
  [8] = "DL data low", [9] = "NR no response data", [10] = "DH data high (diagnosis pending)",
  [12] = "RDL data not received, low", [13] = "RDH data not received, high",
}
local STATION_TYPES = { [0] = "slave", [1] = "master not ready", [2] = "master ready", [3] = "master in ring" }
local SAP = { SET_SLAVE_ADD = 55, RD_INP = 56, RD_OUTP = 57, GLOBAL_CONTROL = 58, GET_CFG = 59,
              SLAVE_DIAG = 60, SET_PRM = 61, CHK_CFG = 62 }
local SERVICE_NAMES = { [55] = "Set_Slave_Add", [56] = "Rd_Inp", [57] = "Rd_Outp", [58] = "Global_Control",
                        [59] = "Get_Cfg", [60] = "Slave_Diag", [61] = "Set_Prm", [62] = "Chk_Cfg" }
local ST1_BITS = { "Station_Non_Existent", "Station_Not_Ready", "Cfg_Fault", "Ext_Diag", "Not_Supported",
                   "Invalid_Slave_Response", "Prm_Fault", "Master_Lock" }
local ST2_BITS = { "Prm_Req", "Stat_Diag", "always 1", "WD_On", "Freeze_Mode", "Sync_Mode", "reserved",
                   "Deactivated" }
local GC_NAMES = { { 0x02, "Clear_Data" }, { 0x04, "Unfreeze" }, { 0x08, "Freeze" }, { 0x10, "Unsync" },
                   { 0x20, "Sync" } }
local CHANNEL_WIDTH = { [1] = "bit", [2] = "2 bits", [3] = "4 bits", [4] = "byte", [5] = "word", [6] = "2 words" }
local CHANNEL_ERROR = { [1] = "short circuit", [2] = "undervoltage", [3] = "overvoltage", [4] = "overload",
                        [5] = "overtemperature", [6] = "line break", [7] = "upper limit exceeded",
                        [8] = "lower limit undershot", [9] = "error" }
local CHANNEL_DIR = { [1] = "input", [2] = "output", [3] = "input/output" }
-- DP-V1 (dp/dpv1.py, the same names): DPV1_Status_1..3 bits, high bit first; Alarm_Mode; the alarm and
-- status blocks inside a device-related block
local DPV1_BITS = {
  { { 7, "DPV1_Enable" }, { 6, "Fail_Safe" }, { 5, "Publisher_Enable" }, { 2, "WD_Base_1ms" },
    { 1, "Dis_Stop_Control" }, { 0, "Dis_Start_Control" } },
  { { 7, "Enable_Pull_Plug_Alarm" }, { 6, "Enable_Process_Alarm" }, { 5, "Enable_Diagnostic_Alarm" },
    { 4, "Enable_Manufacturer_Specific_Alarm" }, { 3, "Enable_Status_Alarm" }, { 2, "Enable_Update_Alarm" },
    { 0, "Chk_Cfg_Mode" } },
  { { 7, "Prm_Cmd" }, { 4, "IsoM_Req" }, { 3, "Prm_Structure" } } }
local DPV1_RESERVED = { 0x18, 0x02, 0x60 }
local ALARM_MODE = { [0] = "1 alarm of each type", "2 alarms in total", "4 alarms in total", "8 alarms in total",
  "12 alarms in total", "16 alarms in total", "24 alarms in total", "32 alarms in total" }
local ALARM_TYPES = { "Diagnostic_Alarm", "Process_Alarm", "Pull_Alarm", "Plug_Alarm", "Status_Alarm", "Update_Alarm" }
local STATUS_TYPES = { [1] = "Status_Message", [2] = "Module_Status", [30] = "Prm_Command_Ack",
  [31] = "H_Status_Message" }
local ALARM_SPEC = { [0] = "no further differentiation", "error appears (slot disturbed)",
  "error disappears (slot okay)", "error disappears, slot still disturbed" }
local STATUS_SPEC = { [0] = "no further differentiation", "status appears", "status disappears", "reserved" }
local MODULE_STATUS = { "data invalid (module fault)", "data invalid (wrong module)", "data invalid (no module)" }
-- DP-V1 acyclic services (dp/msac1.py, dp/capture.py acyclic_service): the slave's SAPs 51 (MSAC_C1
-- Read / Write), 50 (its alarm SAP: Alarm_Ack) and 49 (MSAC_C2, named only); the PDU's first octet is
-- the function (bit 7: a negative answer with Error_Decode, Error_Code_1 = class << 4 | code,
-- Error_Code_2)
local ACYCLIC = { [51] = "MSAC_C1", [50] = "MSAC_C1 alarm", [49] = "MSAC_C2" }
local MSAC_READ, MSAC_WRITE, MSAC_ALARM_ACK = 0x5E, 0x5F, 0x5C
local MSAC_FUNCTIONS = { [0x5E] = "Read", [0x5F] = "Write", [0x5C] = "Alarm_Ack", [0x57] = "Initiate",
  [0x58] = "Abort", [0x48] = "Idle", [0x51] = "Data_Transport", [0x56] = "RM" }
local MSAC_ERROR_DECODE = { [0x80] = "DPV1", [0xFE] = "FMS", [0xFF] = "HART" }
local MSAC_ERROR_CLASSES = { [0xA] = "application", [0xB] = "access", [0xC] = "resource" }
local MSAC_ERROR_CODES = {
  [0xA] = { [0] = "read error", [1] = "write error", [2] = "module failure", [8] = "version conflict",
            [9] = "feature not supported" },
  [0xB] = { [0] = "invalid index", [1] = "write length error", [2] = "invalid slot", [3] = "type conflict",
            [4] = "invalid area", [5] = "state conflict", [6] = "access denied", [7] = "invalid range",
            [8] = "invalid parameter", [9] = "invalid type" },
  [0xC] = { [0] = "read constraint conflict", [1] = "write constraint conflict", [2] = "resource busy",
            [3] = "resource unavailable" } }
-- PROFIdrive parameter channel in data record 47 (drives/profidrive/ds47.py: its names, sizes and words)
local DS47_INDEX = 47
local DS47_REQUEST = { [0x01] = "read", [0x02] = "change" }
local DS47_RESPONSE = { [0x01] = "read ok", [0x02] = "change ok", [0x81] = "read negative",
  [0x82] = "change negative" }
local DS47_ATTRIBUTES = { [0x10] = "value", [0x20] = "description", [0x30] = "text" }
local DS47_FORMATS = { [0x01] = "Boolean", [0x02] = "Integer8", [0x03] = "Integer16", [0x04] = "Integer32",
  [0x05] = "Unsigned8", [0x06] = "Unsigned16", [0x07] = "Unsigned32", [0x08] = "FloatingPoint",
  [0x09] = "VisibleString", [0x0A] = "OctetString", [0x0C] = "TimeOfDay with date indication",
  [0x0D] = "TimeDifference", [0x21] = "N2", [0x22] = "N4", [0x23] = "V2", [0x24] = "L2", [0x25] = "R2",
  [0x26] = "T2", [0x27] = "T4", [0x28] = "D2", [0x29] = "E2", [0x2A] = "C4", [0x2B] = "X2", [0x2C] = "X4",
  [0x32] = "Date", [0x34] = "TimeOfDay without date indication",
  [0x35] = "TimeDifference with date indication", [0x36] = "TimeDifference without date indication",
  [0x40] = "Zero", [0x41] = "Byte", [0x42] = "Word", [0x43] = "Double word", [0x44] = "Error" }
-- a format's values: octets each and kind ("s" signed, "u" unsigned, "f" IEEE 754 single, "o" octets);
-- TimeDifference (0x0D) has none (4 or 6 octets a value: the block does not say which)
local DS47_CODING = { [0x01] = { 1, "u" }, [0x02] = { 1, "s" }, [0x03] = { 2, "s" }, [0x04] = { 4, "s" },
  [0x05] = { 1, "u" }, [0x06] = { 2, "u" }, [0x07] = { 4, "u" }, [0x08] = { 4, "f" }, [0x09] = { 1, "o" },
  [0x0A] = { 1, "o" }, [0x0C] = { 6, "u" }, [0x21] = { 2, "u" }, [0x22] = { 4, "u" }, [0x23] = { 2, "u" },
  [0x24] = { 2, "u" }, [0x25] = { 2, "u" }, [0x26] = { 2, "u" }, [0x27] = { 4, "u" }, [0x28] = { 2, "u" },
  [0x29] = { 2, "u" }, [0x2A] = { 4, "u" }, [0x2B] = { 2, "u" }, [0x2C] = { 4, "u" }, [0x32] = { 7, "u" },
  [0x34] = { 4, "u" }, [0x35] = { 6, "u" }, [0x36] = { 4, "u" }, [0x41] = { 1, "u" }, [0x42] = { 2, "u" },
  [0x43] = { 4, "u" } }
-- formats whose values read best in hex (bit sequences)
local DS47_HEX = { [0x23] = true, [0x41] = true, [0x42] = true, [0x43] = true }
local DS47_ERRORS = { [0x00] = "impermissible parameter number", [0x01] = "parameter value cannot be changed",
  [0x02] = "low or high limit exceeded", [0x03] = "faulty subindex", [0x04] = "no array",
  [0x05] = "incorrect data type", [0x06] = "setting not permitted (may only be reset)",
  [0x07] = "description element cannot be changed", [0x09] = "no description data available",
  [0x0B] = "no operation priority (no parameter change rights)", [0x0F] = "no text array available",
  [0x11] = "request cannot be executed because of operating state", [0x14] = "value impermissible",
  [0x15] = "response too long", [0x16] = "parameter address impermissible", [0x17] = "illegal format",
  [0x18] = "number of values inconsistent", [0x19] = "axis/DO nonexistent",
  [0x20] = "parameter text element cannot be changed", [0x21] = "service not supported" }

-- PROFIdrive (drives/profidrive/words.py, pkw.py)
local CTW_NAMES = { [0] = "ON", [1] = "no OFF2", [2] = "no OFF3", [3] = "enable operation",
                    [4] = "enable ramp generator", [5] = "unfreeze ramp generator", [6] = "enable setpoint",
                    [7] = "fault acknowledge", [8] = "jog 1", [9] = "jog 2", [10] = "control by PLC" }
local STW_NAMES = { [0] = "ready to switch on", [1] = "ready to operate", [2] = "operation enabled",
                    [3] = "fault", [4] = "no OFF2", [5] = "no OFF3", [6] = "switching on inhibited",
                    [7] = "warning", [8] = "at setpoint", [9] = "control requested", [10] = "f reached" }
local AK_REQUEST = { [0] = "no task", [1] = "request parameter value", [2] = "change parameter value (word)",
  [3] = "change parameter value (long word)", [4] = "request description element",
  [5] = "change description element", [6] = "request parameter value (array)",
  [7] = "change parameter value (array word)", [8] = "change parameter value (array long word)",
  [9] = "request number of array elements", [11] = "change array long word and store",
  [12] = "change array word and store", [13] = "change long word and store",
  [14] = "change word and store", [15] = "read or change text" }
local AK_RESPONSE = { [0] = "no response", [1] = "transfer parameter value (word)",
  [2] = "transfer parameter value (long word)", [3] = "transfer description element",
  [4] = "transfer parameter value (array word)", [5] = "transfer parameter value (array long word)",
  [6] = "transfer number of array elements", [7] = "task cannot be executed",
  [8] = "no parameter change rights", [9] = "parameter change report (word)",
  [10] = "parameter change report (long word)", [15] = "transfer text" }

-- ------------------------------------------------------------------------------------------------
-- fields

local function vs(t) local o = {} for k, v in pairs(t) do o[k] = v end return o end

local F = {
  sd = ProtoField.uint8("profibus.sd", "Start delimiter", base.HEX, vs(SD_NAMES)),
  le = ProtoField.uint8("profibus.le", "LE"),
  ler = ProtoField.uint8("profibus.ler", "LEr"),
  da = ProtoField.uint8("profibus.da", "DA (destination)", base.DEC, nil, 0x7F),
  sa = ProtoField.uint8("profibus.sa", "SA (source)", base.DEC, nil, 0x7F),
  da_ext = ProtoField.bool("profibus.da_ext", "DSAP follows", 8, nil, 0x80),
  sa_ext = ProtoField.bool("profibus.sa_ext", "SSAP follows", 8, nil, 0x80),
  fc = ProtoField.uint8("profibus.fc", "FC", base.HEX),
  fc_text = ProtoField.string("profibus.fc_text", "FC in words"),
  fc_req = ProtoField.bool("profibus.fc.request", "Request", 8, nil, 0x40),
  fc_fcb = ProtoField.bool("profibus.fc.fcb", "FCB", 8, nil, 0x20),
  fc_fcv = ProtoField.bool("profibus.fc.fcv", "FCV", 8, nil, 0x10),
  fc_fn = ProtoField.uint8("profibus.fc.function", "Function", base.DEC, vs(REQUEST_NAMES), 0x0F),
  fc_st = ProtoField.uint8("profibus.fc.status", "Status", base.DEC, vs(RESPONSE_NAMES), 0x0F),
  fc_type = ProtoField.uint8("profibus.fc.station_type", "Station type", base.DEC, vs(STATION_TYPES), 0x30),
  dsap = ProtoField.uint8("profibus.dsap", "DSAP"),
  ssap = ProtoField.uint8("profibus.ssap", "SSAP"),
  du = ProtoField.bytes("profibus.du", "DU", base.SPACE),
  fcs = ProtoField.uint8("profibus.fcs", "FCS", base.HEX),
  fcs_status = ProtoField.string("profibus.fcs.status", "FCS status"),
  ed = ProtoField.uint8("profibus.ed", "End delimiter", base.HEX),
  service = ProtoField.string("profibus.service", "Service"),
  -- Set_Prm
  prm_status = ProtoField.uint8("profibus.prm.station_status", "Station status", base.HEX),
  prm_lock = ProtoField.bool("profibus.prm.lock_req", "Lock_Req", 8, nil, 0x80),
  prm_unlock = ProtoField.bool("profibus.prm.unlock_req", "Unlock_Req", 8, nil, 0x40),
  prm_sync = ProtoField.bool("profibus.prm.sync_req", "Sync_Req", 8, nil, 0x20),
  prm_freeze = ProtoField.bool("profibus.prm.freeze_req", "Freeze_Req", 8, nil, 0x10),
  prm_wd_on = ProtoField.bool("profibus.prm.wd_on", "WD_On", 8, nil, 0x08),
  prm_wd1 = ProtoField.uint8("profibus.prm.wd_fact_1", "WD_Fact_1"),
  prm_wd2 = ProtoField.uint8("profibus.prm.wd_fact_2", "WD_Fact_2"),
  prm_wd_ms = ProtoField.uint32("profibus.prm.watchdog_ms", "Watchdog (ms)"),
  prm_tsdr = ProtoField.uint8("profibus.prm.min_tsdr", "min TSDR (bit times)"),
  prm_ident = ProtoField.uint16("profibus.prm.ident", "Ident number", base.HEX),
  prm_group = ProtoField.uint8("profibus.prm.group", "Group_Ident", base.HEX),
  prm_user = ProtoField.bytes("profibus.prm.user_prm", "User_Prm_Data", base.SPACE),
  prm_dpv1 = ProtoField.bytes("profibus.prm.dpv1_status", "DP-V1 status (DPV1_Status_1..3)", base.SPACE),
  prm_dpv1_flags = ProtoField.string("profibus.prm.dpv1_flags", "DP-V1 status bits set"),
  prm_alarm_mode = ProtoField.string("profibus.prm.alarm_mode", "Alarm_Mode"),
  -- Chk_Cfg / Get_Cfg
  cfg_id = ProtoField.uint8("profibus.cfg.identifier", "Identifier", base.HEX),
  cfg_text = ProtoField.string("profibus.cfg.text", "Module"),
  -- Slave_Diag
  diag_st1 = ProtoField.uint8("profibus.diag.st1", "Station status 1", base.HEX),
  diag_st2 = ProtoField.uint8("profibus.diag.st2", "Station status 2", base.HEX),
  diag_st3 = ProtoField.uint8("profibus.diag.st3", "Station status 3", base.HEX),
  diag_master = ProtoField.uint8("profibus.diag.master", "Master address"),
  diag_ident = ProtoField.uint16("profibus.diag.ident", "Ident number", base.HEX),
  diag_flags = ProtoField.string("profibus.diag.flags", "Flags set"),
  diag_ext = ProtoField.bytes("profibus.diag.ext", "Extended diagnosis", base.SPACE),
  diag_block = ProtoField.string("profibus.diag.block", "Diagnosis block"),
  diag_dpv1_type = ProtoField.string("profibus.diag.dpv1_type", "DP-V1 alarm / status type"),
  diag_dpv1_slot = ProtoField.uint8("profibus.diag.dpv1_slot", "DP-V1 slot"),
  diag_dpv1_spec = ProtoField.string("profibus.diag.dpv1_specifier", "DP-V1 specifier"),
  -- Global_Control / Set_Slave_Add
  gc_cmd = ProtoField.uint8("profibus.gc.control", "Control command", base.HEX),
  gc_text = ProtoField.string("profibus.gc.text", "Command"),
  gc_group = ProtoField.uint8("profibus.gc.group", "Group select", base.HEX),
  ssa_addr = ProtoField.uint8("profibus.ssa.new_address", "New station address"),
  ssa_ident = ProtoField.uint16("profibus.ssa.ident", "Ident number", base.HEX),
  ssa_nochg = ProtoField.bool("profibus.ssa.no_add_chg", "No_Add_Chg"),
  ssa_extra = ProtoField.bytes("profibus.ssa.rem_slave_data", "Rem_Slave_Data", base.SPACE),
  outputs = ProtoField.bytes("profibus.outputs", "Outputs", base.SPACE),
  inputs = ProtoField.bytes("profibus.inputs", "Inputs", base.SPACE),
  -- DP-V1 acyclic (MSAC_C1 / MSAC_C2)
  msac = ProtoField.bytes("profibus.msac", "DP-V1 acyclic PDU", base.SPACE),
  msac_service = ProtoField.string("profibus.msac.service", "Acyclic service"),
  msac_kind = ProtoField.string("profibus.msac.kind", "Kind"),
  msac_function = ProtoField.uint8("profibus.msac.function", "Function", base.HEX, vs(MSAC_FUNCTIONS), 0x7F),
  msac_error_bit = ProtoField.bool("profibus.msac.negative", "Negative answer", 8, nil, 0x80),
  msac_slot = ProtoField.uint8("profibus.msac.slot", "Slot"),
  msac_index = ProtoField.uint8("profibus.msac.index", "Index"),
  msac_length = ProtoField.uint8("profibus.msac.length", "Length"),
  msac_data = ProtoField.bytes("profibus.msac.data", "Data", base.SPACE),
  msac_decode = ProtoField.uint8("profibus.msac.error_decode", "Error_Decode", base.HEX, vs(MSAC_ERROR_DECODE)),
  msac_code1 = ProtoField.uint8("profibus.msac.error_code_1", "Error_Code_1", base.HEX),
  msac_class = ProtoField.uint8("profibus.msac.error_class", "Error class", base.HEX, nil, 0xF0),
  msac_code = ProtoField.uint8("profibus.msac.error_code", "Error code", base.DEC, nil, 0x0F),
  msac_code2 = ProtoField.uint8("profibus.msac.error_code_2", "Error_Code_2", base.HEX),
  msac_error = ProtoField.string("profibus.msac.error_text", "Error"),
  msac_alarm_type = ProtoField.uint8("profibus.msac.alarm_type", "Alarm type"),
  msac_specifier = ProtoField.uint8("profibus.msac.specifier", "Specifier", base.HEX),
  msac_station = ProtoField.uint8("profibus.msac.station", "Slave"),
  msac_request = ProtoField.string("profibus.msac.request", "Request answered"),
  msac_note = ProtoField.string("profibus.msac.note", "In words"),
}
local bits_fields = {}
for i, n in ipairs(ST1_BITS) do
  local k = "st1_" .. i
  F[k] = ProtoField.bool("profibus.diag." .. n:lower(), n, 8, nil, 2 ^ (i - 1))
  bits_fields[#bits_fields + 1] = { 1, k }
end
for i, n in ipairs(ST2_BITS) do
  if n ~= "always 1" and n ~= "reserved" then
    local k = "st2_" .. i
    F[k] = ProtoField.bool("profibus.diag." .. n:lower(), n, 8, nil, 2 ^ (i - 1))
    bits_fields[#bits_fields + 1] = { 2, k }
  end
end
F.st3_8 = ProtoField.bool("profibus.diag.ext_diag_overflow", "Ext_Diag_Overflow", 8, nil, 0x80)
bits_fields[#bits_fields + 1] = { 3, "st3_8" }

local fl = {}
for _, v in pairs(F) do fl[#fl + 1] = v end
p_fdl.fields = fl

local E = {
  fcs = ProtoExpert.new("profibus.fcs.bad", "FCS mismatch", expert.group.CHECKSUM, expert.severity.ERROR),
  malformed = ProtoExpert.new("profibus.malformed", "Malformed telegram", expert.group.MALFORMED,
                              expert.severity.ERROR),
  diag = ProtoExpert.new("profibus.diag.problem", "Station reports a problem", expert.group.RESPONSE_CODE,
                         expert.severity.WARN),
}
p_fdl.experts = { E.fcs, E.malformed, E.diag }

local P = {
  station = ProtoField.uint8("profidrive.station", "Station"),
  layout = ProtoField.string("profidrive.layout", "Layout"),
  direction = ProtoField.string("profidrive.direction", "Direction"),
  pkw = ProtoField.bytes("profidrive.pkw", "PKW", base.SPACE),
  pke = ProtoField.uint16("profidrive.pkw.pke", "PKE", base.HEX),
  ak = ProtoField.uint16("profidrive.pkw.ak", "AK", base.DEC, nil, 0xF000),
  spm = ProtoField.uint16("profidrive.pkw.spm", "SPM", base.DEC, nil, 0x0800),
  pnu = ProtoField.uint16("profidrive.pkw.pnu", "PNU", base.DEC, nil, 0x07FF),
  ak_text = ProtoField.string("profidrive.pkw.ak_text", "AK in words"),
  ind = ProtoField.uint16("profidrive.pkw.ind", "IND", base.HEX),
  subindex = ProtoField.uint8("profidrive.pkw.subindex", "Subindex"),
  pwe = ProtoField.uint32("profidrive.pkw.pwe", "PWE", base.HEX_DEC),
  param = ProtoField.string("profidrive.pkw.param", "Parameter"),
  control = ProtoField.uint16("profidrive.control", "Control word", base.HEX),
  control_set = ProtoField.string("profidrive.control.set", "Control bits set"),
  status = ProtoField.uint16("profidrive.status", "Status word", base.HEX),
  status_set = ProtoField.string("profidrive.status.set", "Status bits set"),
  state = ProtoField.string("profidrive.state", "State"),
  reference = ProtoField.uint16("profidrive.reference", "Reference", base.HEX),
  reference_pct = ProtoField.double("profidrive.reference_percent", "Reference (%)"),
  reference_hz = ProtoField.double("profidrive.reference_hz", "Reference (Hz)"),
  actual = ProtoField.uint16("profidrive.actual", "Actual value", base.HEX),
  actual_pct = ProtoField.double("profidrive.actual_percent", "Actual value (%)"),
  actual_hz = ProtoField.double("profidrive.actual_hz", "Actual value (Hz)"),
  word = ProtoField.uint16("profidrive.word", "Word", base.HEX),
  field = ProtoField.string("profidrive.field", "Field"),
  value = ProtoField.double("profidrive.value", "Value"),
  bytes = ProtoField.bytes("profidrive.bytes", "Octets", base.SPACE),
  -- the DP-V1 parameter channel (data record 47)
  ds47_kind = ProtoField.string("profidrive.ds47.kind", "Parameter request or response"),
  ds47_reference = ProtoField.uint8("profidrive.ds47.reference", "Request reference"),
  ds47_request_id = ProtoField.uint8("profidrive.ds47.request_id", "Request ID", base.HEX, vs(DS47_REQUEST)),
  ds47_response_id = ProtoField.uint8("profidrive.ds47.response_id", "Response ID", base.HEX, vs(DS47_RESPONSE)),
  ds47_axis = ProtoField.uint8("profidrive.ds47.axis", "Axis"),
  ds47_count = ProtoField.uint8("profidrive.ds47.count", "Number of parameters"),
  ds47_param = ProtoField.string("profidrive.ds47.parameter", "Parameter"),
  ds47_attribute = ProtoField.uint8("profidrive.ds47.attribute", "Attribute", base.HEX, vs(DS47_ATTRIBUTES)),
  ds47_elements = ProtoField.uint8("profidrive.ds47.elements", "Number of elements"),
  ds47_pnu = ProtoField.uint16("profidrive.ds47.pnu", "PNU"),
  ds47_subindex = ProtoField.uint16("profidrive.ds47.subindex", "Subindex"),
  ds47_format = ProtoField.uint8("profidrive.ds47.format", "Format", base.HEX, vs(DS47_FORMATS)),
  ds47_values = ProtoField.uint8("profidrive.ds47.values", "Number of values"),
  ds47_value = ProtoField.double("profidrive.ds47.value", "Value"),
  ds47_octets = ProtoField.bytes("profidrive.ds47.octets", "Octets", base.SPACE),
  ds47_error = ProtoField.uint16("profidrive.ds47.error", "Error number", base.HEX),
  ds47_error_text = ProtoField.string("profidrive.ds47.error_text", "Error"),
  ds47_extra = ProtoField.uint16("profidrive.ds47.error_extra", "Additional information", base.HEX),
}
local pl = {}
for _, v in pairs(P) do pl[#pl + 1] = v end
p_pd.fields = pl
local E_len = ProtoExpert.new("profidrive.length", "Area length does not match the station's layout",
                              expert.group.PROTOCOL, expert.severity.WARN)
p_pd.experts = { E_len }

p_pd.prefs.stations = Pref.string("Stations", "",
  "station=profile[:layout], comma separated (e.g. 3=fuji-g1:ppo1,6=moeller); profiles from "
  .. "pdrive_stations.lua (pdrive wireshark install); overrides that file's stations")
p_pd.prefs.generic = Pref.bool("Decode unknown stations as PPO", true,
  "Decode the Data_Exchange areas of stations without a layout as PROFIdrive PPO by their length")

-- ------------------------------------------------------------------------------------------------
-- the station table written by `pdrive wireshark install` (pdrive_stations.lua next to this file)

local function script_dir()
  local src = debug.getinfo(1, "S").source or ""
  if src:sub(1, 1) == "@" then src = src:sub(2) end
  return src:match("^(.*[/\\])") or ""
end

local TABLE = nil
local function station_table()
  if TABLE ~= nil then return TABLE end
  if PDRIVE_STATIONS == nil then
    -- Wireshark's loadfile raises when the file is missing: no table is fine
    local ok, f = pcall(loadfile, script_dir() .. "pdrive_stations.lua")
    if ok and f then pcall(f) end
  end
  TABLE = PDRIVE_STATIONS or { stations = {}, layouts = {}, aliases = {}, defaults = {} }
  return TABLE
end

-- the preferences, read once (each read is a call into Wireshark) and again when they change
local PREFS = nil
local function prefs()
  if PREFS == nil then PREFS = { stations = p_pd.prefs.stations or "", generic = p_pd.prefs.generic } end
  return PREFS
end
function p_pd.prefs_changed() PREFS = nil end

local pref_cache_text, pref_cache = nil, {}
local function pref_stations()
  local text = prefs().stations
  if text == pref_cache_text then return pref_cache end
  pref_cache_text, pref_cache = text, {}
  local t = station_table()
  for item in text:gmatch("[^,%s]+") do
    local addr, prof, lay = item:match("^(%d+)=([^:]+):?(.*)$")
    if addr then
      prof = (t.aliases and t.aliases[prof]) or prof
      if lay == "" then lay = t.defaults and t.defaults[prof] or "" end
      pref_cache[tonumber(addr)] = prof .. ":" .. lay
    end
  end
  return pref_cache
end

local function station_layout(addr)
  local t = station_table()
  local key = pref_stations()[addr] or (t.stations and t.stations[addr])
  if key == nil then return nil end
  return t.layouts and t.layouts[key], key
end

-- ------------------------------------------------------------------------------------------------
-- helpers

local byte = string.byte
local HEX = {}
for i = 0, 255 do HEX[i] = string.format("%02x", i) end

-- the octets of a TvbRange as "0a 1b ..": one raw string, no object per octet
local function hexs(range)
  local n = range:len()
  if n == 0 then return "" end
  local s = range:raw()
  local o = {}
  for i = 1, n do o[i] = HEX[byte(s, i)] end
  return table.concat(o, " ")
end

-- the sum of the octets i..j (1-based) of a Lua string, mod 256 (the FCS): string.byte in chunks of
-- 64 octets, no TvbRange per octet
local function octet_sum(s, i, j)
  local sum = 0
  while i <= j do
    local k = i + 63
    if k > j then k = j end
    local c = { byte(s, i, k) }
    for m = 1, #c do sum = sum + c[m] end
    i = k + 1
  end
  return sum % 256
end

local function s16(w) if w >= 0x8000 then return w - 0x10000 end return w end

-- bit operations: Wireshark links Lua 5.2 (bit32, no & or >>) or 5.3/5.4 (& and >>, no bit32); plain
-- arithmetic only when neither exists. The operands are octets and words (never negative).
local band, shr
if type(bit32) == "table" then
  band, shr = bit32.band, bit32.rshift
else
  local chunk = load and load("return function(x, m) return x & m end, function(x, n) return x >> n end")
  if chunk then band, shr = chunk() end
end
if band == nil then
  shr = function(x, n) return math.floor(x / 2 ^ n) end
  band = function(x, m)
    local r, b = 0, 1
    while x > 0 and m > 0 do
      if x % 2 == 1 and m % 2 == 1 then r = r + b end
      x, m, b = math.floor(x / 2), math.floor(m / 2), b * 2
    end
    return r
  end
end

-- v with 4 decimals, trailing zeros and point dropped ("%.4f" always has the point)
local function fmt_num(v)
  return (string.match(string.format("%.4f", v), "^(.-)%.?0*$"))
end

local function bit_list(word, names, width)
  local out = {}
  for b = 0, (width or 16) - 1 do
    if math.floor(word / 2 ^ b) % 2 == 1 then out[#out + 1] = names[b] or ("bit " .. b) end
  end
  return out
end

local function state_from_status(w)
  if w % 16 >= 8 then return "fault" end                          -- bit 3
  if w % 128 >= 64 then return "S1 switching on inhibited" end    -- bit 6
  local low = w % 8
  if low == 7 then return "S4 operation" end
  if low == 3 then return "S3 switched on" end
  if low == 1 then return "S2 ready for switching on" end
  if low == 0 then return "S1 switching on inhibited" end
  if low >= 4 then return "S4 operation" end
  if low >= 2 then return "S3 switched on" end
  return "S1 switching on inhibited"
end

local function word_at(range, order)
  if order == "little" then return range:le_uint() end
  return range:uint()
end

local function add_word(tree, field, range, order, ...)
  if order == "little" then return tree:add_le(field, range, ...) end
  return tree:add(field, range, ...)
end

-- ------------------------------------------------------------------------------------------------
-- PROFIdrive / vendor areas

local function generic_layout(len, direction)
  -- PPO by length: 4 = PPO3, 12 = PPO1 (PPO4 has the same length: taken as PPO1), 20 = PPO2, 28 = PPO5
  local ppo = ({ [4] = 3, [12] = 1, [20] = 2, [28] = 5 })[len]
  if ppo == nil then return nil end
  local pkw = ppo ~= 3
  local fields, off = {}, 0
  if pkw then fields[#fields + 1] = { kind = "pkw", name = "PKW", offset = 0, size = 8 }; off = 8 end
  if direction == "request" then
    fields[#fields + 1] = { kind = "bits", role = "control", name = "STW", what = "control word", offset = off,
                            size = 2, bits = CTW_NAMES }
    fields[#fields + 1] = { kind = "n2", role = "reference", name = "HSW", what = "main setpoint",
                            offset = off + 2, size = 2 }
  else
    fields[#fields + 1] = { kind = "bits", role = "status", name = "ZSW", what = "status word", offset = off,
                            size = 2, bits = STW_NAMES }
    fields[#fields + 1] = { kind = "n2", role = "actual", name = "HIW", what = "main actual value",
                            offset = off + 2, size = 2 }
  end
  local n = 3
  for o = off + 4, len - 2, 2 do
    fields[#fields + 1] = { kind = "word", name = "PZD" .. n, offset = o, size = 2 }
    n = n + 1
  end
  return { name = "PPO" .. ppo .. " (by length)", word_order = "big", length = len, fields = fields,
           generic = true }
end

-- the generic layouts are the same for every area of a length and direction: made once
local GENERIC = { request = {}, response = {} }
local function generic_layout_cached(len, direction)
  local by_len = GENERIC[direction]
  local lay = by_len[len]
  if lay == nil then
    lay = generic_layout(len, direction) or false
    by_len[len] = lay
  end
  return lay or nil
end

-- the texts of a bit word's lines ("bit  8 jog 1: 0"), per names table and word value: a cyclic word
-- repeats, its 16 string.format calls need not (at most 4096 words per names table are kept)
local BIT_LINES = setmetatable({}, { __mode = "k" })
local function bit_lines(w, names)
  local by_w = BIT_LINES[names]
  if by_w == nil then by_w = { n = 0 } BIT_LINES[names] = by_w end
  local lines = by_w[w]
  if lines == nil then
    lines = {}
    for b = 0, 15 do
      local on = math.floor(w / 2 ^ b) % 2 == 1
      if names[b] or on then
        lines[#lines + 1] = string.format("bit %2d %s: %s", b, names[b] or ("bit " .. b), on and "1" or "0")
      end
    end
    if by_w.n >= 4096 then by_w = { n = 0 } BIT_LINES[names] = by_w end
    by_w[w] = lines
    by_w.n = by_w.n + 1
  end
  return lines
end

local function param_label(lay, pnu, sub)
  local params = lay and lay.params
  if params == nil then return nil end
  return params[pnu * 256 + sub] or params[pnu * 256 + 255]
end

local function dissect_pkw(tvb, tree, f, direction, lay, order, notes)
  local r = tvb(f.offset, 8)
  local t = tree:add(P.pkw, r)
  t:set_text("PKW (parameter channel): " .. hexs(r))
  local pke = word_at(r(0, 2), order)
  local ind = word_at(r(2, 2), order)
  local pwe = word_at(r(4, 2), order) * 65536 + word_at(r(6, 2), order)
  local ak = math.floor(pke / 4096)
  local pnu = pke % 2048
  local sub = math.floor(ind / 256)
  local texts = direction == "request" and (lay and lay.ak_request or AK_REQUEST)
                or (lay and lay.ak_response or AK_RESPONSE)
  local ak_text = texts[ak] or "reserved"
  add_word(t, P.pke, r(0, 2), order)
  add_word(t, P.ak, r(0, 2), order)
  add_word(t, P.spm, r(0, 2), order)
  add_word(t, P.pnu, r(0, 2), order)
  t:add(P.ak_text, r(0, 2), ak_text)
  add_word(t, P.ind, r(2, 2), order)
  t:add(P.subindex, r(2, 2), sub)
  t:add(P.pwe, r(4, 4), pwe)
  local label = param_label(lay, pnu, sub)
  if label and ak ~= 0 then t:add(P.param, r(0, 4), label) end
  local where = "PNU " .. pnu .. (sub ~= 0 and ("[" .. sub .. "]") or "")
  if ak == 0 then
    notes[#notes + 1] = "PKW " .. ak_text
  else
    local s = "PKW AK " .. ak .. " " .. ak_text .. ", " .. where .. (label and (" = " .. label) or "")
    if (direction == "response" and (ak == 7 or ak == 8)) then
      s = s .. ": error " .. (pwe % 65536)
    elseif not (direction == "request" and (ak == 1 or ak == 4 or ak == 6 or ak == 9)) then
      s = s .. ", PWE " .. pwe
    end
    notes[#notes + 1] = s
  end
  t:append_text(" -> " .. notes[#notes])
end

local function dissect_field(tvb, tree, f, direction, lay, order, notes)
  if f.offset + f.size > tvb:len() then return end
  local r = tvb(f.offset, f.size)
  if f.kind == "pkw" then return dissect_pkw(tvb, tree, f, direction, lay, order, notes) end
  if f.kind == "bytes" then
    local t = tree:add(P.bytes, r)
    t:set_text(f.name .. ": " .. hexs(r))
    return
  end
  local w = word_at(r, order)
  local label = f.name .. (f.what and (" (" .. f.what .. ")") or "")
  if f.kind == "bits" then
    local names = f.bits or {}
    local set = bit_list(w, names, 16)
    local field = f.role == "control" and P.control or f.role == "status" and P.status or P.word
    local t = add_word(tree, field, r, order)
    local text = string.format("%s 0x%04X: %s", label, w, #set > 0 and table.concat(set, ", ") or "no bits set")
    local note = string.format("%s 0x%04X", f.name, w)
    if f.role == "status" and f.state ~= false then
      local st = state_from_status(w)
      text = text .. " -> " .. st
      tree:add(P.state, r, st)
      note = note .. " " .. st
    end
    t:set_text(text)
    if f.role == "control" then tree:add(P.control_set, r, table.concat(set, ", ")) end
    if f.role == "status" then tree:add(P.status_set, r, table.concat(set, ", ")) end
    if f.role ~= "control" and f.role ~= "status" then tree:add(P.field, r, f.name) end
    for _, line in ipairs(bit_lines(w, names)) do t:add(r, line) end
    notes[#notes + 1] = note
    return
  end
  if f.kind == "n2" or f.kind == "scaled" then
    local v = f.signed == false and w or s16(w)
    local field = f.role == "reference" and P.reference or f.role == "actual" and P.actual or P.word
    local t = add_word(tree, field, r, order)
    local text, hz
    if f.kind == "n2" then
      local pct = v * 100.0 / 16384
      text = string.format("%s 0x%04X: %s %%", label, w, fmt_num(pct))
      if f.role then tree:add(f.role == "reference" and P.reference_pct or P.actual_pct, r, pct) end
      if f.max_hz then
        hz = pct * f.max_hz / 100.0
        text = text .. string.format(" = %.2f Hz (100 %% = %s Hz)", hz, fmt_num(f.max_hz))
      end
    else
      local val = v * (f.scale or 1)
      text = string.format("%s 0x%04X = %s%s", label, w, fmt_num(val), f.unit and f.unit ~= "" and (" " .. f.unit) or "")
      if f.unit == "Hz" then hz = val end
      if field == P.word then tree:add(P.value, r, val) end
    end
    if hz and f.role then tree:add(f.role == "reference" and P.reference_hz or P.actual_hz, r, hz) end
    if field == P.word then tree:add(P.field, r, f.name) end
    t:set_text(text)
    notes[#notes + 1] = hz and string.format("%s %.2f Hz", f.name, hz) or string.format("%s 0x%04X", f.name, w)
    return
  end
  -- plain word
  local t = add_word(tree, P.word, r, order)
  t:set_text(string.format("%s 0x%04X = %d", label, w, w))
  tree:add(P.field, r, f.name)
end

local function dissect_area(tvb, pinfo, tree, station, direction)
  local lay, key = station_layout(station)
  local t = tree:add(p_pd, tvb())
  t:add(P.station, station):set_generated()
  t:add(P.direction, direction == "request" and "request (master -> drive outputs)"
        or "response (drive -> master inputs)"):set_generated()
  local cacheable = true
  if lay and lay[direction] and lay[direction].length ~= tvb:len() then
    t:add_proto_expert_info(E_len, string.format("station %d %s %s is %d octets, the telegram has %d",
      station, key, direction, lay[direction].length, tvb:len()))
    lay = nil
    cacheable = false            -- the expert info belongs to every such telegram: never from the cache
  end
  local area, name
  if lay then
    area = lay[direction]
    name = lay.profile .. " " .. lay.layout
  elseif p_pd.prefs.generic then
    area = generic_layout_cached(tvb:len(), direction)
    name = area and ("generic PROFIdrive " .. area.name)
  end
  if area == nil then
    t:set_text("PROFIdrive: no layout for station " .. station .. " (" .. tvb:len() .. " octets)")
    return nil, cacheable
  end
  t:add(P.layout, name):set_generated()
  local order = (lay and lay.word_order) or area.word_order or "big"
  local notes = {}
  for _, f in ipairs(area.fields) do
    dissect_field(tvb, t, f, direction, lay, order, notes)
  end
  local summary = table.concat(notes, "; ")
  t:set_text("PROFIdrive " .. name .. ", station " .. station .. ": " .. summary)
  return summary, cacheable
end

-- ------------------------------------------------------------------------------------------------
-- DP-V0 services

local function cfg_module(data, i)
  -- one identifier at index i (0-based) of the byte array: returns text, used octets
  local b = data:get_index(i)
  local function amount(n, words) local unit = words and "word" or "byte"
    local k = words and math.floor(n / 2) or n
    return k .. " " .. unit .. (k ~= 1 and "s" or "") end
  if band(b, 0x30) ~= 0 then
    local words = band(b, 0x40) ~= 0
    local n = band(b, 0x0F) + 1
    local octets = words and n * 2 or n
    local dir = band(shr(b, 4), 3)
    local parts = {}
    if dir == 3 then parts[1] = amount(octets, words) .. " in+out"
    elseif dir == 2 then parts[1] = amount(octets, words) .. " out"
    else parts[1] = amount(octets, words) .. " in" end
    if band(b, 0x80) ~= 0 then parts[#parts + 1] = "consistent" end
    return table.concat(parts, ", "), 1
  end
  local nman = band(b, 0x0F)
  local kind = band(shr(b, 6), 3)
  local j = i + 1
  local parts, consistent = {}, false
  local function len_octet(x) local w = band(x, 0x40) ~= 0 local n = band(x, 0x3F) + 1
    if band(x, 0x80) ~= 0 then consistent = true end
    return w and n * 2 or n, w end
  if b == 0 then return "empty slot", 1 end
  if kind == 2 or kind == 3 then
    if j >= data:len() then return "output length octet missing", data:len() - i end
    local n, w = len_octet(data:get_index(j)); j = j + 1
    parts[#parts + 1] = amount(n, w) .. " out"
  end
  if kind == 1 or kind == 3 then
    if j >= data:len() then return "input length octet missing", data:len() - i end
    local n, w = len_octet(data:get_index(j)); j = j + 1
    parts[#parts + 1] = amount(n, w) .. " in"
  end
  if consistent then parts[#parts + 1] = "consistent" end
  if nman > 0 then
    if j + nman > data:len() then return "manufacturer octets missing", data:len() - i end
    local m = {}
    for k = j, j + nman - 1 do m[#m + 1] = string.format("%02x", data:get_index(k)) end
    parts[#parts + 1] = "manufacturer data " .. table.concat(m, " ")
    j = j + nman
  end
  return table.concat(parts, ", "), j - i
end

local function dissect_cfg(tvb, tree, off, len)
  local out = {}
  if len <= 0 then return "" end
  local data = tvb(off, len):bytes()
  local i = 0
  while i < len do
    local text, used = cfg_module(data, i)
    local ti = tree:add(F.cfg_id, tvb(off + i, 1))
    ti:append_text(" (" .. hexs(tvb(off + i, used)) .. "): " .. text)
    tree:add(F.cfg_text, tvb(off + i, used), text)
    out[#out + 1] = text
    i = i + used
  end
  return table.concat(out, "; ")
end

local function dissect_set_prm(tvb, tree, off, len)
  if len < 7 then tree:add_proto_expert_info(E.malformed, "Set_Prm needs 7 octets, got " .. len) return "" end
  local st = tvb(off, 1):uint()
  local t = tree:add(F.prm_status, tvb(off, 1))
  for _, k in ipairs({ "prm_lock", "prm_unlock", "prm_sync", "prm_freeze", "prm_wd_on" }) do
    t:add(F[k], tvb(off, 1))
  end
  local f1, f2 = tvb(off + 1, 1):uint(), tvb(off + 2, 1):uint()
  tree:add(F.prm_wd1, tvb(off + 1, 1))
  tree:add(F.prm_wd2, tvb(off + 2, 1))
  local wd_on = band(st, 0x08) ~= 0
  local wd = f1 * f2 * 10
  tree:add(F.prm_tsdr, tvb(off + 3, 1))
  tree:add(F.prm_ident, tvb(off + 4, 2))
  tree:add(F.prm_group, tvb(off + 6, 1))
  if len > 7 then tree:add(F.prm_user, tvb(off + 7, len - 7)) end
  local dpv1 = ""
  if len >= 10 then
    local o = { tvb(off + 7, 1):uint(), tvb(off + 8, 1):uint(), tvb(off + 9, 1):uint() }
    local reserved = band(o[1], DPV1_RESERVED[1]) + band(o[2], DPV1_RESERVED[2]) + band(o[3], DPV1_RESERVED[3])
    if reserved == 0 then
      local flags = {}
      for i = 1, 3 do
        for _, e in ipairs(DPV1_BITS[i]) do
          if band(shr(o[i], e[1]), 1) == 1 then flags[#flags + 1] = e[2] end
        end
      end
      local am = band(o[3], 0x07)
      local t = tree:add(F.prm_dpv1, tvb(off + 7, 3))
      t:add(F.prm_dpv1_flags, tvb(off + 7, 2), table.concat(flags, ", "))
      t:add(F.prm_alarm_mode, tvb(off + 9, 1), string.format("%d (%s)", am, ALARM_MODE[am]))
      if band(o[1], 0x04) ~= 0 then wd = f1 * f2 end          -- WD_Base_1ms
      dpv1 = ", DP-V1 " .. (#flags > 0 and table.concat(flags, ", ") or "no bit set")
    end
  end
  if wd_on then
    tree:add(F.prm_wd_ms, tvb(off + 1, 2), wd):append_text(string.format(" (%d x %d x %d ms)", f1, f2,
      wd == f1 * f2 and 1 or 10))
  end
  local lock = (band(st, 0xC0) == 0x80) and "lock" or (band(st, 0x40) ~= 0) and "unlock" or "no lock change"
  return string.format("ident 0x%04X, %s, %s, min TSDR %d%s", tvb(off + 4, 2):uint(), lock,
    wd_on and ("watchdog " .. wd .. " ms") or "watchdog off", tvb(off + 3, 1):uint(), dpv1)
end

-- a device-related block read as a DP-V1 alarm or status block (header, type, slot, specifier, data), as
-- dp/dpv1.py reads it: nil when shorter than 4 octets or its type is not defined
local function dpv1_block(tvb, tree, off, ln)
  if ln < 4 then return nil end
  local o1, slot, spec = tvb(off + 1, 1):uint(), tvb(off + 2, 1):uint(), tvb(off + 3, 1):uint()
  local status, code = band(o1, 0x80) ~= 0, band(o1, 0x7F)
  local name = (status and STATUS_TYPES or ALARM_TYPES)[code]
  if name == nil and code >= 32 and code <= 126 then name = "manufacturer-specific " .. code end
  if name == nil then return nil end
  local s = string.format("device-related: DP-V1 %s block: %s (0x%02X), slot %d, specifier %d (%s)",
    status and "status" or "alarm", name, o1, slot, spec, (status and STATUS_SPEC or ALARM_SPEC)[band(spec, 3)])
  if not status then
    s = s .. ", Seq_Nr " .. shr(spec, 3) .. (band(spec, 4) ~= 0 and ", Add_Ack" or "")
  end
  if status and code == 2 then
    local bad = {}
    for k = 4, ln - 1 do
      local o = tvb(off + k, 1):uint()
      for m = 0, 3 do
        local v = band(shr(o, 2 * m), 3)
        if v ~= 0 then bad[#bad + 1] = string.format("module %d: %s", (k - 4) * 4 + m, MODULE_STATUS[v]) end
      end
    end
    s = s .. string.format("; %d modules: %s", (ln - 4) * 4, #bad > 0 and table.concat(bad, "; ") or "all data valid")
  elseif ln > 4 then
    s = s .. "; data " .. hexs(tvb(off + 4, ln - 4))
  end
  tree:add(F.diag_dpv1_type, tvb(off + 1, 1), name)
  tree:add(F.diag_dpv1_slot, tvb(off + 2, 1))
  tree:add(F.diag_dpv1_spec, tvb(off + 3, 1), string.format("%d (%s)", spec,
    (status and STATUS_SPEC or ALARM_SPEC)[band(spec, 3)]))
  return s
end

local function ext_blocks(tvb, tree, off, len)
  local i = 0
  local texts = {}
  while i < len do
    local h = tvb(off + i, 1):uint()
    local typ = shr(h, 6)
    local text, used
    if typ == 2 then
      if i + 3 > len then text, used = "reserved block " .. hexs(tvb(off + i, len - i)), len - i
      else
        local o2, o3 = tvb(off + i + 1, 1):uint(), tvb(off + i + 2, 1):uint()
        local et = band(o3, 0x1F)
        local err = CHANNEL_ERROR[et] or (et >= 16 and ("manufacturer-specific error " .. et) or ("reserved error " .. et))
        text = string.format("channel-related: module %d, channel %d %s, %s: %s", band(h, 0x3F), band(o2, 0x3F),
          CHANNEL_DIR[shr(o2, 6)] or "?", CHANNEL_WIDTH[shr(o3, 5)] or "invalid width", err)
        used = 3
      end
    elseif typ == 3 then
      text, used = "reserved block " .. hexs(tvb(off + i, len - i)), len - i
    else
      local ln = band(h, 0x3F)
      if ln < 1 or i + ln > len then
        text, used = "reserved block " .. hexs(tvb(off + i, len - i)), len - i
      elseif typ == 1 then
        local mods = {}
        for bi = 1, ln - 1 do
          local o = tvb(off + i + bi, 1):uint()
          for b = 0, 7 do if band(shr(o, b), 1) == 1 then mods[#mods + 1] = tostring((bi - 1) * 8 + b) end end
        end
        text = "identifier-related: modules with diagnosis: " .. (#mods > 0 and table.concat(mods, ", ") or "none")
        used = ln
      else
        text = dpv1_block(tvb, tree, off + i, ln)
          or ("device-related: " .. (ln > 1 and hexs(tvb(off + i + 1, ln - 1)) or "(empty)"))
        used = ln
      end
    end
    tree:add(F.diag_block, tvb(off + i, used), text)
    texts[#texts + 1] = text
    i = i + used
  end
  return texts
end

local function dissect_diag(tvb, tree, off, len)
  if len < 6 then tree:add_proto_expert_info(E.malformed, "Slave_Diag reply needs 6 octets, got " .. len) return "" end
  local st = { tvb(off, 1):uint(), tvb(off + 1, 1):uint(), tvb(off + 2, 1):uint() }
  local ts = { tree:add(F.diag_st1, tvb(off, 1)), tree:add(F.diag_st2, tvb(off + 1, 1)),
               tree:add(F.diag_st3, tvb(off + 2, 1)) }
  for _, bf in ipairs(bits_fields) do ts[bf[1]]:add(F[bf[2]], tvb(off + bf[1] - 1, 1)) end
  local flags = {}
  for i, n in ipairs(ST1_BITS) do if band(shr(st[1], i - 1), 1) == 1 then flags[#flags + 1] = n end end
  for i, n in ipairs(ST2_BITS) do
    if band(shr(st[2], i - 1), 1) == 1 and n ~= "always 1" and n ~= "reserved" then flags[#flags + 1] = n end
  end
  if band(st[3], 0x80) ~= 0 then flags[#flags + 1] = "Ext_Diag_Overflow" end
  tree:add(F.diag_flags, tvb(off, 3), table.concat(flags, ", "))
  local master = tvb(off + 3, 1):uint()
  tree:add(F.diag_master, tvb(off + 3, 1)):append_text(master == 255 and " (not parameterised)" or "")
  tree:add(F.diag_ident, tvb(off + 4, 2))
  if band(st[1], 0x47) ~= 0 then
    tree:add_proto_expert_info(E.diag, "Slave_Diag: " .. table.concat(flags, ", "))
  end
  if len > 6 then
    local et = tree:add(F.diag_ext, tvb(off + 6, len - 6))
    ext_blocks(tvb, et, off + 6, len - 6)
  end
  return string.format("ident 0x%04X, master %s, %s", tvb(off + 4, 2):uint(),
    master == 255 and "none" or tostring(master), #flags > 0 and table.concat(flags, ", ") or "no flags")
end

local function dissect_gc(tvb, tree, off, len)
  if len ~= 2 then tree:add_proto_expert_info(E.malformed, "Global_Control needs 2 octets, got " .. len) return "" end
  local c, g = tvb(off, 1):uint(), tvb(off + 1, 1):uint()
  tree:add(F.gc_cmd, tvb(off, 1))
  local cmds = {}
  for _, e in ipairs(GC_NAMES) do if band(c, e[1]) ~= 0 then cmds[#cmds + 1] = e[2] end end
  if #cmds == 0 then cmds[1] = "operate (no command)" end
  tree:add(F.gc_text, tvb(off, 1), table.concat(cmds, " + "))
  tree:add(F.gc_group, tvb(off + 1, 1))
  local grp = "all groups"
  if g ~= 0 then
    local gs = {}
    for i = 0, 7 do if band(shr(g, i), 1) == 1 then gs[#gs + 1] = tostring(i + 1) end end
    grp = "groups " .. table.concat(gs, ",")
  end
  return table.concat(cmds, " + ") .. ", " .. grp
end

local function dissect_ssa(tvb, tree, off, len)
  if len < 4 then tree:add_proto_expert_info(E.malformed, "Set_Slave_Add needs 4 octets, got " .. len) return "" end
  tree:add(F.ssa_addr, tvb(off, 1))
  tree:add(F.ssa_ident, tvb(off + 1, 2))
  tree:add(F.ssa_nochg, tvb(off + 3, 1), tvb(off + 3, 1):uint() ~= 0)
  if len > 4 then tree:add(F.ssa_extra, tvb(off + 4, len - 4)) end
  return string.format("new address %d, ident 0x%04X", tvb(off, 1):uint(), tvb(off + 1, 2):uint())
end

-- ------------------------------------------------------------------------------------------------
-- DP-V1 acyclic services (dp/du_decode.py decode_acyclic, bustools/dpv1view.py, drives/records.py)

-- ds47.py error_text: "0x14 value impermissible"
local function ds47_error_text(n)
  local t = DS47_ERRORS[n]
  if t then return string.format("0x%02X %s", n, t) end
  if n >= 0x65 and n <= 0xFF then return string.format("0x%02X manufacturer-specific error", n) end
  return string.format("0x%02X unknown error number", n)
end

local function ds47_format_name(fmt)
  return DS47_FORMATS[fmt] or string.format("format 0x%02X", fmt)
end

-- ds47.py ParamAddress.describe: "PNU964[0] (1 element)"
local function ds47_address(pnu, sub, el, attr)
  local a = ""
  if attr ~= 0x10 then a = " " .. (DS47_ATTRIBUTES[attr] or string.format("attribute 0x%02X", attr)) end
  return string.format("PNU%d[%d]%s (%d element%s)", pnu, sub, a, el, el == 1 and "" or "s")
end

-- one block at off (format, number of values, the values, a zero octet when they take an odd number):
-- its items under tree; returns its words (ds47.py ParamValues / ParamFault describe) and the offset
-- after it, or nil and what is wrong
local function ds47_block(tvb, tree, off, stop)
  if off + 2 > stop then return nil, "the block (format, number of values) runs past the end" end
  local fmt, n = tvb(off, 1):uint(), tvb(off + 1, 1):uint()
  if fmt == 0x44 then
    if n ~= 1 and n ~= 2 then return nil, "an error block carries 1 or 2 values, not " .. n end
    if off + 2 + 2 * n > stop then return nil, "the error block runs past the end" end
    tree:add(P.ds47_format, tvb(off, 1))
    tree:add(P.ds47_values, tvb(off + 1, 1))
    local num = tvb(off + 2, 2):uint()
    tree:add(P.ds47_error, tvb(off + 2, 2))
    tree:add(P.ds47_error_text, tvb(off + 2, 2), ds47_error_text(num))
    local text = "error " .. ds47_error_text(num)
    if n == 2 then
      tree:add(P.ds47_extra, tvb(off + 4, 2))
      text = text .. string.format(" (additional information %d)", tvb(off + 4, 2):uint())
    end
    return text, off + 2 + 2 * n
  end
  if fmt == 0x40 then
    if n ~= 0 then return nil, "a Zero block carries no values, not " .. n end
    tree:add(P.ds47_format, tvb(off, 1))
    tree:add(P.ds47_values, tvb(off + 1, 1))
    return "Zero", off + 2
  end
  local coding = DS47_CODING[fmt]
  if coding == nil then return nil, string.format("format 0x%02X: the size of its values is not known", fmt) end
  local size, kind = coding[1], coding[2]
  local len = n * size
  if off + 2 + len > stop then
    return nil, string.format("%d %s value(s) need %d octets, %d left", n, DS47_FORMATS[fmt], len, stop - off - 2)
  end
  tree:add(P.ds47_format, tvb(off, 1))
  tree:add(P.ds47_values, tvb(off + 1, 1))
  local name, text = DS47_FORMATS[fmt], nil
  if kind == "o" then
    if len > 0 then tree:add(P.ds47_octets, tvb(off + 2, len)) end
    if fmt == 0x09 then text = name .. " '" .. (len > 0 and tvb(off + 2, len):string() or "") .. "'"
    else text = name .. " " .. (len > 0 and hexs(tvb(off + 2, len)) or "(none)") end
  else
    local shown = {}
    for i = 0, n - 1 do
      local r = tvb(off + 2 + i * size, size)
      local v
      if kind == "f" then v = r:float()
      elseif kind == "s" then v = r:int()
      elseif size > 4 then v = r:uint64():tonumber()
      else v = r:uint() end
      tree:add(P.ds47_value, r, v)
      if i < 8 then
        if kind == "f" then shown[#shown + 1] = string.format("%g", v)
        elseif DS47_HEX[fmt] then shown[#shown + 1] = string.format("0x%0" .. (2 * size) .. "X", v)
        else shown[#shown + 1] = string.format("%d", v) end
      end
    end
    text = name .. " " .. (#shown > 0 and table.concat(shown, ", ") or "(none)") ..
           (n > 8 and string.format(" ... (%d values)", n) or "")
  end
  local nxt = off + 2 + len
  if len % 2 == 1 and nxt < stop then nxt = nxt + 1 end     -- the pad (may be missing after the last)
  return text, nxt
end

-- a PROFIdrive parameter request (in a Write of index 47) or response (in a Read answer of index 47)
-- at off: a PROFIdrive subtree; returns its line (sniff's: "DS47 parameter request: " and ds47.py's
-- describe)
local function dissect_ds47(tvb, root, off, len, is_request)
  local stop = off + len
  local what = is_request and "request" or "response"
  local pd = root:add(p_pd, tvb(off, len))
  pd:add(P.ds47_kind, what):set_generated()
  local function malformed(why)
    pd:add_proto_expert_info(E.malformed, "DS47 parameter " .. what .. ": " .. why)
    pd:set_text("PROFIdrive parameter " .. what .. " (DS47), malformed: " .. why)
    return "DS47 parameter " .. what .. ", malformed: " .. why
  end
  if len < 4 then return malformed("a header of 4 octets, " .. len .. " here") end
  local ref, id, axis, n = tvb(off, 1):uint(), tvb(off + 1, 1):uint(), tvb(off + 2, 1):uint(), tvb(off + 3, 1):uint()
  pd:add(P.ds47_reference, tvb(off, 1))
  pd:add(is_request and P.ds47_request_id or P.ds47_response_id, tvb(off + 1, 1))
  pd:add(P.ds47_axis, tvb(off + 2, 1))
  pd:add(P.ds47_count, tvb(off + 3, 1))
  local ids = is_request and DS47_REQUEST or DS47_RESPONSE
  if ids[id] == nil then return malformed(string.format("%s id 0x%02X", what, id)) end
  local head = string.format("ref %d %s axis %d: ", ref, ids[id], axis)
  local parts = {}
  local pos = off + 4
  if is_request then
    local items = {}
    for i = 1, n do
      if pos + 6 > stop then return malformed("the address of parameter " .. i .. " of " .. n .. " is missing") end
      local attr, el = tvb(pos, 1):uint(), tvb(pos + 1, 1):uint()
      local pnu, sub = tvb(pos + 2, 2):uint(), tvb(pos + 4, 2):uint()
      local addr = ds47_address(pnu, sub, el, attr)
      local pt = pd:add(P.ds47_param, tvb(pos, 6), addr)
      pt:set_text(string.format("Parameter %d: %s", i, addr))
      pt:add(P.ds47_attribute, tvb(pos, 1))
      pt:add(P.ds47_elements, tvb(pos + 1, 1))
      pt:add(P.ds47_pnu, tvb(pos + 2, 2))
      pt:add(P.ds47_subindex, tvb(pos + 4, 2))
      items[i] = pt
      parts[i] = addr
      pos = pos + 6
    end
    if id == 0x02 then
      for i = 1, n do
        local text, nxt = ds47_block(tvb, items[i], pos, stop)
        if text == nil then return malformed("parameter " .. i .. " of " .. n .. ": " .. nxt) end
        items[i]:append_text(" = " .. text)
        parts[i] = parts[i] .. " = " .. text
        pos = nxt
      end
    end
  elseif id ~= 0x02 then                   -- a positive change response is the header alone
    for i = 1, n do
      if pos + 2 > stop then return malformed("the block of parameter " .. i .. " of " .. n .. " is missing") end
      local pt = pd:add(P.ds47_param, tvb(pos, 2), "parameter " .. i)
      local text, nxt = ds47_block(tvb, pt, pos, stop)
      if text == nil then return malformed("parameter " .. i .. " of " .. n .. ": " .. nxt) end
      pt:set_len(nxt - pos)
      pt:set_text(string.format("Parameter %d: %s", i, text))
      parts[i] = text
      pos = nxt
    end
  end
  if pos ~= stop then return malformed(string.format("%d octet(s) after the last parameter", stop - pos)) end
  local desc = head .. (#parts > 0 and table.concat(parts, (is_request and id ~= 0x02) and ", " or "; ")
                        or string.format("%d parameter%s", n, n == 1 and "" or "s"))
  pd:set_text("PROFIdrive parameter " .. what .. " (DS47): " .. desc)
  return "DS47 parameter " .. what .. ": " .. desc
end

-- dp/msac1.py error_text
local function msac_error_text(decode, c1, c2)
  local octets = string.format("(%02X %02X %02X)", decode, c1, c2)
  if decode ~= 0x80 then return (MSAC_ERROR_DECODE[decode] or "reserved error decode") .. " error " .. octets end
  local cls, code = shr(c1, 4), band(c1, 0x0F)
  if cls >= 0xD then return "DPV1 user-specific error " .. octets end
  if MSAC_ERROR_CLASSES[cls] == nil then return "DPV1 reserved error class " .. cls .. " " .. octets end
  local name = MSAC_ERROR_CODES[cls][code]
  if name == nil then name = code >= (cls == 0xC and 8 or 10) and "user-specific" or "reserved" end
  return "DPV1 " .. MSAC_ERROR_CLASSES[cls] .. ": " .. name .. " " .. octets
end

-- dp/capture.py acyclic_service: a telegram's service by its SAP and its PDU's first octet
local function acyclic_service(sap, is_request, first)
  local prefix = ACYCLIC[sap]
  if first == nil then return prefix .. (is_request and " poll" or " reply") end
  local fn = band(first, 0x7F)
  if fn == MSAC_ALARM_ACK and sap == 50 then prefix = "MSAC_C1" end
  local name = MSAC_FUNCTIONS[fn] or string.format("function 0x%02X", fn)
  if is_request then return prefix .. " " .. name .. " request" end
  return prefix .. " " .. name .. (band(first, 0x80) ~= 0 and " error response" or " response")
end

-- A call's telegrams tied together (bustools/dpv1view.py): the request open per (master, slave) and
-- the SC right after a request or poll. Wireshark dissects a file in order first: what a telegram
-- learnt from the ones before it is kept by its frame number (C1_CTX, C1_SC) for every later look;
-- init() starts afresh with each file. A capture without DP-V1 telegrams never looks (C1_SEEN).
local C1_SEEN, C1_OPEN, C1_CTX, C1_SC = false, {}, {}, {}
local C1_AT, C1_NOTE = -2, nil
function p_fdl.init()
  C1_SEEN, C1_OPEN, C1_CTX, C1_SC, C1_AT, C1_NOTE = false, {}, {}, {}, -2, nil
end

-- the note of the SC frame n: the acknowledgement of the request or poll just before it, or nil
local function c1_sc_note(n)
  local note = C1_SC[n]
  if note == nil then
    note = (n == C1_AT + 1) and C1_NOTE or false
    C1_SC[n] = note
  end
  return note or nil
end

local function msac_what(fn, slot, index, length)
  return string.format("%s slot %d index %d length %d", MSAC_FUNCTIONS[fn] or string.format("function 0x%02X", fn),
    slot, index, length)
end

-- the MSAC PDU of a telegram to or from an acyclic SAP (the DU at off, len octets after the SAPs):
-- its items under t (the DS47 record as a PROFIdrive subtree of root); returns the summary
local function dissect_msac(tvb, pinfo, root, t, off, len, sap, is_request, da, sa)
  C1_SEEN = true
  local n = pinfo.number
  local service = ACYCLIC[sap]:match("^%S+")
  local pair = is_request and (sa * 128 + da) or (da * 128 + sa)
  local slave = is_request and da or sa
  -- what the request open between these two stations asked, as it stood when this frame came
  local ctx = C1_CTX[n]
  if ctx == nil then ctx = C1_OPEN[pair] or false C1_CTX[n] = ctx end
  local mt = t:add(F.msac, len > 0 and tvb(off, len) or tvb(off - 2, 2))
  mt:add(F.msac_service, service):set_generated()
  local function arm(kind, what)
    C1_AT = n
    C1_NOTE = kind == "request" and
      string.format("%s: station %d took the request%s; the master polls for the answer", service, slave,
        what and (" (" .. what .. ")") or "") or
      string.format("%s: station %d has no answer yet%s; the master polls again", service, slave,
        what and (" (" .. what .. ")") or "")
  end
  local summary
  if len == 0 then
    mt:add(F.msac_kind, is_request and "poll" or "ack"):set_generated()
    mt:add(F.msac_station, slave):set_generated()
    if ctx then mt:add(F.msac_request, ctx):set_generated() end
    if is_request then
      summary = string.format("%s poll: the master asks station %d for the answer%s", service, da,
        ctx and (" to " .. ctx) or "")
      arm("poll", ctx or nil)
    else
      summary = service .. " reply without data: no answer yet" .. (ctx and (" (to " .. ctx .. ")") or "")
    end
    mt:set_text("DP-V1 " .. summary)
    return summary
  end
  local first = tvb(off, 1):uint()
  local fn = band(first, 0x7F)
  mt:add(F.msac_kind, is_request and "request" or "response"):set_generated()
  mt:add(F.msac_function, tvb(off, 1))
  mt:add(F.msac_error_bit, tvb(off, 1))
  local bad = nil
  if sap == 49 or (fn ~= MSAC_READ and fn ~= MSAC_WRITE and fn ~= MSAC_ALARM_ACK) then
    if len > 1 then mt:add(F.msac_data, tvb(off + 1, len - 1)) end
    summary = acyclic_service(sap, is_request, first) .. ": " .. hexs(tvb(off, len))
    if is_request then arm("request", nil)
    elseif ctx then summary = summary .. " (to " .. ctx .. ")" end
  elseif band(first, 0x80) ~= 0 then
    if is_request then bad = string.format("octet 0: 0x%02X has the error bit set in a request", first)
    elseif len ~= 4 then bad = string.format("error response of %d octets (4 expected)", len)
    else
      local d, c1, c2 = tvb(off + 1, 1):uint(), tvb(off + 2, 1):uint(), tvb(off + 3, 1):uint()
      mt:add(F.msac_decode, tvb(off + 1, 1))
      local ct = mt:add(F.msac_code1, tvb(off + 2, 1))
      ct:add(F.msac_class, tvb(off + 2, 1)):append_text(MSAC_ERROR_CLASSES[shr(c1, 4)] and
        (" (" .. MSAC_ERROR_CLASSES[shr(c1, 4)] .. ")") or "")
      ct:add(F.msac_code, tvb(off + 2, 1))
      mt:add(F.msac_code2, tvb(off + 3, 1))
      local text = msac_error_text(d, c1, c2)
      mt:add(F.msac_error, tvb(off + 1, 3), text)
      summary = string.format("%s response: %s error: %s", service, MSAC_FUNCTIONS[fn], text)
      if ctx then
        mt:add(F.msac_request, ctx):set_generated()
        summary = summary .. " (to " .. ctx .. ")"
      end
    end
  elseif len < 4 then
    bad = string.format("%s PDU of %d octets (header of 4 expected)", MSAC_FUNCTIONS[fn], len)
  elseif fn == MSAC_ALARM_ACK then
    mt:add(F.msac_slot, tvb(off + 1, 1))
    mt:add(F.msac_alarm_type, tvb(off + 2, 1))
    mt:add(F.msac_specifier, tvb(off + 3, 1))
    summary = string.format("%s %s: Alarm_Ack slot %d alarm type %d specifier 0x%02X", service,
      is_request and "request" or "response", tvb(off + 1, 1):uint(), tvb(off + 2, 1):uint(), tvb(off + 3, 1):uint())
    if is_request then C1_OPEN[pair] = "Alarm_Ack slot " .. tvb(off + 1, 1):uint() arm("request", C1_OPEN[pair]) end
  else
    local slot, index, length = tvb(off + 1, 1):uint(), tvb(off + 2, 1):uint(), tvb(off + 3, 1):uint()
    mt:add(F.msac_slot, tvb(off + 1, 1))
    mt:add(F.msac_index, tvb(off + 2, 1))
    mt:add(F.msac_length, tvb(off + 3, 1))
    local dlen = len - 4
    if dlen > 0 then mt:add(F.msac_data, tvb(off + 4, dlen)) end
    local carries = (fn == MSAC_WRITE) == is_request
    if carries and dlen ~= length then bad = string.format("octet 3: length %d but %d data octets follow", length, dlen)
    elseif not carries and dlen > 0 then
      bad = string.format("octet 4: %d octets after a %s %s header", dlen, MSAC_FUNCTIONS[fn],
        is_request and "request" or "response")
    elseif length > 240 then bad = string.format("octet 3: length %d over 240", length) end
    local what = msac_what(fn, slot, index, length)
    summary = string.format("%s %s: %s", service, is_request and "request" or "response", what)
    if is_request then C1_OPEN[pair] = what arm("request", what) end
    if bad == nil and index == DS47_INDEX and carries and dlen > 0 then
      summary = summary .. "; " .. dissect_ds47(tvb, root, off + 4, dlen, is_request)
    end
  end
  if bad then
    mt:add_proto_expert_info(E.malformed, service .. " PDU: " .. bad)
    summary = acyclic_service(sap, is_request, first) .. ": malformed PDU: " .. bad .. ": " .. hexs(tvb(off, len))
    if is_request then arm("request", nil)
    elseif ctx then summary = summary .. " (to " .. ctx .. ")" end
  end
  if not is_request then C1_OPEN[pair] = nil end       -- answered (a reply with data: len > 0 here)
  mt:set_text("DP-V1 " .. summary)
  return summary
end

-- ------------------------------------------------------------------------------------------------
-- FDL telegram

local function fc_words(fc)
  if band(fc, 0x40) ~= 0 then
    local fn = band(fc, 0x0F)
    local name = REQUEST_NAMES[fn] or ("reserved function " .. fn)
    if band(fc, 0x80) ~= 0 and fn == 0 then name = "CV clock value" end
    return string.format("%s, FCB=%d FCV=%d", name, band(shr(fc, 5), 1), band(shr(fc, 4), 1))
  end
  local st = band(fc, 0x0F)
  return string.format("%s (%s)", RESPONSE_NAMES[st] or ("reserved status " .. st), STATION_TYPES[band(shr(fc, 4), 3)])
end

local FC_WORDS = {}
local function fc_words_cached(fc)
  local w = FC_WORDS[fc]
  if w == nil then w = fc_words(fc) FC_WORDS[fc] = w end
  return w
end

-- ------------------------------------------------------------------------------------------------
-- The hot path: the telegrams of a running line (token, short acknowledge, FDL status and
-- Data_Exchange with a good FCS and end delimiter, no SAPs), in every mode. Each call into Wireshark
-- (a TvbRange, a tree item, a method or attribute looked up on a userdata) costs some 2,000 to 4,000
-- instructions with its garbage collection (callgrind, Wireshark 4.0), more than the Lua around it,
-- so this path makes as few as the output needs, and the same output as the full path below:
--   - values are read from one raw string (string.byte), never from a TvbRange per octet or word;
--   - one TvbRange per span, shared by every item on it; an item's label is given when it is added
--     (no set_text / append_text afterwards); the methods are looked up once;
--   - per layout and direction, a plan made once (labels, fields, texts), not per telegram;
--   - without a protocol tree (tshark's summary lines, Wireshark's packet list) only the columns;
--     with a tree that is not shown (a display filter or a field column on the packet list, tshark
--     -Y without -V) only the fields they refer to (TreeItem.visible, TreeItem:referenced); with a
--     shown tree (-V, -T fields / pdml / json, the packet details) every item.
-- Anything else (SAP services, bad FCS, a length that does not match the layout) takes the full
-- path, which decodes and checks everything.

local M_add, M_add_le, M_gen, M_set_text, M_referenced  -- TreeItem methods, looked up once
-- TreeItem.visible and TreeItem:referenced (Wireshark 2.4 and later); without them every tree is
-- built in full
local tree_visible_known = nil
local NUM = {}
for i = 0, 255 do NUM[i] = tostring(i) end
local HEXU = {}
for i = 0, 255 do HEXU[i] = string.format("%02X", i) end

-- Which fields does this pass refer to (tree not shown)? Asked once per field and pass; a new pass
-- (the frame number goes back: a new file, a refilter, a click in the packet list) asks again.
local REF, REF_last = {}, -1
local function ref_reset(pinfo)
  local n = pinfo.number
  if n <= REF_last then REF = {} end
  REF_last = n
end
local function refd(tree, field)
  local r = REF[field]
  if r == nil then r = M_referenced(tree, field) and true or false REF[field] = r end
  return r
end

-- the bits of a bit word, per names table and value: "a, b" (the bits set) and the lines
-- "bit  8 jog 1: 0" (at most 4096 words per names table are kept)
local BITS = setmetatable({}, { __mode = "k" })
local function bits_of(w, names)
  local by_w = BITS[names]
  if by_w == nil then by_w = { n = 0 } BITS[names] = by_w end
  local e = by_w[w]
  if e == nil then
    local set = bit_list(w, names, 16)
    e = { set = table.concat(set, ", "), text = #set > 0 and table.concat(set, ", ") or "no bits set",
          lines = bit_lines(w, names) }
    if by_w.n >= 4096 then by_w = { n = 0 } BITS[names] = by_w end
    by_w[w] = e
    by_w.n = by_w.n + 1
  end
  return e
end

local format, concat, floor = string.format, table.concat, math.floor

-- octets i..j (1-based) of s as "0a 1b ..": one string.byte for all of them
local function hex_of(s, i, j)
  local o = { byte(s, i, j) }
  for k = 1, #o do o[k] = HEX[o[k]] end
  return concat(o, " ")
end

-- the plan of an area (one layout's request or response): made once per area table
local PLANS = setmetatable({}, { __mode = "k" })
local function plan_of(area, lay, direction, name)
  local plan = PLANS[area]
  if plan then return plan end
  local order = (lay and lay.word_order) or area.word_order or "big"
  plan = { name = name, little = order == "little", lay = lay, direction = direction, fields = {},
           ak_texts = direction == "request" and (lay and lay.ak_request or AK_REQUEST)
                      or (lay and lay.ak_response or AK_RESPONSE) }
  for _, f in ipairs(area.fields) do
    local p = { kind = f.kind, off = f.offset, size = f.size, name = f.name, role = f.role,
                label = f.name .. (f.what and (" (" .. f.what .. ")") or "") }
    if f.kind == "bits" then
      p.names = f.bits or {}
      p.field = f.role == "control" and P.control or f.role == "status" and P.status or P.word
      p.state = f.role == "status" and f.state ~= false
      p.set_field = f.role == "control" and P.control_set or f.role == "status" and P.status_set or nil
    elseif f.kind == "n2" or f.kind == "scaled" then
      p.signed = f.signed ~= false
      p.field = f.role == "reference" and P.reference or f.role == "actual" and P.actual or P.word
      p.pct_field = f.role and (f.role == "reference" and P.reference_pct or P.actual_pct) or nil
      p.hz_field = f.role and (f.role == "reference" and P.reference_hz or P.actual_hz) or nil
      if f.kind == "n2" then
        p.max_hz = f.max_hz
        if f.max_hz then p.hz_tail = " (100 % = " .. fmt_num(f.max_hz) .. " Hz)" end
      else
        p.scale = f.scale or 1
        p.hz = f.unit == "Hz"
        p.unit_tail = f.unit and f.unit ~= "" and (" " .. f.unit) or ""
      end
    end
    plan.fields[#plan.fields + 1] = p
  end
  PLANS[area] = plan
  return plan
end

-- the PKW channel at 1-based index i of s: its values and its note (dissect_pkw's rules)
local function pkw_values(s, i, little, plan)
  local a1, a2, b1, b2, c1, c2, d1, d2 = byte(s, i, i + 7)
  local pke, ind, pwe
  if little then pke, ind, pwe = a2 * 256 + a1, b2 * 256 + b1, (c2 * 256 + c1) * 65536 + d2 * 256 + d1
  else pke, ind, pwe = a1 * 256 + a2, b1 * 256 + b2, (c1 * 256 + c2) * 65536 + d1 * 256 + d2 end
  local ak = floor(pke / 4096)
  local pnu = pke % 2048
  local sub = floor(ind / 256)
  local ak_text = plan.ak_texts[ak] or "reserved"
  local label = param_label(plan.lay, pnu, sub)
  local note
  if ak == 0 then
    note = "PKW " .. ak_text
  else
    local where = "PNU " .. pnu .. (sub ~= 0 and ("[" .. sub .. "]") or "")
    note = "PKW AK " .. ak .. " " .. ak_text .. ", " .. where .. (label and (" = " .. label) or "")
    if (plan.direction == "response" and (ak == 7 or ak == 8)) then
      note = note .. ": error " .. (pwe % 65536)
    elseif not (plan.direction == "request" and (ak == 1 or ak == 4 or ak == 6 or ak == 9)) then
      note = note .. ", PWE " .. pwe
    end
  end
  return note, ak, ak_text, sub, pwe, label
end

-- the area's summary (the Info column's and the PROFIdrive item's text) from the raw telegram s,
-- the area at 1-based index base with len octets
local function plan_summary(plan, s, base, len)
  local notes = {}
  local little = plan.little
  local fields = plan.fields
  for k = 1, #fields do
    local p = fields[k]
    if p.off + p.size <= len then
      local kind = p.kind
      local i = base + p.off
      if kind == "pkw" then
        notes[#notes + 1] = (pkw_values(s, i, little, plan))
      elseif kind ~= "bytes" and kind ~= "word" then
        local h, l = byte(s, i, i + 1)
        if little then h, l = l, h end
        local w = h * 256 + l
        if kind == "bits" then
          local note = p.name .. " 0x" .. HEXU[h] .. HEXU[l]
          if p.state then note = note .. " " .. state_from_status(w) end
          notes[#notes + 1] = note
        else
          local v = p.signed and s16(w) or w
          local hz
          if kind == "n2" then
            if p.max_hz then hz = v * 100.0 / 16384 * p.max_hz / 100.0 end
          elseif p.hz then
            hz = v * p.scale
          end
          notes[#notes + 1] = hz and format("%s %.2f Hz", p.name, hz) or (p.name .. " 0x" .. HEXU[h] .. HEXU[l])
        end
      end
    end
  end
  return concat(notes, "; ")
end

-- the area's items under pd: every item when the tree is shown (V), else only the referred ones.
-- tvb: the telegram; s its raw octets; the area at 0-based offset off. Returns the area's summary
-- (plan_summary's) when V.
local function plan_items(plan, tvb, tree, pd, s, off, len, V)
  local little = plan.little
  local notes = {}
  local fields = plan.fields
  for k = 1, #fields do
    local p = fields[k]
    if p.off + p.size <= len then
      local kind = p.kind
      local o = off + p.off
      local i = o + 1
      if kind == "pkw" then
        local note, ak, ak_text, sub, pwe, label = pkw_values(s, i, little, plan)
        notes[#notes + 1] = note
        local add_w = little and M_add_le or M_add
        local t = pd
        if V or refd(tree, P.pkw) then
          t = M_add(pd, P.pkw, tvb(o, 8), s:sub(i, i + 7),
                    "PKW (parameter channel): " .. hex_of(s, i, i + 7) .. " -> " .. note)
        end
        local r = tvb(o, 2)
        if V or refd(tree, P.pke) then add_w(t, P.pke, r) end
        if V or refd(tree, P.ak) then add_w(t, P.ak, r) end
        if V or refd(tree, P.spm) then add_w(t, P.spm, r) end
        if V or refd(tree, P.pnu) then add_w(t, P.pnu, r) end
        if V or refd(tree, P.ak_text) then M_add(t, P.ak_text, r, ak_text) end
        if V or refd(tree, P.ind) or refd(tree, P.subindex) then
          r = tvb(o + 2, 2)
          if V or refd(tree, P.ind) then add_w(t, P.ind, r) end
          if V or refd(tree, P.subindex) then M_add(t, P.subindex, r, sub) end
        end
        if V or refd(tree, P.pwe) then M_add(t, P.pwe, tvb(o + 4, 4), pwe) end
        if label and ak ~= 0 and (V or refd(tree, P.param)) then M_add(t, P.param, tvb(o, 4), label) end
      elseif kind == "bytes" then
        if V or refd(tree, P.bytes) then
          M_add(pd, P.bytes, tvb(o, p.size), s:sub(i, i + p.size - 1), p.name .. ": " .. hex_of(s, i, i + p.size - 1))
        end
      else
        local h, l = byte(s, i, i + 1)
        if little then h, l = l, h end
        local w = h * 256 + l
        local field = p.field
        local r = tvb(o, 2)
        local hex = "0x" .. HEXU[h] .. HEXU[l]
        if kind == "bits" then
          local b = bits_of(w, p.names)
          local st = p.state and state_from_status(w)
          local t
          if V then
            t = M_add(pd, field, r, w, p.label .. " " .. hex .. ": " .. b.text .. (st and (" -> " .. st) or ""))
            notes[#notes + 1] = p.name .. " " .. hex .. (st and (" " .. st) or "")
          elseif refd(tree, field) then
            M_add(pd, field, r, w)
          end
          if st and (V or refd(tree, P.state)) then M_add(pd, P.state, r, st) end
          if p.set_field then
            if V or refd(tree, p.set_field) then M_add(pd, p.set_field, r, b.set) end
          elseif V or refd(tree, P.field) then
            M_add(pd, P.field, r, p.name)
          end
          if V then
            local lines = b.lines
            for k = 1, #lines do M_add(t, r, lines[k]) end
          end
        elseif kind == "n2" or kind == "scaled" then
          local v = p.signed and s16(w) or w
          local text, hz, hzs, val
          local t
          if kind == "n2" then
            local pct = v * 100.0 / 16384
            if V then
              text = p.label .. " " .. hex .. ": " .. fmt_num(pct) .. " %"
            end
            if p.max_hz then
              hz = pct * p.max_hz / 100.0
              hzs = format("%.2f", hz)
              if V then text = text .. " = " .. hzs .. " Hz" .. p.hz_tail end
            end
            if V then t = M_add(pd, field, r, w, text) elseif refd(tree, field) then M_add(pd, field, r, w) end
            if p.pct_field and (V or refd(tree, p.pct_field)) then M_add(pd, p.pct_field, r, pct) end
          else
            val = v * p.scale
            if p.hz then hz = val hzs = format("%.2f", hz) end
            if V then t = M_add(pd, field, r, w, p.label .. " " .. hex .. " = " .. fmt_num(val) .. p.unit_tail)
            elseif refd(tree, field) then M_add(pd, field, r, w) end
            if field == P.word and (V or refd(tree, P.value)) then M_add(pd, P.value, r, val) end
          end
          if hz and p.hz_field and (V or refd(tree, p.hz_field)) then M_add(pd, p.hz_field, r, hz) end
          if field == P.word and (V or refd(tree, P.field)) then M_add(pd, P.field, r, p.name) end
          notes[#notes + 1] = hz and (p.name .. " " .. hzs .. " Hz") or (p.name .. " " .. hex)
        else
          if V then M_add(pd, P.word, r, w, p.label .. " " .. hex .. " = " .. w)
          elseif refd(tree, P.word) then M_add(pd, P.word, r, w) end
          if V or refd(tree, P.field) then M_add(pd, P.field, r, p.name) end
        end
      end
    end
  end
  return concat(notes, "; ")
end

-- the layout of a station's area: (plan or nil, name or nil); nil, nil and false when the length
-- does not match the station's layout (the full path reports that)
local function area_plan(station, direction, len)
  local lay = station_layout(station)
  if lay and lay[direction] and lay[direction].length ~= len then return nil, nil, false end
  local area, name
  if lay then
    area = lay[direction]
    name = lay.profile .. " " .. lay.layout
  elseif prefs().generic then
    area = generic_layout_cached(len, direction)
    name = area and ("generic PROFIdrive " .. area.name)
  end
  if area == nil then return nil, nil, true end
  return plan_of(area, lay, direction, name), lay, true
end

-- Per station and direction the last area's summary: an area that repeats the station's previous
-- one (most of them on a running line) costs one string comparison. The entry holds the layout and
-- the preference it was decoded with.
local area_cache = {}

-- the summary of the area at 0-based offset off (len octets) of the telegram (raw s) and its plan
-- (both nil without a layout), and false when the full path must decode it
local function area_summary(tvb, s, off, len, station, direction)
  local slot = direction == "request" and station or station + 128
  local lay = station_layout(station)
  local generic = prefs().generic
  local c = area_cache[slot]
  local raw = s:sub(off + 1, off + len)
  if c and c.raw == raw and c.lay == lay and c.generic == generic then return c.summary, c.plan, true end
  local plan, _, ok = area_plan(station, direction, len)
  if not ok then area_cache[slot] = nil return nil, nil, false end
  -- a station's first area is read through a TvbRange (the bounds checked by Wireshark), every later
  -- one from the telegram's raw string
  if c == nil then raw = tvb(off, len):raw() end
  local summary = plan and plan_summary(plan, raw, 1, len)
  area_cache[slot] = { raw = raw, lay = lay, generic = generic, summary = summary, plan = plan }
  return summary, plan, true
end

-- the FC item's label as Wireshark writes it ("FC: 0x5d") and the FC in words
local FC_LABEL = {}
local function fc_label(fc)
  FC_LABEL[fc] = "FC: 0x" .. HEX[fc] .. ": " .. fc_words_cached(fc)
  return FC_LABEL[fc]
end

local DIR_TEXT = { request = "request (master -> drive outputs)", response = "response (drive -> master inputs)" }

-- returns the telegram's length when done, nil for the full path
local function dissect_fast(tvb, pinfo, tree, len)
  local s = tvb:raw()
  local sd, o2, o3, o4 = byte(s, 1, 4)
  local body_off, body_len
  if sd == SD1 then body_off, body_len = 1, 3
  elseif sd == SD3 then body_off, body_len = 1, 11
  elseif sd == SD2 and len >= 4 then
    body_off, body_len = 4, o2
    if o3 ~= body_len or o4 ~= SD2 or body_len < 3 then return nil end
  elseif sd ~= SC and sd ~= SD4 then
    return nil
  end
  local fcs_at, fcs, da, sa, fc
  if body_off then
    fcs_at = body_off + body_len                          -- 0-based, as in the tvb
    if len < fcs_at + 2 then return nil end
    local ed
    fcs, ed = byte(s, fcs_at + 1, fcs_at + 2)
    if ed ~= ED or fcs ~= octet_sum(s, body_off + 1, fcs_at) then return nil end
    da, sa, fc = byte(s, body_off + 1, body_off + 3)
    if da >= 0x80 or sa >= 0x80 then return nil end      -- SAPs: DP services
  elseif sd == SD4 and len < 3 then
    return nil
  end
  if M_add == nil then
    M_add, M_add_le, M_gen, M_set_text = tree.add, tree.add_le, tree.set_generated, tree.set_text
    tree_visible_known = pcall(function() return tree.visible end) and pcall(function() return tree.referenced end)
    if tree_visible_known then M_referenced = tree.referenced end
  end
  -- the tree: shown (V), built but not shown (only the referred fields), or none
  local V, T = false, false
  if tree_visible_known then
    V = tree.visible
    T = V or tree.text ~= nil
  else
    V, T = true, true
  end
  if T and not V then ref_reset(pinfo) end
  local cols = pinfo.cols
  cols.protocol = "PROFIBUS"
  if sd == SC then
    -- (a DP-V1 call's acknowledgement: only in a capture with DP-V1 telegrams, C1_SEEN)
    local note = C1_SEEN and c1_sc_note(pinfo.number)
    cols.info = note and ("SC  short acknowledge  " .. note) or "SC  short acknowledge"
    if T then
      local t = M_add(tree, p_fdl, tvb(), "PROFIBUS SC: short acknowledge")
      if V or refd(tree, F.sd) then M_add(t, F.sd, tvb(0, 1)) end
      if V or refd(tree, F.service) then M_gen(M_add(t, F.service, "short acknowledge")) end
      if note then
        if V or refd(tree, F.msac_kind) then M_gen(M_add(t, F.msac_kind, "ack")) end
        if V or refd(tree, F.msac_note) then M_gen(M_add(t, F.msac_note, note)) end
      end
    end
    return len
  end
  if sd == SD4 then
    da, sa = o2 % 128, o3 % 128
    cols.src = NUM[sa]
    cols.dst = NUM[da]
    cols.info = "SD4  token " .. sa .. " -> " .. da
    if T then
      local t = M_add(tree, p_fdl, tvb(), "PROFIBUS SD4: token " .. sa .. " -> " .. da)
      if V or refd(tree, F.sd) then M_add(t, F.sd, tvb(0, 1)) end
      if V or refd(tree, F.da) then M_add(t, F.da, tvb(1, 1)) end
      if V or refd(tree, F.sa) then M_add(t, F.sa, tvb(2, 1)) end
      if V or refd(tree, F.service) then M_gen(M_add(t, F.service, "token")) end
    end
    return len
  end
  local is_request = fc % 128 >= 64                  -- bit 6
  local du_off, du_len = body_off + 3, body_len - 3
  local service, station, direction
  if is_request and fc % 16 == 9 then
    service = "FDL status"
  elseif not is_request and fc % 16 == 0 and du_len == 0 then
    service = "FDL status reply"
  elseif is_request then
    service = "Data_Exchange"
    if du_len > 0 then station, direction = da, "request" end
  else
    service = "Data_Exchange reply"
    if du_len > 0 then station, direction = sa, "response" end
  end
  -- the area's layout and (without a shown tree) its summary; with a shown tree the summary comes
  -- with the items
  local summary, plan
  if station then
    local ok, _
    if V then
      plan, _, ok = area_plan(station, direction, du_len)
    else
      summary, plan, ok = area_summary(tvb, s, du_off, du_len, station, direction)
    end
    if not ok then return nil end              -- the length does not match the layout: the full path warns
  end
  local fcw = fc_words_cached(fc)
  cols.src = NUM[sa]
  cols.dst = NUM[da]
  local info = SD_NAMES[sd] .. "  " .. sa .. " -> " .. da .. "  " .. service .. "  " .. fcw
  if not V then
    if summary and summary ~= "" then info = info .. "  " .. summary end
    cols.info = info
    if not T then return len end
  end

  local t = M_add(tree, p_fdl, tvb(), "PROFIBUS " .. SD_NAMES[sd] .. " " .. sa .. " -> " .. da .. ": " .. service)
  if V or refd(tree, F.sd) then M_add(t, F.sd, tvb(0, 1)) end
  if sd == SD2 then
    if V or refd(tree, F.le) then M_add(t, F.le, tvb(1, 1)) end
    if V or refd(tree, F.ler) then M_add(t, F.ler, tvb(2, 1)) end
  end
  local r = tvb(body_off, 1)
  if V then
    M_add(M_add(t, F.da, r), F.da_ext, r)
    r = tvb(body_off + 1, 1)
    M_add(M_add(t, F.sa, r), F.sa_ext, r)
    r = tvb(body_off + 2, 1)
    local fct = M_add(t, F.fc, r, fc, FC_LABEL[fc] or fc_label(fc))
    M_add(fct, F.fc_req, r)
    if is_request then
      M_add(fct, F.fc_fcb, r)
      M_add(fct, F.fc_fcv, r)
      M_add(fct, F.fc_fn, r)
    else
      M_add(fct, F.fc_type, r)
      M_add(fct, F.fc_st, r)
    end
    M_add(t, F.fc_text, r, fcw)
  else
    if refd(tree, F.da) then M_add(t, F.da, r) end
    if refd(tree, F.da_ext) then M_add(t, F.da_ext, r) end
    r = tvb(body_off + 1, 1)
    if refd(tree, F.sa) then M_add(t, F.sa, r) end
    if refd(tree, F.sa_ext) then M_add(t, F.sa_ext, r) end
    r = tvb(body_off + 2, 1)
    if refd(tree, F.fc) then M_add(t, F.fc, r) end
    if refd(tree, F.fc_req) then M_add(t, F.fc_req, r) end
    if is_request then
      if refd(tree, F.fc_fcb) then M_add(t, F.fc_fcb, r) end
      if refd(tree, F.fc_fcv) then M_add(t, F.fc_fcv, r) end
      if refd(tree, F.fc_fn) then M_add(t, F.fc_fn, r) end
    else
      if refd(tree, F.fc_type) then M_add(t, F.fc_type, r) end
      if refd(tree, F.fc_st) then M_add(t, F.fc_st, r) end
    end
    if refd(tree, F.fc_text) then M_add(t, F.fc_text, r, fcw) end
  end
  local rdu = du_len > 0 and tvb(du_off, du_len)
  if rdu and (V or refd(tree, F.du)) then M_add(t, F.du, rdu) end
  r = tvb(fcs_at, 1)
  if V or refd(tree, F.fcs) then M_add(t, F.fcs, r, fcs, "FCS: 0x" .. HEX[fcs] .. " [correct]") end
  if V or refd(tree, F.fcs_status) then M_gen(M_add(t, F.fcs_status, r, "good")) end
  if V or refd(tree, F.ed) then M_add(t, F.ed, tvb(fcs_at + 1, 1)) end
  if V or refd(tree, F.service) then M_gen(M_add(t, F.service, service)) end
  if station then
    local field = direction == "request" and F.outputs or F.inputs
    if V or refd(tree, field) then M_add(t, field, rdu) end
    local pd = M_add(tree, p_pd, rdu)
    if V or refd(tree, P.station) then M_gen(M_add(pd, P.station, station)) end
    if V or refd(tree, P.direction) then M_gen(M_add(pd, P.direction, DIR_TEXT[direction])) end
    if plan then
      if V or refd(tree, P.layout) then M_gen(M_add(pd, P.layout, plan.name)) end
      local notes = plan_items(plan, tvb, tree, pd, s, du_off, du_len, V)
      if V then summary = notes end
      M_set_text(pd, "PROFIdrive " .. plan.name .. ", station " .. station .. ": " .. summary)
    else
      M_set_text(pd, "PROFIdrive: no layout for station " .. station .. " (" .. du_len .. " octets)")
    end
  end
  if V then
    if summary and summary ~= "" then info = info .. "  " .. summary end
    cols.info = info
  end
  return len
end

-- the full path: every telegram, every check
local function dissect_full(tvb, pinfo, tree, len)
  pinfo.cols.protocol:set("PROFIBUS")
  local sd = tvb(0, 1):uint()
  local t = tree:add(p_fdl, tvb())
  t:add(F.sd, tvb(0, 1))
  if sd == SC then
    t:add(F.service, "short acknowledge"):set_generated()
    local note = C1_SEEN and c1_sc_note(pinfo.number)
    if note then
      t:add(F.msac_kind, "ack"):set_generated()
      t:add(F.msac_note, note):set_generated()
    end
    pinfo.cols.info:set("SC  short acknowledge" .. (note and ("  " .. note) or ""))
    t:set_text("PROFIBUS SC: short acknowledge")
    return len
  end
  if sd == SD4 then
    if len < 3 then t:add_proto_expert_info(E.malformed, "token telegram is 3 octets") return len end
    t:add(F.da, tvb(1, 1))
    t:add(F.sa, tvb(2, 1))
    t:add(F.service, "token"):set_generated()
    local da, sa = band(tvb(1, 1):uint(), 0x7F), band(tvb(2, 1):uint(), 0x7F)
    pinfo.cols.src:set(tostring(sa))
    pinfo.cols.dst:set(tostring(da))
    pinfo.cols.info:set(string.format("SD4  token %d -> %d", sa, da))
    t:set_text(string.format("PROFIBUS SD4: token %d -> %d", sa, da))
    return len
  end
  local body_off, body_len
  if sd == SD1 then body_off, body_len = 1, 3
  elseif sd == SD3 then body_off, body_len = 1, 11
  elseif sd == SD2 then
    if len < 4 then t:add_proto_expert_info(E.malformed, "SD2 header truncated") return len end
    t:add(F.le, tvb(1, 1))
    t:add(F.ler, tvb(2, 1))
    body_off, body_len = 4, tvb(1, 1):uint()
    if tvb(2, 1):uint() ~= body_len or tvb(3, 1):uint() ~= SD2 or body_len < 3 then
      t:add_proto_expert_info(E.malformed, "LE/LEr/SD2 header inconsistent")
      return len
    end
  else
    t:add_proto_expert_info(E.malformed, string.format("0x%02X is no start delimiter", sd))
    pinfo.cols.info:set("garbage " .. hexs(tvb()))
    return len
  end
  if len < body_off + body_len + 2 then
    t:add_proto_expert_info(E.malformed, "telegram truncated")
    return len
  end
  local sum = octet_sum(tvb:raw(body_off, body_len), 1, body_len)
  local da_raw, sa_raw, fc = tvb(body_off, 1):uint(), tvb(body_off + 1, 1):uint(), tvb(body_off + 2, 1):uint()
  local da, sa = band(da_raw, 0x7F), band(sa_raw, 0x7F)
  local dt = t:add(F.da, tvb(body_off, 1))
  dt:add(F.da_ext, tvb(body_off, 1))
  local st = t:add(F.sa, tvb(body_off + 1, 1))
  st:add(F.sa_ext, tvb(body_off + 1, 1))
  local is_request = band(fc, 0x40) ~= 0
  local fct = t:add(F.fc, tvb(body_off + 2, 1))
  fct:append_text(": " .. fc_words(fc))
  fct:add(F.fc_req, tvb(body_off + 2, 1))
  if is_request then
    fct:add(F.fc_fcb, tvb(body_off + 2, 1))
    fct:add(F.fc_fcv, tvb(body_off + 2, 1))
    fct:add(F.fc_fn, tvb(body_off + 2, 1))
  else
    fct:add(F.fc_type, tvb(body_off + 2, 1))
    fct:add(F.fc_st, tvb(body_off + 2, 1))
  end
  t:add(F.fc_text, tvb(body_off + 2, 1), fc_words(fc))
  local du_off, du_len = body_off + 3, body_len - 3
  local dsap, ssap
  if band(da_raw, 0x80) ~= 0 and du_len >= 1 then
    dsap = band(tvb(du_off, 1):uint(), 0x3F)
    t:add(F.dsap, tvb(du_off, 1), dsap)
    du_off, du_len = du_off + 1, du_len - 1
  end
  if band(sa_raw, 0x80) ~= 0 and du_len >= 1 then
    ssap = band(tvb(du_off, 1):uint(), 0x3F)
    t:add(F.ssap, tvb(du_off, 1), ssap)
    du_off, du_len = du_off + 1, du_len - 1
  end
  if du_len > 0 then t:add(F.du, tvb(du_off, du_len)) end
  local fcs_at = body_off + body_len
  local fcs = tvb(fcs_at, 1):uint()
  local ft = t:add(F.fcs, tvb(fcs_at, 1))
  if fcs == sum then
    ft:append_text(" [correct]")
    t:add(F.fcs_status, tvb(fcs_at, 1), "good"):set_generated()
  else
    ft:append_text(string.format(" [incorrect, should be 0x%02X]", sum))
    t:add(F.fcs_status, tvb(fcs_at, 1), "bad"):set_generated()
    ft:add_proto_expert_info(E.fcs, string.format("FCS 0x%02X, the octets sum to 0x%02X", fcs, sum))
  end
  local et = t:add(F.ed, tvb(fcs_at + 1, 1))
  if tvb(fcs_at + 1, 1):uint() ~= ED then et:add_proto_expert_info(E.malformed, "end delimiter is not 0x16") end

  -- the DP service (the same rules as dp/capture.py Captured.describe)
  local service
  if is_request and band(fc, 0x0F) == 9 then
    service = "FDL status"
  elseif not is_request and dsap == nil and ssap == nil and band(fc, 0x0F) == 0 and du_len == 0 then
    service = "FDL status reply"
  else
    local sap = is_request and dsap or ssap
    local name
    if not is_request and dsap == nil and ssap == nil then name = "Data_Exchange"
    elseif sap == nil then name = "Data_Exchange"
    else name = SERVICE_NAMES[sap] or ("SAP " .. sap) end
    service = name .. (is_request and "" or " reply")
    if dsap ~= nil and ACYCLIC[sap] then
      service = acyclic_service(sap, is_request, du_len > 0 and tvb(du_off, 1):uint() or nil)
    end
  end
  t:add(F.service, service):set_generated()

  local sapnote = dsap and string.format(" [%d->%d]", ssap or 0, dsap) or ""
  pinfo.cols.src:set(tostring(sa))
  pinfo.cols.dst:set(tostring(da))
  local summary = nil
  local sap = is_request and dsap or ssap
  if du_len >= 0 then
    if is_request and dsap == SAP.SET_PRM then summary = dissect_set_prm(tvb, t, du_off, du_len)
    elseif is_request and dsap == SAP.CHK_CFG then summary = dissect_cfg(tvb, t, du_off, du_len)
    elseif not is_request and ssap == SAP.GET_CFG then summary = dissect_cfg(tvb, t, du_off, du_len)
    elseif not is_request and ssap == SAP.SLAVE_DIAG then summary = dissect_diag(tvb, t, du_off, du_len)
    elseif is_request and dsap == SAP.GLOBAL_CONTROL then summary = dissect_gc(tvb, t, du_off, du_len)
    elseif is_request and dsap == SAP.SET_SLAVE_ADD then summary = dissect_ssa(tvb, t, du_off, du_len)
    elseif dsap ~= nil and ACYCLIC[sap] then
      summary = dissect_msac(tvb, pinfo, tree, t, du_off, du_len, sap, is_request, da, sa)
    elseif not is_request and ssap == SAP.RD_INP and du_len > 0 then
      t:add(F.inputs, tvb(du_off, du_len))
      summary = dissect_area(tvb(du_off, du_len):tvb(), pinfo, tree, sa, "response")
    elseif not is_request and ssap == SAP.RD_OUTP and du_len > 0 then
      t:add(F.outputs, tvb(du_off, du_len))
      summary = dissect_area(tvb(du_off, du_len):tvb(), pinfo, tree, sa, "request")
    elseif service == "Data_Exchange" and du_len > 0 then
      t:add(F.outputs, tvb(du_off, du_len))
      summary = dissect_area(tvb(du_off, du_len):tvb(), pinfo, tree, da, "request")
    elseif service == "Data_Exchange reply" and du_len > 0 then
      t:add(F.inputs, tvb(du_off, du_len))
      summary = dissect_area(tvb(du_off, du_len):tvb(), pinfo, tree, sa, "response")
    end
  end
  local info = string.format("%s  %d -> %d%s  %s  %s", SD_NAMES[sd], sa, da, sapnote, service, fc_words(fc))
  if summary and summary ~= "" then info = info .. "  " .. summary end
  if fcs ~= sum then info = info .. "  [FCS bad]" end
  pinfo.cols.info:set(info)
  t:set_text(string.format("PROFIBUS %s %d -> %d: %s", SD_NAMES[sd], sa, da, service))
  return len
end

function p_fdl.dissector(tvb, pinfo, tree)
  local len = tvb:len()
  if len < 1 then return 0 end
  return dissect_fast(tvb, pinfo, tree, len) or dissect_full(tvb, pinfo, tree, len)
end

-- DLT_USER0 (link type 147), as pdrive writes pcap files (wtap_encaps in Wireshark >= 3.x; wtap before)
local encaps = wtap_encaps or wtap
DissectorTable.get("wtap_encap"):add(encaps.USER0, p_fdl)
