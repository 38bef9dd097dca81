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

Fast path (issue 38): a drive's area changes every cycle in its speed word, rarely elsewhere. A
family codec's speed_plan (drives/speedplan.py SpeedWord) says where that word sits, which words
the drive object does not read, and the Hz fields the word gives; the rest of the area (the word put
to its class, those words to zero) is decoded the slow way once per its octets and kept (bounded),
the word's fields computed each time -- the same drive object as the slow way
(tests/test_sniff_fast.py), at a fraction of the cost. PassiveDecoder.suffix makes sniff's line
without the drive object: per station and direction a _Lane keeps each rest's line around the Hz
(found by the area as an int with the speed word masked), so a telegram whose speed word changes
costs a lookup, the word's Hz text and a concatenation. A family without a plan is decoded the slow
way.
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
    from profidrive_cli.drives.speedplan import SpeedWord

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


#: the Data_Exchange request functions (is_data_exchange)
_DX_FUNCTIONS = (F.SRD_LOW, F.SRD_HIGH)
_SC, _SD4, _FC_REQ = F.SC, F.SD4, F.FC_REQ

#: decoded areas kept per decoder: a station's area mostly repeats its previous one (the same
#: command, reference and parameter request cycle after cycle); cleared when this many are kept
AREA_CACHE_MAX = 1024


