"""Together: the same blocking work on several stations at once, one bus cycle carrying a request to
each -- fleet dump / diff, the API's Bus.read_params. Without it a line of drives is read one station
after another, each PKW (or MEMOBUS) transaction waiting for its own cycles: a line of 50 drives a
minute where the wire allows seconds.

How: every station's job (a function that talks to its drive through the drive's CyclicChannel, as
the families' parameter paths do: `s.params.dump`) runs in a thread of its own, and the station's
MeteredChannel sends its exchanges into the run instead of to the bus (LockstepChannel). A round
goes when every job still running has posted its next outputs (or has ended): each posted station
gets one Data_Exchange, in address order, and its inputs go back to its job. The job whose post
completes the round runs it itself, so a line where one drive is left reads with no hand-over
between threads; one round at a time, so never two threads on the bus. The rounds are therefore
the same whatever the threads' timing: each job sees exactly the exchanges it asked for, in order,
as on its own channel. The caller's thread runs on_done as each job ends, and the rounds that no
job starts (a late job, below).

A DP-V1 drive's parameter path (DS47 over class-1 Read/Write) posts each telegram of its call -- the
request, then each poll -- into the rounds the same way (LockstepChannel.c1_read / c1_write: one
SRD to SAP 51 in place of its Data_Exchange, Master.c1_step), so a DS47 drive is read beside PKW
drives, one telegram of each in flight per round.

Rules, each written here once:
- unpaced while the jobs run: a round goes as soon as it is full (the wire, the slaves' answers and
  the CPU are the pace); the jobs' own cycle rates do not apply.
- a window: at most as many jobs at once as one round of ROUND_S (0.25 s) on the wire carries, and
  never more than MAX_JOBS threads; the others start, in address order, as jobs end. A longer round
  would stretch each job's transactions past their own timeouts (a line of 30 drives at 9.6 kbit/s
  would take 1.6 s a round).
- the keep rule holds (dp.poller.keep_within: a quarter of the DP watchdog): a station whose job has
  ended or has not posted yet (its thread did not get the CPU) gets a Data_Exchange with its last
  outputs once its last request is that old; a round waits for a late job only until then, then
  goes without it. `keep` names more stations to hold (the API's other open drives).
- a station that drops out is brought up again by its next exchange (Master.exchange), as on its own
  channel; a BusError of its exchange is raised in its job only.
- a lost link ends every job (LinkLost in each) and is raised in the caller's thread; so is
  anything that thread gets while it waits (Ctrl-C, session.SessionTerminated): every job is ended
  (Stopped at its next exchange; a round under way ends first), its thread joined, then the
  exception goes on -- the sessions' own exits make the safe stop and release the stations, as for
  one station.

Threads, not a rewrite of every family's parameter path as a state machine: the families' request
loops stay the one code path of `param get` and of the dump. No click and no rich.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable, Mapping
from typing import TYPE_CHECKING, Generic, TypeVar, overload

from profidrive_cli import BusError
from profidrive_cli.dp import msac1 as M1
from profidrive_cli.dp.acyclic import C1Call
from profidrive_cli.dp.poller import keep_within
from profidrive_cli.fdl.timing import wire_time_data_exchange
from profidrive_cli.link.base import LinkLost

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.dp.poller import Master
    from profidrive_cli.session.cycle import MeteredChannel

T = TypeVar("T")
#: what a round gives a station's job: its inputs, a DP-V1 call's answer (None: not yet), or the
#: exception its telegram raised
_Answer = bytes | M1.Msac1Pdu | None | BaseException

#: the longest round the run lets grow on the wire (the window of jobs at once), seconds: an eighth
#: of the 2 s a PKW request waits for its answer (drives/profidrive/pkw.py), which comes a round
#: or two after the request; at 19.2 kbit/s 9 PPO1 stations, at 1.5 Mbit/s the whole line
ROUND_S = 0.25
#: and the most jobs (threads) at once, whatever the rate
MAX_JOBS = 32
#: how long (real seconds) a job may be late to post before the stations of running jobs count
#: for the keep rule too (its thread did not get the CPU; on a virtual clock the rule never fires)
LATE_S = 0.05
#: the shortest and longest single wait for a late job, real seconds (it is waited for until a held
#: station's keep-alive is due on the link's clock; the wait is cut in pieces of at most MAX_WAIT_S)
MIN_WAIT_S = 0.001
MAX_WAIT_S = 0.25
#: how long the end of a stopped run waits for each job's thread (it ends at its next exchange;
#: a round under way first: each posted station's exchange, a station's bring-up at most)
JOIN_S = 30.0


class Stopped(BusError):
    """Raised in a job's exchange when the run it belongs to was ended (a lost link, Ctrl-C, a
    signal in the caller's thread)."""


