"""pdrive run / status / param / faults through click on the in-process simulated bus (a plant that
survives between commands, like `pdrive sim`), for each of the five default stations."""

import json

import pytest

from profidrive_cli.cli.main import main

RAMPS = {3: ("F07", "F08"), 4: ("F07", "F08"), 6: ("F002", "F003"), 7: ("C1-01", "C1-02")}
# a writable parameter per station, a value to set, and the factory value
WRITABLE = {3: ("F07", "2.5", 6.0), 4: ("E31", "40", 60.0), 6: ("F002", "1.5", 5.0),
            7: ("C1-01", "4", 10.0)}
TRIPS = {3: "OC1", 4: "OU2", 5: "OC", 6: "E05", 7: "EF0"}




class Result:
    def __init__(self, exit_code, stdout, stderr):
        self.exit_code, self.stdout, self.stderr = exit_code, stdout, stderr
        self.output = stdout + stderr


@pytest.fixture
def pdrive(capsys, monkeypatch):
    """Run `pdrive ARGS --port PORT` through main() (exit codes and one-line errors as a user sees them)."""
    monkeypatch.setenv("PDRIVE_PORT", "")
    monkeypatch.delenv("PDRIVE_STATION", raising=False)

    def run(*args, port="sim://"):
        capsys.readouterr()
        try:
            main(list(args) + ["--port", port])
            code = 0
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
        o = capsys.readouterr()
        return Result(code, o.out, o.err)
    return run


def ok(r):
    assert r.exit_code == 0, r.output
    return r


def lines(r):
    return [json.loads(x) for x in r.stdout.splitlines() if x.startswith("{")]


@pytest.fixture
def status(pdrive):
    def get(address, port="sim://"):
        return json.loads(ok(pdrive("status", str(address), "--json", port=port)).stdout)
    return get


# -- run -------------------------------------------------------------------------------------------

@pytest.mark.parametrize("address", [3, 4, 5, 6, 7])
def test_run_reaches_30_hz_and_ends_stopped(sim, pdrive, status, address):
    for code in RAMPS.get(address, ()):           # Toyo's ramps have no PNU: 5 s to 60 Hz stays
        ok(pdrive("param", "set", str(address), code, "0.2"))
    duration = "3.2" if address == 5 else "0.8"
    r = ok(pdrive("run", str(address), "--hz", "30", "--duration", duration, "--json"))
    ev = lines(r)
    start, end = ev[0], ev[-1]
    assert start["event"] == "start" and start["station"] == address
    assert start["reference_hz"] == pytest.approx(30.0, abs=0.01)
    actual = [e["actual_hz"] for e in ev if e["event"] == "update" and e["phase"] == "running"]
    assert any(abs(a - 30.0) <= 0.3 for a in actual), actual[-5:]
    assert end["event"] == "end" and end["stopped"] and end["stop"]["how"] == "normal"
    assert end["reached_after_s"] is not None
    st = status(address)
    assert st["stopped"] and not st["running"] and st["actual_hz"] == 0


def test_run_in_reverse_with_percent_and_a_csv_log(sim, pdrive, tmp_path):
    ok(pdrive("param", "set", "6", "F002", "0.2"))
    log = tmp_path / "run.csv"
    r = ok(pdrive("run", "6", "--percent", "20", "--reverse", "--duration", "0.5", "--json",
                  "--log", str(log)))
    ev = lines(r)
    assert ev[0]["reference_percent"] == pytest.approx(-20.0)
    assert min(e["actual_percent"] for e in ev if e["event"] == "update") < -10
    rows = log.read_text().splitlines()
    assert rows[0].startswith("time_s,cycle,control_word,reference,status_word,actual")
    assert len(rows) - 1 == ev[-1]["cycles"]


#: station 3 with F07 = 0.1 s (0 -> F03 60 Hz): a 0.2 s run reaches its reference (a run that does
#: not, exits 1: test_run_not_reaching_its_reference_exits_1)
FAST3 = "sim://?set=3:F07=0.1"


def test_run_without_parameter_channel_says_where_fmax_comes_from(pdrive):
    r = ok(pdrive("run", "3", "--ppo", "3", "--hz", "30", "--fmax", "50", "--duration", "0.2", "--json",
                  port=FAST3))
    start = lines(r)[0]
    assert start["fmax_hz"] == 50.0 and start["fmax_source"] == "from --fmax"
    assert start["reference_percent"] == pytest.approx(60.0)
    r = ok(pdrive("run", "3", "--ppo", "4", "--hz", "30", "--duration", "0.2", port=FAST3))
    assert "the profile default (layout ppo4 has no parameter channel" in r.stdout


