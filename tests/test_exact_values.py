"""Issue 12 findings 2, 3, 6: values are never rounded, dangerous parameters need --allow-dangerous,
restore checks every row before the first write, dumps detect truncation and survive failed dumps.

Expected values are hand calculations from the profiles' ranges and resolutions (Fuji F07: 0.1 s steps,
0..6000 s, factory 6.0 s; o27: codes 0..15, factory 0; Moeller F002 0.01 s steps; Yaskawa b1-01 codes 0..4)."""

import json
import math

import pytest

from profidrive_cli import UsageError
from profidrive_cli.drives.profile import load_profile
from profidrive_cli import session as S
from profidrive_cli.session import Parameters, DriveStation
from profidrive_cli.drives.values import danger, value_problem

from test_drive_cmds import pdrive  # noqa: F401  (the fixture: main() as a user runs it)
from test_session import session


def get(pdrive, address, code):
    r = pdrive("param", "get", str(address), code, "--json")
    assert r.exit_code == 0, r.output
    return json.loads(r.stdout)["parameters"][0]["value"]


FUJI = load_profile("fuji-g1")
MOELLER = load_profile("moeller")
YASKAWA = load_profile("yaskawa")


# -- the one check ----------------------------------------------------------------------------------

@pytest.mark.parametrize("value,nearest", [(0.05, "nearest 0 s or 0.1 s"), (2.55, "nearest 2.5 s or 2.6 s"),
                                           (0.01, "nearest 0 s or 0.1 s"), (5999.95, "nearest 5999.9 s or 6000 s")])
def test_a_value_between_two_steps_is_refused_with_its_neighbours(value, nearest):
    msg = value_problem(FUJI.param("F07"), value)
    assert msg is not None and "cannot be held exactly: resolution 0.1 s" in msg and msg.endswith(nearest)


@pytest.mark.parametrize("value", [0, 0.1, 2.5, 0.1 + 0.2, 6000, 6000.0, 1234.5])
def test_multiples_of_the_step_pass_float_noise_included(value):
    assert value_problem(FUJI.param("F07"), value) is None


def test_codes_take_whole_numbers_only():
    msg = value_problem(FUJI.param("o27"), 10.7)
    assert "o27 = 10.7 cannot be held exactly" in msg and msg.endswith("nearest 10 or 11")
    assert value_problem(FUJI.param("o27"), 10.0) is None
    assert "outside 0..15" in value_problem(FUJI.param("o27"), 16)


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, True, "3"])
def test_not_a_number_is_refused(value):
    assert value_problem(FUJI.param("F07"), value) is not None


def test_range_listed_codes_and_wire_width():
    assert value_problem(FUJI.param("F07"), 6000.1).endswith("outside 0..6000 s; nearest 6000 s")
    assert value_problem(MOELLER.param("F002"), 1.555).endswith("nearest 1.55 s or 1.56 s")
    b031 = value_problem(MOELLER.param("b031"), 5)           # ranges [[0, 3], [10, 10]]
    assert "outside 0..3, 10" in b031 and b031.endswith("nearest 3 or 10")
    b101 = value_problem(YASKAWA.param("b1-01"), 7)          # values 0..4
    assert "is not one of its codes 0, 1, 2, 3, 4" in b101
    assert value_problem(YASKAWA.param("o1-03"), 100) is None  # in the 40-39999 range of codes
    assert "does not fit" in value_problem(FUJI.param("H03"), 70000)   # no range: the 16-bit word


def test_dangerous_parameters_of_each_profile_say_what_happens():
    assert "auto-tuning" in danger(FUJI.param("P04")) and "whatever the PROFIdrive state" in danger(FUJI.param("P04"))
    assert "factory values" in danger(FUJI.param("H03"))
    assert "factory values" in danger(MOELLER.param("b084"))
    assert "auto-tuning" in danger(MOELLER.param("H001"))
    assert "factory value" in danger(YASKAWA.param("A1-03"))
    assert danger(FUJI.param("F07")) is None


