"""Likely causes of a line's trouble, ranked, each with the telegrams or figures that show it --
from what a passive listener counted and timed (bustools/passive_live.py LiveList).

What the passive data can show, and what each rule reads:

    silent station      a station that answered stopped answering for SILENT_AFTER rounds in a row
                        (requests to it, a repeat of one not counted) while other stations answered
                        after its silence began: its power, its connector or its spur
    silent line         stations stopped answering and no station answered after the silence
                        began: the line, the master's adapter or the listener -- no station named
    watchdog expired    a station answered RS, or was parameterised again, after the master had
                        been silent towards it longer than the watchdog of its Set_Prm
    duplicate address   Slave_Diag answers from one address carry two ident numbers
    second master       tokens or Set_Prm from more than one master address
    repeats             retries and corrupt replies concentrated on a few stations (80 % or more on
                        at most half the stations, more than a line that drops at random would put on
                        them: BY_CHANCE): their spur, connector or cable
    losses on the line  repeats on most stations, none concentrated: the line (noise, termination,
                        the cable), with the repeats and losses per station
    late replies        replies later than the slot time (and than passive_live.LATE_FLOOR_S: the
                        arrival times of a capture through a USB adapter or a pty are good to some
                        ms only), at least MIN_LATE of them and 1 % of its Data_Exchange answers
    framing errors      corrupt telegrams spread over the line: noise, termination, baud rate

Not from one passive capture (they need more): "illegal frames only at high rates" needs captures
(or `scan --watch` passes) at two baud rates; a cable fault's place needs an oscilloscope or the
line's reflection measurement; a station that answers late because its own cycle is slow needs its
response time from the GSD (Max_Tsdr) to compare with.

The rules on answers and losses are written once, on Record (a station's answering record, the
same whether a passive listener or `scan --watch` counted it): silence_causes and loss_causes.
likely_causes (sniff --live, the recorder) and watch_causes (scan --watch) build the records from
their own counters and add what only their source can show.

Sans-IO and pure: likely_causes(live) -> [Cause], best first.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import comb
from typing import Any

from profidrive_cli.bustools.passive_live import LOST_AFTER, LiveList, StationLive, slot_s

#: rounds in a row without an answer before one station is blamed: passes of `scan --watch`, rounds
#: of the master's requests to it in a capture (passive_live.LOST_AFTER, the lost() trigger's
#: number). One number for every source: one pass or one request and its retry lost is what a line
#: that drops at random does to every station now and then
SILENT_AFTER = LOST_AFTER
#: the least repeats (retries + corrupt replies) before "concentrated" or "spread" is worth saying
MIN_REPEATS = 5
#: share of the repeats on the few stations that makes them "concentrated"
CONCENTRATED = 0.8
#: ... and only when a line that drops at random would put that many on them this rarely: the
#: binomial tail P(X >= their repeats | all repeats, their share of the stations), times the ways to
#: choose that many stations (a random line picks *some* stations to be unlucky)
BY_CHANCE = 0.001
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


@dataclass(frozen=True)
class Record:
    """One station's answering record, as either source counted it. Only stations that answered at
    least once have one (an empty address the master polls is no station that "answers").

    silent: rounds in a row without an answer up to now (SILENT_AFTER blames it); silent_since: when
    that run began (the time of its first unanswered request or pass; None: it answers);
    last_answer: the time of its last answer; retries, corrupt, no_answer, requests: its counters
    (requests 0: not counted by the source)."""
    address: int
    silent: int
    silent_since: float | None
    last_answer: float
    retries: int = 0
    corrupt: int = 0
    no_answer: int = 0
    requests: int = 0

    @property
    def repeats(self) -> int:
        return self.retries + self.corrupt


def silence_causes(recs: list[Record], unit: str) -> list[Cause]:
    """The silent-station rule: a station silent for SILENT_AFTER `unit` (passes, rounds) in a row
    is named when another station answered *after* its silence began (an answer before that, even
    in the same round, shows nothing about the span); when no station answered since, the line,
    the master's adapter or the listener went silent, and no single station is named."""
    out: list[Cause] = []
    alone: list[Record] = []
    for s in recs:
        if s.silent < SILENT_AFTER or s.silent_since is None:
            continue
        since = s.silent_since
        others = [o.address for o in recs if o is not s and o.last_answer > since]
        ev = [f"station {s.address}: {s.silent} {unit} in a row unanswered since {since:.3f} s "
              f"(last answer at {s.last_answer:.3f} s)"]
        if others:
            ev.append(f"stations {', '.join(map(str, others))} answered after its silence began")
            out.append(Cause(f"station {s.address} stopped answering while the others answer: its "
                             f"power, its bus connector or the cable to it", 0.9, tuple(ev),
                             (s.address,)))
        else:
            alone.append(s)
    if alone:
        t = min(s.silent_since or 0.0 for s in alone)
        line = tuple(f"station {s.address}: {s.silent} {unit} in a row unanswered since "
                     f"{s.silent_since:.3f} s" for s in alone)
        out.append(Cause(f"no station answered since {t:.3f} s: the line, the master's adapter, the "
                         f"baud rate or the listener, not one station", 0.6,
                         line + ("no other station answered after that",)))
    return out


