"""Baseline and drift (issue 27): `pdrive scan --save FILE`, `pdrive scan --compare FILE [--junit FILE]`
(bustools/baseline.py, cli/scan_baseline.py) and the checklist step `baseline`.

Expected values: the margins stated in bustools/baseline.py and docs/commands.md (counters: more than 1
above the baseline; reply time: more than 5 ms and more than 50 % longer), hand arithmetic on them, the
simulated plant as its URL builds it (sim/plant.py: the default plant 3 fuji-g1 0xFD01, 4 fuji-pdp3
0xFD02, 5 toyo 0x0BE7, 6 moeller 0xFD06, 7 yaskawa 0x00CA; `stations=3,4,5,6` is the default plant
without station 7), and the bus timing of the simulator (`tsdr=N`: a station answers N bit times after
the request, so tsdr=1000 instead of the default 11 adds (1000 - 11) / 19200 s = 51.51 ms at 19.2k).
"""

from __future__ import annotations

import json
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest
from click.testing import CliRunner

from profidrive_cli.bustools import baseline as B
from profidrive_cli.cli.main import cli
from profidrive_cli.datafile import DataFileError
from test_json_contract import assert_contract


def _run(*args, cwd=None):
    p = subprocess.run([sys.executable, "-m", "profidrive_cli", *args], capture_output=True, text=True,
                       stdin=subprocess.DEVNULL, timeout=120, cwd=cwd)
    return p.returncode, p.stdout, p.stderr


def _cli(*args):
    return CliRunner().invoke(cli, list(args))


def st(addr, ident=0xFD01, cfg=b"\xf3\xf1", reply=16.0, unanswered=0, **counters):
    return B.StationRecord(addr, "slave", ident, cfg, unanswered, reply,
                           {"requests": 6, **{k: 0 for k in B.COUNTER_KEYS}, **counters})


def net(*stations):
    return B.NetworkRecord("sim://", 19200, 2, 0, 126, "2026-01-01T00:00:00+00:00", tuple(stations))


# -- compare: sans-IO ------------------------------------------------------------------------------

def test_the_same_network_has_no_difference():
    a = net(st(3), st(7, 0x00CA, b"\x5f\x6f"))
    assert B.compare(a, a) == []


def test_missing_and_new_stations_are_named():
    d = B.compare(net(st(3), st(7, 0x00CA)), net(st(3), st(9, 0x00CA)))
    assert [(x.station, x.kind) for x in d] == [(7, "missing"), (9, "new")]
    assert d[0].text == "station 7 (0x00CA) is missing" and d[1].text == "station 9 (0x00CA) is new"


def test_other_ident_type_and_configuration():
    other = B.StationRecord(3, "master ready for the ring", 0x00CA, b"\x5f\x6f", 0, 16.0, {})
    d = B.compare(net(st(3)), net(other))
    assert [x.kind for x in d] == ["type", "ident", "cfg"]
    assert d[1].baseline == "0xFD01" and d[1].now == "0x00CA"
    assert d[2].text == "station 3: configuration (Get_Cfg) 5f 6f, baseline f3 f1"


def test_a_configuration_no_longer_read_is_a_difference():
    d = B.compare(net(st(3)), net(st(3, cfg=None)))
    assert [x.kind for x in d] == ["cfg"] and "not read" in d[0].text


@pytest.mark.parametrize("was, now, differs", [
    (0, 1, False),          # one more: within the margin of 1
    (0, 2, True),           # two more: above it
    (3, 4, False),
    (3, 5, True),
    (5, 0, False),          # fewer errors is no difference
])
def test_counter_margin(was, now, differs):
    d = B.compare(net(st(3, retries=was)), net(st(3, retries=now)))
    assert bool(d) == differs
    if differs:
        assert (d[0].kind, d[0].item, d[0].baseline, d[0].now) == ("counter", "retries", was, now)


def test_the_warm_up_requests_are_not_counted_as_lost():
    """A slave that woke only after 4 unanswered FDL status requests has 4 no_answer from them; a
    baseline taken while it was awake (0) is no different."""
    d = B.compare(net(st(3)), net(st(3, unanswered=4, no_answer=4)))
    assert d == []
    d = B.compare(net(st(3)), net(st(3, unanswered=4, no_answer=6)))       # 2 lost beyond the warm-up
    assert [(x.item, x.baseline, x.now) for x in d] == [("no_answer", 0, 2)]


@pytest.mark.parametrize("base, now, differs", [
    (16.0, 21.0, False),    # 5.0 ms more: not more than 5 ms
    (16.0, 21.5, False),    # 5.5 ms more, but not more than 50 % of 16 = 8 ms
    (16.0, 24.5, True),     # 8.5 ms more: above both
    (2.0, 7.5, True),       # 5.5 ms more, 275 %
    (2.0, 6.9, False),      # 4.9 ms more
    (30.0, 10.0, False),    # faster is no difference
])
def test_reply_time_margin(base, now, differs):
    d = B.compare(net(st(3, reply=base)), net(st(3, reply=now)))
    assert bool(d) == differs
    assert all(x.kind == "reply_time" for x in d)