# -- param set ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("code,text,words,factory", [
    ("o27", "10.7", "nearest 10 or 11", 0),
    ("F07", "0.05", "resolution 0.1 s; nearest 0 s or 0.1 s", 6.0),
    ("F07", "2.55", "nearest 2.5 s or 2.6 s", 6.0),
    ("F07", "nan", "nan is not a value a parameter can hold", 6.0),
    ("F07", "inf", "inf is not a value a parameter can hold", 6.0),
])
def test_param_set_refuses_a_value_it_would_round(sim, pdrive, code, text, words, factory):
    r = pdrive("param", "set", "3", code, text)
    assert r.exit_code == 2 and words in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.output
    assert get(pdrive, 3, code) == pytest.approx(factory)


@pytest.mark.parametrize("address,code,text", [(6, "F002", "1.555"), (7, "C1-01", "4.05"), (7, "b1-01", "7"),
                                               (4, "F07", "0.05")])
def test_param_set_exact_values_in_every_family(sim, pdrive, address, code, text):
    before = get(pdrive, address, code)
    r = pdrive("param", "set", str(address), code, text)
    assert r.exit_code == 2, r.output
    assert get(pdrive, address, code) == before


@pytest.mark.parametrize("code,value", [("P04", "2"), ("H03", "1"), ("PNU970", "1")])
def test_dangerous_parameter_needs_allow_dangerous_yes_is_not_enough(sim, pdrive, code, value):
    r = pdrive("param", "set", "3", code, value, "--yes")
    assert r.exit_code == 2 and "dangerous" in r.stderr and "--allow-dangerous" in r.stderr, r.output
    assert "nothing was written" in r.stderr
    assert get(pdrive, 3, code) == 0


def test_allow_dangerous_writes_it(sim, pdrive):
    r = pdrive("param", "set", "3", "P04", "2", "--allow-dangerous")
    assert r.exit_code == 0, r.output
    assert get(pdrive, 3, "P04") == 2


def test_moeller_auto_tuning_is_dangerous_too(sim, pdrive):
    r = pdrive("param", "set", "6", "H001", "2", "--yes")
    assert r.exit_code == 2 and "auto-tuning" in r.stderr


# -- restore: validate all, then write -------------------------------------------------------------

def test_restore_with_one_bad_row_writes_nothing(sim, pdrive, tmp_path):
    f = tmp_path / "bad.yaml"
    f.write_text("pdrive_dump: 1\nstation: {address: 3, profile: fuji-opc-g1-pdp}\nparameters:\n"
                 "  F08: {value: 7.5}\n  F07: {value: 99999}\n  E10: {value: 0.05}\n")
    r = pdrive("param", "restore", "3", str(f))
    assert r.exit_code == 2, r.output
    lines = r.stderr.strip().splitlines()
    assert any(f"{f}:5:" in x and "99999 s is outside 0..6000 s" in x for x in lines), lines
    assert lines[-1].endswith("problem(s); nothing was written")
    assert get(pdrive, 3, "F08") == 6.0 and get(pdrive, 3, "F07") == 6.0


def test_restore_of_nan_writes_nothing_and_does_not_crash(sim, pdrive, tmp_path):
    f = tmp_path / "nan.yaml"
    f.write_text("pdrive_dump: 1\nstation: {address: 3, profile: fuji-opc-g1-pdp}\nparameters:\n"
                 "  F08: {value: 7.5}\n  F07: {value: .nan}\n")
    r = pdrive("param", "restore", "3", str(f), "--json")
    assert r.exit_code == 2, r.output
    d = json.loads(r.stdout)
    assert d["written"] == 0 and len(d["problems"]) == 1 and "F07" in d["problems"][0]
    assert "Traceback" not in r.output
    assert get(pdrive, 3, "F08") == 6.0


def test_restore_lists_every_problem_identity_unknown_readonly_rounding(sim, tmp_path):
    f = tmp_path / "many.yaml"
    f.write_text("pdrive_dump: 1\nstation: {address: 3, profile: fuji-opc-g1-pdp, ident: '0x1234'}\n"
                 "parameters:\n  F07: {value: 2.55}\n  ZZ99: {value: 1}\n  PNU918: {value: 3}\n"
                 "  F08: {value: 7.5}\n")
    doc = Parameters.load_dump(f)
    with session(3) as s:
        with pytest.raises(getattr(S, 'RestoreRefused', UsageError)) as ei:
            s.params.restore(doc)
        probs = ei.value.problems
        assert s.params.read("F08").value == 6.0
    assert any("ident 0x1234" in p for p in probs)
    assert any(p.startswith(f"{f}:4:") and "nearest 2.5 s or 2.6 s" in p for p in probs)
    assert any(p.startswith(f"{f}:5:") and "ZZ99" in p for p in probs)
    assert any(p.startswith(f"{f}:6:") and "read-only" in p for p in probs)
    assert len(probs) == 4


