"""drives/profidrive/pkw.py: PKE limits, AK tables and the channel's AK-0 / timeout rules, one case
per gap mutation testing found (issue 20).

Expected values: PKE layout and AK tables of the reference §6.2 (bits 15..12 AK, bit 11 SPM
"normally 0", bits 10..0 PNU; request AK 8 = change array double word; response AK 8 = no
parameter change rights; error numbers table), and hand-counted cycles of the channel contract
(per cycle outputs() then feed(); AK 0 for at least one cycle and until the drive answers AK 0,
at most max_zero_cycles; timeout counted from submit()).
"""

import pytest

from profidrive_cli.drives.profidrive import pkw as P

IDLE = (0, 0, 0, 0)
READ23 = (0x1017, 0, 0, 0)          # AK 1, PNU 23 (0x017)


class Card:
    """A drive's PKW side: executes a task when the request words change (AK 0 clears), answers
    after `delay` cycles (the answer of cycle n is what the card made of the words of cycle
    n - delay); `answers_zero` False: keeps showing its last answer instead of AK 0."""

    def __init__(self, delay=0, answers_zero=True, values=None, error_pnus=()):
        self.delay, self.answers_zero = delay, answers_zero
        self.values = dict(values or {23: 500})
        self.error_pnus = dict(error_pnus)
        self.pipe: list[tuple] = []
        self.last = None
        self.resp = P.IDLE
        self.executed = 0

    def _process(self, words):
        if words == self.last:
            return
        self.last = words
        req = P.PkwFrame.from_words(words)
        if req.ak == 0:
            if self.answers_zero:
                self.resp = P.IDLE
            return
        self.executed += 1
        if req.pnu in self.error_pnus:
            ak, num = self.error_pnus[req.pnu]
            self.resp = P.PkwFrame(ak, req.pnu, 0, num)
        elif req.ak in (2, 3):
            self.values[req.pnu] = req.value
            self.resp = P.PkwFrame(1, req.pnu, 0, req.value)
        else:
            self.resp = P.PkwFrame(1, req.pnu, 0, self.values[req.pnu])

    def __call__(self, words):
        self.pipe.append(tuple(words))
        if len(self.pipe) > self.delay:
            self._process(self.pipe.pop(0))
        return self.resp.words()


def cycle(ch, card, now, limit=60, step=0.01):
    sent = []
    for i in range(limit):
        out = ch.outputs()
        sent.append(out)
        res = ch.feed(card(out), now + step * (i + 1))
        if res is not None:
            return res, sent
    return None, sent


# -- PKE ------------------------------------------------------------------------------------------

def test_pke_spm_defaults_to_0_and_pnu_uses_all_11_bits():
    assert P.encode_pke(1, 23) == 0x1017
    assert P.encode_pke(1, 0x7FF) == 0x17FF
    assert P.decode_pke(0x17FF) == (1, 0, 2047)


def test_pke_limits_say_what():
    with pytest.raises(ValueError) as e:
        P.encode_pke(16, 1)
    assert str(e.value) == "AK 16 outside 0..15"
    with pytest.raises(ValueError) as e:
        P.encode_pke(1, 2048)
    assert str(e.value) == "PNU 2048 outside 0..2047"


def test_from_words_needs_four():
    with pytest.raises(ValueError) as e:
        P.PkwFrame.from_words((1, 2, 3))
    assert str(e.value) == "PKW is 4 words, got 3"


def test_array_double_word_write_is_ak_8():
    assert P.write_request(916, 5, 1, array=True, long=True).ak == 8
    assert P.write_request(916, 5, 1, array=True).ak == 7


def test_no_positive_answer_to_a_reserved_request_id():
    # AK 10 is reserved (§6.2): nothing but an error matches it
    assert not P.matches(P.PkwFrame(10, 5), P.PkwFrame(1, 5))
    assert P.matches(P.PkwFrame(10, 5), P.PkwFrame(7, 5, 0, 0))


# -- submit ---------------------------------------------------------------------------------------

def test_submit_refusals_say_what():
    ch = P.PkwChannel()
    ch.submit(P.read_request(23))
    with pytest.raises(P.PkwBusy) as e:
        ch.submit(P.read_request(26))
    assert str(e.value) == "PKW request PNU 23 still outstanding"
    with pytest.raises(ValueError) as e:
        P.PkwChannel().submit(P.IDLE)
    assert str(e.value) == "AK 0 is not a request"


