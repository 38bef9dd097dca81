"""The family hook of `pdrive sniff --station` ("one station, one door": families only in drives/):
Drive.normalise_area(profile, direction, area), a class fact without a bus, reads a decoded area in the
common words of the `drive` object (docs/json.md). bustools/passive.py asks the watched station's Drive
class (drives.drive_class) and names no family; here a family of its own, registered the way a plug-in
is (a Family row, docs/plugins.md), is what passive shows."""

from __future__ import annotations

import ast
from pathlib import Path
from typing import Any

import pytest

from profidrive_cli.bustools.passive import PassiveDecoder, Watched, frame_suffix
from profidrive_cli.dp.capture import Capture
from profidrive_cli.drives import drive_class, registry
from profidrive_cli.drives.base import Drive
from profidrive_cli.drives.profidrive.drive import ProfidriveDrive
from profidrive_cli.drives.profile import load_profile, load_profile_file
from profidrive_cli.fdl import frames as F

ROOT = Path(__file__).resolve().parent.parent
MASTER = 2


def test_the_base_drive_reads_no_area_shape():
    # the base names nothing: a family without its own reading gives the station only
    prof = load_profile("fuji-g1")
    area = {"control_word": {"command": "operate", "set": [], "hex": "0x047F"}}
    assert Drive.normalise_area(prof, "request", area) == {}
    assert Drive.normalise_area(prof, "request", area) is not Drive.normalise_area(prof, "request", area)


def test_each_shipped_family_answers_with_its_own_reading():
    # Fuji and Moeller read their areas with the PROFIdrive core's PPO/PKW reading; Toyo adds mode 1's
    # state; Yaskawa reads its run command / status words and MEMOBUS area
    where = {name: drive_class(load_profile(name)).normalise_area.__func__.__qualname__
             for name in ("fuji-g1", "fuji-pdp3", "moeller", "toyo", "yaskawa")}
    assert where == {"fuji-g1": "ProfidriveDrive.normalise_area",
                     "fuji-pdp3": "ProfidriveDrive.normalise_area",
                     "moeller": "ProfidriveDrive.normalise_area",
                     "toyo": "ToyoDrive.normalise_area", "yaskawa": "YaskawaDrive.normalise_area"}


def _identifiers(path: Path) -> set[str]:
    """Every name the code of a file uses or defines (not its strings, docstrings and comments)."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Name):
            out.add(node.id)
        elif isinstance(node, ast.Attribute):
            out.add(node.attr)
        elif isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            out.add(node.name)
        elif isinstance(node, ast.alias):
            out.add(node.name)
        elif isinstance(node, ast.ImportFrom):
            out.add(node.module or "")
    return out


def test_passive_names_no_family():
    # no area_shape branch, no family's module, words or helpers: passive asks the Drive class
    names = _identifiers(ROOT / "profidrive_cli" / "bustools" / "passive.py")
    assert {"drive_class", "normalise_area"} <= names
    family_words = ("fuji", "moeller", "toyo", "yaskawa", "profidrive.", "memobus", "pkw", "ppo",
                    "area_shape")
    assert [n for n in sorted(names) if any(w in n.lower() for w in family_words)] == []


# -- a family of its own: what passive shows is its hook's answer -------------------------------------

class HookDrive(ProfidriveDrive):
    """The PROFIdrive core's drive, with its own reading of an area (and a record of what it was given)."""

    family = "hooktest"
    calls: list[tuple[str, str, list[str]]] = []

    @classmethod
    def normalise_area(cls, profile: Any, direction: str, area: dict[str, Any]) -> dict[str, Any]:
        cls.calls.append((profile.name, direction, sorted(area)))
        if direction == "request":
            return {"command": "as the hook says", "reference_hz": 12.5}
        return {"state": "hook state", "actual_hz": 7.25, "param": {"text": "hook param"}}


HOOK_PROFILE = """\
profile: hook-card
family: hooktest
title: A card of a family of its own
identity: {ident: 0x4322}
layouts:
  ppo1: {cfg: "F3 F1", pkw: true}
default_layout: ppo1
"""


@pytest.fixture
def hook_profile(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Any:
    row = registry.Family("hooktest", "profidrive_cli.drives.profidrive", f"{__name__}:HookDrive", None,
                          "profidrive_cli.drives.profidrive.config:ProfidriveConfig.from_profile")
    monkeypatch.setattr(registry, "_plugins", {"hooktest": row})
    HookDrive.calls.clear()
    path = tmp_path / "hook-card.yaml"
    path.write_text(HOOK_PROFILE, encoding="utf-8")
    return load_profile_file(path)


def _captured(*telegrams: bytes) -> list[Any]:
    cap = Capture()
    return [c for i, tg in enumerate(telegrams) for c in cap.feed(tg, i * 0.01)]


def test_passive_shows_the_family_hooks_reading(hook_profile: Any) -> None:
    assert drive_class(hook_profile) is HookDrive
    # PPO1: PKW idle, CTW 0x047F, reference 0x2000; the answer STW 0x0337, actual 0x2000
    out_area = bytes.fromhex("00" * 8 + "04 7F 20 00")
    in_area = bytes.fromhex("00" * 8 + "03 37 20 00")
    req = F.encode(F.Frame(F.SD2, 9, MASTER, F.request_fc(F.SRD_HIGH, True, True), out_area))
    rep = F.encode(F.Frame(F.SD2, MASTER, 9, F.DL, in_area))
    dec = PassiveDecoder({9: Watched(9, hook_profile)})
    r, a = (dec.decode(c) for c in _captured(req, rep))
    assert r == {"station": 9, "profile": "hook-card", "direction": "request", "layout": "ppo1",
                 "command": "as the hook says", "reference_hz": 12.5,
                 "text": "as the hook says, reference 12.50 Hz"}
    assert frame_suffix(a) == "  | <- drive 9 (hook-card ppo1): hook state, actual 7.25 Hz; hook param"
    # given the area the family's codec decoded (here the core's decode_area), once per direction
    assert [(name, d) for name, d, _ in HookDrive.calls] == [("hook-card", "request"),
                                                            ("hook-card", "response")]
    assert {"control_word", "reference"} <= set(HookDrive.calls[0][2])
    assert {"status_word", "actual"} <= set(HookDrive.calls[1][2])
