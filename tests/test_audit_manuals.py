"""`pdrive audit` and the profiles against the card manuals (issue 34, "Against the manuals"): each
case quotes the manual line it stands on (../shared/seeds/, spec ../shared/spec/); expected values
come from the manual or a hand calculation in the comment, never from the code under test.
The simulated plant (sim://): 3 fuji-g1, 4 fuji-pdp3, 5 toyo, 6 moeller, 7 yaskawa."""

from __future__ import annotations

import pytest

import profidrive_cli as pdrive


def audit(url: str, station: int, **kw):
    with pdrive.open_bus(url) as bus:
        (res,) = bus.audit([station], **kw)
    return res


# -- the comm-loss reaction time is the watchdog plus the card's delay -----------------------------

@pytest.mark.parametrize("station", [3, 4, 5, 6, 7])
def test_a_watchdog_alone_above_the_process_limit_is_an_error_on_every_family(station):
    # every family's factory reaction acts when the DP watchdog expires (Fuji o27 = 0, Moeller
    # P002 = 0, Toyo protection 18, Yaskawa F6-01 = 1): the drive runs on its last command for the
    # watchdog itself. Hand calculation: --watchdog 3000 ms is WD_Fact_1 x WD_Fact_2 x 10 ms =
    # 150 x 2 x 10 ms = 3.0 s (bus reference: the watchdog is the two factors times 10 ms), above a
    # 2.8 s limit: an error, whatever the card's delay is (0 here)
    res = audit("sim://?timing=virtual", station, watchdog_ms=3000, max_reaction_s=2.8)
    errs = [f for f in res.findings if f.rule == "comm_loss.delay"]
    assert [f.severity for f in errs] == ["error"], res.findings
    assert "3 s" in errs[0].why and "2.8 s" in errs[0].why
    # the same reaction within the limit: 3.0 s <= 3.5 s
    res = audit("sim://?timing=virtual", station, watchdog_ms=3000, max_reaction_s=3.5)
    assert not [f for f in res.findings if f.rule == "comm_loss.delay"]


def test_the_watchdog_counts_as_the_set_prm_gives_it():
    # OPC-PDP3 Table 9.1 (L6478-6559): o27 = 11 decelerates after the o28 time. --watchdog 2561 ms:
    # ceil(2561 / 10) = 257 units of 10 ms; 257 is prime and above 255, so the Set_Prm's factors
    # hold 129 x 2 = 258 units = 2.58 s at the least. Reaction 2.58 + o28 0.2 = 2.78 s, above a
    # 2.77 s limit (with the 2.561 s asked for it would be 2.761 s, within it)
    res = audit("sim://?timing=virtual&set=4:o27=11,o28=0.2", 4, watchdog_ms=2561, max_reaction_s=2.77)
    assert res.watchdog_s == pytest.approx(2.58)
    (f,) = [f for f in res.findings if f.rule == "comm_loss.delay"]
    assert f.severity == "error" and "2.78 s" in f.why


def test_o28_2_5_against_2_8_is_an_error_the_watchdog_counted():
    # the case: watchdog 500 ms (pdrive's default; 50 x 1 x 10 ms) + o28 2.5 s = 3.0 s on
    # the last command, above --max-reaction 2.8; the fix: o28 at most 2.8 - 0.5 = 2.3 s
    res = audit("sim://?timing=virtual&set=3:o27=11,o28=2.5", 3, max_reaction_s=2.8)
    (f,) = [f for f in res.findings if f.rule == "comm_loss.delay"]
    assert f.severity == "error" and f.check == {"param": "o28", "max": 2.3}