def test_first_request_goes_out_at_once_even_with_zero_after_error():
    ch = P.PkwChannel(zero_after_error=True)
    ch.submit(P.read_request(23), 0.0)
    assert ch.outputs() == READ23


def test_by_default_no_ak0_after_an_error_or_between_identical_requests():
    card = Card(error_pnus={99: (7, 0)})
    ch = P.PkwChannel()
    ch.submit(P.read_request(99), 0.0)
    res, _ = cycle(ch, card, 0.0)
    assert res.error == 0
    ch.submit(P.read_request(23), 1.0)
    assert ch.outputs() == READ23


def test_after_success_zero_after_error_sends_the_next_request_at_once():
    card = Card(values={23: 500, 26: 300})
    ch = P.PkwChannel(zero_after_error=True)
    ch.submit(P.read_request(23), 0.0)
    res, _ = cycle(ch, card, 0.0)
    assert res.ok and res.describe_error() == "ok"
    ch.submit(P.read_request(26), 1.0)
    assert ch.outputs() == (0x101A, 0, 0, 0)


# -- AK 0 in between ------------------------------------------------------------------------------

def test_exactly_one_ak0_cycle_when_the_drive_answers_it_at_once():
    card = Card()
    ch = P.PkwChannel(zero_between_identical=True)
    ch.submit(P.read_request(23), 0.0)
    cycle(ch, card, 0.0)
    card.values[23] = 777
    ch.submit(P.read_request(23), 1.0)
    res, sent = cycle(ch, card, 1.0)
    assert sent == [IDLE, READ23]
    assert res.value == 777 and card.executed == 2


def test_ak0_until_a_slow_drive_answers_it_no_stale_echo():
    """The drive answers two cycles late: the old answer to the same PNU is still coming in while
    AK 0 goes out; the channel waits for the drive's AK 0 and then gets the new value."""
    card = Card(delay=2)
    ch = P.PkwChannel(zero_between_identical=True)
    ch.submit(P.read_request(23), 0.0)
    res, _ = cycle(ch, card, 0.0)
    assert res.value == 500
    card.values[23] = 777
    ch.submit(P.read_request(23), 1.0)
    res, sent = cycle(ch, card, 1.0)
    assert res.value == 777 and card.executed == 2
    # the card answered AK 0 to the first AK 0 two cycles later: three AK 0 cycles went out
    assert sent[:4] == [IDLE, IDLE, IDLE, READ23]


def test_ak0_at_most_max_zero_cycles_when_the_drive_never_answers_it():
    card = Card(answers_zero=False)
    ch = P.PkwChannel(zero_between_identical=True, max_zero_cycles=3)
    ch.submit(P.read_request(23), 0.0)
    cycle(ch, card, 0.0)
    ch.submit(P.read_request(23), 1.0)
    res, sent = cycle(ch, card, 1.0)
    assert sent[:4] == [IDLE, IDLE, IDLE, READ23]


def test_an_idle_cycle_counts_only_when_the_drive_answered_ak0():
    """After a completed read, one idle cycle whose answer is still the old response is no AK 0
    from the drive: an identical request still needs AK 0 first."""
    card = Card(delay=1)
    ch = P.PkwChannel(zero_between_identical=True)
    ch.submit(P.read_request(23), 0.0)
    res, _ = cycle(ch, card, 0.0)
    assert res.ok
    out = ch.outputs()
    assert out == IDLE
    answer = card(out)                        # the card has not processed AK 0 yet
    assert answer != IDLE
    ch.feed(answer, 0.5)
    ch.submit(P.read_request(23), 1.0)
    assert ch.outputs() == IDLE


@pytest.mark.parametrize("rule", ["zero_after_error", "zero_between_identical"])
def test_after_an_error_answer_the_rules_apply(rule):
    card = Card(error_pnus={99: (7, 2)})
    ch = P.PkwChannel(**{rule: True})
    ch.submit(P.read_request(99), 0.0)
    res, _ = cycle(ch, card, 0.0)
    assert res.error == 2 and res.error_text == "value outside the limits"
    assert res.request == P.read_request(99) and res.response.ak == 7
    ch.submit(P.read_request(99), 1.0)
    assert ch.outputs() == IDLE


# -- AK 8 and error texts -------------------------------------------------------------------------