def test_margins_are_the_callers():
    m = B.Margins(counter=5, reply_ms=100.0, reply_ratio=10.0)
    assert B.compare(net(st(3, retries=0, reply=1.0)), net(st(3, retries=5, reply=90.0)), m) == []


# -- the file ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["base.yaml", "base.yml", "base.json", "base"])
def test_a_record_reads_back_the_same(tmp_path, name):
    rec = net(st(3, unanswered=2, no_answer=2), st(7, 0x00CA, b"\x5f\x6f", reply=None),
              B.StationRecord(1, "master in the ring", None, None, 0, None, {}))
    p = tmp_path / name
    p.write_text(B.dumps(rec, p))
    assert B.load(p) == rec
    if name.endswith("json"):
        json.loads(p.read_text())                   # plain JSON


GOOD = """\
pdrive_baseline: 1
saved: '2026-01-01T00:00:00+00:00'
port: sim://
baud: 19200
master_address: 2
first: 0
last: 126
count: 2
stations:
- station: 3
  type: slave
  ident: 64769
  cfg: f3 f1
  reply_ms: 16.5
  counters: {requests: 6, retries: 0}
- station: 7
  type: slave
  ident: 202
  cfg: 5f 6f
  reply_ms: null
  counters: {}
end: pdrive_baseline
"""


def test_the_sample_file_is_a_baseline(tmp_path):
    p = tmp_path / "b.yaml"
    p.write_text(GOOD)
    rec = B.load(p)
    assert [(s.address, s.ident, s.cfg) for s in rec.stations] == [(3, 0xFD01, b"\xf3\xf1"),
                                                                   (7, 0x00CA, b"\x5f\x6f")]


@pytest.mark.parametrize("old, new, line, words", [
    ("  ident: 202\n", "  ident: x\n", 18, "'ident' must be a whole number"),
    ("  cfg: f3 f1\n", "  cfg: zz\n", 13, "'cfg' must be octets"),
    ("  reply_ms: 16.5\n", "  reply_ms: -1\n", 14, "'reply_ms' must be a number >= 0"),
    ("count: 2\n", "count: 3\n", 8, "incomplete or edited"),
    ("end: pdrive_baseline\n", "", None, "incomplete"),
    ("- station: 7\n", "- station: 3\n", 16, "station 3 listed twice"),
    ("  type: slave\n  ident: 64769\n", "  type: slave\n  idnt: 64769\n", 12, "unknown key 'idnt'"),
    ("pdrive_baseline: 1\n", "pdrive_baseline: 2\n", 1, "not a pdrive baseline"),
    ("last: 126\n", "last: 5\n", 16, "outside first..last 0..5"),
    ("  counters: {requests: 6, retries: 0}\n", "  counters: [1]\n", 15, "'counters' must be a mapping"),
])
def test_a_bad_file_names_file_and_line(tmp_path, old, new, line, words):
    assert old in GOOD
    p = tmp_path / "b.yaml"
    p.write_text(GOOD.replace(old, new, 1))
    with pytest.raises(DataFileError) as e:
        B.load(p)
    assert words in str(e.value)
    assert str(e.value).startswith(f"{p}:{line}:" if line else f"{p}:")


def test_a_file_cut_off_after_a_station_is_refused(tmp_path):
    p = tmp_path / "b.yaml"
    p.write_text(GOOD[:GOOD.index("- station: 7")])
    with pytest.raises(DataFileError, match="incomplete"):
        B.load(p)


# -- the command -------------------------------------------------------------------------------------

def test_done_when_save_then_compare_on_the_plant_without_station_7(tmp_path):
    f = tmp_path / "accepted.yaml"
    code, out, err = _run("scan", "--port", "sim://", "--save", str(f))
    assert code == 0, err
    assert f"baseline saved to {f}: 5 station(s)" in out
    code, out, err = _run("scan", "--port", "sim://", "--compare", str(f))
    assert code == 0, err
    assert "no difference" in out
    code, out, err = _run("scan", "--port", "sim://?stations=3,4,5,6", "--compare", str(f))
    assert code == 1, err
    assert "1 difference" in out and "station 7 (0x00CA) is missing" in out


