"""The view of `pdrive run 3,4,5`: a rich Live table with a row per drive on a terminal, text lines
otherwise (a line per drive each second of the run, phases, the end), or a JSON Lines stream (`--json`:
one object per line with an "event" key: start, phase, update (one per drive, with `station`), end).
Rendering only; the run is session/multirun.py."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from rich.live import Live
from rich.markup import escape
from rich.table import Table
from rich.text import Text

from profidrive_cli.api import format_counters
from profidrive_cli.cli.common import emit_json, err, out
from profidrive_cli.cli.render_drive import fmt_num, stop_json

if TYPE_CHECKING:
    from profidrive_cli.api.station import Sample


def sample_dict(address: int, t_s: float, sample: Sample, phase: str) -> dict[str, Any]:
    st = sample.status
    return {"event": "update", "station": address, "phase": phase, "t_s": round(t_s, 3),
            "state": st.state, "running": st.running, "stopped": st.stopped, "fault": st.fault,
            "fault_code": st.fault_code, "flags": [k for k, v in st.flags.items() if v],
            "reference_hz": sample.reference_hz, "actual_hz": sample.actual_hz,
            "reference_percent": sample.reference_percent, "actual_percent": sample.actual_percent,
            "cycles": sample.cycles, "counters": sample.counters}


def start_json(header: dict[str, Any]) -> dict[str, Any]:
    """The start event in the contract's names (docs/json.md): the watchdog as `watchdog_s`."""
    d: dict[str, Any] = {"event": "start"}
    for k, v in header.items():
        if k == "watchdog_ms":
            d["watchdog_s"] = None if v is None else v / 1000.0
        else:
            d[k] = v
    return d


def end_json(end: dict[str, Any]) -> dict[str, Any]:
    """The end event in the contract's names: each station's stop time as `stop.duration_s`."""
    d = {"event": "end", **end}
    if "stations" in end:
        d["stations"] = [{**s, "stop": stop_json(s.get("stop"))} if "stop" in s else s
                         for s in end["stations"]]
    return d