def test_run_not_reaching_its_reference_exits_1(pdrive):
    # F07 = 6 s from 0 to F03 = 60 Hz (profile fuji-opc-g1-pdp defaults; the sim ramps with F07):
    # 30 Hz takes 3 s, so a 1 s run ends at about 10 Hz, short of its reference
    r = pdrive("run", "3", "--hz", "30", "--duration", "1")
    assert r.exit_code == 1, r.output
    err = [x for x in r.stderr.splitlines() if x.startswith("pdrive:")]
    assert len(err) == 1 and "station 3: did not reach its reference (30 Hz) within 1 s" in err[0]
    assert "the drive is stopped" in err[0] and "Traceback" not in r.output
    # several drives: the same rule and the same words (session/multirun.py)
    r = pdrive("run", "3,4", "--hz", "30", "--duration", "1")
    assert r.exit_code == 1 and "station 3: did not reach its reference" in r.stderr, r.output


def test_run_of_a_tripped_drive_fails_with_the_reason(pdrive):
    r = pdrive("run", "6", "--hz", "10", "--duration", "0.5", port="sim://?trip=6:E05")
    assert r.exit_code == 1
    assert "fault" in r.output and "Traceback" not in r.output


def test_run_warns_about_a_cycle_rate_above_the_baud_rate(pdrive):
    r = ok(pdrive("run", "7", "--hz", "5", "--duration", "0.2", "--cycle-hz", "400", "--json",
                  port="sim://?set=7:C1-01=0.1"))       # C1-01 0.1 s: 5 Hz reached in the 0.2 s
    assert any("more than 19.2k allows" in w for w in lines(r)[0]["warnings"])


# -- status ----------------------------------------------------------------------------------------

def test_status_without_address_on_a_one_drive_bus(pdrive):
    r = ok(pdrive("status", "--json", port="sim://?stations=5:toyo"))
    d = json.loads(r.stdout)
    assert d["station"] == 5 and d["family"] == "toyo" and d["state"].startswith("S1")
    r = pdrive("status")
    assert r.exit_code == 2 and "5 drive stations" in r.output


def test_status_text_names_state_speed_and_fault(pdrive):
    r = ok(pdrive("status", "3", port="sim://?trip=3:OC1"))
    assert "state:  fault" in r.stdout and "fault:  OC1" in r.stdout
    assert "60 Hz, read from the drive (F03)" in r.stdout


# -- param -----------------------------------------------------------------------------------------

@pytest.mark.parametrize("address", [3, 4, 6, 7])
def test_param_set_get_round_trip(sim, pdrive, address):
    code, value, factory = WRITABLE[address]
    d = json.loads(ok(pdrive("param", "set", str(address), code, value, "--json")).stdout)
    assert d["old"]["value"] == pytest.approx(factory) and d["new"]["value"] == pytest.approx(float(value))
    d = json.loads(ok(pdrive("param", "get", str(address), code, "--json")).stdout)
    assert d["parameters"][0]["value"] == pytest.approx(float(value))


def test_toyo_has_no_writable_parameter_with_a_published_pnu(sim, pdrive):
    r = pdrive("param", "set", "5", "A-00", "50")
    assert r.exit_code == 2 and "does not publish its PNU" in r.output
    d = json.loads(ok(pdrive("param", "get", "5", "dc-voltage", "PNU684", "--json")).stdout)
    assert [p["code"] for p in d["parameters"]] == ["dc-voltage", "motor-speed"]
    assert d["parameters"][0]["unit"] == "V"


def test_param_save_where_the_card_can(sim, pdrive):
    r = ok(pdrive("param", "set", "6", "F002", "3", "--save"))
    assert "saved to non-volatile memory" in r.stdout
    r = ok(pdrive("param", "set", "3", "F07", "3", "--save"))
    assert "stored by the card itself" in r.stdout


