"""session/safestop.py sans-IO, with a scripted drive on a fake clock: the escalation time rule,
the normal stop / coast escalation and its messages, the shutdown on every way out. Reached through
session/motion.py's Motion (a SafeStop) on a fake station, as DriveStation builds it.

Expected values are worked by hand from the documented rule (docs/commands.md "the safe stop",
tests/test_escalation.py): wait 1.5 x the deceleration time (scaled by the speed it ran at, at most
100 %) + 3 s, at least 5 s, at most 600 s; 30 s when the deceleration time is unknown; a coast stop
then gets 10 s. The comm-loss words are the manuals' (Fuji o27/o28, Moeller P002, Toyo protection 18).
Written for mutation testing (tools/mutation/run.py session/safestop.py).
"""

from types import SimpleNamespace

import pytest

import profidrive_cli.session.safestop as ss
from profidrive_cli import PdriveError, UsageError
from profidrive_cli.drives.base import Drive as BaseDrive
from profidrive_cli.drives.base import DriveError, DriveStatus, ParamValue
from profidrive_cli.link.base import LinkLost
from profidrive_cli.session.motion import Motion

DT = 0.25          # one cycle on the fake clock (exact in binary)


def status(state="operation", running=True, speed=50.0, fault=False, fault_code=None):
    return DriveStatus(state=state, running=running, fault=fault, flags={}, speed_percent=speed,
                       speed_hz=None, fault_code=fault_code)


RUNNING = status()
STOPPED = status("stopped", running=False, speed=0.0)


class Clock:
    def __init__(self):
        self.t = 100.0

    def now(self):
        return self.t


def codec_of(family):
    """The family's Drive class (the base Drive for a family without a codec here)."""
    from profidrive_cli.drives.fuji.drive import FujiDrive
    from profidrive_cli.drives.moeller import MoellerDrive
    from profidrive_cli.drives.toyo.drive import ToyoDrive
    from profidrive_cli.drives.yaskawa import YaskawaDrive
    return {"fuji": FujiDrive, "moeller": MoellerDrive, "toyo": ToyoDrive,
            "yaskawa": YaskawaDrive}.get(family, BaseDrive)


class Drive:
    """Scripted: `normal_after` / `coast_after` cycles after that stop command, it reports `rest`.
    The family hooks (ramp_param, comm_loss_words) are the family codec's own, run on it."""

    family = "fuji"

    def __init__(self, clock, normal_after=None, coast_after=None, rest=STOPPED, fault_status=None,
                 channel=True, decel=None, ramps=None, last=RUNNING):
        self.clock = clock
        self.normal_after, self.coast_after = normal_after, coast_after
        self.rest, self.fault_status = rest, fault_status
        self.has_param_channel = channel
        self.decel = decel
        self.cfg = SimpleNamespace(ramps=ramps) if ramps is not None else SimpleNamespace()
        self.last_status = last
        self.commands: list[tuple] = []
        self.reads: list[str] = []
        self.cycles = 0
        self._left = None
        self.fail_on: dict[str, Exception] = {}

    @property
    def ramp_codes(self):
        return codec_of(self.family).ramp_codes

    @property
    def comm_loss_words(self):
        return codec_of(self.family).comm_loss_words

    def ramp_param(self, role):
        # a codec's cfg.ramps is always a mapping (the profile's ramps); without one (no cfg, or
        # not a mapping) the card's own codes answer (the base Drive's rule)
        ramps = getattr(getattr(self, "cfg", None), "ramps", None)
        codec = codec_of(self.family) if isinstance(ramps, dict) else BaseDrive
        return codec.ramp_param(self, role)

    def speed_scale_hz(self):
        return None

    def on_motion(self, listener):
        self.listeners = [*getattr(self, "listeners", []), listener]

    def turn(self):
        """Something tells the drive to turn the motor (a codec's start / jog on)."""
        for listener in getattr(self, "listeners", []):
            listener()

    def last_seen(self):
        """The PROFIdrive codecs' own (drives/profidrive): their last_status."""
        from profidrive_cli.drives.profidrive import ProfidriveDrive
        return ProfidriveDrive.last_seen(self)

    def stop(self, how, wait=True):
        self.commands.append((how, wait))
        if how in self.fail_on:
            raise self.fail_on[how]
        self._left = self.normal_after if how == "normal" else self.coast_after

    def cycle(self):
        self.clock.t += DT
        self.cycles += 1
        if self._left is not None:
            if self._left <= 0:
                return self.rest
            self._left -= 1
        return RUNNING

    def status(self):
        if self.fault_status is None:
            raise DriveError("status not readable")
        return self.fault_status

    def read_param(self, code):
        self.reads.append(code)
        if isinstance(self.decel, Exception):
            raise self.decel
        return ParamValue(code, "deceleration time 1", 0, self.decel, "s")