def loss_causes(recs: list[Record]) -> list[Cause]:
    """Repeats (retries + corrupt replies) concentrated on a few stations name them; spread over the
    stations they are the line's, with the figures per station. A station silent for SILENT_AFTER
    rounds is left out (its silence is its own cause, its losses would only repeat it)."""
    recs = [s for s in recs if s.silent < SILENT_AFTER]
    trouble = {s.address: s.repeats for s in recs}
    total = sum(trouble.values())
    if total < MIN_REPEATS or len(trouble) < 2:
        return []
    by = {s.address: s for s in recs}
    hit = _few(trouble)
    if hit is not None:
        few, got = hit
        ev = [_losses(by[a]) for a in few]
        rest = [s for s in recs if s.address not in few]
        ev.append(f"the other {len(rest)} station(s): {total - got} retries and corrupt replies")
        return [Cause(f"repeats concentrated on station(s) {', '.join(map(str, few))} "
                      f"({100 * got / total:.0f} % of {total}): their spur, connector or cable, not "
                      f"the whole line", 0.7, tuple(ev), tuple(few))]
    hit_n = sum(1 for v in trouble.values() if v)
    if 2 * hit_n <= len(recs):
        return []                  # on a few stations, but not more than chance: too little to say
    top = max(trouble, key=lambda a: trouble[a])
    spread = tuple(_losses(s) for s in recs) + (
        f"{total} repeats on {hit_n} of {len(recs)} stations, the most on station {top}: "
        f"{trouble[top]} ({100 * trouble[top] / total:.0f} %)",)
    return [Cause(f"repeats spread over the line ({total} on {hit_n} of {len(recs)} stations): "
                  f"noise, a missing or extra termination, the cable or the baud rate, not one "
                  f"station", 0.5, spread)]


def _losses(s: Record) -> str:
    of = f" of {s.requests} requests" if s.requests else ""
    return (f"station {s.address}: {s.retries} retries, {s.corrupt} corrupt replies, "
            f"{s.no_answer} unanswered{of}")


def _few(trouble: dict[int, int]) -> tuple[list[int], int] | None:
    """(the stations, their repeats) when at most half the stations hold CONCENTRATED of the
    repeats and a line that drops at random would put that many on them less often than BY_CHANCE;
    None otherwise."""
    total = sum(trouble.values())
    few: list[int] = []
    got = 0
    for a in sorted(trouble, key=lambda a: -trouble[a])[:max(1, len(trouble) // 2)]:
        if not trouble[a]:
            break
        few.append(a)
        got += trouble[a]
        if got >= CONCENTRATED * total:
            k, n = len(few), len(trouble)
            return (few, got) if comb(n, k) * _tail(got, total, k / n) < BY_CHANCE else None
    return None


def _tail(x: int, n: int, p: float) -> float:
    """P(X >= x) for X binomial(n, p)."""
    return sum(comb(n, i) * p ** i * (1 - p) ** (n - i) for i in range(x, n + 1))


# -- sniff --live and the recorder: a passive listener's counters ---------------------------------

def live_records(live: LiveList) -> list[Record]:
    """The records of the stations that answered at least once in the capture."""
    return [Record(s.address, s.silent, s.silent_since, s.last_answer_t,
                   retries=s.counters["retries"], corrupt=s.counters["illegal"],
                   no_answer=s.counters["no_answer"])
            for s in sorted(live.stations.values(), key=lambda s: s.address)
            if s.last_answer_t is not None]


def likely_causes(live: LiveList) -> list[Cause]:
    """The causes the counters and timing of `live` show, best first."""
    recs = live_records(live)
    answered = {r.address for r in recs}
    sts = [s for s in sorted(live.stations.values(), key=lambda s: s.address)
           if s.address in answered]
    out: list[Cause] = []
    out += silence_causes(recs, "rounds")
    out += _watchdog(sts)
    out += _duplicate(sts)
    out += _masters(live, sts)
    out += loss_causes(recs)
    out += _late(live, sts)
    out += _framing(live, sts)
    return sorted(out, key=lambda c: -c.score)


def causes_json(live: LiveList) -> list[dict[str, Any]]:
    """likely_causes as the JSON contract's objects (`causes` in sniff's live event)."""
    return [c.as_dict() for c in likely_causes(live)]


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


# -- scan --watch: the same rules on an active master's counters -----------------------------------

def watch_records(stations: list[Any]) -> list[Record]:
    """The records of `scan --watch`'s slaves (bustools/buswatch.py WatchedStation) that answered at
    least once while watched."""
    return [Record(s.address, s.silent_passes, s.silent_since_s, s.last_answer_s,
                   retries=s.counters.get("retries", 0), corrupt=s.counters.get("illegal", 0),
                   no_answer=s.counters.get("no_answer", 0), requests=s.counters.get("requests", 0))
            for s in stations if s.station_type == "slave" and s.last_answer_s is not None]


def watch_causes(stations: list[Any]) -> list[Cause]:
    """Likely causes from `scan --watch`'s stations (bustools/buswatch.py WatchedStation: category,
    the answering record, counters requests / retries / no_answer / illegal / reparams), best first."""
    sts = sorted((s for s in stations if s.station_type == "slave"), key=lambda s: s.address)
    recs = watch_records(sts)
    out = silence_causes(recs, "passes") + loss_causes(recs)
    for s in sts:
        c = s.counters
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
    return sorted(out, key=lambda c: -c.score)
