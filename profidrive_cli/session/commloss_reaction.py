"""The comm-loss test's expectations, read from the drive (session/commloss.py runs the test):

    read_reaction(sess) -> Reaction      silence mode: what the drive does when its master goes away
    clear_reaction(sess) -> Reaction     clear mode: what it does with all-zero outputs
    check_bus_control(sess)              DriveError when the bus cannot run the drive (Fuji y98)
    read_accel(sess) -> (s, code)        the acceleration time, for the wait until at speed

Family rules from the card manuals (see the profiles' decisions): Fuji o27/o28 + F08 (Table 9.1), H81
(light alarms), y98, OPC-PDP3 o32 (Table 10.1); Moeller P002 (+ P001 shown); Yaskawa F6-01 + C1-02 /
C1-09, b1-03; Toyo protection 18 (fixed), control word bit 10 and C-00.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from profidrive_cli import UsageError
from profidrive_cli.drives.base import DriveError

_ACCEL_CODES = {"fuji": "F07", "moeller": "F002", "yaskawa": "C1-01"}

_YASKAWA_F601 = {0: ("ramp", "C1-02", "ramp to stop with C1-02, then the BUS fault"),
                 1: ("coast", None, "coast to stop and trip BUS"),
                 2: ("ramp", "C1-09", "fast stop with C1-09, then the BUS fault"),
                 3: ("none", None, "alarm only: BUS is shown and the drive keeps running")}
#: Toyo PBUS66-Z manual L612-620 (C-00 factory 0) and Table 3.5 notes 1-2 (L2769-2773)
TOYO_C00_WARNING = ("C-00 (multi-function input source) cannot be read over the bus (Toyo publishes "
                    "no PNU); with C-00 = 0, the factory setting, OFF2 and OFF3 from the bus act as "
                    "a normal stop (manual Table 3.5 notes 1 and 2): a coast or quick stop pdrive "
                    "sends takes the deceleration time; set C-00 = 1 for the full control word")


@dataclass
class Reaction:
    """The drive's configured reaction to a lost master, read from the drive."""
    words: str                     # e.g. "o27 = 0: coast to a stop at once, then trip Er5"
    stop: str                      # "coast" | "ramp" | "trip" | "none"
    delay_s: float = 0.0           # configured delay after the watchdog
    recover: bool = False          # forgotten when the link returns within the delay
    alarm: str | None = None       # the fault the drive shows
    decel_s: float | None = None   # ramp time from max frequency to 0 (stop == "ramp")
    settings: dict = field(default_factory=dict)   # code -> value read from the drive
    warnings: list = field(default_factory=list)   # what may make the drive act otherwise

    def stop_s(self, hz: float, fmax_hz: float) -> float:
        if self.stop != "ramp" or not self.decel_s or fmax_hz <= 0:
            return 0.0
        return self.decel_s * min(1.0, abs(hz) / fmax_hz)

    @property
    def stop_known(self) -> bool:
        """False: a ramp stop whose time could not be read (the limit counts none)."""
        return self.stop != "ramp" or bool(self.decel_s)


# -- per family ------------------------------------------------------------------------------
def _read(sess, code: str):
    return sess.drive.read_param(code)


def _readable(sess, code: str) -> bool:
    p = sess.profile.param(code)
    return (p is not None and (p.pnu is not None or p.register is not None)
            and sess.drive.has_param_channel)


def read_reaction(sess) -> Reaction:
    """What the drive is set to do when its master goes away, read from the drive (family rules
    from the card manuals; see the profiles' decisions)."""
    fam = sess.profile.family
    d = sess.drive
    if fam != "toyo" and not d.has_param_channel:
        raise UsageError(f"station {sess.address}: layout {sess.layout} has no parameter channel, so "
                         f"the comm-loss setting cannot be read (choose a layout with one, e.g. --ppo 1)")
    try:
        if fam == "fuji":
            return _fuji_reaction(sess)
        if fam == "moeller":
            vals = d.comm_loss_setting()
            code = d.mc.comm_loss_param
            main = vals[code]
            shown = {k: int(v.raw) for k, v in vals.items()}
            others = ", ".join(f"{k} = {v}" for k, v in shown.items() if k != code)
            extra = f" ({others} shown as well: the card's slot decides which one applies)" if others else ""
            if int(main.raw) == 1:
                return Reaction(f"{code} = 1: keep running on the last command{extra}", "none",
                                settings=shown)
            return Reaction(f"{code} = {int(main.raw)}: trip {d.mc.comm_loss_alarm} (output off, "
                            f"the motor coasts){extra}", "trip", alarm=d.mc.comm_loss_alarm,
                            settings=shown)
        if fam == "yaskawa":
            return _yaskawa_reaction(sess)
        if fam == "toyo":
            return Reaction("protection 18 (COMM, communication timeout): trip, run commands forced "
                            "off (fixed: the manual names no setting)", "trip", alarm="COMM",
                            warnings=[TOYO_C00_WARNING])
    except (DriveError, KeyError, ValueError) as e:
        raise DriveError(f"station {sess.address}: cannot read the comm-loss setting: {e}") from None
    raise UsageError(f"station {sess.address}: the comm-loss test knows no comm-loss reaction for "
                     f"the {fam} family (profile {sess.profile.name})")


