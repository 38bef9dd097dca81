"""The manual-table defects of issue 17: what the simulated cards answer and how values are shown,
checked against the manuals' tables (spec lines quoted per test)."""

from __future__ import annotations

from pathlib import Path

import pytest

from profidrive_cli.drives import profidrive as pd
from profidrive_cli.drives.profidrive import PkwFrame
from profidrive_cli.drives.profile import load_profile
from profidrive_cli.sim.plant import build_bus


def _station(url: str, address: int):
    bus = build_bus(url)
    model = bus.slaves[address].model
    model.edit_rights = 1
    return model


def _read(model, pnu: int) -> PkwFrame:
    return model.pkw_answer(PkwFrame(1, pnu, 0, 0))


# --- PNU 918 / 963 -------------------------------------------------------------------------------

# moeller-de6-net-dp.md 6.3 (src L716-728, Table 7): "| 0 | 12 Mbit/s |" ... "| 5 | 187.5 kbit/s |"
# ... "| 8 | 19.2 kbit/s |", "| 9 | 9.6 kbit/s |"
# fuji-opc-g1-pdp.md 6 (src L1046-1051, L2700-2706): "| 2 | 19.2 kbit/s |", "| 5 | 187.5 kbit/s |",
# "| 7 | 1.5 Mbit/s |"
@pytest.mark.parametrize("name, baud, code", [
    ("moeller", "19200", 8), ("moeller", "187500", 5), ("moeller", "9600", 9), ("moeller", "1.5M", 3),
    ("fuji-g1", "19200", 2), ("fuji-g1", "187500", 5), ("fuji-pdp3", "1.5M", 7), ("fuji-pdp3", "9600", 1),
])
def test_sim_pnu963_is_the_cards_own_code_for_the_bus_baud_rate(name, baud, code):
    m = _station(f"sim://?stations=9:{name}&baud={baud}", 9)
    r = _read(m, 963)
    assert (r.ak, r.value) == (1, code)


# moeller-de6-net-dp.md 6.1: "| 918 | 0x396 | PROFIBUS-DP slave address | 1..99 | R | Value of the rotary
# switches |"; fuji-opc-g1-pdp.md: "| 918 | 0x396 | - | Node (station) address | 0-125 | R | - |"
@pytest.mark.parametrize("name, address", [("moeller", 6), ("moeller", 42), ("fuji-g1", 3),
                                           ("fuji-pdp3", 17)])
def test_sim_pnu918_is_the_station_address(name, address):
    m = _station(f"sim://?stations={address}:{name}", address)
    r = _read(m, 918)
    assert (r.ak, r.value) == (1, address)


def test_make_model_options_still_pin_address_and_baud_code():
    from profidrive_cli.sim.moeller import make_model
    m = make_model(load_profile("moeller"), address=12, baud_code=4)
    m.on_bus(6, 19200)
    m.edit_rights = 1
    assert (_read(m, 918).value, _read(m, 963).value) == (12, 4)


# --- a word write is acknowledged with AK 1 -------------------------------------------------------

# moeller-de6-net-dp.md 5.3 (src L451-466): "| 2 | Write parameter value (word) | 1 | 7 or 8 | yes |",
# "| 3 | Write parameter value (double word) | 2 | 7 or 8 | yes |"
def test_moeller_sim_answers_a_word_write_with_ak1_even_for_a_4_byte_parameter():
    m = _station("sim://?stations=6:moeller", 6)
    f002 = load_profile("moeller").param("F002")          # 1st acceleration time, 4 octets
    assert f002.extra["bytes"] == 4
    r = m.pkw_answer(PkwFrame(2, f002.pnu, 0, 400))        # 4.00 s, as a word
    assert (r.ak, r.pnu, r.value) == (1, f002.pnu, 400)
    r = m.pkw_answer(PkwFrame(3, f002.pnu, 0, 500))        # the same as a double word
    assert (r.ak, r.value) == (2, 500)
    r = m.pkw_answer(PkwFrame(1, f002.pnu, 0, 0))          # a read answers in the parameter's width
    assert (r.ak, r.value) == (2, 500)


# fuji-opc-g1-pdp.md 5.2 (Table 8.9): "| 1 | Parameter value (word) transferred OK: reply to RC 1 and RC 2 |"
def test_fuji_sim_answers_a_word_write_with_ak1():
    m = _station("sim://?stations=3:fuji-g1", 3)
    f07 = load_profile("fuji-g1").param("F07")
    r = m.pkw_answer(PkwFrame(2, f07.pnu, f07.index, 500))
    assert r.ak == 1
    assert pd.RESPONSE_TEXT[r.ak] == "transfer parameter value (word)"