class Profile:
    def __init__(self, family="fuji", codes=("F08", "F003", "C1-02", "X9")):
        self.family = family
        self.codes = set(codes)
        self.name = f"{family}-test"
        self.max_frequency_default = 50.0

    def param(self, code):
        return object() if code in self.codes else None


class Master:
    def __init__(self, reply_timeout=1.0):
        self.released: list[int] = []
        self.flushed = 0
        self.rt = reply_timeout
        self.asked: list[int] = []
        self.params = SimpleNamespace(reply_timeout=self._reply_timeout)
        self.link = SimpleNamespace(flush_input=self._flush)
        self.release_error = None

    def _reply_timeout(self, n):
        self.asked.append(n)
        return self.rt

    def _flush(self):
        self.flushed += 1

    def release(self, address):
        self.released.append(address)
        if self.release_error:
            raise self.release_error


class StationLines:
    """A fake station's message line and Drive (session.station.StationView's need_drive / warn /
    say): warnings and messages kept in lists."""

    def need_drive(self):
        return self.drive

    def warn(self, text):
        self.warnings.append(text)

    def say(self, text):
        self.messages.append(text)


class Session(StationLines):
    """The station Motion reads (motion.MotionStation), with its Motion as DriveStation has it.
    may_run: the drive was told to turn (Drive.on_motion, as a start or jog does). stop_result:
    None runs Motion's own stop; a StopReport / exception scripts it (the shutdown's tests)."""

    def __init__(self, drive=None, clock=None, family="fuji", decel_s=None, stop_timeout_s=None,
                 may_run=True, watchdog_ms=500.0):
        self.channel = clock or Clock()
        self.drive = drive
        self.profile = Profile(family)
        self.layout = "ppo1"
        self.stop_timeout_s = stop_timeout_s
        self.signals = SimpleNamespace(hurry=False)
        self.warnings: list[str] = []
        self.messages: list[str] = []
        self.master = Master()
        self.watchdog_ms = watchdog_ms
        self.link_lost = False
        self.address = 3
        self.on_sample = None
        self.t0, self.achieved_hz, self.cycles, self.counters = 0.0, 0.0, 0, {}
        self.stop_calls = 0
        self.stop_result = None
        self.motion = Motion(self)
        self.motion.decel_s = decel_s
        real_stop = self.motion.stop

        def stop(on_sample=None, timeout=None):
            self.stop_calls += 1
            if self.stop_result is None:
                return real_stop(on_sample, timeout)
            if isinstance(self.stop_result, BaseException):
                raise self.stop_result
            return self.stop_result
        self.motion.stop = stop
        if drive is not None:
            drive.family = family
            self.motion.watch(drive)
            if may_run:
                drive.turn()

    # what DriveStation delegates to its Motion
    final_status = property(lambda self: self.motion.final_status,
                            lambda self, v: setattr(self.motion, "final_status", v))
    stop_report = property(lambda self: self.motion.stop_report,
                           lambda self, v: setattr(self.motion, "stop_report", v))
    comm_loss_text = property(lambda self: self.motion.comm_loss_text,
                              lambda self, v: setattr(self.motion, "comm_loss_text", v))



# -- the escalation time ---------------------------------------------------------------------------

