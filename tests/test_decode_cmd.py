"""`pdrive decode` (cli/decode_cmd.py) on the Moeller spec's test vectors, through click."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from profidrive_cli import UsageError
from profidrive_cli.cli.decode_cmd import decode_cmd


def run(*args):
    return CliRunner().invoke(decode_cmd, list(args))


def ok(*args) -> str:
    r = run(*args)
    assert r.exit_code == 0, (r.output, r.exception)
    return r.output


def test_done_when_request():
    out = ok("moeller", "--ppo", "1", "--request", "3017", "0000", "0000", "0190", "047F", "2000")
    assert ("summary: change parameter value (long word), PNU 23 = F002 1st Acceleration time 1 "
            "= 4.00 s; operate; reference 50 %") in out
    assert "PKE 0x3017: AK 3 change parameter value (long word)" in out
    assert "PWE 0x00000190 = 400 -> 4.00 s" in out
    assert "STW (control word) 0x047F: ON, no OFF2, no OFF3, enable operation" in out
    assert "HSW (reference) 0x2000: 50 % = 25.00 Hz" in out


def test_done_when_response():
    out = ok("moeller", "--ppo", "1", "--response", "2017 0000 0000 0190 0337 2000")
    assert ("summary: transfer parameter value (long word), PNU 23 = F002 1st Acceleration time 1 "
            "= 4.00 s; S4 operation; actual 50 %") in out
    assert "ZSW (status word) 0x0337: ready to switch on, ready to operate, operation enabled" in out
    assert "HIW (actual value) 0x2000: 50 % = 25.00 Hz" in out


@pytest.mark.parametrize("hexes", [
    ["30 17 00 00 00 00 01 90 04 06 20 00"],
    ["301700000000019004062000"],
    ["0x3017", "0x0000", "0x0000", "0x0190", "0x0406", "0x2000"],
    ["30:17:00:00:00:00:01:90:04:06:20:00"],
])
def test_hex_forms(hexes):
    out = ok("moeller", "--ppo", "1", "--request", *hexes)
    assert "0x0406" in out and "ready (OFF1)" in out and "F002" in out


def test_tv1a_response_text():
    out = ok("moeller", "--ppo", "1", "--response", "20 17 00 00 00 00 01 90 03 31 20 00")
    assert "ZSW (status word) 0x0331: ready to switch on, no OFF2, no OFF3, at setpoint, " \
           "control requested -> S2 ready for switching on" in out


def test_tv2a_request_and_response():
    out = ok("moeller", "--ppo", "2", "--request",
             "73 94 01 00 00 00 00 3D 04 06 20 00 00 00 00 00 00 00 00 00")
    assert "AK 7 change parameter value (array word)" in out
    assert "PNU 916 PZD assignment, actual-value telegram" in out
    assert "IND 0x0100 (subindex 1)" in out and "61 (A038 Jogging frequency)" in out
    out = ok("moeller", "--ppo", "2", "--response",
             "43 94 01 00 00 00 00 3D 03 31 20 00 01 F4 00 00 00 00 00 00")
    assert "AK 4 transfer parameter value (array word)" in out and "PZD3 0x01F4 (500)" in out


def test_tv2b():
    out = ok("moeller", "--ppo", "2", "--request",
             "73 94 01 00 00 00 00 3D 04 7F 20 00 00 00 00 00 00 00 00 00")
    assert "-> operate" in out
    out = ok("moeller", "--ppo", "2", "--response",
             "43 94 01 00 00 00 00 3D 03 37 20 00 01 F4 00 00 00 00 00 00")
    assert "S4 operation" in out


def test_tv3_json():
    out = ok("moeller", "--ppo", "2", "--request", "--json",
             "73 93 01 00 00 00 00 3E 04 7F 20 00 00 4B 00 00 00 00 00 00")
    d = json.loads(out)
    assert (d["pkw"]["ak"], d["pkw"]["pnu"], d["pkw"]["subindex"], d["pkw"]["pwe"]) == (7, 915, 1, 62)
    assert d["pkw"]["maps"]["code"] == "A004"
    assert d["control_word"]["word"] == 0x047F and d["reference"]["reference_percent"] == 50.0
    assert d["pzd"][0]["raw"] == 75
    out = ok("moeller", "--ppo", "2", "--response", "--json",
             "43 93 01 00 00 00 00 3E 03 37 20 00 01 F4 00 00 00 00 00 00")
    d = json.loads(out)
    assert d["pkw"]["ak"] == 4 and d["status_word"]["state"] == "S4 operation"
    assert d["actual"]["actual_hz"] == 25.0 and d["pzd"][0]["raw"] == 500


def test_json_done_when():
    d = json.loads(ok("moeller", "--ppo", "1", "--request", "--json", "3017 0000 0000 0190 047F 2000"))
    assert d["pkw"]["code"] == "F002" and d["pkw"]["value"] == 4.0 and d["pkw"]["unit"] == "s"
    assert d["control_word"]["command"] == "operate"
    assert d["control_word"]["bus_controls"] == "frequency and commands"
    assert d["reference"]["reference_percent"] == 50.0 and d["reference"]["reference_hz"] == 25.0


def test_error_response_and_fault_memory():
    out = ok("moeller", "--ppo", "1", "--response", "70 BD 00 00 00 00 00 11 03 37 20 00")
    assert "task cannot be executed" in out and "error 17" in out and "A001" in out
    out = ok("moeller", "--ppo", "1", "--response", "43 B3 09 00 00 00 00 05 02 40 00 00")
    assert "E05 Motor overload" in out and "S1 switching on inhibited" in out


def test_ppo3_and_format():
    out = ok("moeller", "--ppo", "3", "--request", "047F 2000")
    assert "PKE" not in out and "-> operate" in out
    out = ok("moeller", "--format", "ppo3", "--response", "0337 C000")
    assert "-100 % = -50.00 Hz" in out
    out = ok("moeller", "--request", "04 06 20 00 00 00 00 00 00 00 00 00")   # default layout ppo1
    assert "PPO1 request" in out


@pytest.mark.parametrize("args,msg", [
    (["moeller", "--ppo", "1", "3017"], "--request"),
    (["moeller", "--ppo", "1", "--request", "30 17 00"], "12 octets, got 3"),
    (["moeller", "--ppo", "1", "--request", "zz"], "bad hex"),
    (["moeller", "--ppo", "1", "--request", "301"], "odd number"),
    (["moeller", "--ppo", "7", "--request", "00"], "has no PPO7"),
    (["moeller", "--format", "extended1", "--request", "00"], "no layout 'extended1'"),
    (["moeller", "--ppo", "1", "--format", "ppo1", "--request", "00"], "not both"),
    (["nosuchdrive", "--ppo", "1", "--request", "00"], "unknown profile"),
])
def test_usage_errors(args, msg):
    r = run(*args)
    assert r.exit_code != 0 and isinstance(r.exception, UsageError)
    assert msg in str(r.exception) and "\n" not in str(r.exception)


def test_exit_code_2_through_main(capsys):
    from profidrive_cli.cli.main import main
    with pytest.raises(SystemExit) as ei:
        main(["decode", "moeller", "--ppo", "1", "--request", "30 17"])
    assert ei.value.code == 2
    assert "12 octets, got 2" in capsys.readouterr().err
    with pytest.raises(SystemExit) as ei:
        main(["decode", "moeller", "--ppo", "1", "--request", "3017 0000 0000 0190 047F 2000"])
    assert ei.value.code == 0
    assert "reference 50 %" in capsys.readouterr().out


def test_request_and_response_together_are_refused():
    # one area is either the master's output or the drive's input: both flags cannot be meant
    r = run("moeller", "--ppo", "1", "--request", "--response", "3017 0000 0000 0190 047F 2000")
    assert r.exit_code != 0 and isinstance(r.exception, UsageError)
    assert "either --request or --response, not both" in str(r.exception)
    r = run("moeller", "--ppo", "1", "--response", "--request", "3017 0000 0000 0190 047F 2000")
    assert isinstance(r.exception, UsageError) and r.output == ""
