"""PROFIdrive core (drives/profidrive.py): words, PPO areas, CTW/STW state machine, N2, PKW channel."""

from __future__ import annotations

import textwrap

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from profidrive_cli import UsageError
from profidrive_cli.datafile import DataFileError
from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.profidrive import Ctw, State, Target
from profidrive_cli.drives.profile import load_profile, load_profile_file

words16 = st.integers(0, 0xFFFF)


# -- words and octets ---------------------------------------------------------------------------

def test_word_order():
    assert pd.words_to_bytes([0x3017, 0x0190]) == bytes.fromhex("30170190")
    assert pd.words_to_bytes([0x3017, 0x0190], "little") == bytes.fromhex("17309001")
    assert pd.bytes_to_words(bytes.fromhex("17309001"), "little") == [0x3017, 0x0190]
    with pytest.raises(ValueError):
        pd.bytes_to_words(b"\x01\x02\x03")
    with pytest.raises(ValueError):
        pd.words_to_bytes([1], "middle")


@given(st.lists(words16, max_size=20), st.sampled_from(["big", "little"]))
def test_words_round_trip(words, order):
    assert pd.bytes_to_words(pd.words_to_bytes(words, order), order) == words


def test_ppo_layouts_from_profile():
    prof = load_profile("moeller")
    sizes = {n: (pd.ppo_layout(prof, f"ppo{n}").output_len, pd.ppo_layout(prof, f"ppo{n}").pkw)
             for n in range(1, 6)}
    assert sizes == {1: (12, True), 2: (20, True), 3: (4, False), 4: (12, False), 5: (28, True)}
    for n, (pkw, pzd) in pd.PPO_TYPES.items():
        lay = pd.ppo_layout(prof, f"ppo{n}")
        assert (lay.pkw, lay.pzd_out, lay.pzd_in) == (pkw, pzd, pzd) == \
            (pd.PpoLayout.ppo(n).pkw, pd.PpoLayout.ppo(n).pzd_out, pd.PpoLayout.ppo(n).pzd_in)


@given(st.integers(1, 5), st.sampled_from(["big", "little"]), st.data())
def test_area_round_trip(n, order, data):
    lay = pd.PpoLayout.ppo(n, order)
    pkw = tuple(data.draw(st.lists(words16, min_size=4, max_size=4))) if lay.pkw else None
    pzd = data.draw(st.lists(words16, min_size=lay.pzd_out, max_size=lay.pzd_out))
    raw = pd.encode_area(lay, pd.PpoArea(pkw, pzd))
    assert len(raw) == lay.output_len
    back = pd.decode_area_bytes(lay, raw)
    assert back.pkw == pkw and back.pzd == pzd


def test_area_length_checked():
    with pytest.raises(ValueError, match="12 octets"):
        pd.decode_area_bytes(pd.PpoLayout.ppo(1), b"\x00" * 10)


def test_little_endian_area():
    lay = pd.PpoLayout.ppo(1, "little")
    raw = pd.encode_area(lay, pd.PpoArea((0x1001, 0, 0, 5), [0x047F, 0x2000]))
    assert raw == bytes.fromhex("0110 0000 0000 0500 7F04 0020".replace(" ", ""))


# -- control and status words -------------------------------------------------------------------

def test_ctw_bits_named():
    assert int(Ctw.NO_OFF2 | Ctw.NO_OFF3 | Ctw.CONTROL_BY_PLC) == 0x0406
    assert pd.bit_list(0x047F, pd.CTW_NAMES) == [
        "ON", "no OFF2", "no OFF3", "enable operation", "enable ramp generator",
        "unfreeze ramp generator", "enable setpoint", "control by PLC"]
    assert pd.bit_list(0x8001, {0: "a"}) == ["a", "bit 15"]


@pytest.mark.parametrize("stw,moving,state", [
    (0x0240, None, State.S1), (0x0040, True, State.S1), (0x0331, None, State.S2),
    (0x0333, None, State.S3), (0x0337, None, State.S4), (0x0333, True, State.S5),
    (0x0331, True, State.S5), (0x0008, None, State.FAULT), (0x0248, None, State.FAULT),
    (0x0000, None, State.S1), (0x0230, True, State.S5),
])
def test_state_from_status(stw, moving, state):
    assert pd.state_from_status(stw, moving) is state


# every state x every target; status words as a PROFIdrive drive shows them
STATES = {"S1": (0x0240, None), "S2": (0x0331, None), "S3": (0x0333, None), "S4": (0x0337, None),
          "S5": (0x0333, True), "FAULT": (0x0238, None)}