# --- decode says when a request/response ID is one the card does not use -------------------------

def _pkw(name: str, direction: str, hexwords: str) -> dict:
    from profidrive_cli.drives import decode_area
    return decode_area(load_profile(name), "ppo1", direction, bytes.fromhex(hexwords))["pkw"]


# fuji-opc-g1-pdp.md 5.2 (Table 8.9, src L884-889): requests "| 3-5 | Not used |", "| 8 | Not used |";
# responses "| 2, 3 | Not used |", "| 5 | Not used |"
@pytest.mark.parametrize("direction, ak", [("request", 3), ("request", 4), ("request", 5), ("request", 8),
                                           ("response", 2), ("response", 3), ("response", 5)])
def test_decode_names_fuji_ids_the_card_does_not_use(direction, ak):
    pk = _pkw("fuji-g1", direction, f"{ak:X}104 1A00 0000 0190 0000 0000")
    assert pk["ak_text"].endswith("(not used by this card)")
    assert pk["card_supported"] is False


# Table 8.9: "| 2 | Write parameter value (word) |", "| 4 | Array-element value (word) transferred OK |"
@pytest.mark.parametrize("direction, ak", [("request", 1), ("request", 2), ("request", 6), ("request", 7),
                                           ("request", 9), ("response", 1), ("response", 4),
                                           ("response", 6), ("response", 7)])
def test_decode_keeps_fuji_ids_the_card_uses_plain(direction, ak):
    pk = _pkw("fuji-g1", direction, f"{ak:X}104 1A00 0000 0001 0000 0000")
    assert "by this card" not in pk["ak_text"]
    assert "card_supported" not in pk


# moeller-de6-net-dp.md 5.3 (src L451-466): "| 4 | Read description element | 3 | 7 | **no** |",
# "| 5 | Write description element | 3 | 7 | **no** |", "| 8 | ... (array double word) | 5 | 7 or 8 | **no** |";
# 5.4: "| 3 | Description element transferred | **no** |", "| 5 | ... (array double word) | **no** |"
@pytest.mark.parametrize("direction, ak, generic", [
    ("request", 4, "request description element"), ("request", 5, "change description element"),
    ("request", 8, "change parameter value (array long word)"),
    ("response", 3, "transfer description element"), ("response", 5, "transfer parameter value (array long word)"),
    ("response", 9, "parameter change report (word)")])
def test_decode_names_moeller_ids_the_card_does_not_support(direction, ak, generic):
    pk = _pkw("moeller", direction, f"{ak:X}017 0000 0000 0190 0000 0000")
    assert pk["ak_text"] == f"{generic} (not supported by this card)"


# moeller 5.3: "| 3 | Write parameter value (double word) | 2 | 7 or 8 | yes |"
def test_decode_keeps_moeller_supported_ids_plain():
    pk = _pkw("moeller", "request", "3017 0000 0000 0190 0000 0000")
    assert pk["ak_text"] == "change parameter value (long word)"
    pk = _pkw("moeller", "response", "2017 0000 0000 0190 0000 0000")
    assert pk["ak_text"] == "transfer parameter value (long word)"


# --- every `format:` is handled ------------------------------------------------------------------

def test_every_format_each_shipped_profile_uses_has_a_formatter_for_its_family():
    from profidrive_cli.drives.formats import FORMATS, formatter_for
    from profidrive_cli.drives.profile import all_profiles
    used = set()
    for prof in all_profiles():
        for p in prof.parameters.values():
            fmt = p.extra.get("format")
            if fmt is None:
                continue
            used.add(fmt)
            assert fmt in FORMATS, f"{prof.name} {p.code}: format {fmt!r}"
            assert formatter_for(prof, fmt) is not None, f"{prof.name} {p.code}: no formatter for {fmt!r}"
    assert used <= set(FORMATS)
    assert {"fcode", "alarm", "alarm947", "baud", "bits", "speed", "history", "hex", "code"} <= used


def test_a_profile_with_an_unknown_format_is_refused_with_file_and_line(tmp_path):
    from profidrive_cli.datafile import DataFileError
    from profidrive_cli.drives.profile import load_profile_file
    src = load_profile("yaskawa").path.read_text(encoding="utf-8").splitlines()
    i = next(n for n, line in enumerate(src) if line.lstrip().startswith("- {code:"))
    src[i] = src[i].replace("{code:", "{format: octal, code:", 1)
    f = tmp_path / "bad.yaml"
    f.write_text("\n".join(src) + "\n", encoding="utf-8")
    with pytest.raises(DataFileError) as e:
        load_profile_file(f)
    assert f"bad.yaml:{i + 1}" in str(e.value) and "unknown format 'octal'" in str(e.value)


