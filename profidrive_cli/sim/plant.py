"""The simulated plant: which stations sit on the simulated bus, from a sim:// URL.

    sim://                                   default plant: 3 fuji-g1, 4 fuji-pdp3, 5 toyo, 6 moeller, 7 yaskawa
    sim://?stations=3:fuji-g1,9:yaskawa      choose stations (profile names or aliases)
    sim://?stations=3,4,5,6                  an address alone: the default plant's station there (here
                                             the default plant without station 7)
    sim://?baud=187500&timing=wire           wire-timed bus (see sim/bus.py); timing=virtual: the same
                                             on a simulated clock (tests, benchmarks). With baud= the
                                             stations are locked to that rate (a running bus) and stay
                                             silent to a master at another rate; without it they
                                             answer at the port's rate, whatever it is
    sim://?tsdr=30                           stations answer 30 bit times after a request (at least
                                             the min TSDR of Set_Prm; default 11)
    sim://?drop=0.01&powercycle=0.001&...    fault injection (keys in sim/faults.py)
    sim://?unplug=3@5-8                      station 3 unplugged 5 s after the bus's first telegram,
                                             plugged in again at 8 s (sim/faults.py)
    sim://?trip=3:OC1                        station 3 starts tripped with alarm OC1
    sim://?set=7:A1-02=3,C1-01=2             station 7 starts with these settings (engineering units); also
                                             a model's own settings (SETTINGS of sim/<family>.py), e.g.
                                             set=7:d5-01=1: the simulated SI-P1 in torque control
    sim://?faults=6:E01,E05                  station 6's fault history pre-filled (repeat the key per station)
    sim://?warmup=3:4,5:2                    station 3 still searches the baud rate (Baud_Search): it
                                             misses the first 4 valid telegrams on the line (to any
                                             station, its own included) and takes the rate from the
                                             5th, which it answers when it is addressed (station 5:
                                             from the 3rd); sim/slave.py SimSlave.baud_search
    sim://?warmup=3:0.5s                     station 3's search reaches the line's rate 0.5 s after
                                             power-on (the bus's clock): it takes the rate from the
                                             first valid telegram after that
    sim://?firstcontact=3,5                  stations 3 and 5 keep the first-contact rule of a Siemens
                                             CBP2 drive board (kolod/profibus): from a master they
                                             keep no frame count for (after power-on), an SRD/SDA is
                                             executed only when it starts a sequence, FCV=0 with FCB=1
                                             (reference §2.3 rule 1); FCV=1 or FCV=0/FCB=0 there get no
                                             answer at all. FDL status is answered as usual. A CBP2 as
                                             kolod/profibus met it: firstcontact=3&warmup=3:5;
                                             sim/slave.py SimSlave.first_contact
    sim://?learn=line.pcapng                 the stations of a capture, answering as the captured ones
                                             did (sim/learn.py; not with stations=)
    sim://?wd=0                              (debug) ignore the watchdog... not offered: the sim always enforces it

Each station runs the family's drive model (the sim_model of its row in drives/registry.py: sim/<family>.py,
make_model(profile, **options)); a family without a model runs a plain DP-V0 slave with the profile's
ident and configurations. A station named by a profile the index knows, without set=, is built on first
use (sim/lazy.py): until a master parameterises it (or a trip, a fault history or a look at the model
needs it) it answers FDL status and Slave_Diag from the index's ident, so a bus scan loads no profile
and no drive model.
"""

from __future__ import annotations

import functools
import importlib
from collections.abc import Collection
from types import ModuleType
from typing import TYPE_CHECKING, Any
from urllib.parse import parse_qs, urlsplit

from profidrive_cli import UsageError
from profidrive_cli.drives.profile import Profile, index_entry, load_profile
from profidrive_cli.drives.registry import sim_model_ref
from profidrive_cli.fdl.timing import parse_baud
from profidrive_cli.sim.bus import SimBus
from profidrive_cli.sim.lazy import LazyModel
from profidrive_cli.sim.model import SlaveModel
from profidrive_cli.sim.slave import SimSlave

if TYPE_CHECKING:
    from profidrive_cli.drives.profile import IndexEntry
    from profidrive_cli.sim.faults import FaultPlan

DEFAULT_PLANT = ((3, "fuji-g1"), (4, "fuji-pdp3"), (5, "toyo"), (6, "moeller"), (7, "yaskawa"))
KNOWN_KEYS = {"stations", "baud", "timing", "trip", "faults", "tsdr", "seed", "set", "warmup",
              "firstcontact", "learn"}
#: the most telegrams a station of warmup= may miss, and the longest search in seconds (bounds for
#: the URL, not device figures)
MAX_WARMUP = 1000
MAX_WARMUP_S = 3600.0
TIMINGS = ("instant", "wire", "virtual")


