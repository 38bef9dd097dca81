"""The plug-in interface under the version promise: the names a family plug-in fills, implements or
uses, with their signatures (docs/plugins.md, "The plug-in interface (promised)"; docs/versioning.md).

Everything else of drives/ and sim/ stays below the promise, as docs/versioning.md says of modules
below profidrive_cli.api: a plug-in that overrides or calls it does so at its own risk.
tests/test_plugin_contract.py holds the code and the doc's table to PLUGIN_INTERFACE: each name exists
with this signature, the table lists exactly these names, and the demo plug-in (tests/data/plugin_demo)
runs on them alone.

This module imports nothing of pdrive (drives/ must not import sim/, and drives.registry must not import
drives.base): the owners are named by their import paths in OWNERS.
"""

from __future__ import annotations

from typing import Final, Literal, NamedTuple

#: "must": the plug-in implements it (the base has no default, or its default does nothing a card
#: wants); "may": the plug-in may override it, pdrive's default applies otherwise; "pdrive": pdrive
#: provides it and the plug-in uses it (calls it, constructs it, raises it, reads it), never overrides it
Need = Literal["must", "may", "pdrive"]


class Promise(NamedTuple):
    #: "Owner.attribute", or "Owner" for the class itself (a dataclass: its constructor)
    name: str
    #: as documented: "(self, timeout: float = 5.0) -> DriveStatus" for a method (cls first for a
    #: class method), "@property -> bool" for a property, ": bool = False" for an attribute or a
    #: dataclass field, "class DriveError(BusError)" for an exception class
    signature: str
    need: Need


#: where each owner of a promised name is imported from ("module:Class"). "codec" is the module a
#: Family row's `codec` names (the plug-in's own); pdrive's PROFIdrive core is the reference one.
OWNERS: Final[dict[str, str]] = {
    "Family": "profidrive_cli.drives.registry:Family",
    "codec": "profidrive_cli.drives.profidrive",
    "Drive": "profidrive_cli.drives.base:Drive",
    "CyclicChannel": "profidrive_cli.drives.base:CyclicChannel",
    "DriveStatus": "profidrive_cli.drives.base:DriveStatus",
    "ParamInfo": "profidrive_cli.drives.base:ParamInfo",
    "ParamValue": "profidrive_cli.drives.base:ParamValue",
    "FaultRecord": "profidrive_cli.drives.base:FaultRecord",
    "DriveError": "profidrive_cli.drives.base:DriveError",
    "ParamError": "profidrive_cli.drives.base:ParamError",
    "SlaveModel": "profidrive_cli.sim.model:SlaveModel",
}

_OPT = "str | None"

