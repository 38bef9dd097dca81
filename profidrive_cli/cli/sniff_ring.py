"""`pdrive sniff --ring SECONDS --trigger EXPR`: the black-box recorder's CLI glue -- options checked,
the port listened to (never written), one pcap per event through outfile.OutputFile (replace on
success) and one line (or JSON event) per event. The ring, the events and the triggers are
bustools/recorder.py and bustools/triggers.py; the likely causes bustools/causes.py.
"""

from __future__ import annotations

import os
import signal
import time
from datetime import datetime
from pathlib import Path
from typing import Any

from profidrive_cli import UsageError
from profidrive_cli.bustools.causes import likely_causes
from profidrive_cli.bustools.listen import listen
from profidrive_cli.bustools.recorder import Done, Event, Recorder
from profidrive_cli.bustools.triggers import TriggerSet, parse_all
from profidrive_cli.cli.common import emit_json, err, out
from profidrive_cli.dp.capture import LINKTYPES, Capture, PcapWriter, merge_errors
from profidrive_cli.outfile import OutputFile, OutputPathError, check_output_path

#: the file name in a --out directory; a pattern may use the same fields
DEFAULT_NAME = "pdrive-{time}-{n}-{trigger}.pcap"
FIELDS = ("{n}", "{time}", "{trigger}", "{station}")


class _Stop(Exception):
    """SIGTERM (systemd's stop): end the listening like Ctrl-C, writing what is open."""


def out_pattern(out_opt: str | None) -> str:
    """--out DIR (an existing directory: DEFAULT_NAME in it) or a file pattern with {n} or {time}
    (and optionally {trigger}, {station}); checked before the port opens."""
    target = out_opt or "."
    if Path(target).is_dir():
        pattern = str(Path(target) / DEFAULT_NAME)
    else:
        pattern = target
        if "{n}" not in pattern and "{time}" not in pattern:
            raise UsageError(f"--out {target}: not a directory, and as a file pattern it needs {{n}} "
                             f"or {{time}} (one file per event), e.g. events/ev-{{time}}-{{n}}.pcap")
    try:
        sample = name_for(pattern, 1, 0.0, "lost", 3)
    except (KeyError, IndexError, ValueError):
        raise UsageError(f"--out {target}: a pattern may use only {', '.join(FIELDS)}") from None
    check_output_path(sample, "--out")
    return pattern


def name_for(pattern: str, n: int, wall: float, trigger: str, station: int | None) -> str:
    stamp = datetime.fromtimestamp(wall).strftime("%Y%m%d-%H%M%S")
    return pattern.format(n=n, time=stamp, trigger=trigger, station="bus" if station is None else station)


def listen_baud(opts: Any) -> int | None:
    """The line's baud rate when the options name one (None with --baud auto: not known yet): the
    bus load and the slot time are figured with it."""
    return None if opts.baud in (None, "", "auto") else int(opts.baud_rate())


def _file_trigger(label: str) -> str:
    """lost(3) -> lost3, cycle(*)>20ms -> cycle-all: safe in a file name."""
    return "".join(ch for ch in label.replace("*", "all").split(">")[0] if ch.isalnum() or ch == "-")