def make_model(profile: Profile, **options: Any) -> SlaveModel:    # (the sim:// URL's options)
    ref = sim_model_ref(profile)          # the family table (drives/registry.py) names the model
    m: SlaveModel
    if ref is not None:
        mod_name, _, fn_name = ref.partition(":")
        m = getattr(importlib.import_module(mod_name), fn_name)(profile, **options)
    else:
        m = SlaveModel(profile.ident, {n: l.cfg for n, l in profile.layouts.items()},
                       name=profile.title)
        m.family = profile.name
    if getattr(m, "default_layout", None) is None:
        m.default_layout = profile.default_layout
    _gsd_modes(profile, m)
    return m


def _gsd_modes(profile: Profile, m: SlaveModel) -> None:
    """The station offers Sync / Freeze (sim/slave.py) exactly where its own GSD file, the library file
    the profile names (`gsd:`), claims them (Sync_Mode_supp / Freeze_Mode_supp)."""
    gsd = getattr(profile, "gsd", None)
    if not gsd:
        return
    from profidrive_cli.data import gsd_dir
    from profidrive_cli.gsd.library import parse_cached
    path = gsd_dir() / gsd
    if path.is_file():
        g = parse_cached(path)
        m.sync_supported, m.freeze_supported = bool(g.sync_mode_supp), bool(g.freeze_mode_supp)


def _index_entry(name: str) -> IndexEntry | None:
    """The profile index entry a station name (profile name or alias) stands for; None for a path
    or a name the index does not know (then the full load says what is wrong, at once)."""
    if name.endswith((".yaml", ".yml")) or "/" in name:
        return None
    return index_entry(name)


def _build_model(name: str, addr: int, baud: int, preset: dict[str, float] | None = None) -> SlaveModel:
    prof = load_profile(name)
    try:
        model = make_model(prof, **_preset_options(prof, preset or {}))
    except ValueError as e:
        raise UsageError(f"sim URL: set= for station {addr}: {e}") from None
    model.on_bus(addr, baud)
    return model


def _station_list(text: str) -> list[tuple[int, str]]:
    out: list[tuple[int, str]] = []
    for item in filter(None, (t.strip() for t in text.split(","))):
        addr, colon, name = item.partition(":")
        try:
            a = int(addr)
        except ValueError:
            raise UsageError(f"sim URL: station '{item}' must be ADDRESS:PROFILE, e.g. 3:fuji-g1") from None
        if not colon:
            # an address alone: the default plant's station at that address
            name = dict(DEFAULT_PLANT).get(a, "")
            if not name:
                raise UsageError(f"sim URL: station '{item}' must be ADDRESS:PROFILE (an address alone "
                                 f"only for the default plant's {', '.join(str(b) for b, _ in DEFAULT_PLANT)})")
        if not 0 <= a <= 125 or not name:
            raise UsageError(f"sim URL: station '{item}' must be ADDRESS:PROFILE with address 0..125")
        if any(a == b for b, _ in out):
            raise UsageError(f"sim URL: address {a} used twice")
        out.append((a, name))
    return out


def _per_station(values: list[str], key: str) -> dict[int, list[str]]:
    out: dict[int, list[str]] = {}
    for v in values:
        addr, _, rest = v.partition(":")
        try:
            a = int(addr)
        except ValueError:
            raise UsageError(f"sim URL: {key}={v} must be ADDRESS:CODE[,CODE...]") from None
        out.setdefault(a, []).extend(c.strip() for c in rest.split(",") if c.strip())
    return out


def _warmups(values: list[str]) -> dict[int, tuple[int, float]]:
    """warmup=ADDR:COUNT or ADDR:SECONDSs [,...] (the key may repeat) -> {address: (telegrams
    missed, seconds of search)}."""
    out: dict[int, tuple[int, float]] = {}
    for v in values:
        for item in filter(None, (t.strip() for t in v.split(","))):
            addr, colon, what = item.partition(":")
            what = what.strip()
            a, n, sec = -1, -1, -1.0
            try:
                a = int(addr)
                if what.lower().endswith("s"):
                    n, sec = 0, float(what[:-1])
                else:
                    n, sec = int(what), 0.0
            except ValueError:
                pass
            if (not colon or not 0 <= a <= 125 or not 0 <= n <= MAX_WARMUP
                    or not 0.0 <= sec <= MAX_WARMUP_S):        # (NaN fails too)
                raise UsageError(f"sim URL: warmup={v} must be ADDRESS:COUNT or ADDRESS:SECONDSs"
                                 f"[,...] with address 0..125, count 0..{MAX_WARMUP} (valid "
                                 f"telegrams on the line the station misses) or seconds "
                                 f"0..{MAX_WARMUP_S:g} (its search time), e.g. warmup=3:4 or "
                                 f"warmup=3:0.5s")
            out[a] = (n, sec)
    return out


