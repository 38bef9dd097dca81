"""Control-word bits as each card defines them, in `pdrive decode` and in the passive (sniff) decoder,
and the OFF2 > OFF3 > OFF1 precedence there.

Manual lines (/work/shared/seeds/):
- Fuji OPC-G1-PDP (001_02ee17c3305f1f71.txt) Table 8.5, L2227: "b8, b9 Not used. --- ---",
  L2230: "b12 to b15 Not used. --- ---".
- Fuji OPC-PDP3 (000_59efe766ba1d441f.txt) L5166: "b8, b9 Not used. --- ---".
- Moeller DE6-NET-DP (003_f2e14cc27342d73f.txt) L542: "8 1 Inching 1 ON ...", L544: "9 Not used",
  "14 to 15 Not used".
- Toyo PBUS66-Z (002_e31e7b20f4f4e720.txt) L2781: "OFF1、OFF2、OFF3 の各命令が２つ以上同時に入力された場合、
  優先順位は高い方から OFF2－OFF3－OFF1の順になります" (several OFFs at once: OFF2 first, then OFF3, then
  OFF1); spec D9: 0x0478 (bits 0, 1, 2 all 0) is treated as OFF2. The PROFIdrive cards (Fuji, Moeller)
  follow the same profile order: OFF2 (coast) before OFF3 (quick stop) before OFF1.
"""

import pytest

from profidrive_cli.bustools.passive import PassiveDecoder, watch_list
from profidrive_cli.drives import decode_area
from profidrive_cli.drives.profile import load_profile
from profidrive_cli.fdl import frames as F
from profidrive_cli.dp.capture import Capture

MASTER = 2


def _ctw_field(profile, layout, hexarea):
    area = decode_area(profile, layout, "request", bytes.fromhex(hexarea))
    return area["control_word"]


@pytest.mark.parametrize("name", ["fuji-g1", "fuji-pdp3"])
def test_fuji_bits_8_9_are_not_jog(name):
    cw = _ctw_field(load_profile(name), "ppo3", "07 7F 20 00")     # 0x047F + bits 8 and 9
    assert "jog" not in cw["command"]
    assert cw["command"] == "operate; bits 8, 9 set (not used by this card)"
    names = {b["bit"]: b["name"] for b in cw["bits"]}
    assert names[8] == "bit 8 (not used)" and names[9] == "bit 9 (not used)"


def test_fuji_bits_12_15_not_used():
    cw = _ctw_field(load_profile("fuji-g1"), "ppo3", "F4 7F 20 00")
    assert cw["command"] == "operate; bits 12, 13, 14, 15 set (not used by this card)"


def test_moeller_bit_8_is_inching_bit_9_not_used():
    prof = load_profile("moeller")
    cw = _ctw_field(prof, "ppo3", "05 7F 00 00")                  # 0x057F: manual's inching 1 (spec 3.5)
    assert cw["command"] == "operate; inching 1"
    cw = _ctw_field(prof, "ppo3", "06 7F 20 00")                  # bit 9 instead
    assert "jog" not in cw["command"] and cw["command"] == "operate; bit 9 set (not used by this card)"


def test_toyo_keeps_its_jog_bits():
    # Toyo mode 0 does define jog 1 / jog 2 on bits 8/9 (toyo-vf66-pbus66z.md L278-279): 0x0507
    cw = _ctw_field(load_profile("toyo"), "ppo3", "07 05 00 00")
    assert "forward jog (jog 1)" in cw["command"]


# -- the passive decoder (sniff --station) --------------------------------------------------------

def _req(da, data):
    return F.encode(F.Frame(F.SD2, da, MASTER, F.request_fc(F.SRD_HIGH, True, True), bytes(data),
                            None, None))


def _sniff(spec, area_hex):
    cap = Capture()
    (c,) = cap.feed(_req(int(spec.split("=")[0]), bytes.fromhex(area_hex)), 0.0)
    return PassiveDecoder(watch_list([spec])).decode(c)


def test_sniff_fuji_bits_8_9_not_jog():
    r = _sniff("3=fuji-pdp3:ppo3", "07 7F 20 00")
    assert "jog" not in r["command"] and "not used by this card" in r["command"]
    assert "jog" not in r["text"]


def test_sniff_moeller_names_inching_and_unused_bit_9():
    r = _sniff("6=moeller:ppo3", "07 7F 00 00")                  # bits 8 and 9
    assert r["command"] == "operate; inching 1; bit 9 set (not used by this card)"


@pytest.mark.parametrize("spec, area, want", [
    # bits 1 and 2 both 0 (OFF2 and OFF3 at once): OFF2 wins
    ("3=fuji-pdp3:ppo3", "04 79 00 00", "OFF2 coast stop"),      # 0x0479
    ("6=moeller:ppo3", "04 79 00 00", "OFF2 coast stop"),
    ("5=toyo:ppo3", "78 04 00 00", "OFF2 coast stop"),           # 0x0478, spec D9 (little-endian)
    # OFF3 and OFF1 at once (bit 2 and bit 0 = 0): OFF3 wins over OFF1
    ("3=fuji-pdp3:ppo3", "04 7A 00 00", "OFF3 quick stop"),      # 0x047A
    ("5=toyo:ppo3", "7A 04 00 00", "OFF3 quick stop"),
])
def test_sniff_off2_before_off3_before_off1(spec, area, want):
    r = _sniff(spec, area)
    assert r["command"].split(";")[0] == want