def run_ring(opts: Any, ring_s: float | None, trigger_exprs: tuple[str, ...], after_s: float | None,
             out_opt: str | None, stations: tuple[str, ...], duration: float,
             linktype: str, others: dict[str, Any] | None = None) -> None:
    """Listen until --duration (given: else until Ctrl-C or SIGTERM), writing a capture per event."""
    import click

    from profidrive_cli.bustools.passive import PassiveDecoder, watch_list
    if ring_s is None:
        raise UsageError("--trigger, --after and --out belong to the recorder: give --ring SECONDS")
    given = [k for k, v in (others or {}).items() if v]
    if given:
        raise UsageError(f"--ring writes its own captures and listens to a port: not with "
                         f"{', '.join(given)}")
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
    watched = watch_list(stations) if stations else {}
    triggers = parse_all(list(trigger_exprs), set(watched))
    pattern = out_pattern(out_opt)
    tset = TriggerSet(triggers, PassiveDecoder(watched) if watched else None, baud=listen_baud(opts))
    rec = Recorder(tset, ring_s, after)
    writer = _Writer(pattern, LINKTYPES[linktype], opts.json, tset)
    cap = Capture()  # type: ignore[no-untyped-call]
    link = opts.open_link()
    if link.is_simulator:
        err.print("sim:// is silent unless a master talks: start `pdrive sim --plc --pty` and "
                  "record the pty it prints")
    if not opts.json:
        err.print(f"recording: ring {ring_s:g} s, {after:g} s after each event, triggers "
                  f"{', '.join(t.label for t in triggers)}; captures {pattern}", markup=False)
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
    if not opts.json:
        err.print(f"{rec.events} event(s), {writer.files} capture(s), {rec.telegrams} telegrams heard")


class _Writer:
    """Writes a Done capture (pcap through OutputFile) and prints its events."""

    def __init__(self, pattern: str, linktype: int, as_json: bool, tset: TriggerSet):
        self.pattern, self.linktype, self.as_json, self.tset = pattern, linktype, as_json, tset
        self.start = time.time()
        self.files = 0
        self._used: set[str] = set()

    def write_all(self, done: list[Done]) -> None:
        for d in done:
            self.write(d)

    def _path(self, d: Done) -> str:
        first = d.events[0].fired
        path = name_for(self.pattern, d.n, self.start + d.t_event,
                        _file_trigger(first.trigger.label), first.station)
        if path in self._used:                       # two events in one second, {time} only
            stem, dot, ext = path.rpartition(".")
            path = f"{stem}-{d.n}.{ext}" if dot else f"{path}-{d.n}"
        self._used.add(path)
        return path

    def write(self, d: Done) -> None:
        path = self._path(d)
        f = OutputFile(path, "wb", what="--out")
        try:
            f.open()
            w = PcapWriter(f, self.linktype, self.start)
            for t, raw in d.packets:
                w.write(t, raw)
            f.commit()
        except OutputPathError as e:                 # the directory went away: a bus-side problem
            f.discard()
            from profidrive_cli.outfile import OutputWriteError
            raise OutputWriteError(str(e)) from None
        finally:
            if not f.committed:
                f.discard()
        self.files += 1
        for ev in d.events:
            self._say(d, ev, path)

    def _say(self, d: Done, e: Event, path: str) -> None:
        f = e.fired
        causes = [c for c in likely_causes(self.tset.live)
                  if not c.stations or f.station is None or f.station in c.stations]
        wall = datetime.fromtimestamp(self.start + f.t)
        window = (f"{len(d.packets)} telegrams, {d.before_s:.1f} s before, {d.after_s:.1f} s after"
                  + ("" if d.complete else ", listening ended first")
                  + (f", {d.dropped} over the cap not kept" if d.dropped else ""))
        if self.as_json:
            emit_json({"event": "trigger", "t_s": round(f.t, 6),
                       "time": wall.isoformat(timespec="milliseconds"), "trigger": f.trigger.label,
                       "station": f.station, "text": f.text, "repeats": e.repeats,
                       "capture": os.fspath(path), "telegrams": len(d.packets),
                       "before_s": round(d.before_s, 3), "after_s": round(d.after_s, 3),
                       "complete": d.complete, "causes": [c.as_dict() for c in causes]})
            return
        rep = f" (x{e.repeats + 1})" if e.repeats else ""
        why = f"; likely: {causes[0].title}" if causes else ""
        out.print(f"{wall.strftime('%Y-%m-%d %H:%M:%S.%f')[:-3]}  {f.trigger.label}{rep}  {f.text}; "
                  f"capture {path} ({window}){why}", markup=False, soft_wrap=True)
