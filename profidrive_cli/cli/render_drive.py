"""Rendering for the drive commands (run / status / param / faults): rich live view, tables, JSON
objects, and the key reader for `run`. No protocol logic here."""

from __future__ import annotations

import os
import select
import sys
import time
from collections import deque
from typing import TYPE_CHECKING, Any, Callable, Iterable

from rich.console import Group
from rich.live import Live
from rich.markup import escape
from rich.panel import Panel
from rich.table import Table
from rich.text import Text

from profidrive_cli.cli import jsonout as J
from profidrive_cli.cli.common import emit_json, err, out
from profidrive_cli.drives.base import value_text as value_text  # noqa: F401  (also used as R.value_text)

if TYPE_CHECKING:
    from rich.console import RenderableType

    from profidrive_cli.drives.base import DriveStatus, FaultRecord, ParamValue
    from profidrive_cli.api.station import Sample
    from profidrive_cli.api.station import DriveStation
    from profidrive_cli.api.station import Monitors, TripRecords
    from profidrive_cli.api.station import ParamRow

SPARK = "▁▂▃▄▅▆▇█"


def sparkline(values: Iterable[float | None], hi: float = 100.0) -> str:
    """Block characters for |value| in 0..hi (a blank for no value)."""
    chars = []
    for v in values:
        if v is None:
            chars.append(" ")
            continue
        x = min(1.0, abs(v) / hi) if hi else 0.0
        chars.append(SPARK[min(len(SPARK) - 1, int(round(x * (len(SPARK) - 1))))])
    return "".join(chars)


def fmt_num(v: float | None, digits: int = 2, unit: str = "") -> str:
    if v is None:
        return "-"
    text = f"{v:.{digits}f}"
    return f"{text} {unit}" if unit else text


def flag_words(flags: dict[str, bool]) -> str:
    on = [k for k, v in flags.items() if v]
    return ", ".join(on) if on else "(none set)"


def counter_words(c: dict[str, Any]) -> str:
    keys = ("retries", "no_answer", "illegal", "reparams", "rs", "rr")
    return ", ".join(f"{k.replace('_', ' ')} {c.get(k, 0)}" for k in keys)


# =============================================================================================
# run: the live view
# =============================================================================================


def torque_fields(st: DriveStatus) -> dict[str, float]:
    """The torque keys of a status where the card has them (torque runs, cards with a torque word)."""
    out: dict[str, float] = {}
    ref = getattr(st, "torque_ref_percent", None)
    if ref is not None:
        out["torque_ref_percent"] = ref
    actual = getattr(st, "torque_percent", None)
    if actual is not None:
        out["torque_percent"] = actual
    return out


def torque_words(st: DriveStatus) -> str:
    d = torque_fields(st)
    if not d:
        return ""
    return (f"  torque ref {fmt_num(d.get('torque_ref_percent'), 1, '%')} "
            f"actual {fmt_num(d.get('torque_percent'), 1, '%')}")


