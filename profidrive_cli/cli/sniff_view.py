"""What `pdrive sniff` prints for each captured frame: one line (or one JSON object) per frame,
with --station the watched drives' outputs and inputs in words; with --live the passive live list
instead (rich Live on a terminal, a plain table at the end otherwise, JSON Lines with --json).

Rendering only: the decoding is bustools/passive.py, the live list bustools/passive_live.py.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

from profidrive_cli.bustools.passive import frame_suffix
from profidrive_cli.cli.common import emit_json, out
from profidrive_cli.dp.capture import acyclic_sap, format_line, frame_json_head, frame_service
from profidrive_cli.dp.du_decode import DECODED_SERVICES, decode_du
from profidrive_cli.fdl.frames import SC

if TYPE_CHECKING:                                   # pragma: no cover
    from collections.abc import Callable

    from rich.live import Live
    from rich.table import Table

    from profidrive_cli.bustools.dpv1view import AcyclicView
    from profidrive_cli.bustools.passive import PassiveDecoder
    from profidrive_cli.bustools.passive_live import LiveList
    from profidrive_cli.bustools.slaveview import DxView, SlaveView
    from profidrive_cli.dp.capture import Captured
    from profidrive_cli.fdl.frames import Frame

#: a frame's `decoded` object: a dict, or a Data_Exchange by module (DxView)
Decoded = tuple["dict[str, Any] | None", "DxView | None"]

REFRESH_S = 0.5
#: the decoded data unit's lines sit under the frame line, past its time column
DECODED_INDENT = " " * 16


class SniffView:
    def __init__(self, station_specs: Iterable[str] = (), live: bool = False, as_json: bool = False,
                 refresh_s: float = REFRESH_S, gsd_dir: str | None = None,
                 baud: int | None = None) -> None:
        self.decoder: PassiveDecoder | None = None
        if station_specs:
            from profidrive_cli.bustools.passive import PassiveDecoder, watch_list
            self.decoder = PassiveDecoder(watch_list(station_specs))
        self.live: LiveList | None = None
        if live:
            from profidrive_cli.bustools.causes import causes_json
            from profidrive_cli.bustools.passive_live import LiveList
            self.live = LiveList(baud=baud, explain=causes_json)
        self.as_json = as_json
        self.refresh_s = refresh_s
        self._shown_at: float | None = None
        self._rich_live: Live | None = None
        self.slaves: SlaveView | None = None                  # every slave by module (issue 27)
        if not live:
            from profidrive_cli.bustools.slaveview import SlaveView
            self.slaves = SlaveView(gsd_dir, set(self.decoder.watched) if self.decoder else ())
        #: frame lines not yet written (flush())
        self._lines: list[str] = []
        #: DP-V1 acyclic telegrams in words (made at the first one: they are rare)
        self.acyclic: AcyclicView | None = None
        #: a frame's `decoded` object: _decoded_plain, or for the one telegram after a DP-V1
        #: request or poll _decoded_after_request (no test per frame on the Data_Exchange path)
        self._decoded: Callable[[Captured, Frame], Decoded] = self._decoded_plain

    # -- frames ----------------------------------------------------------------------------------
    def frames(self, items: Iterable[Captured]) -> None:
        """frame() of each item in turn; in text mode with --station a watched station's
        Data_Exchange line made here (the most telegrams of a line), without a call per frame."""
        if self.live is not None or self.as_json or self.decoder is None:
            for c in items:
                self.frame(c)
            return
        suffix = self.decoder.suffix
        write = self._lines.append
        plain = self._plain_line
        for c in items:
            s = suffix(c)
            if s is None:
                plain(c)
            else:
                # a watched station's Data_Exchange: nothing by module under it (SlaveView skips
                # the watched stations)
                write(format_line(c) + s + "\n")

    def frame(self, c: Captured) -> None:
        if self.live is None and not self.as_json:
            return self._line(c)
        d = self.decoder.decode(c) if self.decoder is not None else None
        if self.live is not None:
            self.live.feed(c)
            if d is not None and "error" not in d:
                st = self.live.station(d["station"])
                st.drive["profile"] = d["profile"]
                st.drive[d["direction"]] = {k: v for k, v in d.items()
                                            if k not in ("station", "profile", "direction")}
            return
        f = c.frame
        write = self._lines.append
        if f is None:                                   # a framing error: its line / bad_frame
            write(json.dumps(frame_json(c.describe())) + "\n" if self.as_json
                  else format_line(c) + "\n")
            return
        dec, view = self._decoded(c, f)
        if self.as_json:
            # json.dumps of {frame_json(c.describe()), decoded, drive}: the frame's text from its
            # head's pieces (dp/capture.py), a Data_Exchange's `decoded` from its station's
            written = frame_json_head(c)
            if view is not None:
                written += ', "decoded": ' + view.json_text()
            elif dec is not None:
                written += ', "decoded": ' + json.dumps(dec)
            if d is not None:
                written += ', "drive": ' + json.dumps(drive_json(d))
            write(written + "}\n")                     # emit_json's text, written by flush()
        else:
            # a plain write, not rich's print (8x dearer per line): the same text, no markup
            line = format_line(c)
            if d is not None:
                line += frame_suffix(d)
            write(line + "\n")
            self._decoded_lines(dec, view)

    def _decoded_plain(self, c: Captured, f: Frame) -> Decoded:
        """The frame's `decoded` object: a Data_Exchange's by module (a DxView, made into text or
        JSON as needed), any other frame's as a dict (du_decode, with the GSD's view; a DP-V1
        acyclic telegram's from bustools/dpv1view.py)."""
        if f.dsap is None and f.ssap is None and self.slaves is not None:
            return None, self.slaves.dx_view(f)      # (du_decode has nothing for these)
        sap = acyclic_sap(f)
        if sap is not None:
            return self._acyclic_frame(f, sap), None
        service, has_du = frame_service(c)
        dec = decode_du(service, f.data) if has_du and service in DECODED_SERVICES else None
        if self.slaves is not None:
            dec = self.slaves.decode(f, dec)
        return dec, None

    def _acyclic_frame(self, f: Frame, sap: int) -> dict[str, Any]:
        """A DP-V1 acyclic telegram's `decoded`; after a request or a poll the next telegram's
        decoding looks for the slave's short acknowledgement."""
        if self.acyclic is None:
            from profidrive_cli.bustools.dpv1view import AcyclicView
            self.acyclic = AcyclicView()
        dec = self.acyclic.frame(f, sap)
        if f.is_request:
            self._decoded = self._decoded_after_request
        return dec

    def _decoded_after_request(self, c: Captured, f: Frame) -> Decoded:
        """_decoded of the telegram after a DP-V1 request or poll (then _decoded_plain again): an
        SC is the slave's acknowledgement, named by the request it answers. (With --station in
        text mode a watched station's Data_Exchange goes by without this call: only an unanswered
        request followed by such a telegram and then an SC would name that SC wrongly.)"""
        self._decoded = self._decoded_plain
        assert self.acyclic is not None
        if f.sd == SC:
            return self.acyclic.short_ack(), None
        self.acyclic.next_frame()
        return self._decoded_plain(c, f)

    def _decoded_lines(self, dec: dict[str, Any] | None, view: DxView | None) -> None:
        if view is not None:
            self._lines.append(DECODED_INDENT + view.text() + "\n")
        elif dec is not None:
            for text in dec.get("text", []):
                self._lines.append(DECODED_INDENT + text + "\n")

    def _line(self, c: Captured) -> None:
        """frame() in text mode: the frame's line with the drive's words (PassiveDecoder.suffix:
        the line without the drive object), the decoded lines under it."""
        if self.decoder is not None:
            suffix = self.decoder.suffix(c)
            if suffix is not None:
                self._lines.append(format_line(c) + suffix + "\n")      # (as in frames())
                return
        self._plain_line(c)

    def _plain_line(self, c: Captured) -> None:
        """The line of a frame that carries no drive's words, the decoded lines under it."""
        f = c.frame
        if f is None:
            self._lines.append(format_line(c) + "\n")
            return
        dec, view = self._decoded(c, f)
        self._lines.append(format_line(c) + "\n")
        self._decoded_lines(dec, view)

    def flush(self) -> None:
        """The frames shown so far out to the reader: once per chunk of the capture, not per line."""
        if self._lines:
            sys.stdout.write("".join(self._lines))
            self._lines.clear()
            sys.stdout.flush()

    # -- the live list ---------------------------------------------------------------------------
    def tick(self, t: float) -> None:
        """Refresh the live list every refresh_s seconds (t: seconds since the capture started)."""
        if self.live is None:
            return
        if self._shown_at is not None and t - self._shown_at < self.refresh_s:
            return
        self._shown_at = t
        if self.as_json:
            emit_json(live_json(self.live.snapshot(t), final=False))
        elif out.is_terminal:
            from rich.live import Live
            table = live_table(self.live.snapshot(t))
            if self._rich_live is None:
                self._rich_live = Live(table, console=out, auto_refresh=False, transient=False)
                self._rich_live.start()
            self._rich_live.update(table, refresh=True)

    def finish(self, t: float) -> None:
        """The end of the capture: the frames not yet written, or the live list's last state."""
        self.flush()
        if self.live is None:
            return
        snap = self.live.snapshot(t)
        if self.as_json:
            emit_json(live_json(snap, final=True))
        elif self._rich_live is not None:
            self._rich_live.update(live_table(snap), refresh=True)
            self._rich_live.stop()
        elif out.is_terminal:
            out.print(live_table(snap))
        else:
            for line in plain_table(snap):
                out.print(line, markup=False)


