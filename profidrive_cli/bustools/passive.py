"""The passive PROFIdrive view of a running bus (`pdrive sniff --station 3=fuji-g1`): each given
station's Data_Exchange outputs and inputs as the drive sees them, from captured telegrams alone.

Built on the families' offline decoders (drives.decode_area, as `pdrive decode` uses them) and
their Drive classes' normalise_area, which reads the area in common words: command and state in the
codec's words, reference and actual in Hz, the parameter channel (a PKW channel, a register area) as
requests and answers with the card's native codes ("read F07", "F07 = 5.0 s"). No family is named
here. Never transmits; sans-IO (dp.capture.Captured in, plain dicts and one-line texts out).

The layout comes from `--station ADDR=PROFILE:LAYOUT`, else from the Chk_Cfg the master sent (when
the capture saw it), else the profile's default layout (or the one layout whose lengths fit).
The max frequency that turns N2 words into Hz is the profile's default until an answer to a read of
the profile's max-frequency parameter goes by on the wire; from then on that value.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from types import ModuleType
from typing import TYPE_CHECKING, Any

from profidrive_cli import UsageError
from profidrive_cli.dp import services as S
from profidrive_cli.fdl import frames as F

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.dp.capture import Captured
    from profidrive_cli.drives.profile import Profile

#: a family codec's decoded area (drives/<family>/codec.py decode_area): its shape is the family's,
#: its values JSON's; and the common `drive` object made from it (docs/json.md), whose `param` and
#: values come from that area
Area = dict[str, Any]
DriveObject = dict[str, Any]
#: a codec's decode_area (with or without max_hz) and whether it takes max_hz
Decoder = tuple[Callable[..., Area], bool]


@dataclass
class Watched:
    """One station given with --station."""
    address: int
    profile: Profile
    layout: str | None = None        # as given; None: inferred
    seen_cfg: bytes | None = None    # the last Chk_Cfg the master sent it
    fmax: float | None = None        # learnt from an answer of the max-frequency parameter
    #: the family's (decode_area, takes max_hz), looked up at the first area
    decoder: Decoder | None = field(default=None, repr=False, compare=False)

    @property
    def name(self) -> str:
        return self.profile.name

    def layout_for(self, direction: str, n: int) -> str | None:
        """The layout to decode an area of n octets with (None: none fits)."""
        lays = self.profile.layouts
        if self.layout is not None:
            return self.layout
        if self.seen_cfg is not None:
            for name, lay in lays.items():
                if lay.cfg == self.seen_cfg:
                    return name
        d = self.profile.default_layout

        def fits(name: str) -> bool:
            lay = lays[name]
            return (lay.output_len if direction == "request" else lay.input_len) == n
        if fits(d):
            return d
        fitting = [name for name in lays if fits(name)]
        return fitting[0] if len(fitting) == 1 else None


def parse_station(text: str) -> tuple[int, str, str | None]:
    """'3=fuji-g1' or '6=moeller:ppo1' -> (3, 'fuji-g1', None) / (6, 'moeller', 'ppo1')."""
    addr, eq, rest = text.partition("=")
    name, _, layout = rest.partition(":")
    addr, name, layout = addr.strip(), name.strip(), layout.strip()
    if not eq or not name or not (addr.isascii() and addr.isdigit()) or not 0 <= int(addr) <= 125:
        raise UsageError(f"--station {text[:60]!r}: give ADDRESS=PROFILE[:LAYOUT] with address "
                         f"0..125, e.g. 3=fuji-g1 or 6=moeller:ppo1")
    return int(addr), name, layout or None


def watch_list(specs: Iterable[str]) -> dict[int, Watched]:
    """--station values -> {address: Watched}; unknown profiles and layouts refused (exit 2)."""
    from profidrive_cli.drives.profile import load_profile
    out: dict[int, Watched] = {}
    for text in specs:
        addr, name, layout = parse_station(text)
        if addr in out:
            raise UsageError(f"--station {text}: station {addr} given twice")
        prof = load_profile(name)
        if layout is not None and layout not in prof.layouts:
            raise UsageError(f"--station {text}: {prof.name} has no layout '{layout}' "
                             f"(known: {', '.join(prof.layouts)})")
        out[addr] = Watched(addr, prof, layout)
    return out


def is_data_exchange(f: F.Frame) -> bool:
    """A Data_Exchange request or its data reply (no SAPs, user data)."""
    if f.sd in (F.SC, F.SD4) or f.dsap is not None or f.ssap is not None:
        return False
    if f.is_request:
        return f.function in (F.SRD_LOW, F.SRD_HIGH)
    return bool(f.data)


#: decoded areas kept per decoder: a station's area mostly repeats its previous one (the same
#: command, reference and parameter request cycle after cycle); cleared when this many are kept
AREA_CACHE_MAX = 1024


class PassiveDecoder:
    """Feed captured frames; decode() gives the `drive` object of a watched station's frame (the
    same object for the same station, direction, octets, layout and max frequency: do not change
    it)."""

    def __init__(self, watched: dict[int, Watched]):
        self.watched = watched
        self._areas: dict[tuple[int, str, bytes, str | None, float | None], DriveObject] = {}

    def decode(self, c: Captured) -> DriveObject | None:
        f = c.frame
        if f is None or f.sd in (F.SC, F.SD4):
            return None
        if f.is_request and f.da in self.watched and f.dsap == S.SAP_CHK_CFG:
            self.watched[f.da].seen_cfg = bytes(f.data)
            return None
        if not is_data_exchange(f):
            return None
        direction = "request" if f.is_request else "response"
        st = self.watched.get(f.da if f.is_request else f.sa)
        if st is None:
            return None
        return self._decode_area(st, direction, bytes(f.data))

    def _decode_area(self, st: Watched, direction: str, data: bytes) -> DriveObject:
        layout = st.layout_for(direction, len(data))
        key = (st.address, direction, data, layout, st.fmax)
        d = self._areas.get(key)
        if d is None:
            if len(self._areas) >= AREA_CACHE_MAX:
                self._areas.clear()
            d = self._areas[key] = _decode_new(st, direction, data, layout)
        if d.get("param") and direction == "response":
            _learn_fmax(st, d["param"])
        return d


def _decode_new(st: Watched, direction: str, data: bytes, layout: str | None) -> DriveObject:
    base: DriveObject = {"station": st.address, "profile": st.name, "direction": direction}
    if layout is None:
        base["error"] = (f"{len(data)} octets fit no layout of {st.name} "
                         f"({', '.join(st.profile.layouts)})")
        return base
    base["layout"] = layout
    try:
        area = _decode(st, layout, direction, data)
    except (UsageError, ValueError) as e:
        base["error"] = str(e)
        return base
    d = normalise(st.profile, direction, area)
    return {**base, **d}


#: family codec -> (its decode_area, whether that takes max_hz): looked up (inspect.signature) once
#: per codec, not per frame
_DECODERS: dict[ModuleType, Decoder] = {}


def _decoder(profile: Profile) -> Decoder:
    from profidrive_cli.drives import codec_module
    mod = codec_module(profile)
    hit = _DECODERS.get(mod)
    if hit is None:
        fn = mod.decode_area
        hit = _DECODERS[mod] = (fn, "max_hz" in inspect.signature(fn).parameters)
    return hit


def _decode(st: Watched, layout: str, direction: str, data: bytes) -> Area:
    if st.decoder is None:
        st.decoder = _decoder(st.profile)
    fn, takes_max_hz = st.decoder
    if st.fmax is not None and takes_max_hz:
        return fn(st.profile, layout, direction, data, max_hz=st.fmax)
    return fn(st.profile, layout, direction, data)


def _learn_fmax(st: Watched, param: dict[str, Any]) -> None:
    if param.get("code") and param.get("code") == st.profile.max_frequency_param \
            and isinstance(param.get("value"), (int, float)) and param["value"] > 0:
        st.fmax = float(param["value"])


# -- one family's decoded area -> the common `drive` object -------------------------------------

def normalise(profile: Profile, direction: str, area: Area) -> DriveObject:
    """The common fields of a decoded area: command / control (request), state / status
    (response), reference_hz / actual_hz, param (the parameter channel) -- in the family's words,
    its Drive class's normalise_area -- and text (one line)."""
    from profidrive_cli.drives import drive_class
    d: DriveObject = drive_class(profile).normalise_area(profile, direction, area)
    d["text"] = drive_text(d)
    return d


def drive_text(d: DriveObject) -> str:
    """The decoded part of a sniff line: 'operate, reference 30.00 Hz; read F07'."""
    parts = []
    if "command" in d:
        parts.append(str(d["command"]))
    if d.get("reference_hz") is not None:
        parts.append(f"reference {d['reference_hz']:.2f} Hz")
    if "state" in d:
        parts.append(str(d["state"]))
    if d.get("actual_hz") is not None:
        parts.append(f"actual {d['actual_hz']:.2f} Hz")
    text = ", ".join(parts)
    if d.get("param"):
        text += ("; " if text else "") + d["param"]["text"]
    return text


def frame_suffix(d: DriveObject) -> str:
    """What `pdrive sniff --station` appends to a frame's line."""
    arrow = "->" if d["direction"] == "request" else "<-"
    who = f"drive {d['station']} ({d['profile']}"
    who += f" {d['layout']})" if d.get("layout") else ")"
    if "error" in d:
        return f"  | {arrow} {who}: {d['error']}"
    return f"  | {arrow} {who}: {d['text']}"
