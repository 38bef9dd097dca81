"""Jog: the cards' own jog functions (Toyo PBUS66-Z CTW bits 8/9 and run-command bit 1, Moeller
DE6-NET-DP CTW bit 8 "inching 1" at A038), refusals where a card has none (Fuji, Yaskawa, Toyo with the
PLC), `pdrive jog` on sim:// and through `pdrive sim --pty` (duration, SIGTERM, key held on a terminal),
and the checklist step `jog`. Expected words and speeds come from the specs / manuals cited per test."""

import json
import os
import select
import signal
import subprocess
import time

import pytest

from conftest import pdrive_cmd, pty_sim_process, read_until_turning
from profidrive_cli.checklist.spec import ChecklistError, load_checklist_text
from profidrive_cli.drives import make_drive
from profidrive_cli.drives.base import DriveError
from profidrive_cli.drives.jog import jog_refusal
from profidrive_cli.drives.profile import load_profile
from profidrive_cli.sim import moeller, toyo
from profidrive_cli.sim.direct import DirectChannel


def _direct(name, mod, layout, **opts):
    prof = load_profile(name)
    model = mod.make_model(prof, **opts)
    ch = DirectChannel(model, prof.layouts[layout].cfg)
    d = make_drive(ch, prof, layout)
    d.cycle()
    return prof, model, ch, d


def _cycle_for(d, seconds):
    end = d.channel.now() + seconds
    st = d.cycle()
    while d.channel.now() < end:
        st = d.cycle()
    return st


# ---------------------------------------------------------------------------------------------
# the codecs and the simulated cards
# ---------------------------------------------------------------------------------------------

def test_moeller_jog_runs_at_a038_with_the_manuals_control_word():
    # spec moeller 3.1 bit 8 "Inching 1 ON: accelerate to ... A038 (PNU 61). The state must be
    # 'Enable operation'" (manual L542-543); spec 3.5 "Jog (inching 1 -> A038) | 0x057F"
    prof, model, ch, d = _direct("moeller", moeller, "ppo1")
    assert d.write_param("A038", 7.5).value == 7.5          # 0..9.99 Hz, x100 (manual L831)
    d.jog(True)
    st = _cycle_for(d, 3.0)
    assert d.last_ctw == 0x057F
    assert st.speed_hz == pytest.approx(7.5, abs=0.01)
    d.jog(False)                                             # bit 8 = 0: brakes, back to "Enable operation"
    st = _cycle_for(d, 3.0)
    assert d.last_ctw == 0x047F and st.speed_hz == 0.0 and st.state.startswith("S4")
    st = d.stop("normal")
    assert st.stopped and d.last_ctw & 0x0F00 == 0x0400      # no bit 8, no bit 11 after the stop


def test_moeller_reverse_jog_is_bit_11():
    # spec moeller 3.1 bit 11 "1: reverse" (direction = sign of HSW XOR bit 11): 0x057F | 0x0800
    prof, model, ch, d = _direct("moeller", moeller, "ppo1")
    d.jog(True, reverse=True)
    st = _cycle_for(d, 3.0)
    assert d.last_ctw == 0x0D7F
    assert st.speed_hz == pytest.approx(-5.0, abs=0.01)      # sim A038 = 5.00 Hz (manual example raw 500)
    st = d.stop("normal")
    assert st.stopped and not d.last_ctw & 0x0900


def test_toyo_mode0_jog_words_and_speed():
    # spec toyo 3.1 bits 8/9 "valid only when bits 4, 5 and 6 are all 0" (manual L2725-2731, L2919);
    # spec D11: forward 0x0507, reverse 0x0607. The simulated jog speed is 10 % of A-00 = 60 Hz.
    for reverse, word, hz in ((False, 0x0507, 6.0), (True, 0x0607, -6.0)):
        prof, model, ch, d = _direct("toyo", toyo, "ppo1")
        d.jog(True, reverse=reverse)
        st = _cycle_for(d, 3.0)
        assert d.last_ctw == word
        assert st.speed_hz == pytest.approx(hz, abs=0.01) and st.running
        t0 = ch.now()
        st = d.stop("normal")
        assert st.stopped and not d.last_ctw & 0x0300
        # OFF1 after a jog ramps (sim decel 5 s for 60 Hz: 6 Hz -> 0 in 0.5 s), no instant stop
        assert ch.now() - t0 >= 0.45


