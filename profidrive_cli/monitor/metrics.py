"""The Prometheus text exposition of the monitor's live view (`/metrics` of `pdrive monitor --web`):
a CollectorRegistry of its own with one custom collector that turns the live view (monitor/model.py)
into metric families at each scrape. prometheus_client (extra `monitor`) is imported inside render()
only. Nothing is kept between scrapes: the counters are the monitor's since it started (a restart of
the monitor is a counter reset, as Prometheus expects).

The series (their names are the contract; docs/monitor.md):

    pdrive_station_up{station,ident,profile}         1 in data exchange, 0 in any other state
    pdrive_station_state{station,state}              1 for the station's current DP state, 0 for the
                                                     others (model.STATE_COLOURS' words)
    pdrive_station_exchanges_total{station}          Data_Exchange telegrams answered
    pdrive_station_retries_total{station}            retries of a request to it
    pdrive_station_no_answer_total{station}          requests it left unanswered
    pdrive_station_illegal_total{station}            illegal answers (a wrong frame, a bad FCS)
    pdrive_station_reparams_total{station}           new parameterisations (Set_Prm) of it
    pdrive_station_cycle_seconds{station}            its Data_Exchange cycle (when measured)
    pdrive_drive_fault{station,profile}              1 the drive reports a fault, 0 none (when known)
    pdrive_bus_frames_total                          telegrams heard
    pdrive_bus_tokens_total                          token frames heard
    pdrive_bus_errors_total{kind}                    line errors by kind (framing, fcs, ...)
    pdrive_bus_load_percent                          the bus load (when measured)
    pdrive_token_rotation_seconds                    the token's rotation time (when measured)
    pdrive_masters                                   masters heard passing the token
    pdrive_events_total{kind}                        events by kind since the monitor started
    pdrive_events_by_cause_total{cause}              events by their likely cause (when the live
                                                     view carries "events_by_cause")
    pdrive_adapter_up                                1 the port is heard, 0 lost and being reopened
    pdrive_store_bytes                               the history's size on disk (with a history)
    pdrive_store_full                                1 the history's disk is full (with a history)
"""

from __future__ import annotations

from typing import Any, Iterator

from profidrive_cli.monitor.model import SAMPLE_COUNTERS, STATE_COLOURS

#: the Content-Type of the exposition (the text format 0.0.4)
CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"


def _num(v: Any) -> float | None:
    if isinstance(v, bool):
        return float(v)
    if isinstance(v, (int, float)):
        return float(v)
    return None


def _label(v: Any) -> str:
    return "" if v is None else str(v)


def families(live: dict[str, Any]) -> Iterator[Any]:
    """The metric families of one live view (prometheus_client's GaugeMetricFamily and
    CounterMetricFamily)."""
    from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily

    stations = [s for s in live.get("stations") or [] if isinstance(s, dict)]
    up = GaugeMetricFamily("pdrive_station_up", "1 when the station is in data exchange",
                           labels=["station", "ident", "profile"])
    state = GaugeMetricFamily("pdrive_station_state", "1 for the station's current DP state",
                              labels=["station", "state"])
    counters = {name: CounterMetricFamily(f"pdrive_station_{name}", f"the station's {name} "
                                          "since the monitor started", labels=["station"])
                for name in SAMPLE_COUNTERS}
    cycle = GaugeMetricFamily("pdrive_station_cycle_seconds", "the station's Data_Exchange cycle",
                              labels=["station"])
    fault = GaugeMetricFamily("pdrive_drive_fault", "1 when the drive reports a fault",
                              labels=["station", "profile"])
    for s in stations:
        st = str(s.get("station"))
        current = str(s.get("state") or "")
        up.add_metric([st, _label(s.get("ident_hex")), _label(s.get("profile"))],
                      1.0 if current == "data exchange" else 0.0)
        for word in list(STATE_COLOURS) + ([current] if current not in STATE_COLOURS else []):
            state.add_metric([st, word], 1.0 if word == current else 0.0)
        got = s.get("counters") or {}
        for name, fam in counters.items():
            v = _num(got.get(name))
            if v is not None:
                fam.add_metric([st], v)
        c = _num(s.get("cycle_s"))
        if c is not None:
            cycle.add_metric([st], c)
        f = s.get("fault")
        if f is not None:
            fault.add_metric([st, _label(s.get("profile"))], 1.0 if f else 0.0)
    yield up
    yield state
    yield from counters.values()
    yield cycle
    yield fault

    bus = live.get("bus") or {}
    for key, name, text in (("frames", "pdrive_bus_frames", "telegrams heard"),
                            ("tokens", "pdrive_bus_tokens", "token frames heard")):
        v = _num(bus.get(key))
        if v is not None:
            fam = CounterMetricFamily(name, text)
            fam.add_metric([], v)
            yield fam
    errors = CounterMetricFamily("pdrive_bus_errors", "line errors by kind", labels=["kind"])
    for kind, n in sorted((bus.get("errors") or {}).items()):
        v = _num(n)
        if v is not None:
            errors.add_metric([str(kind)], v)
    yield errors
    for key, name, text in (("load_percent", "pdrive_bus_load_percent", "the bus load (percent)"),
                            ("rotation_s", "pdrive_token_rotation_seconds",
                             "the token's rotation time")):
        v = _num(bus.get(key))
        if v is not None:
            yield GaugeMetricFamily(name, text, value=v)
    masters = bus.get("masters")
    if isinstance(masters, (list, tuple)):
        yield GaugeMetricFamily("pdrive_masters", "masters heard passing the token",
                                value=float(len(masters)))

    by_kind = CounterMetricFamily("pdrive_events", "events by kind since the monitor started",
                                  labels=["kind"])
    for kind, n in sorted((live.get("events_by_kind") or {}).items()):
        v = _num(n)
        if v is not None:
            by_kind.add_metric([str(kind)], v)
    yield by_kind
    by_cause = live.get("events_by_cause")
    if isinstance(by_cause, dict):
        fam = CounterMetricFamily("pdrive_events_by_cause", "events by their likely cause",
                                  labels=["cause"])
        for cause, n in sorted(by_cause.items(), key=lambda kv: str(kv[0])):
            v = _num(n)
            if v is not None:
                fam.add_metric([_label(cause)], v)
        yield fam

    adapter = live.get("adapter")
    if adapter is not None:
        yield GaugeMetricFamily("pdrive_adapter_up", "1 when the port is heard",
                                value=1.0 if adapter == "connected" else 0.0)
    store = live.get("store")
    if isinstance(store, dict):
        v = _num(store.get("bytes"))
        if v is not None:
            yield GaugeMetricFamily("pdrive_store_bytes", "the history's size on disk", value=v)
        yield GaugeMetricFamily("pdrive_store_full", "1 when the history's disk is full",
                                value=1.0 if store.get("full") else 0.0)


class _LiveCollector:
    def __init__(self, live: dict[str, Any]) -> None:
        self.live = live

    def collect(self) -> Iterator[Any]:
        return families(self.live)

    def describe(self) -> list[Any]:
        return []                           # (no check at registration: the view is read at scrape)


def render(live: dict[str, Any]) -> bytes:
    """The Prometheus text exposition (CONTENT_TYPE) of one live view."""
    from prometheus_client import CollectorRegistry, generate_latest

    registry = CollectorRegistry(auto_describe=False)
    registry.register(_LiveCollector(live))
    return generate_latest(registry)