def test_compare_json_and_junit(tmp_path):
    f, j = tmp_path / "accepted.json", tmp_path / "report.xml"
    assert _cli("scan", "--port", "sim://", "--save", str(f), "--json").exit_code == 0
    r = _cli("scan", "--port", "sim://?stations=3,4,5,6", "--compare", str(f), "--json", "--junit", str(j))
    assert r.exit_code == 1, r.output
    doc = json.loads(r.output)
    assert_contract(doc, "scan compare")                                  # docs/json.md
    assert doc["equal"] is False
    assert [(d["station"], d["kind"]) for d in doc["differences"]] == [(7, "missing")]
    assert [s["station"] for s in doc["stations"]] == [3, 4, 5, 6]
    root = ET.parse(j).getroot()
    cases = {c.get("name"): c for c in root.iter("testcase")}
    assert sorted(cases) == [f"station {a}" for a in (3, 4, 5, 6, 7)]
    assert cases["station 7"].find("failure") is not None
    assert all(cases[f"station {a}"].find("failure") is None for a in (3, 4, 5, 6))
    assert root.get("failures") == "1"
    r = _cli("scan", "--port", "sim://", "--compare", str(f), "--json", "--junit", str(j))
    assert r.exit_code == 0 and json.loads(r.output)["equal"] is True
    assert ET.parse(j).getroot().get("failures") == "0"


