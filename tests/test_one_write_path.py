"""One write path (docs/architecture.md, "The house after issue 36", **One write path**): a family
implements only the hook Drive.write_resolved(info, value); Drive.write_param(code, value) is the base
class's one method (resolve with param_info, the read-only and exact-value checks, then
write_resolved), overridden by no family. Before this, PROFIdrive (Fuji G1, Fuji PDP3, Moeller) and
Toyo each had their own write_param that wrote without passing write_resolved, and Yaskawa's had its
own checks in its own order; on that code both tests below fail (the ast walk names
drives/profidrive/drive.py, drives/toyo/drive.py and drives/yaskawa/drive.py; the sim writes of
stations 3, 4, 5 and 6 through write_param never reach write_resolved).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import profidrive_cli as pdrive
from profidrive_cli.drives.base import ParamValue

DRIVES = Path(__file__).resolve().parent.parent / "profidrive_cli" / "drives"

#: the default sim:// plant's stations -> a code each family writes and a value the profile allows
#: (Toyo publishes no PNU for its settings: a raw PNU, which the session checks as a 16-bit word)
WRITES = {3: ("fuji-g1", "F07", 2.5), 4: ("fuji-pdp3", "E31", 40.0), 5: ("toyo", "PNU5", 1),
          6: ("moeller", "F002", 1.5), 7: ("yaskawa", "C1-01", 4.0)}


def _write_param_definitions() -> list[str]:
    """file:line of every `def write_param` inside a class in drives/, but base.Drive's."""
    found = []
    for f in sorted(DRIVES.rglob("*.py")):
        tree = ast.parse(f.read_text(encoding="utf-8"), str(f))
        for cls in (n for n in ast.walk(tree) if isinstance(n, ast.ClassDef)):
            for node in cls.body:
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name == "write_param":
                    where = f"{f.relative_to(DRIVES.parent).as_posix()}:{node.lineno} {cls.name}"
                    if where.startswith("drives/base.py:") and cls.name == "Drive":
                        continue
                    found.append(where)
    return found


def test_no_family_defines_write_param():
    assert _write_param_definitions() == [], \
        "a family defines its own write_param (implement write_resolved instead):\n" + \
        "\n".join(_write_param_definitions())


def test_base_write_param_is_defined_once_and_final():
    from profidrive_cli.drives.base import Drive
    tree = ast.parse((DRIVES / "base.py").read_text(encoding="utf-8"))
    drive = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "Drive")
    defs = {n.name: n for n in drive.body if isinstance(n, ast.FunctionDef)}
    assert "write_param" in defs and "write_resolved" in defs
    # write_resolved is the family's hook: the base does not write through write_param (no cycle)
    calls = [n for n in ast.walk(defs["write_resolved"])
             if isinstance(n, ast.Attribute) and n.attr == "write_param"]
    assert calls == []
    assert getattr(Drive.write_param, "__final__", False) is True        # typing.final: mypy refuses overrides


@pytest.mark.parametrize("address", sorted(WRITES))
def test_write_param_and_plan_execute_reach_the_same_write_resolved(monkeypatch, address):
    profile, code, value = WRITES[address]
    with pdrive.open_bus("sim://?timing=virtual") as bus:
        station = bus.drive(address)._station
        d = station.need_drive()
        assert profile.split("-")[0] in d.family
        seen: list[tuple[str, str, float | int]] = []

        def recorded(info, v):                  # nothing reaches the card: the route is the point
            seen.append((info.code, type(info).__name__, v))
            return ParamValue(info.code, info.name, int(v), v, info.unit)
        monkeypatch.setattr(d, "write_resolved", recorded)

        d.write_param(code, value)
        params = station.params
        params.execute(params.plan(code, value))
        assert len(seen) == 2, f"station {address} ({profile}): write_resolved calls {seen}"
        assert seen[0] == seen[1]