def _fuji_light_alarm(sess, settings: dict) -> list[str]:
    """H81 (light-alarm selection, FRENIC manual): er5 selected as a light alarm keeps the inverter
    running whatever o27 says (OPC-G1-PDP manual L2781-2784, OPC-PDP3 L6557-6559). Which bit stands
    for er5 is in the FRENIC manual, not in the card's: any bit set is said."""
    if not _readable(sess, "H81"):
        return []
    h81 = int(_read(sess, "H81").raw)
    settings["H81"] = h81
    if h81 == 0:
        return []
    return [f"H81 = 0x{h81:04X}: some alarms are light alarms; if er5 is one of them the inverter keeps "
            f"running after a break whatever o27 says (card manual, chapter 9)"]


def _fuji_reaction(sess) -> Reaction:
    from profidrive_cli.drives import fuji as fj
    d = sess.drive
    fc = d.fc if hasattr(d, "fc") else fj.fuji_config(sess.profile)
    o27 = int(_read(sess, fc.comm_loss_param).raw)
    o28 = float(_read(sess, fc.comm_loss_timer).value)
    act = fj.comm_loss_action(sess.profile, o27)
    words = fj.comm_loss_text(sess.profile, o27, o28)
    settings: dict[str, float | None] = {fc.comm_loss_param: o27, fc.comm_loss_timer: o28}
    warnings = _fuji_light_alarm(sess, settings)
    if act.stop == "none":
        return Reaction(words + " -- the drive keeps running without a master", "none",
                        settings=settings, warnings=warnings)
    decel = None
    if act.stop == "ramp":
        decel = float(_read(sess, fc.comm_loss_decel).value)
        if decel == 0.0:             # 0 = the F03 time as the sim and the manual's ramps say
            decel = None
        settings[fc.comm_loss_decel] = decel
    stop = "ramp" if act.stop == "ramp" else ("trip" if act.trip else "coast")
    return Reaction(words, stop, delay_s=o28 if act.delayed else 0.0,
                    recover=act.recover and act.delayed, alarm=fc.comm_loss_alarm if act.trip else None,
                    decel_s=decel, settings=settings, warnings=warnings)


def _yaskawa_reaction(sess) -> Reaction:
    if sess.profile.param("F6-01") is None:
        return Reaction("BUS fault (the profile has no F6-01: assumed coast)", "trip", alarm="BUS")
    f601 = int(_read(sess, "F6-01").raw)
    stop, ramp_code, words = _YASKAWA_F601.get(f601, ("coast", None, "outside 0..3: assumed coast"))
    settings: dict[str, float] = {"F6-01": f601}
    decel = None
    if ramp_code:
        decel = float(_read(sess, ramp_code).value)
        settings[ramp_code] = decel
    return Reaction(f"F6-01 = {f601}: {words}", "trip" if stop == "coast" else stop,
                    alarm=None if stop == "none" else "BUS", decel_s=decel, settings=settings)


