"""The public face of a station that its parts stand on: session.DriveStation is the station
(discovery, bring-up, the metered channel, the Drive), and its Motion (with the safe stop),
Parameters and monitors read it only through these names -- as typing.Protocols, so that none of
them imports drivesession.py (which builds them) and no import cycle forms."""

from __future__ import annotations

from typing import Any, Protocol

from profidrive_cli.drives.base import Drive
from profidrive_cli.drives.profile import Profile
from profidrive_cli.session.cycle import MeteredChannel


class StationView(Protocol):
    """A located, possibly connected station: who it is, its bus, its Drive, its message line."""

    @property
    def profile(self) -> Profile | None: ...
    @property
    def layout(self) -> str | None: ...
    @property
    def address(self) -> int | None: ...
    @property
    def ident(self) -> int | None: ...
    @property
    def master(self) -> Any: ...
    @property
    def drive(self) -> Drive | None: ...
    @property
    def channel(self) -> MeteredChannel | None: ...

    def need_drive(self) -> Drive:
        """The connected Drive (PdriveError before the station is connected)."""
        ...

    def say(self, text: str) -> None: ...
    def warn(self, text: str) -> None: ...


__all__ = ["StationView"]