@pytest.mark.parametrize("decel,percent,expected", [
    (10.0, None, 18.0),          # 1.5 * 10 + 3
    (10.0, 100.0, 18.0),
    (10.0, 50.0, 10.5),          # 1.5 * 10 * 0.5 + 3
    (10.0, -50.0, 10.5),         # reverse: the magnitude counts
    (10.0, 150.0, 18.0),         # above 100 %: at most the full ramp
    (1.4, 100.0, 5.1),           # 1.5 * 1.4 + 3 = 5.1, just above the floor
    (1.0, 100.0, 5.0),           # 4.5 -> the 5 s floor
    (20.0, 0.0, 5.0),            # 3 s -> the floor
    (396.0, None, 597.0),        # just under the cap
    (398.0, None, 600.0),        # 600 exactly
    (400.0, None, 600.0),        # 603 -> the 600 s cap
])
def test_stop_timeout_rule(decel, percent, expected):
    s = Session(decel_s=decel)
    assert s.motion.stop_timeout(percent) == pytest.approx(expected)


def test_stop_timeout_unknown_deceleration_is_30_s():
    assert Session(decel_s=None).motion.stop_timeout() == 30.0
    assert Session(decel_s=None).motion.stop_timeout(50.0) == 30.0


def test_stop_timeout_given_by_the_user_wins():
    s = Session(decel_s=10.0, stop_timeout_s=2)
    assert s.motion.stop_timeout(100.0) == 2.0 and isinstance(s.motion.stop_timeout(), float)


def test_coast_timeout_and_default_constants():
    assert ss.COAST_TIMEOUT_S == 10.0 and ss.DEFAULT_STOP_TIMEOUT_S == 30.0


# -- reading the deceleration time and the comm-loss behaviour -------------------------------------

@pytest.mark.parametrize("family,code", [("fuji", "F08"), ("moeller", "F003"), ("yaskawa", "C1-02")])
def test_read_decel_uses_the_family_code(family, code):
    clock = Clock()
    s = Session(Drive(clock, decel=7.5), clock, family=family)
    v = ss.read_decel(s.drive, s.profile)
    assert v == 7.5 and isinstance(v, float) and s.drive.reads == [code]


def test_read_decel_prefers_the_profiles_ramp_code():
    clock = Clock()
    s = Session(Drive(clock, decel=2, ramps={"decel": "X9"}), clock, family="fuji")
    assert ss.read_decel(s.drive, s.profile) == 2.0 and s.drive.reads == ["X9"]


def test_read_decel_drive_without_cfg_or_with_odd_ramps_uses_the_family_code():
    clock = Clock()
    d = Drive(clock, decel=4)
    del d.cfg
    assert ss.read_decel(d, Profile("fuji")) == 4.0 and d.reads == ["F08"]
    d = Drive(clock, decel=4, ramps=["X9"])                          # not a mapping: ignored
    assert ss.read_decel(d, Profile("fuji")) == 4.0 and d.reads == ["F08"]


def test_read_decel_ramps_without_decel_falls_back_to_the_family_code():
    clock = Clock()
    s = Session(Drive(clock, decel=3, ramps={"accel": "F07"}), clock, family="fuji")
    assert ss.read_decel(s.drive, s.profile) == 3.0 and s.drive.reads == ["F08"]


def test_read_decel_none_without_channel_code_or_param():
    clock = Clock()
    s = Session(Drive(clock, decel=3, channel=False), clock)
    assert ss.read_decel(s.drive, s.profile) is None and s.drive.reads == []
    s = Session(Drive(clock, decel=3), clock, family="toyo")        # no deceleration code known
    assert ss.read_decel(s.drive, s.profile) is None and s.drive.reads == []
    s = Session(Drive(clock, decel=3), clock, family="fuji")
    s.profile.codes = set()                                          # the profile lacks F08
    assert ss.read_decel(s.drive, s.profile) is None and s.drive.reads == []


@pytest.mark.parametrize("err", [DriveError("no answer"), UsageError("bad"), "slow"])
def test_read_decel_unreadable_is_none(err):
    clock = Clock()
    s = Session(Drive(clock, decel=err if isinstance(err, Exception) else err), clock)
    assert ss.read_decel(s.drive, s.profile) is None                 # "slow": float() ValueError


def test_read_decel_none_value_is_none():
    clock = Clock()
    assert ss.read_decel(Drive(clock, decel=None), Profile()) is None   # float(None): TypeError


