"""`pdrive sniff --ring SECONDS --trigger EXPR`: the black-box recorder's CLI glue -- options checked,
the port listened to (never written), one pcap per event through the store (bustools/ringstore.py:
outfile.OutputFile, the disk bound, a failed write an event and the listening goes on) and one line
(or JSON event) per event, removal, disk state and error. The ring, the events and the triggers are
bustools/recorder.py and bustools/triggers.py; the likely causes bustools/causes.py.
"""

from __future__ import annotations

import signal
import time
from datetime import datetime
from collections.abc import Callable, Generator
from typing import TYPE_CHECKING, Any, Protocol

from profidrive_cli import UsageError
from profidrive_cli.bustools.causes import likely_causes
from profidrive_cli.bustools.listen import listen
from profidrive_cli.bustools.recorder import Done, Event, Recorder
from profidrive_cli.bustools.ringstore import (
    DEFAULT_MAX_DISK, DiskState, Failed, Pattern, Removed, Store, out_pattern, parse_size, size_text,
    unique,
)
from profidrive_cli.bustools.triggers import TriggerSet, parse_all
from profidrive_cli.cli.common import emit_json, err, out
from profidrive_cli.dp.capture import LINKTYPES, Capture, PcapWriter, merge_errors
from profidrive_cli.outfile import OutputWriteError

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.dp.capture import Captured


class RingSource(Protocol):
    """--ring --from-file's file (sniff_cmd.RingSource): its path, its modification time and its
    entries in batches, (entries, last), opened when first read and closed when done."""
    path: str
    mtime: float

    def entries(self, cap: Capture, started: Callable[[float], None]
                ) -> Generator[tuple[list[Captured], bool], None, None]: ...


class _Stop(Exception):
    """SIGTERM (systemd's stop): end the listening like Ctrl-C, writing what is open."""


def listen_baud(opts: Any) -> int | None:
    """The line's baud rate when the options name one (None with --baud auto: not known yet): the
    bus load and the slot time are figured with it."""
    return None if opts.baud in (None, "", "auto") else int(opts.baud_rate())


def run_ring(opts: Any, ring_s: float | None, trigger_exprs: tuple[str, ...], after_s: float | None,
             out_opt: str | None, stations: tuple[str, ...], duration: float,
             linktype: str, others: dict[str, Any] | None = None, max_disk: str | None = None,
             keep_days: float | None = None, from_file: RingSource | None = None) -> None:
    """Listen until --duration (given: else until Ctrl-C or SIGTERM), writing a capture per event.
    A capture that cannot be written is an error event and the listening goes on; the command
    ends with exit 1 (OutputWriteError) when any was not written. With `from_file` (--from-file)
    the file's telegrams instead of the port's, on the file's clock (a pcap's packet times, from
    its first; a raw file's all at 0, its captures' wall clock the file's modification time)."""
    import click

    from profidrive_cli.bustools.passive import PassiveDecoder, watch_list
    if ring_s is None:
        raise UsageError("--trigger, --after, --out, --max-disk and --keep belong to the recorder: "
                         "give --ring SECONDS")
    given = [k for k, v in (others or {}).items() if v]
    if given:
        raise UsageError(f"--ring writes its own captures: not with {', '.join(given)}")
    if ring_s <= 0:
        raise UsageError("--ring must be positive (seconds before an event to keep)")
    ctx = click.get_current_context(silent=True)
    until: float | None = duration
    if ctx is not None and ctx.get_parameter_source("duration") == click.core.ParameterSource.DEFAULT:
        until = None                            # the recorder runs until it is stopped
    after = ring_s if after_s is None else after_s
    if after < 0:
        raise UsageError("--after must be 0 or more seconds")
    if until is not None and until <= 0:
        raise UsageError("--duration must be positive")
    max_bytes = DEFAULT_MAX_DISK if max_disk is None else parse_size(max_disk)
    if keep_days is not None and not keep_days > 0:
        raise UsageError("--keep must be above 0 days")
    watched = watch_list(stations) if stations else {}
    triggers = parse_all(list(trigger_exprs), set(watched))
    pattern = out_pattern(out_opt)
    # a file's line rate only from --baud / PDRIVE_BAUD (as sniff --from-file --live: the default
    # and a port's configured rate say nothing about the line the file was captured on)
    baud = listen_baud(opts) if from_file is None or opts.source_of("baud").startswith(("option", "env")) \
        else None
    tset = TriggerSet(triggers, PassiveDecoder(watched) if watched else None, baud=baud)
    store = Store(pattern, max_bytes, None if keep_days is None else keep_days * 86400.0)
    # numbered on after an earlier run's captures: a restart never writes over one of them
    rec = Recorder(tset, ring_s, after, first_n=store.last_number() + 1)
    writer = _Writer(pattern, LINKTYPES[linktype], opts.json, tset, store)
    cap = Capture()
    if from_file is not None:
        return _from_file(from_file, opts.json, ring_s, after, triggers, pattern, max_bytes,
                          keep_days, rec, writer, store)
    link = opts.open_link()
    if link.is_simulator:
        err.print("sim:// is silent unless a master talks: start `pdrive sim --plc --pty` and "
                  "record the pty it prints")
    if not opts.json:
        keep = "" if keep_days is None else f", none older than {keep_days:g} days (--keep)"
        err.print(f"recording: ring {ring_s:g} s, {after:g} s after each event, triggers "
                  f"{', '.join(t.label for t in triggers)}; captures {pattern.text}, at most "
                  f"{size_text(max_bytes)} of them (--max-disk){keep}"
                  + (f"; numbered on from {rec.captures + 1} (an earlier run's are there)"
                     if rec.captures else ""), markup=False)
    old = signal.getsignal(signal.SIGTERM)

    def on_term(*_a: object) -> None:
        raise _Stop()
    signal.signal(signal.SIGTERM, on_term)
    try:
        link.flush_input()
        writer.start = time.time()

        def on_data(data: bytes, t: float) -> None:
            writer.write_all(rec.feed(merge_errors(cap.feed(data, t))))

        listen(link, until, on_data, on_tick=lambda t: writer.write_all(rec.tick(t)))
    except (KeyboardInterrupt, _Stop):
        pass
    finally:
        signal.signal(signal.SIGTERM, old)
        link.close()
    writer.write_all(rec.close())
    _summary(opts.json, rec, store)


