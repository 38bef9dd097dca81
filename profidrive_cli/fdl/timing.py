"""Bus timing per baud rate (reference §1.1 and §4) in bit times and seconds.

Defaults for a single-master PC: TSL is only our own reply timeout, so over USB adapters it is
widened (reference §4.3): the default slot time is max(standard TSL, what the adapter's latency needs).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

BAUD_RATES = (9600, 19200, 45450, 93750, 187500, 500000, 1500000, 3000000, 6000000, 12000000)
BAUD_NAMES = {9600: "9.6k", 19200: "19.2k", 45450: "45.45k", 93750: "93.75k", 187500: "187.5k",
              500000: "500k", 1500000: "1.5M", 3000000: "3M", 6000000: "6M", 12000000: "12M"}

# baud -> (TSL, min TSDR, max TSDR, TQUI, TSET) in bit times (reference §4.1)
_TABLE = {
    9600: (100, 11, 60, 0, 1), 19200: (100, 11, 60, 0, 1), 45450: (100, 11, 60, 0, 1),
    93750: (100, 11, 60, 0, 1), 187500: (100, 11, 60, 0, 1), 500000: (200, 11, 100, 0, 1),
    1500000: (300, 11, 150, 0, 1), 3000000: (400, 11, 250, 3, 4), 6000000: (600, 11, 450, 6, 8),
    12000000: (1000, 11, 800, 9, 16),
}
TSYN_BITS = 33
CHAR_BITS = 11


def parse_baud(text: str | int) -> int:
    """'19200', '19.2k', '1.5M', '187500' -> bit/s; ValueError listing the DP rates otherwise."""
    if isinstance(text, int):
        b = text
    else:
        t = text.strip().lower().replace("_", "")
        mult = 1
        if t.endswith("k"):
            mult, t = 1000, t[:-1]
        elif t.endswith("m"):
            mult, t = 1000000, t[:-1]
        try:
            b = round(float(t) * mult)
        except (ValueError, OverflowError):     # 'x', 'nan'; 'inf', '1e999' (no integer)
            b = -1
    if b not in _TABLE:
        raise ValueError(f"{text!r} is not a PROFIBUS-DP baud rate "
                         f"({', '.join(BAUD_NAMES[r] for r in BAUD_RATES)})")
    return b


@dataclass(frozen=True)
class BusParams:
    baud: int = 19200
    tsl: int = 100          # slot time, bit times
    min_tsdr: int = 11
    max_tsdr: int = 60
    tqui: int = 0
    tset: int = 1
    retries: int = 1
    #: extra seconds added to every reply timeout for the link (USB latency, OS scheduling)
    link_latency: float = 0.0

    @classmethod
    def for_baud(cls, baud: int, slot_time: int | None = None, retries: int | None = None,
                 link_latency: float = 0.0) -> "BusParams":
        tsl, mn, mx, tqui, tset = _TABLE[baud]
        p = cls(baud, tsl, mn, mx, tqui, tset, 1, link_latency)
        if slot_time is not None:
            if not mx + 15 <= slot_time <= 16383:
                raise ValueError(f"slot time {slot_time} outside {mx + 15}..16383 bit times "
                                 f"at {BAUD_NAMES[baud]}")
            p = replace(p, tsl=slot_time)
        if retries is not None:
            if not 0 <= retries <= 15:
                raise ValueError(f"retries {retries} outside 0..15")
            p = replace(p, retries=retries)
        return p

    # -- times in seconds -----------------------------------------------------------------
    @property
    def t_bit(self) -> float:
        return 1.0 / self.baud

    def chars(self, n: int) -> float:
        return n * CHAR_BITS / self.baud

    @property
    def tsyn(self) -> float:
        return TSYN_BITS / self.baud

    @property
    def tid1(self) -> int:
        return 35 + 2 * self.tset + self.tqui

    @property
    def tid1_seconds(self) -> float:
        """Idle time the initiator keeps after a reply before its next request (>= TSYN)."""
        return self.tid1 / self.baud

    @property
    def tid2(self) -> int:
        """Idle after an unacknowledged (SDN) telegram, bit times: max TSDR."""
        return self.max_tsdr

    @property
    def slot_seconds(self) -> float:
        return self.tsl / self.baud

    def reply_timeout(self, reply_octets: int = 255) -> float:
        """How long the master waits for a whole reply: slot time for its first octet, the octets'
        wire time, and the link's own latency."""
        return self.slot_seconds + self.chars(reply_octets) + self.link_latency

    def cycle_time(self, req_octets: int, reply_octets: int, tsdr_bits: int | None = None) -> float:
        """Wire time of one request/reply cycle (reference §4.2 message cycle estimate):
        TSYN + request + TSDR + reply + TID1 idle before the next request."""
        tsdr = self.max_tsdr if tsdr_bits is None else tsdr_bits
        return (self.chars(req_octets) + (tsdr + self.tid1) / self.baud
                + self.chars(reply_octets))


def transaction_wire_time(params: BusParams, req_octets: int, reply_octets: int | None,
                          tsdr_bits: int = 11, attempts: int = 1) -> float:
    """The least time one request costs on the wire, idle time included.

    Answered: request + TSDR + reply + TID1 (the idle before the next request).
    Unanswered: each attempt is request + slot time (TSL >= TSYN, so the next request may follow
    at once); `attempts` = 1 + retries for a station that is not there.
    """
    if reply_octets is None:
        return attempts * (params.chars(req_octets) + params.slot_seconds)
    return params.cycle_time(req_octets, reply_octets, tsdr_bits)


def frame_octets(du_octets: int, saps: bool = False) -> int:
    """Octets of a data telegram with `du_octets` of user data (SD1 / SD3 / SD2 as encode() picks)."""
    n = du_octets + (2 if saps else 0)
    return 6 if n == 0 else (14 if n == 8 else n + 9)


def wire_time_data_exchange(baud: int, out_octets: int, in_octets: int, tsdr_bits: int = 11) -> float:
    """Seconds for one Data_Exchange on the wire: SD2 frames (9 octets + data), TSDR, TID1."""
    p = BusParams.for_baud(baud)
    def frame_len(n: int) -> int:
        return 6 if n == 0 else (14 if n == 8 else n + 9)
    return p.cycle_time(frame_len(out_octets), frame_len(in_octets), tsdr_bits)
