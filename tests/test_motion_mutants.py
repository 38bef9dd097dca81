"""session/motion.py's Motion sans-IO, on a fake station and a recording drive: who may turn the motor
(may_run), the maximum frequency that 100 % stands for (fmax: read, given, or the profile default,
with its words), percent for Hz, the reference bounds, the start order, poll / status / sample, jog
and torque runs. Written for mutation testing (tools/mutation/run.py session/motion.py).

Expected values come from the manuals' specs and the docs, or are worked by hand:
- 100 % of the speed word is the maximum frequency: Fuji F03 (../shared/spec/fuji-opc-g1-pdp.md
  L379 "Both are ratios of the maximum frequency **F03**"), Moeller A004 (moeller-de6-net-dp.md L382
  "0x4000 = +100 % of the maximum frequency A004"), Toyo A-00 (toyo-vf66-pbus66z.md L145 "20000 =
  maximum speed A-00"; the profile: "A-00 has no published PNU"), Yaskawa E1-04 (a register, no PNU).
- docs/config.md L113-117: where the drive's maximum frequency can be read it is always used, and an
  fmax that differs by more than 0.1 % is a warning naming both figures and where it came from:
  "fmax 1 Hz from /home/me/src/cloned-repo/pdrive.yaml:8 ignored: the drive says F03 = 60 Hz".
- docs/commands.md L62 "max frequency 60 Hz read from the drive (F03)"; L81 "max frequency 60 Hz the
  profile default (layout ppo3 has no parameter channel; F03 not read — give --fmax if the drive is
  set otherwise)".
- The profiles' default_hz: fuji-opc-g1-pdp 60 Hz, toyo-pbus66z 60 Hz, moeller-de6-net-dp 50 Hz.
"""

from dataclasses import replace
from types import SimpleNamespace

import pytest

import profidrive_cli.session.safestop as ss
from profidrive_cli import UsageError
from profidrive_cli.config import FileHz
from profidrive_cli.drives.base import DriveError, DriveStatus, ParamValue
from profidrive_cli.drives.profile import load_profile
from profidrive_cli.session.motion import Motion

from test_safestop_mutants import StationLines


def status(state="operation", running=True, speed=50.0, fault=False, fault_code=None):
    return DriveStatus(state=state, running=running, fault=fault, flags={}, speed_percent=speed,
                       speed_hz=None, fault_code=fault_code)


RUNNING = status()
STOPPED = status("stopped", running=False, speed=0.0)
READY = status("ready", running=False, speed=0.0)


class Clock:
    def __init__(self, t=100.0):
        self.t = t

    def now(self):
        return self.t


class FakeDrive:
    """Records every call in `calls` (in order); answers as scripted."""

    family = "fuji"
    comm_loss_words = "family words: the card's own comm-loss behaviour"
    fmax_unread = None          # Drive.fmax_unread: the max frequency was read (or never tried)

    def __init__(self, channel=True, max_hz=50.0, decel=6.5, comm=None, cycles=None, status_reply=None,
                 start_reply=RUNNING, supports_jog=True, jog_ref="A038", torque_why=None,
                 limit_why=None, notes=()):
        self.has_param_channel = channel
        self.max_hz = max_hz
        self.decel = decel
        self.comm = comm
        self.cycle_replies = list(cycles or [])
        self.status_reply = status_reply
        self.start_reply = start_reply
        self.supports_jog = supports_jog
        self.jog_ref = jog_ref
        self.torque_why, self.limit_why = torque_why, limit_why
        self.notes = list(notes)
        self.calls: list[tuple] = []
        self.listeners: list = []
        self.scale = None

    # -- what Motion asks --
    def on_motion(self, listener):
        self.listeners.append(listener)

    def turn(self):
        for listener in self.listeners:
            listener()

    def max_frequency(self):
        self.calls.append(("max_frequency",))
        if isinstance(self.max_hz, Exception):
            raise self.max_hz
        return self.max_hz

    def use_max_frequency(self, hz):
        self.calls.append(("use_max_frequency", hz))
        self.scale = hz

    def speed_scale_hz(self):
        return self.scale

    def ramp_param(self, role):
        return "F08" if role == "decel" else None

    def read_param(self, code):
        self.calls.append(("read_param", code))
        return ParamValue(code, "deceleration time 1" if code == "F08" else "jog", 0, self.decel, "s")

    def comm_loss_summary(self):
        self.calls.append(("comm_loss_summary",))
        return self.comm

    def set_speed(self, percent):
        self.calls.append(("set_speed", percent))

    def start(self, timeout=5.0):
        self.calls.append(("start", timeout))
        if isinstance(self.start_reply, Exception):
            raise self.start_reply
        return self.start_reply

    def cycle(self):
        self.calls.append(("cycle",))
        return self.cycle_replies.pop(0) if self.cycle_replies else RUNNING

    def status(self):
        self.calls.append(("status",))
        if isinstance(self.status_reply, Exception):
            raise self.status_reply
        return self.status_reply

    # jog
    def jog_refusal(self):
        return "toyo: this card's jog needs the Toyo frame"

    def jog_reference(self):
        return self.jog_ref

    def jog(self, on, reverse=False):
        self.calls.append(("jog", on, reverse))

    def cycles_until(self, predicate, timeout, what):
        self.calls.append(("cycles_until", timeout, what))
        st = self.cycle_replies.pop(0) if self.cycle_replies else RUNNING
        assert predicate(st)
        return st

    def last_seen(self):
        return None

    def start_hint(self, last):
        return None

    # torque
    def torque_support(self):
        return self.torque_why

    def torque_limit_support(self):
        return self.limit_why

    def torque_resolution(self):
        return 0.1                     # Yaskawa SI-P1: 0.1 % (yaskawa-profibus-dp.md §2.4)

    def torque_notes(self):
        return self.notes

    def set_torque(self, percent):
        self.calls.append(("set_torque", percent))

    def set_torque_limit(self, percent):
        self.calls.append(("set_torque_limit", percent))

    def names(self):
        return [c[0] for c in self.calls]


