"""pdrive sniff: passive capture, one line per frame; pcap output; offline decoding of raw files."""

from __future__ import annotations

import time

import click

from profidrive_cli import UsageError
from profidrive_cli.cli.common import bus_options, emit_json, out
from profidrive_cli.datafile import read_input_file
from profidrive_cli.dp.capture import Capture, PcapWriter, format_line, merge_errors
from profidrive_cli.outfile import OutputFile, check_output_path


# a raw capture file: 16 MiB is ~14 s of a saturated bus at 12 Mbit/s, ~2 h at 19.2 kbit/s
MAX_CAPTURE_BYTES = 16 * 1024 * 1024


def _line(c) -> str:
    return format_line(c)


@click.command("sniff")
@click.option("--duration", default=10.0, show_default=True, type=float, help="Seconds to listen.")
@click.option("--pcap", "pcap_file", default=None, metavar="FILE",
              help="Also write a pcap file (link type 257, PROFIBUS_DL).")
@click.option("--raw", "raw_out", default=None, metavar="FILE",
              help="Also write the received octets as they came (decode later with --from-file).")
@click.option("--from-file", "raw_file", default=None, metavar="FILE",
              help="Decode a raw byte capture (a regular file up to 16 MiB) offline instead of listening.")
@bus_options
def sniff_cmd(opts, duration, pcap_file, raw_out, raw_file):
    """Passive capture: one line per frame (time, SD, SA->DA, SAPs, FC in words, service, DU).

    --pcap and --raw files are written beside the target and replace it only when the capture
    ended well (also by Ctrl-C); on an error an existing file stays as it was.
    """
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
    # read (and check) the input before anything is written
    raw = read_input_file(raw_file, "raw capture", MAX_CAPTURE_BYTES) if raw_file else None
    count = 0
    try:
        for f in files:
            f.open()
        writer = PcapWriter(files[0]) if pcap_file else None
        raw_fh = files[-1] if raw_out else None

        def show(items):
            nonlocal count
            for c in merge_errors(items):
                count += 1
                if writer and c.frame is not None:
                    writer.write(c.t, c.raw)
                if opts.json:
                    emit_json(frame_json(c.describe()))
                else:
                    out.print(_line(c), markup=False)

        if raw is not None:
            show(cap.feed(raw, 0.0))
            if len(cap.rx):
                show([_truncated(cap)])
        else:
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
                        if raw_fh is not None:
                            raw_fh.write(data)
                        show(cap.feed(data, time.monotonic() - start))
            except KeyboardInterrupt:
                pass                                 # Ctrl-C ends a capture: keep what was captured
            finally:
                link.close()
        for f in files:
            f.commit()
    finally:
        for f in files:
            if not f.committed:
                f.discard()
    if raw_file:
        return
    if not opts.json:
        out.print(f"{count} frame(s)")


def frame_json(d: dict) -> dict:
    """A frame in the contract's shape (docs/json.md): "event" frame (or bad_frame), t_s."""
    out = {"event": "bad_frame" if "error" in d else "frame"}
    out.update(("t_s" if k == "t" else k, v) for k, v in d.items())
    return out


def _truncated(cap):
    from profidrive_cli.dp.capture import Captured
    raw = bytes(cap.rx.buf)
    cap.rx.reset()
    return Captured(cap._t, raw, None, "truncated frame at end of input")