def test_toyo_mode1_jog_is_run_command_bit_1():
    # spec toyo 3.4 Table 3.7: bit 1 jog command, bit 2 reverse (manual L3048); status flag bit 2 "jog running"
    prof, model, ch, d = _direct("toyo", toyo, "toyo")
    d.jog(True, reverse=True)
    st = _cycle_for(d, 3.0)
    assert d.run_cmd & 0x7 == 0x6
    assert st.state == "jog" and st.flags["jog running"]
    assert abs(st.speed_hz) == pytest.approx(6.0, abs=0.01)     # 10 % of A-00 = 60 Hz
    d.jog(False)
    st = d.stop("normal")
    assert st.stopped and d.run_cmd & 0x3 == 0


@pytest.mark.parametrize("name,layout,words", [
    ("fuji-g1", "ppo1", "CTW bits 8 and 9 are not used by this card"),
    ("fuji-pdp3", "ppo4", "CTW bits 8 and 9 are not used by this card"),
    ("yaskawa", "extended1", "SI-P1 run command word has no jog bit"),
    ("toyo", "toyo_plch", "PLC contact I00021"),
])
def test_cards_without_jog_are_refused_with_the_reason(name, layout, words):
    prof = load_profile(name)
    why = jog_refusal(prof, layout)
    assert why is not None and words in why and why.startswith(prof.name)


def test_jogging_cards_are_not_refused():
    for name in ("toyo", "moeller"):
        prof = load_profile(name)
        for layout in prof.layouts:
            if layout != "toyo_plch":
                assert jog_refusal(prof, layout) is None, (name, layout)


def test_a_drive_without_jog_raises_instead_of_sending():
    from profidrive_cli.sim.plant import make_model
    prof = load_profile("fuji-g1")
    ch = DirectChannel(make_model(prof), prof.layouts["ppo1"].cfg)
    d = make_drive(ch, prof, "ppo1")
    with pytest.raises(DriveError, match="no jog over PROFIBUS"):
        d.jog(True)
    assert ch.cycles == 0


# ---------------------------------------------------------------------------------------------
# pdrive jog on sim://
# ---------------------------------------------------------------------------------------------

def pdrive(*args, timeout=60):
    return subprocess.run(pdrive_cmd() + list(args), capture_output=True, text=True, timeout=timeout,
                          stdin=subprocess.DEVNULL)


def _events(stdout):
    return [json.loads(line) for line in stdout.strip().splitlines()]


@pytest.mark.parametrize("address,args,hz,speed", [
    (6, [], 5.0, {"code": "A038", "value": 5.0, "unit": "Hz"}),
    (6, ["--reverse"], -5.0, {"code": "A038", "value": 5.0, "unit": "Hz"}),
    (5, ["--reverse"], -6.0, None),
])
def test_jog_on_sim_reaches_the_jog_speed_and_ends_stopped(address, args, hz, speed):
    r = pdrive("jog", str(address), "--port", "sim://", "--duration", "1.5", "--json", *args)
    assert r.returncode == 0, r.stderr
    ev = _events(r.stdout)
    assert ev[0]["event"] == "start" and ev[0]["jog_speed"] == speed
    end = ev[-1]
    assert end["event"] == "end" and end["reason"] == "duration 1.5 s reached"
    assert end["peak_hz"] == pytest.approx(hz, abs=0.02)
    assert end["stopped"] and end["stop"]["how"] == "normal" and not end["fault"]