class Station(StationLines):
    """The station Motion reads (motion.MotionStation), with its Motion as DriveStation builds it."""

    def __init__(self, drive=None, profile="fuji-opc-g1-pdp", layout="ppo1", clock=None):
        self.drive = drive
        self.profile = load_profile(profile) if isinstance(profile, str) else profile
        self.layout = layout
        self.channel = clock or Clock()
        self.t0, self.achieved_hz, self.cycles, self.counters = 90.0, 37.5, 1234, {"retries": 2}
        self.warnings: list[str] = []
        self.messages: list[str] = []
        self.stop_timeout_s = None
        self.signals = SimpleNamespace(hurry=False)
        self.watchdog_ms = 500.0
        self.on_sample = None
        self.link_lost = False
        self.address = 3
        self.ident = None
        self.master = None
        self.motion = Motion(self)
        if drive is not None:
            self.motion.watch(drive)



def station(profile="fuji-opc-g1-pdp", layout="ppo1", **kw):
    return Station(FakeDrive(**kw), profile, layout)


# -- may it turn ---------------------------------------------------------------------------------

def test_may_run_is_false_until_something_commands_motion():
    s = station()
    assert s.motion.may_run is False


def test_a_command_given_to_the_drive_directly_sets_may_run():
    s = station()
    s.drive.turn()                                  # Drive.on_motion: a checklist step's start
    assert s.motion.may_run is True and len(s.drive.listeners) == 1


def test_confirm_stopped_clears_may_run():
    s = station()
    s.drive.turn()
    s.motion.confirm_stopped()
    assert s.motion.may_run is False


@pytest.fixture
def scripted_stop(monkeypatch):
    """SafeStop.stop (Motion's super) replaced: records its arguments, returns the scripted report."""
    seen = []

    def stop(self, on_sample=None, timeout=None):
        seen.append((on_sample, timeout))
        return seen_report[0]
    seen_report = [None]
    monkeypatch.setattr(ss.SafeStop, "stop", stop)
    return seen, seen_report


def test_a_confirmed_stop_clears_may_run_and_passes_its_arguments(scripted_stop):
    seen, report = scripted_stop
    s = station()
    s.drive.turn()
    report[0] = ss.StopReport("normal", True)
    cb = print
    r = s.motion.stop(cb, 12.5)
    assert r is report[0] and seen == [(cb, 12.5)]
    assert s.motion.may_run is False


def test_an_unconfirmed_stop_keeps_may_run(scripted_stop):
    seen, report = scripted_stop
    s = station()
    s.drive.turn()
    report[0] = ss.StopReport("failed", False)
    s.motion.stop()
    assert s.motion.may_run is True and seen == [(None, None)]


