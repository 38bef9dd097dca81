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
    multirun.py      MultiRun: several drives in one run on a Group
    live.py          Live: the loop of run and jog (keys, rendering: the CLI); Reach, the "reached" rule
    monitors.py      run --monitor and the trip records of `faults`
    commloss.py      the comm-loss acceptance test (commloss_reaction.py: its expectations)

Public API (stable; everything else is internal)
------------------------------------------------

    DriveStation(master, address=None, *, profile=None, layout=None, ppo=None, fmt=None,
                 watchdog_ms=500, cycle_hz=None, stop_timeout=None, close_link=True,
                 handle_signals=True, before_connect=None, on_message=None, log_csv=None,
                 env=None)

        with DriveStation(master, 5, ppo=3) as s:   # identify, Set_Prm/Chk_Cfg, Drive
        # (the CLI and the checklist get theirs from api.Bus.session(): docs/api.md)
            s.start(percent=s.percent_for_hz(30.0))
            while ...: sample = s.poll()
        # leaving the block: normal stop (bounded wait), coast if it does not stop, release, close

      master        dp.poller.Master (api.make_master builds it); the session closes its link on exit
                    unless close_link=False
      address       station 0..125; None -> env PDRIVE_STATION, else the only drive station on the bus
                    (FDL status + Slave_Diag scan; UsageError listing the candidates otherwise)
      profile       profile name / alias / path; None -> chosen from the station's ident. A profile of
                    another device than the station's ident is refused (the message names the station's)
      layout | ppo | fmt   layout name, --ppo N (-> "ppoN") or --format NAME; default: the profile's
      watchdog_ms   DP watchdog armed in Set_Prm (always; 10..650000 ms)
      cycle_hz      Data_Exchange rate. None -> the fastest the bus allows for this station (wire time
                    of one exchange at the baud rate), capped at 100 Hz on real ports and 50 Hz on the
                    instant simulator; 0 -> unpaced (parameter work: as fast as the link answers).
                    A rate above the wire limit adds a warning.
      stop_timeout  seconds to wait for the normal stop before coasting; None -> from the drive's
                    deceleration time where it can be read (1.5 x + 3 s, at least 5 s), else 30 s
      before_connect(session)   called after the station is identified and before Set_Prm: the CLI
                    asks for confirmation here (raise to cancel; nothing has been written yet)
      on_message(text)          warnings and what the safe stop did, one line each (also kept in
                    .warnings / .messages)
      log_csv       path: one CSV row per Data_Exchange (time, cycle, control word, reference, status
                    word, actual, output and input octets)
      handle_signals  while the session is open (main thread only), SIGTERM raises
                    SessionTerminated in the main thread; during the safe stop a second SIGINT/SIGTERM
                    escalates to a coast stop instead of interrupting it

    Attributes after open: station (Candidate), address, ident, profile, layout (name), drive
    (drives.base.Drive), channel (MeteredChannel), cycle_hz (target, 0 = unpaced), wire_hz (the bus
    limit for this station), warnings, messages, link_lost, stop_report (after stop() / close),
    final_status (the last DriveStatus seen); settable: on_sample(Sample), called on every cycle
    while a stop is awaited (also the stop on exit) — live views keep updating through it.

    Parts:    .motion (Motion: may_run, start, stop, jog, torque), .params (Parameters: plan / execute,
              read, save, dump / compare / restore); the names below hand on to them
    Motion:   start(percent) / set_reference(percent) / poll() -> Sample / status() -> Sample /
              stop(on_sample=None) -> StopReport (normal, then coast; bounded) / may_run
    Speed:    fmax(override=None) -> (hz, source words);  percent_for_hz(hz, fmax_override=None)
    Bus:      counters -> dict (master.fdl.counters_for(address));  achieved_hz;  cycles
    Params:   param_info(code) -> ParamInfo (UsageError with the closest codes / the station's family);
              parse_value(code, text);  read_param(code);  write_param(code, value, allow_dangerous=False)
              (checks: writable, not dangerous, exact value -- resolution, range, codes, wire width:
              drives/values.py --, stop-only while running; returns the value read back);
              danger_of(info) -> str | None;  save() -> str;  fault_history();  current_fault();  clear_fault()
    Files:    dump(progress=None) -> dict (YAML-ready: station identity + parameters, count, end marker);
              load_dump(path) -> dict (file:line errors; a cut-off format-2 file is refused);
              compare(doc, progress=None) -> [ParamRow];
              restore(doc, dry_run=False, progress=None, allow_dangerous=False) -> [ParamRow]: every row
              checked before the first write (RestoreRefused(.problems), nothing written); only what
              differs is written and read back; RestoreInterrupted(.rows) when a write fails part-way

    Module functions: find_drive_stations(master, first=0, last=125) -> [Candidate];
    choose_profile(ident, name=None) -> (Profile, warnings); resolve_layout(profile, layout, ppo, fmt);
    wire_limit_hz(baud, out_octets, in_octets); default_cycle_hz(link, wire_hz);
    suggest_codes(profile, code); profiles_with_code(code)
    Exceptions: SessionTerminated(BaseException) .signum;  errors the user sees are UsageError (exit 2)
    or BusError / DriveError (exit 1), one line each.
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
