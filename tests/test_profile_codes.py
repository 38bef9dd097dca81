"""Every code a profile names is checked when the profile loads (issue 35): a user profile copied from a
shipped one with `ppo_select: {param: o0}` loaded without complaint and `param diff 9 --defaults` then
died with KeyError: 'o0' in sim/fuji.py. Now the load says file:line, and every command that loads the
profile -- a drive command, `sniff --from-file --station`, `sim --learn` of a capture with the
profile's ident -- gives that one line and exit 2.

The user profiles live in a folder of PDRIVE_PROFILE_PATH; each is a shipped profile's text with one
line changed, and the expected line number is where that text sits in the copy (found in the text,
not from the code under test)."""

from __future__ import annotations

from pathlib import Path

import pytest
from profidrive_cli.datafile import DataFileError
from profidrive_cli.drives import profile as profmod
from profidrive_cli.fdl import frames as F

from test_wireshark import pd  # noqa: F401  (pdrive in this process: the same fixture)

ROOT = Path(__file__).resolve().parent.parent
#: an ident no shipped profile has, so that a lookup by ident finds the copy
IDENT = 0xFD99


def _copy(folder: Path, shipped: str, old: str, new: str) -> tuple[Path, int]:
    """profiles/SHIPPED with `old` replaced by `new`, renamed `mine` (alias mine, ident IDENT), in
    `folder`; (its path, the line of `new`)."""
    text = (ROOT / "profiles" / f"{shipped}.yaml").read_text(encoding="utf-8")
    assert text.count(old) == 1, old
    lines = text.replace(old, new).splitlines()
    for i, line in enumerate(lines):
        if line.startswith("profile: "):
            lines[i] = "profile: mine"
        elif line.startswith("aliases: "):
            lines[i] = "aliases: [mine]"
        elif line.strip().startswith("ident: ") and "ident_" not in line:
            lines[i] = line.split("ident:")[0] + f"ident: 0x{IDENT:04X}"
    path = folder / "mine.yaml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    first_new = new.splitlines()[0]
    return path, next(i + 1 for i, line in enumerate(lines) if first_new in line)


@pytest.fixture
def user_dir(tmp_path, monkeypatch):
    d = tmp_path / "myprofiles"
    d.mkdir()
    monkeypatch.setenv("PDRIVE_PROFILE_PATH", str(d))
    profmod.clear_cache()
    yield d
    profmod.clear_cache()


CASES = [
    # the issue's profile
    ("fuji-opc-g1-pdp", "ppo_select: {param: o30, power_cycle: true}", "ppo_select: {param: o0, power_cycle: true}",
     "ppo_select.param: o0 is not a parameter of this profile"),
    # a family key read only when it was used (the comm-loss test): now on load
    ("fuji-opc-pdp3", "  action_param: o27\n", "  action_param: o99\n",
     "comm_loss.action_param: o99 is not a parameter"),
    # monitors and trip records: the codes were never checked against the parameters
    ("fuji-opc-g1-pdp", "  default: [M09, M11, M12, M07]", "  default: [M09, M11, M99, M07]",
     "monitors.default: M99 is not a parameter of this profile"),
    ("moeller-de6-net-dp", "    - {position: \"2 (d082)\", fields: [d082, PNU362,",
     "    - {position: \"2 (d082)\", fields: [d082, X362,",
     "trip_records.records.fields: X362 is not a parameter of this profile"),
    ("toyo-pbus66z", "  default: [current, output-voltage, torque, dc-voltage]",
     "  default: [current, output-voltage, torque, dc-volts]", "monitors.default: dc-volts is not a parameter"),
]


@pytest.mark.parametrize("shipped, old, new, words", CASES)
def test_a_code_the_profile_does_not_have_is_a_file_line_error_on_load(user_dir, shipped, old, new, words):
    path, line = _copy(user_dir, shipped, old, new)
    with pytest.raises(DataFileError) as e:
        profmod.load_profile("mine")
    assert (Path(e.value.path), e.value.line) == (path, line)
    assert words in str(e.value)


def test_the_shipped_profiles_and_their_unchanged_copies_load(user_dir):
    """The checks refuse nothing the shipped profiles name (Toyo's traceback points TB08[0,99],
    Moeller's raw PNU356, Yaskawa's monitor words included)."""
    for p in sorted((ROOT / "profiles").glob("*.yaml")):
        assert profmod.load_profile_file(p).name == p.stem


def _one_line(code, text, path, line, words):
    assert code == 2, text
    assert len(text.strip().splitlines()) == 1, text
    assert f"{path}:{line}: " in text and words in text and "Traceback" not in text, text


def test_every_command_that_loads_the_issues_profile_gives_one_line_exit_2(user_dir, tmp_path, monkeypatch, pd):
    path, line = _copy(user_dir, *CASES[0][:3])
    words = CASES[0][3]
    monkeypatch.chdir(tmp_path)
    # the issue's command
    _one_line(*pd("param", "diff", "9", "--defaults", "--profile", "mine", "--port", "sim://?stations=9:mine"),
              path, line, words)
    # sniff --from-file with the station decoded by the profile
    dx = F.encode(F.Frame(F.SD2, 9, 2, 0x7D, bytes(12)))
    (tmp_path / "dx.raw").write_bytes(dx)
    (tmp_path / "s.pcap").write_bytes(b"old")
    _one_line(*pd("sniff", "--from-file", "dx.raw", "--station", "9=mine", "--pcap", "s.pcap"), path, line, words)
    assert (tmp_path / "s.pcap").read_bytes() == b"old"
    # sim --learn of a start-up whose Slave_Diag reply carries the profile's ident (octets 4..5, big-endian):
    # FDL request SRD high with SAPs 62 -> 60 to station 9, the reply SAPs 60 -> 62, st1..st3, master, ident
    req = F.encode(F.Frame(F.SD2, 9, 2, 0x6D, b"", 60, 62))
    rep = F.encode(F.Frame(F.SD2, 2, 9, 0x08, bytes([0x02, 0x05, 0x00, 0xFF]) + IDENT.to_bytes(2, "big"), 62, 60))
    (tmp_path / "startup.raw").write_bytes(req + rep)
    _one_line(*pd("sim", "--learn", "startup.raw", "--pty"), path, line, words)
