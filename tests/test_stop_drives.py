"""session/safestop.py stop_drives, the one stop path, with several members in rounds (what
Group.stop_all hands it: end_round, hurry, the stations out of data exchange), sans-IO on the fake
clock and scripted drives of tests/test_safestop_mutants.py. The single stop (SafeStop.stop, a group
of one) is pinned there; here: rounds, prefixes, StationOut, the group's words.
Written for mutation testing (tools/mutation/run.py session/safestop.py).
"""

import pytest

import profidrive_cli.session.safestop as ss
from profidrive_cli.drives.base import DriveError
from profidrive_cli.session.group import StationOut as GroupStationOut
from test_safestop_mutants import DT, RUNNING, STOPPED, Clock, Drive, Session, status


class OutDrive(Drive):
    """Out of data exchange (StationOut) for its first `out_for` cycles and stop commands."""

    def __init__(self, clock, address, out_for=0, **kw):
        super().__init__(clock, **kw)
        self.address = address
        self.out_for = out_for

    def stop(self, how, wait=True):
        if self.out_for > 0:
            self.commands.append((how, "out"))
            self._left = self.normal_after if how == "normal" else self.coast_after
            raise ss.StationOut(self.address, "no answer")
        return super().stop(how, wait)

    def cycle(self):
        if self.out_for > 0:
            self.out_for -= 1
            self.clock.t += DT
            raise ss.StationOut(self.address, "no answer")
        return super().cycle()


class Rounds:
    def __init__(self):
        self.n = 0

    def __call__(self):
        self.n += 1


def member(clock, address, decel_s=10.0, percent=50.0, timeout=None, drive=None, seen=None, **kw):
    d = drive or Drive(clock, **kw)
    s = Session(d, clock, decel_s=decel_s)
    s.address = address
    s.motion.comm_loss_text = None
    on_sample = None if seen is None else (lambda smp: seen.append((address, smp.status)))
    return s, ss.StopMember(s.motion, percent, timeout, f"station {address}: ", on_sample)


def test_station_out_is_the_group_s_own():
    assert GroupStationOut is ss.StationOut
    e = ss.StationOut(4, "absent")
    assert str(e) == "station 4 is out of data exchange (absent)" and (e.address, e.why) == (4, "absent")


def test_members_stop_in_rounds_each_with_its_own_report():
    clock = Clock()
    seen = []
    a, ma = member(clock, 3, normal_after=1, seen=seen)
    b, mb = member(clock, 4, normal_after=3, seen=seen)
    rounds = Rounds()
    ss.stop_drives([ma, mb], now=clock.now, end_round=rounds)
    assert a.drive.commands == b.drive.commands == [("normal", False)]
    # the command round, then 4 rounds: a stops in the 2nd, b in the 4th
    assert rounds.n == 1 + 4
    ra, rb = a.motion.stop_report, b.motion.stop_report
    assert (ra.how, ra.stopped, ra.message, ra.status) == ("normal", True, "stopped", STOPPED)
    assert (rb.how, rb.stopped, rb.message) == ("normal", True, "stopped")
    assert ra.seconds == pytest.approx(3 * DT) and rb.seconds == pytest.approx(6 * DT)
    assert a.motion.may_run is False and b.motion.may_run is False
    assert a.motion.final_status is STOPPED and b.motion.final_status is STOPPED
    assert seen == [(3, RUNNING), (4, RUNNING), (3, STOPPED), (4, RUNNING), (4, RUNNING), (4, STOPPED)]
    assert a.warnings == b.warnings == []


def test_without_on_sample_the_last_status_is_kept():
    clock = Clock()
    a, ma = member(clock, 3, coast_after=None, timeout=0.5)
    ss.stop_drives([ma], now=clock.now)
    assert a.motion.final_status is RUNNING and a.motion.stop_report.status is RUNNING


def test_a_stuck_member_coasts_in_the_group_s_words_the_other_stops_normally():
    clock = Clock()
    a, ma = member(clock, 3, normal_after=0)
    b, mb = member(clock, 4, coast_after=2, timeout=1.0)
    ss.stop_drives([ma, mb], now=clock.now, end_round=Rounds())
    assert a.motion.stop_report.how == "normal" and a.warnings == []
    assert b.warnings == ["station 4: not stopped after 1 s: coasting"]
    assert b.drive.commands == [("normal", False), ("coast", False)]
    r = b.motion.stop_report
    assert (r.how, r.stopped) == ("coast", True)
    assert r.message == "stopped; not stopped after 1 s; coasted"
    assert b.motion.may_run is False