def _text(name, code, raw):
    from profidrive_cli.drives.formats import display_text
    prof = load_profile(name)
    p = prof.param(code)
    return display_text(prof, p, raw, p.from_raw(raw))


# fuji-opc-g1-pdp.md L603: "M16 (latest) ... give the inverter 'alarm code' (decimal)"; L611-616:
# "| 0 | 0000 | --- | No alarm |", "| 1 | 2301 | OC1 (0c1) | Overcurrent during acceleration |",
# "| 5 | 2330 | EF (ef) | Ground fault |"
@pytest.mark.parametrize("name", ["fuji-g1", "fuji-pdp3"])
def test_fuji_m16_to_m19_show_the_alarm_name(name):
    assert _text(name, "M16", 1).startswith("1 (OC1 ")
    assert _text(name, "M19", 5).startswith("5 (EF ")
    assert _text(name, "M17", 0) == "0 (no alarm)"


# fuji-opc-g1-pdp.md L243: "F26 -> group F = 0x04, number 26 = 0x1A, giving assignment '041A'";
# L240: "| 0x0000 | No assignment (factory default) |"; fuji-opc-pdp3.md L227: "F26 -> 0x041A"
@pytest.mark.parametrize("name", ["fuji-g1", "fuji-pdp3"])
@pytest.mark.parametrize("code", ["o40", "o43", "o48", "o51", "PNU915", "PNU916"])
def test_fuji_pcd_assignments_show_four_hex_digits_and_the_function_code(name, code):
    assert _text(name, code, 0x041A) == "0x041A (F26)"
    assert _text(name, code, 0) == "0x0000 (not assigned)"


# moeller-de6-net-dp.md 6.3 (src L716-728): "| 0 | 12 Mbit/s |", "| 9 | 9.6 kbit/s |";
# fuji-opc-g1-pdp.md L579-591: "| 10 | 12 Mbit/s |" (profile: 12M), "| 1 | 9.6 kbit/s |"
def test_pnu963_shows_each_cards_own_baud_coding():
    assert _text("moeller", "PNU963", 0) == "0 (12 Mbit/s)"
    assert _text("moeller", "PNU963", 9) == "9 (9.6 kbit/s)"
    assert _text("fuji-g1", "PNU963", 10) == "10 (12M)"
    assert _text("fuji-g1", "PNU963", 1) == "1 (9.6k)"