def frame_json(d: dict[str, Any]) -> dict[str, Any]:
    """A frame in the contract's shape (docs/json.md): "event" frame (or bad_frame), t_s."""
    out = {"event": "bad_frame" if "error" in d else "frame"}
    out.update(("t_s" if k == "t" else k, v) for k, v in d.items())
    return out


def drive_json(d: dict[str, Any]) -> dict[str, Any]:
    """A decoded area in the contract's names (docs/json.md): the control / status bits set as
    `flags`."""
    return {("flags" if k in ("control", "status") else k): v for k, v in d.items()}


def _cycle_json(c: dict[str, Any] | None, counted: bool = False) -> dict[str, Any]:
    """{min, mean, max[, n]} in seconds -> cycle_min_s, cycle_mean_s, cycle_max_s[, cycles_measured]."""
    c = c or {}
    d = {"cycle_min_s": c.get("min"), "cycle_mean_s": c.get("mean"), "cycle_max_s": c.get("max")}
    if counted:
        d["cycles_measured"] = c.get("n", 0)
    return d


def live_json(snap: dict[str, Any], final: bool) -> dict[str, Any]:
    """A live-list snapshot as a `live` event: the cycle times as `*_s` keys (as in
    `scan --watch`), the decoded drive areas as in the frame events."""
    out = {"event": "live", "final": final}
    for k, v in snap.items():
        if k == "cycle_s":
            out.update(_cycle_json(v))
        elif k == "stations":
            out[k] = [_station_json(st) for st in v]
        else:
            out[k] = v
    return out