class PassiveDecoder:
    """Feed captured frames; decode() gives the `drive` object of a watched station's frame (the
    same object for the same station, direction, octets, layout and max frequency: do not change
    it)."""

    def __init__(self, watched: dict[int, Watched], fast: bool = True):
        self.watched = watched
        self._areas: dict[tuple[int, str, bytes, str | None, float | None], DriveObject] = {}
        #: the fast path (_fast): off, every area is decoded the slow way (tests compare the two)
        self.fast = fast
        self._plans: dict[tuple[int, str, str, float | None], _Plan | None] = {}
        self._rests: dict[tuple[tuple[int, str, str, float | None], bytes], DriveObject] = {}
        #: suffix()'s lanes by station, of requests and of responses
        self._req_lanes: dict[int, _Lane] = {}
        self._rsp_lanes: dict[int, _Lane] = {}

    def decode(self, c: Captured, speed: bool = True) -> DriveObject | None:
        """The drive object of a watched station's Data_Exchange telegram (None for any other).
        speed=False: its reference / actual fields and text may be those of an area like it with
        another speed word (the recorder's triggers read the command, state, flags and parameter
        channel only): the fast path's rest as it is, no Hz computed, no text written."""
        hit = self._locate(c)
        if hit is None:
            return None
        return self._decode_area(hit[0], hit[1], hit[2], speed)

    def suffix(self, c: Captured) -> str | None:
        """frame_suffix(decode(c)) (None where decode gives None), made without the drive object
        on the fast path: per station and direction a _Lane keeps each rest's line around the Hz
        (the words but the speed word), so a telegram costs a lookup of its rest, the Hz of its
        speed word and a concatenation."""
        f = c.frame
        if f is None:
            return None
        sd = f.sd
        if sd == _SC or sd == _SD4:
            return None
        if f.dsap is not None or f.ssap is not None:
            self._locate(c)                          # (a Chk_Cfg to a watched station: noted)
            return None
        fc = f.fc
        data = f.data
        if fc & _FC_REQ:
            if fc & 0x0F not in _DX_FUNCTIONS:
                return None
            lane = self._req_lanes.get(f.da)
        else:
            if not data:
                return None
            lane = self._rsp_lanes.get(f.sa)
        if lane is None:
            hit = self._locate(c)
            if hit is None:
                return None                          # not a watched station
            lane = self._lane(*hit)
        st = lane.st
        if lane.cfg is not st.seen_cfg or lane.fmax != st.fmax or len(data) != lane.size:
            lane = self._lane(st, lane.direction, data if type(data) is bytes else bytes(data))
        if lane.mask < 0:
            return self._suffix_slow(st, lane.direction, data if type(data) is bytes else bytes(data))
        word = data[lane.hi] << 8 | data[lane.lo]
        key = int.from_bytes(data, "big") & lane.mask | lane.classes[
            0 if not word else 2 if word & 0x8000 else 1]
        e = lane.lines.get(key)
        if e is None:
            e = self._lane_line(lane, key, data if type(data) is bytes else bytes(data))
            if e is None:
                return self._suffix_slow(st, lane.direction,
                                         data if type(data) is bytes else bytes(data))
        hz = lane.hz_texts.get(word)
        if hz is None:
            hz = lane.hz_text(word)
        if e[3] is not None and e[3] != st.fmax:    # an answer of the max-frequency parameter
            st.fmax = e[3]
        return e[0] + hz + e[1] if hz else e[2]

    def _lane(self, st: Watched, direction: str, data: bytes) -> _Lane:
        """The station's lane for areas like `data` (its layout, max frequency and Chk_Cfg as they
        are now), kept until one of them changes; a lane without a plan (mask -1) sends its areas
        the slow way."""
        layout = st.layout_for(direction, len(data))
        plan = None
        if self.fast and layout is not None:
            pkey = (st.address, direction, layout, st.fmax)
            plan = self._plans.get(pkey, _UNKNOWN)
            if plan is _UNKNOWN:
                plan = self._plans[pkey] = _plan(st, direction, layout)
            if plan is not None and plan.size != len(data):
                plan = None
        lane = _Lane(st, direction, len(data), layout, plan)
        (self._req_lanes if direction == "request" else self._rsp_lanes)[st.address] = lane
        return lane

    def _lane_line(self, lane: _Lane, key: int, data: bytes) -> _Line | None:
        """The lane's line pieces for the rest of `data` (kept under `key`); None when the rest
        does not decode (the slow way)."""
        st = lane.st
        found = self._rest(st, lane.direction, data, lane.layout)
        if found is None:
            return None
        plan, _, rest = found
        before, label, after, without = _pieces(rest, plan.hz_key)
        teach = (_taught_fmax(st.profile, rest["param"])
                 if rest.get("param") and lane.direction == "response" else None)
        if len(lane.lines) >= AREA_CACHE_MAX:
            lane.lines.clear()
        e = lane.lines[key] = (before + label, after, without, teach)
        return e

    def _suffix_slow(self, st: Watched, direction: str, data: bytes) -> str:
        """suffix() the way that makes the drive object (decode's)."""
        layout = st.layout_for(direction, len(data))
        if self.fast and (st.address, direction, data, layout, st.fmax) not in self._areas:
            found = self._rest(st, direction, data, layout)
            if found is not None:
                plan, word, rest = found
                if rest.get("param") and direction == "response":
                    _learn_fmax(st, rest["param"])
                before, label, after, without = _pieces(rest, plan.hz_key)
                hz_text = plan.hz_text(word)
                return before + label + hz_text + after if hz_text else without
        return frame_suffix(self._decode_area(st, direction, data))

    def _locate(self, c: Captured) -> tuple[Watched, str, bytes] | None:
        """(the watched station, "request" / "response", the area) of a Data_Exchange telegram;
        None for any other (a Chk_Cfg to a watched station noted: it names the layout)."""
        f = c.frame
        if f is None:
            return None
        sd = f.sd
        if sd == F.SC or sd == F.SD4:
            return None
        fc = f.fc
        if f.dsap is None and f.ssap is None:        # a Data_Exchange request or its data reply
            if fc & F.FC_REQ:
                if fc & 0x0F not in _DX_FUNCTIONS:
                    return None
                st = self.watched.get(f.da)
                direction = "request"
            else:
                if not f.data:
                    return None
                st = self.watched.get(f.sa)
                direction = "response"
            if st is None:
                return None
            data = f.data
            return st, direction, data if type(data) is bytes else bytes(data)
        if fc & F.FC_REQ and f.da in self.watched and f.dsap == S.SAP_CHK_CFG:
            self.watched[f.da].seen_cfg = bytes(f.data)
        return None

    def _decode_area(self, st: Watched, direction: str, data: bytes, speed: bool = True
                     ) -> DriveObject:
        layout = st.layout_for(direction, len(data))
        key = (st.address, direction, data, layout, st.fmax)
        d = self._areas.get(key)
        if d is None and not speed and self.fast:
            found = self._rest(st, direction, data, layout)
            if found is not None:
                d = found[2]
                if d.get("param") and direction == "response":
                    _learn_fmax(st, d["param"])
                return d
        if d is None:
            if len(self._areas) >= AREA_CACHE_MAX:
                self._areas.clear()
            d = self._fast(st, direction, data, layout) if self.fast else None
            if d is None:
                d = _decode_new(st, direction, data, layout)
            self._areas[key] = d
        if d.get("param") and direction == "response":
            _learn_fmax(st, d["param"])
        return d

    def _fast(self, st: Watched, direction: str, data: bytes, layout: str | None) -> DriveObject | None:
        """The area's drive object from its rest's -- the area with its speed word put to the word's
        class and the octets the drive object does not read to zero, decoded the slow way once per
        the rest's octets -- and the word's own fields (the family's speed_plan); None where the
        family has no plan for the area (the slow way then)."""
        found = self._rest(st, direction, data, layout)
        if found is None:
            return None
        plan, word, rest = found
        d = dict(rest)
        for k, v in plan.word.fields(word).items():
            if k in d:
                d[k] = v
        d["text"] = drive_text(d)
        return d

    def _rest(self, st: Watched, direction: str, data: bytes, layout: str | None
              ) -> tuple[_Plan, int, DriveObject] | None:
        """(the plan, the speed word, the rest's drive object) for _fast; None without a plan or
        when the rest does not decode."""
        if layout is None:
            return None
        pkey = (st.address, direction, layout, st.fmax)
        plan = self._plans.get(pkey, _UNKNOWN)
        if plan is _UNKNOWN:
            plan = self._plans[pkey] = _plan(st, direction, layout)
        if plan is None or len(data) != plan.size:
            return None
        at = plan.offset
        word = int.from_bytes(data[at:at + 2], plan.order)
        parts = [data[a:b] if fill is None else fill for a, b, fill in plan.segments]
        parts[plan.slot] = plan.classes[0 if not word else 2 if word & 0x8000 else 1]
        rest_key = (pkey, b"".join(parts))
        rest = self._rests.get(rest_key)
        if rest is None:
            if len(self._rests) >= AREA_CACHE_MAX:
                self._rests.clear()
            rest = self._rests[rest_key] = _decode_new(st, direction, rest_key[1], layout)
        if "error" in rest:
            return None
        return plan, word, rest