def test_jog_is_paced_like_run_not_by_the_cpu():
    # `run --help`: the Data_Exchange rate defaults to "the fastest the bus allows, at most 100/s"
    # (session/cycle.py CAP_REAL_HZ); at 1.5 Mbit/s on the virtual-time bus the wire allows ~2,900
    # exchanges/s (the start event's wire_hz), so the cap decides: 100/s. Unpaced, a jog ran every
    # exchange the wire allows (4,422 over 1.5 s here).
    port, baud = "sim://?timing=virtual&baud=1500000", "1500000"
    r = pdrive("jog", "6", "--port", port, "--baud", baud, "--duration", "1")
    assert r.returncode == 0, r.stderr
    assert "cycle 100.0 Hz (bus limit" in r.stdout + r.stderr, r.stdout + r.stderr
    r = pdrive("jog", "6", "--port", port, "--baud", baud, "--duration", "1", "--json")
    assert r.returncode == 0, r.stderr
    ev = _events(r.stdout)
    start, end = ev[0], ev[-1]
    assert start["cycle_hz_target"] == 100.0 and start["wire_hz"] > 1000
    # every exchange lies between the session's start and its last event, on the bus's own clock
    elapsed = max(e["t_s"] for e in ev if "t_s" in e)
    assert elapsed >= 1.0
    assert end["cycles"] <= elapsed * 100.0 * 1.2 + 20, (end["cycles"], elapsed)


@pytest.mark.parametrize("address", [3, 4, 7])
def test_jog_refused_on_cards_without_jog(address):
    r = pdrive("jog", str(address), "--port", "sim://", "--duration", "1")
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and ("no jog over PROFIBUS" in lines[0] or "no jog bit" in lines[0]), r.stderr
    assert r.stdout == ""


def test_jog_without_a_terminal_needs_a_duration():
    r = pdrive("jog", "6", "--port", "sim://")
    assert r.returncode == 2 and "give --duration S" in r.stderr and "Traceback" not in r.stderr


# ---------------------------------------------------------------------------------------------
# through a real serial path: pdrive sim --pty
# ---------------------------------------------------------------------------------------------

#: the jogs over the pty are not about the watchdog: with 5 s (instead of 500 ms) a master stalled at
#: load (or stopped 0.8 s with SIGSTOP) does not trip the drive on comm loss (E70) and fail a test of
#: the jog; a fault that happens all the same is cleared before the next test (conftest.py)
LONG_WD = ("--watchdog", "5000")


@pytest.fixture(scope="module")
def pty_sim():
    with pty_sim_process() as port:
        yield port


def _status(port, address):
    r = pdrive("status", str(address), "--port", port, "--json")
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def test_jog_through_a_pty_ends_stopped_after_the_duration(pty_sim):
    r = pdrive("jog", "6", "--port", pty_sim, "--duration", "1.5", "--yes", "--json", *LONG_WD)
    assert r.returncode == 0, r.stderr
    end = _events(r.stdout)[-1]
    assert end["peak_hz"] == pytest.approx(5.0, abs=0.02) and end["stopped"]
    st = _status(pty_sim, 6)
    assert st["stopped"] and not st["running"] and not st["fault"], st


def test_jog_on_a_real_port_asks_and_refusal_comes_first(pty_sim):
    r = pdrive("jog", "6", "--port", pty_sim, "--duration", "1")
    assert r.returncode == 2 and "add --yes" in r.stderr
    r = pdrive("jog", "3", "--port", pty_sim, "--duration", "1")        # Fuji: the reason, not the question
    assert r.returncode == 2 and "no jog over PROFIBUS" in r.stderr and "--yes" not in r.stderr


@pytest.mark.parametrize("address", [5, 6])
def test_sigterm_during_jog_through_a_pty_leaves_the_drive_stopped(pty_sim, address):
    p = subprocess.Popen(pdrive_cmd() + ["jog", str(address), "--port", pty_sim, "--duration", "60", "--yes",
                                         "--json", *LONG_WD], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         stdin=subprocess.DEVNULL, text=True)
    try:
        read_until_turning(p, phase="jogging", deadline_s=30)
        p.send_signal(signal.SIGTERM)
        out, err = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 143, err
    end = json.loads(out.strip().splitlines()[-1])
    assert end["event"] == "end" and end["reason"] == "SIGTERM"
    assert end["stop"]["how"] == "normal" and end["stopped"]
    assert "Traceback" not in err
    st = _status(pty_sim, address)
    assert st["stopped"] and not st["running"] and not st["fault"], st


# ---------------------------------------------------------------------------------------------
# a key held on a terminal: deadman
# ---------------------------------------------------------------------------------------------

