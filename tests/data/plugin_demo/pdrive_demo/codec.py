"""The demo family's codec: pdrive's PROFIdrive core as it is (a card that follows PROFIdrive V2)."""

from profidrive_cli.drives.profidrive import decode_area
from profidrive_cli.drives.profidrive.drive import ProfidriveDrive


class DemoDrive(ProfidriveDrive):
    pass


def make_drive(channel, profile, layout=None):
    return DemoDrive(channel, profile, layout)


__all__ = ["DemoDrive", "decode_area", "make_drive"]
