"""`pdrive doctor`: the adapter's own timing, measured on the open port (issue 26, "Adapters").

    turnaround      from the last octet of a request to the line being free for the answer, as the
                    host sees it. With local echo: when the echo of the last octet has arrived
                    (at most echo time - write start - the request's wire time). Without echo the
                    line's release is invisible; a known station's answer bounds it: round trip
                    minus both telegrams' wire time minus the slave's min TSDR (11 bit), and the
                    answer coming whole proves the adapter let go of the line within min TSDR.
    request gap     the time between consecutive requests the link can send: FDL status requests to
                    the probe address (nobody answered it in the echo check) back to back, each
                    one written and drained (echo read back, or tcdrain) before the next.

Both are compared with what the baud rate needs, in bit times (reference §4.1/4.2: min TSDR 11,
max TSDR, TSL, TSYN 33 bit before every request). A verdict (ok) only where the figures prove it;
otherwise the figures as info. Every row is (name, status, detail, data); dp/doctor.py adds them
to its report. Sends nothing on a busy line. The clock is a parameter (tests pass a fake one).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from profidrive_cli.fdl import frames as F
from profidrive_cli.fdl.timing import BAUD_NAMES, BusParams
from profidrive_cli.link.serial_link import ECHO_WAIT_S, read_available

#: (check name, status, detail, data) as dp/doctor.py's Report.add takes them
Row = tuple[str, str, str, dict[str, Any]]

OK, INFO, SKIP = "ok", "info", "skip"

#: samples of each measurement (few: each is one FDL status request on the wire)
TURNAROUNDS = 5
GAP_REQUESTS = 8

Clock = Callable[[], float]


def timing_rows(ser: Any, baud: int, master: int, probe: int, *, echo: bool, busy: bool,
                probe_silent: bool, round_trip: dict[str, Any] | None,
                clock: Clock = time.monotonic) -> list[Row]:
    """The `turnaround` and `request gap` rows for an open port (pyserial-like `ser`).
    echo: the adapter hears itself (doctor's echo check); probe_silent: nobody answered the echo
    check's FDL status request to `probe`; round_trip: the data of doctor's round-trip row (the
    station asked and its round trips in ms), None when no station answered."""
    if busy:
        return [("turnaround", SKIP, "not measured on a busy line", {}),
                ("request gap", SKIP, "not measured on a busy line", {})]
    p = BusParams.for_baud(baud)
    req = F.encode(F.Frame(F.SD1, probe, master, F.request_fc(F.FDL_STATUS)))
    try:
        turn = _turnaround(ser, req, p, echo, round_trip, clock)
    except Exception as e:                       # noqa: BLE001  (the port's own error, as a row)
        turn = ("turnaround", "fail", f"measuring failed: {e}", {})
    try:
        gap = _gap(ser, req, p, echo, probe, probe_silent, clock)
    except Exception as e:                       # noqa: BLE001
        gap = ("request gap", "fail", f"measuring failed: {e}", {})
    return [turn, gap]


def _bits(seconds: float, baud: int) -> int:
    return round(seconds * baud)


def _needs(p: BusParams) -> dict[str, Any]:
    """What the baud rate asks, in bit times (reference §4.1)."""
    return {"min_tsdr_bits": p.min_tsdr, "max_tsdr_bits": p.max_tsdr, "tsl_bits": p.tsl,
            "tid1_bits": p.tid1}


def _read_n(ser: Any, n: int, until: float, clock: Clock) -> tuple[bytes, float]:
    """Read until `n` octets came or the clock passes `until`: (octets, clock when the last came)."""
    got = b""
    at = clock()
    while len(got) < n:
        left = until - clock()
        if left <= 0:
            break
        chunk = read_available(ser, left)
        if chunk:
            got += chunk
            at = clock()
    return got, at


def _settle(ser: Any, p: BusParams, clock: Clock) -> None:
    """Let an answer to the last request pass (the slot time and a reply), then drop the input."""
    end = clock() + p.slot_seconds + p.chars(6) + p.tid1_seconds
    while clock() < end:
        read_available(ser, end - clock())
    ser.reset_input_buffer()


def _turnaround(ser: Any, req: bytes, p: BusParams, echo: bool, round_trip: dict[str, Any] | None,
                clock: Clock) -> Row:
    baud = p.baud
    wire = p.chars(len(req))
    rate = BAUD_NAMES.get(baud, str(baud))
    if echo:
        echoes: list[float] = []          # write start -> the echo's last octet read
        for _ in range(TURNAROUNDS):
            ser.reset_input_buffer()
            t0 = clock()
            ser.write(req)
            got, at = _read_n(ser, len(req), t0 + wire + ECHO_WAIT_S, clock)
            if got[:len(req)] == req:
                echoes.append(at - t0)
            _settle(ser, p, clock)
        if not echoes:
            return ("turnaround", INFO, "the echo did not come back this time: nothing measured",
                    {"method": "echo", **_needs(p)})
        if min(echoes) < wire:
            return ("turnaround", INFO, f"the echo came back in {min(echoes) * 1000:.2f} ms, sooner "
                    f"than the request's own wire time ({wire * 1000:.2f} ms at {rate}): no real line "
                    "behind this port (a pty, or a converter that echoes from a buffer), nothing to "
                    "measure", {"method": "echo", **_needs(p)})
        times = [t - wire for t in echoes]
        worst = max(times)
        bits = _bits(worst, baud)
        data = {"method": "echo", "turnaround_ms": [round(t * 1000, 3) for t in times],
                "turnaround_bits": bits, **_needs(p)}
        text = (f"the echo of the last octet is read at most {worst * 1000:.2f} ms ({bits} bit at "
                f"{rate}) after the request could have ended (write start + its wire time "
                f"{wire * 1000:.2f} ms); the line's own figures: min TSDR {p.min_tsdr} bit, max TSDR "
                f"{p.max_tsdr} bit, slot time TSL {p.tsl} bit")
        if bits <= p.tsl:
            return ("turnaround", OK, text + ": within the slot time", data)
        return ("turnaround", INFO, text + f": {bits - p.tsl} bit beyond the slot time, every "
                "request-reply takes that much longer than on the wire (the reply timeout counts "
                "from the echo, so no reply is lost to it)", data)
    if round_trip and round_trip.get("round_trips_ms"):
        station = round_trip.get("station")
        fastest = min(round_trip["round_trips_ms"]) / 1000.0
        on_wire = wire + p.min_tsdr / baud + p.chars(6)
        if fastest < on_wire:
            return ("turnaround", INFO, f"station {station} answered in {fastest * 1000:.2f} ms, "
                    f"sooner than request, min TSDR and answer take on the wire "
                    f"({on_wire * 1000:.2f} ms at {rate}): no real line behind this port, nothing "
                    "to measure", {"method": "round trip", "station": station, **_needs(p)})
        bound = fastest - on_wire
        bits = _bits(bound, baud)
        data = {"method": "round trip", "station": station, "turnaround_ms": [round(bound * 1000, 3)],
                "turnaround_bits": bits, **_needs(p)}
        return ("turnaround", OK, f"no echo to time it; station {station}'s answers came whole, so "
                f"the adapter let go of the line within the slave's min TSDR ({p.min_tsdr} bit); the "
                f"port adds at most {bound * 1000:.2f} ms ({bits} bit at {rate}) per exchange "
                f"(fastest round trip {fastest * 1000:.2f} ms minus both telegrams' wire time and "
                f"min TSDR)", data)
    return ("turnaround", INFO, "not measurable here: no echo to time and no station answered "
            "(give --station N of a station on the bus)", {"method": None, **_needs(p)})


def _gap(ser: Any, req: bytes, p: BusParams, echo: bool, probe: int, probe_silent: bool,
         clock: Clock) -> Row:
    baud = p.baud
    wire = p.chars(len(req))
    line = wire + p.tsyn                   # the line's own: the request and TSYN before the next
    needs = {"wire_bits": _bits(wire, baud), "tsyn_bits": _bits(p.tsyn, baud)}
    if not probe_silent:
        return ("request gap", SKIP, f"not measured: address {probe} answered the echo check (the "
                "requests go back to back, with no room for answers; give --probe-address of a "
                "free address)", needs)
    ser.reset_input_buffer()
    starts: list[float] = []
    for _ in range(GAP_REQUESTS):
        starts.append(clock())
        ser.write(req)
        if echo:
            _read_n(ser, len(req), clock() + wire + ECHO_WAIT_S, clock)
        else:
            ser.flush()                    # tcdrain: until the driver has sent it
    starts.append(clock())
    _settle(ser, p, clock)
    gaps = [b - a for a, b in zip(starts, starts[1:])]
    typical = sorted(gaps)[len(gaps) // 2]
    data = {"gap_ms": [round(g * 1000, 3) for g in gaps], "gap_bits": _bits(typical, baud),
            "requests_per_s": round(1.0 / typical, 1) if typical > 0 else None, **needs}
    rate = BAUD_NAMES.get(baud, str(baud))
    text = (f"{len(gaps)} FDL status requests back to back: one every {typical * 1000:.2f} ms "
            f"(median, {_bits(typical, baud)} bit at {rate}); the line needs {line * 1000:.2f} ms "
            f"(the request's {_bits(wire, baud)} bit + TSYN {_bits(p.tsyn, baud)} bit)")
    if typical < wire:
        return ("request gap", INFO, text + ": faster than the wire, so the port buffers (a pty or a "
                "converter): no figure for a real line", data)
    if typical <= 2 * line:
        return ("request gap", OK, text + ": the port keeps pace with the line", data)
    return ("request gap", INFO, text + f": the port, not the line, limits the request rate "
            f"(at most {1.0 / typical:.0f} requests/s, the line {1.0 / line:.0f}/s)", data)