class RunView:
    """mode 'live' (rich Live on a terminal), 'text' (a line a second) or 'json' (one object per
    update, at most `json_hz` per second, plus start/phase/end events)."""

    def __init__(self, mode: str, json_hz: float = 10.0, trend_len: int = 60, trend_hz: float = 5.0) -> None:
        self.mode = mode
        self.json_period = 1.0 / json_hz
        self.trend: deque[float | None] = deque(maxlen=trend_len)
        self.trend_period = 1.0 / trend_hz
        self.header: dict[str, Any] = {}
        self.phase = "starting"
        self.last: Sample | None = None
        self.hint = ""
        self._last_emit = -1e9
        self._last_trend = -1e9
        self._last_text = -1e9
        self._live: Live | None = None
        self.reached_after: float | None = None
        self.peak_hz: float | None = None
        #: session.monitors.Monitors of run --monitor, or None
        self.monitors: Monitors | None = None
        #: a fault code -> its name (session.live.fault_name on the station's profile), or None
        self.fault_name: Callable[[str], str | None] | None = None

    # -- lifecycle ---------------------------------------------------------------------------
    def start(self, header: dict[str, Any]) -> None:
        self.header = header
        if self.mode == "json":
            emit_json({"event": "start", **start_json(header)})
        elif self.mode == "text":
            out.print(escape(self._header_line()))
        else:
            self._live = Live(console=out, refresh_per_second=8, transient=False,
                              get_renderable=self._renderable)
            self._live.start()

    def _header_line(self) -> str:
        h = self.header
        return (f"station {h['address']}: {h['profile']} ({h['title']}), layout {h['layout']}; "
                f"max frequency {h['fmax_hz']:g} Hz {h['fmax_source']}; cycle {h['cycle_hz_target']:.1f} Hz "
                f"(bus limit {h['wire_hz']:.1f} Hz), watchdog {h['watchdog_ms']:g} ms")

    def set_phase(self, phase: str, sample: Sample | None = None) -> None:
        self.phase = phase
        if self.mode == "json":
            d: dict[str, Any] = {"event": "phase", "phase": phase}
            if sample is not None:
                d["t_s"] = round(sample.t, 3)
            emit_json(d)
        elif self.mode == "text":
            out.print(f"-- {phase}")
        if sample is not None:
            self.update(sample, force=True)

    def update(self, sample: Sample, force: bool = False) -> None:
        self.last = sample
        now = time.monotonic()
        if now - self._last_trend >= self.trend_period:
            self._last_trend = now
            self.trend.append(sample.actual_percent)
        if self.mode == "json":
            if force or now - self._last_emit >= self.json_period:
                self._last_emit = now
                d: dict[str, Any] = {"event": "update", "phase": self.phase, **sample_json(sample.to_dict()),
                     **torque_fields(sample.status)}
                if self.monitors is not None:
                    d["monitors"] = monitors_json(self.monitors.to_dict())
                emit_json(d)
        elif self.mode == "text":
            if force or now - self._last_text >= 1.0:
                self._last_text = now
                out.print(escape(self._text_line(sample)))

    def _text_line(self, s: Sample) -> str:
        st = s.status
        fault = f"  FAULT {self._fault_words(st.fault_code)}" if st.fault else ""
        mon = f"  {monitor_words(self.monitors)}" if self.monitors is not None else ""
        return (f"{s.t:7.2f} s  {st.state:<28} ref {fmt_num(s.reference_hz, 2, 'Hz')} "
                f"({fmt_num(s.reference_percent, 1, '%')})  actual {fmt_num(s.actual_hz, 2, 'Hz')} "
                f"({fmt_num(s.actual_percent, 1, '%')})  {s.cycle_hz:5.1f} cycles/s  "
                f"retries {s.counters.get('retries', 0)} errors "
                f"{s.counters.get('no_answer', 0) + s.counters.get('illegal', 0)}{torque_words(st)}{fault}{mon}")

    def _fault_words(self, code: str | None) -> str:
        """'EF0 (External fault ...)' as `pdrive faults` names it; 'code not read' without a code."""
        if not code:
            return "(code not read)"
        name = self.fault_name(code) if self.fault_name is not None else None
        return f"{code} ({name})" if name else str(code)

    def finish(self, end: dict[str, Any]) -> None:
        if self._live is not None:
            self._live.stop()
            self._live = None
        if self.mode == "json":
            emit_json({"event": "end", **end_json(end)})
        else:
            msg = end.get("message") or ""
            stop = end.get("stop") or {}
            words = f"end: {end.get('reason', '')}"
            if stop:
                words += f"; stop: {stop.get('how')}" + (f" ({stop.get('message')})" if stop.get("message") else "")
            if end.get("reached_after_s") is not None:
                words += f"; reached the reference after {end['reached_after_s']:.2f} s"
            if msg:
                words += f"; {msg}"
            err.print(escape(words))

    # -- rich rendering ----------------------------------------------------------------------
    def _renderable(self) -> Panel:
        h = self.header
        s = self.last
        title = f"station {h.get('address')} · {h.get('profile')} · {h.get('layout')}"
        if s is None:
            return Panel(Text("connecting…"), title=title)
        st = s.status
        t = Table.grid(padding=(0, 2))
        t.add_column(style="bold")
        t.add_column()
        state = Text(st.state, style="bold red" if st.fault else ("bold green" if st.running else "bold"))
        if st.fault:
            state.append(f"  fault {self._fault_words(st.fault_code)}", style="red")
        t.add_row("phase", Text(self.phase))
        t.add_row("state", state)
        t.add_row("status bits", Text(flag_words(st.flags)))
        t.add_row("reference", Text(f"{fmt_num(s.reference_hz, 2, 'Hz')}   {fmt_num(s.reference_percent, 2, '%')}"))
        t.add_row("actual", Text(f"{fmt_num(s.actual_hz, 2, 'Hz')}   {fmt_num(s.actual_percent, 2, '%')}"))
        if torque_fields(st):
            t.add_row("torque", Text(f"reference {fmt_num(st.torque_ref_percent, 1, '%')}   "
                                     f"actual {fmt_num(st.torque_percent, 1, '%')}"))
        t.add_row("max frequency", Text(f"{s.fmax_hz:g} Hz {h.get('fmax_source', '')}"))
        t.add_row("cycle", Text(f"{s.cycle_hz:.1f} /s (target {h.get('cycle_hz_target', 0):.1f}, "
                                f"bus limit {h.get('wire_hz', 0):.1f})   {s.cycles} exchanges"))
        t.add_row("bus", Text(counter_words(s.counters)))
        t.add_row("trend", Text(sparkline(self.trend) or " ", style="cyan"))
        if self.monitors is not None:
            t.add_row("monitors", Text(monitor_words(self.monitors) or "-"))
        parts: list[RenderableType] = [t]
        if self.hint:
            parts.append(Text(self.hint, style="dim"))
        return Panel(Group(*parts), title=title)