def _first_contacts(values: list[str]) -> set[int]:
    """firstcontact=ADDR[,ADDR...] (the key may repeat) -> the addresses keeping the CBP2 rule."""
    out: set[int] = set()
    for v in values:
        for item in (t.strip() for t in v.split(",")):
            try:
                a = int(item)
            except ValueError:
                a = -1
            if not 0 <= a <= 125:
                raise UsageError(f"sim URL: firstcontact={v} must be ADDRESS[,ADDRESS...] with "
                                 f"address 0..125, e.g. firstcontact=3")
            out.add(a)
    return out


def _presets(values: list[str]) -> dict[int, dict[str, float]]:
    """set=ADDR:CODE=VALUE[,CODE=VALUE...] -> {address: {code: value}} (engineering units): the
    drive's settings as the plant starts (a drive commissioned before, e.g. set=7:A1-02=3)."""
    out: dict[int, dict[str, float]] = {}
    for addr, items in _per_station(values, "set").items():
        for item in items:
            code, eq, value = item.partition("=")
            try:
                out.setdefault(addr, {})[code.strip()] = float(value)
            except ValueError:
                raise UsageError(f"sim URL: set={addr}:{item} must be CODE=NUMBER") from None
            if not eq:
                raise UsageError(f"sim URL: set={addr}:{item} must be CODE=NUMBER")
    return out


def _preset_options(profile: Profile, values: dict[str, float]) -> dict[str, dict[str, float]]:
    """The model options that preset `values`: `defaults` (code -> value), which every family's
    make_model takes (the Yaskawa model turns them into its parameter options, E1_04=50)."""
    if not values:
        return {}
    from profidrive_cli.drives.values import profile_value_problem
    out: dict[str, float] = {}
    for code, v in values.items():
        p = profile.param(code)
        if p is None:
            # a setting the family's model takes beyond the profile (SETTINGS of its module: code ->
            # the values it takes), e.g. the Yaskawa model's d5-01, which has no register
            extra = _model_settings(profile)
            key = next((k for k in extra if k.lower() == code.lower()), None)
            if key is None:
                raise UsageError(f"sim URL: set=: {code} is not a parameter of {profile.name}")
            if v not in extra[key]:
                raise UsageError(f"sim URL: set=: {key} = {v:g}: the simulated {profile.name} takes "
                                 f"{' or '.join(f'{x:g}' for x in extra[key])}")
            out[key] = v
            continue
        out[code] = v
        # a setting the drive cannot hold exactly is refused, as on the master side (never rounded:
        # F07=0.01 with F07's 0.1 s resolution used to start the plant with F07 = 0)
        why = profile_value_problem(profile, p, v)
        if why is not None:
            raise UsageError(f"sim URL: set=: {why}")
    return {"defaults": out}


def _model_settings(profile: Profile) -> dict[str, Collection[float]]:
    """The settings the family's sim model takes beyond the profile's parameters: the SETTINGS table
    of its module (code -> the values it takes); {} for none."""
    ref = sim_model_ref(profile)
    if ref is None:
        return {}
    return dict(getattr(importlib.import_module(ref.partition(":")[0]), "SETTINGS", None) or {})


def url_baud(url: str) -> int | None:
    """The rate a sim:// URL locks its stations to (`baud=`), or None (no baud=: they answer at any
    rate; not a sim URL). UsageError for a baud= that is no DP rate, as build_bus says it."""
    parts = urlsplit(url)
    if parts.scheme != "sim":
        return None
    q = parse_qs(parts.query, keep_blank_values=True)
    if "baud" not in q:
        return None
    try:
        return parse_baud(q["baud"][-1])
    except ValueError as e:
        raise UsageError(f"sim URL: {e}") from None