def _station_json(st: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in st.items():
        if k == "cycle_s":
            out.update(_cycle_json(v, counted=True))
        elif k == "drive":
            out[k] = {dk: (drive_json(dv) if isinstance(dv, dict) else dv) for dk, dv in v.items()}
        else:
            out[k] = v
    return out


def _ms(c: dict[str, Any] | None, key: str) -> str:
    return "-" if not c else f"{c[key] * 1000:.1f}"


def _drive_text(drive: dict[str, Any]) -> str:
    req, rep = drive.get("request", {}), drive.get("response", {})
    parts = []
    if req:
        parts.append(" ".join(x for x in (str(req.get("command", "")),
                     "" if req.get("reference_hz") is None else f"{req['reference_hz']:.2f} Hz") if x))
    if rep:
        parts.append(" ".join(x for x in (str(rep.get("state", "")),
                     "" if rep.get("actual_hz") is None else f"{rep['actual_hz']:.2f} Hz") if x))
    return " / ".join(parts)


COLUMNS = ("station", "ident", "state", "exchanges", "cycle ms min/mean/max", "retries",
           "no answer", "illegal", "reparams", "drive (command / state)")


def _rows(snap: dict[str, Any]) -> list[tuple[str, ...]]:
    rows: list[tuple[str, ...]] = []
    for s in snap["stations"]:
        c = s["cycle_s"]
        k = s["counters"]
        rows.append((str(s["station"]), s["ident_hex"] or "-", s["state"], str(s["exchanges"]),
                     f"{_ms(c, 'min')}/{_ms(c, 'mean')}/{_ms(c, 'max')}", str(k["retries"]),
                     str(k["no_answer"]), str(k["illegal"]), str(k["reparams"]),
                     _drive_text(s.get("drive", {})) or "-"))
    return rows


def _caption(snap: dict[str, Any]) -> str:
    c = snap["cycle_s"]
    errs = ", ".join(f"{k} {v}" for k, v in snap["errors"].items()) or "none"
    masters = ", ".join(map(str, snap["masters"])) or "none seen"
    load = snap.get("bus_load_percent")
    rot = snap.get("token_rotation_s")
    causes = "".join(f"\nlikely: {x['title']} ({'; '.join(x['evidence'])})"
                     for x in snap.get("causes", []))
    return (f"{snap['frames']} frames in {snap['t_s']:.1f} s; master(s) {masters}; master cycle "
            f"min/mean/max {_ms(c, 'min')}/{_ms(c, 'mean')}/{_ms(c, 'max')} ms; token rotation "
            f"{_ms(rot, 'min')}/{_ms(rot, 'mean')}/{_ms(rot, 'max')} ms; bus load "
            f"{'unknown (no baud rate: --baud)' if load is None else f'{load:.1f} %'}; "
            f"framing errors: {errs}{causes}")


def live_table(snap: dict[str, Any]) -> Table:
    from rich.table import Table
    t = Table(title="passive live list (listening only)", caption=_caption(snap))
    for col in COLUMNS:
        t.add_column(col, justify="right" if col in ("station", "exchanges", "retries", "no answer",
                                                     "illegal", "reparams") else "left")
    for r in _rows(snap):
        t.add_row(*r)
    return t


def plain_table(snap: dict[str, Any]) -> list[str]:
    rows = [COLUMNS] + _rows(snap)
    widths = [max(len(r[i]) for r in rows) for i in range(len(COLUMNS))]
    lines = ["  ".join(v.ljust(w) for v, w in zip(r, widths)).rstrip() for r in rows]
    return lines + [_caption(snap)]