class CommDrive:
    """comm_loss_setting() scripted; comm_loss_summary() is the family codec's own (drives/fuji,
    drives/moeller; the base default for the others) run on it."""
    has_param_channel = True

    def __init__(self, value, family="fuji"):
        self.value = value
        self.family = family

    def comm_loss_setting(self):
        if isinstance(self.value, Exception):
            raise self.value
        return self.value

    def comm_loss_summary(self):
        return codec_of(self.family).comm_loss_summary(self)

    @property
    def comm_loss_words(self):
        return codec_of(self.family).comm_loss_words


@pytest.mark.parametrize("raw,words", [
    (1, "P002 = 1: the drive keeps running on the last command"),
    (0, "P002 = 0: the drive trips (E70) and coasts"),
    (2, "P002 = 2: the drive trips (E70) and coasts"),
])
def test_read_comm_loss_moeller_from_p002(raw, words):
    d = CommDrive({"P002": ParamValue("P002", "comm loss", raw, raw)}, "moeller")
    assert ss.read_comm_loss(d) == words


def test_read_comm_loss_fuji_reads_the_card():
    d = CommDrive("o27 = 0: trips at once", "fuji")
    assert ss.read_comm_loss(d) == "o27 = 0: trips at once"


@pytest.mark.parametrize("family,start", [
    ("fuji", "its o27/o28 setting"), ("moeller", "P002 (0 = trip E70 and coast"),
    ("toyo", "protection 18 (COMM)"), ("yaskawa", "a BUS fault"),
    ("other", "its communication-loss setting")])
def test_read_comm_loss_words_when_it_cannot_be_read(family, start):
    for err in (DriveError("x"), UsageError("y")):
        assert ss.read_comm_loss(CommDrive(err, family)).startswith(start)
    d = CommDrive("read", family)
    d.has_param_channel = False
    assert ss.read_comm_loss(d).startswith(start)


# -- the stop and its escalation -------------------------------------------------------------------

def test_normal_stop_reports_the_time_on_the_session_clock():
    clock = Clock()
    d = Drive(clock, normal_after=7)
    s = Session(d, clock, decel_s=10.0)
    r = s.motion.stop(None, None)
    assert d.commands == [("normal", False)]
    assert (r.how, r.stopped, r.message) == ("normal", True, "stopped")
    assert r.seconds == pytest.approx(8 * DT)          # 7 running cycles, the 8th reports stopped
    assert r.status is STOPPED and s.final_status is STOPPED and s.motion.may_run is False
    assert s.warnings == []


def test_stop_samples_go_to_on_sample():
    clock = Clock()
    d = Drive(clock, normal_after=2)
    s = Session(d, clock, decel_s=10.0)
    s.t0, s.achieved_hz, s.cycles, s.counters = clock.t, 4.0, 0, {}
    got = []
    r = s.motion.stop(got.append, None)
    assert r.how == "normal" and [smp.status for smp in got] == [RUNNING, RUNNING, STOPPED]
    assert got[-1].t == pytest.approx(3 * DT)


def test_coast_samples_go_to_on_sample_too():
    clock = Clock()
    d = Drive(clock, coast_after=2)
    s = Session(d, clock, decel_s=10.0)
    s.t0, s.achieved_hz, s.cycles, s.counters = clock.t, 4.0, 0, {}
    got = []
    r = s.motion.stop(got.append, 1.0)
    assert r.how == "coast"
    # normal: 5 cycles (the first past 1 s); coast: 2 running cycles and the stopped one
    assert len(got) == 5 + 3 and got[-1].status is STOPPED


def test_fault_during_stop_reads_the_fault_code():
    clock = Clock()
    tripped = status("fault", running=False, speed=0.0, fault=True)
    d = Drive(clock, normal_after=1, rest=tripped,
              fault_status=status("fault", running=False, speed=0.0, fault=True, fault_code="OC3"))
    s = Session(d, clock, decel_s=10.0)
    r = s.motion.stop(None, None)
    assert (r.how, r.stopped) == ("normal", True)
    assert r.message == "the drive is in fault (OC3): its output is off"
    assert r.status.fault_code == "OC3"


def test_fault_code_unreadable_keeps_the_fault():
    clock = Clock()
    tripped = status("fault", running=False, speed=0.0, fault=True)
    s = Session(Drive(clock, normal_after=0, rest=tripped), clock, decel_s=10.0)
    r = s.motion.stop(None, None)
    assert r.message == "the drive is in fault: its output is off" and r.status is tripped


