"""The session layer: one drive station in Data_Exchange behind the Drive interface, with a safe stop
on every way out. Between drives/ (profiles, make_drive) and checklist/ + cli/; it may import link,
fdl, dp, gsd, drives, outfile and datafile -- nothing of checklist, cli, api, sim or bustools/ (the
bus-level tools without a drive session; the layer plan: tests/test_layering.py). No click and no
rich: cli/drive_cmds.py and the checklist runner build on it.

    drivesession.py  DriveStation: the station (discovery, bring-up, the metered channel, the Drive)
                     composed with .motion (Motion) and .params (Parameters); its other public methods
                     hand on to those two
    station.py       StationView: the station's face its parts read (a Protocol: no import cycle)
    discovery.py     finding the station (scan, PDRIVE_STATION), choosing the profile and the layout
    cycle.py         the cycle rate (wire limit, cap), MeteredChannel, Sample
    bringup.py       Set_Prm / Chk_Cfg / Data_Exchange and the family's Drive
    motion.py        Motion: the only owner of "may it turn"; max frequency, percent for Hz,
                     reference, start, poll, status, jog (jog.py), torque runs (torque.py)
    safestop.py      SafeStop (Motion's base): normal stop, escalation to coast, shutdown and release
    signals.py       SIGTERM -> SessionTerminated; a second signal during the stop hurries it
    cyclelog.py      the --log CSV, one row per Data_Exchange (outfile.OutputFile)
    parameters.py    Parameters: plan(code, value) -> WritePlan (the code resolved and checked once),
                     execute(plan) (stop-only, write, read back), read, save; dump / compare / restore
    paramtypes.py    code helpers, value text, WritePlan, ParamRow
    backup.py        dump and compare;  dumpfile.py: the dump file format and loading
    restore.py       restore: plan every row first, then write and read back
    group.py         Group: several stations on one bus cycle (run 3,4,5, the checklist's together, api)
    together.py      run_together: several stations' parameter jobs at once, one round carrying a
                     request of each (fleet dump / diff, api Bus.read_params)
    multirun.py      MultiRun: several drives in one run on a Group
    live.py          Live: the loop of run and jog (keys, rendering: the CLI); Reach, the "reached" rule
    monitors.py      run --monitor and the trip records of `faults`
    commloss.py      the comm-loss acceptance test (commloss_reaction.py: its expectations)

The station level (not a versioned contract; tools reach it through profidrive_cli.api.station and
api.Bus.station(), never by importing this package: docs/api.md "For tools: the station level")
-----------------------------------------------------------------------------------------------

    DriveStation(master, address=None, *, profile=None, layout=None, ppo=None, fmt=None,
                 watchdog_ms=500, cycle_hz=None, stop_timeout=None, close_link=True,
                 handle_signals=True, before_connect=None, on_message=None, log_csv=None, env=None)

        with bus.station(5, ppo=3) as s:                # identify, Set_Prm/Chk_Cfg, the Drive
            s.motion.start(percent=s.motion.percent_for_hz(30.0))
            while ...: sample = s.motion.poll()
        # leaving the block: normal stop (bounded wait), coast if it does not stop, release, close

      address       station 0..125; None -> env PDRIVE_STATION, else the only drive station on the bus
      profile       name / alias / path; None -> from the station's ident (another device's: refused)
      layout | ppo | fmt   layout name, --ppo N (-> "ppoN") or --format NAME; default: the profile's
      watchdog_ms   DP watchdog armed in Set_Prm (10..650000 ms)
      cycle_hz      None -> the wire limit for this station, capped (100 Hz real, 50 Hz sim); 0 -> unpaced
      stop_timeout  None -> from the drive's deceleration time (1.5 x + 3 s, at least 5 s), else 30 s
      before_connect(station)  after identify, before Set_Prm (the CLI's confirmation)
      on_message(text), log_csv, handle_signals (SIGTERM -> SessionTerminated while open)

    The station keeps: address, ident, profile, layout, drive, channel, cycle_hz, wire_hz, warnings,
    messages, link_lost; counters, achieved_hz, cycles; settle(...) before connect (a coordinator's
    rate, watchdog, Sync/Freeze, --log columns); fault_history(), trip_records(), clear_fault().
    Its parts: .motion (Motion: may_run, fmax, percent_for_hz, start, poll, status, jog, torque,
    stop -> StopReport, stop_report, final_status) and .params (Parameters: info, read, plan ->
    WritePlan, execute, write (= plan + execute), save, dump / compare / restore, load_dump).
    Errors the user sees are UsageError (exit 2) or BusError / DriveError (exit 1), one line each.
"""

from profidrive_cli.session.backup import ParamRow
from profidrive_cli.session.cycle import (MeteredChannel, Sample, default_cycle_hz,
                                          wire_limit_hz)
from profidrive_cli.session.cyclelog import cycle_words
from profidrive_cli.session.discovery import (Candidate, choose_profile, find_drive_stations,
                                              resolve_layout)
from profidrive_cli.session.station import DEFAULT_WATCHDOG_MS, DriveStation
from profidrive_cli.session.dumpfile import DUMP_END, DUMP_FORMAT
from profidrive_cli.session.motion import Motion
from profidrive_cli.session.parameters import Parameters
from profidrive_cli.session.paramtypes import ParamInfo, WritePlan, profiles_with_code, suggest_codes
from profidrive_cli.session.restore import RestoreInterrupted, RestoreRefused
from profidrive_cli.session.safestop import StopReport
from profidrive_cli.session.signals import SessionTerminated

__all__ = [
    "DEFAULT_WATCHDOG_MS", "DUMP_END", "DUMP_FORMAT", "DriveStation", "Candidate", "MeteredChannel",
    "Motion", "ParamInfo", "ParamRow", "Parameters", "RestoreInterrupted", "RestoreRefused", "Sample", "SessionTerminated",
    "StopReport", "choose_profile", "cycle_words", "default_cycle_hz", "find_drive_stations",
    "profiles_with_code", "resolve_layout", "suggest_codes", "wire_limit_hz", "WritePlan",
]