def test_the_real_stop_of_a_stopped_drive_clears_may_run():
    s = station(cycles=[STOPPED] * 5)
    s.drive.stop = lambda how, wait=True: s.drive.calls.append(("stop", how))
    s.drive.last_status = RUNNING
    s.drive.turn()
    r = s.motion.stop()
    assert r.stopped is True and s.motion.may_run is False


# -- fmax: read from the drive ---------------------------------------------------------------------

def test_fmax_read_from_the_drive():
    s = station(max_hz=50)                          # an int from the drive: a float all the same
    hz, src = s.motion.fmax()
    assert hz == 50.0 and type(hz) is float
    assert src == "read from the drive (F03)"       # docs/commands.md L62
    assert s.drive.names() == ["max_frequency"] and s.warnings == []
    assert s.motion.fmax_hz == 50.0 and type(s.motion.fmax_hz) is float


def test_fmax_the_drive_could_not_give_is_the_profile_default_said_so():
    # the codec fell back (Drive.fmax_unread: a DS47 read that timed out): never "read from the drive"
    s = station(max_hz=50)
    s.drive.fmax_unread = "PNU 3: no answer"
    hz, src = s.motion.fmax()
    assert hz == 60.0                                   # fuji-opc-pdp3.yaml: default_hz 60.0
    assert src.startswith("the profile default (F03 could not be read: PNU 3: no answer")
    assert "read from the drive" not in src and "max_frequency" not in s.drive.names()
    s = station(max_hz=50)
    s.drive.fmax_unread = "PNU 3: no answer"
    assert s.motion.fmax(40.0) == (40.0, "from --fmax")     # the user's value then holds


def test_fmax_read_over_a_register_only_parameter():
    # Yaskawa E1-04 has a register and no PNU (profiles/yaskawa-si-p1.yaml): readable
    s = station("yaskawa-si-p1", max_hz=60.0)
    assert s.motion.fmax() == (60.0, "read from the drive (E1-04)")


def test_fmax_read_moeller():
    s = station("moeller-de6-net-dp", max_hz=87.0)
    assert s.motion.fmax() == (87.0, "read from the drive (A004)")   # docs/commands.md L241


@pytest.mark.parametrize("override,warns", [
    (50.0, False),
    (50.04, False),        # |50.04 - 50| = 0.04 <= 0.1 % of 50.04 (0.05004): the same
    (49.96, False),        # 0.04 <= 0.1 % of 50 (0.05)
    (50.06, True),         # 0.06 > 0.1 % of 50.06 (0.05006)
    (49.94, True),         # 0.06 > 0.05
    (60.0, True),
])
def test_fmax_override_against_the_drive(override, warns):
    s = station(max_hz=50.0)
    assert s.motion.fmax(override) == (50.0, "read from the drive (F03)")
    expected = [f"--fmax {override:g} Hz ignored: the drive says F03 = 50 Hz"] if warns else []
    assert s.warnings == expected
    assert "use_max_frequency" not in s.drive.names()


def test_fmax_from_a_config_file_against_the_drive_names_its_line():
    # docs/config.md L116-117
    s = station(max_hz=60.0)
    assert s.motion.fmax(FileHz(1.0, "/home/me/src/cloned-repo/pdrive.yaml:8")) == \
        (60.0, "read from the drive (F03)")
    assert s.warnings == ["fmax 1 Hz from /home/me/src/cloned-repo/pdrive.yaml:8 ignored: "
                          "the drive says F03 = 60 Hz"]


def test_fmax_read_error_propagates():
    s = station(max_hz=DriveError("no answer"))
    with pytest.raises(DriveError, match="no answer"):
        s.motion.fmax()


# -- fmax: given -------------------------------------------------------------------------------------

def test_fmax_override_without_a_parameter_channel():
    s = station(channel=False)
    hz, src = s.motion.fmax(55)
    assert (hz, src) == (55.0, "from --fmax") and type(hz) is float
    assert s.drive.calls == [("use_max_frequency", 55.0)] and s.warnings == []
    assert type(s.drive.scale) is float


def test_fmax_override_from_a_config_file_without_a_parameter_channel():
    s = station(channel=False)
    hz, src = s.motion.fmax(FileHz(45.0, "pdrive.yaml:8"))
    assert (hz, src) == (45.0, "from pdrive.yaml:8") and type(hz) is float


