"""Issue 28, a line of drives: session/fleet.py (the matrix, the odd values, the golden file) and
`pdrive param fleet dump / diff` on the in-process simulated bus.

Expected values by hand: five stations of one profile, four holding F07 = 6.0 s (the Fuji factory
value, tests/test_drive_cmds.py WRITABLE) and one 5.0 s (the sim URL's set=9:F07=5): the majority is
6.0 (4 of 5 > half), station 9's value is the odd one. 2 against 2 is no strict majority.
"""

import json

import pytest

from conftest import run_main
from profidrive_cli import UsageError
from profidrive_cli.datafile import DataFileError
from profidrive_cli.session.fleet import StationSettings, compare, load_golden, parse_stations

FIVE = "sim://?stations=3:fuji-g1,8:fuji-g1,9:fuji-g1,10:fuji-g1,11:fuji-g1&set=9:F07=5"


def st(a, **values):
    return StationSettings(a, "fuji-opc-g1-pdp", values)


def test_parse_stations():
    assert parse_stations("3-7,9") == [3, 4, 5, 6, 7, 9]
    assert parse_stations("12") == [12]
    for bad, words in (("3-x", "'3-x' is not an address"), ("7-3", "7-3 is not a range"),
                       ("120-130", "not a range of bus addresses"), ("3,3", "station 3 given twice")):
        with pytest.raises(UsageError, match=words):
            parse_stations(bad)


def test_the_odd_value_is_the_one_against_the_majority():
    r = compare([st(3, F07=6.0, F08=6.0), st(8, F07=6.0, F08=6.0), st(9, F07=5.0, F08=6.0),
                 st(10, F07=6.0, F08=6.0), st(11, F07=6.0, F08=6.0)])
    assert r.odd == [(9, "F07")]
    assert r.majority["fuji-opc-g1-pdp"] == {"F07": 6.0, "F08": 6.0}
    assert r.split == [] and r.violations == []
    # within half a step (F07 scale 0.1 s: 6.04 is 6.0 on the drive) is the same value
    assert compare([st(3, F07=6.0), st(4, F07=6.04), st(5, F07=6.0)]).odd == []


def test_no_strict_majority_is_split_not_odd():
    r = compare([st(3, F07=6.0), st(4, F07=5.0), st(5, F07=6.0), st(6, F07=5.0)])
    assert r.odd == [] and r.split == [("fuji-opc-g1-pdp", "F07")]


def test_golden_file_with_exceptions(tmp_path):
    g = tmp_path / "golden.yaml"
    g.write_text("pdrive_golden: 1\nprofile: fuji-g1\nparameters:\n  F07: 6.0\n  F08: {value: 6.0}\n"
                 "except:\n  9: [F07]\n")
    gold = load_golden(g)
    sets = [st(3, F07=6.0, F08=6.0), st(9, F07=5.0, F08=6.0), st(10, F07=6.0)]
    r = compare(sets, gold)
    assert [(v.station, v.code, v.why) for v in r.violations] == [(10, "F08", "missing")]
    assert r.cells["F07"][9].excepted and not r.cells["F07"][9].violation
    g.write_text("parameters:\n  F07: 6.0\n")
    r = compare(sets, load_golden(g))
    assert [(v.station, v.code, v.value, v.golden) for v in r.violations] == [(9, "F07", 5.0, 6.0)]


@pytest.mark.parametrize("text, where", [
    ("parameters:\n  F07: x\n", ":2: F07: the value must be a number"),
    ("parameters:\n  F07: .inf\n", ":2: F07: the value must be a number, got inf"),
    ("parameters: [F07]\n", ":1: not a golden file"),
    ("parameters:\n  F07: 6\nexcept:\n  200: [F07]\n", ":4: except: 200 is not a station address"),
    ("parameters:\n  F07: 6\nexcept:\n  9: {F07: 1}\n", ":4: except: station 9: give a list of codes"),
    ("parameters:\n  F07: 6\nprofile: nosuch\n", ":3: unknown profile 'nosuch'"),
    ("parameters:\n  F07: 6\nexcepts: {}\n", ":3: unknown key 'excepts'"),
])
def test_golden_file_errors_name_file_and_line(tmp_path, text, where):
    g = tmp_path / "g.yaml"
    g.write_text(text)
    with pytest.raises(DataFileError) as e:
        load_golden(g)
    assert f"{g}{where}" in str(e.value)


