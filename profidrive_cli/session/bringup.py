"""Bring-up: parameterise and configure the chosen station (Set_Prm with the DP watchdog and the
GSD's User_Prm_Data, Chk_Cfg of the layout), reach Data_Exchange at the session's rate, and build the
family's Drive on a MeteredChannel (the station kept in data exchange while the master talks to
other stations: Master.keep). Talks to the bus through dp.poller.Master only; starts nothing.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol

from profidrive_cli import BusError
from profidrive_cli.drives.base import Drive
from profidrive_cli.drives.profile import Profile
from profidrive_cli.session.cycle import MeteredChannel
from profidrive_cli.session.cyclelog import CycleLog, Extra


class Connecting(Protocol):
    """What connect() reads and sets on the station being opened (session.DriveSession)."""
    master: Any
    address: int | None
    ident: int | None
    profile: Profile | None
    layout: str | None
    watchdog_ms: float
    dp_sync: bool
    dp_freeze: bool
    cycle_hz: float
    channel: MeteredChannel | None
    t0: float
    log_csv: str | Path | None
    log_extra: Extra | None
    cyclelog: CycleLog | None
    drive: Drive | None

    def warn(self, text: str) -> None: ...


def connect(sess: Connecting) -> Drive:
    """Set_Prm (watchdog, the GSD's User_Prm_Data), Chk_Cfg of the layout, Data_Exchange at the
    session's rate through a MeteredChannel (with the --log hook), then the family's Drive."""
    from profidrive_cli.drives import make_drive
    from profidrive_cli.dp.station import SlaveConfig
    assert sess.profile is not None and sess.layout is not None and sess.ident is not None  # located
    lay = sess.profile.layouts[sess.layout]
    sc = SlaveConfig(ident=sess.ident, cfg=lay.cfg, user_prm=user_prm(sess),
                     wd_ms=sess.watchdog_ms, sync=sess.dp_sync,
                     freeze=sess.dp_freeze)          # Sync_Req / Freeze_Req (multirun.py)
    sess.master.add_station(sess.address, sc)
    try:
        sess.master.bring_up(sess.address, timeout=3.0, fail_fast=True)
    except BusError as e:
        raise BusError(f"{e} (profile {sess.profile.name}, layout {sess.layout}: Chk_Cfg "
                       f"{lay.cfg.hex(' ').upper()})") from None
    period = 1.0 / sess.cycle_hz if sess.cycle_hz else 0.0
    # kept in data exchange while the master brings up (or talks to) other stations on this bus
    # (pdrive run 3,4,5, the checklist's together, the API's drives): dp.poller.Master.keep
    sess.master.keep(sess.address, period)
    sess.channel = MeteredChannel(sess.master.channel(sess.address, period))
    sess.t0 = sess.channel.now()
    if sess.log_csv:
        sess.cyclelog = CycleLog(sess.log_csv, sess.channel, sess.t0, lambda: sess.drive, sess.warn,
                                 sess.log_extra)
    drive: Drive = make_drive(sess.channel, sess.profile, sess.layout)
    sess.drive = drive
    return drive


def user_prm(sess: Connecting) -> bytes:
    """The device's default User_Prm_Data from its GSD (library or PDRIVE_GSD_DIR), else none."""
    if sess.ident is None:
        return b""
    try:
        from profidrive_cli.gsd.interp import device_user_prm
        from profidrive_cli.gsd.library import find_by_ident
        g = find_by_ident(sess.ident)
        return device_user_prm(g) if g is not None else b""
    except Exception:       # a broken user GSD must not keep the drive from starting
        return b""

