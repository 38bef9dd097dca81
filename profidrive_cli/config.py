"""pdrive's config file: named ports, a default port and per-station defaults, and where each
effective setting came from.

Files (YAML, read with datafile.load_yaml: bounded, file:line errors, exit 2):

    user     $XDG_CONFIG_HOME/pdrive/config.yaml (default ~/.config/pdrive/config.yaml; on Windows
             %APPDATA%\\pdrive\\config.yaml)
    project  the nearest pdrive.yaml in the current folder or one above it (the search stops at
             the first one found, and at the file-system root);
             PDRIVE_CONFIG=FILE names the file to use instead of the search (it must exist)

Precedence, highest first: command-line option > environment variable (PDRIVE_PORT, PDRIVE_BAUD) >
project file > user file > built-in default. A named port's own `baud` / `master_address` count as
file values of that file (above the files' top-level `baud` / `master_address`); a name defined in
both files is taken whole from the project file.

    port: line1                  # default port: a name below or a device / URL
    baud: 19200                  # default baud rate (a number or a name like 187.5k, 1.5M, auto)
    master_address: 2
    ports:
      line1:
        port: /dev/ttyUSB0       # required
        baud: 187500
        master_address: 2
        stations:
          3: {profile: fuji-g1, layout: ppo3, fmax: 60}

A top-level module: imports no layer of pdrive (tests/test_layering.py), only datafile for YAML.
"""

from __future__ import annotations

import os
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.datafile import LineDict

USER_FILE = Path("pdrive") / "config.yaml"
PROJECT_FILE = "pdrive.yaml"
DEFAULT_BAUD = "19200"
DEFAULT_MASTER_ADDRESS = 2
NAME_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_.-]{0,63}$")

_TOP_KEYS = ("port", "baud", "master_address", "ports")
_PORT_KEYS = ("port", "baud", "master_address", "stations")
_STATION_KEYS = ("profile", "layout", "fmax")


class FileText(str):
    """A text from a config file that keeps where it was set (`source`: "FILE:LINE"): wherever
    it is used (a station's profile or layout), a mistake in it is blamed on that line."""
    source: str

    def __new__(cls, value: str, source: str) -> FileText:
        obj = super().__new__(cls, value)
        obj.source = source
        return obj


class FileHz(float):
    """A frequency from a config file (a station's fmax) that keeps where it was set: the fmax
    source label says "from FILE:LINE", not "from --fmax" (session/motion.py)."""
    source: str

    def __new__(cls, value: float, source: str) -> FileHz:
        obj = super().__new__(cls, value)
        obj.source = source
        return obj


def source_of(value: object) -> str | None:
    """Where a config file set `value` ("FILE:LINE": a FileText or FileHz), None for a value given
    any other way (an option, a default)."""
    return value.source if isinstance(value, (FileText, FileHz)) else None


@dataclass(frozen=True)
class Setting:
    """One effective value and where it came from: "option --port", "env PDRIVE_PORT",
    "FILE:LINE" or "default". `project`: a project file (a pdrive.yaml found in the working folder
    or above) set it -- or, for a port chosen by name, chose it or defined it (cli/common.py names
    the file on stderr when the value is used)."""
    value: Any
    source: str
    project: bool = field(default=False, compare=False, repr=False)

    def to_dict(self) -> dict[str, Any]:
        return {"value": self.value, "source": self.source}


_Setting = Setting


@dataclass(frozen=True)
class NamedPort:
    name: str
    port: Setting
    baud: Setting | None = None
    master_address: Setting | None = None
    #: station -> {"profile" | "layout" | "fmax": Setting}
    stations: dict[int, dict[str, Setting]] = field(default_factory=dict)
    source: str = ""


@dataclass(frozen=True)
class ConfigFile:
    kind: str              # "user", "project" or "PDRIVE_CONFIG"
    path: Path
    exists: bool


@dataclass
class Config:
    """The config files read (lowest precedence first) and what they set."""
    files: list[ConfigFile] = field(default_factory=list)
    port: Setting | None = None
    baud: Setting | None = None
    master_address: Setting | None = None
    ports: dict[str, NamedPort] = field(default_factory=dict)