@pytest.mark.parametrize("address", [3, 4, 5, 6, 7])
def test_dump_change_restore(sim, pdrive, tmp_path, address):
    f = tmp_path / f"s{address}.yaml"
    d = json.loads(ok(pdrive("param", "dump", str(address), "-o", str(f), "--json")).stdout)
    text = f.read_text()
    assert "pdrive_dump: 2" in text and f"address: {address}" in text
    assert text.endswith("end: pdrive_dump\n") and "count: " in text
    if address == 5:
        assert d["settings"] == 0 and d["readonly"] > 10        # monitors only (see the profile)
        r = ok(pdrive("param", "restore", "5", str(f)))
        assert "nothing in the file" in r.stdout
        return
    code, value, factory = WRITABLE[address]
    ok(pdrive("param", "set", str(address), code, value))
    r = pdrive("param", "diff", str(address), str(f), "--json")
    assert r.exit_code == 1, r.output       # like diff(1): 1 when the drive differs from the file
    diff = json.loads(r.stdout)
    changed = [row for row in diff["rows"] if row["result"] == "differs"]
    assert [row["code"] for row in changed] == [code]
    dry = json.loads(ok(pdrive("param", "restore", str(address), str(f), "--dry-run", "--json")).stdout)
    assert dry["counts"].get("would apply") == 1
    r = ok(pdrive("param", "restore", str(address), str(f)))
    assert "1 applied" in r.stdout and "refused" not in r.stdout and code in r.stdout
    d = json.loads(ok(pdrive("param", "get", str(address), code, "--json")).stdout)
    assert d["parameters"][0]["value"] == pytest.approx(factory)
    diff = json.loads(ok(pdrive("param", "diff", str(address), str(f), "--json")).stdout)
    assert "differs" not in diff["counts"]
    r = pdrive("param", "diff", str(address), str(f))       # equal again: 0, the count says so
    assert r.exit_code == 0 and "0 parameter(s) differ" in r.stdout, r.output


# -- faults ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("address", [3, 4, 5, 6, 7])
def test_faults_after_an_injected_trip(pdrive, address):
    code = TRIPS[address]
    port = f"sim://?trip={address}:{code}"
    r = ok(pdrive("faults", str(address), port=port))
    assert f"fault {code}" in r.stdout and code in r.stdout.split("fault history", 1)[1]
    d = json.loads(ok(pdrive("faults", str(address), "--json", port=port)).stdout)
    assert d["current"]["fault"] and d["current"]["code"] == code
    assert code in d["history"][0]["codes"]


def test_faults_clear_acknowledges(sim, pdrive, status):
    port = "sim://?trip=4:OU2"
    d = json.loads(ok(pdrive("faults", "4", "--clear", "--json", port=port)).stdout)
    assert d["cleared"]["was"] == "OU2" and not d["cleared"]["fault"]
    assert not status(4, port)["fault"]


# -- bad input: one line, exit 2 for usage, 1 for bus/drive --------------------------------------

@pytest.mark.parametrize("args,code,msg", [
    (["param", "get", "3", "F3x"], 2, "closest fuji codes: F03"),
    (["param", "get", "7", "A004"], 2, "A004 is a moeller code"),
    (["param", "get", "5", "C1-01"], 2, "station 5 is toyo-pbus66z"),
    (["param", "set", "3", "F07", "7000"], 2, "outside 0..6000 s"),
    (["param", "set", "3", "F07", "fast"], 2, "expected a number 0..6000 s"),
    (["param", "set", "7", "E1-04", "-5"], 2, "outside 40..400 Hz"),
    (["param", "set", "3", "M16", "1"], 2, "read-only"),
    (["param", "set", "3", "F07"], 2, "expected [ADDRESS] CODE VALUE"),
    (["param", "get", "3"], 2, "param get: missing argument CODE after the address 3"),
    (["param", "get", "42", "F03"], 1, "station 42 does not answer"),
    (["status", "42"], 1, "station 42 does not answer"),
    (["status", "200"], 2, "outside 0..125"),
    (["run", "3"], 2, "--hz F or --percent P"),
    (["run", "3", "--hz", "100"], 2, "above the maximum frequency 60 Hz"),
    (["run", "7", "--ppo", "1", "--hz", "5"], 2, "no PPO layouts"),
    (["run", "3", "--format", "xyz", "--hz", "5"], 2, "has the layouts ppo1, ppo2, ppo3, ppo4"),
    (["run", "5", "--profile", "moeller", "--hz", "5"], 2, "station 5 is toyo-pbus66z"),
    (["param", "restore", "3", "/nonexistent.yaml"], 2, "file not found"),
])
def test_bad_input_is_one_line(pdrive, args, code, msg):
    r = pdrive(*args)
    assert r.exit_code == code, r.output
    assert msg in r.output
    assert "Traceback" not in r.output
    assert len(r.output.strip().splitlines()) == 1, r.output