# =============================================================================================
# run / jog: the JSON stream's objects in the contract's shape (docs/json.md); the text view
# keeps reading the dicts as the commands build them
# =============================================================================================


def start_json(header: dict[str, Any]) -> dict[str, Any]:
    """station, ident + ident_hex, watchdog_s (the header says watchdog_ms)."""
    d = J.station_identity(header)
    if "watchdog_ms" in d:
        d = J.renamed(d, {"watchdog_ms": "watchdog_s"})
        d["watchdog_s"] = None if d["watchdog_s"] is None else d["watchdog_s"] / 1000.0
    return d


def sample_json(d: dict[str, Any]) -> dict[str, Any]:
    """A sample's dict: t -> t_s, flags as the list of names set."""
    d = J.renamed(d, {"t": "t_s"})
    if "flags" in d:
        d["flags"] = J.flag_list(d["flags"])
    return d


def monitors_json(d: dict[str, Any]) -> dict[str, Any]:
    """{code: {value, unit, raw, t, via}} -> the same with t_s."""
    return {c: J.renamed(v, {"t": "t_s"}) for c, v in d.items()}


def stop_json(d: dict[str, Any] | None) -> dict[str, Any] | None:
    """The stop report: seconds -> duration_s."""
    return None if d is None else J.renamed(d, {"seconds": "duration_s"})


def end_json(end: dict[str, Any]) -> dict[str, Any]:
    d = dict(end)
    if "stop" in d:
        d["stop"] = stop_json(d["stop"])
    if isinstance(d.get("monitors"), dict):
        d["monitors"] = monitors_json(d["monitors"])
    return d


def monitor_header(mons: Monitors) -> list[dict[str, str]]:
    """The start event's monitor list: code, name and unit of each."""
    return [{"code": c, "name": mons.values[c].name, "unit": mons.values[c].unit} for c in mons.codes]


def monitor_words(mons: Monitors) -> str:
    """'d002 3.4 A · d013 180.5 V' (— until a value was read)."""
    parts = []
    for c in mons.active:
        v = mons.values[c]
        parts.append(f"{c} " + (value_text(v.value, v.unit) if v.value is not None else "—"))
    return " · ".join(parts)


# =============================================================================================
# keys while running (terminal only)
# =============================================================================================


