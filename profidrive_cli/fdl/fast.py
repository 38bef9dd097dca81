"""Precomputed telegrams for the Data_Exchange fast path, sans-IO.

A station in data exchange gets the same request every cycle except for the outputs and the FCB,
and answers with the same header every cycle except for the inputs. DxTemplate holds, for one
station, one FCB state and one pair of area lengths, everything that does not change:

    request  = head + outputs + (head_fcs + sum(outputs)) & 0xFF + ED
    reply ok = len(reply) == reply_len and reply starts with reply_head (DL from that station to us)
               and its FCS and ED are right

The octets are those fdl.frames.encode() gives for the same telegram (SD1 / SD2 / SD3 chosen by
length the same way): the templates are built from encode() with zero data, whose FCS is then the
sum of the header alone. Anything that does not fit (another status, another length, a broken
telegram, a parity flag) is left to the general engine (fdl.master.FdlMaster.feed).
"""

from __future__ import annotations

from profidrive_cli.fdl import frames as F


class DxTemplate:
    __slots__ = ("head", "head_fcs", "reply_head", "reply_fcs", "reply_len", "reply_data_end",
                 "timeout", "cap", "request_len")

    def __init__(self, head: bytes, head_fcs: int, reply_head: bytes, reply_fcs: int,
                 reply_len: int):
        self.head = head
        self.head_fcs = head_fcs
        self.reply_head = reply_head
        self.reply_fcs = reply_fcs
        self.reply_len = reply_len
        self.reply_data_end = reply_len - 2
        self.timeout = self.cap = 0.0
        self.request_len = 0


def dx_template(master: int, station: int, fc: int, n_out: int, n_in: int) -> DxTemplate:
    """The template of an SRD-high Data_Exchange (no SAPs) from `master` to `station` with request
    FC `fc`, n_out output octets and n_in input octets in a DL reply."""
    req = F.encode(F.Frame(F.SD2, station, master, fc, bytes(n_out)))
    rep = F.encode(F.Frame(F.SD2, master, station, F.response_fc(F.DL), bytes(n_in)))
    return DxTemplate(req[:len(req) - 2 - n_out], req[-2],
                      rep[:len(rep) - 2 - n_in], rep[-2], len(rep))