class Outcome(Generic[T]):
    """What one station's job gave: its value, or the exception it raised (BusError, DriveError,
    UsageError... the caller reports it per station)."""

    __slots__ = ("value", "error")

    def __init__(self, value: T | None = None, error: BaseException | None = None) -> None:
        self.value = value
        self.error = error

    @property
    def ok(self) -> bool:
        return self.error is None


class LockstepChannel:
    """The inner channel of a station's MeteredChannel during a run: exchange() posts the outputs to
    the coordinator and waits for the round that carries them."""

    def __init__(self, run: "_Run", address: int) -> None:
        self.run = run
        self.address = address
        self.cycles = 0

    def now(self) -> float:
        return self.run.master.link.now()

    def exchange(self, outputs: bytes) -> bytes:
        self.cycles += 1
        return self.run.post(self.address, bytes(outputs))

    # DP-V1 class-1 calls (drives/base.AcyclicChannel): each telegram of the call (the request,
    # then its polls) is this station's part of one round, as an exchange would be
    def c1_read(self, slot: int, index: int, length: int, timeout_s: float) -> bytes:
        return self._c1(M1.read_request(slot, index, length), timeout_s).data

    def c1_write(self, slot: int, index: int, data: bytes, timeout_s: float) -> None:
        self._c1(M1.write_request(slot, index, data), timeout_s)

    def _c1(self, pdu: bytes, timeout_s: float) -> M1.Msac1Pdu:
        call = C1Call(self.address, pdu, self.now(), timeout_s)
        while True:
            got = self.run.post(self.address, call)
            if isinstance(got, M1.Msac1Pdu):
                return got


class _Run:
    """One run's shared state: the posted outputs, the answers, the jobs still running, and who is
    on the bus (`busy`: one round, or the caller's on_done, at a time)."""

    def __init__(self, master: "Master", held: list[int], within: dict[int, float | None]) -> None:
        self.master = master
        self.held = held
        self.within = within
        self.cond = threading.Condition()
        #: a station's outputs for its Data_Exchange, or the class-1 call it takes the next step of
        self.posted: dict[int, bytes | C1Call] = {}
        self.answers: dict[int, _Answer] = {}
        self.running: set[int] = set()
        #: jobs ended since the caller last looked (for on_done)
        self.ended: list[int] = []
        self.stopped: BaseException | None = None
        self.busy = False
        self.rounds = 0
        #: when the last round ended (real time: how late a job is to post)
        self.last_round = time.monotonic()

    # -- with self.cond held -------------------------------------------------------------------
    def full(self) -> bool:
        """Every running job has posted (and one has): the round may go."""
        return bool(self.posted) and self.running <= self.posted.keys()

    def round(self) -> None:
        """One round of what is posted, on the bus with the lock let go meanwhile (the jobs still
        computing post into the next one). A lost link (or anything else) stops the run."""
        batch = dict(sorted(self.posted.items()))
        self.posted.clear()
        self.busy = True
        self.cond.release()
        try:
            got = _round(self.master, batch, self.held, self.within)
        except BaseException as e:          # noqa: BLE001  (every job and the caller see it)
            self.cond.acquire()
            self.stopped = self.stopped or e
            got = {}
        else:
            self.cond.acquire()
        self.busy = False
        self.rounds += 1
        self.last_round = time.monotonic()
        self.answers.update(got)
        self.cond.notify_all()

    # -- a job's thread --------------------------------------------------------------------------
    @overload
    def post(self, address: int, outputs: bytes) -> bytes: ...
    @overload
    def post(self, address: int, outputs: C1Call) -> M1.Msac1Pdu | None: ...

    def post(self, address: int, outputs: bytes | C1Call) -> bytes | M1.Msac1Pdu | None:
        """A job's exchange: its outputs into the round; the last job to post runs the round itself
        (no hand-over to another thread on the way: a line where one drive is left reads at the
        pace of one station's own channel)."""
        with self.cond:
            if self.stopped is not None:
                raise self._stopped()
            self.posted[address] = outputs
            while address not in self.answers:
                if self.stopped is not None:
                    self.posted.pop(address, None)
                    raise self._stopped()
                if not self.busy and not self.ended and self.full():
                    self.round()            # (a job that ended goes to on_done first)
                    continue
                self.cond.wait()
            got = self.answers.pop(address)
        if isinstance(got, BaseException):
            raise got
        return got

    def _stopped(self) -> BaseException:
        why = self.stopped
        if isinstance(why, (LinkLost, Stopped)):
            return why
        return Stopped(f"stopped ({type(why).__name__}{': ' + str(why) if str(why) else ''})")


