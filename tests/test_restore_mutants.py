"""session/restore.py sans-IO: validate every row, then write only what differs, each read back.

A fake Parameters (session/parameters.py; what restore.py uses of it: session/params.ParamView) hands
restore() the rows compare() would give (session/backup.ParamRow) and records every bus write; the profile is the real Fuji OPC-G1-PDP one (ident 0xFD01, alias fuji-g1; F08
deceleration time 1 in 0.1 s steps, so a read-back within half a step, 0.05 s, is the value
written). The rule (module doc, docs/commands.md "param restore"): any problem -> RestoreRefused
listing them all with file:line, nothing written; a failure part-way -> RestoreInterrupted whose rows
say applied / unknown / not written / refused. Written for mutation testing
(tools/mutation/run.py session/restore.py).
"""

from types import SimpleNamespace

import pytest

import profidrive_cli.session.restore as rs
from profidrive_cli import BusError, UsageError
from profidrive_cli.drives.base import DriveError, DriveStatus, ParamValue
from profidrive_cli.drives.profile import load_profile
from profidrive_cli.session.backup import ParamRow

FUJI = load_profile("fuji-opc-g1-pdp")
PATH = "/tmp/plant.yaml"


def status(running, speed):
    return DriveStatus(state="x", running=running, fault=False, flags={}, speed_percent=speed,
                       speed_hz=None)


class Drive:
    def __init__(self, st=None, keeps=None, fail=None):
        self.st = st or status(False, 0.0)
        self.keeps = keeps or {}          # code -> the value the drive keeps instead
        self.fail = fail or {}            # code -> exception on write
        self.values: dict[str, float] = {}
        self.log: list[tuple] = []
        self.cycles = 0

    def cycle(self):
        self.cycles += 1
        return self.st

    def write_param(self, code, value):
        self.log.append(("write", code, value))
        if code in self.fail:
            raise self.fail[code]
        self.values[code] = self.keeps.get(code, value)

    def read_param(self, code):
        self.log.append(("read", code))
        return ParamValue(code, code, 0, self.values[code], "s")

    def read_resolved(self, info):
        return self.read_param(info.code)


class Session:
    def __init__(self, rows=(), drive=None, access=None, dangers=None):
        self.profile = FUJI
        self.ident = 0xFD01
        self.address = 3
        self.drive = drive or Drive()
        self.rows = list(rows)
        self.access = access or {}        # code -> "rw" / "stop"
        self.dangers = dangers or {}      # code -> what writing it does
        self.warnings: list[str] = []
        self.compared = []
        self.executed = []

    def warn(self, text):
        self.warnings.append(text)

    def need_drive(self):
        return self.drive

    def compare(self, doc, progress, allow_dangerous=False, check_identity=True):
        self.compared.append((progress, allow_dangerous, check_identity))
        return self.rows

    def info(self, code):
        return SimpleNamespace(code=code, name=code, access=self.access.get(code, "rw"))

    def danger_of(self, info):
        return self.dangers.get(info.code)

    def execute(self, plan, check_running=True):
        self.executed.append((plan.info.code, check_running))
        return self.drive.write_param(plan.info.code, plan.value)


@pytest.fixture
def checked(monkeypatch):
    """restore's check of a row, Parameters.plan, recorded (its own rules are session/parameters.py's,
    tested there)."""
    calls = []
    refuse = {}

    def plan(session, info, value, allow_dangerous=False):
        calls.append((info.code, value, allow_dangerous))
        if info.code in refuse:
            raise UsageError(refuse[info.code])
        return SimpleNamespace(info=info, value=value)
    monkeypatch.setattr(Session, "plan", plan, raising=False)
    return SimpleNamespace(calls=calls, refuse=refuse)


def row(code, result, file_value=1.0, line=0, why="", reason="", drive_value=0.0):
    return ParamRow(code, f"name of {code}", "s", file_value, drive_value, result, reason, line=line,
                    why=why)


def doc(station=None, **kw):
    d = {"_path": PATH, "station": station or {}}
    d.update(kw)
    return d


# -- the two errors --------------------------------------------------------------------------------

