"""The one family table: a profile's `family:` -> where its codec, Drive class, sim model and config live.

Each row names its parts as lazy references ("module" or "module:attribute" strings, the way
python-can's BACKENDS table names its interfaces), so that reading the table imports nothing: the codec
is imported when a profile of the family is decoded or driven, the sim model only by sim/plant.py
(drives/ never imports sim/; the sim reference is a name the sim layer resolves).

    codec        the family module: make_drive(channel, profile, layout), decode_area(profile, layout,
                 direction, data), and the optional hooks the shared code asks it for by name
                 (param_value, effective_scale, input_words, FORMATTERS, PARSERS)
    drive_class  the Drive subclass make_drive returns: its class-level facts (supports_jog,
                 monitor_mapping, area_shape, ...) are readable before a station is connected
    sim_model    make_model(profile, **options) -> SlaveModel in sim/; None: the station is a plain DP-V0
                 slave with the profile's ident and configurations
    config       the reader of the family's own profile keys: config(profile) -> its config type
    core_config  for a family on the PROFIdrive core: profile -> drives.profidrive.ProfidriveConfig
                 built from the family's own keys; None: the profile's `profidrive:` section is read
    wire_fields  where each field of its areas sits on the wire (drives/wirefields.py, the Wireshark
                 station table) for a family whose areas are not PROFIdrive PPO words; None: PPO words
    sim_diag_len the Slave_Diag length its card allows (the simulator answers with it before the
                 model is built, sim/lazy.py); 6 = no room for extended diagnosis

A profile whose `family:` is not a row here is refused when it loads (drives/profile.py, file:line).
A new family is one row here, its codec package, its sim model and its profile (docs/architecture.md) --
or, without forking, a plug-in: a distribution with an entry point in the group `profidrive_cli.families`
that names a Family row (or a function returning one) whose `profiles` names the folder of its
profiles (docs/plugins.md). Plug-ins are read only when a name is not in the table above (or all
families are listed), so a command on the shipped families never scans the installed distributions.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from types import ModuleType
from typing import TYPE_CHECKING, Any, Callable, Protocol

from profidrive_cli import UsageError

if TYPE_CHECKING:
    from pathlib import Path

# The table imports nothing of drives/ (drives/__init__, drives.profile and the core's config ask it;
# drives.base -> drives.values -> drives would close an import cycle): a profile is what has a name
# and a family, a Drive / CyclicChannel / ProfidriveConfig are the codec's own (Any here).


class ProfileLike(Protocol):
    @property
    def name(self) -> str: ...

    @property
    def family(self) -> str: ...


@dataclass(frozen=True)
class Family:
    name: str
    codec: str
    drive_class: str
    sim_model: str | None
    config: str
    core_config: str | None = None
    wire_fields: str | None = None
    sim_diag_len: int = 6
    #: a plug-in's profile folder: "package" (its profiles/ folder) or "package:folder"; None for the
    #: shipped families (profiles/ of pdrive)
    profiles: str | None = None


_PKG = "profidrive_cli.drives"
_SIM = "profidrive_cli.sim"

FAMILIES: dict[str, Family] = {f.name: f for f in (
    Family("fuji", f"{_PKG}.fuji", f"{_PKG}.fuji.drive:FujiDrive", f"{_SIM}.fuji:make_model",
           f"{_PKG}.fuji.config:fuji_config", f"{_PKG}.fuji.config:profidrive_config"),
    Family("moeller", f"{_PKG}.moeller", f"{_PKG}.moeller:MoellerDrive", f"{_SIM}.moeller:make_model",
           f"{_PKG}.moeller:moeller_config"),
    Family("profidrive", f"{_PKG}.profidrive", f"{_PKG}.profidrive.drive:ProfidriveDrive",
           f"{_SIM}.dpv1_axis:make_model", f"{_PKG}.profidrive.config:ProfidriveConfig.from_profile"),
    Family("toyo", f"{_PKG}.toyo", f"{_PKG}.toyo.drive:ToyoDrive", f"{_SIM}.toyo:make_model",
           f"{_PKG}.toyo.config:toyo_config", f"{_PKG}.toyo.config:profidrive_config",
           wire_fields=f"{_PKG}.wirefields:toyo_fields", sim_diag_len=15),
    Family("yaskawa", f"{_PKG}.yaskawa", f"{_PKG}.yaskawa.drive:YaskawaDrive", f"{_SIM}.yaskawa:make_model",
           f"{_PKG}.yaskawa.config:family_config", wire_fields=f"{_PKG}.wirefields:yaskawa_fields"),
)}


#: the entry-point group of family plug-ins (docs/plugins.md)
ENTRY_POINT_GROUP = "profidrive_cli.families"

#: the plug-ins' rows, read once on first need: name -> Family; and why a plug-in did not load
_plugins: dict[str, Family] | None = None
_plugin_problems: list[str] = []


def plugins() -> dict[str, Family]:
    """The families installed plug-ins add (entry points of ENTRY_POINT_GROUP), read once. A plug-in
    that does not load, or names a family pdrive already has, is left out; why is said by known()."""
    global _plugins
    if _plugins is None:
        from importlib.metadata import entry_points
        found: dict[str, Family] = {}
        for ep in sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
            where = f"plug-in {ep.value!r} (entry point {ep.name!r})"
            try:
                obj = ep.load()
                row = obj() if callable(obj) and not isinstance(obj, Family) else obj
            except Exception as e:                      # a broken plug-in must not break pdrive
                _plugin_problems.append(f"{where} did not load: {type(e).__name__}: {e}")
                continue
            if not isinstance(row, Family):
                _plugin_problems.append(f"{where} gives {type(row).__name__}, not a Family row")
            elif row.name in FAMILIES or row.name in found:
                _plugin_problems.append(f"{where}: family {row.name!r} is already known")
            else:
                found[row.name] = row
        _plugins = found
    return _plugins


def reset_plugins() -> None:
    """Forget the plug-ins read so far (tests, or after installing one in a running process)."""
    global _plugins
    _plugins = None
    _plugin_problems.clear()


def find(name: str) -> Family | None:
    """The row of a family: the table first, then the plug-ins."""
    fam = FAMILIES.get(name)
    return fam if fam is not None else plugins().get(name)


def all_families() -> dict[str, Family]:
    """The table and the plug-ins' rows."""
    return {**FAMILIES, **plugins()}


