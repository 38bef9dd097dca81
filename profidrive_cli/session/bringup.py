"""Bring-up: parameterise and configure the chosen station (Set_Prm with the DP watchdog and the
GSD's User_Prm_Data, Chk_Cfg of the layout), reach Data_Exchange at the session's rate, and build the
station's MeteredChannel (Station builds the family's Drive on it) (the station kept in data exchange while the master talks to
other stations: Master.keep). Talks to the bus through dp.poller.Master only; starts nothing.
"""

from __future__ import annotations

from typing import Any

from profidrive_cli import BusError
from profidrive_cli.drives.profile import Profile
from profidrive_cli.session.cycle import MeteredChannel


def bring_up(master: Any, address: int, ident: int, profile: Profile, layout: str, *,
             watchdog_ms: float, cycle_hz: float, sync: bool = False, freeze: bool = False
             ) -> MeteredChannel:
    """Set_Prm (watchdog, the GSD's User_Prm_Data, Sync_Req / Freeze_Req: multirun.py), Chk_Cfg of
    the layout, Data_Exchange at `cycle_hz` (0: unpaced); the station kept in data exchange while
    the master talks to others. Returns its MeteredChannel."""
    from profidrive_cli.dp.station import SlaveConfig
    from profidrive_cli.drives import drive_class
    lay = profile.layouts[layout]
    prm = drive_class(profile).set_prm_user_data(profile, user_prm(ident))
    sc = SlaveConfig(ident=ident, cfg=lay.cfg, user_prm=prm,
                     wd_ms=watchdog_ms, sync=sync, freeze=freeze)
    master.add_station(address, sc)
    try:
        master.bring_up(address, timeout=3.0, fail_fast=True)
    except BusError as e:
        raise BusError(f"{e} (profile {profile.name}, layout {layout}: Chk_Cfg "
                       f"{lay.cfg.hex(' ').upper()})") from None
    period = 1.0 / cycle_hz if cycle_hz else 0.0
    # kept in data exchange while the master brings up (or talks to) other stations on this bus
    # (pdrive run 3,4,5, the checklist's together, the API's drives): dp.poller.Master.keep
    master.keep(address, period)
    return MeteredChannel(master.channel(address, period))


def user_prm(ident: int | None) -> bytes:
    """The device's default User_Prm_Data from its GSD (library or PDRIVE_GSD_DIR), else none."""
    if ident is None:
        return b""
    try:
        from profidrive_cli.gsd.interp import device_user_prm
        from profidrive_cli.gsd.library import find_by_ident
        g = find_by_ident(ident)
        return device_user_prm(g) if g is not None else b""
    except Exception:       # a broken user GSD must not keep the drive from starting
        return b""