def test_restore_refuses_stop_only_rows_while_the_motor_runs(sim, tmp_path):
    f = tmp_path / "f03.yaml"
    f.write_text("parameters:\n  F08: {value: 7.5}\n  F03: {value: 50.0}\n")
    doc = Parameters.load_dump(f)
    with session(3) as s:
        s.motion.start(10.0)
        with pytest.raises(getattr(S, 'RestoreRefused', UsageError)) as ei:
            s.params.restore(doc)
        assert any("F03" in p and "stopped" in p for p in ei.value.problems)
        assert s.params.read("F08").value == 6.0


def test_restore_skips_dangerous_rows_and_says_so(sim, pdrive, tmp_path):
    f = tmp_path / "d.yaml"
    f.write_text("parameters:\n  P04: {value: 2}\n  F08: {value: 7.5}\n")
    r = pdrive("param", "restore", "3", str(f))
    assert r.exit_code == 0, r.output
    assert "skipped (dangerous; --allow-dangerous writes them): P04" in r.stderr
    assert get(pdrive, 3, "P04") == 0 and get(pdrive, 3, "F08") == 7.5
    assert "no end marker" in r.stderr                       # an old-style file: accepted, with a warning


def _unplug_on_write(monkeypatch, cls, after: int):
    # restore writes each row's plan through Drive.write_resolved (session/parameters.py execute)
    calls = {"n": 0}
    real = cls.write_resolved

    def write(self, info, value):
        calls["n"] += 1
        if calls["n"] > after:
            self.channel.inner.master.link.ser.unplug()
        return real(self, info, value)
    monkeypatch.setattr(cls, "write_resolved", write)


def test_link_lost_mid_restore_says_which_rows_landed(sim, pdrive, tmp_path, monkeypatch):
    from profidrive_cli.drives.fuji import FujiDrive
    f = tmp_path / "three.yaml"
    f.write_text("parameters:\n  F07: {value: 2.5}\n  F08: {value: 7.5}\n  o28: {value: 3.0}\n")
    _unplug_on_write(monkeypatch, FujiDrive, 1)
    r = pdrive("param", "restore", "3", str(f), "--json")
    assert r.exit_code == 1, r.output
    d = json.loads(r.stdout.splitlines()[0])
    assert d["landed"] == ["F07"] and d["uncertain"] == ["F08"] and d["not_landed"] == ["o28"]
    assert "restore interrupted" in d["interrupted"]
    monkeypatch.undo()
    sim.clear()


def test_link_lost_mid_restore_text(sim, pdrive, tmp_path, monkeypatch):
    from profidrive_cli.drives.fuji import FujiDrive
    f = tmp_path / "three.yaml"
    f.write_text("parameters:\n  F07: {value: 2.5}\n  F08: {value: 7.5}\n  o28: {value: 3.0}\n")
    _unplug_on_write(monkeypatch, FujiDrive, 1)
    r = pdrive("param", "restore", "3", str(f))
    assert r.exit_code == 1, r.output
    assert "1 applied" in r.stdout and "1 unknown" in r.stdout and "1 not written" in r.stdout
    assert "restore interrupted" in r.stderr and "1 row(s) written and read back" in r.stderr


# -- dump files: truncation, atomic replacement ------------------------------------------------------