def test_fault_with_a_code_is_not_read_again():
    clock = Clock()
    tripped = status("fault", running=False, speed=0.0, fault=True, fault_code="E70")
    d = Drive(clock, normal_after=0, rest=tripped, fault_status=status(fault_code="WRONG"))
    r = Session(d, clock, decel_s=10.0).motion.stop(None, None)
    assert r.message == "the drive is in fault (E70): its output is off"


def run_stuck(decel_s, last=RUNNING, coast_after=3, timeout=None, **kw):
    clock = Clock()
    d = Drive(clock, normal_after=None, coast_after=coast_after, last=last, **kw)
    s = Session(d, clock, decel_s=decel_s)
    r = s.motion.stop(None, timeout)
    return s, d, r


def test_stuck_drive_is_coasted_after_the_escalation_time():
    # 50 % of fmax, decel 10 s: 1.5 * 10 * 0.5 + 3 = 10.5 s, then 3 cycles of coasting
    s, d, r = run_stuck(10.0)
    assert d.commands == [("normal", False), ("coast", False)]
    assert s.warnings == ["not stopped after 10.5 s: coasting"]
    assert (r.how, r.stopped) == ("coast", True)
    assert r.message == "not stopped after 10.5 s; coasted"
    # the normal wait ends at the first cycle past 10.5 s (43 cycles = 10.75 s), the coast takes 4
    assert r.seconds == pytest.approx(43 * DT + 4 * DT)
    assert s.motion.may_run is False and r.status is STOPPED


def test_escalation_uses_the_last_status_speed():
    s, d, r = run_stuck(10.0, last=status(speed=100.0))
    assert s.warnings == ["not stopped after 18 s: coasting"]
    s, d, r = run_stuck(10.0, last=None)                # speed unknown: the full ramp
    assert s.warnings == ["not stopped after 18 s: coasting"]


def test_escalation_reads_drive_last_when_there_is_no_last_status():
    clock = Clock()
    d = Drive(clock, coast_after=0, last=None)
    d.last = status(speed=20.0)                         # 1.5 * 10 * 0.2 + 3 = 6 s
    from profidrive_cli.drives.yaskawa import YaskawaDrive
    d.last_seen = lambda: YaskawaDrive.last_seen(d)     # Yaskawa keeps it in `last`
    s = Session(d, clock, decel_s=10.0)
    s.motion.stop(None, None)
    assert s.warnings == ["not stopped after 6 s: coasting"]


def test_an_explicit_timeout_wins():
    s, d, r = run_stuck(10.0, timeout=2.0)
    assert s.warnings == ["not stopped after 2 s: coasting"]
    assert r.seconds == pytest.approx(9 * DT + 4 * DT)


def test_wait_stopped_gives_up_at_the_first_cycle_past_the_timeout():
    clock = Clock()
    d = Drive(clock)
    s = Session(d, clock)
    assert s.motion.wait_stopped(5.0, None) is None
    assert d.cycles == 21 and s.final_status is RUNNING     # 5.25 s > 5 s


def test_a_second_signal_hurries_to_the_coast():
    clock = Clock()
    d = Drive(clock, coast_after=1)
    s = Session(d, clock, decel_s=10.0)
    s.signals.hurry = True
    r = s.motion.stop(None, None)
    assert d.cycles == 1 + 2                             # one normal cycle, then the coast
    assert s.warnings == ["stop hurried by a second signal: coasting"]
    assert r.how == "coast" and r.message == "stop hurried by a second signal; coasted"
    assert s.signals.hurry is False                      # the coast wait is not hurried away


def test_a_failed_normal_stop_coasts():
    clock = Clock()
    d = Drive(clock, coast_after=0)
    d.fail_on["normal"] = DriveError("refused")
    s = Session(d, clock, decel_s=10.0)
    r = s.motion.stop(None, None)
    assert s.warnings == ["normal stop failed: refused: coasting"]
    assert (r.how, r.stopped, r.message) == ("coast", True, "normal stop failed: refused; coasted")


