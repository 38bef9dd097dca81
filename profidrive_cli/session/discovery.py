"""Which station, which profile, which layout: the bus scan for drive stations (FDL status +
Slave_Diag), PDRIVE_STATION, the profile chosen from the station's ident (or the one named, refused
when it belongs to another device), and the layout from --ppo / --format. Reads the bus through
dp/ (scan, Slave_Diag) and profiles through drives/profile.py; writes nothing to a station.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, Mapping

from profidrive_cli import BusError, UsageError
from profidrive_cli.config import source_of
from profidrive_cli.drives.profile import Profile, all_profiles, load_profile, profile_for_ident

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.dp.poller import Master


@dataclass
class Candidate:
    address: int
    ident: int | None
    profile: Profile | None          # the profile whose ident matches (None: not a known drive)
    state: str = ""                  # DP state in words (from Slave_Diag)

    def describe(self) -> str:
        if self.profile is not None:
            return f"{self.address} ({self.profile.name})"
        return f"{self.address} (ident 0x{self.ident:04X})" if self.ident is not None else str(self.address)


def find_drive_stations(master: "Master", first: int = 0, last: int = 125) -> list[Candidate]:
    """Every slave that answers FDL status and Slave_Diag, with its profile (None when the ident is
    not one of ours). Retries are off during the probe so an empty bus is scanned quickly."""
    from profidrive_cli.dp.scan import scan
    saved = master.fdl.params
    master.fdl.params = dataclasses.replace(saved, retries=0)
    try:
        entries = scan(master, first, last)
    finally:
        master.fdl.params = saved
    out: list[Candidate] = []
    for e in entries:
        if e.station_type != "slave" or e.diag is None:
            continue
        out.append(Candidate(e.address, e.ident, profile_for_ident(e.diag.ident),
                                e.diag.state_words(master.address)))
    return out


def station_from_env(env: Mapping[str, str] | None) -> int | None:
    text = (env or {}).get("PDRIVE_STATION")
    if text in (None, ""):
        return None
    try:
        a = int(str(text).strip(), 0)
    except ValueError:
        raise UsageError(f"PDRIVE_STATION={text!r} is not a station address (0..125)") from None
    if not 0 <= a <= 125:
        raise UsageError(f"PDRIVE_STATION={a} is outside 0..125")
    return a


def family_words(p: Profile) -> str:
    return f"{p.name} ({p.title}, family {p.family}, ident 0x{p.ident:04X})"


def choose_profile(ident: int | None, name: str | None = None, address: int | None = None
                   ) -> tuple[Profile, list[str]]:
    """The profile for a station: `name` if given (refused when the station's ident belongs to
    another profile), else the one whose ident matches. Returns (profile, warnings)."""
    where = f"station {address}" if address is not None else "the station"
    own = profile_for_ident(ident) if ident is not None else None
    if name:
        src = source_of(name)                        # a config file's FILE:LINE (config.FileText)
        try:
            prof = load_profile(name)
        except UsageError as e:
            raise UsageError(f"{src}: profile: {e}") if src else e from None
        if ident is None or prof.ident == ident:
            return prof, []
        if own is not None:
            use = own.aliases[0] if own.aliases else own.name
            fix = f"correct that line or give --profile {use}" if src else \
                f"leave out --profile or use --profile {use}"
            raise UsageError(f"{src + ': profile: ' if src else ''}{where} is {family_words(own)}, "
                             f"not {prof.name} (family {prof.family}); {fix}")
        return prof, [f"{where} reports ident 0x{ident:04X}, profile {prof.name} expects "
                      f"0x{prof.ident:04X}: using {prof.name} as asked (a vendor GSD with the real "
                      f"ident may replace the placeholder)"]
    if own is None:
        known = ", ".join(f"{p.name} 0x{p.ident:04X}" for p in all_profiles())
        raise UsageError(f"{where} reports ident 0x{ident:04X}, which no drive profile has "
                         f"({known}); name one with --profile")
    return own, []


def resolve_layout(profile: Profile, layout: str | None = None, ppo: int | None = None,
                   fmt: str | None = None) -> str:
    given = [x for x in (layout, ppo, fmt) if x is not None]
    if len(given) > 1:
        raise UsageError("give at most one of --ppo N and --format NAME")
    names = ", ".join(profile.layouts)
    name: str | None
    if ppo is not None:
        name = f"ppo{ppo}"
        if name not in profile.layouts:
            ppos = [n[3:] for n in profile.layouts if n.startswith("ppo")]
            if not ppos:
                raise UsageError(f"--ppo {ppo}: {profile.name} has no PPO layouts; use --format "
                                 f"{' | '.join(profile.layouts)}")
            raise UsageError(f"--ppo {ppo}: {profile.name} supports PPO {', '.join(ppos)} "
                             f"(layouts: {names})")
        return name
    name = fmt if fmt is not None else layout
    if name is None:
        return profile.default_layout
    if name not in profile.layouts:
        low = {n.lower(): n for n in profile.layouts}
        if name.lower() in low:
            return low[name.lower()]
        source = source_of(layout)
        said = f"{source}: layout {name}" if fmt is None and source is not None \
            else f"--format {name}"               # a config file's layout names its FILE:LINE
        raise UsageError(f"{said}: {profile.name} has the layouts {names}")
    return name


def locate(master: "Master", address: int | None, env: Mapping[str, str],
           profile_named: bool = False) -> Candidate:
    """The station to open: `address`, else PDRIVE_STATION in `env`, else the only drive station on
    the bus -- the only slave at all when a profile is named and no known drive answers (UsageError
    listing the candidates when there are several; BusError when none answers)."""
    if address is None:
        address = station_from_env(env)
    port = getattr(master.link, "name", "") or "the bus"
    if address is not None:
        d = master.slave_diag(address, wake=True)     # (a slave still searching the rate)
        if d is None:
            raise BusError(f"station {address} does not answer on {port}")
        return Candidate(address, d.ident, profile_for_ident(d.ident), d.state_words(master.address))
    found = find_drive_stations(master)
    drives = [s for s in found if s.profile is not None]
    if profile_named and not drives:
        drives = found
    if len(drives) == 1:
        return drives[0]
    if not drives:
        others = f" (other slaves: {', '.join(s.describe() for s in found)})" if found else ""
        raise BusError(f"no drive station answers on {port}{others}")
    raise UsageError(f"{len(drives)} drive stations on {port}: "
                     f"{', '.join(s.describe() for s in drives)}; give ADDRESS "
                     f"(or set PDRIVE_STATION)")