@dataclass(frozen=True)
class Effective:
    """The settings a command uses. port.value is the device / URL (a name resolved), port_name the
    config name it came from (None when none)."""
    port: Setting
    port_name: str | None
    baud: Setting
    master_address: Setting
    stations: dict[int, dict[str, Setting]]
    files: tuple[ConfigFile, ...] = ()

    def station_defaults(self, address: int | None) -> dict[str, Setting]:
        """{"profile" | "layout" | "fmax": Setting} the config gives this station on this port."""
        if address is None:
            return {}
        return dict(self.stations.get(address, {}))

    def to_dict(self) -> dict[str, Any]:
        return {"files": [{"kind": f.kind, "path": str(f.path), "exists": f.exists} for f in self.files],
                "port": {**self.port.to_dict(), "name": self.port_name},
                "baud": self.baud.to_dict(), "master_address": self.master_address.to_dict(),
                "stations": [{"station": a, **{k: s.to_dict() for k, s in d.items()}}
                             for a, d in sorted(self.stations.items())]}


# ------------------------------------------------------------------------------------------ files


def user_config_path(env: Mapping[str, str] | None = None, platform: str | None = None) -> Path:
    """The user file: $XDG_CONFIG_HOME/pdrive/config.yaml where that is set (absolute); else, on
    Windows, %APPDATA%\\pdrive\\config.yaml (where Windows programs keep their settings), elsewhere
    ~/.config/pdrive/config.yaml. `platform`: sys.platform (tests switch it)."""
    env = os.environ if env is None else env
    platform = sys.platform if platform is None else platform
    base = env.get("XDG_CONFIG_HOME") or ""
    if base and Path(base).is_absolute():
        return Path(base) / USER_FILE
    if platform == "win32":
        appdata = env.get("APPDATA") or ""
        root = Path(appdata) if appdata else Path(env.get("USERPROFILE") or Path.home()) / "AppData" / "Roaming"
        return root / USER_FILE
    return Path(env.get("HOME") or Path.home()) / ".config" / USER_FILE


def project_config_path(cwd: str | Path | None = None) -> Path | None:
    """The nearest pdrive.yaml in `cwd` or a folder above it, None when there is none."""
    here = Path(cwd if cwd is not None else os.getcwd()).resolve()
    for d in (here, *here.parents):
        p = d / PROJECT_FILE
        if p.is_file():
            return p
    return None


def config_files(env: Mapping[str, str] | None = None, cwd: str | Path | None = None
                 ) -> list[ConfigFile]:
    """The files that apply, lowest precedence first (the user file, then the project file or the
    one PDRIVE_CONFIG names)."""
    env = os.environ if env is None else env
    user = user_config_path(env)
    files = [ConfigFile("user", user, user.is_file())]
    named = env.get("PDRIVE_CONFIG")
    if named:
        p = Path(named)
        files.append(ConfigFile("PDRIVE_CONFIG", p, p.exists()))
    else:
        found = project_config_path(cwd)
        if found is not None:
            files.append(ConfigFile("project", found, True))
    return files


def load(env: Mapping[str, str] | None = None, cwd: str | Path | None = None) -> Config:
    """Read every config file that applies. UsageError / DataFileError (file:line) on a bad one;
    PDRIVE_CONFIG naming a missing file is an error, a missing user file is not."""
    cfg = Config(files=config_files(env, cwd))
    for f in cfg.files:
        if not f.exists:
            if f.kind == "PDRIVE_CONFIG":
                from profidrive_cli.datafile import DataFileError
                raise DataFileError(f.path, None, "file not found (named by PDRIVE_CONFIG)")
            continue
        _apply(cfg, f.path, f.kind == "project")
    return cfg


