"""Likely causes of a line's trouble, ranked, each with the telegrams or figures that show it --
from what a passive listener counted and timed (bustools/passive_live.py LiveList).

What the passive data can show, and what each rule reads:

    silent station      a station that answered stopped answering (LOST_AFTER requests in a row)
                        while the others still answer: its power, its connector or its spur
    watchdog expired    a station answered RS, or was parameterised again, after the master had
                        been silent towards it longer than the watchdog of its Set_Prm
    duplicate address   Slave_Diag answers from one address carry two ident numbers
    second master       tokens or Set_Prm from more than one master address
    repeats             retries and corrupt replies concentrated on a few stations (80 % or more on
                        at most half the stations): their spur, connector or cable, not the line
    late replies        replies later than the slot time (and than passive_live.LATE_FLOOR_S: the
                        arrival times of a capture through a USB adapter or a pty are good to some
                        ms only), at least MIN_LATE of them and 1 % of its Data_Exchange answers
    framing errors      corrupt telegrams spread over the line: noise, termination, baud rate

Not from one passive capture (they need more): "illegal frames only at high rates" needs captures
(or `scan --watch` passes) at two baud rates; a cable fault's place needs an oscilloscope or the
line's reflection measurement; a station that answers late because its own cycle is slow needs its
response time from the GSD (Max_Tsdr) to compare with.

Sans-IO and pure: likely_causes(live) -> [Cause], best first.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from profidrive_cli.bustools.passive_live import LOST_AFTER, LiveList, StationLive, slot_s

#: the least retries + corrupt replies before "concentrated" is worth saying
MIN_REPEATS = 5
#: share of the repeats on the few stations that makes them "concentrated"
CONCENTRATED = 0.8
#: late replies worth naming: at least this many, and at least 1 % of the station's replies
MIN_LATE = 3


@dataclass(frozen=True)
class Cause:
    title: str
    score: float                      # 0..1: how strongly the evidence points at it (ranks)
    evidence: tuple[str, ...]
    stations: tuple[int, ...] = ()

    def as_dict(self) -> dict[str, Any]:
        return {"title": self.title, "score": round(self.score, 2), "stations": list(self.stations),
                "evidence": list(self.evidence)}


def likely_causes(live: LiveList) -> list[Cause]:
    """The causes the counters and timing of `live` show, best first."""
    out: list[Cause] = []
    sts = sorted(live.stations.values(), key=lambda s: s.address)
    out += _silent(sts)
    out += _watchdog(sts)
    out += _duplicate(sts)
    out += _masters(live, sts)
    out += _repeats(sts)
    out += _late(live, sts)
    out += _framing(live, sts)
    return sorted(out, key=lambda c: -c.score)


def causes_json(live: LiveList) -> list[dict[str, Any]]:
    """likely_causes as the JSON contract's objects (`causes` in sniff's live event)."""
    return [c.as_dict() for c in likely_causes(live)]


def _silent(sts: list[StationLive]) -> list[Cause]:
    out = []
    for s in sts:
        if s.last_answer_t is None or s.silent < LOST_AFTER:
            continue
        since = s.last_answer_t
        others = [o.address for o in sts if o is not s and o.last_answer_t is not None
                  and o.last_answer_t > since]
        ev = [f"station {s.address}: {s.silent} requests in a row unanswered, last answer at "
              f"{since:.3f} s"]
        if others:
            ev.append(f"stations {', '.join(map(str, others))} answered after that")
            out.append(Cause(f"station {s.address} stopped answering while the others answer: its "
                             f"power, its bus connector or the cable to it", 0.9, tuple(ev),
                             (s.address,)))
        else:
            out.append(Cause(f"station {s.address} stopped answering (no other station answered "
                             f"since either: the line or the listener)", 0.5, tuple(ev),
                             (s.address,)))
    return out


def _watchdog(sts: list[StationLive]) -> list[Cause]:
    out = []
    for s in sts:
        if not s.wd_expiries:
            continue
        ev = tuple(f"at {t:.3f} s: {gap * 1000:.0f} ms without a request to it, watchdog "
                   f"{wd * 1000:.0f} ms (its Set_Prm)" for t, gap, wd in s.wd_expiries)
        out.append(Cause(f"station {s.address}'s watchdog expired: the master was silent towards it "
                         f"longer than the watchdog (master busy, stopped, or its cycle too slow)",
                         0.8, ev, (s.address,)))
    return out


def _duplicate(sts: list[StationLive]) -> list[Cause]:
    out = []
    for s in sts:
        if len(s.diag_idents) > 1:
            ids = ", ".join(f"0x{i:04X}" for i in sorted(s.diag_idents))
            out.append(Cause(f"two devices answer as station {s.address} (duplicate address)", 0.85,
                             (f"its Slave_Diag answers carried the idents {ids}",), (s.address,)))
    return out


def _masters(live: LiveList, sts: list[StationLive]) -> list[Cause]:
    out = []
    if len(live.token_from) > 1:
        ev = tuple(f"master {m}: {n} tokens" for m, n in sorted(live.token_from.items()))
        out.append(Cause(f"more than one master passes the token: "
                         f"{', '.join(map(str, sorted(live.token_from)))} (a second master on the "
                         f"line, or two masters with one address)", 0.6, ev))
    for s in sts:
        if len(s.sets_prm_from) > 1:
            ms = ", ".join(map(str, sorted(s.sets_prm_from)))
            out.append(Cause(f"station {s.address} is parameterised by masters {ms}", 0.7,
                             (f"Set_Prm to station {s.address} from {ms}",), (s.address,)))
    return out


def _few(trouble: dict[int, int]) -> tuple[list[int], int, int] | None:
    """(the stations, their share, the total) when at most half the stations hold CONCENTRATED of
    the trouble (at least MIN_REPEATS in all); None when it is spread or too little to say."""
    total = sum(trouble.values())
    if total < MIN_REPEATS or len(trouble) < 2:
        return None
    few: list[int] = []
    got = 0
    for a in sorted(trouble, key=lambda a: -trouble[a])[:max(1, len(trouble) // 2)]:
        if not trouble[a]:
            break
        few.append(a)
        got += trouble[a]
        if got >= CONCENTRATED * total:
            return few, got, total
    return None


def _repeats(sts: list[StationLive]) -> list[Cause]:
    hit = _few({s.address: s.counters["retries"] + s.counters["illegal"] for s in sts})
    if hit is None:
        return []
    few, got, total = hit
    by = {s.address: s for s in sts}
    ev = [f"station {a}: {by[a].counters['retries']} retries, {by[a].counters['illegal']} corrupt "
          f"replies, {by[a].exchanges} Data_Exchange answered" for a in few]
    rest = [s for s in sts if s.address not in few]
    ev.append(f"the other {len(rest)} station(s): {total - got} retries and corrupt replies, "
              f"{sum(s.exchanges for s in rest)} Data_Exchange answered")
    return [Cause(f"repeats concentrated on station(s) {', '.join(map(str, few))} "
                  f"({100 * got / total:.0f} % of {total}): their spur, connector or cable, not the "
                  f"whole line", 0.7, tuple(ev), tuple(few))]


def _late(live: LiveList, sts: list[StationLive]) -> list[Cause]:
    if not live.baud:
        return []
    late = [s for s in sts if s.late >= MIN_LATE and s.late * 100 >= s.exchanges]
    if not late:
        return []
    ev = tuple(f"station {s.address}: {s.late} replies later than {live.late_s * 1000:.1f} ms "
               f"(of {s.exchanges} Data_Exchange answered), up to {s.late_max * 1000:.1f} ms"
               for s in late)
    ev += (f"slot time at {live.baud} bit/s: {slot_s(live.baud) * 1000:.2f} ms; judged late from "
           f"{live.late_s * 1000:.1f} ms on (a capture's arrival times are good to some ms only)",)
    return [Cause(f"late replies from station(s) {', '.join(str(s.address) for s in late)}: the "
                  f"station is busy, or a repeater / converter delays them", 0.5,
                  ev, tuple(s.address for s in late))]


def _framing(live: LiveList, sts: list[StationLive]) -> list[Cause]:
    n = sum(live.errors.values())
    if not n:
        return []
    kinds = ", ".join(f"{k} {v}" for k, v in sorted(live.errors.items()))
    return [Cause("corrupt telegrams on the line: noise, a missing or extra termination, or a "
                  "listener at the wrong baud rate", 0.4,
                  (f"{n} framing error(s) in {live.frames} telegrams ({kinds})",))]


# -- scan --watch: the same reading of an active master's counters -------------------------------

def watch_causes(stations: list[Any]) -> list[Cause]:
    """Likely causes from `scan --watch`'s stations (bustools/buswatch.py WatchedStation: category,
    counters requests / retries / no_answer / illegal / reparams), best first."""
    sts = sorted((s for s in stations if s.station_type == "slave"), key=lambda s: s.address)
    out: list[Cause] = []
    answering = [s.address for s in sts if s.category != "no answer"]
    for s in sts:
        c = s.counters
        if s.category == "no answer" and s.seen_passes:
            ev = (f"station {s.address}: no valid reply in the last pass ({c.get('no_answer', 0)} "
                  f"requests unanswered of {c.get('requests', 0)})",)
            if answering:
                out.append(Cause(f"station {s.address} stopped answering while the others answer: its "
                                 f"power, its bus connector or the cable to it", 0.9,
                                 ev + (f"stations {', '.join(map(str, answering))} answer",),
                                 (s.address,)))
            else:
                out.append(Cause(f"no station answers any more: the line, the adapter or the baud "
                                 f"rate", 0.6, ev, (s.address,)))
        if c.get("reparams"):
            out.append(Cause(f"station {s.address} left data exchange and was parameterised again "
                             f"{c['reparams']} time(s): its watchdog expired (the master too slow or "
                             f"silent), or it lost power", 0.7,
                             (f"station {s.address}: {c['reparams']} re-parameterisation(s) in "
                              f"{c.get('requests', 0)} requests",), (s.address,)))
        if s.category == "configuration fault":
            out.append(Cause(f"station {s.address} refuses its configuration (Cfg_Fault / Prm_Fault): "
                             f"`pdrive gsd match {s.address}` names the modules it has", 0.8,
                             (f"station {s.address}: {s.state}",), (s.address,)))
    hit = _few({s.address: s.counters.get("retries", 0) + s.counters.get("illegal", 0) for s in sts})
    if hit is not None:
        few, got, total = hit
        by = {s.address: s.counters for s in sts}
        lines = tuple(f"station {a}: {by[a].get('retries', 0)} retries, {by[a].get('illegal', 0)} "
                      f"corrupt replies of {by[a].get('requests', 0)} requests" for a in few)
        out.append(Cause(f"repeats concentrated on station(s) {', '.join(map(str, few))} "
                         f"({100 * got / total:.0f} % of {total}): their spur, connector or cable, not "
                         f"the whole line", 0.7, lines, tuple(few)))
    else:
        corrupt = {s.address: s.counters.get("illegal", 0) for s in sts}
        if sum(corrupt.values()) >= MIN_REPEATS and sum(1 for v in corrupt.values() if v) > len(sts) // 2:
            out.append(Cause("corrupt replies from most stations: noise, a missing or extra "
                             "termination, or the wrong baud rate", 0.5,
                             tuple(f"station {a}: {n} corrupt" for a, n in corrupt.items() if n)))
    return sorted(out, key=lambda c: -c.score)