class _Plan:
    """A family's SpeedWord for one station, direction and layout, cut for _fast: the area as
    `segments` in order, each (start, end, None) for octets read from the area or (start, end,
    zeros) for an ignored range, and which segment is the speed word (`slot`)."""
    __slots__ = ("word", "offset", "order", "size", "segments", "slot", "classes", "hz_key",
                 "hz_texts")

    def __init__(self, word: SpeedWord, size: int, direction: str):
        self.word, self.offset, self.order, self.size = word, word.offset, word.order, size
        #: the Hz field drive_text reads (a rest's line around it: _pieces)
        self.hz_key = "reference_hz" if direction == "request" else "actual_hz"
        #: the word's Hz as the line shows it ("30.00 Hz"; "": none), by word (bounded)
        self.hz_texts: dict[int, str] = {}
        fixed = {word.offset: 2}
        for a, n in word.ignore:
            if n > 0 and not any(a < b + m and b < a + n for b, m in fixed.items()):
                fixed[a] = n                              # (a range over the speed word: not)
        segments: list[tuple[int, int, bytes | None]] = []
        self.slot = 0
        pos = 0
        for a in sorted(fixed):
            if a > pos:
                segments.append((pos, a, None))
            if a == word.offset:
                self.slot = len(segments)
            segments.append((a, a + fixed[a], bytes(fixed[a])))
            pos = a + fixed[a]
        if pos < size:
            segments.append((pos, size, None))
        self.segments = segments
        #: the speed word's class: 0, 1, -1 as two octets in the plan's byte order
        self.classes = (b"\x00\x00", (1).to_bytes(2, word.order), b"\xff\xff")  # type: ignore[arg-type]

    def hz_text(self, word: int) -> str:
        """The Hz the speed word gives as the line shows it ("30.00 Hz"; "": none), kept by word
        (bounded)."""
        w = self.word
        hz = w.hz(word) if w.hz is not None else w.fields(word).get(self.hz_key)
        if len(self.hz_texts) >= AREA_CACHE_MAX:
            self.hz_texts.clear()
        text = self.hz_texts[word] = "" if hz is None else f"{hz:.2f} Hz"
        return text


#: a rest's text line (suffix): (the line up to the Hz, after it, the line without an Hz, the max
#: frequency the rest teaches or None)
_Line = tuple[str, str, str, "float | None"]


class _Lane:
    """suffix()'s way for one watched station's areas in one direction, made for the layout, max
    frequency and Chk_Cfg the station had and the area's length (made anew when one changes):
    the plan's speed word (its octets `hi`, `lo`), the rest of an area as one int (the area's
    octets as a big-endian number, the speed word and the ignored words masked out (`mask`), the
    word's class in its place (`classes`)) and each rest's line pieces by that int (`lines`,
    bounded). Without a plan mask is -1: the slow way."""
    __slots__ = ("st", "direction", "size", "layout", "cfg", "fmax", "plan", "hi", "lo", "mask",
                 "classes", "lines", "hz_texts", "hz_text")

    def __init__(self, st: Watched, direction: str, size: int, layout: str | None,
                 plan: _Plan | None):
        self.st, self.direction, self.size, self.layout = st, direction, size, layout
        self.cfg, self.fmax = st.seen_cfg, st.fmax
        self.plan = plan
        self.lines: dict[int, _Line] = {}
        self.hz_texts: dict[int, str] = {}
        self.hz_text: Callable[[int], str] = str
        self.hi, self.lo, self.mask = 0, 0, -1        # the speed word's high and low octet
        self.classes: tuple[int, ...] = (0, 0, 0)
        if plan is None:
            return
        at = plan.offset
        self.hi, self.lo = (at + 1, at) if plan.order == "little" else (at, at + 1)
        mask = (1 << (8 * size)) - 1
        for a, b, fill in plan.segments:
            if fill is not None:
                mask &= ~(((1 << (8 * (b - a))) - 1) << (8 * (size - b)))
        self.mask = mask
        shift = 8 * (size - plan.offset - 2)
        self.classes = tuple(int.from_bytes(x, "big") << shift for x in plan.classes)
        self.hz_texts = plan.hz_texts
        self.hz_text = plan.hz_text