def test_the_single_stop_s_words_when_asked():
    clock = Clock()
    b, mb = member(clock, 4, coast_after=0, timeout=1.0)
    ss.stop_drives([mb], now=clock.now, state_in_coast_report=False)
    assert b.motion.stop_report.message == "not stopped after 1 s; coasted"


def test_a_coast_ending_in_fault_says_so():
    clock = Clock()
    tripped = status("fault", running=False, speed=0.0, fault=True, fault_code="OC1")
    b, mb = member(clock, 4, coast_after=0, timeout=1.0, rest=tripped)
    ss.stop_drives([mb], now=clock.now)
    assert b.motion.stop_report.message == ("the drive is in fault (OC1): its output is off; not "
                                            "stopped after 1 s; coasted")


def test_a_hurry_coasts_every_member_still_under_its_normal_stop():
    clock = Clock()
    a, ma = member(clock, 3, coast_after=1)
    b, mb = member(clock, 4, coast_after=1)
    asked = []

    def hurry():
        asked.append(clock.t)
        return len(asked) == 1
    ss.stop_drives([ma, mb], now=clock.now, hurry=hurry)
    assert a.warnings == ["station 3: stop hurried by a second signal: coasting"]
    assert b.warnings == ["station 4: stop hurried by a second signal: coasting"]
    assert a.motion.stop_report.message == "stopped; stop hurried by a second signal; coasted"
    assert len(asked) == 2                  # asked after each round with a member left, not after


def test_a_hurry_during_the_coast_is_ignored_in_a_group():
    clock = Clock()
    a, ma = member(clock, 3, coast_after=3, timeout=0.5)
    ss.stop_drives([ma], now=clock.now, hurry=lambda: a.motion.stop_report is None
                   and a.drive.commands[-1][0] == "coast")
    assert a.motion.stop_report.how == "coast" and a.motion.stop_report.stopped


def test_a_hurry_during_the_coast_ends_it_when_asked():
    clock = Clock()
    a, ma = member(clock, 3, coast_after=30, timeout=0.5)
    ss.stop_drives([ma], now=clock.now, hurry_ends_coast=True,
                   hurry=lambda: a.drive.commands[-1][0] == "coast")
    r = a.motion.stop_report
    assert (r.how, r.stopped) == ("failed", False)
    assert r.message == ("not stopped after 0.5 s; the drive does not report stopped after a coast "
                         "stop either")
    assert r.seconds == pytest.approx(4 * DT) and a.motion.may_run is True


def test_a_refused_normal_stop_coasts_at_once():
    clock = Clock()
    rounds = Rounds()
    a, ma = member(clock, 3, coast_after=0)
    a.drive.fail_on["normal"] = DriveError("refused")
    b, mb = member(clock, 4, normal_after=0)
    ss.stop_drives([ma, mb], now=clock.now, end_round=rounds)
    assert a.drive.commands == [("normal", False), ("coast", False)]
    assert a.warnings == ["station 3: normal stop failed: refused: coasting"]
    r = a.motion.stop_report
    assert (r.how, r.message) == ("coast", "stopped; normal stop failed: refused; coasted")
    assert r.seconds == pytest.approx(DT) and rounds.n == 2


def test_a_refused_coast_stop_fails_that_member_only():
    clock = Clock()
    a, ma = member(clock, 3)
    a.drive.fail_on["normal"] = DriveError("a")
    a.drive.fail_on["coast"] = DriveError("b")
    a.motion.final_status = RUNNING
    b, mb = member(clock, 4, normal_after=1)
    ss.stop_drives([ma, mb], now=clock.now)
    r = a.motion.stop_report
    assert (r.how, r.stopped, r.seconds, r.status) == ("failed", False, 0.0, RUNNING)
    assert r.message == "normal stop failed: a; coast stop not possible: b"
    assert a.motion.may_run is True and a.drive.cycles == 0
    assert b.motion.stop_report.how == "normal" and b.motion.may_run is False


def test_a_coast_refused_after_the_wait_fails_with_its_time():
    clock = Clock()
    a, ma = member(clock, 3, timeout=1.0)
    a.drive.fail_on["coast"] = DriveError("b")
    ss.stop_drives([ma], now=clock.now)
    r = a.motion.stop_report
    assert r.message == "not stopped after 1 s; coast stop not possible: b"
    assert r.seconds == pytest.approx(5 * DT)


