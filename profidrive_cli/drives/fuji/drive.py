"""FujiDrive: the PROFIdrive core's Drive with the Fuji dialect (function-code addressing, the
error-104 busy retry, M16-M19 fault narrowing, y97 storage, o27/o30 summaries).

Subclasses drives/profidrive ProfidriveDrive through its hooks; the channel does the waiting.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING, Any

from profidrive_cli import UsageError
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.base import (CyclicChannel, DriveError, DriveStatus, FaultRecord, ParamError, ParamValue,
                                        Reaction)
from profidrive_cli.drives.fuji.codes import (alarm_by_mcode, alarm_candidates, comm_loss_text,
                                              parse_function_code, pcd_assignment_code, ppo_for_o30)
from profidrive_cli.drives.fuji import reaction
from profidrive_cli.drives.fuji.config import FUJI_STW_BITS, fuji_config

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import Profile

class FujiDrive(pd.ProfidriveDrive):
    family = "fuji"
    #: F07 acceleration time 1, F08 deceleration time 1 (when the profile's ramps name none)
    ramp_codes = {"accel": "F07", "decel": "F08"}
    comm_loss_words = "its o27/o28 setting (o27 = 3 or 13..15 ignores the loss: the motor keeps running)"

    @classmethod
    def audit_rules(cls, profile: Any) -> list[Any]:
        """The family's `pdrive audit` rules (drives/fuji/audit.py), each citing its manual line."""
        from profidrive_cli.drives.fuji.audit import audit_rules
        return audit_rules(profile)

    def __init__(self, channel: CyclicChannel, profile: Profile, layout: str | None = None):
        self.fc = fuji_config(profile)
        super().__init__(channel, profile, layout)
        #: remarks for the user from the last calls (e.g. "o30 takes effect after a power cycle")
        self.notes: list[str] = []

    def take_notes(self) -> list[str]:
        n = list(self.notes)
        self.notes.clear()
        return n

    def save_support(self) -> str:
        return "command" if self.fc.storage else "automatic"

    def _family_not_restored(self, p: Any) -> str:
        if p.code[:1].upper() == "S" and p.code[1:].isdigit():
            return "command data (S codes), not a setting"
        return super()._family_not_restored(p)

    # -- addressing ----------------------------------------------------------------------------
    def resolve_param(self, code: str) -> pd.ParamRef:
        return self._resolve_in(self.profile, self.cfg, code)

    @classmethod
    def resolve_for(cls, profile: Any, code: str) -> pd.ParamRef:
        return cls._resolve_in(profile, pd.config(profile), code)

    @staticmethod
    def _resolve_in(profile: Any, cfg: pd.ProfidriveConfig, code: str) -> pd.ParamRef:
        text = code.strip()
        fcode = parse_function_code(profile, text)
        if fcode is not None:
            canon, _, pnu, sub = fcode
            p = profile.param(canon)
            if p is not None:
                return pd.ParamRef(p.code, p.name, p.pnu, p.index or 0, False, p.size, p)
            return pd.ParamRef(canon, "", pnu, sub, False, 16, None)
        m = re.fullmatch(r"(?i)P(?:NU)?\s*(\d+)", text)   # "PNU918" / "P918" short forms
        if m and profile.param(f"PNU{int(m.group(1))}") is not None:
            text = f"PNU{int(m.group(1))}"
        return pd.resolve_code(profile, text, cfg)

    # -- PKW with the busy retry ---------------------------------------------------------------
    def request(self, frame: pd.PkwFrame, timeout: float | None = None) -> pd.PkwResult:
        """Run one request; error 104 (busy, a write still in progress) is retried until the timeout."""
        limit = timeout if timeout is not None else self.cfg.pkw_timeout
        end = self.channel.now() + max(limit, 6.0)
        while True:
            res = super().request(frame, timeout)
            if res.error != self.fc.busy_error or self.channel.now() > end:
                return res
            for _ in range(3):
                self.cycle()

    def write_refused_message(self, ref: pd.ParamRef, value: float | int, result: pd.PkwResult) -> str:
        if result.error == 1:
            return (f"{ref.label}: the card refused the write (error 1: {result.error_text}); either "
                    f"the code is read-only or PNU927 = 0 blocks parameter writes (write PNU927 = 1)")
        if result.error == 11:
            return (f"{ref.label} cannot be changed while the inverter runs or a run-command input is "
                    f"on (error 11); stop it first")
        if result.error == 101:
            return (f"{ref.label}: link priority error (error 101): another command source (y99, LE/LOC "
                    f"terminals) has priority")
        if result.error == self.fc.busy_error:
            return f"{ref.label}: the card stayed busy (error {result.error}); try again"
        return super().write_refused_message(ref, value, result)

    def _write(self, ref: pd.ParamRef, value: float | int) -> ParamValue:
        pv = super()._write(ref, value)
        if ref.param is not None and ref.param.extra.get("power_cycle"):
            self.notes.append(f"{ref.code} takes effect after the inverter is switched off and on")
        return pv

    supports_jog = False

    def jog_refusal(self) -> str:
        return self._no_jog_words(self.profile)

    @staticmethod
    def _no_jog_words(profile: Any) -> str:
        return (f"{profile.name}: CTW bits 8 and 9 are not used by this card; there is no jog "
                f"over PROFIBUS (use run with a low speed instead)")

    @classmethod
    def jog_refusal_for(cls, profile: Any, layout: str) -> str | None:
        return cls._no_jog_words(profile)

    def jog(self, on: bool = True, reverse: bool = False) -> None:
        raise DriveError(self.jog_refusal())

    def start_hint(self, status: DriveStatus) -> str:
        hint = ("the card takes CTW/MRV only with y98 = 3 (run and frequency from PROFIBUS), CTW bits "
                "4, 5, 6 and 10 = 1, and no higher-priority source (H30, y99, LE/LOC terminals)")
        if not status.flags.get(FUJI_STW_BITS[9], True):
            hint = "STW bit 9 (R/L) is 0: PROFIBUS is not the command source; " + hint
        return hint

    # -- faults --------------------------------------------------------------------------------
    def _mcode(self, param: str | None) -> int | None:
        if param is None or self.pkw is None:
            return None
        try:
            return int(self.read_param(param).raw)
        except DriveError:
            return None

    def fault_record(self, position: str, raw: int, mcode: int | None) -> FaultRecord:
        if raw == 0 and not mcode:
            return FaultRecord(position, 0, [], ["no alarm"])
        cands = alarm_candidates(self.profile, raw)
        exact = alarm_by_mcode(self.profile, mcode) if mcode else None
        if exact is not None and (not cands or exact in cands):
            return FaultRecord(position, raw, [exact.code], [exact.meaning])
        if not cands:
            return FaultRecord(position, raw, [f"?0x{raw:04X}"], [f"unknown malfunction code 0x{raw:04X}"])
        return FaultRecord(position, raw, [a.code for a in cands], [a.meaning for a in cands])

    def fault_history(self) -> list[FaultRecord]:
        """PNU947 (1, 9, 17, 25), each narrowed to one alarm by M16-M19 when they can be read."""
        out = []
        for pos, ind, mparam in self.fc.history:
            res = self.request(pd.read_request(self.fc.history_pnu, ind, array=True))
            if not res.ok:
                raise ParamError(f"fault memory PNU {self.fc.history_pnu}[{ind}]: {res.describe_error()}",
                                 res.error)
            rec = self.fault_record(pos, res.value & 0xFFFF, self._mcode(mparam))
            if not rec.empty:            # 0000 / 0: no alarm in the slot (OPC-G1-PDP Table 10.1)
                out.append(rec)
        return out

    def current_alarm(self) -> FaultRecord | None:
        if self.pkw is None:
            return None
        pos, ind, mparam = self.fc.history[0]
        try:
            raw = self.read_raw(self.fc.history_pnu, ind, array=True) & 0xFFFF
        except DriveError:
            return None
        return self.fault_record(pos, raw, self._mcode(mparam))

    def status(self) -> DriveStatus:
        self._ensure_fmax()
        st = self.cycle()
        if st.fault:
            rec = self.current_alarm()
            if rec is not None and rec.codes:
                st.fault_code = "/".join(rec.codes)
        return st

    # -- storage -------------------------------------------------------------------------------
    def save(self, timeout: float = 15.0) -> None:
        """OPC-PDP3: y97 = 2 copies the RAM data into EEPROM; y97 reads 1 when done (PDP3 manual
        *6: "change the setting value to 2 ... if the value has returned to 1, data saving is
        complete"). The drive's save mode is kept: y97 is read first and, when it was 0 (every
        write to EEPROM), written back to 0 after the save, so later changes still reach the EEPROM."""
        s = self.fc.storage
        if s is None:
            raise DriveError(f"{self.profile.name}: PKW writes go straight to the inverter's memory; "
                             f"there is no separate save (y97 is an OPC-PDP3 feature)")
        code = s["param"]
        found = int(self.read_param(code).raw)
        self.write_raw_code(code, s["save"])
        end = self.channel.now() + max(timeout, float(s.get("save_time_s", 5.0)) + 1.0)
        while True:
            if int(self.read_param(code).raw) == s["saved_reads"]:
                if found == s["eeprom"]:
                    self._restore_storage(code, found)
                return
            if self.channel.now() > end:
                raise DriveError(f"{code} did not return to {s['saved_reads']} within {timeout:g} s: "
                                 f"save not confirmed (do not switch off yet)")
            for _ in range(10):
                self.cycle()

    def _restore_storage(self, code: str, mode: int) -> None:
        """y97 back to the mode found before the save (0: EEPROM), checked by reading it back."""
        self.write_raw_code(code, mode)
        now = int(self.read_param(code).raw)
        if now != mode:
            raise DriveError(f"saved, but {code} reads {now} after writing {mode} back: later changes "
                             f"go to RAM only (write {code} = {mode})")

    def write_raw_code(self, code: str, raw: int) -> None:
        ref = self.resolve_param(code)
        res = self.request(pd.write_request(ref.pnu, raw, ref.subindex, ref.array))
        if not res.ok:
            raise ParamError(self.write_refused_message(ref, raw, res), res.error)

    def storage_mode(self) -> str:
        s = self.fc.storage
        if s is None:
            return "direct (every write is stored)"
        v = int(self.read_param(s["param"]).raw)
        return {s["eeprom"]: "EEPROM (non-volatile; limited write cycles)",
                s["ram"]: "RAM only (lost at power-off; save to keep)"}.get(v, f"{s['param']} = {v}")

    def set_storage(self, where: str) -> None:
        s = self.fc.storage
        if s is None:
            raise DriveError(f"{self.profile.name}: storage selection (y97) is an OPC-PDP3 feature")
        if where not in ("ram", "eeprom"):
            raise UsageError("storage must be ram or eeprom")
        self.write_raw_code(s["param"], s[where])

    # -- settings summaries --------------------------------------------------------------------
    def comm_loss_setting(self) -> str:
        fc = self.fc
        o27 = int(self.read_param(fc.comm_loss_param).raw)
        o28 = float(self.read_param(fc.comm_loss_timer).value)
        return comm_loss_text(self.profile, o27, o28)

    monitor_mapping = "read"          # o48..o51 (= PNU 916) take effect only after a power cycle

    def pzd_assignment_param(self, slot: int) -> str:
        return f"o{47 + slot}"

    def pzd_assigned_code(self, raw: int) -> str | None:
        return pcd_assignment_code(self.profile, raw)

    def comm_loss_summary(self) -> str | None:
        return self.comm_loss_setting()

    def comm_loss_reaction(self) -> Reaction | None:
        return reaction.comm_loss_reaction(self)

    def zero_data_reaction(self, head: str) -> Reaction | None:
        return reaction.zero_data_reaction(self, head)

    def bus_run_refusal(self) -> str | None:
        return reaction.bus_run_refusal(self)

    def ppo_setting(self) -> str:
        v = int(self.read_param(self.fc.ppo_param).raw)
        lay = ppo_for_o30(self.profile, v)
        return f"{self.fc.ppo_param} = {v}: {lay.upper() if lay else '?'}" + (
            "" if lay == self.layout else f" (the master uses {self.layout.upper()}: power-cycle "
                                          f"after changing {self.fc.ppo_param})")


def make_drive(channel: CyclicChannel, profile: Profile, layout: str | None = None) -> FujiDrive:
    fuji_config(profile)
    return FujiDrive(channel, profile, layout)