def _apply(cfg: Config, path: Path, project: bool = False) -> None:
    from profidrive_cli.datafile import DataFileError, LineDict, load_yaml

    def Setting(value: Any, source: str) -> _Setting:  # every value of this file: its kind travels with it
        return _Setting(value, source, project)
    doc = load_yaml(path, "config file")
    if doc is None:
        return
    if not isinstance(doc, LineDict):
        raise DataFileError(path, getattr(doc, "line", None) or 1, "a config file is a mapping "
                            f"(keys: {', '.join(_TOP_KEYS)})")
    _known(doc, _TOP_KEYS, path, "config file")

    def where(d: LineDict, key: str) -> str:
        return f"{path}:{d.line_of(key)}"
    if "port" in doc:
        cfg.port = Setting(_text(doc, "port", path), where(doc, "port"))
    if "baud" in doc:
        cfg.baud = Setting(_baud(doc, "baud", path), where(doc, "baud"))
    if "master_address" in doc:
        cfg.master_address = Setting(_address(doc, "master_address", path, "master_address"),
                                     where(doc, "master_address"))
    ports = doc.get("ports")
    if ports is None:
        return
    if not isinstance(ports, LineDict):
        raise DataFileError(path, doc.line_of("ports"), "ports: a mapping of names to ports expected")
    for name, entry in ports.items():
        line = ports.line_of(name)
        if not isinstance(name, str) or not NAME_RE.match(name):
            raise DataFileError(path, line, f"ports: {name!r} is not a port name (a letter, then "
                                f"letters, digits, '_', '-', '.')")
        if isinstance(entry, str):
            cfg.ports[name] = NamedPort(name, Setting(entry, f"{path}:{line}"), source=f"{path}:{line}")
            continue
        if not isinstance(entry, LineDict):
            raise DataFileError(path, line, f"ports.{name}: a mapping with `port:` expected")
        _known(entry, _PORT_KEYS, path, f"ports.{name}")
        if "port" not in entry:
            raise DataFileError(path, line, f"ports.{name}: `port:` (the device or URL) is missing")
        dev = _text(entry, "port", path, f"ports.{name}.port")
        if NAME_RE.match(dev) and dev in ports and dev != name:
            raise DataFileError(path, entry.line_of("port"),
                                f"ports.{name}.port: {dev!r} is another name, not a device")
        np = NamedPort(
            name, Setting(dev, where(entry, "port")),
            Setting(_baud(entry, "baud", path, f"ports.{name}.baud"), where(entry, "baud"))
            if "baud" in entry else None,
            Setting(_address(entry, "master_address", path, f"ports.{name}.master_address"),
                    where(entry, "master_address")) if "master_address" in entry else None,
            _stations(entry, path, name, project), f"{path}:{line}")
        cfg.ports[name] = np


def _stations(entry: LineDict, path: Path, name: str, project: bool = False) -> dict[int, dict[str, Setting]]:
    from profidrive_cli.datafile import DataFileError, LineDict
    st = entry.get("stations")
    if st is None:
        return {}
    if not isinstance(st, LineDict):
        raise DataFileError(path, entry.line_of("stations"),
                            f"ports.{name}.stations: a mapping of station addresses expected")
    out: dict[int, dict[str, Setting]] = {}
    for addr, d in st.items():
        line = st.line_of(addr)
        if isinstance(addr, bool) or not isinstance(addr, int) or not 0 <= addr <= 125:
            raise DataFileError(path, line, f"ports.{name}.stations: {addr!r} is not a station "
                                f"address 0..125")
        what = f"ports.{name}.stations.{addr}"
        if not isinstance(d, LineDict):
            raise DataFileError(path, line, f"{what}: a mapping (profile, layout, fmax) expected")
        _known(d, _STATION_KEYS, path, what)
        vals: dict[str, Setting] = {}
        for key in ("profile", "layout"):
            if key in d:
                src = f"{path}:{d.line_of(key)}"
                vals[key] = Setting(FileText(_text(d, key, path, f"{what}.{key}"), src), src, project)
        if "fmax" in d:
            v = d["fmax"]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v <= 10000:
                raise DataFileError(path, d.line_of("fmax"), f"{what}.fmax: {v!r} is not a frequency "
                                    f"in Hz above 0 (at most 10000)")
            src = f"{path}:{d.line_of('fmax')}"
            vals["fmax"] = Setting(FileHz(v, src), src, project)
        out[addr] = vals
    return out