class FailingCycle(Drive):
    def __init__(self, clock, fail_at, **kw):
        super().__init__(clock, **kw)
        self.fail_at = fail_at

    def cycle(self):
        st = super().cycle()
        if self.cycles in self.fail_at:
            raise DriveError(f"bad reply {self.cycles}")
        return st


def test_a_drive_error_in_the_normal_wait_coasts_in_the_coast_wait_fails():
    clock = Clock()
    d = FailingCycle(clock, {2, 4}, coast_after=5)
    a, ma = member(clock, 3, drive=d)
    ss.stop_drives([ma], now=clock.now)
    assert a.warnings == ["station 3: normal stop failed: bad reply 2: coasting"]
    r = a.motion.stop_report
    assert (r.how, r.stopped) == ("failed", False)
    assert r.message == "normal stop failed: bad reply 2; coast stop not possible: bad reply 4"
    assert r.seconds == pytest.approx(4 * DT) and r.status is RUNNING


def test_a_drive_error_of_one_member_does_not_hold_up_the_other_in_its_round():
    clock = Clock()
    rounds = Rounds()
    a, ma = member(clock, 3, drive=FailingCycle(clock, {1}, coast_after=0))
    b, mb = member(clock, 4, normal_after=1)
    ss.stop_drives([ma, mb], now=clock.now, end_round=rounds)
    assert b.drive.cycles == 2 and rounds.n == 1 + 2
    assert a.motion.stop_report.message == "stopped; normal stop failed: bad reply 1; coasted"


def test_a_station_out_of_data_exchange_is_waited_out():
    clock = Clock()
    rounds = Rounds()
    d = OutDrive(clock, 4, out_for=3, normal_after=0)
    b, mb = member(clock, 4, drive=d)
    a, ma = member(clock, 3, normal_after=5)
    ss.stop_drives([mb, ma], now=clock.now, end_round=rounds, out=lambda addr: None)
    assert d.commands == [("normal", "out")]        # the command is kept for when it is back
    # the other is cycled in every round the first is out: it stops in the 6th round
    assert rounds.n == 1 + 6 and a.drive.cycles == 6
    assert b.motion.stop_report.how == "normal" and b.motion.stop_report.stopped
    assert a.motion.stop_report.how == "normal"


def test_without_out_a_station_out_is_raised():
    clock = Clock()
    d = OutDrive(clock, 4, out_for=0, normal_after=3)
    b, mb = member(clock, 4, drive=d)
    d.out_for = 0

    def cycle():
        raise ss.StationOut(4, "gone")
    d.cycle = cycle
    with pytest.raises(ss.StationOut):
        ss.stop_drives([mb], now=clock.now)
    d2 = OutDrive(clock, 5, out_for=1)
    c, mc = member(clock, 5, drive=d2)
    with pytest.raises(ss.StationOut):
        ss.stop_drives([mc], now=clock.now)


def test_a_station_still_out_at_the_end_is_reported_so():
    clock = Clock()
    d = OutDrive(clock, 4, out_for=10 ** 6)
    b, mb = member(clock, 4, drive=d, timeout=1.0)
    b.watchdog_ms = 300.0
    ss.stop_drives([mb], now=clock.now, out={4: "no answer"}.get)
    r = b.motion.stop_report
    assert (r.how, r.stopped) == ("failed", False)
    assert r.message == ("station 4 out of data exchange (no answer): pdrive could not send the "
                         "stop; its DP watchdog (300 ms) ends data exchange and the drive stops by "
                         "its communication-loss setting")
    assert b.warnings == ["station 4: not stopped after 1 s: coasting"]
    assert d.commands == [("normal", "out"), ("coast", "out")]
    # the normal wait ends at the first round past 1 s (5), the coast at the first past 10 s (41)
    assert r.seconds == pytest.approx(5 * DT + 41 * DT)
    b.motion.stop_report = None
    b.motion.comm_loss_text = "o27 = 0: trips at once"
    d.commands.clear()
    ss.stop_drives([ss.StopMember(b.motion, None, 1.0, "station 4: ")], now=clock.now,
                   out={4: "absent"}.get)
    assert b.motion.stop_report.message.endswith("(300 ms) ends data exchange and the drive stops "
                                                 "by o27 = 0: trips at once")


