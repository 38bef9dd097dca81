"""The station level of the API: what pdrive's own tools (the CLI's drive commands, the checklist,
the asyncio face) use beyond Bus.drive(), and what a user's tool may use the same way (docs/api.md
"The station level"). Bus.station() opens a DriveStation; everything a tool does with it goes
through the names here -- no tool imports session/ (tests/test_layering.py: the one door).

    DriveStation    one drive station, the one owner of its state (session/station.py);
                    .motion: Motion (may it turn, start / jog / torque, the one stop path),
                    .params: Parameters (the one write path: plan -> execute; dump / compare / restore)
    Sample          one status sample of a station (status, reference, actual, counters)
    StopReport      how a stop ended (normal / coast / failed / not sent)
    Live, Reach     the loop of run and jog; the one "reached" rule (NOT_REACHED, end_status,
                    fault_name: the words of a run's end)
    MultiRun, Group several drives in one run; several stations on one bus cycle
    Outcome, Stopped  what Bus.together() gives per station (its jobs at once: fleet dump / diff)
    Monitors, TripRecords, setup_monitors   run --monitor and the card's trip records
    run_commloss, check_commloss_args, CommLossResult   the comm-loss acceptance test
    dump files      load_dump, write_dump, not_dumped_words; restore's RestoreRefused /
                    RestoreInterrupted / scope_problem; backup's default_source, nothing_compared,
                    CARD_MANUAL
    codes           suggest_codes (the closest codes), wire_limit_hz (a station's wire limit)

The station level is typed (mypy --strict) but not a versioned contract (docs/versioning.md): it
changes when the tools need it, and CHANGELOG.md says so where a user would notice.
"""

from typing import TYPE_CHECKING

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.session.backup import CARD_MANUAL, default_source, nothing_compared
    from profidrive_cli.session.commloss import CommLossResult, run_commloss
    from profidrive_cli.session.commloss import check_args as check_commloss_args
    from profidrive_cli.session.cycle import Sample, wire_limit_hz
    from profidrive_cli.session.discovery import Candidate
    from profidrive_cli.session.dumpfile import load_dump, not_dumped_words, write_dump
    from profidrive_cli.session.group import Group
    from profidrive_cli.session.live import NOT_REACHED, Live, Reach, end_status, fault_name
    from profidrive_cli.session.monitors import Monitors, TripRecords, setup_monitors
    from profidrive_cli.session.motion import Motion
    from profidrive_cli.session.multirun import MultiRun
    from profidrive_cli.session.parameters import Parameters
    from profidrive_cli.session.paramtypes import ParamInfo, ParamRow, WritePlan, suggest_codes
    from profidrive_cli.session.restore import RestoreInterrupted, RestoreRefused, scope_problem
    from profidrive_cli.session.safestop import StopReport
    from profidrive_cli.session.signals import SessionTerminated
    from profidrive_cli.session.station import DEFAULT_WATCHDOG_MS, DriveStation
    from profidrive_cli.session.together import Outcome, Stopped

#: name -> (module, attribute): loaded on first use (PEP 562), so that a command importing one name
#: (drive_opts: SessionTerminated) loads that module only, not the whole station level
_HOME: dict[str, tuple[str, str]] = {
    **{n: ("profidrive_cli.session.backup", n) for n in ("CARD_MANUAL", "default_source", "nothing_compared")},
    **{n: ("profidrive_cli.session.commloss", n) for n in ("CommLossResult", "run_commloss")},
    "check_commloss_args": ("profidrive_cli.session.commloss", "check_args"),
    **{n: ("profidrive_cli.session.cycle", n) for n in ("Sample", "wire_limit_hz")},
    "Candidate": ("profidrive_cli.session.discovery", "Candidate"),
    **{n: ("profidrive_cli.session.dumpfile", n) for n in ("load_dump", "not_dumped_words", "write_dump")},
    "Group": ("profidrive_cli.session.group", "Group"),
    **{n: ("profidrive_cli.session.live", n)
       for n in ("NOT_REACHED", "Live", "Reach", "end_status", "fault_name")},
    **{n: ("profidrive_cli.session.monitors", n) for n in ("Monitors", "TripRecords", "setup_monitors")},
    "Motion": ("profidrive_cli.session.motion", "Motion"),
    "MultiRun": ("profidrive_cli.session.multirun", "MultiRun"),
    "Parameters": ("profidrive_cli.session.parameters", "Parameters"),
    **{n: ("profidrive_cli.session.paramtypes", n)
       for n in ("ParamInfo", "ParamRow", "WritePlan", "suggest_codes")},
    **{n: ("profidrive_cli.session.restore", n)
       for n in ("RestoreInterrupted", "RestoreRefused", "scope_problem")},
    "StopReport": ("profidrive_cli.session.safestop", "StopReport"),
    "SessionTerminated": ("profidrive_cli.session.signals", "SessionTerminated"),
    **{n: ("profidrive_cli.session.station", n) for n in ("DEFAULT_WATCHDOG_MS", "DriveStation")},
    **{n: ("profidrive_cli.session.together", n) for n in ("Outcome", "Stopped")},
}


def __getattr__(name: str) -> object:
    home = _HOME.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    import importlib
    value = getattr(importlib.import_module(home[0]), home[1])
    globals()[name] = value
    return value


__all__ = [
    "CARD_MANUAL", "Candidate", "CommLossResult", "DEFAULT_WATCHDOG_MS", "DriveStation", "Group", "Live",
    "Monitors", "Motion", "MultiRun", "NOT_REACHED", "Outcome", "ParamInfo", "ParamRow", "Parameters", "Reach",
    "RestoreInterrupted", "RestoreRefused", "Sample", "SessionTerminated", "StopReport", "Stopped", "TripRecords",
    "WritePlan", "check_commloss_args", "default_source", "end_status", "fault_name", "load_dump",
    "not_dumped_words", "nothing_compared", "run_commloss", "scope_problem", "setup_monitors",
    "suggest_codes", "wire_limit_hz", "write_dump",
]