def test_param_get_on_the_sim_shows_alarm_fcode_and_baud_texts():
    import json
    import subprocess
    import sys
    r = subprocess.run([sys.executable, "-m", "profidrive_cli", "param", "get", "3", "M16", "o40", "PNU963",
                        "--json", "--port", "sim://?trip=3:OC1&baud=187500", "--baud", "187500"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    got = {p["code"]: p for p in json.loads(r.stdout)["parameters"]}
    assert got["M16"]["raw"] == 1 and got["M16"]["text"].startswith("1 (OC1 ")
    assert got["o40"]["text"].startswith("0x")
    assert got["PNU963"]["text"] == "5 (187.5k)"          # L588: "| 5 | 187.5 kbit/s |"


# decode shows the same texts (the one formatter)
def test_decode_shows_an_o40_read_response_as_a_function_code():
    from profidrive_cli.drives import decode_area
    prof = load_profile("fuji-g1")
    o40 = prof.param("o40")
    words = f"1{o40.pnu:03X} {o40.index:02X}00 0000 041A 0000 0000"
    pk = decode_area(prof, "ppo1", "response", bytes.fromhex(words))["pkw"]
    assert pk["value_text"] == "0x041A (F26)"


# moeller-de6-net-dp.md 6.4 (src L730-759, Table 8): "| 0 | No fault |", "| 1 | Overcurrent (inverter) |"
def test_moeller_pnu947_shows_the_fault_name():
    assert _text("moeller", "PNU947", 1).startswith("1 (E01 ")
    assert _text("moeller", "PNU947", 0) == "0 (no fault)"


# --- the code lists against the manuals' tables ----------------------------------------------------

SPEC = Path("/work/shared/spec")


def _spec_rows(name: str, header: str) -> list[list[str]]:
    """The rows of the markdown table right after the line `header` in a spec file."""
    lines = (SPEC / name).read_text(encoding="utf-8").splitlines()
    i = lines.index(header) + 2
    rows = []
    while i < len(lines) and lines[i].startswith("|"):
        rows.append([c.strip() for c in lines[i].strip("|").split("|")])
        i += 1
    return rows


@pytest.mark.skipif(not SPEC.is_dir(), reason="the reference specs are not on this machine")
@pytest.mark.parametrize("name, spec, header, dec_col, hex_col, code_col", [
    ("fuji-g1", "fuji-opc-g1-pdp.md",
     "| M16-M19 code (dec) | PNU947 code (hex) | Mnemonic (source form) | Description |", 0, 1, 2),
    ("fuji-pdp3", "fuji-opc-pdp3.md", "| PNU947 (hex) | M16-M19 (dec) | Keypad | Meaning |", 1, 0, 2),
])
def test_fuji_alarm_table_matches_the_manual_row_by_row(name, spec, header, dec_col, hex_col, code_col):
    from profidrive_cli.drives.fuji import fuji_config
    prof = load_profile(name)
    mcodes = fuji_config(prof).mcodes
    rows = _spec_rows(spec, header)
    assert len(rows) > 30
    for r in rows:
        if not r[dec_col].isdigit():        # a PNU947 code with no M-code (pdp3: "| FFFF | — (none) | OH6 |")
            a = prof.alarm_by_code(r[code_col])
            assert a is not None and a.number == int(r[hex_col], 16) and mcodes.get(a.code) is None
            continue
        dec, num = int(r[dec_col]), int(r[hex_col], 16)
        code = r[code_col].replace("*", "").split(" (")[0].strip()
        if dec == 0:
            continue
        a = prof.alarm_by_code(code)
        assert a is not None, f"{name}: {code} missing"
        assert (a.number, mcodes.get(a.code)) == (num, dec), f"{name}: {code}"


# moeller-de6-net-dp.md 6.3 and fuji-opc-g1-pdp.md L579-591: the baud-rate code tables
@pytest.mark.skipif(not SPEC.is_dir(), reason="the reference specs are not on this machine")
def test_baud_code_tables_match_the_manuals():
    from profidrive_cli.drives.profidrive.pnu import baud_code_for
    from profidrive_cli.fdl.timing import parse_baud
    moeller = {int(r[0]): r[1] for r in _spec_rows("moeller-de6-net-dp.md", "| Value | Baud rate |")}
    codes = pd.config(load_profile("moeller")).baud_codes
    assert codes == moeller
    fuji = {int(r[0]): r[1] for r in _spec_rows("fuji-opc-g1-pdp.md", "| Value | Rate |")}
    fcodes = pd.config(load_profile("fuji-g1")).baud_codes
    assert set(fuji) == set(fcodes) == set(range(11))
    for code, text in fuji.items():
        if code:                                     # "| 5 | 187.5 kbit/s |" -> 187500 -> code 5
            num, unit = text.split()[:2]
            rate = parse_baud(num + ("k" if unit.startswith("k") else "M"))
            assert baud_code_for(fcodes, rate) == code, text


# the real byte path: `pdrive sim --pty --baud 187500` and pdrive on the other end; moeller 6.3 (src L716-728):
# "| 5 | 187.5 kbit/s |"; fuji-opc-g1-pdp.md L588: "| 5 | 187.5 kbit/s |"; PNU 918 = the station address
def test_pnu918_963_and_texts_over_a_pty():
    import json
    import signal
    import subprocess
    from conftest import pdrive_cmd
    sim = subprocess.Popen(pdrive_cmd() + ["sim", "--json", "--pty", "--baud", "187500"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        port = json.loads(sim.stdout.readline())["port"]
        got = {}
        for addr in (3, 6):
            r = subprocess.run(pdrive_cmd() + ["param", "get", str(addr), "PNU918", "PNU963", "--json",
                                               "--port", port, "--baud", "187500"],
                               capture_output=True, text=True, timeout=120)
            assert r.returncode == 0, r.stderr
            got[addr] = {p["code"]: p for p in json.loads(r.stdout)["parameters"]}
        assert got[3]["PNU918"]["value"] == 3 and got[6]["PNU918"]["value"] == 6
        assert got[3]["PNU963"]["text"] == "5 (187.5k)"
        assert got[6]["PNU963"]["text"] == "5 (187.5 kbit/s)"
    finally:
        sim.send_signal(signal.SIGINT)
        try:
            sim.wait(timeout=10)
        except subprocess.TimeoutExpired:
            sim.kill()