def test_a_fault_code_not_readable_while_out_keeps_the_fault():
    clock = Clock()
    tripped = status("fault", running=False, speed=0.0, fault=True)
    d = OutDrive(clock, 4, normal_after=0, rest=tripped)

    def status_out():
        raise ss.StationOut(4, "gone")
    d.status = status_out
    b, mb = member(clock, 4, drive=d)
    ss.stop_drives([mb], now=clock.now, out=lambda a: None)
    assert b.motion.stop_report.message == "the drive is in fault: its output is off"
    with pytest.raises(ss.StationOut):
        c, mc = member(clock, 5, drive=d)
        ss.stop_drives([mc], now=clock.now)


def test_a_group_s_on_sample_that_raises_is_raised():
    clock = Clock()
    a, ma = member(clock, 3, normal_after=2)

    def boom(smp):
        raise RuntimeError("closed stdout")
    ma.on_sample = boom
    with pytest.raises(RuntimeError):
        ss.stop_drives([ma], now=clock.now)
    assert a.motion.stop_report is None and a.motion.may_run is True


def test_the_single_stop_keeps_a_raising_on_sample_and_goes_on():
    clock = Clock()
    d = Drive(clock, normal_after=2)
    s = Session(d, clock, decel_s=10.0)
    calls = []

    def boom(smp):
        calls.append(smp.status)
        raise RuntimeError("closed stdout")
    r = s.motion.stop(boom, None)
    assert r.how == "normal" and r.stopped and calls == [RUNNING]
    assert isinstance(s.motion.callback_error, RuntimeError)
    assert s.final_status is STOPPED


def test_a_third_signal_during_the_single_stop_s_coast_ends_its_wait():
    clock = Clock()

    class Signalled(Drive):
        def cycle(self):
            st = super().cycle()
            if self.commands[-1][0] == "coast":
                s.signals.hurry = True          # a third signal, during the coast wait
            return st
    d = Signalled(clock, coast_after=30)
    s = Session(d, clock, decel_s=10.0)
    s.signals.hurry = True
    r = s.motion.stop(None, None)
    assert (r.how, r.stopped) == ("failed", False)
    assert r.message == ("stop hurried by a second signal; the drive does not report stopped after "
                         "a coast stop either")
    assert d.cycles == 2 and s.signals.hurry is True and s.motion.may_run is True


def test_nothing_is_known_before_the_first_start():
    s = Session(None, Clock())
    fresh = ss.SafeStop(s)
    assert fresh.decel_s is None and fresh.comm_loss_text is None and fresh.stop_report is None


# -- wait_stopped: the wait without a command (not the stop) ---------------------------------------

def test_wait_stopped_reads_the_fault_code_once_in_fault():
    clock = Clock()
    tripped = status("fault", running=False, speed=0.0, fault=True)
    coded = status("fault", running=False, speed=0.0, fault=True, fault_code="OC2")
    d = Drive(clock, normal_after=1, rest=tripped, fault_status=coded)
    d.stop("normal", wait=False)
    s = Session(d, clock)
    assert s.motion.wait_stopped(5.0, None) is coded
    d2 = Drive(clock, normal_after=0, rest=tripped)              # not readable: the fault stays
    d2.stop("normal", wait=False)
    assert Session(d2, clock).motion.wait_stopped(5.0, None) is tripped
    with_code = status("fault", running=False, speed=0.0, fault=True, fault_code="E70")
    d3 = Drive(clock, normal_after=0, rest=with_code, fault_status=coded)
    d3.stop("normal", wait=False)
    assert Session(d3, clock).motion.wait_stopped(5.0, None) is with_code
    d4 = Drive(clock, normal_after=0, rest=STOPPED, fault_status=coded)
    d4.stop("normal", wait=False)
    assert Session(d4, clock).motion.wait_stopped(5.0, None) is STOPPED


def test_wait_stopped_keeps_a_raising_on_sample_and_goes_on():
    clock = Clock()
    d = Drive(clock, normal_after=2)
    d.stop("normal", wait=False)
    s = Session(d, clock)
    calls = []

    def boom(smp):
        calls.append(smp.status)
        raise RuntimeError("closed stdout")
    assert s.motion.wait_stopped(5.0, boom) is STOPPED
    assert calls == [RUNNING] and str(s.motion.callback_error) == "closed stdout"