EXPECTED = {
    # target:       S1      S2      S3      S4      S5      FAULT
    "ready":       (0x0406, 0x0406, 0x0406, 0x047E, 0x047E, 0x0406),
    "off1":        (0x0406, 0x0406, 0x0406, 0x047E, 0x047E, 0x0406),
    "switched_on": (0x0406, 0x0407, 0x0407, 0x0407, 0x0407, 0x0406),
    "operate":     (0x0406, 0x047F, 0x047F, 0x047F, 0x047F, 0x0406),
    "off2":        (0x047D,) * 6,
    "off3":        (0x047B,) * 6,
    "disable":     (0x0477,) * 6,
    "ack":         (0x0406, 0x0406, 0x0406, 0x0406, 0x0406, 0x0406),
}


@pytest.mark.parametrize("target", list(EXPECTED))
@pytest.mark.parametrize("state", list(STATES))
def test_next_control_word_every_pair(state, target):
    stw, moving = STATES[state]
    want = EXPECTED[target][list(STATES).index(state)]
    got = pd.next_control_word(stw, target, moving=moving)
    assert got == want, f"{state} -> {target}: 0x{got:04X} != 0x{want:04X}"


def test_next_control_word_derived_from_bits():
    base = Ctw.NO_OFF2 | Ctw.NO_OFF3 | Ctw.CONTROL_BY_PLC
    run = base | Ctw.ON | pd.RUN_BITS
    assert pd.next_control_word(0x0240, Target.OPERATE) == base
    assert pd.next_control_word(0x0331, Target.OPERATE) == run
    assert pd.next_control_word(0x0337, Target.OFF1) == run & ~Ctw.ON
    assert pd.next_control_word(0x0337, Target.OFF2) == run & ~Ctw.NO_OFF2
    assert pd.next_control_word(0x0337, Target.OFF3) == run & ~Ctw.NO_OFF3


def test_ack_edge():
    fault = 0x0238
    # D-8: 0x0406 -> 0x0486 -> 0x0406 (edge on bit 7 only when the previous word had it low)
    assert pd.next_control_word(fault, "ack", previous=0x0406) == 0x0486
    assert pd.next_control_word(fault, "ack", previous=0x0486) == 0x0406
    assert pd.next_control_word(fault, "ack", previous=None) == 0x0406
    # never acknowledges unless asked
    for t in ("operate", "ready", "switched_on"):
        assert not pd.next_control_word(fault, t, previous=0x0406) & Ctw.FAULT_ACK


def test_extra_bits():
    # Fuji/Toyo style: bits 4-6 held -> 0x0476 then 0x047F
    assert pd.next_control_word(0x0240, "operate", 0x0070) == 0x0476
    assert pd.next_control_word(0x0331, "operate", 0x0070) == 0x047F
    # reverse (bit 11) and jog (bit 8) pass through; derived bits cannot be forced
    assert pd.next_control_word(0x0337, "operate", 0x0800 | 0x0100) == 0x0D7F
    assert pd.next_control_word(0x0240, "operate", 0x00FF) == 0x0476


def test_off1_keeps_operation_enabled_while_ramping():
    # after 0x047E the status may already look like S2/S3 while the motor still turns: keep bit 3
    assert pd.next_control_word(0x0333, "off1", previous=0x047E) == 0x047E
    assert pd.next_control_word(0x0331, "off1", previous=0x047E) == 0x047E


@pytest.mark.parametrize("stw,target,moving,reached", [
    (0x0337, "operate", None, True), (0x0333, "operate", None, False),
    (0x0331, "ready", None, True), (0x0331, "off1", False, True), (0x0333, "off1", True, False),
    (0x0240, "off2", False, True), (0x0240, "off3", False, True), (0x0333, "off3", True, False),
    (0x0238, "ack", None, False), (0x0240, "ack", None, True), (0x0333, "switched_on", None, True),
    (0x0333, "disable", False, True),
])
def test_target_reached(stw, target, moving, reached):
    assert pd.target_reached(stw, target, moving) is reached


def test_target_parse():
    assert Target.parse("coast") is Target.OFF2 and Target.parse("quick") is Target.OFF3
    with pytest.raises(ValueError, match="unknown target"):
        Target.parse("fly")


def test_command_from_control_word():
    assert pd.command_from_control_word(0x047F) == "operate"
    assert pd.command_from_control_word(0x0406) == "ready (OFF1)"
    assert pd.command_from_control_word(0x047E) == "OFF1 ramp stop"
    assert pd.command_from_control_word(0x047D) == "OFF2 coast stop"
    assert pd.command_from_control_word(0x047B) == "OFF3 quick stop"
    assert pd.command_from_control_word(0x0486) == "ready (OFF1); fault acknowledge"
    assert pd.command_from_control_word(0x007F).startswith("no control")
    assert pd.command_from_control_word(0x045F) == "operate without unfreeze ramp generator"