def test_coast_not_possible():
    clock = Clock()
    d = Drive(clock)
    d.fail_on["normal"] = DriveError("a")
    d.fail_on["coast"] = DriveError("b")
    s = Session(d, clock, decel_s=10.0)
    s.final_status = RUNNING
    r = s.motion.stop(None, None)
    assert (r.how, r.stopped) == ("failed", False)
    assert r.message == "normal stop failed: a; coast stop not possible: b"
    assert r.seconds == 0.0                              # both refused at once: no cycle passed
    assert r.status is RUNNING and s.motion.may_run is True


def test_coast_that_does_not_stop_either_fails_after_10_s():
    s, d, r = run_stuck(10.0, timeout=1.0, coast_after=None)
    assert (r.how, r.stopped) == ("failed", False)
    assert r.message == ("not stopped after 1 s; the drive does not report stopped after a coast "
                         "stop either")
    # normal: first cycle past 1 s (5 cycles); coast: first cycle past 10 s (41 cycles)
    assert r.seconds == pytest.approx(5 * DT + 41 * DT)
    assert r.status is RUNNING and s.motion.may_run is True


def test_stop_report_to_dict():
    r = ss.StopReport("coast", True, 12.34567, "m", STOPPED)
    assert r.to_dict() == {"how": "coast", "stopped": True, "seconds": 12.346, "message": "m",
                           "state": "stopped"}
    assert ss.StopReport("failed", False).to_dict() == {"how": "failed", "stopped": False,
                                                        "seconds": 0.0, "message": "", "state": None}


# -- shutdown on every way out ---------------------------------------------------------------------

def shut(exc=None, may_run=True, result=None, family="toyo"):
    clock = Clock()
    s = Session(Drive(clock), clock, family=family, may_run=may_run)
    s.stop_result = result
    hooks = []
    s.motion.after_stop = [hooks.append]
    s.motion.shutdown(exc)
    return s, hooks


def test_link_lost_words():
    s = Session(Drive(Clock()), family="toyo", watchdog_ms=1500)
    assert s.motion.link_lost_words(OSError("gone")) == (
        "link lost (gone): pdrive cannot send a stop. The station's DP watchdog (1500 ms) takes it "
        "out of data exchange within 1.5 s of the last telegram; the drive then stops by protection "
        "18 (COMM): the inverter trips and coasts")
    s.comm_loss_text = "P002 = 1: keeps running"
    assert s.motion.link_lost_words(OSError("x")).endswith("the drive then stops by P002 = 1: keeps running")
    s.comm_loss_text, s.drive = None, None                          # no family known
    assert s.motion.link_lost_words(OSError("x")).endswith("stops by its communication-loss setting")


def test_shutdown_after_a_lost_link_sends_nothing():
    s, hooks = shut(LinkLost("unplugged"))
    assert s.link_lost is True and s.stop_calls == 0 and s.master.released == []
    assert s.stop_report.how == "not sent (link lost)" and s.stop_report.stopped is False
    assert s.stop_report.seconds == 0.0
    assert s.messages == [s.stop_report.message]
    assert s.messages[0].startswith("link lost (unplugged): pdrive cannot send a stop.")
    assert hooks == [False]


def test_shutdown_link_lost_not_running_says_nothing():
    s, hooks = shut(LinkLost("unplugged"), may_run=False)
    assert s.stop_report is None and s.messages == [] and hooks == [False] and s.master.released == []


def test_shutdown_without_drive_or_address_does_nothing():
    s = Session(None)
    s.motion.shutdown(None)
    assert s.master.released == [] and s.messages == []
    clock = Clock()
    s = Session(Drive(clock), clock)
    s.address = None
    s.motion.shutdown(None)
    assert s.master.released == [] and s.stop_calls == 0


def test_shutdown_normal_stop_then_hooks_then_release():
    s, hooks = shut(result=ss.StopReport("normal", True, 2.04, "stopped", STOPPED))
    assert s.messages == ["stopped (normal stop, 2.0 s)"]
    assert hooks == [True] and s.master.released == [3] and s.master.flushed == 0


def test_shutdown_normal_stop_into_a_fault_says_the_fault():
    faulted = status("fault", running=False, speed=0.0, fault=True, fault_code="OC1")
    s, _ = shut(result=ss.StopReport("normal", True, 1.0, "the drive is in fault (OC1): its output is off",
                                     faulted))
    assert s.messages == ["the drive is in fault (OC1): its output is off"]