class MultiView:
    """mode 'live', 'text' or 'json'. Updates are emitted at most `rate` times a second of the run's
    clock per drive (phases and each drive's last sample always)."""

    def __init__(self, mode: str, rate: float = 10.0) -> None:
        self.mode = mode
        self.period = 1.0 / rate if mode == "json" else 1.0
        self.header: dict[str, Any] = {}
        self.phase = "connecting"
        self.rows: dict[int, tuple[float, Sample, str]] = {}          # address -> (t_s, sample, phase)
        self.phases: dict[int, str] = {}
        self.hint = ""
        self._last: dict[int, float] = {}
        self._shown_phase: dict[int, str] = {}
        self._pending: set[int] = set()          # a newer sample than the one shown
        self._live: Live | None = None

    # -- callbacks of session.multirun.MultiRun ------------------------------------------------
    def start(self, header: dict[str, Any]) -> None:
        self.header = header
        if self.mode == "json":
            emit_json(start_json(header))
            return
        for w in header.get("warnings") or ():   # (--json carries them in the start event)
            err.print(escape(f"warning: {w}"))
        if self.mode == "text":
            for line in self._header_lines():
                out.print(escape(line))
            return
        self._live = Live(console=out, refresh_per_second=8, transient=False,
                          get_renderable=self._renderable)
        self._live.start()

    def set_phase(self, phase: str, address: int | None = None) -> None:
        for a in sorted(self._pending):          # what happened before the phase, shown before it
            self._emit(a)
        if address is None:
            self.phase = phase
            for a in self.phases:
                self.phases[a] = phase
        else:
            self.phases[address] = phase
        if self.mode == "json":
            emit_json({"event": "phase", "phase": phase,
                       **({"station": address} if address is not None else {})})
        elif self.mode == "text":
            out.print(escape(f"-- {phase}" + (f" (station {address})" if address is not None else "")))

    def update(self, address: int, t_s: float, sample: Sample, phase: str) -> None:
        self.rows[address] = (t_s, sample, phase)
        self.phases[address] = phase
        if phase == self._shown_phase.get(address) and t_s - self._last.get(address, -1e9) < self.period:
            self._pending.add(address)
            return
        self._emit(address)

    def _emit(self, address: int) -> None:
        t_s, sample, phase = self.rows[address]
        self._pending.discard(address)
        self._last[address] = t_s
        self._shown_phase[address] = phase
        if self.mode == "json":
            emit_json(sample_dict(address, t_s, sample, phase))
        elif self.mode == "text":
            out.print(escape(self._line(address, t_s, sample, phase)))

    def finish(self, end: dict[str, Any]) -> None:
        if not self.header:                      # refused before anything started: the error says it
            return
        for a in sorted(self._pending):          # each drive's last sample is always shown
            self._emit(a)
        if self._live is not None:
            self._live.refresh()
            self._live.stop()
            self._live = None
        if self.mode == "json":
            emit_json(end_json(end))
            return
        err.print(escape(f"end: {end.get('reason', '')}"))
        for s in end.get("stations", []):
            stop = s.get("stop") or {}
            words = f"station {s['station']}: "
            words += (f"reached the reference after {s['reached_after_s']:.2f} s"
                      if s.get("reached_after_s") is not None else "did not reach the reference"
                      if s.get("started") else "not started")
            if stop:
                words += f"; stop: {stop.get('how')}" + (f" ({stop.get('message')})"
                                                         if stop.get("message") else "")
            if s.get("problem"):
                words += f"; {s['problem']}"
            err.print(escape(words))

    # -- text ----------------------------------------------------------------------------------
    def _header_lines(self) -> list[str]:
        h = self.header
        lines = [f"{len(h['stations'])} drives on one cycle of {h['cycle_hz_target']:.1f} Hz (bus limit "
                 f"{h['wire_hz']:.1f} rounds/s), watchdog {h['watchdog_ms']:g} ms"
                 + ("; Sync" + (" and Freeze" if h.get("freeze") else "") + " (outputs take effect "
                    "together)" if h.get("sync") else "")]
        for s in h["stations"]:
            lines.append(f"station {s['station']}: {s['profile']} ({s['title']}), layout {s['layout']}; "
                         f"reference {s['reference_hz']:g} Hz; max frequency {s['fmax_hz']:g} Hz "
                         f"{s['fmax_source']}")
        return lines

    @staticmethod
    def _line(address: int, t_s: float, s: Sample, phase: str) -> str:
        st = s.status
        fault = f"  FAULT {st.fault_code or ''}" if st.fault else ""
        return (f"{t_s:7.2f} s  station {address:<3} {phase:<9} {st.state:<28} ref "
                f"{fmt_num(s.reference_hz, 2, 'Hz')}  actual {fmt_num(s.actual_hz, 2, 'Hz')}  "
                f"retries {s.counters.get('retries', 0)} errors "
                f"{s.counters.get('no_answer', 0) + s.counters.get('illegal', 0)}{fault}")

    # -- rich ----------------------------------------------------------------------------------
    def _renderable(self) -> Table:
        h = self.header
        t = Table(title=f"{len(h.get('stations', []))} drives · cycle {h.get('cycle_hz_target', 0):.1f} Hz"
                  + (" · Sync" if h.get("sync") else "") + f" · {self.phase}",
                  caption=self.hint or None)
        for col in ("station", "profile", "phase", "state", "reference", "actual", "bus"):
            t.add_column(col)
        for s in h.get("stations", []):
            a = s["station"]
            row = self.rows.get(a)
            if row is None:
                t.add_row(str(a), s["profile"], self.phases.get(a, self.phase), "-", "-", "-", "-")
                continue
            _, smp, phase = row
            st = smp.status
            state = Text(st.state, style="bold red" if st.fault else ("bold green" if st.running else ""))
            if st.fault and st.fault_code:
                state.append(f" {st.fault_code}", style="red")
            t.add_row(str(a), s["profile"], phase, state, fmt_num(smp.reference_hz, 2, "Hz"),
                      fmt_num(smp.actual_hz, 2, "Hz"), format_counters(smp.counters))
        return t