def check_bus_control(sess) -> None:
    """Refuse (DriveError, before anything moves) a drive the bus cannot run. Fuji: y98 must be 3
    (run and frequency from PROFIBUS, the manual's recommendation); with y98 = 0 the inverter does
    not even trip er5 (OPC-PDP3 manual L3783-3789)."""
    if sess.profile.family != "fuji" or not _readable(sess, "y98"):
        return
    y98 = int(_read(sess, "y98").raw)
    if y98 == 3:
        return
    src = {0: "run and frequency commands come from the inverter",
           1: "the run command comes from the inverter (only the frequency from PROFIBUS)",
           2: "the frequency comes from the inverter (only the run command from PROFIBUS)"}
    er5 = ("; and with y98 = 0 the inverter does not trip er5 when the link is lost (card manual: "
           "'The er5 does not occur when y98 = 0')" if y98 == 0 else "")
    raise DriveError(f"station {sess.address}: y98 = {y98}: {src.get(y98, 'not a PROFIBUS source')}, so "
                     f"the test cannot run the drive at the speed it asks from the bus{er5}; set "
                     f"y98 = 3 (run and frequency from PROFIBUS) and test again")


def clear_reaction(sess) -> Reaction:
    """Clear mode: the outputs go to zero (control word 0, bit 10 = 0). Fuji OPC-PDP3: o32 decides
    (Table 10.1, L6562-6584); OPC-G1-PDP and Toyo (PROFIdrive mode): bit 10 = 0 keeps the last
    command; otherwise the drive stops by its normal stop (its deceleration time where it can be
    read; Yaskawa b1-03 = 1 coasts)."""
    fam = sess.profile.family
    d = sess.drive
    head = "Global_Control Clear_Data: the outputs go to zero (control word 0, no run command)"
    try:
        if fam == "fuji":
            return _fuji_clear(sess, head)
        if fam == "toyo" and sess.layout != "toyo":
            return Reaction(head + "; control word bit 10 = 0: the card ignores the master's command and "
                            "keeps the previous cycle's (manual Table 3.5) -- the drive keeps running",
                            "none", warnings=[TOYO_C00_WARNING])
        if fam == "yaskawa" and _readable(sess, "b1-03") and int(_read(sess, "b1-03").raw) == 1:
            return Reaction(head + "; b1-03 = 1: coast to stop", "coast", settings={"b1-03": 1})
    except DriveError as e:
        raise DriveError(f"station {sess.address}: cannot read the all-zero-data setting: {e}") from None
    from profidrive_cli.session.safestop import read_decel
    decel = read_decel(sess)
    extra = [] if decel or fam != "toyo" else [TOYO_C00_WARNING]
    return Reaction(head + "; the drive must stop by its normal stop" +
                    (f" (deceleration time {decel:g} s from max frequency)" if decel else
                     " (its deceleration time cannot be read: the limit counts no stop time)"),
                    "ramp", decel_s=decel, warnings=extra)


def _fuji_clear(sess, head: str) -> Reaction:
    from profidrive_cli.drives import fuji as fj
    d = sess.drive
    fc = d.fc if hasattr(d, "fc") else fj.fuji_config(sess.profile)
    zd = fc.zero_data
    if not zd:
        return Reaction(head + "; control word bit 10 = 0: the card ignores the control word and keeps "
                        "the last command -- the drive keeps running", "none")
    code = zd.get("param", "o32")
    if not _readable(sess, code):
        return Reaction(f"{head}; {code} decides (not readable on layout {sess.layout}): 1 or 2 coast "
                        f"to a stop, 0 (factory) keeps running", "coast",
                        warnings=[f"{code} not read: with {code} = 0, the factory setting, the "
                                  f"inverter ignores all-zero data and keeps running"])
    v = int(_read(sess, code).raw)
    if v in (1, 2):                  # 2: the run command's CTW had bit 10 = 1
        how = "coast to a stop, state S1" + (" (the last control word had bit 10 = 1)" if v == 2 else "")
        return Reaction(f"{head}; {code} = {v}: {how}", "coast", settings={code: v})
    return Reaction(f"{head}; {code} = {v}: all-zero data ignored, the inverter keeps the current "
                    f"operation (card manual Table 10.1{'; values of 3 and above act as 0' if v else ''})"
                    " -- the drive keeps running", "none", settings={code: v})


def read_accel(sess) -> tuple[float | None, str | None]:
    """(acceleration time from 0 to the max frequency, its code) where the drive says it."""
    d = sess.drive
    ramps = getattr(getattr(d, "cfg", None), "ramps", {}) or {}
    code = (ramps.get("accel") if isinstance(ramps, dict) else None) or \
        _ACCEL_CODES.get(sess.profile.family)
    if not code or not _readable(sess, code):
        return None, code
    try:
        return float(_read(sess, code).value), code
    except (DriveError, UsageError, ValueError, TypeError):
        return None, code