# -- N2 -----------------------------------------------------------------------------------------

@pytest.mark.parametrize("word,pct", [(0x0000, 0.0), (0x2000, 50.0), (0x4000, 100.0),
                                      (0xC000, -100.0), (0x8000, -200.0),
                                      (0x7FFF, 199.993896484375)])
def test_n2_table(word, pct):
    assert pd.n2_to_percent(word) == pct
    assert pd.n2_from_percent(pct) == word


def test_n2_hz_and_clamp():
    assert pd.n2_to_hz(0x2000, 50.0) == 25.0
    assert pd.n2_to_hz(0x2000, 75.0) == 37.5
    assert pd.n2_from_hz(-30.0, 60.0) == 0xE000
    assert pd.n2_from_percent(250) == 0x7FFF and pd.n2_from_percent(-250) == 0x8000
    with pytest.raises(ValueError):
        pd.n2_from_hz(1.0, 0.0)


@given(words16)
def test_n2_word_round_trip(word):
    assert pd.n2_from_percent(pd.n2_to_percent(word)) == word


@given(st.floats(-200.0, 199.99, allow_nan=False))
def test_n2_percent_round_trip(pct):
    assert abs(pd.n2_to_percent(pd.n2_from_percent(pct)) - pct) <= 100.0 / 16384 / 2 + 1e-12


@given(st.floats(-100.0, 100.0, allow_nan=False), st.floats(1.0, 500.0, allow_nan=False))
def test_n2_hz_round_trip(hz_pct, fmax):
    hz = hz_pct * fmax / 100.0
    assert abs(pd.n2_to_hz(pd.n2_from_hz(hz, fmax), fmax) - hz) <= fmax / 16384 / 2 + 1e-9


# -- PKE / PKW frames ---------------------------------------------------------------------------

@pytest.mark.parametrize("pke,ak,spm,pnu", [
    (0x3017, 3, 0, 23), (0x2017, 2, 0, 23), (0x7394, 7, 0, 916), (0x4394, 4, 0, 916),
    (0x7393, 7, 0, 915), (0x4393, 4, 0, 915), (0x1800 | 5, 1, 1, 5)])
def test_pke(pke, ak, spm, pnu):
    assert pd.decode_pke(pke) == (ak, spm, pnu)
    assert pd.encode_pke(ak, pnu, spm) == pke


def test_pke_limits():
    with pytest.raises(ValueError):
        pd.encode_pke(16, 1)
    with pytest.raises(ValueError):
        pd.encode_pke(1, 2048)


@given(st.integers(0, 15), st.integers(0, 0x7FF), st.integers(0, 1), st.integers(0, 255),
       st.integers(0, 255), st.integers(0, 0xFFFFFFFF))
def test_pkw_frame_round_trip(ak, pnu, spm, sub, low, value):
    f = pd.PkwFrame(ak, pnu, sub, value, spm, low)
    words = f.words()
    assert all(0 <= w <= 0xFFFF for w in words)
    assert pd.PkwFrame.from_words(words) == f
    assert words[1] >> 8 == sub            # subindex in the high octet of IND
    assert (words[2] << 16 | words[3]) == value


def test_request_builders():
    assert pd.write_request(23, 400, long=True).words() == (0x3017, 0, 0, 0x0190)
    assert pd.write_request(916, 61, 1, array=True).words() == (0x7394, 0x0100, 0, 0x3D)
    assert pd.read_request(947, 9, array=True).words() == (0x63B3, 0x0900, 0, 0)
    assert pd.write_request(5, -1 & 0xFFFF).value == 0xFFFF
    assert [f.words() for f in pd.save_requests()] == [(0x23CB, 0, 0, 0), (0x23CB, 0, 0, 1)]
    assert pd.pzd_map_write("actual", 1, 61).words() == (0x7394, 0x0100, 0, 0x3D)
    assert pd.pzd_map_read("setpoint", 2).words() == (0x6393, 0x0200, 0, 0)


# -- PKW channel --------------------------------------------------------------------------------