def test_shutdown_coast_and_failed_words():
    s, _ = shut(result=ss.StopReport("coast", True, 13.26, "not stopped after 10 s; coasted", STOPPED))
    assert s.messages == ["stopped by a coast stop after 13.3 s (not stopped after 10 s; coasted)"]
    s, hooks = shut(result=ss.StopReport("failed", False, 20.0, "no stop"))
    assert s.messages == ["could not confirm the stop: no stop"]
    assert hooks == [True] and s.master.released == [3]


def test_shutdown_link_lost_during_the_stop():
    s, hooks = shut(result=LinkLost("unplugged"))
    assert s.link_lost is True and s.stop_report.how == "not sent (link lost)"
    assert s.stop_report.message.startswith("link lost (unplugged): pdrive cannot send a stop.")
    assert s.stop_report.stopped is False and s.stop_report.seconds == 0.0
    assert s.messages == [s.stop_report.message] and hooks == [False] and s.master.released == []


def test_shutdown_stop_failed_still_releases():
    s, hooks = shut(result=PdriveError("busy"))
    assert s.stop_report.how == "failed" and s.stop_report.stopped is False
    assert s.stop_report.message == "stop failed: busy" and s.stop_report.seconds == 0.0
    assert s.messages == ["stop failed: busy; the station's watchdog (500 ms) ends data exchange "
                          "when pdrive lets go"]
    assert hooks == [True] and s.master.released == [3]


def test_shutdown_not_started_is_not_needed():
    clock = Clock()
    s = Session(Drive(clock), clock, may_run=False)
    s.final_status = STOPPED
    hooks = []
    s.motion.after_stop = [hooks.append]
    s.motion.shutdown(None)
    assert s.stop_calls == 0
    r = s.stop_report
    assert r.status is STOPPED
    assert (r.how, r.stopped, r.seconds, r.message) == ("not needed", True, 0.0,
                                                        "not started by this session")
    assert hooks == [True] and s.master.released == [3]


def test_shutdown_keeps_an_earlier_stop_report():
    clock = Clock()
    s = Session(Drive(clock), clock, may_run=False)
    earlier = ss.StopReport("normal", True, 1.0, "stopped", STOPPED)
    s.stop_report = earlier
    s.motion.shutdown(None)
    assert s.stop_report is earlier and s.master.released == [3]


def test_shutdown_release_error_is_swallowed():
    clock = Clock()
    s = Session(Drive(clock), clock, may_run=False)
    s.master.release_error = PdriveError("gone")
    s.motion.shutdown(None)
    assert s.master.released == [3]


def test_shutdown_after_an_exception_flushes_a_stale_reply(monkeypatch):
    slept = []
    monkeypatch.setattr(ss.time, "sleep", slept.append)
    clock = Clock()
    s = Session(Drive(clock), clock)
    s.stop_result = ss.StopReport("normal", True, 1.0, "stopped", STOPPED)
    s.master.rt = 0.02                     # a reply of 64 octets is over after 20 ms: wait that
    s.motion.shutdown(KeyboardInterrupt())
    assert slept == [0.02] and s.master.asked == [64] and s.master.flushed == 1
    assert s.master.released == [3]
    slept.clear()
    s = Session(Drive(clock), clock)
    s.stop_result = ss.StopReport("normal", True, 1.0, "stopped", STOPPED)
    s.master.rt = 1.0                      # but never more than 50 ms
    s.motion.shutdown(RuntimeError("x"))
    assert slept == [0.05] and s.master.flushed == 1


def test_shutdown_flush_error_does_not_stop_the_stop(monkeypatch):
    monkeypatch.setattr(ss.time, "sleep", lambda t: None)
    clock = Clock()
    s = Session(Drive(clock), clock)
    s.stop_result = ss.StopReport("normal", True, 1.0, "stopped", STOPPED)

    def boom():
        raise OSError("closed")
    s.master.link.flush_input = boom
    s.motion.shutdown(RuntimeError("x"))
    assert s.stop_calls == 1 and s.master.released == [3]