def test_refused_message_names_the_first_and_counts_the_rest():
    e = rs.RestoreRefused(["a: one"])
    assert str(e) == "nothing was written: a: one" and e.problems == ["a: one"]
    e = rs.RestoreRefused(["a", "b"])
    assert str(e) == "nothing was written: a (and 1 more problem(s))"
    e = rs.RestoreRefused(["a", "b", "c"])
    assert str(e) == "nothing was written: a (and 2 more problem(s))"
    assert isinstance(e, UsageError)


def test_interrupted_counts_landed_and_left():
    rows = [row("A", "applied"), row("B", "applied"), row("C", "unknown"), row("D", "not written"),
            row("E", "refused"), row("F", "unchanged"), row("G", "skipped")]
    cause = BusError("no answer")
    e = rs.RestoreInterrupted(rows, cause)
    assert str(e) == ("restore interrupted: no answer; 2 row(s) written and read back, 3 not "
                      "(see the table)")
    assert e.rows is rows and e.cause is cause and isinstance(e, BusError)


# -- identity --------------------------------------------------------------------------------------

def test_same_profile_by_name_or_alias_and_same_ident_is_fine(checked):
    s = Session()
    assert rs.restore_problems(s, doc({"profile": "fuji-opc-g1-pdp", "ident": "0xFD01"}), []) == []
    assert rs.restore_problems(s, doc({"profile": "fuji-g1", "ident": 0xFD01}), []) == []
    assert rs.restore_problems(s, doc({}), []) == []


def test_another_profile_is_a_problem():
    s = Session()
    p = rs.restore_problems(s, doc({"profile": "toyo-pbus66z", "title": "Toyo VF66"}), [])
    assert p == [f"{PATH}: dumped from a toyo-pbus66z station (Toyo VF66); station 3 is "
                 f"fuji-opc-g1-pdp (Fuji FRENIC-MEGA, OPC-G1-PDP, family fuji, ident 0xFD01)"]


def test_an_unknown_profile_is_a_problem():
    p = rs.restore_problems(Session(), doc({"profile": "no-such-card"}), [])
    assert len(p) == 1 and p[0].startswith(f"{PATH}: dumped from a no-such-card station (); station 3 is")


@pytest.mark.parametrize("ident", ["0x0BE7", "junk", 0x0BE7])
def test_another_ident_is_a_problem(ident):
    p = rs.restore_problems(Session(), doc({"ident": ident}), [])
    assert p == [f"{PATH}: dumped from a station with ident {ident}; station 3 reports 0xFD01"]


def test_without_a_path_the_file_is_named_the_file():
    p = rs.restore_problems(Session(), {"station": {"ident": "0x1"}}, [])
    assert p == ["the file: dumped from a station with ident 0x1; station 3 reports 0xFD01"]
    p = rs.restore_problems(Session(), {}, [row("F08", "missing", line=4, reason="x")])
    assert p == ["the file:4: F08: cannot be read from the drive: x"]


# -- per row ---------------------------------------------------------------------------------------

def test_row_problems_with_file_and_line(checked):
    rows = [row("F08", "missing", line=7, reason="no answer"),
            row("Q99", "skipped", line=8, why="unknown", reason="unknown parameter 'Q99'"),
            row("F03", "skipped", line=9, why="read-only"),
            row("S05", "skipped", line=10, why="not restored", reason="command data"),
            row("F07", "applied", line=11),
            row("E31", "missing", line=0, reason="gone")]
    p = rs.restore_problems(Session(), doc(), rows)
    assert p == [f"{PATH}:7: F08: cannot be read from the drive: no answer",
                 f"{PATH}:8: Q99: unknown parameter 'Q99'",
                 f"{PATH}:9: F03 (name of F03) is read-only",
                 f"{PATH}: E31: cannot be read from the drive: gone"]
    assert checked.calls == []                 # none of these is a row to write


def test_rows_to_write_are_checked_with_their_value(checked):
    rows = [row("F07", "differs", 2.5, line=3), row("F08", "unchanged", 6.0, line=4)]
    checked.refuse["F07"] = "F07 (Acceleration time 1): 2.55 s is not a multiple of 0.1 s"
    p = rs.restore_problems(Session(), doc(), rows)
    assert p == [f"{PATH}:3: F07 (Acceleration time 1): 2.55 s is not a multiple of 0.1 s"]
    assert checked.calls == [("F07", 2.5, True), ("F08", 6.0, True)]


