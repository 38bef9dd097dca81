"""`pdrive convert IN OUT`: a capture file into another format, the formats by extension (dp/capfile.py:
raw, pcap, pcapng, ProfiTrace .ptd). Streams: memory does not grow with the file."""

from __future__ import annotations

import click

from profidrive_cli import UsageError


@click.command("convert")
@click.argument("src", metavar="IN")
@click.argument("dst", metavar="OUT")
@click.option("--linktype", type=click.Choice(["147", "257"]), default=None,
              help="pcap / pcapng link type of OUT: 147 (DLT_USER0, pdrive's dissector) or 257 "
                   "(PROFIBUS_DL). Default: IN's when it is a pcap or pcapng, else 147.")
@click.option("--baud", type=int, default=None, metavar="BIT/S",
              help="A .ptd OUT: the line's baud rate (in its header, and the unit of its bit-time "
                   "timestamps). Default: IN's when it is a .ptd, else 1500000.")
def convert_cmd(src: str, dst: str, linktype: str | None, baud: int | None) -> None:
    """Convert a capture between raw, pcap, pcapng and ProfiTrace .ptd, by the files' extensions.

    What a format cannot hold is dropped: raw keeps only the octets, pcap no direction and no
    comment, ptd keeps a telegram's fields (its FCS is computed again). A time OUT cannot hold
    (pcap: until 2106-02-07; ptd: not before the first packet's second) is an error. OUT is
    replaced only when the whole file converted; on any error the old OUT stays as it was.
    """
    from profidrive_cli.cli.common import out
    from profidrive_cli.dp.capfile import PTD_BAUDS, capture_format, open_capture, open_writer
    from profidrive_cli.dp.capture import TimeRangeError
    from profidrive_cli.outfile import OutputFile, OutputWriteError, check_output_path

    fin, fout = capture_format(src), capture_format(dst)
    reader = open_capture(src, fin)                       # the header read and checked: before OUT
    try:
        lt = int(linktype) if linktype else (reader.linktype or 147)
        rate = baud if baud is not None else (reader.baud or 1_500_000)
        if fout == "ptd" and rate not in PTD_BAUDS:
            raise UsageError(f"--baud {rate}: a ProfiTrace file knows only "
                             f"{', '.join(str(b) for b in PTD_BAUDS)} bit/s")
        check_output_path(dst, "output capture")
        target = OutputFile(dst, "wb", what="output capture")
        fh = target.open()
        try:
            try:
                writer = open_writer(fh, fout, linktype=lt, baud=rate)
                for p in reader:
                    writer.write(p)
                writer.close()
            except TimeRangeError as e:             # a time OUT's format cannot hold: IN's packet
                raise UsageError(f"{src}: {e}") from None
            except OSError as e:
                raise OutputWriteError(f"output capture {dst}: write failed: {e.strerror or e}") from None
            target.commit()
        finally:
            if not target.committed:
                target.discard()
    finally:
        reader.close()
    out.print(f"{writer.count} packet(s): {src} ({fin}) -> {dst} ({fout})", highlight=False)