class KeyReader:
    """Single keys from stdin in cbreak mode (Ctrl-C still sends SIGINT). Yields 'up', 'down', 'r',
    'space', 'q'."""

    def __init__(self) -> None:
        self.fd = sys.stdin.fileno()
        self._old: list[Any] | None = None
        self._buf = b""
        self._since = 0.0

    def __enter__(self) -> KeyReader:
        import termios
        import tty
        self._old = termios.tcgetattr(self.fd)
        tty.setcbreak(self.fd, termios.TCSANOW)   # keep keys typed while starting
        return self

    def __exit__(self, *exc: object) -> None:
        import termios
        if self._old is not None:
            termios.tcsetattr(self.fd, termios.TCSADRAIN, self._old)

    def keys(self) -> list[str]:
        r, _, _ = select.select([self.fd], [], [], 0)
        if r:
            try:
                self._buf += os.read(self.fd, 64)
            except OSError:
                return []
            self._since = time.monotonic()
        out_keys: list[str] = []
        b = self._buf
        while b:
            if b[:1] == b"\x1b":
                if len(b) >= 3 and b[1:2] in (b"[", b"O"):
                    key = {b"A": "up", b"B": "down"}.get(b[2:3])
                    if key:
                        out_keys.append(key)
                    b = b[3:]              # other sequences (arrows left/right, ...) are ignored
                elif len(b) < 3 and b in (b"\x1b", b"\x1b[", b"\x1bO") and \
                        time.monotonic() - self._since < 0.2:
                    break                  # an escape sequence still arriving
                else:
                    b = b[1:]              # a lone Escape
            else:
                c = b[:1]
                b = b[1:]
                key = {b" ": "space", b"q": "q", b"Q": "q", b"r": "r", b"R": "r", b"+": "up",
                       b"-": "down"}.get(c)
                if key:
                    out_keys.append(key)
        self._buf = b
        return out_keys


# =============================================================================================
# status / params / faults
# =============================================================================================


def status_dict(session: DriveStation, sample: Sample) -> dict[str, Any]:
    st = sample.status
    assert session.profile is not None and session.ident is not None    # an open session found them
    fmax, src = session.motion.fmax() if session.drive is not None else (sample.fmax_hz, "")
    return {"address": session.address, "ident": f"0x{session.ident:04X}", "profile": session.profile.name,
            "family": session.profile.family, "title": session.profile.title, "layout": session.layout,
            "state": st.state, "running": st.running, "stopped": st.stopped, "fault": st.fault,
            "fault_code": st.fault_code, "flags": dict(st.flags),
            "speed_hz": sample.actual_hz, "speed_percent": sample.actual_percent,
            "reference_percent": sample.reference_percent, "reference_hz": sample.reference_hz,
            "fmax_hz": fmax, "fmax_source": src,
            "raw": dict(st.raw), "counters": sample.counters, **torque_fields(st)}


def status_json(d: dict[str, Any]) -> dict[str, Any]:
    """status_dict in the contract's shape: station, ident + ident_hex, flags as the list of names
    set, actual_hz / actual_percent."""
    d = J.renamed(J.station_identity(d), {"speed_hz": "actual_hz", "speed_percent": "actual_percent"})
    d["flags"] = J.flag_list(d["flags"])
    return d


def print_status(d: dict[str, Any]) -> None:
    out.print(f"[bold]station {d['address']}[/bold]: {escape(d['profile'])} ({escape(d['title'])}), "
              f"layout {escape(d['layout'])}")
    state = d["state"] + ("  (stopped)" if d["stopped"] else ("  (running)" if d["running"] else ""))
    out.print(f"  state:  {escape(state)}")
    out.print(f"  speed:  {fmt_num(d['speed_hz'], 2, 'Hz')} ({fmt_num(d['speed_percent'], 2, '%')} of "
              f"{d['fmax_hz']:g} Hz, {escape(d['fmax_source'])})")
    if d.get("reference_percent") is not None:
        out.print(f"  reference: {fmt_num(d['reference_percent'], 2, '%')}")
    if d.get("torque_percent") is not None:
        out.print(f"  torque: {fmt_num(d['torque_percent'], 1, '%')} of rated")
    out.print(f"  fault:  {escape(d['fault_code'] or ('yes (code not readable)' if d['fault'] else 'none'))}")
    on = [k for k, v in d["flags"].items() if v]
    off = [k for k, v in d["flags"].items() if not v]
    out.print(f"  status bits set:     {escape(', '.join(on) or '(none)')}")
    out.print(f"  status bits not set: {escape(', '.join(off) or '(none)')}")
    raw = ", ".join(f"{k} 0x{v & 0xFFFF:04X}" for k, v in d["raw"].items() if isinstance(v, int))
    out.print(f"  words:  {escape(raw)}")