def test_held_key_jogs_and_release_stops():
    mfd, sfd = os.openpty()
    p = subprocess.Popen(pdrive_cmd() + ["jog", "6", "--port", "sim://"],
                         stdin=sfd, stdout=sfd, stderr=sfd, env={**os.environ, "COLUMNS": "120"})
    os.close(sfd)
    buf = b""

    def read_for(seconds, send=None, every=0.05):
        nonlocal buf
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            if send:
                os.write(mfd, send)
            r, _, _ = select.select([mfd], [], [], every)
            if r:
                try:
                    buf += os.read(mfd, 65536)
                except OSError:
                    return
    try:
        end = time.monotonic() + 20
        while b"hold space" not in buf and time.monotonic() < end:
            read_for(0.2)
        read_for(2.0, send=b" ")                  # a held key: the terminal repeats it
        held = buf
        read_for(3.0)                             # released: no more keys
        released = buf[len(held):]
        os.write(mfd, b"q")
        end = time.monotonic() + 30
        while p.poll() is None and time.monotonic() < end:
            read_for(0.2)
        read_for(0.2)
    finally:
        if p.poll() is None:
            p.kill()
        os.close(mfd)
    text = buf.decode(errors="replace")
    assert p.returncode == 0, text[-2000:]
    assert "5.00 Hz" in held.decode(errors="replace")           # A038 reached while held
    assert "key released" in released.decode(errors="replace")
    assert "q pressed" in text


# ---------------------------------------------------------------------------------------------
# the checklist step
# ---------------------------------------------------------------------------------------------

HEAD = """\
name: t
stations:
  - {name: f, address: 3, profile: fuji-g1}
  - {name: y, address: 7, profile: yaskawa}
  - {name: m, address: 6, profile: moeller}
steps:
"""


def test_checklist_validate_refuses_jog_where_the_card_has_none():
    with pytest.raises(ChecklistError) as ei:
        load_checklist_text(HEAD + "  - jog: 1\n", "t.yaml")
    errs = [str(e) for e in ei.value.errors]
    assert len(errs) == 2
    # the capability refusal's words (drives/capabilities.py), the same as `pdrive jog` prints
    assert errs[0].startswith("t.yaml:7: step 1 (jog): fuji-opc-g1-pdp (layout ppo1) cannot jog: "
                              "CTW bits 8 and 9 are not used")
    assert errs[1].startswith("t.yaml:7: step 1 (jog): yaskawa-si-p1 (layout extended1) cannot jog: "
                              "the SI-P1 run command word has no jog bit")


def test_checklist_validate_refuses_jog_while_running():
    text = HEAD + "  - run: {hz: 10}\n    stations: [m]\n  - jog: 1\n    stations: [m]\n"
    with pytest.raises(ChecklistError) as ei:
        load_checklist_text(text, "t.yaml")
    assert [str(e) for e in ei.value.errors] == [
        "t.yaml:9: step 2 (jog): the drive is left running by an earlier step; add a stop step first "
        "(a jog starts from standstill)"]


def test_checklist_jog_runs_on_sim(tmp_path):
    f = tmp_path / "j.yaml"
    f.write_text("name: j\nstations:\n  - {name: m, address: 6, profile: moeller}\n"
                 "  - {name: t, address: 5, profile: toyo}\nsteps:\n"
                 "  - jog: {duration: 2, hz: 5, tolerance: 0.05}\n    stations: [m]\n"
                 "  - jog: {duration: 2, direction: reverse, hz: 6, tolerance: 0.05}\n    stations: [t]\n"
                 "  - jog: {duration: 1, hz: 9}\n    stations: [m]\n    on_fail: continue\n")
    r = pdrive("checklist", "run", str(f), "--port", "sim://", "--json")
    assert r.returncode == 1, r.stderr
    doc = json.loads(r.stdout)
    flat = [s for st in doc["stations"] for s in st["steps"]]          # station m (steps 1, 3), then t (2)
    assert [(s["index"], s["status"]) for s in flat] == [(1, "passed"), (3, "failed"), (2, "passed")], flat
    assert flat[0]["measured"]["peak_hz"] == pytest.approx(5.0, abs=0.02)        # A038 = 5.00 Hz
    assert "did not reach 9 Hz" in flat[1]["message"] and flat[1]["measured"]["stopped"]
    assert flat[2]["measured"]["peak_hz"] == pytest.approx(-6.0, abs=0.02)       # 10 % of 60 Hz, reverse