def run_together(master: "Master", channels: Mapping[int, "MeteredChannel"],
                 jobs: Mapping[int, Callable[[], T]], keep: Iterable[int] = (),
                 on_done: Callable[[int, Outcome[T]], None] | None = None,
                 cancel: threading.Event | None = None) -> dict[int, Outcome[T]]:
    """Run jobs[address]() for every station at once, each on its own channel (channels[address],
    the station's MeteredChannel: its inner channel is the run's while the jobs run, then its own
    again), one bus round carrying the next request of each (see the module doc). keep: more
    stations to hold in data exchange meanwhile. on_done(address, outcome): called in this thread,
    between two rounds, as soon as a station's job has ended (the CLI writes its file and releases
    the station, so the rounds no longer keep it). cancel: once set, the run ends before its next
    round (Stopped; the asyncio face's cancellation). Returns {address: Outcome} in the jobs'
    order; raises LinkLost, Stopped when cancelled, and whatever this thread gets while it waits
    (KeyboardInterrupt, SessionTerminated) or on_done raises, after every job has ended."""
    if not jobs:
        return {}
    missing = [a for a in jobs if a not in channels]
    if missing:
        raise ValueError(f"run_together: no channel for station(s) {missing}")
    outcomes: dict[int, Outcome[T]] = {}
    held = sorted(set(jobs) | set(keep))
    run = _Run(master, held, {a: _within(master, a) for a in held})
    old_inner = {a: channels[a].inner for a in jobs}
    threads: list[threading.Thread] = []

    def work(address: int, job: Callable[[], T]) -> None:
        try:
            outcomes[address] = Outcome(value=job())
        except BaseException as e:          # noqa: BLE001  (the caller reports it per station)
            outcomes[address] = Outcome(error=e)
        finally:
            with run.cond:
                run.running.discard(address)
                run.ended.append(address)
                run.cond.notify_all()

    def done(addresses: list[int]) -> None:
        if on_done is not None:
            for a in addresses:
                on_done(a, outcomes.get(a, Outcome(error=Stopped("the job did not end"))))

    waiting = list(jobs.items())
    width = window(master, list(jobs))

    def start() -> None:
        """Start jobs (address order) while fewer than `width` run (with run.cond held)."""
        while waiting and len(run.running) < width:
            a, job = waiting.pop(0)
            run.running.add(a)
            t = threading.Thread(target=work, args=(a, job), name=f"pdrive-station-{a}", daemon=True)
            threads.append(t)
            t.start()

    for a in jobs:
        channels[a].inner = LockstepChannel(run, a)
    try:
        with run.cond:
            start()
        _watch(run, done, cancel, start)
    except BaseException as e:
        with run.cond:
            run.stopped = run.stopped or e
            run.cond.notify_all()
        for t in threads:
            # a job's round in progress ends first (bounded: each posted station's exchange, a
            # station's bring-up at most): never two threads on the bus
            t.join(JOIN_S)
        raise
    finally:
        for a, inner in old_inner.items():
            channels[a].inner = inner
    for t in threads:
        t.join()
    return {a: outcomes.get(a, Outcome(error=Stopped("the job did not end"))) for a in jobs}


def window(master: "Master", addresses: list[int]) -> int:
    """How many jobs run at once: as many stations as one round on the wire carries (their
    Data_Exchanges at the bus rate) within ROUND_S and within the keep rule of each of them (a
    quarter of its watchdog: a station exchanged first in a round must not be due before the
    round is over), at least one, at most MAX_JOBS. A longer round would stretch each job's own
    transactions past their timeouts (a PKW request waits 2 s for its answer, which comes a round
    or two later) and hold more threads than a line needs: the others wait for a job to end, their
    stations held in data exchange by the keep rule."""
    baud = master.params.baud
    rules = [w for w in (_within(master, a) for a in addresses) if w]
    budget = min([ROUND_S, *rules])
    width = 0
    total = 0.0
    for a in sorted(addresses):
        st = master.stations.get(a)
        if st is None:
            t = 0.0
        else:
            t = wire_time_data_exchange(baud, st.output_len, st.input_len)
        if width and total + t > budget:
            break
        total += t
        width += 1
    return max(1, min(MAX_JOBS, width))