def test_fmax_override_used_where_the_parameter_has_no_number():
    # Toyo A-00: no published PNU (profiles/toyo-pbus66z.yaml): the override is used, not read
    s = station("toyo-pbus66z", channel=True)
    assert s.motion.fmax(75.0) == (75.0, "from --fmax")
    assert s.drive.calls == [("use_max_frequency", 75.0)]


def test_a_small_positive_override_is_taken():
    s = station(channel=False)
    assert s.motion.fmax(0.5) == (0.5, "from --fmax")


@pytest.mark.parametrize("override,words", [
    (0, "--fmax 0: must be above 0 Hz"),
    (0.0, "--fmax 0: must be above 0 Hz"),
    (-5.0, "--fmax -5: must be above 0 Hz"),
    (FileHz(0.0, "pdrive.yaml:8"), "fmax 0 Hz from pdrive.yaml:8: must be above 0 Hz"),
])
def test_fmax_override_at_or_below_zero_is_refused(override, words):
    s = station(channel=False)
    with pytest.raises(UsageError) as e:
        s.motion.fmax(override)
    assert str(e.value) == words
    assert s.drive.calls == []


# -- fmax: the profile default ----------------------------------------------------------------------

def test_fmax_default_without_a_parameter_channel():
    s = station(channel=False, layout="ppo3")
    hz, src = s.motion.fmax()
    assert hz == 60.0 and type(hz) is float           # fuji-opc-g1-pdp default_hz 60.0
    assert src == ("the profile default (layout ppo3 has no parameter channel; F03 not read — "
                   "give --fmax if the drive is set otherwise)")    # docs/commands.md L81
    assert s.drive.calls == [("use_max_frequency", 60.0)]


def test_fmax_default_when_the_parameter_has_no_number():
    s = station("toyo-pbus66z", channel=True)
    assert s.motion.fmax() == (60.0, "the profile default (A-00 has no published parameter number; "
                                     "A-00 not read — give --fmax if the drive is set otherwise)")
    assert s.drive.calls == [("use_max_frequency", 60.0)]


def test_fmax_default_when_the_parameter_is_not_in_the_profile():
    prof = replace(load_profile("fuji-opc-g1-pdp"), max_frequency_param="F99")
    s = Station(FakeDrive(channel=True), prof)
    assert s.motion.fmax() == (60.0, "the profile default (F99 has no published parameter number; "
                                     "F99 not read — give --fmax if the drive is set otherwise)")
    assert "max_frequency" not in s.drive.names()


def test_fmax_default_when_the_profile_names_no_parameter():
    prof = replace(load_profile("moeller-de6-net-dp"), max_frequency_param=None)
    s = Station(FakeDrive(channel=True), prof)
    assert s.motion.fmax() == (50.0, "the profile default (the profile names no max-frequency "
                                     "parameter; max frequency not read — give --fmax if the drive "
                                     "is set otherwise)")
    assert s.drive.calls == [("use_max_frequency", 50.0)]


def test_fmax_default_is_a_float_from_an_int_default():
    prof = replace(load_profile("fuji-opc-g1-pdp"), max_frequency_default=60)
    s = Station(FakeDrive(channel=False), prof)
    hz, _ = s.motion.fmax()
    assert type(hz) is float and type(s.drive.scale) is float
    s2 = Station(FakeDrive(channel=False), prof)
    assert type(s2.motion.fmax_hz) is float and s2.motion.fmax_hz == 60.0


# -- fmax: kept per override -------------------------------------------------------------------------

def test_fmax_is_read_once_per_override():
    s = station(max_hz=50.0)
    first = s.motion.fmax()
    assert s.motion.fmax() is first                 # kept: no second read
    assert s.drive.names() == ["max_frequency"]
    s.motion.fmax(60.0)                             # another override: read again, warned
    s.motion.fmax(60.0)                             # the same again: kept, not warned twice
    assert s.drive.names() == ["max_frequency", "max_frequency"]
    assert s.warnings == ["--fmax 60 Hz ignored: the drive says F03 = 50 Hz"]
    s.motion.fmax()                                 # back to none: read again
    assert s.drive.names() == ["max_frequency"] * 3


def test_fmax_hz_before_and_after_fmax():
    s = station(max_hz=50.0)
    assert s.motion.fmax_hz == 60.0 and type(s.motion.fmax_hz) is float   # the profile default
    assert s.drive.calls == []                                            # no bus traffic
    s.motion.fmax()
    assert s.motion.fmax_hz == 50.0


