"""pdrive sniff: passive capture, one line per frame; pcap output; offline decoding of raw files."""

from __future__ import annotations

import time

import click

from profidrive_cli import UsageError
from profidrive_cli.cli.common import bus_options, emit_json, out
from profidrive_cli.datafile import read_input_file
from profidrive_cli.fdl.capture import Capture, PcapWriter, merge_errors


# a raw capture file: 16 MiB is ~14 s of a saturated bus at 12 Mbit/s, ~2 h at 19.2 kbit/s
MAX_CAPTURE_BYTES = 16 * 1024 * 1024


def _line(c) -> str:
    d = c.describe()
    if "error" in d:
        return f"{d['t']:>12.6f}  !! {d['error']}: {d['raw']}"
    if d["sd"] == "SC":
        return f"{d['t']:>12.6f}  SC   short acknowledge"
    if d["sd"] == "SD4":
        return f"{d['t']:>12.6f}  SD4  token {d['sa']} -> {d['da']}"
    saps = "" if d["dsap"] is None else f" [{d['ssap']}->{d['dsap']}]"
    return (f"{d['t']:>12.6f}  {d['sd']}  {d['sa']:>3} -> {d['da']:<3}{saps}  {d['fc_text']}  "
            f"{d['service']}  {d['du']}")


@click.command("sniff")
@click.option("--duration", default=10.0, show_default=True, type=float, help="Seconds to listen.")
@click.option("--pcap", "pcap_file", default=None, type=click.Path(dir_okay=False, writable=True),
              help="Also write a pcap file (link type 257, PROFIBUS_DL).")
@click.option("--from-file", "raw_file", default=None, metavar="FILE",
              help="Decode a raw byte capture (a regular file up to 16 MiB) offline instead of listening.")
@bus_options
def sniff_cmd(opts, duration, pcap_file, raw_file):
    """Passive capture: one line per frame (time, SD, SA->DA, SAPs, FC in words, service, DU)."""
    cap = Capture()
    # read (and check) the input before anything is written
    raw = read_input_file(raw_file, "raw capture", MAX_CAPTURE_BYTES) if raw_file else None
    pcap_fh = open(pcap_file, "wb") if pcap_file else None
    writer = PcapWriter(pcap_fh) if pcap_fh else None
    count = 0

    def show(items):
        nonlocal count
        for c in merge_errors(items):
            count += 1
            if writer and c.frame is not None:
                writer.write(c.t, c.raw)
            if opts.json:
                emit_json(c.describe())
            else:
                out.print(_line(c), markup=False)

    try:
        if raw is not None:
            show(cap.feed(raw, 0.0))
            if len(cap.rx):
                show([_truncated(cap)])
            return
        if duration <= 0:
            raise UsageError("--duration must be positive")
        link = opts.open_link()
        try:
            if link.is_simulator:
                from profidrive_cli.cli.common import err
                err.print("sim:// is silent unless a master talks: nothing to sniff "
                          "(use `pdrive sim --pty` and a master on the other end)")
            start = time.monotonic()
            end = start + duration
            while time.monotonic() < end:
                data = link.read(min(end, time.monotonic() + 0.2))
                if data:
                    show(cap.feed(data, time.monotonic() - start))
        except KeyboardInterrupt:
            pass
        finally:
            link.close()
    finally:
        if pcap_fh:
            pcap_fh.close()
    if not opts.json:
        out.print(f"{count} frame(s)")


def _truncated(cap):
    from profidrive_cli.fdl.capture import Captured
    raw = bytes(cap.rx.buf)
    cap.rx.reset()
    return Captured(cap._t, raw, None, "truncated frame at end of input")