def _known(d: LineDict, keys: tuple[str, ...], path: Path, what: str) -> None:
    from profidrive_cli.datafile import DataFileError
    for k in d:
        if k not in keys:
            raise DataFileError(path, d.line_of(k), f"{what}: unknown key {k!r} (known: "
                                f"{', '.join(keys)})")


def _text(d: LineDict, key: str, path: Path, what: str | None = None) -> str:
    from profidrive_cli.datafile import DataFileError
    v = d[key]
    if not isinstance(v, str) or not v.strip():
        raise DataFileError(path, d.line_of(key), f"{what or key}: a text expected, not {v!r}")
    return v.strip()


def _baud(d: LineDict, key: str, path: Path, what: str | None = None) -> str:
    from profidrive_cli.datafile import DataFileError
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, (int, str)) or (isinstance(v, str) and not v.strip()):
        raise DataFileError(path, d.line_of(key), f"{what or key}: a baud rate (e.g. 187500, "
                            f"1.5M, auto) expected, not {v!r}")
    return str(v).strip()


def _address(d: LineDict, key: str, path: Path, what: str) -> int:
    from profidrive_cli.datafile import DataFileError
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= 125:
        raise DataFileError(path, d.line_of(key), f"{what}: {v!r} is not a bus address 0..125")
    return v


# -------------------------------------------------------------------------------------- resolve

#: a Windows serial device: the one kind of device that looks like a port name
_COM_RE = re.compile(r"^COM[0-9]+$", re.IGNORECASE)


def _not_a_lost_name(port: Setting, cfg: Config) -> None:
    """A port from a file or PDRIVE_PORT that has the form of a port name (never of a device path
    or URL) but names no port of the config files: a mistake in that file:line (or env), refused
    here (exit 2) -- not later as "no such port" (exit 1) of a device nobody meant."""
    v = port.value
    if not isinstance(v, str) or port.source.startswith(("option", "default")):
        return
    if NAME_RE.match(v) and not _COM_RE.match(v):
        from profidrive_cli import UsageError
        names = ", ".join(cfg.ports) or "none"
        raise UsageError(f"{port.source}: port {v!r} is not a port name of the config files "
                         f"(names: {names}) and not a device or URL")



def resolve(port: str | None = None, baud: str | int | None = None,
            master_address: int | None = None, *, env: Mapping[str, str] | None = None,
            config: Config | None = None, cwd: str | Path | None = None) -> Effective:
    """The effective port, baud rate and master address, each with its source. The arguments are
    what the command line (or the API caller) gave: None means not given."""
    env = os.environ if env is None else env
    cfg = config if config is not None else load(env, cwd)
    if port:
        chosen: Setting | None = Setting(port, "option --port")
    elif env.get("PDRIVE_PORT"):
        chosen = Setting(env["PDRIVE_PORT"], "env PDRIVE_PORT")
    else:
        chosen = cfg.port
    named = cfg.ports.get(chosen.value) if chosen is not None else None
    if chosen is not None and named is not None:
        dev = Setting(named.port.value, f"{chosen.source} -> {named.port.source}",
                      chosen.project or named.port.project)
    else:
        dev = chosen if chosen is not None else Setting(None, "default")
        _not_a_lost_name(dev, cfg)

    def pick(given: Any, given_src: str, env_name: str | None, per_port: Setting | None, top: Setting | None,
             default: Any) -> Setting:
        if given is not None:
            return Setting(given, given_src)
        if env_name and env.get(env_name):
            return Setting(env[env_name], f"env {env_name}")
        if per_port is not None:
            return per_port
        if top is not None:
            return top
        return Setting(default, "default")

    b = pick(None if baud is None else str(baud), "option --baud", "PDRIVE_BAUD",
             named.baud if named else None, cfg.baud, DEFAULT_BAUD)
    m = pick(master_address, "option --master-address", None,
             named.master_address if named else None, cfg.master_address, DEFAULT_MASTER_ADDRESS)
    return Effective(dev, named.name if named else None, b, m,
                     dict(named.stations) if named else {}, tuple(cfg.files))