def test_dangerous_rows_are_skipped_with_the_reason(checked):
    s = Session(dangers={"H03": "resets the function codes"})
    rows = [row("H03", "differs", 1, line=5), row("F07", "differs", 2.0, line=6)]
    assert rs.restore_problems(s, doc(), rows) == []
    assert (rows[0].result, rows[0].why) == ("skipped", "dangerous")
    assert rows[0].reason == "dangerous: writing it resets the function codes (--allow-dangerous writes it)"
    assert rows[1].result == "differs"
    assert checked.calls == [("F07", 2.0, True)]


def test_dangerous_rows_allowed_are_checked_and_kept(checked):
    s = Session(dangers={"H03": "resets the function codes"})
    rows = [row("H03", "differs", 1, line=5)]
    assert rs.restore_problems(s, doc(), rows, allow_dangerous=True) == []
    assert rows[0].result == "differs" and checked.calls == [("H03", 1, True)]


def test_a_row_compare_already_skipped_as_dangerous_gets_the_words(checked):
    s = Session(dangers={"H03": "resets the function codes"})
    r1 = row("H03", "skipped", why="dangerous", reason="dangerous")
    r2 = row("H04", "skipped", why="dangerous", reason="initialises")      # danger_of: None
    assert rs.restore_problems(s, doc(), [r1, r2]) == []
    assert r1.reason == "dangerous: writing it resets the function codes (--allow-dangerous writes it)"
    assert r2.reason == "dangerous: writing it initialises (--allow-dangerous writes it)"
    assert checked.calls == []


def test_stop_only_rows_while_running(checked):
    d = Drive(status(True, 40.0))
    s = Session(drive=d, access={"F07": "stop", "F08": "stop", "E31": "stop"})
    rows = [row("F07", "differs", 1.0, line=3), row("F08", "differs", 2.0, line=4),
            row("E31", "unchanged", 3.0, line=5)]
    p = rs.restore_problems(s, doc(), rows)
    assert p == [f"{PATH}:3: F07 (name of F07) can only be changed while the motor is stopped, and the "
                 f"drive is running; stop it first",
                 f"{PATH}:4: F08 (name of F08) can only be changed while the motor is stopped, and the "
                 f"drive is running; stop it first"]
    assert d.cycles == 1                        # asked once for all rows


def test_stop_only_rows_coasting_down_count_as_running(checked):
    s = Session(drive=Drive(status(False, 12.0)), access={"F07": "stop"})
    assert len(rs.restore_problems(s, doc(), [row("F07", "differs", 1.0)])) == 1


def test_stop_only_rows_when_stopped_and_rw_rows_when_running_are_fine(checked):
    s = Session(drive=Drive(status(False, 0.0)), access={"F07": "stop"})
    assert rs.restore_problems(s, doc(), [row("F07", "differs", 1.0)]) == []
    d = Drive(status(True, 40.0))
    s = Session(drive=d)
    assert rs.restore_problems(s, doc(), [row("F07", "differs", 1.0)]) == []
    assert d.cycles == 0


# -- restore ---------------------------------------------------------------------------------------

def test_problems_refuse_everything_and_write_nothing(checked):
    d = Drive()
    s = Session([row("F07", "differs", 1.0), row("F08", "missing", line=4, reason="x"),
                 row("E31", "missing", line=5, reason="y")], drive=d)
    with pytest.raises(rs.RestoreRefused) as e:
        rs.restore(s, doc())
    assert e.value.problems == [f"{PATH}:4: F08: cannot be read from the drive: x",
                                f"{PATH}:5: E31: cannot be read from the drive: y"]
    assert d.log == []


def test_warnings_and_the_compare_call(checked):
    s = Session([])
    prog = object()
    assert rs.restore(s, doc(_warnings=["old file", "no ident"]), progress=prog, allow_dangerous=True) == []
    assert s.warnings == ["old file", "no ident"]
    assert s.compared == [(prog, True, False)]     # identity: restore_problems refuses, not warns
    rs.restore(s, doc())
    assert s.compared[-1] == (None, False, False)


