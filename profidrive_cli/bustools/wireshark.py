"""`pdrive wireshark install`: the shipped Lua dissector, the generated station table and the extcap
launcher, written into Wireshark's personal folders (or given ones).

The dissector (wireshark/pdrive.lua, package data profidrive_cli.wireshark_files) is copied as it is.
The station table `pdrive_stations.lua` is generated here from the profiles (drives/wirefields.py):
every profile's layouts with their fields, the aliases and default layouts, and the stations the user
named (`--station 3=fuji-g1 --station 6=moeller:ppo1`). Every file is written atomically
(outfile.write_text_atomic). No click, no rich: the cli module prints what this returns.
"""

from __future__ import annotations

import os
import shlex
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

from profidrive_cli import PdriveError, UsageError, __version__
from profidrive_cli.outfile import check_output_path, write_text_atomic

DISSECTOR = "pdrive.lua"
STATION_TABLE = "pdrive_stations.lua"
EXTCAP_NAME = "pdrive-extcap"


# ---------------------------------------------------------------------------------------------
# where things go

def personal_dirs(platform: str = sys.platform, env: Mapping[str, str] = os.environ,
                  home: Path | None = None) -> tuple[Path, list[Path]]:
    """(plugins folder, extcap folders): Wireshark's personal folders ("Personal Lua Plugins" and
    the personal extcap path in Help > About > Folders). Windows: %APPDATA%\\Wireshark\\plugins and
    \\extcap. Elsewhere ~/.local/lib/wireshark/plugins; extcap in ~/.local/lib/wireshark/extcap
    (Wireshark 4.2 and later) and in the personal configuration folder's extcap (up to 4.0:
    $XDG_CONFIG_HOME/wireshark/extcap, by default ~/.config/wireshark/extcap) -- both are written."""
    if platform.startswith("win"):
        appdata = env.get("APPDATA")
        if not appdata:
            raise UsageError("APPDATA is not set: give the plugins folder with --dir")
        base = Path(appdata) / "Wireshark"
        return base / "plugins", [base / "extcap"]
    home = home or Path.home()
    base = home / ".local" / "lib" / "wireshark"
    config = Path(env["XDG_CONFIG_HOME"]) if env.get("XDG_CONFIG_HOME") else home / ".config"
    return base / "plugins", [base / "extcap", config / "wireshark" / "extcap"]


def dissector_source() -> str:
    """The shipped dissector's text (package data; the repository's wireshark/ in a checkout)."""
    from profidrive_cli.data import wireshark_dir
    path = wireshark_dir() / DISSECTOR
    try:
        return path.read_text("utf-8")
    except OSError as e:
        raise PdriveError(f"the shipped dissector {path} cannot be read: {e.strerror or e} "
                          "(reinstall pdrive)") from None


# ---------------------------------------------------------------------------------------------
# stations

@dataclass
class StationSpec:
    address: int
    profile: str          # the profile's full name
    layout: str


def parse_station(text: str) -> StationSpec:
    """'3=fuji-g1' or '6=moeller:ppo1' -> StationSpec (profile by name or alias; default layout)."""
    from profidrive_cli.drives.profile import load_profile
    addr, sep, rest = text.partition("=")
    if not sep or not rest:
        raise UsageError(f"--station {text!r}: expected ADDRESS=PROFILE[:LAYOUT], e.g. 3=fuji-g1")
    try:
        address = int(addr, 0)
    except ValueError:
        raise UsageError(f"--station {text!r}: {addr!r} is not a station address") from None
    if not 0 <= address <= 126:
        raise UsageError(f"--station {text!r}: station address {address} is outside 0..126")
    name, _, layout = rest.partition(":")
    prof = load_profile(name)
    layout = layout or prof.default_layout
    if layout not in prof.layouts:
        raise UsageError(f"--station {text!r}: {prof.name} has no layout '{layout}' "
                         f"(known: {', '.join(prof.layouts)})")
    return StationSpec(address, prof.name, layout)


def station_table(stations: list[StationSpec]) -> dict[str, object]:
    """The table the dissector reads: every profile's layouts, aliases, default layouts, stations."""
    from profidrive_cli.drives.profile import all_profiles
    from profidrive_cli.drives.wirefields import layout_table
    layouts: dict[str, object] = {}
    aliases: dict[str, str] = {}
    defaults: dict[str, str] = {}
    for prof in all_profiles():
        defaults[prof.name] = prof.default_layout
        for a in prof.aliases:
            aliases[a] = prof.name
        for lname in prof.layouts:
            layouts[f"{prof.name}:{lname}"] = layout_table(prof, lname)
    return {"stations": {s.address: f"{s.profile}:{s.layout}" for s in stations},
            "aliases": aliases, "defaults": defaults, "layouts": layouts}