PLUGIN_INTERFACE: Final[tuple[Promise, ...]] = (
    # -- the registry row (entry point group profidrive_cli.families) --------------------------
    Promise("Family.name", ": str", "must"),
    Promise("Family.codec", ": str", "must"),
    Promise("Family.drive_class", ": str", "must"),
    Promise("Family.sim_model", f": {_OPT}", "must"),
    Promise("Family.config", ": str", "must"),
    Promise("Family.core_config", f": {_OPT} = None", "may"),
    Promise("Family.wire_fields", f": {_OPT} = None", "may"),
    Promise("Family.sim_diag_len", ": int = 6", "may"),
    Promise("Family.profiles", f": {_OPT} = None", "may"),
    # -- the codec module the row's `codec` names -------------------------------------------------
    Promise("codec.make_drive",
            "(channel: CyclicChannel, profile: Profile, layout: str | None = None) -> Drive", "must"),
    Promise("codec.decode_area",
            "(profile: Profile, layout: str, direction: str, data: bytes) -> dict[str, Any]", "must"),
    # -- Drive: what a family implements ----------------------------------------------------------
    Promise("Drive.cycle", "(self) -> DriveStatus", "must"),
    Promise("Drive.start", "(self, timeout: float = 5.0) -> DriveStatus", "must"),
    Promise("Drive.stop", "(self, mode: str = 'normal', wait: bool = True, timeout: float = 30.0) "
                          "-> DriveStatus", "must"),
    Promise("Drive.set_speed", "(self, percent: float) -> None", "must"),
    Promise("Drive.reset_fault", "(self, timeout: float = 5.0) -> DriveStatus", "must"),
    Promise("Drive.status", "(self) -> DriveStatus", "must"),
    Promise("Drive.read_param", "(self, code: str) -> ParamValue", "must"),
    Promise("Drive.write_resolved", "(self, info: ParamInfo, value: float | int) -> ParamValue",
            "must"),
    Promise("Drive.fault_history", "(self) -> list[FaultRecord]", "must"),
    # -- Drive: what a family may override ---------------------------------------------------------
    Promise("Drive.family", ": str = ''", "may"),
    Promise("Drive.has_param_channel", "@property -> bool", "may"),
    Promise("Drive.max_frequency", "(self) -> float", "may"),
    Promise("Drive.save", "(self) -> None", "may"),
    Promise("Drive.save_support", "(self) -> str", "may"),
    Promise("Drive.supports_jog", ": bool = False", "may"),
    Promise("Drive.jog_refusal", "(self) -> str", "may"),
    Promise("Drive.jog_refusal_for", "(cls, profile: Any, layout: str) -> str | None", "may"),
    Promise("Drive.jog", "(self, on: bool = True, reverse: bool = False) -> None", "may"),
    Promise("Drive.jog_reference", "(self) -> str | None", "may"),
    Promise("Drive.status_flag_names", "(cls, profile: Any, layout: str) -> list[str]", "may"),
    Promise("Drive.param_label_for", "(cls, profile: Any, code: str) -> tuple[str, Any]", "may"),
    Promise("Drive.param_info", "(self, code: str) -> ParamInfo", "may"),
    Promise("Drive.read_many",
            "(self, codes: Sequence[str]) -> Iterator[tuple[str, ParamValue | DriveError | UsageError]]",
            "may"),
    Promise("Drive.normalise_area",
            "(cls, profile: Any, direction: str, area: dict[str, Any]) -> dict[str, Any]", "may"),
    Promise("Drive.set_prm_user_data", "(cls, profile: Any, user_prm: bytes) -> bytes", "may"),
    # -- Drive: what pdrive provides ---------------------------------------------------------------
    Promise("Drive.__init__", "(self, channel: CyclicChannel, profile: Any, layout: str | None = None)",
            "pdrive"),
    Promise("Drive.write_param", "(self, code: str, value: float | int) -> ParamValue", "pdrive"),
    Promise("Drive.channel", ": CyclicChannel", "pdrive"),
    Promise("Drive.profile", ": Any", "pdrive"),
    Promise("Drive.layout", ": str", "pdrive"),
    Promise("Drive.cycles_until", "(self, predicate: Callable[[DriveStatus], bool], timeout: float, "
                                  "what: str) -> DriveStatus", "pdrive"),
    Promise("Drive._notify_motion", "(self) -> None", "pdrive"),
    Promise("CyclicChannel.exchange", "(self, outputs: bytes) -> bytes", "pdrive"),
    Promise("CyclicChannel.now", "(self) -> float", "pdrive"),
    Promise("DriveStatus", "(state: str, running: bool, fault: bool, flags: dict[str, bool], "
                           "speed_percent: float | None, speed_hz: float | None, "
                           "reference_percent: float | None = None, fault_code: str | None = None, "
                           "raw: dict[str, int] = <factory>, torque_ref_percent: float | None = None, "
                           "torque_percent: float | None = None)", "pdrive"),
    Promise("ParamValue", "(code: str, name: str, raw: int, value: float | int, unit: str = '', "
                          "text: str | None = None)", "pdrive"),
    Promise("ParamInfo", "(code: str, name: str, unit: str, param: Any, access: str, ref: Any = None)",
            "pdrive"),
    Promise("FaultRecord", "(position: str, raw: int, codes: list[str], meanings: list[str])", "pdrive"),
    Promise("DriveError", "class DriveError(BusError)", "pdrive"),
    Promise("ParamError", "class ParamError(DriveError)", "pdrive"),
    Promise("ParamError.__init__", "(self, message: str, number: int | None = None)", "pdrive"),
    # -- the simulator's model (the row's `sim_model`: make_model(profile, **options)) -------------
    Promise("SlaveModel.__init__", "(self, ident: int, cfgs: dict[str, bytes] | None = None, "
                                   "name: str = 'DP-V0 slave', user_prm_len: int | None = None, "
                                   "max_diag_len: int = 6)", "pdrive"),
    Promise("SlaveModel.layout", ": str | None", "pdrive"),
    Promise("SlaveModel.input_len", ": int", "pdrive"),
    Promise("SlaveModel.output_len", ": int", "pdrive"),
    Promise("SlaveModel.family", ": str = 'plain'", "may"),
    Promise("SlaveModel.data_exchange", "(self, outputs: bytes, now: float) -> bytes", "must"),
    Promise("SlaveModel.tick", "(self, now: float) -> None", "may"),
    Promise("SlaveModel.next_due", "(self, now: float) -> float | None", "may"),
    Promise("SlaveModel.catch_up", "(self, times: list[float], then: float | None = None) -> None", "may"),
    Promise("SlaveModel.on_leave_data_exchange", "(self, now: float, reason: str) -> None", "may"),
    Promise("SlaveModel.ext_diag", "(self) -> bytes", "may"),
)

#: promised names whose code has not arrived yet; the contract test checks each once it exists
PENDING: Final[frozenset[str]] = frozenset()

#: what pdrive ships for a plug-in to build on instead of writing its own (the PROFIdrive core), by
#: import path ("module:attribute"), with the promised name each one fills
BUILDING_BLOCKS: Final[dict[str, str]] = {
    "profidrive_cli.drives.profidrive:make_drive": "codec.make_drive",
    "profidrive_cli.drives.profidrive:decode_area": "codec.decode_area",
    "profidrive_cli.drives.profidrive.drive:ProfidriveDrive": "Family.drive_class",
    "profidrive_cli.drives.profidrive.config:ProfidriveConfig.from_profile": "Family.config",
    "profidrive_cli.sim.profidrive_model:ProfidriveModel": "Family.sim_model",
}


def promised(owner: str, need: Need | None = None) -> dict[str, Promise]:
    """The promised names of `owner` ("Drive", "SlaveModel", ...) without the owner, optionally only
    those of one `need`: {"cycle": Promise("Drive.cycle", ...), ...}."""
    out: dict[str, Promise] = {}
    for p in PLUGIN_INTERFACE:
        head, _, attr = p.name.partition(".")
        if head == owner and attr and (need is None or p.need == need):
            out[attr] = p
    return out