def test_a_session_without_after_stop_hooks():
    clock = Clock()
    s = Session(Drive(clock), clock, may_run=False)
    s.motion.after_stop = []
    s.motion.shutdown(None)
    assert s.master.released == [3] and s.messages == []


def test_after_stop_hook_errors_are_said_and_the_others_run():
    clock = Clock()
    s = Session(Drive(clock), clock, may_run=False)
    seen = []

    def bad(ok):
        raise RuntimeError("PZD map not restored")
    s.motion.after_stop = [bad, seen.append]
    s.motion.shutdown(None)
    assert s.messages == ["after the stop: PZD map not restored"] and seen == [True]
    assert s.master.released == [3]


# -- callbacks that fail during the stop (the stop goes on; the first error comes after the release) --

def test_a_failing_on_sample_does_not_stop_the_stop():
    clock = Clock()
    d = Drive(clock, normal_after=3)
    s = Session(d, clock, decel_s=10.0)
    calls = []

    def bad(sample):
        calls.append(sample.status)
        raise RuntimeError("view gone")
    r = s.motion.stop(bad, None)
    assert (r.how, r.stopped) == ("normal", True)          # 3 running cycles, the 4th stopped
    assert calls == [RUNNING]                              # not called again after it raised
    assert isinstance(s.motion.callback_error, RuntimeError)
    assert str(s.motion.callback_error) == "view gone"
    assert s.final_status is STOPPED


def test_wait_stopped_passes_on_sample_and_returns_the_status():
    clock = Clock()
    d = Drive(clock, normal_after=2)
    s = Session(d, clock)
    d.stop("normal", wait=False)
    got = []
    st = s.motion.wait_stopped(5.0, got.append)
    assert st is STOPPED
    assert [smp.status for smp in got] == [RUNNING, RUNNING, STOPPED]


def test_shutdown_raises_a_callback_error_after_the_release():
    clock = Clock()
    s = Session(Drive(clock, normal_after=1), clock, decel_s=10.0)

    def bad(sample):
        raise RuntimeError("view gone")
    s.on_sample = bad
    s.motion.stop = lambda on_sample=None, timeout=None: Motion.stop(s.motion, bad, timeout)
    with pytest.raises(RuntimeError, match="view gone"):
        s.motion.shutdown(None)
    assert s.master.released == [3]                       # released before it was raised
    assert s.motion.callback_error is None                # raised once, then forgotten


def test_shutdown_after_an_exception_keeps_that_one_first():
    clock = Clock()
    s = Session(Drive(clock, normal_after=1), clock, decel_s=10.0)
    err = RuntimeError("view gone")
    s.motion.callback_failed(err)
    s.motion.shutdown(KeyboardInterrupt())                 # the session's own exception goes on
    assert s.master.released == [3] and s.motion.callback_error is err


def test_a_message_hook_that_raises_is_kept_as_the_callback_error():
    clock = Clock()
    s = Session(Drive(clock), clock, may_run=False)
    boom = OSError("terminal gone")

    def say(text):
        raise boom
    s.say = say
    s.motion.after_stop = [lambda ok: (_ for _ in ()).throw(RuntimeError("hook"))]
    with pytest.raises(OSError):
        s.motion.shutdown(None)
    assert s.master.released == [3]


def test_link_lost_words_without_an_exception():
    # the link was found lost before and the session is closed without an exception: no "(None)"
    s = Session(Drive(Clock()), family="toyo", watchdog_ms=1500)
    assert s.motion.link_lost_words(None).startswith(
        "link lost: pdrive cannot send a stop. The station's DP watchdog (1500 ms) takes it")


def test_the_stop_facts_are_read_once_at_the_first_start():
    # a fresh Motion knows neither; read_stop_facts (start / jog) reads both, a second call nothing
    clock = Clock()
    s = Session(Drive(clock, channel=False), clock, family="toyo")
    assert s.motion.comm_loss_text is None and s.motion.decel_s is None
    s.motion.read_stop_facts()
    # Toyo protection 18 (toyo-vf66-pbus66z.md): fixed, the words need no parameter channel
    assert s.motion.comm_loss_text == "protection 18 (COMM): the inverter trips and coasts"
    s.motion.comm_loss_text = "kept"
    s.motion.read_stop_facts()
    assert s.motion.comm_loss_text == "kept"
