"""Fuji o40-o43 / o48-o51 (PCD assignment words) typed as the manual writes them, and `param set`
answering in the same text as `param get`.

G1 manual (/work/shared/seeds/001_02ee17c3305f1f71.txt) L2440-2453: "F => Function code group 04hex
Example for F26", "26 Function code number 1Ahex", ... "041A"; spec fuji-opc-g1-pdp.md L243: "F26 -> group
F = 0x04, number 26 = 0x1A, giving assignment "041A"". Group codes from the same table (profile
function_codes.groups): F = 0x04, W = 0x10 (L2448 "W 16 10hex"), so 0x1050 = W80 and 1050 decimal =
0x041A = F26.
"""

import pytest

from profidrive_cli import UsageError
from profidrive_cli.drives.formats import value_from_text
from profidrive_cli.drives.profile import load_profile
from test_run_safety import pdrive

PDP3 = load_profile("fuji-pdp3")
O40 = PDP3.param("o40")
PORT = "sim://?stations=3:fuji-pdp3"


@pytest.mark.parametrize("text, word", [
    ("041A", 0x041A),          # the manual's own notation
    ("0x041A", 0x041A),
    ("0X041a", 0x041A),
    ("F26", 0x041A),
    ("f26", 0x041A),
    ("0", 0),                  # not assigned
    ("0410", 0x0410),          # F16 (decimal 410 = 0x019A names no group: no doubt)
    ("y98", 0x0F62),           # group y = 0x0F, 98 = 0x62
])
def test_fcode_text_accepted(text, word):
    assert value_from_text(PDP3, O40, text) == word


@pytest.mark.parametrize("text, words", [
    ("F2G", ["expected a function code (F26)", "041A or 0x041A", "got 'F2G'", "closest codes: F26"]),
    ("041G", ["expected a function code", "got '041G'"]),
    ("9999", ["0x9999 names no function code", "041A or 0x041A"]),
    ("1050", ["reads two ways", "0x1050 (W80)", "0x041A (F26)"]),
])
def test_bad_fcode_text_refused_with_the_forms(text, words):
    with pytest.raises(UsageError) as e:
        value_from_text(PDP3, O40, text)
    for w in words:
        assert w in str(e.value), str(e.value)


def test_plain_parameters_have_no_notation():
    assert value_from_text(PDP3, PDP3.param("F07"), "4.5") is None


def _answer(r):
    return r.stdout.strip().splitlines()[0]


def test_cli_set_answers_like_get_and_takes_the_manual_notation():
    for text in ("0x041A", "041A", "F26"):
        r = pdrive("param", "set", "3", "o40", text, "--yes", "--port", PORT)
        assert r.returncode == 0, r.stderr
        line = _answer(r)
        assert line.startswith("o40 (") and " = 0x041A (F26) (was 0x0000 (not assigned))" in line, line
        assert "1050" not in line


def test_cli_get_shows_the_same_text():
    r = pdrive("param", "get", "3", "o40", "--json", "--port", PORT)
    assert r.returncode == 0, r.stderr
    assert '"0x0000 (not assigned)"' in r.stdout


@pytest.mark.parametrize("text", ["F2G", "1050", "9999"])
def test_cli_bad_text_exit_2_one_line(text):
    r = pdrive("param", "set", "3", "o40", text, "--yes", "--port", PORT)
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pdrive: o40: ") and "Traceback" not in r.stderr
    assert r.stdout.strip() == ""