def test_save_json_is_the_file(tmp_path):
    f = tmp_path / "accepted.json"
    r = _cli("scan", "--port", "sim://?warmup=3:4", "--save", str(f), "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.output)
    assert_contract(doc, "scan save")                                     # docs/json.md
    assert doc == json.loads(f.read_text())
    by = {s["station"]: s for s in doc["stations"]}
    # station 3 misses 4 telegrams on the line: its quick-pass probe (the 3rd, after 0 and 1) is
    # missed, the second pass's answered (dp/scan.py)
    assert by[3]["unanswered_before"] == 1 and by[3]["counters"]["no_answer"] == 1
    assert (by[7]["ident"], by[7]["cfg"]) == (0x00CA, "5f 6f")    # Yaskawa SI-P1, layout extended1 5F 6F


def test_another_device_at_an_address(tmp_path):
    f = tmp_path / "a.yaml"
    assert _cli("scan", "--port", "sim://?stations=3:fuji-g1", "--save", str(f)).exit_code == 0
    r = _cli("scan", "--port", "sim://?stations=3:yaskawa", "--compare", str(f))
    assert r.exit_code == 1
    assert "station 3: ident 0x00CA, baseline 0xFD01" in r.output
    assert "station 3: configuration (Get_Cfg) 5f 6f, baseline f3 f1" in r.output


def test_a_slower_station_is_a_reply_time_difference(tmp_path):
    """On the virtual clock a station with tsdr=1000 answers 989 bit times later than one with the
    default 11: 51.51 ms at 19.2k, far beyond 5 ms and 50 %."""
    f = tmp_path / "a.json"
    assert _cli("scan", "--port", "sim://?timing=virtual&stations=3", "--save", str(f)).exit_code == 0
    r = _cli("scan", "--port", "sim://?timing=virtual&stations=3&tsdr=1000", "--slot-time", "2000",
             "--compare", str(f), "--json")
    assert r.exit_code == 1, r.output
    (d,) = json.loads(r.output)["differences"]
    assert d["kind"] == "reply_time"
    assert d["now"] - d["baseline"] == pytest.approx(989 / 19200 * 1000, abs=0.05)


def test_the_baseline_compared_at_another_rate_leaves_reply_times_out(tmp_path):
    f = tmp_path / "a.json"
    assert _cli("scan", "--port", "sim://?stations=3", "--save", str(f)).exit_code == 0
    r = _cli("scan", "--port", "sim://?stations=3", "--baud", "187500", "--compare", str(f), "--json")
    assert r.exit_code == 0, r.output
    assert "reply times not compared" in json.loads(r.output)["notes"][0]


def test_nothing_answered_saves_nothing_and_keeps_the_old_file(tmp_path):
    f = tmp_path / "a.yaml"
    f.write_text("the old baseline\n")
    code, out, err = _run("scan", "--port", "sim://", "--from", "10", "--to", "12", "--save", str(f))
    assert code == 1 and "no baseline saved" in err
    assert f.read_text() == "the old baseline\n"


def test_a_bad_baseline_is_one_line_with_file_and_line_exit_2(tmp_path):
    f, j = tmp_path / "b.yaml", tmp_path / "r.xml"
    f.write_text(GOOD.replace("  ident: 202\n", "  ident: x\n"))
    code, out, err = _run("scan", "--port", "sim://", "--compare", str(f), "--junit", str(j))
    assert code == 2 and out == ""
    lines = [x for x in err.splitlines() if x.strip()]
    assert len(lines) == 1 and f"{f}:18:" in lines[0] and "Traceback" not in err
    assert not j.exists()                                   # nothing written


@pytest.mark.parametrize("args, words", [
    (["--save", "a.yaml", "--compare", "b.yaml"], "one at a time"),
    (["--save", "a.yaml", "--watch"], "--watch does not go"),
    (["--junit", "r.xml"], "--junit goes with --compare"),
    (["--compare", "GOOD", "--from", "3"], "--from / --to go with --save"),
    (["--save", "no/such/dir/a.yaml"], "does not exist"),
])
def test_bad_options_are_one_line_exit_2(tmp_path, args, words):
    (tmp_path / "GOOD").write_text(GOOD)
    code, out, err = _run("scan", "--port", "sim://", *args, cwd=tmp_path)
    assert code == 2, err
    lines = [x for x in err.splitlines() if x.strip()]
    assert len(lines) == 1 and words in lines[0]
    assert not (tmp_path / "a.yaml").exists()


# -- the checklist step --------------------------------------------------------------------------------

CHECKLIST = """\
name: baseline
port: sim://
stations:
  - address: 3
    profile: fuji-g1
steps:
  - baseline: accepted.yaml
"""


def _checklist(tmp_path, text=CHECKLIST, save_on="sim://"):
    assert _cli("scan", "--port", save_on, "--save", str(tmp_path / "accepted.yaml")).exit_code == 0
    p = tmp_path / "cl.yaml"
    p.write_text(text)
    return p


def test_checklist_step_passes_on_the_accepted_plant(tmp_path):
    r = _cli("checklist", "run", str(_checklist(tmp_path)), "--yes", "--json")
    assert r.exit_code == 0, r.output
    step = json.loads(r.output)["stations"][0]["steps"][0]
    assert step["status"] == "passed"
    assert_contract(step["measured"], "checklist measured baseline")       # docs/json.md
    assert step["measured"]["stations"] == [3, 4, 5, 6, 7] and step["measured"]["differences"] == []


def test_checklist_step_fails_naming_the_missing_station(tmp_path):
    r = _cli("checklist", "run", str(_checklist(tmp_path)), "--port", "sim://?stations=3,4,5,6", "--yes",
             "--json")
    assert r.exit_code == 1, r.output
    step = json.loads(r.output)["stations"][0]["steps"][0]
    assert step["status"] == "failed" and "station 7 (0x00CA) is missing" in step["message"]


def test_checklist_step_scope_station_looks_at_its_own_station_only(tmp_path):
    text = CHECKLIST.replace("baseline: accepted.yaml", "baseline: {file: accepted.yaml, scope: station}")
    r = _cli("checklist", "run", str(_checklist(tmp_path, text)), "--port", "sim://?stations=3,4,5,6",
             "--yes", "--json")
    assert r.exit_code == 0, r.output


def test_checklist_dry_run_reads_the_file_and_compares_nothing(tmp_path):
    r = _cli("checklist", "run", str(_checklist(tmp_path)), "--dry-run", "--yes", "--json")
    assert r.exit_code == 0, r.output
    step = json.loads(r.output)["stations"][0]["steps"][0]
    assert step["measured"] == {"compared": False} and "dry run" in step["message"]


@pytest.mark.parametrize("body, line, words", [
    ("baseline: {file: accepted.yaml, scope: all}", 7, "'scope' must be bus or station"),
    ("baseline: {file: accepted.yaml, counter_margin: -1}", 7, "'counter_margin' must be at least 0"),
    ("baseline: {scope: bus}", 7, "missing field 'file'"),
    ("baseline: missing.yaml", 7, "file not found"),
])
def test_bad_checklist_step_names_the_line(tmp_path, body, line, words):
    p = _checklist(tmp_path, CHECKLIST.replace("baseline: accepted.yaml", body))
    code, out, err = _run("checklist", "validate", str(p))
    assert code == 2
    assert f"cl.yaml:{line}" in err and words in err


def test_a_bad_baseline_in_a_checklist_names_both_files(tmp_path):
    p = _checklist(tmp_path)
    (tmp_path / "accepted.yaml").write_text(GOOD.replace("  ident: 202\n", "  ident: x\n"))
    code, out, err = _run("checklist", "validate", str(p))
    assert code == 2 and "cl.yaml:7" in err and "accepted.yaml:18:" in err


# -- the plant of the "done when": an address alone is the default plant's station -------------------

def test_an_address_alone_is_the_default_plants_station():
    from profidrive_cli import UsageError
    from profidrive_cli.sim.plant import build_bus
    bus = build_bus("sim://?stations=3,4,5,6")
    # the default plant (sim/plant.py DEFAULT_PLANT) without 7: the idents of its profiles
    assert {a: s.model.ident for a, s in bus.slaves.items()} == {3: 0xFD01, 4: 0xFD02, 5: 0x0BE7,
                                                                6: 0xFD06}
    with pytest.raises(UsageError, match="station '9' must be ADDRESS:PROFILE"):
        build_bus("sim://?stations=3,9")
