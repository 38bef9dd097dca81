"""Issue 25 step 2: a parameter write is resolved once and checked once (session/parameters.py:
Parameters.plan -> WritePlan, Parameters.execute). `pdrive param set` on sim:// and the API's
Drive.set_param, for each family with a writable parameter, counted by wrapping the family's Drive:

  * Drive.param_info: how the family addresses the code (the session's one resolve);
  * the codec's own resolve under it (PROFIdrive/Fuji/Moeller/Toyo resolve_param, Yaskawa _resolve):
    also once -- value_problem, the read of the old value, the write and its read back use the
    resolved address (ParamInfo.ref) through Drive.read_resolved / write_resolved;
  * Drive.value_problem: the exact-value check, once.

Before step 2 one `param set 3 F07 2.5` made 3 param_info calls, 9 codec resolves and 2
value_problem calls (each check ran in the CLI, then again in write_param, then in the codec).
The written value is read back as before (expected values: tests/test_drive_cmds.py WRITABLE, the
profiles' factory values: Fuji F07 6.0 s, Fuji PDP3 E31 60 Hz, Moeller F002 5.0 s, Yaskawa C1-01 10 s).
"""

from __future__ import annotations

import collections
import functools
import json

import pytest

import profidrive_cli as pdrive
from profidrive_cli.cli.main import main
from profidrive_cli.drives import drive_class
from profidrive_cli.drives.base import Drive, DriveError
from profidrive_cli.drives.profile import load_profile
from profidrive_cli import UsageError

#: station -> (profile, a writable code, a value it holds exactly, factory value)
WRITABLE = {3: ("fuji-opc-g1-pdp", "F07", "2.5", 6.0), 4: ("fuji-opc-pdp3", "E31", "40", 60.0),
            6: ("moeller-de6-net-dp", "F002", "1.5", 5.0), 7: ("yaskawa-si-p1", "C1-01", "4", 10.0)}

pytestmark = pytest.mark.usefixtures("no_config_at_all")


@pytest.fixture
def counted(monkeypatch):
    """Wrap every Drive class's param_info, value_problem and codec resolve (on each class that
    defines one, so a subclass's super() call is counted once per class it passes)."""
    calls: collections.Counter = collections.Counter()

    def wrap(cls, name, label):
        f = cls.__dict__.get(name)
        if f is None:
            return

        @functools.wraps(f)
        def w(*a, **k):
            calls[label] += 1
            return f(*a, **k)
        monkeypatch.setattr(cls, name, w)
    seen: set[type] = set()
    for _, (prof, _, _, _) in WRITABLE.items():
        for cls in drive_class(load_profile(prof)).__mro__:
            if cls in seen or not issubclass(cls, Drive):
                continue
            seen.add(cls)
            wrap(cls, "param_info", "param_info")
            wrap(cls, "value_problem", "value_problem")
            wrap(cls, "resolve_param", "resolve")
            wrap(cls, "_resolve", "resolve")
    return calls


def _cli(capsys, *args):
    capsys.readouterr()
    try:
        main(list(args) + ["--port", "sim://"])
        code = 0
    except SystemExit as e:
        code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
    out = capsys.readouterr()
    assert code == 0, out.out + out.err
    return out.out


@pytest.mark.parametrize("address", sorted(WRITABLE))
def test_param_set_resolves_once_and_checks_once(sim, monkeypatch, capsys, counted, address):
    monkeypatch.setenv("PDRIVE_PORT", "")
    _, code, value, factory = WRITABLE[address]
    counted.clear()
    d = json.loads(_cli(capsys, "param", "set", str(address), code, value, "--yes", "--json"))
    assert dict(counted) == {"param_info": 1, "resolve": 1, "value_problem": 1}
    assert d["old"]["value"] == pytest.approx(factory) and d["new"]["value"] == pytest.approx(float(value))


def test_api_set_param_resolves_once_and_checks_once(counted):
    with pdrive.open_bus("sim://?timing=virtual") as bus:
        for address, (_, code, value, _) in sorted(WRITABLE.items()):
            drive = bus.drive(address)
            counted.clear()
            p = drive.set_param(code, float(value))
            assert dict(counted) == {"param_info": 1, "resolve": 1, "value_problem": 1}, address
            assert p.value == pytest.approx(float(value))
            counted.clear()
            assert drive.param(code).value == pytest.approx(float(value))
            assert dict(counted) == {"param_info": 1, "resolve": 1}, address      # a read: no check


def test_a_plan_is_checked_before_anything_is_written_and_executed_without_a_second_check():
    # Fuji F07 (acceleration time 1): 0..6000 s in 0.1 s steps (profile; tests/test_exact_values.py)
    with pdrive.open_bus("sim://?timing=virtual") as bus:
        params = bus.drive(3)._station.params
        plan = params.plan("F07", "2.5")
        assert (plan.code, plan.info.code, plan.value, plan.text) == ("F07", "F07", 2.5, "2.5")
        assert plan.danger is None and not plan.stop_only
        with pytest.raises(UsageError, match="nearest 2.5 s or 2.6 s"):
            params.plan("F07", "2.55")
        with pytest.raises(UsageError, match="is dangerous"):
            params.plan("H03", 1)             # data initialisation (fuji-opc-g1-pdp.yaml:116, dangerous)
        danger = params.plan("H03", 0, allow_dangerous=True)
        assert danger.dangerous and danger.allowed and "factory values" in (danger.danger or "")
        assert params.execute(plan).value == pytest.approx(2.5)
        assert params.read("F07").value == pytest.approx(2.5)


def test_execute_refuses_a_stop_only_parameter_while_the_motor_turns():
    # Fuji F03 (maximum frequency) may only change while stopped (profiles/fuji-opc-g1-pdp.yaml:111, access: stop)
    with pdrive.open_bus("sim://?timing=virtual") as bus:
        d = bus.drive(3)
        params = d._station.params
        plan = params.plan("F03", "50")
        assert plan.stop_only
        d.run(hz=10.0)
        with pytest.raises(DriveError, match="only be changed while the motor is stopped"):
            params.execute(plan)
        d.stop()
        assert params.execute(plan).value == pytest.approx(50.0)
