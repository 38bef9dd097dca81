"""pdrive sniff: passive capture, one line per frame; pcap output; offline decoding of raw files."""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Generator, Iterator
from typing import IO, TYPE_CHECKING

import click

from profidrive_cli import UsageError
from profidrive_cli.bustools.listen import listen
from profidrive_cli.cli.common import BusOptions, bus_options, out
from profidrive_cli.datafile import DataFileError, open_input_file
from profidrive_cli.dp.capture import HOLD, LINKTYPES, Capture, ErrorMerger, PcapWriter, TimeRangeError, format_line
from profidrive_cli.outfile import OutputFile, check_output_path

if TYPE_CHECKING:
    from profidrive_cli.cli.sniff_view import SniffView
    from profidrive_cli.dp.capfile import CaptureReader
    from profidrive_cli.dp.capture import Captured
    from profidrive_cli.link.base import Link


# a raw capture file: 16 MiB is ~14 s of a saturated bus at 12 Mbit/s, ~2 h at 19.2 kbit/s
MAX_CAPTURE_BYTES = 16 * 1024 * 1024
#: --from-file is read and shown this many octets at a time: the memory stays flat in the file's size
CHUNK_BYTES = 16 * 1024


def _line(c: Captured) -> str:
    return format_line(c)


@click.command("sniff")
@click.option("--duration", default=10.0, show_default=True, type=float, help="Seconds to listen.")
@click.option("--pcap", "pcap_file", default=None, metavar="FILE",
              help="Also write a pcap file (link type 147 DLT_USER0, which `pdrive wireshark install` "
                   "lets Wireshark decode; see --linktype).")
@click.option("--linktype", type=click.Choice(sorted(LINKTYPES)), default="147", show_default=True,
              help="pcap link type: 147 (DLT_USER0, opened by Wireshark with pdrive's dissector) or "
                   "257 (PROFIBUS_DL, for tools that know it).")
@click.option("--raw", "raw_out", default=None, metavar="FILE",
              help="Also write the received octets as they came (decode later with --from-file).")
@click.option("--from-file", "raw_file", default=None, metavar="FILE",
              help="Decode a capture file offline instead of listening: pcap, pcapng or ProfiTrace .ptd "
                   "by extension, any other as raw octets (a regular file up to 16 MiB).")
@click.option("--station", "stations", multiple=True, metavar="ADDR=PROFILE[:LAYOUT]",
              help="Decode this station's Data_Exchange as its drive sees it (command, state, Hz, "
                   "parameter requests), e.g. 3=fuji-g1 or 6=moeller:ppo1. Repeatable.")
@click.option("--live", is_flag=True,
              help="A passive live list (stations, DP state, master cycle time, retries, errors) "
                   "refreshed in place instead of one line per frame.")
@click.option("--gsd-dir", metavar="DIR", default=None,
              help="Your GSD files (searched before the library): every slave's data by module.")
@click.option("--ring", type=float, default=None, metavar="SECONDS",
              help="Black-box recorder: keep the last SECONDS of telegrams and write one pcap per "
                   "event (--trigger) with them and --after seconds after it; runs until Ctrl-C "
                   "unless --duration is given.")
@click.option("--trigger", "triggers", multiple=True, metavar="EXPR",
              help="With --ring: what makes an event, e.g. 'lost(*),fault(7),cycle>20ms' "
                   "(docs/commands.md). Repeatable.")
@click.option("--after", "after_s", type=float, default=None, metavar="SECONDS",
              help="With --ring: seconds recorded after an event (default: the ring's).")
@click.option("--out", "out_dir", default=None, metavar="DIR|PATTERN",
              help="With --ring: a directory, or a file pattern with {n} or {time} (default: .).")
@click.option("--max-disk", "max_disk", default=None, metavar="SIZE",
              help="With --ring: the most disk its captures take, e.g. 100M or 2G; the oldest are "
                   "removed first (default: 1G).")
@click.option("--keep", "keep_days", type=float, default=None, metavar="DAYS",
              help="With --ring: remove its captures older than DAYS (default: kept while within "
                   "--max-disk).")
