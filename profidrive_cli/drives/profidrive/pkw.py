"""The PKW parameter channel: PKE/IND/PWE encoding, the AK request/response tables, the channel.

Sans-IO: `PkwChannel` is fed the received PKW words and a time and gives the words to send; it never
waits. Knows no profile and no PNU meanings (those are in pnu.py / params.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

from profidrive_cli.drives.base import DriveError

def encode_pke(ak: int, pnu: int, spm: int = 0) -> int:
    if not 0 <= ak <= 15:
        raise ValueError(f"AK {ak} outside 0..15")
    if not 0 <= pnu <= 0x7FF:
        raise ValueError(f"PNU {pnu} outside 0..2047")
    return (ak << 12) | ((spm & 1) << 11) | pnu


def decode_pke(pke: int) -> tuple[int, int, int]:
    """-> (AK, SPM, PNU)"""
    return (pke >> 12) & 0xF, (pke >> 11) & 1, pke & 0x7FF


REQUEST_TEXT: dict[int, str] = {
    0: "no task", 1: "request parameter value", 2: "change parameter value (word)",
    3: "change parameter value (long word)", 4: "request description element",
    5: "change description element", 6: "request parameter value (array)",
    7: "change parameter value (array word)", 8: "change parameter value (array long word)",
    9: "request number of array elements", 11: "change array long word and store",
    12: "change array word and store", 13: "change long word and store",
    14: "change word and store", 15: "read or change text",
}
RESPONSE_TEXT: dict[int, str] = {
    0: "no response", 1: "transfer parameter value (word)",
    2: "transfer parameter value (long word)", 3: "transfer description element",
    4: "transfer parameter value (array word)", 5: "transfer parameter value (array long word)",
    6: "transfer number of array elements", 7: "task cannot be executed",
    8: "no parameter change rights", 9: "parameter change report (word)",
    10: "parameter change report (long word)", 15: "transfer text",
}
#: request AK -> positive response AKs accepted (lenient: word/long word answers both accepted)
POSITIVE_RESPONSES: dict[int, frozenset[int]] = {
    1: frozenset({1, 2}), 2: frozenset({1, 2}), 3: frozenset({1, 2}), 4: frozenset({3}),
    5: frozenset({3}), 6: frozenset({4, 5}), 7: frozenset({4, 5}), 8: frozenset({4, 5}),
    9: frozenset({6}), 11: frozenset({4, 5}), 12: frozenset({4, 5}), 13: frozenset({1, 2}),
    14: frozenset({1, 2}), 15: frozenset({15}),
}
ERROR_RESPONSES = frozenset({7, 8})
ARRAY_REQUESTS = frozenset({6, 7, 8, 9, 11, 12})
WRITE_REQUESTS = frozenset({2, 3, 5, 7, 8, 11, 12, 13, 14})

#: PKW error numbers (AK 7, PWE) of the PROFIdrive profile; 8, 10, 13, 14, 16, 19 are reserved in
#: V3 and carry their PROFIdrive V2 meanings (as SEW's and Lenze's PROFIBUS manuals print them, e.g.
#: Lenze EDS82ZAFPC201 8.2.3). A card's own table (the profile's pkw.errors) wins over these.
GENERIC_ERRORS: dict[int, str] = {
    0: "parameter number does not exist",
    1: "parameter is read-only",
    2: "value outside the limits",
    3: "wrong subindex",
    4: "parameter is not an array",
    5: "wrong data type",
    6: "only 0 may be written",
    7: "description element is read-only",
    8: "PPO-Write requested in IR not available (PROFIdrive V2)",
    9: "description data not available",
    10: "access group wrong (PROFIdrive V2)",
    11: "no parameter change rights",
    12: "key word missing",
    13: "text cannot be read in cyclic data transfer (PROFIdrive V2)",
    14: "name cannot be read in cyclic data transfer (PROFIdrive V2)",
    15: "no text array",
    16: "no PPO-Write (PROFIdrive V2)",
    17: "not possible in the current operating state",
    18: "other error",
    19: "data cannot be read in cyclic interchange (PROFIdrive V2)",
    20: "value not allowed",
    21: "response too long",
    22: "parameter address not allowed",
    23: "illegal format",
    24: "number of values inconsistent",
}


@dataclass(frozen=True)
class PkwFrame:
    """The 4 PKW words of one direction, decoded. `value` is PWE1:PWE2 as a 32-bit number."""
    ak: int
    pnu: int
    subindex: int = 0
    value: int = 0
    spm: int = 0
    ind_low: int = 0      # IND low octet: reserved in PROFIdrive V2 (Siemens: page)

    @property
    def pke(self) -> int:
        return encode_pke(self.ak, self.pnu, self.spm)

    @property
    def ind(self) -> int:
        return (self.subindex & 0xFF) << 8 | (self.ind_low & 0xFF)

    def words(self) -> tuple[int, int, int, int]:
        v = self.value & 0xFFFFFFFF
        return (self.pke, self.ind, v >> 16, v & 0xFFFF)

    @classmethod
    def from_words(cls, words: Sequence[int]) -> "PkwFrame":
        if len(words) != 4:
            raise ValueError(f"PKW is 4 words, got {len(words)}")
        ak, spm, pnu = decode_pke(words[0])
        return cls(ak=ak, pnu=pnu, subindex=(words[1] >> 8) & 0xFF, value=(words[2] << 16) | words[3],
                   spm=spm, ind_low=words[1] & 0xFF)

    @property
    def key(self) -> tuple[int, int]:
        return (self.pnu, self.subindex)


PkwRequest = PkwFrame
PkwResponse = PkwFrame
IDLE = PkwFrame(0, 0)


def read_request(pnu: int, subindex: int = 0, array: bool = False) -> PkwFrame:
    return PkwFrame(6 if array else 1, pnu, subindex)


def write_request(pnu: int, value: int, subindex: int = 0, array: bool = False,
                  long: bool = False) -> PkwFrame:
    ak = (8 if long else 7) if array else (3 if long else 2)
    return PkwFrame(ak, pnu, subindex, value & 0xFFFFFFFF)


@dataclass
class PkwResult:
    request: PkwFrame
    response: PkwFrame | None
    error: int | None = None          # the card's error number (AK 7/8), None when ok
    error_text: str = ""
    timed_out: bool = False

    @property
    def ok(self) -> bool:
        return self.response is not None and self.response.ak not in ERROR_RESPONSES \
            and not self.timed_out

    @property
    def value(self) -> int:
        return self.response.value if self.response is not None else 0

    def describe_error(self) -> str:
        if self.timed_out:
            return self.error_text
        return f"error {self.error} ({self.error_text})" if self.error is not None else "ok"


class PkwBusy(DriveError):
    """A request was submitted while another one is outstanding."""


def matches(request: PkwFrame, response: PkwFrame) -> bool:
    """Is `response` the answer to `request`? PNU must echo; subindex too (lenient on errors)."""
    if response.ak == 0 or response.pnu != request.pnu:
        return False
    if response.ak in ERROR_RESPONSES:
        return response.subindex in (request.subindex, 0)
    if response.ak not in POSITIVE_RESPONSES.get(request.ak, frozenset()):
        return False
    return response.subindex == request.subindex


class PkwChannel:
    """The parameter channel as an asynchronous request/response over cyclic data (sans-IO).

    Per cycle: `outputs()` gives the 4 PKW words to send, then `feed(input words, now)` with the
    4 PKW words received; feed returns a PkwResult when the outstanding request is answered (or
    timed out), else None. AK 0 is sent while idle; one request at a time.

    Rules selectable per card:
      zero_after_error        after an error (or a timeout) send AK 0 before the next request
      zero_between_identical  before a request to the same PNU/subindex as the previous one send
                              AK 0 (so the drive sees a new task and a stale echo cannot match)
    In both cases AK 0 goes out for at least one cycle and until the drive answers AK 0 (at most
    `max_zero_cycles` cycles).
    """

    def __init__(self, *, timeout: float = 2.0, zero_after_error: bool = False,
                 zero_between_identical: bool = False, error_texts: dict[int, str] | None = None,
                 max_zero_cycles: int = 20):
        self.timeout = timeout
        self.zero_after_error = zero_after_error
        self.zero_between_identical = zero_between_identical
        self.error_texts = dict(GENERIC_ERRORS)
        if error_texts:
            self.error_texts.update(error_texts)
        self.max_zero_cycles = max_zero_cycles
        self._req: PkwFrame | None = None
        self._deadline: float | None = None
        self._zeroing = 0            # AK 0 cycles still owed before the request goes out (>0)
        self._zero_sent = 0
        self._last: PkwFrame | None = None       # last completed request
        self._last_failed = False
        self._idle_cycles = 0                    # AK 0 cycles sent since the last completion
        self._idle_answered = False              # drive answered AK 0 since the last completion

    @property
    def busy(self) -> bool:
        return self._req is not None

    @property
    def pending(self) -> PkwFrame | None:
        return self._req

    def error_text(self, number: int) -> str:
        return self.error_texts.get(number, f"error {number}")

    def submit(self, request: PkwFrame, now: float | None = None) -> None:
        if self._req is not None:
            raise PkwBusy(f"PKW request PNU {self._req.pnu} still outstanding")
        if request.ak == 0:
            raise ValueError("AK 0 is not a request")
        need_zero = (self.zero_after_error and self._last_failed) or (
            self.zero_between_identical and self._last is not None and self._last.key == request.key)
        if need_zero and self._idle_cycles >= 1 and self._idle_answered:
            need_zero = False
        self._req = request
        self._zeroing = 1 if need_zero else 0
        self._zero_sent = 0
        self._deadline = None if now is None else now + self.timeout

    def cancel(self) -> None:
        if self._req is not None:
            self._finish(self._req, failed=True)

    def outputs(self) -> tuple[int, int, int, int]:
        if self._req is None:
            self._idle_cycles += 1
            return IDLE.words()
        if self._zeroing:
            self._zero_sent += 1
            return IDLE.words()
        return self._req.words()

    def _finish(self, req: PkwFrame, failed: bool) -> None:
        self._req = None
        self._last = req
        self._last_failed = failed
        self._idle_cycles = 0
        self._idle_answered = False
        self._zeroing = 0

    def feed(self, inputs: Sequence[int], now: float) -> PkwResult | None:
        resp = PkwFrame.from_words(inputs)
        req = self._req
        if req is None:
            if resp.ak == 0:
                self._idle_answered = True
            return None
        if self._deadline is None:
            self._deadline = now + self.timeout
        if self._zeroing:
            if self._zero_sent >= 1 and (resp.ak == 0 or self._zero_sent >= self.max_zero_cycles):
                self._zeroing = 0
            elif now > self._deadline:
                return self._timeout(req)
            return None
        if matches(req, resp):
            if resp.ak in ERROR_RESPONSES:
                num = resp.value & 0xFFFF
                text = self.error_text(num)
                if resp.ak == 8:
                    text = f"no parameter change rights ({text})" if num else \
                        "no parameter change rights"
                self._finish(req, failed=True)
                return PkwResult(req, resp, num, text)
            self._finish(req, failed=False)
            return PkwResult(req, resp)
        if now > self._deadline:
            return self._timeout(req)
        return None

    def _timeout(self, req: PkwFrame) -> PkwResult:
        self._finish(req, failed=True)
        return PkwResult(req, None, None, f"no answer to PNU {req.pnu} within {self.timeout:g} s",
                         timed_out=True)