def build_bus(url: str, now: float = 0.0, default_baud: int = 19200) -> SimBus:
    parts = urlsplit(url)
    if parts.scheme != "sim":
        raise UsageError(f"not a sim URL: {url}")
    q = parse_qs(parts.query, keep_blank_values=True)
    unknown = set(q) - KNOWN_KEYS
    from profidrive_cli.sim import faults as faults_mod
    fault_keys = {k for k in unknown if k in faults_mod.URL_KEYS}
    unknown -= fault_keys
    if unknown:
        raise UsageError(f"sim URL: unknown option(s) {', '.join(sorted(unknown))} "
                         f"(known: {', '.join(sorted(KNOWN_KEYS | set(faults_mod.URL_KEYS)))})")
    stations = _station_list(q["stations"][-1]) if "stations" in q else list(DEFAULT_PLANT)
    try:
        baud = url_baud(url) or parse_baud(default_baud)
    except ValueError as e:
        raise UsageError(f"sim URL: {e}") from None
    timing = q.get("timing", ["instant"])[-1]
    if timing not in TIMINGS:
        raise UsageError(f"sim URL: timing must be {', '.join(TIMINGS)}, got {timing!r}")
    trips = _per_station(q.get("trip", []), "trip")
    warmups = _warmups(q.get("warmup", []))
    first_contacts = _first_contacts(q.get("firstcontact", []))
    seeded = _per_station(q.get("faults", []), "faults")
    slaves = []
    presets = _presets(q.get("set", []))
    if "learn" in q:
        if "stations" in q:
            raise UsageError("sim URL: learn= and stations= exclude each other (learn= takes the "
                             "capture's stations)")
        from profidrive_cli.sim.learn import learned_slaves, load_plans
        slaves.extend(learned_slaves(load_plans(q["learn"][-1]), make_model, baud))
        stations = []
    for addr, name in stations:
        preset = presets.pop(addr, {})
        entry = None if preset else _index_entry(name)
        model: SlaveModel | LazyModel
        # (an entry that answers to a name has its family and ident: drives/profile.py _read_entry)
        if entry is not None and entry.ident is not None and entry.family is not None:
            # built on first use (sim/lazy.py): a scan loads no profile, no model, no codec
            model = LazyModel(functools.partial(_build_model, name, addr, baud), entry.ident,
                              entry.family, f"{addr} ({name})")
        else:
            model = _build_model(name, addr, baud, preset)
        slave = SimSlave(addr, model)
        if isinstance(model, LazyModel):            # (entry is not None)
            model.attach(slave)
        slaves.append(slave)
    if presets:
        raise UsageError(f"sim URL: set= for station(s) {', '.join(map(str, sorted(presets)))}, "
                         f"which are not on the bus")
    addrs = {s.address: s for s in slaves}
    for a in set(trips) | set(seeded):
        if a not in addrs:
            raise UsageError(f"sim URL: no station {a} to trip or seed faults")
    for a, (n, sec) in warmups.items():
        if a not in addrs:
            what = f"{sec:g}s" if sec else str(n)
            raise UsageError(f"sim URL: warmup={a}:{what}: no station {a} on the bus")
        addrs[a].baud_search(n, sec, now)
    for a in sorted(first_contacts):
        if a not in addrs:
            raise UsageError(f"sim URL: firstcontact={a}: no station {a} on the bus")
        addrs[a].first_contact = True
    for a, codes in seeded.items():
        try:
            addrs[a].model.seed_faults(codes)
        except ValueError as e:
            raise UsageError(f"sim URL: faults for station {a}: {e}") from None
    for a, codes in trips.items():
        try:
            addrs[a].model.trip(codes[-1], now)
        except (ValueError, IndexError) as e:
            raise UsageError(f"sim URL: trip for station {a}: {e}") from None
    try:
        tsdr = int(q.get("tsdr", ["11"])[-1])
        seed = int(q.get("seed", ["1"])[-1])
    except ValueError:
        raise UsageError("sim URL: tsdr and seed must be whole numbers") from None
    if not 11 <= tsdr <= 1023:
        raise UsageError(f"sim URL: tsdr={tsdr} outside 11..1023 bit times")
    plan = faults_mod.plan_from_query(q, seed=seed) if fault_keys else None
    if plan is not None:
        _check_trip_codes(plan, addrs, faults_mod)
        for a in plan.unplugs:
            if a not in addrs:
                raise UsageError(f"sim URL: unplug={a}@...: no station {a} on the bus")
    return SimBus(slaves, baud=baud, timing=timing, tsdr_bits=tsdr, faults=plan)


def _check_trip_codes(plan: FaultPlan, addrs: dict[int, SimSlave], faults_mod: ModuleType) -> None:
    """drivetrip needs an alarm each station in scope knows: fill in the defaults, refuse unknown codes."""
    for a in plan.trip_codes:
        if a not in addrs:
            raise UsageError(f"sim URL: tripcode for station {a}, which is not on the bus")
    if not plan.rates.get("drivetrip") and not plan.trip_codes:
        return
    for a, s in addrs.items():
        if plan.only is not None and a not in plan.only and a not in plan.trip_codes:
            continue
        code = plan.trip_codes.get(a)
        if code is None:
            try:
                code = faults_mod.default_trip_code(s.model)
            except ValueError as e:
                raise UsageError(f"sim URL: drivetrip: {e} (limit it with only=)") from None
        prof = getattr(s.model, "profile", None)
        known = {x.code.upper() for x in getattr(prof, "alarms", [])}
        if known and code.upper() not in known:
            raise UsageError(f"sim URL: tripcode {code} unknown for station {a} "
                             f"({', '.join(sorted(known)[:10])}, ...)")
        plan.trip_codes[a] = code