@bus_options
def sniff_cmd(opts: BusOptions, duration: float, pcap_file: str | None, linktype: str,
              raw_out: str | None, raw_file: str | None, stations: tuple[str, ...], live: bool,
              gsd_dir: str | None, ring: float | None, triggers: tuple[str, ...],
              after_s: float | None, out_dir: str | None, max_disk: str | None,
              keep_days: float | None) -> None:
    """Passive capture: one line per frame (time, SD, SA->DA, SAPs, FC in words, service, DU).

    --pcap and --raw files are written beside the target and replace it only when the capture
    ended well (also by Ctrl-C); on an error an existing file stays as it was.
    """
    if (ring is not None or triggers or after_s is not None or out_dir is not None
            or max_disk is not None or keep_days is not None):
        from profidrive_cli.cli.sniff_ring import run_ring
        return run_ring(opts, ring, triggers, after_s, out_dir, stations, duration, linktype,
                        others={"--pcap": pcap_file, "--raw": raw_out, "--live": live},
                        max_disk=max_disk, keep_days=keep_days,
                        from_file=_ring_source(raw_file) if raw_file else None)
    if raw_out is not None and raw_file:
        raise UsageError("--raw writes what is received from a port; with --from-file there is nothing "
                         "to receive")
    if not raw_file and duration <= 0:
        raise UsageError("--duration must be positive")
    # every output path checked before the port is opened; each written only on success
    files = [OutputFile(path, "wb", what=what) for path, what in ((pcap_file, "--pcap"),
                                                                  (raw_out, "--raw")) if path]
    for f in files:
        check_output_path(f.path, f.what)
    cap = Capture()
    merger = ErrorMerger()
    view = _view(stations, live, opts.json, opts if live else None, gsd_dir, bool(raw_file))
    # check the input before anything is written; it is read in chunks and shown as it is read.
    # pcap, pcapng and ProfiTrace .ptd files by their extension (dp/capfile.py), any other as raw
    packets = _packet_file(raw_file) if raw_file else None
    src = (open_input_file(raw_file, "raw capture", MAX_CAPTURE_BYTES)
           if raw_file and packets is None else None)
    # pcap times are wall clock: the capture's start (for --from-file: when the raw file was last
    # written, the end of its capture) plus the monotonic offset of each frame
    start_wall = _mtime(raw_file) if raw_file else time.time()
    count = 0
    try:
        for f in files:
            f.open()
        writer = PcapWriter(files[0], LINKTYPES[linktype], start_wall) if pcap_file else None
        raw_fh = files[-1] if raw_out else None

        def show(items: list[Captured], end_of_chunk: bool = True) -> None:
            nonlocal count
            merged = merger.feed(items)
            if end_of_chunk:
                merged += merger.flush()
            count += len(merged)
            if writer is not None:
                for c in merged:
                    if c.frame is not None:
                        writer.write(c.t, c.raw)
            view.frames(merged)
            view.flush()

        if raw_file:
            def started(t0: float) -> None:
                if writer is not None:
                    writer.start = t0                # the file's own clock: its first telegram
            for items, last in file_entries(raw_file, cap, packets, src, started):
                show(items, end_of_chunk=last)
            view.finish(cap._t)
        else:
            link = opts.open_link()
            start = time.monotonic()
            try:
                _listen_start(link)

                def on_data(data: bytes, t: float) -> None:
                    if raw_fh is not None:
                        raw_fh.write(data)
                    show(cap.feed(data, t))

                if writer is not None:
                    writer.start = time.time()       # wall clock of t = 0
                listen(link, duration, on_data, on_tick=view.tick)
            except KeyboardInterrupt:
                pass                                 # Ctrl-C ends a capture: keep what was captured
            finally:
                link.close()
                view.finish(time.monotonic() - start)
        for f in files:
            f.commit()
    except TimeRangeError as e:                      # a time the --pcap file cannot hold
        raise UsageError(f"{raw_file + ': ' if raw_file else ''}--pcap {pcap_file}: {e}") from None
    finally:
        if src is not None:
            src.close()
        if packets is not None:
            packets.close()
        for f in files:
            if not f.committed:
                f.discard()
    if raw_file:
        return
    if not opts.json and not live:
        out.print(f"{count} frame(s)")


#: packets of a pcap / pcapng / .ptd file decoded before their lines are written
PACKETS_PER_SHOW = 1024