def _summary(as_json: bool, rec: Recorder, store: Store, heard: str = "heard") -> None:
    """The closing line (text mode); OutputWriteError (exit 1) when a capture was not written."""
    if not as_json:
        err.print(f"{rec.events} event(s), {store.written} capture(s)"
                  + (f", {store.failed} not written" if store.failed else "")
                  + (f", {store.removed} removed (disk bound)" if store.removed else "")
                  + f", {rec.telegrams} telegrams {heard}")
    first = store.first_failure
    if first is not None:
        raise OutputWriteError(f"{store.failed} capture(s) could not be written (the first: capture "
                               f"{first.n}, {first.path}: {first.reason})")


def _from_file(source: RingSource, as_json: bool, ring_s: float, after: float, triggers: list[Any],
               pattern: Pattern, max_bytes: int, keep_days: float | None, rec: Recorder,
               writer: _Writer, store: Store) -> None:
    """--ring --from-file: the file's telegrams through the recorder, in the order and with the
    times `sniff --from-file` shows them (sniff_cmd.file_entries), a capture per event."""
    from profidrive_cli.dp.capture import ErrorMerger
    writer.start = source.mtime
    if not as_json:
        keep = "" if keep_days is None else f", none older than {keep_days:g} days (--keep)"
        err.print(f"from {source.path}: ring {ring_s:g} s, {after:g} s after each event, triggers "
                  f"{', '.join(t.label for t in triggers)}; captures {pattern.text}, at most "
                  f"{size_text(max_bytes)} of them (--max-disk){keep}", markup=False)

    def started(t0: float) -> None:
        writer.start = t0                          # a packet file's clock: its first packet
    merger = ErrorMerger()
    entries = source.entries(Capture(), started)
    try:
        for items, last in entries:
            merged = merger.feed(items)
            if last:
                merged += merger.flush()
            writer.write_all(rec.feed(merged))
    except KeyboardInterrupt:
        pass
    finally:
        entries.close()
    writer.write_all(rec.close())
    _summary(as_json, rec, store, "read")


def pcap_size(packets: list[tuple[float, bytes]]) -> int:
    """A classic pcap's size: the 24-octet header, 16 octets and the telegram per packet."""
    return 24 + sum(16 + len(raw) for _, raw in packets)