@pytest.mark.parametrize("num, text", [
    (0, "no parameter change rights"),
    (12, "no parameter change rights (key word missing)"),
])
def test_ak8_no_parameter_change_rights(num, text):
    card = Card(error_pnus={23: (8, num)})
    ch = P.PkwChannel()
    ch.submit(P.write_request(23, 1), 0.0)
    res, _ = cycle(ch, card, 0.0)
    assert not res.ok and res.error == num and res.error_text == text
    assert res.request.pnu == 23 and res.response.ak == 8
    assert res.describe_error() == f"error {num} ({text})"


def test_unknown_error_number_is_named_by_its_number():
    card = Card(error_pnus={23: (7, 150)})
    ch = P.PkwChannel()
    ch.submit(P.read_request(23), 0.0)
    res, _ = cycle(ch, card, 0.0)
    assert res.error_text == "error 150"
    assert P.PkwChannel().error_text(150) == "error 150"


def test_success_result_carries_the_request():
    ch = P.PkwChannel()
    req = P.read_request(23)
    ch.submit(req, 0.0)
    res, _ = cycle(ch, Card(), 0.0)
    assert res.request is req and res.error is None


# -- timeout --------------------------------------------------------------------------------------

def test_timeout_counts_from_submit_and_not_before_it_has_passed():
    ch = P.PkwChannel(timeout=1.0)
    ch.submit(P.read_request(23), now=0.0)
    silent = IDLE
    ch.outputs()
    assert ch.feed(silent, 0.5) is None
    ch.outputs()
    assert ch.feed(silent, 1.0) is None            # exactly at the deadline: still waiting
    ch.outputs()
    res = ch.feed(silent, 1.2)
    assert res is not None and res.timed_out
    assert res.request == P.read_request(23)
    assert res.error_text == "no answer to PNU 23 within 1 s" == res.describe_error()


def test_timeout_without_submit_time_counts_from_the_first_feed():
    ch = P.PkwChannel(timeout=1.0)
    ch.submit(P.read_request(23))
    ch.outputs()
    assert ch.feed(IDLE, 5.0) is None
    ch.outputs()
    assert ch.feed(IDLE, 6.0) is None
    ch.outputs()
    assert ch.feed(IDLE, 6.1).timed_out


def test_timeout_while_sending_ak0():
    card = Card(answers_zero=False)
    ch = P.PkwChannel(timeout=1.0, zero_between_identical=True, max_zero_cycles=1000)
    ch.submit(P.read_request(23), 0.0)
    cycle(ch, card, 0.0)
    ch.submit(P.read_request(23), 10.0)
    ch.outputs()
    assert ch.feed(card(IDLE), 11.0) is None      # at the deadline: not yet
    ch.outputs()
    res = ch.feed(card(IDLE), 11.5)
    assert res.timed_out and res.request == P.read_request(23) and not ch.busy


@pytest.mark.parametrize("rule", ["zero_after_error", "zero_between_identical"])
def test_after_a_timeout_the_rules_apply(rule):
    ch = P.PkwChannel(timeout=0.1, **{rule: True})
    ch.submit(P.read_request(23), 0.0)
    res, _ = cycle(ch, lambda w: IDLE, 0.0)
    assert res.timed_out
    # the drive may still answer the old task: AK 0 first (identical request, or after a failure)
    ch.submit(P.read_request(23), 1.0)
    assert ch.outputs() == IDLE


# -- cancel ---------------------------------------------------------------------------------------

def test_cancel_frees_the_channel_and_counts_as_a_failure():
    ch = P.PkwChannel(zero_after_error=True)
    ch.cancel()                                   # idle: nothing to cancel
    assert not ch.busy
    ch.submit(P.read_request(23), 0.0)
    assert ch.outputs() == READ23
    ch.cancel()
    assert not ch.busy and ch.pending is None and ch.outputs() == IDLE
    ch.submit(P.read_request(26), 1.0)
    assert ch.outputs() == IDLE                   # the cancelled task may still be answered


def test_cancel_then_identical_request_sends_ak0_first():
    ch = P.PkwChannel(zero_between_identical=True)
    ch.submit(P.read_request(23), 0.0)
    ch.outputs()
    ch.cancel()
    ch.submit(P.read_request(23), 1.0)
    assert ch.outputs() == IDLE