# -- percent for Hz, the reference -----------------------------------------------------------------

@pytest.mark.parametrize("hz,pct", [(25.0, 50.0), (-25.0, -50.0), (50.0, 100.0), (-50.0, -100.0),
                                    (0.0, 0.0), (12.5, 25.0)])
def test_percent_for_hz(hz, pct):
    s = station(max_hz=50.0)
    assert s.motion.percent_for_hz(hz) == pytest.approx(pct, abs=1e-12)


def test_percent_for_hz_within_rounding_of_100_is_taken():
    s = station(max_hz=50.0)
    assert s.motion.percent_for_hz(50.0 * (1 + 1e-12)) == pytest.approx(100.0)


def test_percent_for_hz_at_the_rounding_allowance_exactly_is_taken():
    # 100 x 50.0000000005 / 50 is 100 + 1e-9 exactly in binary (checked by hand with float
    # arithmetic): at the allowance, not above it
    s = station(max_hz=50.0)
    assert 100.0 * 50.0000000005 / 50.0 == 100.0 + 1e-9
    assert s.motion.percent_for_hz(50.0000000005) == 100.0 + 1e-9
    assert s.motion.percent_for_hz(-50.0000000005) == -(100.0 + 1e-9)


@pytest.mark.parametrize("hz", [50.3, -50.3, 51.0, -51.0, 100.0])
def test_percent_for_hz_above_fmax_is_refused(hz):
    s = station(max_hz=50.0)
    with pytest.raises(UsageError) as e:
        s.motion.percent_for_hz(hz)
    assert str(e.value) == (f"{hz:g} Hz is above the maximum frequency 50 Hz "
                            f"(read from the drive (F03))")


def test_percent_for_hz_with_an_override():
    s = station(channel=False)
    assert s.motion.percent_for_hz(30.0, 40.0) == pytest.approx(75.0)
    assert s.drive.calls == [("use_max_frequency", 40.0)]
    with pytest.raises(UsageError, match=r"^41 Hz is above the maximum frequency 40 Hz \(from --fmax\)$"):
        s.motion.percent_for_hz(41.0, 40.0)


@pytest.mark.parametrize("pct", [-100.0, -99.5, 0.0, 42.0, 100.0])
def test_set_reference_inside_the_bounds(pct):
    s = station()
    s.motion.set_reference(pct)
    assert s.drive.calls == [("set_speed", pct)]


@pytest.mark.parametrize("pct", [-100.5, 100.5, 101.0, -101.0, 150.0])
def test_set_reference_outside_the_bounds(pct):
    s = station()
    with pytest.raises(UsageError) as e:
        s.motion.set_reference(pct)
    assert str(e.value) == f"speed {pct:g} % is outside -100..100 % of the maximum frequency"
    assert s.drive.calls == []


# -- start ---------------------------------------------------------------------------------------

def test_start_reads_the_stop_facts_then_sets_the_reference_then_starts():
    s = station(comm="o27 = 0: trips Er5 at once")
    smp = s.motion.start(40.0, timeout=7.5)
    assert s.drive.calls == [("read_param", "F08"), ("comm_loss_summary",), ("set_speed", 40.0),
                             ("start", 7.5)]
    assert s.motion.decel_s == 6.5 and s.motion.comm_loss_text == "o27 = 0: trips Er5 at once"
    assert s.motion.may_run is True
    assert smp.status is RUNNING and s.motion.final_status is RUNNING


def test_start_without_a_reference_and_the_default_timeout():
    s = station()
    s.motion.start()
    assert s.drive.calls == [("read_param", "F08"), ("comm_loss_summary",), ("start", 5.0)]
    assert s.motion.comm_loss_text == FakeDrive.comm_loss_words


def test_start_reads_the_stop_facts_once():
    s = station(comm="read words")
    s.motion.start(10.0)
    s.motion.start(20.0)
    assert s.drive.names().count("read_param") == 1
    assert s.drive.names().count("comm_loss_summary") == 1
    assert s.drive.names()[-2:] == ["set_speed", "start"]


def test_stop_facts_already_known_are_not_read():
    s = station()
    s.motion.decel_s = 3.0
    s.motion.comm_loss_text = "known"
    s.motion.read_stop_facts()
    assert s.drive.calls == [] and s.motion.decel_s == 3.0 and s.motion.comm_loss_text == "known"