def _within(master: "Master", address: int) -> float | None:
    """How old the station's last request may get: its watchdog's keep rule (not its own cycle
    period: while the jobs run, a station waiting for its turn needs only to stay in data
    exchange), None: no watchdog."""
    st = master.stations.get(address)
    return keep_within(st.config.wd_ms if st is not None else None)


def _watch(run: _Run, done: Callable[[list[int]], None], cancel: threading.Event | None,
           start: Callable[[], None] = lambda: None) -> None:
    """The caller's part, until every job has ended: on_done for the jobs that ended (between two
    rounds); a round when the jobs' last post did not start one (a job ended instead); a round
    without a late job (its thread did not get the CPU) when a held station's keep-alive is due on
    the link's clock (on a virtual clock that never happens: the slaves' watchdogs do not run
    while the master waits either); the run's end on a lost link or a cancel."""
    cond = run.cond
    master = run.master
    with cond:
        while True:
            if run.stopped is not None:
                raise run.stopped
            if cancel is not None and cancel.is_set():
                raise Stopped("cancelled")
            if run.busy:
                cond.wait(MAX_WAIT_S)
                continue
            if run.ended:
                ended, run.ended = run.ended, []
                run.busy = True
                cond.release()
                try:
                    done(ended)
                finally:
                    cond.acquire()
                    run.busy = False
                    cond.notify_all()
                start()                     # the next jobs in their place
                continue
            if not run.running:
                return
            if run.full():
                run.round()
                continue
            # the stations whose jobs are about to post are exchanged by the next round anyway:
            # only those that are not (done, waiting for their turn, kept for the caller) count,
            # and the running ones too once their jobs are LATE_S late (a thread without the CPU)
            late = time.monotonic() - run.last_round > LATE_S
            due = _next_due(master, run.held if late else
                            [a for a in run.held if a not in run.running], run.within)
            now = master.link.now()
            if due is not None and now >= due:
                run.round()                 # a late job: the round goes without it
                continue
            wait = MAX_WAIT_S if due is None else min(MAX_WAIT_S, max(MIN_WAIT_S, due - now))
            cond.wait(wait if late else min(wait, LATE_S))


def _next_due(master: "Master", held: list[int], within: dict[int, float | None]) -> float | None:
    """The link time at which the first held station in data exchange needs its keep-alive."""
    due: float | None = None
    for a in held:
        w = within.get(a)
        st = master.stations.get(a)
        if not w or st is None or not st.in_data_exchange:
            continue
        last = master.last_request(a)
        t = (last if last is not None else master.link.now()) + w
        due = t if due is None else min(due, t)
    return due


def _round(master: "Master", posted: dict[int, bytes | C1Call], held: list[int],
           within: dict[int, float | None]) -> dict[int, _Answer]:
    """One Data_Exchange for every posted station (address order), then a keep-alive for every held
    station not posted whose last request is its keep_within() old. LinkLost is raised (the caller
    ends every job); any other BusError goes to its own job."""
    answers: dict[int, _Answer] = {}
    for a, outputs in posted.items():
        try:
            if isinstance(outputs, C1Call):
                answers[a] = master.c1_step(outputs)        # one telegram of a DP-V1 call
            else:
                answers[a] = master.exchange(a, outputs)
        except LinkLost:
            raise
        except BusError as e:
            answers[a] = e
    now = master.link.now()
    for a in held:
        w = within.get(a)
        if a in posted or not w:
            continue
        st = master.stations.get(a)
        last = master.last_request(a)
        if st is None or not st.in_data_exchange or (last is not None and now - last < w):
            continue
        try:
            master.exchange(a, None)
        except LinkLost:
            raise
        except BusError:
            pass                            # seen by its own next exchange
    return answers


__all__ = ["LockstepChannel", "MAX_JOBS", "Outcome", "ROUND_S", "Stopped", "run_together", "window"]