def _lua(v: object, indent: str = "") -> str:
    if v is None:
        return "nil"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v) if v == v and abs(v) != float("inf") else "0"
    if isinstance(v, str):
        out = ['"']
        for ch in v:
            if ch in '"\\':
                out.append("\\" + ch)
            elif ch == "\n":
                out.append("\\n")
            elif ord(ch) < 32:
                out.append(f"\\{ord(ch)}")
            else:
                out.append(ch)
        out.append('"')
        return "".join(out)
    if isinstance(v, (list, tuple)):
        inner = indent + "  "
        return "{\n" + "".join(f"{inner}{_lua(x, inner)},\n" for x in v) + indent + "}"
    if isinstance(v, dict):
        inner = indent + "  "
        items = []
        for k, x in v.items():
            if x is None:
                continue
            key = f"[{k}]" if isinstance(k, int) else f"[{_lua(str(k))}]"
            items.append(f"{inner}{key} = {_lua(x, inner)},\n")
        return "{\n" + "".join(items) + indent + "}"
    raise TypeError(f"cannot write {type(v).__name__} as Lua")


def render_station_table(stations: list[StationSpec]) -> str:
    names = " ".join(f"{s.address}={s.profile}:{s.layout}" for s in stations) or "(none)"
    return (f"-- pdrive station table for pdrive.lua: generated by pdrive {__version__} "
            f"(pdrive wireshark install) from profiles/*.yaml; do not edit, run the install again.\n"
            f"-- stations: {names}\n"
            f"PDRIVE_STATIONS = {_lua(station_table(stations))}\n")


# ---------------------------------------------------------------------------------------------
# extcap launcher

def launcher_text(platform: str = sys.platform, python: str = sys.executable) -> tuple[str, str]:
    """(file name, text) of the extcap launcher: runs `python -m profidrive_cli wireshark extcap`
    with this interpreter, and finds the package also when it runs from a source checkout."""
    pkg_parent = str(Path(__file__).resolve().parent.parent.parent)
    if platform.startswith("win"):
        return (EXTCAP_NAME + ".bat",
                "@echo off\r\n"
                f"set \"PYTHONPATH={pkg_parent};%PYTHONPATH%\"\r\n"
                f"\"{python}\" -m profidrive_cli wireshark extcap %*\r\n")
    return (EXTCAP_NAME,
            "#!/bin/sh\n"
            "# Wireshark extcap launcher written by `pdrive wireshark install`: pdrive sniff as a\n"
            "# live capture interface. Runs pdrive with the Python it was installed with.\n"
            f"PYTHONPATH={shlex.quote(pkg_parent)}${{PYTHONPATH:+:$PYTHONPATH}}\n"
            "export PYTHONPATH\n"
            f"exec {shlex.quote(python)} -m profidrive_cli wireshark extcap \"$@\"\n")


# ---------------------------------------------------------------------------------------------
# install

@dataclass
class Installed:
    plugins_dir: Path
    files: list[Path] = field(default_factory=list)
    extcap: list[Path] = field(default_factory=list)
    stations: list[StationSpec] = field(default_factory=list)


def install(plugins_dir: str | None = None, stations: Sequence[str] = (), extcap_dir: str | None = None,
            with_extcap: bool = True) -> Installed:
    """Write pdrive.lua, pdrive_stations.lua and (with_extcap) the extcap launcher into each extcap
    folder. The personal folders are created when missing; a folder given with --dir / --extcap-dir
    must exist."""
    specs = [parse_station(s) for s in stations]
    seen: dict[int, str] = {}
    for s in specs:
        if s.address in seen:
            raise UsageError(f"--station: station {s.address} given twice")
        seen[s.address] = s.profile
    personal_plugins, personal_extcap = personal_dirs()
    pdir = Path(plugins_dir) if plugins_dir else personal_plugins
    edirs = [Path(extcap_dir)] if extcap_dir else personal_extcap
    # everything is checked and generated before the first file is written
    if not plugins_dir:
        _mkdir(pdir)
    if with_extcap and not extcap_dir:
        for d in edirs:
            _mkdir(d)
    lua = dissector_source()
    table = render_station_table(specs)
    name, launcher = launcher_text()
    targets = [(pdir / DISSECTOR, lua, "dissector"), (pdir / STATION_TABLE, table, "station table")]
    if with_extcap:
        targets += [(d / name, launcher, "extcap launcher") for d in edirs]
    for path, _, what in targets:
        check_output_path(path, what)
    result = Installed(pdir, stations=specs)
    for path, text, what in targets:
        write_text_atomic(path, text, what)
        if what == "extcap launcher":
            result.extcap.append(path)
            if not sys.platform.startswith("win"):
                os.chmod(path, 0o755)
        else:
            result.files.append(path)
    return result


def _mkdir(d: Path) -> None:
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise UsageError(f"cannot create {d}: {e.strerror or e}") from None