class FakeCard:
    """Executes a task once, repeats the answer while the same words stay in the output, answers
    AK 0 to AK 0; `latency` cycles of AK 0 first; `values` is the parameter store."""

    def __init__(self, latency=0):
        self.latency = latency
        self.values = {23: 500, 26: 300}
        self.last = None
        self.resp = pd.IDLE
        self.wait = 0
        self.executed = 0

    def __call__(self, words):
        words = tuple(words)
        if words != self.last:
            self.last = words
            req = pd.PkwFrame.from_words(words)
            if req.ak == 0:
                self.resp = pd.IDLE
            else:
                self.executed += 1
                self.wait = self.latency
                if req.pnu not in self.values:
                    self.resp = pd.PkwFrame(7, req.pnu, req.subindex, 0)
                elif req.ak in (2, 3):
                    self.values[req.pnu] = req.value
                    self.resp = pd.PkwFrame(2, req.pnu, 0, req.value)
                else:
                    self.resp = pd.PkwFrame(2, req.pnu, 0, self.values[req.pnu])
        if self.wait:
            self.wait -= 1
            return pd.IDLE.words()
        return self.resp.words()


def run(ch: pd.PkwChannel, card, now=0.0, limit=50):
    sent = []
    for i in range(limit):
        out = ch.outputs()
        sent.append(out)
        res = ch.feed(card(out), now + 0.01 * (i + 1))
        if res is not None:
            return res, sent
    return None, sent


def test_channel_idle_and_simple_read():
    ch = pd.PkwChannel()
    assert ch.outputs() == (0, 0, 0, 0) and not ch.busy
    card = FakeCard()
    ch.submit(pd.read_request(23), now=0.0)
    res, sent = run(ch, card)
    assert res.ok and res.value == 500 and res.response.ak == 2
    assert sent == [(0x1017, 0, 0, 0)]
    assert ch.outputs() == (0, 0, 0, 0)     # AK 0 when idle again


def test_channel_one_request_at_a_time():
    ch = pd.PkwChannel()
    ch.submit(pd.read_request(23))
    with pytest.raises(pd.PkwBusy):
        ch.submit(pd.read_request(26))
    with pytest.raises(ValueError):
        pd.PkwChannel().submit(pd.IDLE)


def test_channel_waits_through_ak0_and_latency():
    ch = pd.PkwChannel()
    ch.submit(pd.read_request(26))
    res, sent = run(ch, FakeCard(latency=5))
    assert res.ok and res.value == 300 and len(sent) == 6


def test_channel_error_and_texts():
    ch = pd.PkwChannel(error_texts={0: "no such parameter here"})
    ch.submit(pd.read_request(99))
    res, _ = run(ch, FakeCard())
    assert not res.ok and res.error == 0 and res.error_text == "no such parameter here"
    assert "error 0" in res.describe_error()


def test_channel_timeout():
    ch = pd.PkwChannel(timeout=0.1)
    ch.submit(pd.read_request(23), now=0.0)
    res, sent = run(ch, lambda w: (0, 0, 0, 0), limit=100)
    assert res.timed_out and not res.ok and "within 0.1 s" in res.error_text
    assert not ch.busy and len(sent) <= 12


def test_channel_ignores_other_pnu_and_subindex():
    req = pd.read_request(947, 9, array=True)
    assert not pd.matches(req, pd.PkwFrame(4, 947, 1, 5))
    assert not pd.matches(req, pd.PkwFrame(4, 946, 9, 5))
    assert not pd.matches(req, pd.PkwFrame(1, 947, 9, 5))     # wrong response ID for an array read
    assert pd.matches(req, pd.PkwFrame(4, 947, 9, 5))
    assert pd.matches(req, pd.PkwFrame(7, 947, 0, 3))          # errors may not echo IND


def test_identical_requests_need_ak0_in_between():
    card = FakeCard()
    # without the rule a repeated read completes at once on the stale echo, without a new task
    ch = pd.PkwChannel()
    ch.submit(pd.read_request(23))
    run(ch, card)
    card.values[23] = 777
    ch.submit(pd.read_request(23))
    res, sent = run(ch, card)
    assert res.value == 500 and card.executed == 1            # stale!
    # with the rule: AK 0 goes out until the card answers AK 0, then the request again
    card = FakeCard()
    ch = pd.PkwChannel(zero_between_identical=True)
    ch.submit(pd.read_request(23))
    run(ch, card)
    card.values[23] = 777
    ch.submit(pd.read_request(23))
    res, sent = run(ch, card)
    assert res.value == 777 and card.executed == 2
    assert sent[0] == (0, 0, 0, 0) and sent[-1] == (0x1017, 0, 0, 0)