def known() -> str:
    """The family names, sorted, for messages: 'fuji, moeller, ...' (and why a plug-in is missing)."""
    names = ", ".join(sorted(all_families()))
    return names + "".join(f"; {p}" for p in _plugin_problems)


def unknown_family(name: object) -> str | None:
    """None for a family in the table or a plug-in, else the one-line complaint (the caller adds
    file:line)."""
    if isinstance(name, str) and find(name) is not None:
        return None
    return f"family {name!r} unknown (known: {known()})"


def family_of(profile: ProfileLike) -> Family:
    fam = find(profile.family)
    if fam is None:
        raise UsageError(f"profile {profile.name}: no codec for family '{profile.family}' "
                         f"(known: {known()})")
    return fam


def plugin_profile_dirs() -> list["Path"]:
    """The profile folders the family plug-ins bring (their rows' `profiles`), in family order."""
    from importlib.resources import files
    from pathlib import Path
    out: list[Path] = []
    for fam in sorted(plugins().values(), key=lambda f: f.name):
        if fam.profiles is None:
            continue
        pkg, _, folder = fam.profiles.partition(":")
        try:
            path = Path(str(files(pkg) / (folder or "profiles")))
        except (ImportError, TypeError, ValueError) as e:
            _plugin_problems.append(f"family {fam.name!r}: profiles {fam.profiles!r}: {e}")
            continue
        out.append(path)
    return out


def resolve(ref: str) -> Any:
    """'package.module' -> the module; 'package.module:Name.attr' -> that attribute of it."""
    mod_name, _, attrs = ref.partition(":")
    obj: Any = importlib.import_module(mod_name)
    for a in filter(None, attrs.split(".")):
        obj = getattr(obj, a)
    return obj


def codec_module(profile: ProfileLike) -> ModuleType:
    mod: ModuleType = resolve(family_of(profile).codec)
    return mod


def drive_class(profile: ProfileLike) -> Any:
    """The family's Drive class: its class-level facts without a bus."""
    cls: Any = resolve(family_of(profile).drive_class)
    return cls


def make_drive(channel: Any, profile: ProfileLike, layout: str | None = None) -> Any:
    fn: Callable[[Any, ProfileLike, str | None], Any] = codec_module(profile).make_drive
    return fn(channel, profile, layout)


def decode_area(profile: ProfileLike, layout: str, direction: str, data: bytes) -> dict[str, Any]:
    fn: Callable[[ProfileLike, str, str, bytes], dict[str, Any]] = codec_module(profile).decode_area
    return fn(profile, layout, direction, data)


def family_config(profile: ProfileLike) -> object:
    """The family's own profile keys, read and checked (file:line), as its config type."""
    fn: Callable[[ProfileLike], object] = resolve(family_of(profile).config)
    return fn(profile)


def core_config_reader(profile: ProfileLike) -> Callable[[ProfileLike], Any] | None:
    """The family's builder of the PROFIdrive core's config from its own keys; None: the profile's
    `profidrive:` section is read (or the family is not on the core)."""
    fam = find(profile.family)
    if fam is None or fam.core_config is None:
        return None
    fn: Callable[[ProfileLike], Any] = resolve(fam.core_config)
    return fn


def wire_fields_ref(profile: ProfileLike) -> str | None:
    """The 'module:function' reference of the family's own wire-field layout; None: PPO words."""
    return family_of(profile).wire_fields


def sim_diag_len(family: str) -> int:
    """The Slave_Diag length the family's card allows (6 for a family not in the table)."""
    fam = find(family)
    return fam.sim_diag_len if fam is not None else 6


def sim_model_ref(profile: ProfileLike) -> str | None:
    """The 'module:make_model' reference of the family's sim model, for sim/plant.py to import (drives/
    does not import sim/); None: no model (a plain DP-V0 slave)."""
    return family_of(profile).sim_model
