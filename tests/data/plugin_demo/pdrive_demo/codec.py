"""The demo family's codec: pdrive's PROFIdrive core as it is (a card that follows PROFIdrive V2)."""

from profidrive_cli.drives.profidrive import decode_area
from profidrive_cli.drives.profidrive.drive import ProfidriveDrive


class DemoDrive(ProfidriveDrive):
    """The core's drive. A family answers its own questions through the Drive's hooks; the one shown
    here: how `pdrive sniff --station` reads a captured area (normalise_area, a class method, no bus),
    the core's reading with the card named in the state."""

    @classmethod
    def normalise_area(cls, profile, direction, area):
        d = super().normalise_area(profile, direction, area)
        if "state" in d:
            d["state"] = f"demo card: {d['state']}"
        return d


def make_drive(channel, profile, layout=None):
    return DemoDrive(channel, profile, layout)


__all__ = ["DemoDrive", "decode_area", "make_drive"]
