"""sniff's DP-V1 acyclic telegrams in words: the MSAC_C1 PDU with the data record it carries, and
each telegram set in its call's sequence.

A class-1 Read or Write (dp/acyclic.py) is a request to SAP 51, the slave's short acknowledgement,
polls (the same SAPs, no data) answered SC until the answer is ready, then the answer. dp/du_decode.py
reads the PDU (decode_acyclic); here, above dp/, the data record it carries is read in the drives'
words (drives/records.py: index 47, the PROFIdrive parameter channel -- a Write of index 47 carries a
parameter request, a Read response of index 47 its parameter response). And the telegrams are tied
together: a poll, a negative answer and a reply without data name the request they belong
to, the short acknowledgement after a request or a poll says what it means (short_ack), a response
names the parameters of the DS47 request it answers (the same reference).

Sans-IO: fdl frames in, the `decoded` object of docs/json.md out. Its state is bounded: the open
request and the last DS47 request per (master, slave), at most MAX_PAIRS pairs (then started afresh).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from profidrive_cli.dp import msac1 as M
from profidrive_cli.dp.du_decode import decode_acyclic
from profidrive_cli.drives.records import Record, request_record, response_record
from profidrive_cli.fdl import frames as F

#: the (master, slave) pairs whose requests are kept; a capture with more starts afresh
MAX_PAIRS = 512


@dataclass(frozen=True)
class _Open:
    """A request sent and not yet answered: what it asked (for the poll, SC and error lines)."""
    service: str
    sap: int
    what: str


def _what(pdu: M.Msac1Pdu) -> str:
    """A request in short: 'Read slot 0 index 47 length 240' (a Write without its data)."""
    if pdu.alarm is not None:
        return f"Alarm_Ack slot {pdu.slot}"
    return f"{pdu.name} slot {pdu.slot} index {pdu.index} length {pdu.length}"


class AcyclicView:
    """The DP-V1 acyclic telegrams of a capture in order: frame() for each telegram to or from an
    acyclic SAP, short_ack() for the short acknowledgement that follows a request or a poll."""

    def __init__(self) -> None:
        self._open: dict[tuple[int, int], _Open] = {}
        #: the last record request written per pair (a DS47 parameter request), its response's names
        self._records: dict[tuple[int, int], Record] = {}
        #: the request or poll just seen (the next telegram may be its SC): pair, open request, kind
        self._last: tuple[tuple[int, int], _Open, str] | None = None

    def frame(self, f: F.Frame, sap: int) -> dict[str, Any]:
        """A telegram to (request, poll) or from (response, reply without data) the slave's
        acyclic SAP `sap` in words: `msac` and `text`, `ds47` for a parameter request or response."""
        is_request = f.is_request
        dec, pdu = decode_acyclic(sap, is_request, f.data)
        m = dec["msac"]
        pair = (f.sa, f.da) if is_request else (f.da, f.sa)
        if len(self._open) >= MAX_PAIRS or len(self._records) >= MAX_PAIRS:
            self._open.clear()
            self._records.clear()
        self._last = None
        opened = self._open.get(pair)
        if is_request:
            if pdu is not None:
                opened = self._open[pair] = _Open(m["service"], sap, _what(pdu))
            elif f.data:
                opened = None           # named by its function only, or malformed: no request named
            self._last = (pair, opened or _Open(m["service"], sap, ""), m["kind"])
            if not f.data:
                m["station"] = f.da
                tail = f" to {opened.what}" if opened is not None else ""
                dec["text"] = [f"{m['service']} poll: the master asks station {f.da} for the "
                               f"answer{tail}"]
                if opened is not None:
                    m["request"] = opened.what
        elif opened is not None and (pdu is None or pdu.is_error or not f.data):
            m["request"] = opened.what
            dec["text"] = [dec["text"][0] + f" (to {opened.what})"]
        if not is_request and f.data:
            self._open.pop(pair, None)              # answered (or a reply the call does not go on with)
        if pdu is not None and pdu.error is None and pdu.alarm is None:
            rec = None
            if is_request and pdu.function == M.WRITE:
                rec = request_record(pdu.index, pdu.data)
                if rec is not None:
                    self._records[pair] = rec
            elif not is_request and pdu.function == M.READ:
                rec = response_record(pdu.index, pdu.data, self._records.get(pair))
            if rec is not None:
                dec["ds47"] = rec.obj
                dec["text"].append(rec.text)
        return dec

    def short_ack(self) -> dict[str, Any] | None:
        """The `decoded` object of a short acknowledgement right after a request or a poll to an
        acyclic SAP (the slave took the request / has no answer yet); None after anything else.
        Call it for the telegram that follows each request or poll (frame() arms it)."""
        last, self._last = self._last, None
        if last is None:
            return None
        (_, slave), opened, kind = last
        m: dict[str, Any] = {"service": opened.service, "sap": opened.sap, "kind": "ack",
                             "station": slave}
        what = ""
        if opened.what:
            m["request"] = opened.what
            what = f" ({opened.what})"
        text = (f"{opened.service}: station {slave} took the request{what}; the master polls for "
                "the answer" if kind == "request" else
                f"{opened.service}: station {slave} has no answer yet{what}; the master polls again")
        return {"msac": m, "text": [text]}

    def next_frame(self) -> None:
        """Another telegram than an SC came after a request or poll: its SC is not to come."""
        self._last = None


__all__ = ["AcyclicView", "MAX_PAIRS"]