def test_start_with_a_reference_out_of_bounds_sends_nothing_and_may_not_run():
    s = station()
    with pytest.raises(UsageError):
        s.motion.start(150.0)
    assert "start" not in s.drive.names() and "set_speed" not in s.drive.names()
    assert s.motion.may_run is False


def test_a_start_that_fails_still_may_have_turned_the_motor():
    s = station(start_reply=DriveError("the drive did not reach operation"))
    with pytest.raises(DriveError):
        s.motion.start(30.0)
    assert s.motion.may_run is True


# -- poll, status, sample -------------------------------------------------------------------------

def test_poll_without_a_fault_is_one_cycle():
    s = station(cycles=[RUNNING])
    assert s.motion.poll().status is RUNNING
    assert s.drive.calls == [("cycle",)]


def test_poll_reads_the_fault_code_when_the_cycle_has_none():
    tripped = status("fault", running=False, fault=True, fault_code=None)
    named = status("fault", running=False, fault=True, fault_code="OC1")
    s = station(cycles=[tripped], status_reply=named)
    smp = s.motion.poll()
    assert smp.status is named and s.motion.final_status is named
    assert s.drive.calls == [("cycle",), ("status",)]


def test_poll_keeps_a_fault_that_has_its_code():
    named = status("fault", running=False, fault=True, fault_code="OC1")
    s = station(cycles=[named], status_reply=STOPPED)
    assert s.motion.poll().status is named and s.drive.calls == [("cycle",)]


def test_poll_with_no_fault_and_no_code_reads_nothing_more():
    st = status(fault=False, fault_code=None)
    s = station(cycles=[st], status_reply=STOPPED)
    assert s.motion.poll().status is st and s.drive.calls == [("cycle",)]


def test_status_with_a_parameter_channel_reads_fmax():
    s = station(max_hz=50.0, status_reply=READY)
    smp = s.motion.status()
    assert s.drive.calls == [("max_frequency",), ("status",)]
    assert smp.status is READY and smp.fmax_hz == 50.0


def test_status_without_a_parameter_channel_does_not_settle_fmax():
    s = station(channel=False, status_reply=READY)
    smp = s.motion.status()
    assert s.drive.calls == [("status",)]
    assert smp.fmax_hz == 60.0                      # the profile default, nothing settled


def test_status_survives_an_unreadable_fmax():
    s = station(max_hz=DriveError("no answer"), status_reply=READY)
    smp = s.motion.status()
    assert smp.status is READY and smp.fmax_hz == 60.0


def test_sample_fields():
    s = station(max_hz=50.0)
    s.motion.fmax()
    s.channel.t = 102.5
    smp = s.motion.sample(RUNNING)
    assert smp.t == pytest.approx(12.5)             # 102.5 - t0 90.0
    assert (smp.status, smp.fmax_hz, smp.cycle_hz, smp.cycles, smp.counters) == \
        (RUNNING, 50.0, 37.5, 1234, {"retries": 2})
    assert type(smp.fmax_hz) is float and s.motion.final_status is RUNNING


def test_sample_uses_the_codecs_scale_before_fmax_is_settled():
    s = station()
    s.drive.scale = 45.0
    assert s.motion.sample(RUNNING).fmax_hz == 45.0
    s.drive.scale = None
    assert s.motion.sample(RUNNING).fmax_hz == 60.0


def test_sample_without_a_drive_uses_the_profile_default():
    s = Station(None, "moeller-de6-net-dp")
    smp = s.motion.sample(STOPPED)
    assert smp.fmax_hz == 50.0 and type(smp.fmax_hz) is float


def test_sample_from_an_int_scale_is_a_float():
    s = station()
    s.drive.scale = 45
    assert type(s.motion.sample(RUNNING).fmax_hz) is float


# -- jog -------------------------------------------------------------------------------------------

def test_jog_refusal():
    assert station().motion.jog_refusal() is None
    s = station(supports_jog=False)
    assert s.motion.jog_refusal() == "toyo: this card's jog needs the Toyo frame"


def test_jog_speed():
    s = station(decel=5.0)
    v = s.motion.jog_speed()
    assert v.code == "A038" and v.value == 5.0 and s.drive.calls == [("read_param", "A038")]
    assert station(jog_ref=None).motion.jog_speed() is None