#: not looked up yet (None: the family has no plan for the area)
_UNKNOWN: Any = object()


def _reads_as_planned(cls: Any, codec: ModuleType) -> bool:
    """The plan is the codec's, written for its decode_area read by pdrive's families' or the
    codec's own package's normalise_area: a Drive class that reads areas its own way (a plug-in's
    on a shipped codec) gets the slow way."""
    owner = next((k for k in getattr(cls, "__mro__", ()) if "normalise_area" in vars(k)), None)
    if owner is None:
        return False
    package = codec.__name__ if hasattr(codec, "__path__") else codec.__name__.rpartition(".")[0]
    return bool(owner.__module__.startswith(("profidrive_cli.drives.", package + ".")))


def _plan(st: Watched, direction: str, layout: str) -> _Plan | None:
    """The family codec's speed_plan for this station's areas (drives/speedplan.py SpeedWord), with
    the max frequency its decode_area is given (_decode); None when the codec has none, or for a
    word outside the layout's area."""
    from profidrive_cli.drives import codec_module, drive_class
    mod = codec_module(st.profile)
    fn = getattr(mod, "speed_plan", None)
    if fn is None or not _reads_as_planned(drive_class(st.profile), mod):
        return None
    if st.decoder is None:
        st.decoder = _decoder(st.profile)
    max_hz = st.fmax if st.fmax is not None and st.decoder[1] else None
    word: SpeedWord | None = fn(st.profile, layout, direction, max_hz)
    lay = st.profile.layouts.get(layout)
    if word is None or lay is None:
        return None
    size = lay.output_len if direction == "request" else lay.input_len
    if not 0 <= word.offset <= size - 2 or word.order not in ("big", "little"):
        return None
    return _Plan(word, size, direction)


def _pieces(rest: DriveObject, hz_key: str) -> tuple[str, str, str, str]:
    """frame_suffix of a drive object like the rest's with another Hz (drive_text's parts in its
    order): (before, label, after, without) -- the line is before + label + f"{hz:.2f} Hz" +
    after, or `without` when the Hz is None."""
    arrow = "->" if rest["direction"] == "request" else "<-"
    who = f"drive {rest['station']} ({rest['profile']}"
    who += f" {rest['layout']})" if rest.get("layout") else ")"
    head = f"  | {arrow} {who}: "
    pre: list[str] = []
    post: list[str] = []
    parts = pre
    if "command" in rest:
        parts.append(str(rest["command"]))
    if hz_key == "reference_hz":
        parts = post
    elif rest.get("reference_hz") is not None:
        parts.append(f"reference {rest['reference_hz']:.2f} Hz")
    if "state" in rest:
        parts.append(str(rest["state"]))
    if hz_key == "actual_hz":
        parts = post
    elif rest.get("actual_hz") is not None:
        parts.append(f"actual {rest['actual_hz']:.2f} Hz")
    param = rest["param"]["text"] if rest.get("param") else None
    label = "reference " if hz_key == "reference_hz" else "actual "
    before = head + "".join(p + ", " for p in pre)
    after = "".join(", " + p for p in post) + ("" if param is None else "; " + param)
    text = ", ".join(pre + post)
    if param is not None:
        text += ("; " if text else "") + param
    return before, label, after, head + text


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


def _taught_fmax(profile: Profile, param: dict[str, Any]) -> float | None:
    """The max frequency an answer's parameter channel gives (an answer of the profile's
    max-frequency parameter with a positive value), else None."""
    if param.get("code") and param.get("code") == profile.max_frequency_param \
            and isinstance(param.get("value"), (int, float)) and param["value"] > 0:
        return float(param["value"])
    return None


def _learn_fmax(st: Watched, param: dict[str, Any]) -> None:
    fmax = _taught_fmax(st.profile, param)
    if fmax is not None:
        st.fmax = fmax


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