def test_allow_dangerous_reaches_the_checks_and_writes_the_row(checked):
    d = Drive()
    rows = [row("H03", "differs", 1.0)]
    out = rs.restore(Session(rows, drive=d, dangers={"H03": "resets the function codes"}), doc(),
                     allow_dangerous=True)
    assert out[0].result == "applied" and d.log == [("write", "H03", 1.0), ("read", "H03")]
    d = Drive()
    rows = [row("H03", "differs", 1.0)]
    out = rs.restore(Session(rows, drive=d, dangers={"H03": "resets the function codes"}), doc())
    assert out[0].result == "skipped" and d.log == []


def test_dry_run_writes_nothing(checked):
    d = Drive()
    rows = [row("F07", "differs", 1.0), row("F08", "unchanged", 6.0)]
    out = rs.restore(Session(rows, drive=d), doc(), dry_run=True)
    assert [r.result for r in out] == ["would apply", "unchanged"] and d.log == []


def test_writes_only_what_differs_each_read_back(checked):
    d = Drive(keeps={"F08": 6.04})               # within half a 0.1 s step of 6.0
    rows = [row("F07", "differs", 2.5), row("E31", "unchanged", 60.0), row("F08", "differs", 6.0)]
    out = rs.restore(Session(rows, drive=d), doc())
    assert d.log == [("write", "F07", 2.5), ("read", "F07"), ("write", "F08", 6.0), ("read", "F08")]
    assert [r.result for r in out] == ["applied", "unchanged", "applied"]
    assert out[0].new_value == 2.5 and out[2].new_value == 6.04


def test_a_value_the_drive_does_not_keep_stops_the_restore(checked):
    d = Drive(keeps={"F08": 6.06})               # more than half a step away: not what was written
    rows = [row("F08", "differs", 6.0), row("F07", "differs", 2.5)]
    with pytest.raises(rs.RestoreInterrupted) as e:
        rs.restore(Session(rows, drive=d), doc())
    assert [r.result for r in e.value.rows] == ["refused", "not written"]
    assert rows[0].reason == "the drive kept 6.06 s" and rows[0].new_value == 6.06
    assert isinstance(e.value.cause, DriveError) and str(e.value.cause) == "F08: the drive kept 6.06 s"
    assert ("write", "F07", 2.5) not in d.log


def test_an_indexed_code_uses_its_parameters_step(checked):
    d = Drive(keeps={"F08[0]": 6.04})
    out = rs.restore(Session([row("F08[0]", "differs", 6.0)], drive=d), doc())
    assert out[0].result == "applied"


def test_a_code_without_a_profile_entry_must_match_exactly(checked):
    d = Drive(keeps={"REG0x0100": 6.04})
    with pytest.raises(rs.RestoreInterrupted):
        rs.restore(Session([row("REG0x0100", "differs", 6.0)], drive=d), doc())


def test_a_bus_error_mid_way_says_what_landed(checked):
    cause = BusError("no answer from station 3")
    d = Drive(fail={"F08": cause})
    rows = [row("F07", "differs", 2.5), row("F08", "differs", 6.0), row("E31", "differs", 50.0)]
    with pytest.raises(rs.RestoreInterrupted) as e:
        rs.restore(Session(rows, drive=d), doc())
    assert [r.result for r in rows] == ["applied", "unknown", "not written"]
    assert rows[1].reason == "the write or its read-back did not complete: no answer from station 3"
    assert e.value.cause is cause and e.value.__cause__ is cause
    assert "1 row(s) written and read back, 2 not" in str(e.value)


def test_a_refused_write_mid_way(checked):
    cause = UsageError("F08: out of range")
    d = Drive(fail={"F08": cause})
    rows = [row("F08", "differs", 6.0), row("F07", "differs", 2.5)]
    with pytest.raises(rs.RestoreInterrupted) as e:
        rs.restore(Session(rows, drive=d), doc())
    assert [r.result for r in rows] == ["refused", "not written"]
    assert rows[0].reason == "F08: out of range" and e.value.cause is cause
    assert e.value.__cause__ is cause


def test_each_write_executes_its_plan_without_a_second_running_check(checked):
    # the rows were checked with the drive stopped (restore_problems, before the first write): the
    # writes themselves take no second look per row (check_running=False, exactly)
    d = Drive()
    rows = [row("F07", "differs", 2.5), row("F08", "differs", 6.0)]
    s = Session(rows, drive=d)
    rs.restore(s, doc())
    assert s.executed == [("F07", False), ("F08", False)]
    assert all(flag is False for _, flag in s.executed)