def param_table(values: Iterable[ParamValue]) -> Table:
    t = Table(show_header=True)
    for c in ("code", "name", "value", "raw"):
        t.add_column(c)
    for pv in values:
        t.add_row(escape(pv.code), escape(pv.name or ""), escape(pv.text or value_text(pv.value, pv.unit)),
                  f"{pv.raw} (0x{pv.raw:X})" if isinstance(pv.raw, int) and pv.raw >= 0 else str(pv.raw))
    return t


def param_json(pv: ParamValue) -> dict[str, Any]:
    d: dict[str, Any] = {"code": pv.code, "name": pv.name, "value": pv.value, "unit": pv.unit, "raw": pv.raw}
    if getattr(pv, "text", None):
        d["text"] = pv.text          # the value as the card's tables show it (`format:`)
    return d


def rows_table(rows: Iterable[ParamRow], title: str,
               columns: tuple[str, ...] = ("code", "name", "file", "drive", "result", "reason"),
               sources: dict[str, str] | None = None) -> Table:
    """sources: code -> where its factory value comes from (the `source` column of diff --defaults)."""
    t = Table(title=title, show_header=True)
    for c in columns:
        t.add_column(c)
    for r in rows:
        vals = {"code": r.code, "name": r.name, "file": value_text(r.file_value, r.unit),
                "drive": value_text(r.drive_value, r.unit), "result": r.result, "reason": r.reason,
                "now": value_text(r.new_value, r.unit), "factory": value_text(r.file_value, r.unit),
                "source": (sources or {}).get(r.code, "")}
        style = {"applied": "green", "refused": "red", "would apply": "yellow", "differs": "yellow"}.get(r.result)
        t.add_row(*(escape(str(vals[c])) for c in columns), style=style)
    return t


def faults_table(records: Iterable[FaultRecord], title: str) -> Table:
    t = Table(title=title, show_header=True)
    for c in ("position", "number", "alarm", "meaning"):
        t.add_column(c)
    for r in records:
        t.add_row(escape(str(r.position)), f"{r.raw} (0x{r.raw:04X})" if r.raw else "0",
                  escape(" / ".join(r.codes) or "-"), escape("\n".join(r.meanings)))
    return t


def fault_json(r: FaultRecord) -> dict[str, Any]:
    return {"position": r.position, "number": r.raw, "codes": list(r.codes), "meanings": list(r.meanings)}


def print_trip_records(trips: TripRecords) -> None:
    """faults: the card's trip records as a table (one row per record, one column per field), or the
    one line saying the card keeps none / none is stored."""
    if not trips.supported or trips.note:
        out.print(f"trip records: {escape(trips.note)}")
        return
    latest = f" (newest: record {trips.latest})" if trips.latest is not None else ""
    if not trips.records:
        # no record: the pointer names none (Moeller PNU 354 reads 00 before the first trip too)
        out.print("trip records: none stored")
        return
    t = Table(title=f"trip records{latest}", show_header=True)
    t.add_column("record")
    names = [f["code"] for f in trips.records[0].fields]
    for f in trips.records[0].fields:
        t.add_column(escape(_field_label(f)))
    for r in trips.records:
        cells = [escape(value_text(f["value"], f["unit"])) for f in r.fields]
        t.add_row(escape(r.position), *(cells + [""] * (len(names) - len(cells))))
    out.print(t)


def _field_label(f: dict[str, Any]) -> str:
    """'Trip record 1 (d081): frequency' -> 'frequency'; the code where the name says nothing."""
    name: str = f.get("name") or f["code"]
    return name.split("): ", 1)[1] if "): " in name else name
