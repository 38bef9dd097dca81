"""Torque bounds and the torque-limit word per layout.

- The accepted range is -200..200 % of rated torque, both signs (drives/torque.py decision: "a torque
  reference or limit is accepted in -200..200 %"); a negative torque below -200 % must be refused just
  like a positive one above 200 %.
- Yaskawa SI-P1: in the 3-word basic message output bytes 4-5 are the torque reference only
  (yaskawa-profibus-dp.md L412, §2.6: "| 4-5 | Torque reference; flux-vector mode ..."); only the
  16-word Extended Data 1 message has "Torque reference / torque limit" and "Torque compensation"
  (L341-342). So --torque-limit is refused on basic (and extended2), exit 2, before anything moves.
"""

import pytest

from profidrive_cli import UsageError
from profidrive_cli.drives import make_drive
from profidrive_cli.drives.base import DriveError
from profidrive_cli.drives.profile import load_profile
from profidrive_cli.drives.torque import TORQUE_MAX_PERCENT, capability_refusal, torque_counts
from profidrive_cli.sim.direct import DirectChannel
from profidrive_cli.sim.yaskawa import make_model as yaskawa_model
from test_run_safety import pdrive


# -- the range, both signs ----------------------------------------------------------------------

@pytest.mark.parametrize("percent", [-200.1, -250.0, -1000.0, 200.1, 250.0])
def test_torque_beyond_200_percent_refused_either_sign(percent):
    with pytest.raises(UsageError, match=r"outside -200\.\.200 %"):
        torque_counts(percent, 0.1)


def test_torque_at_the_bounds_accepted():
    assert TORQUE_MAX_PERCENT == 200.0
    assert torque_counts(-200.0, 0.1) == -2000          # 0.1 % a count (Yaskawa): -200 / 0.1
    assert torque_counts(200.0, 0.02) == 10000          # 5000 = 100 % (Toyo): 200 % = 10000


def _yaskawa(layout, **opts):
    prof = load_profile("yaskawa")
    model = yaskawa_model(prof, **opts)
    ch = DirectChannel(model, prof.layouts[layout].cfg)
    return model, ch, make_drive(ch, prof, layout)


def test_yaskawa_negative_torque_beyond_200_refused_by_the_drive():
    model, ch, d = _yaskawa("extended1", A1_02=3)
    with pytest.raises(UsageError, match="outside"):
        d.set_torque(-200.5)
    assert d.torque_reference == 0.0                    # nothing set


def test_cli_refuses_negative_torque_beyond_200():
    r = pdrive("run", "5", "--ppo", "5", "--torque", "-250", "--duration", "1", "--port", "sim://")
    assert r.returncode == 2, r.stderr
    assert "outside -200..200 %" in r.stderr and "Traceback" not in r.stderr


# -- the torque-limit word per layout (Yaskawa) -------------------------------------------------

@pytest.mark.parametrize("layout", ["basic", "extended2"])
def test_yaskawa_torque_limit_refused_without_the_limit_word(layout):
    model, ch, d = _yaskawa(layout, A1_02=3)
    why = d.torque_limit_support()
    assert why is not None
    with pytest.raises(DriveError):
        d.set_torque_limit(50.0)


def test_yaskawa_basic_refusal_is_the_capability_refusal():
    prof = load_profile("yaskawa")
    model, ch, d = _yaskawa("basic", A1_02=3)
    words = capability_refusal(prof, "torque_limit", "basic")
    assert words is not None and "Extended Data 1" in words
    assert d.torque_limit_support() == words
    assert d.torque_support() is None                    # basic keeps its torque reference (L412)
    model, ch, d = _yaskawa("extended1", A1_02=3)
    assert d.torque_limit_support() is None and capability_refusal(prof, "torque_limit", "extended1") is None


def test_cli_run_torque_limit_on_basic_refused_before_anything_moves():
    r = pdrive("run", "7", "--format", "basic", "--hz", "30", "--torque-limit", "50", "--duration", "1",
               "--port", "sim://", timeout=120)
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pdrive: --torque-limit: "), r.stderr
    assert "cannot take a torque limit" in lines[0] and "Extended Data 1" in lines[0]
    assert "reached" not in r.stdout and "running" not in r.stdout
