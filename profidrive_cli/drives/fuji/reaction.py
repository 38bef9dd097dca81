"""Fuji's reactions for the comm-loss test (FujiDrive.comm_loss_reaction / zero_data_reaction /
bus_run_refusal), read from the drive: o27/o28 + F08 (Table 9.1), H81 (light alarms), y98, OPC-PDP3
o32 (Table 10.1). Reads through the drive's own read_param only.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

from profidrive_cli.drives.base import ParamValue, Reaction
from profidrive_cli.drives.fuji.codes import comm_loss_action, comm_loss_text
from profidrive_cli.drives.fuji.config import FujiConfig

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import Profile


class FujiDriveLike(Protocol):
    """What these readers use of a drives.fuji.drive.FujiDrive (which imports this module)."""
    @property
    def fc(self) -> FujiConfig: ...
    @property
    def profile(self) -> Profile: ...
    @property
    def layout(self) -> str: ...
    def can_read(self, code: str) -> bool: ...
    def read_param(self, code: str) -> ParamValue: ...


def light_alarm(d: FujiDriveLike, settings: dict[str, Any]) -> list[str]:
    """H81 (light-alarm selection, FRENIC manual): er5 selected as a light alarm keeps the inverter
    running whatever o27 says (OPC-G1-PDP manual L2781-2784, OPC-PDP3 L6557-6559). Which bit stands
    for er5 is in the FRENIC manual, not in the card's: any bit set is said."""
    if not d.can_read("H81"):
        return []
    h81 = int(d.read_param("H81").raw)
    settings["H81"] = h81
    if h81 == 0:
        return []
    return [f"H81 = 0x{h81:04X}: some alarms are light alarms; if er5 is one of them the inverter keeps "
            f"running after a break whatever o27 says (card manual, chapter 9)"]


def comm_loss_reaction(d: FujiDriveLike) -> Reaction:
    fc = d.fc
    o27 = int(d.read_param(fc.comm_loss_param).raw)
    o28 = float(d.read_param(fc.comm_loss_timer).value)
    act = comm_loss_action(d.profile, o27)
    words = comm_loss_text(d.profile, o27, o28)
    settings: dict[str, float | None] = {fc.comm_loss_param: o27, fc.comm_loss_timer: o28}
    warnings = light_alarm(d, settings)
    if act.stop == "none":
        return Reaction(words + " -- the drive keeps running without a master", "none",
                        settings=settings, warnings=warnings)
    decel = None
    if act.stop == "ramp":
        decel = float(d.read_param(fc.comm_loss_decel).value)
        if decel == 0.0:             # 0 = the F03 time as the sim and the manual's ramps say
            decel = None
        settings[fc.comm_loss_decel] = decel
    stop = "ramp" if act.stop == "ramp" else ("trip" if act.trip else "coast")
    return Reaction(words, stop, delay_s=o28 if act.delayed else 0.0,
                    recover=act.recover and act.delayed, alarm=fc.comm_loss_alarm if act.trip else None,
                    decel_s=decel, settings=settings, warnings=warnings)


def bus_run_refusal(d: FujiDriveLike) -> str | None:
    """y98 must be 3 (run and frequency from PROFIBUS, the manual's recommendation); with y98 = 0
    the inverter does not even trip er5 (OPC-PDP3 manual L3783-3789)."""
    if not d.can_read("y98"):
        return None
    y98 = int(d.read_param("y98").raw)
    if y98 == 3:
        return None
    src = {0: "run and frequency commands come from the inverter",
           1: "the run command comes from the inverter (only the frequency from PROFIBUS)",
           2: "the frequency comes from the inverter (only the run command from PROFIBUS)"}
    er5 = ("; and with y98 = 0 the inverter does not trip er5 when the link is lost (card manual: "
           "'The er5 does not occur when y98 = 0')" if y98 == 0 else "")
    return (f"y98 = {y98}: {src.get(y98, 'not a PROFIBUS source')}, so "
            f"the test cannot run the drive at the speed it asks from the bus{er5}; set "
            f"y98 = 3 (run and frequency from PROFIBUS) and test again")


def zero_data_reaction(d: FujiDriveLike, head: str) -> Reaction:
    zd = d.fc.zero_data
    if not zd:
        return Reaction(head + "; control word bit 10 = 0: the card ignores the control word and keeps "
                        "the last command -- the drive keeps running", "none")
    code = zd.get("param", "o32")
    if not d.can_read(code):
        return Reaction(f"{head}; {code} decides (not readable on layout {d.layout}): 1 or 2 coast "
                        f"to a stop, 0 (factory) keeps running", "coast",
                        warnings=[f"{code} not read: with {code} = 0, the factory setting, the "
                                  f"inverter ignores all-zero data and keeps running"])
    v = int(d.read_param(code).raw)
    if v in (1, 2):                  # 2: the run command's CTW had bit 10 = 1
        how = "coast to a stop, state S1" + (" (the last control word had bit 10 = 1)" if v == 2 else "")
        return Reaction(f"{head}; {code} = {v}: {how}", "coast", settings={code: v})
    return Reaction(f"{head}; {code} = {v}: all-zero data ignored, the inverter keeps the current "
                    f"operation (card manual Table 10.1{'; values of 3 and above act as 0' if v else ''})"
                    " -- the drive keeps running", "none", settings={code: v})