def test_every_cut_of_a_dump_is_refused(sim, pdrive, tmp_path):
    f = tmp_path / "full.yaml"
    assert pdrive("param", "dump", "3", "-o", str(f)).exit_code == 0
    text = f.read_text()
    assert text.endswith("end: pdrive_dump\n")
    Parameters.load_dump(f)                                # the whole file loads
    cuts = set()
    pos = 0
    for line in text.splitlines(keepends=True):
        cuts.update({pos, pos + len(line) // 2, pos + len(line) - 1})
        pos += len(line)
    cuts = sorted(c for c in cuts if c < len(text) - 1)      # len-1: only the final newline is gone
    cut = tmp_path / "cut.yaml"
    for c in cuts:
        cut.write_text(text[:c])
        with pytest.raises(UsageError):
            Parameters.load_dump(cut)
    r = pdrive("param", "restore", "3", str(cut))
    assert r.exit_code == 2


def test_a_dump_with_a_wrong_count_is_refused(tmp_path):
    f = tmp_path / "c.yaml"
    f.write_text("pdrive_dump: 2\ncount: 2\nparameters:\n  F07: {value: 2.5}\nend: pdrive_dump\n")
    with pytest.raises(UsageError, match="count: 2.*1 parameter"):
        Parameters.load_dump(f)
    f.write_text("pdrive_dump: 2\ncount: 1\nparameters:\n  F07: {value: 2.5}\n")
    with pytest.raises(UsageError, match="incomplete"):
        Parameters.load_dump(f)


OLD = b"keep me: the previous dump\n"


def test_failed_dump_keeps_the_old_file_station_absent(sim, pdrive, tmp_path):
    f = tmp_path / "d.yaml"
    f.write_bytes(OLD)
    r = pdrive("param", "dump", "9", "-o", str(f))
    assert r.exit_code == 1 and f.read_bytes() == OLD
    assert [p.name for p in tmp_path.iterdir()] == ["d.yaml"]


def test_failed_dump_keeps_the_old_file_port_missing(pdrive, tmp_path):
    f = tmp_path / "d.yaml"
    f.write_bytes(OLD)
    r = pdrive("param", "dump", "3", "-o", str(f), port=str(tmp_path / "ttyNONE"))
    assert r.exit_code != 0 and f.read_bytes() == OLD
    assert [p.name for p in tmp_path.iterdir()] == ["d.yaml"]


def test_failed_dump_keeps_the_old_file_link_dropped(sim, pdrive, tmp_path, monkeypatch):
    from profidrive_cli.drives.fuji import FujiDrive
    f = tmp_path / "d.yaml"
    f.write_bytes(OLD)
    calls = {"n": 0}
    real = FujiDrive.read_param

    def read(self, code):
        calls["n"] += 1
        if calls["n"] == 5:
            self.channel.inner.master.link.ser.unplug()
        return real(self, code)
    monkeypatch.setattr(FujiDrive, "read_param", read)
    r = pdrive("param", "dump", "3", "-o", str(f))
    assert r.exit_code == 1 and "link lost" in r.stderr, r.output
    assert f.read_bytes() == OLD
    assert [p.name for p in tmp_path.iterdir()] == ["d.yaml"]


def test_dump_path_is_checked_before_the_bus(pdrive, tmp_path):
    r = pdrive("param", "dump", "3", "-o", str(tmp_path / "no" / "d.yaml"), port=str(tmp_path / "ttyNONE"))
    assert r.exit_code == 2 and "does not exist" in r.stderr


# -- the same over a real byte path: `pdrive sim --pty` (state persists between commands) ------------

def test_over_a_pty_nothing_rounded_nothing_dangerous_no_partial_restore(tmp_path):
    import subprocess
    from conftest import pdrive_cmd
    from test_pty_bus import _start_sim, _stop
    sim, info = _start_sim(["--pty"])
    port = info["port"]

    def pd(*args):
        return subprocess.run(pdrive_cmd() + list(args) + ["--port", port], capture_output=True, text=True,
                              timeout=120)
    try:
        for args in (("3", "o27", "10.7", "--yes"), ("3", "F07", "0.05", "--yes"), ("3", "P04", "2", "--yes")):
            r = pd("param", "set", *args)
            assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
        f = tmp_path / "bad.yaml"
        f.write_text("parameters:\n  F08: {value: 7.5}\n  F07: {value: 99999}\n")
        r = pd("param", "restore", "3", str(f), "--yes")
        assert r.returncode == 2 and f"{f}:3:" in r.stderr, r.stderr
        r = pd("param", "get", "3", "o27", "F07", "F08", "P04", "--json")
        assert r.returncode == 0, r.stderr
        got = {p["code"]: p["value"] for p in json.loads(r.stdout)["parameters"]}
        assert got == {"o27": 0, "F07": 6.0, "F08": 6.0, "P04": 0}
    finally:
        assert _stop(sim) == 0