def test_fleet_diff_live_names_the_station_and_the_code(capsys, monkeypatch):
    r = run_main(capsys, monkeypatch, "param", "fleet", "diff", "3,8-11", "--port", FIVE)
    assert r.exit_code == 1, r.stderr
    assert "odd: station 9 F07 = 5 s" in r.stdout
    assert "1 odd value(s)" in r.stdout
    r = run_main(capsys, monkeypatch, "param", "fleet", "diff", "3,8-11", "--port", FIVE, "--json")
    d = json.loads(r.stdout)
    assert d["odd"] == [{"station": 9, "code": "F07"}]
    assert d["matrix"]["F07"]["9"] == {"value": 5.0, "odd": True}
    assert d["majority"]["fuji-opc-g1-pdp"]["F07"] == 6.0


def test_fleet_dump_then_diff_the_directory(capsys, monkeypatch, tmp_path):
    d = tmp_path / "line"
    d.mkdir()
    r = run_main(capsys, monkeypatch, "param", "fleet", "dump", "3,8-11", "-o", d, "--port", FIVE)
    assert r.exit_code == 0, r.stderr
    assert sorted(p.name for p in d.iterdir()) == [f"station-{a:03d}.yaml" for a in (3, 8, 9, 10, 11)]
    assert (d / "station-009.yaml").read_text().endswith("end: pdrive_dump\n")
    html = tmp_path / "line.html"
    r = run_main(capsys, monkeypatch, "param", "fleet", "diff", d, "--html", html)
    assert r.exit_code == 1 and "odd: station 9 F07 = 5 s" in r.stdout
    page = html.read_text()
    from profidrive_cli.checklist.report_html import CSS
    assert CSS in page and '<td class="odd">5 s</td>' in page
    g = tmp_path / "golden.yaml"
    g.write_text("parameters:\n  F07: 6.0\nexcept:\n  9: [F07]\n")
    r = run_main(capsys, monkeypatch, "param", "fleet", "diff", d, "--golden", g)
    assert r.exit_code == 0, r.stdout            # the odd value is station 9's exception
    g.write_text("parameters:\n  F07: 6.0\n")
    r = run_main(capsys, monkeypatch, "param", "fleet", "diff", d, "--golden", g, "--json")
    assert r.exit_code == 1
    assert json.loads(r.stdout)["violations"] == [
        {"station": 9, "code": "F07", "value": 5.0, "golden": 6.0, "why": "differs from the golden file"}]


def test_fleet_bad_input_is_one_line_exit_2(capsys, monkeypatch, tmp_path):
    r = run_main(capsys, monkeypatch, "param", "fleet", "diff", tmp_path / "nope", "--port", FIVE)
    assert r.exit_code == 2 and "neither a directory nor station addresses" in r.stderr
    r = run_main(capsys, monkeypatch, "param", "fleet", "diff", tmp_path, "--port", FIVE)
    assert r.exit_code == 2 and "no dump files" in r.stderr
    r = run_main(capsys, monkeypatch, "param", "fleet", "dump", "3", "-o", tmp_path / "missing",
                 "--port", FIVE)
    assert r.exit_code == 2 and "Traceback" not in r.stderr


def test_mutated_golden_files_only_raise_one_line_errors(tmp_path):
    # every one-character deletion and a few replacements of a valid file: a golden file or a
    # DataFileError / UsageError (one line), never another exception
    good = "pdrive_golden: 1\nprofile: fuji-g1\nparameters:\n  F07: 6.0\n  F08: {value: 6}\nexcept:\n  9: [F07]\n"
    g = tmp_path / "g.yaml"
    texts = [good[:i] + good[i + 1:] for i in range(len(good))]
    texts += [good.replace("6.0", x) for x in ("[]", "{}", "null", "true", "'6'", "1e999")]
    texts += [good.replace("9:", x) for x in ("-1:", "x:", "[9]:", "9.5:", "true:")]
    for text in texts:
        g.write_text(text)
        try:
            load_golden(g)
        except (DataFileError, UsageError) as e:
            assert "\n" not in str(e), text
