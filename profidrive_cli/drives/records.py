"""DP-V1 data records in the drives' words, for the passive tools (sniff reads them here: bustools
may not import a family package): record 47, the PROFIdrive parameter channel ("base mode parameter
access", drives/profidrive/ds47.py) -- a parameter request in a Write of index 47, its parameter
response in the answer to a Read of index 47. The words are the codec's (ParamRequest.describe,
its names of request and response IDs, attributes, formats and error numbers).

Each decoded record is a Record: its JSON object (sniff's `decoded.ds47`, docs/json.md), its line in
words and, for a request, the parameters a response with the same reference answers (a response
carries only values: the request names them). Sans-IO, nothing kept.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from profidrive_cli.drives.profidrive import ds47 as D

#: the record index of the PROFIdrive parameter channel
DS47 = D.INDEX


@dataclass(frozen=True)
class Record:
    """A data record in words: `obj` the JSON object, `text` its line. A parameter request's
    `reference` and `addresses` ((PNU, subindex) per parameter) pair it with its response."""
    obj: dict[str, Any]
    text: str
    reference: int | None = None
    addresses: tuple[tuple[int, int], ...] = ()


def _values(item: D.ParamValues | D.ParamFault) -> dict[str, Any]:
    """One parameter's block: its format and values (numbers) or octets (a string format), or its
    error (number, text, additional information)."""
    if isinstance(item, D.ParamFault):
        return {"error": item.number, "error_text": item.text, "extra": item.extra}
    d: dict[str, Any] = {"format": item.format_name}
    if isinstance(item.values, bytes):
        d["octets"] = item.values.hex(" ")
    else:
        d["values"] = list(item.values)
    return d


def request_record(index: int, data: bytes) -> Record | None:
    """The data of a Write of record `index` in words: a DS47 parameter request (header, then per
    parameter its attribute, elements, PNU, subindex and a change request's values); None for a
    record without a decoder here."""
    if index != DS47:
        return None
    try:
        req = D.ParamRequest.decode(data)
    except D.Ds47Error as e:
        return Record({"kind": "request", "problem": str(e)},
                      f"DS47 parameter request, malformed: {e}")
    params = []
    for i, a in enumerate(req.addresses):
        p: dict[str, Any] = {"pnu": a.pnu, "subindex": a.subindex, "elements": a.elements,
                             "attribute": D.ATTRIBUTES.get(a.attribute, f"0x{a.attribute:02X}")}
        if i < len(req.values):
            p.update(_values(req.values[i]))
        params.append(p)
    obj = {"kind": "request", "reference": req.reference, "request_id": req.request_id,
           "request": D.REQUEST_NAMES[req.request_id], "axis": req.axis, "count": len(params),
           "parameters": params}
    return Record(obj, f"DS47 parameter request: {req.describe()}", req.reference,
                  tuple((a.pnu, a.subindex) for a in req.addresses))


def response_record(index: int, data: bytes, request: Record | None = None) -> Record | None:
    """The data of a Read answer of record `index` in words: a DS47 parameter response (header,
    then per parameter its format and values, or its error number and text); `request` the
    parameter request written before it -- with the same reference and number of parameters each
    entry names its PNU and subindex. None for a record without a decoder here."""
    if index != DS47:
        return None
    try:
        res = D.ParamResponse.decode(data)
    except D.Ds47Error as e:
        return Record({"kind": "response", "problem": str(e)},
                      f"DS47 parameter response, malformed: {e}")
    pairs = request.addresses if request is not None and request.reference == res.reference \
        and len(request.addresses) == len(res.items) else None
    params = []
    for i, item in enumerate(res.items):
        p: dict[str, Any] = {}
        if pairs is not None:
            p.update(pnu=pairs[i][0], subindex=pairs[i][1])
        p.update(_values(item))
        params.append(p)
    obj = {"kind": "response", "reference": res.reference, "response_id": res.response_id,
           "response": D.RESPONSE_NAMES[res.response_id], "axis": res.axis, "count": res.count,
           "parameters": params}
    return Record(obj, f"DS47 parameter response: {res.describe()}", res.reference)


__all__ = ["DS47", "Record", "request_record", "response_record"]
