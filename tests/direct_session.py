"""A session on a Drive that exchanges data over a DirectChannel (no bus, a simulated clock): the
session level the checklist stands on (runner.StationHandle.session; in pdrive api.Bus.session), for
the checklist's unit tests. Its checked write_param, save and safe stop are the session's own; it was
never brought up on a bus, so it has no master (no counters, nothing to release) and nothing stops
the drive when the test leaves it (the runner's own stop is what the tests see)."""

from __future__ import annotations

from profidrive_cli.session import DriveStation


def direct_session(drive, spec) -> DriveStation:
    """The session of `drive` (made by make_drive on a DirectChannel) for the checklist station `spec`."""
    s = DriveStation(None, spec.address, profile=spec.profile.name, layout=spec.layout,
                     handle_signals=False)
    s.address, s.profile, s.layout = spec.address, spec.profile, spec.layout
    s.drive, s.channel = drive, drive.channel
    return s