class _Writer:
    """Writes a Done capture (pcap through the Store: the disk bound, the write faults as events)
    and prints what happened: the store's events, then the capture's trigger events."""

    def __init__(self, pattern: Pattern, linktype: int, as_json: bool, tset: TriggerSet,
                 store: Store | None = None):
        self.pattern, self.linktype, self.as_json, self.tset = pattern, linktype, as_json, tset
        self.store = store or Store(pattern)
        self.start = time.time()
        #: the paths taken in the newest capture's second: a name repeats only within one second
        #: ({time} without {n}), so the set never holds more than one second's captures
        self._second: int | None = None
        self._used: set[str] = set()

    @property
    def files(self) -> int:
        return self.store.written

    def write_all(self, done: list[Done]) -> None:
        for d in done:
            self.write(d)

    def _path(self, d: Done) -> str:
        first = d.events[0].fired
        wall = self.start + d.t_event
        path = self.pattern.path(d.n, wall, first.trigger.label, first.station)
        if int(wall) != self._second:
            self._second, self._used = int(wall), set()
        if path in self._used:                       # two events in one second, {time} only
            path = unique(path, d.n)
        self._used.add(path)
        return path

    def write(self, d: Done) -> bool:
        """The capture written (True) or not (False: its error event said why)."""
        path = self._path(d)

        def fill(fh: Any) -> None:
            w = PcapWriter(fh, self.linktype, self.start)
            for t, raw in d.packets:
                w.write(t, raw)
        written, happened = self.store.save(d.n, path, pcap_size(d.packets), fill)
        for h in happened:
            self._say_store(h)
        for ev in d.events:
            self._say(d, ev, path, written)
        return written

    def _emit(self, obj: dict[str, Any], line: str) -> None:
        if self.as_json:
            emit_json(obj)
        else:
            out.print(line, markup=False, soft_wrap=True)

    def _say_store(self, h: Removed | Failed | DiskState) -> None:
        now = datetime.now()
        stamp = now.strftime('%Y-%m-%d %H:%M:%S.%f')[:-3]
        iso = now.isoformat(timespec="milliseconds")
        if isinstance(h, Removed):
            obj: dict[str, Any] = {"event": "removed", "time": iso, "path": h.path, "bytes": h.size,
                                   "why": h.why, "count": h.count}
            if h.error is not None:
                obj["error"] = h.error
                line = f"{stamp}  could not remove {h.path} ({h.why}): {h.error}"
            else:
                line = (f"{stamp}  removed {h.path} ({size_text(h.size)}, {h.why}; "
                        f"{h.count} removed so far)")
            self._emit(obj, line)
        elif isinstance(h, DiskState):
            self._emit({"event": "disk", "time": iso, "full": h.full, "directory": h.directory,
                        "text": h.reason},
                       f"{stamp}  disk full in {h.directory} ({h.reason}): captures are not written "
                       f"until there is room; still listening" if h.full else
                       f"{stamp}  disk has room again in {h.directory}: {h.reason}")
        else:
            text = f"capture {h.n} not written: --out {h.path}: {h.reason}"
            self._emit({"event": "error", "error": text, "exit_code": 1, "time": iso,
                        "capture": h.n, "path": h.path, "reason": h.reason},
                       f"{stamp}  error: {text}; still listening")

    def _say(self, d: Done, e: Event, path: str, written: bool = True) -> None:
        f = e.fired
        causes = [c for c in likely_causes(self.tset.live)
                  if not c.stations or f.station is None or f.station in c.stations]
        wall = datetime.fromtimestamp(self.start + f.t)
        window = (f"{len(d.packets)} telegrams, {d.before_s:.1f} s before, {d.after_s:.1f} s after"
                  + ("" if d.complete else ", listening ended first")
                  + (f", {d.dropped} over the cap not kept" if d.dropped else ""))
        rep = f" (x{e.repeats + 1})" if e.repeats else ""
        why = f"; likely: {causes[0].title}" if causes else ""
        self._emit({"event": "trigger", "t_s": round(f.t, 6),
                    "time": wall.isoformat(timespec="milliseconds"), "trigger": f.trigger.label,
                    "station": f.station, "text": f.text, "repeats": e.repeats,
                    "capture": path, "written": written, "telegrams": len(d.packets),
                    "before_s": round(d.before_s, 3), "after_s": round(d.after_s, 3),
                    "complete": d.complete, "causes": [c.as_dict() for c in causes]},
                   f"{wall.strftime('%Y-%m-%d %H:%M:%S.%f')[:-3]}  {f.trigger.label}{rep}  {f.text}; "
                   f"capture {path}{'' if written else ' NOT WRITTEN'} ({window}){why}")