def file_entries(path: str, cap: Capture, packets: CaptureReader | None, src: IO[bytes] | None,
                 started: Callable[[float], None]) -> Iterator[tuple[list[Captured], bool]]:
    """A capture file's entries in batches, (entries, last), as decoded in one piece: a packet
    file's (`packets`) timed from its first packet (`started(its time)` is called then), a raw
    file's (`src`, read in CHUNK_BYTES) all at 0; the last batch ends with the truncated telegram
    the file ended in, if any. Errors of a run of garbage over two batches are for an ErrorMerger
    to join (end_of_chunk at the last)."""
    if packets is not None:
        t0 = None
        batch: list[Captured] = []
        for p in packets:
            if t0 is None:
                t0 = p.t
                started(t0)
            batch += cap.feed(p.raw, p.t - t0)
            if len(batch) >= PACKETS_PER_SHOW:
                yield batch, False
                batch = []
        rest = cap.feed(b"", cap._t)
        yield (batch + rest + [_truncated(cap)] if len(cap.rx) else batch + rest), True
    elif src is not None:
        # shown as if decoded in one piece: a telegram that starts in the chunk's last octets
        # waits for the next (HOLD), a garbage run that goes on in it stays one entry
        for chunk in _chunks(src, path):
            yield cap.feed(chunk, 0.0, hold=HOLD), False
        rest = cap.feed(b"", 0.0)
        yield (rest + [_truncated(cap)] if len(cap.rx) else rest), True


def _packet_file(path: str) -> CaptureReader | None:
    """The open packet reader of a pcap, pcapng or ProfiTrace .ptd file (by extension; its header
    checked now, before anything is written); None for a raw octet file (any other extension)."""
    from profidrive_cli.dp.capfile import capture_format, open_capture
    fmt = capture_format(path, "raw")
    return None if fmt == "raw" else open_capture(path, fmt)


class RingSource:
    """--ring --from-file: the file (its path, its modification time: the wall clock of its start
    when it carries no times) and its entries (file_entries), opened when they are first read --
    after the recorder's options were checked -- and closed when done."""

    def __init__(self, path: str):
        self.path = path
        self.mtime = _mtime(path)

    def entries(self, cap: Capture, started: Callable[[float], None]
                ) -> Generator[tuple[list[Captured], bool], None, None]:
        packets = _packet_file(self.path)
        src = open_input_file(self.path, "raw capture", MAX_CAPTURE_BYTES) if packets is None else None
        try:
            yield from file_entries(self.path, cap, packets, src, started)
        finally:
            if src is not None:
                src.close()
            if packets is not None:
                packets.close()


def _ring_source(path: str) -> RingSource:
    return RingSource(path)


def _chunks(fh: IO[bytes], path: str) -> Iterator[bytes]:
    """The file's octets, CHUNK_BYTES at a time; DataFileError when it grew past the size limit or
    cannot be read."""
    total = 0
    while True:
        try:
            chunk = fh.read(CHUNK_BYTES)
        except OSError as e:
            raise DataFileError(path, None, f"cannot read raw capture: {e.strerror or e}") from None
        if not chunk:
            return
        total += len(chunk)
        if total > MAX_CAPTURE_BYTES:
            raise DataFileError(path, None, f"too large for a raw capture: more than "
                                            f"{MAX_CAPTURE_BYTES} bytes")
        yield chunk


def _mtime(path: str) -> float:
    try:
        return os.path.getmtime(path)
    except OSError:
        return time.time()


def _truncated(cap: Capture) -> Captured:
    from profidrive_cli.dp.capture import Captured
    raw = bytes(cap.rx.buf)
    cap.rx.reset()
    return Captured(cap._t, raw, None, "truncated frame at end of input")


def _view(stations: tuple[str, ...], live: bool, as_json: bool, opts: BusOptions | None = None,
          gsd_dir: str | None = None, from_file: bool = False) -> SniffView:
    """How each frame is shown: one line / JSON object (with --station the drives' words, every other
    slave by its GSD's modules, `gsd_dir` searched first), or the --live list (its bus load figured
    at the baud rate `opts` give; for a file only a rate given by --baud or PDRIVE_BAUD: the default
    and a port's configured rate say nothing about the line a file was captured on)."""
    from profidrive_cli.cli.sniff_ring import listen_baud
    from profidrive_cli.cli.sniff_view import SniffView
    return SniffView(stations, live, as_json, gsd_dir=gsd_dir,
                     baud=listen_baud(opts) if opts is not None and (
                         not from_file or opts.source_of("baud").startswith(("option", "env")))
                     else None)


def _listen_start(link: Link) -> None:
    """Before listening: sim:// has no master of its own (point to one that has); octets a port
    buffered before the capture started are dropped (they would carry the wrong times). Sniff
    never writes to the port."""
    if link.is_simulator:
        from profidrive_cli.cli.common import err
        err.print("sim:// is silent unless a master talks: nothing to sniff here. For a running "
                  "bus to listen to, start `pdrive sim --plc --pty` and sniff the pty it prints "
                  "(`pdrive sniff --port /dev/pts/N --station 3=fuji-g1 ...`)")
    link.flush_input()