def test_jog_refused_sends_nothing_and_may_not_run():
    s = station(supports_jog=False)
    with pytest.raises(UsageError, match="^toyo: this card's jog needs the Toyo frame$"):
        s.motion.jog()
    assert s.drive.calls == [] and s.motion.may_run is False


def test_jog_in_fault_reads_the_stop_facts_and_may_not_run():
    s = station(cycles=[status("fault", running=False, fault=True, fault_code="OC1")])
    with pytest.raises(DriveError, match="reset it first"):
        s.motion.jog()
    assert s.drive.calls == [("read_param", "F08"), ("comm_loss_summary",), ("cycle",)]
    assert s.motion.may_run is False


def test_jog_on():
    s = station(cycles=[READY, RUNNING])
    smp = s.motion.jog()
    assert s.drive.calls == [("read_param", "F08"), ("comm_loss_summary",), ("cycle",),
                             ("jog", True, False), ("cycles_until", 5.0, "the jog to start")]
    assert s.motion.may_run is True and smp.status is RUNNING


def test_jog_reverse_with_a_timeout():
    s = station(cycles=[READY, RUNNING])
    s.motion.jog(reverse=True, timeout=2.5)
    assert ("jog", True, True) in s.drive.calls and ("cycles_until", 2.5, "the jog to start") in s.drive.calls


def test_release_jog():
    s = station(cycles=[STOPPED])
    smp = s.motion.release_jog()
    assert s.drive.calls == [("jog", False, False), ("cycle",)]
    assert smp.status is STOPPED and s.motion.final_status is STOPPED


# -- torque ----------------------------------------------------------------------------------------

def test_check_torque():
    s = station()
    s.motion.check_torque(50.0)                     # a multiple of 0.1 %: taken
    s.motion.check_torque(50.0, 120.0)
    s.motion.check_torque(None, 120.0)
    with pytest.raises(UsageError, match="^--torque-limit 0 %: must be above 0 %$"):
        s.motion.check_torque(None, 0.0)
    s = station(torque_why="fuji: no torque word")
    with pytest.raises(UsageError, match="^--torque: fuji: no torque word$"):
        s.motion.check_torque(50.0)
    s.motion.check_torque(None)                     # nothing asked: nothing refused
    s = station(limit_why="no limit word")
    with pytest.raises(UsageError, match="^--torque-limit: no limit word$"):
        s.motion.check_torque(None, 100.0)
    assert s.drive.calls == []


def test_start_torque_order_and_notes():
    s = station(notes=["set d5-01 = 1", "set A1-02 = 3"])
    s.warnings.append("set A1-02 = 3")              # already said: not said twice
    smp = s.motion.start_torque(30.0, 150.0, percent=20.0, timeout=4.0)
    assert s.warnings == ["set A1-02 = 3", "set d5-01 = 1"]
    assert s.drive.calls == [("set_torque", 30.0), ("set_torque_limit", 150.0), ("read_param", "F08"),
                             ("comm_loss_summary",), ("set_speed", 20.0), ("start", 4.0)]
    assert s.motion.may_run is True and smp.status is RUNNING


def test_start_torque_defaults():
    s = station()
    s.motion.start_torque(30.0)
    assert s.drive.calls == [("set_torque", 30.0), ("read_param", "F08"), ("comm_loss_summary",),
                             ("start", 5.0)]


def test_start_torque_refused_sends_nothing():
    s = station(torque_why="fuji: no torque word", notes=["a note"])
    with pytest.raises(UsageError):
        s.motion.start_torque(30.0)
    assert s.drive.calls == [] and s.warnings == [] and s.motion.may_run is False
    s = station(limit_why="no limit word")
    with pytest.raises(UsageError):
        s.motion.start_torque(30.0, 80.0)
    assert s.drive.calls == [] and s.motion.may_run is False


def test_set_torque():
    s = station()
    s.motion.set_torque(-25.5)
    assert s.drive.calls == [("set_torque", -25.5)]
    with pytest.raises(UsageError):
        s.motion.set_torque(33.33)                  # not a multiple of 0.1 %: refused
    with pytest.raises(UsageError):
        s.motion.set_torque(250.0)                  # outside -200..200 %
    assert s.drive.calls == [("set_torque", -25.5)]
    s = station(torque_why="fuji: no torque word")
    with pytest.raises(UsageError, match="^--torque: fuji: no torque word$"):
        s.motion.set_torque(10.0)
    assert s.drive.calls == []
