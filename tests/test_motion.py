"""session/motion.py Motion: the only owner of "may it turn" (docs/architecture.md, issue 25 step 3).

may_run is written in session/motion.py only (before: set in safestop.py, jog.py, motion.py,
bringup.py's track_motion wrapper and multirun.py); the other modules read it. What track_motion
guarded, a start or jog of the session's Drive by a caller that does not go through the session
(the checklist's run, together and jog steps call Drive.start / Drive.jog themselves), is covered
by Drive.on_motion: the safe stop on close still stops the drive."""

import re
from pathlib import Path

import pytest

from profidrive_cli.session import DriveStation
from profidrive_cli.session.motion import Motion

from test_session import drive_model, session, short_ramps

PKG = Path(__file__).resolve().parent.parent / "profidrive_cli"

def standstill_hz(s):
    """The frequency below which the drive counts as stopped: DriveStatus.stopped's 0.05 % of the
    maximum frequency (drives/base.py). The model's own ramp may leave a few uHz after the stop it
    confirmed (seen under load: 8.5e-06 Hz), never more than that."""
    return 0.0005 * s.motion.fmax_hz


#: an assignment to may_run / _may_run (not a comparison), or a setattr naming it
WRITES = re.compile(r"""\b_?may_run\s*(?:=(?!=)|[-+|&]=)|setattr\([^)]*["']_?may_run["']""")


def _sites(pattern):
    out = []
    for f in sorted(PKG.rglob("*.py")):
        for n, line in enumerate(f.read_text(encoding="utf-8").splitlines(), 1):
            if pattern.search(line):
                out.append(f"{f.relative_to(PKG.parent).as_posix()}:{n}: {line.strip()}")
    return out


def test_motion_is_the_only_writer_of_may_run():
    assert [s for s in _sites(WRITES) if not s.startswith("profidrive_cli/session/motion.py:")] == []
    # and nobody can set it from outside: a read-only property on Motion, none on DriveStation
    assert Motion.may_run.fset is None and not hasattr(DriveStation, "may_run")


def test_no_module_reads_a_sessions_private_state():
    # the brief's grep: `grep -rnoE "\bsess(ion)?\._[a-z_]+" profidrive_cli` (21 hits before)
    assert _sites(re.compile(r"\bsess(ion)?\._[a-z_]+")) == []


# -- what bringup.track_motion guarded: a Drive started behind the session's back ------------------

@pytest.mark.parametrize("address,layout", [(3, None), (5, None), (5, "toyo"), (6, None), (7, None)])
def test_a_drive_started_directly_is_stopped_on_close(sim, address, layout):
    short_ramps(address)
    s = session(address, layout=layout)         # Toyo: PROFIdrive mode, and mode 1's run command
    with s:
        d = s.drive
        d.set_speed(20.0)
        d.start(timeout=5.0)                   # as the checklist's run step does
        assert s.motion.may_run
        for _ in range(5):
            assert s.motion.poll().status.running
    assert s.motion.stop_report.how == "normal" and s.motion.stop_report.stopped, s.motion.stop_report
    model = drive_model(sim, address)
    assert abs(model.out_hz if address == 7 else model.freq) < standstill_hz(s)


@pytest.mark.parametrize("address,layout", [(5, None), (5, "toyo"), (6, None)])
def test_a_jog_given_directly_is_stopped_on_close_even_after_its_own_stop(sim, address, layout):
    # the checklist's jog step: jog on, jog off, its own stop; the session's close still stops
    # (may_run stays True until a stop of the session confirms it)
    short_ramps(address)
    s = session(address, layout=layout)
    with s:
        d = s.drive
        d.jog(True)
        assert s.motion.may_run
        for _ in range(5):
            d.cycle()
        d.jog(False)
        d.stop("normal", wait=True, timeout=30.0)
        assert s.motion.may_run
    assert s.motion.stop_report.how == "normal" and s.motion.stop_report.stopped, s.motion.stop_report
    assert abs(drive_model(sim, address).freq) < standstill_hz(s)


def test_a_session_that_never_commands_motion_needs_no_stop():
    with session(3) as s:
        s.drive.set_speed(20.0)                # a reference alone turns nothing
        s.motion.status()
        assert not s.motion.may_run
    assert s.motion.stop_report.how == "not needed"