def test_no_zero_needed_after_idle_cycle():
    card = FakeCard()
    ch = pd.PkwChannel(zero_between_identical=True)
    ch.submit(pd.read_request(23))
    run(ch, card)
    ch.feed(card(ch.outputs()), 1.0)          # one idle cycle, the card answered AK 0
    ch.submit(pd.read_request(23))
    assert ch.outputs() == (0x1017, 0, 0, 0)


def test_zero_after_error():
    card = FakeCard()
    ch = pd.PkwChannel(zero_after_error=True)
    ch.submit(pd.read_request(99))
    res, _ = run(ch, card)
    assert res.error == 0
    ch.submit(pd.read_request(23))
    res, sent = run(ch, card)
    assert sent[0] == (0, 0, 0, 0) and res.ok and res.value == 500


# -- configuration from the profile -------------------------------------------------------------

GENERIC = textwrap.dedent("""\
    profile: generic-test
    family: profidrive
    title: Generic PROFIdrive test drive
    identity: {ident: 0x1234}
    layouts:
      ppo1: {cfg: "F3 F1", pkw: true}
    default_layout: ppo1
    max_frequency: {param: FMAX, default_hz: 50.0}
    profidrive:
    %s
    parameters:
      - {code: FMAX, name: Max frequency, pnu: 10, unit: Hz, scale: 0.01, min: 25, max: 400, default: 50}
    """)


def _prof(tmp_path, section: str):
    p = tmp_path / "generic-test.yaml"
    p.write_text(GENERIC % textwrap.indent(section, "  "))
    return load_profile_file(p, check_sections=False)


def test_config_defaults_and_keys(tmp_path):
    prof = _prof(tmp_path, textwrap.dedent("""\
        labels: {control: CTW, status: STW}
        ctw_bits: {11: reverse, 9: null}
        held_ctw_bits: [4, 5, 6]
        pkw: {timeout_s: 1.5, zero_after_error: true, errors: {104: busy}, error_numbers: {stop_only: 11}}
        fault_memory: {pnu: 947, subindexes: [1, 9, 17, 25]}
        device_ids: {0x812C: DF6}"""))
    c = pd.ProfidriveConfig.from_profile(prof)
    assert c.ctw_names[11] == "reverse" and 9 not in c.ctw_names
    assert c.held_ctw_bits == 0x70 and c.pkw_timeout == 1.5 and c.zero_after_error
    assert c.error_text(104) == "busy" and c.error_text(2) == pd.GENERIC_ERRORS[2]
    assert c.error_numbers["stop_only"] == 11
    assert c.fault_positions == ["current", "last", "2nd last", "3rd last"]
    assert c.device_ids == {0x812C: "DF6"}


@pytest.mark.parametrize("section,line,msg", [
    ("bogus: 1", 10, "unknown key 'bogus'"),
    ("held_ctw_bits: [0]", 10, "cannot include bits"),
    ("pkw: {timeout_s: -1}", 10, "timeout_s"),
    ("ramps: {accel: NOPE}", 10, "NOPE is not in parameters"),
    ("fault_memory: {subindexes: [1, 9], positions: [a]}", 10, "one text per subindex"),
    ("ctw_bits: {16: x}", 10, "bit numbers 0..15"),
    ("pkw:\n  error_numbers: {nonsense: 3}", 11, "nonsense"),
])
def test_config_errors_name_file_and_line(tmp_path, section, line, msg):
    prof = _prof(tmp_path, section)
    with pytest.raises(DataFileError) as ei:
        pd.ProfidriveConfig.from_profile(prof)
    assert ei.value.line == line and msg in ei.value.message
    assert str(ei.value).startswith(f"{tmp_path / 'generic-test.yaml'}:{line}:")


def test_resolve_codes():
    prof = load_profile("moeller")
    r = pd.resolve_code(prof, "F002")
    assert (r.pnu, r.subindex, r.array, r.size) == (23, 0, False, 32)
    r = pd.resolve_code(prof, "PNU947[9]")
    assert (r.code, r.pnu, r.subindex, r.array) == ("PNU947", 947, 9, True)
    r = pd.resolve_code(prof, "pnu 0x17")
    assert (r.code, r.pnu) == ("F002", 23)
    r = pd.resolve_code(prof, "PNU1999")
    assert (r.code, r.param) == ("PNU1999", None)
    with pytest.raises(UsageError, match="unknown parameter"):
        pd.resolve_code(prof, "ZZZ9")


@settings(max_examples=50)
@given(st.integers(1, 0x7FF), st.integers(0, 255))
def test_resolve_raw_any(pnu, sub):
    prof = load_profile("moeller")
    r = pd.resolve_code(prof, f"PNU{pnu}[{sub}]")
    assert (r.pnu, r.subindex) == (pnu, sub)
