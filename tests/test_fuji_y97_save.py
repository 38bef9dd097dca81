"""OPC-PDP3 y97 (communication data storage selection) and `save`.

PDP3 manual (/work/shared/seeds/000_59efe766ba1d441f.txt):
  L4288-4291: "y97 Communication data storage selection  0  0 to 2 *5,*6"
  L4325-4333 (*6): "The factory default is "0", and updated data is saved to nonvolatile memory. ...
  the setting value should be changed to "1" and the save destination used as volatile memory if
  updating data frequently. By doing so, data is deleted when the power is turned OFF. To save volatile
  memory data to nonvolatile memory, change the setting value to "2". After doing so, check the setting
  value, and if the value has returned to "1", data saving is complete."

So a save writes 2 and waits for 1, which leaves y97 = 1 (RAM only). A drive that stored every write
in EEPROM before (y97 = 0) must get y97 = 0 back, or every later change is lost at power-off.
The simulator keeps an EEPROM copy (sim/fuji.py `eeprom`, `power_cycle()`).
"""

import pytest

from profidrive_cli.drives import make_drive
from profidrive_cli.drives.profile import load_profile
from profidrive_cli.sim.direct import DirectChannel
from profidrive_cli.sim.fuji import make_model


def pdp3(**defaults):
    prof = load_profile("fuji-pdp3")
    model = make_model(prof, defaults=defaults or None)
    ch = DirectChannel(model, prof.layouts["ppo1"].cfg)
    return model, make_drive(ch, prof, "ppo1")


# -- the simulator as the manual says ---------------------------------------------------------------

def test_sim_y97_2_saves_ram_and_reads_1():
    model, d = pdp3(y97=1)
    d.write_param("F07", 4.0)                   # y97 = 1: RAM only
    model.power_cycle()
    assert d.read_param("F07").value != 4.0     # "data is deleted when the power is turned OFF"
    d.write_param("F07", 4.0)
    d.write_raw_code("y97", 2)                  # "change the setting value to 2"
    assert d.read_param("y97").raw == 2         # still saving (the sim takes 1 s)
    for _ in range(200):
        d.cycle()
        if d.read_param("y97").raw == 1:
            break
    assert d.read_param("y97").raw == 1         # "the value has returned to 1": saved
    model.power_cycle()
    assert d.read_param("F07").value == 4.0
    assert d.read_param("y97").raw == 1


def test_sim_y97_0_stores_every_write():
    model, d = pdp3()                           # factory default y97 = 0
    assert d.read_param("y97").raw == 0
    d.write_param("F07", 6.5)
    model.power_cycle()
    assert d.read_param("F07").value == 6.5     # "updated data is saved to nonvolatile memory"


# -- save keeps the drive's save mode ----------------------------------------------------------------

def test_save_on_an_eeprom_drive_leaves_y97_0_and_later_changes_survive():
    model, d = pdp3()                           # y97 = 0
    d.write_param("F07", 4.0)
    d.save()
    assert model.saves == 1                     # the RAM -> EEPROM copy ran (y97 = 2 was written)
    assert d.read_param("y97").raw == 0         # left as found
    d.write_param("F07", 7.0)                   # a later change
    model.power_cycle()
    assert d.read_param("F07").value == 7.0     # still in EEPROM after power-off
    assert d.read_param("y97").raw == 0


def test_save_on_a_ram_drive_leaves_y97_1():
    model, d = pdp3(y97=1)
    d.write_param("F07", 4.0)
    d.save()
    assert model.saves == 1 and d.read_param("y97").raw == 1
    model.power_cycle()
    assert d.read_param("F07").value == 4.0     # saved
    d.write_param("F07", 8.0)                   # RAM only, as the user chose with y97 = 1
    model.power_cycle()
    assert d.read_param("F07").value == 4.0


def test_y97_writes_in_order():
    model, d = pdp3()
    d.save()
    y97 = load_profile("fuji-pdp3").param("y97")
    writes = [r.value for r, _ in model.pkw_log if r.ak in (2, 7) and r.pnu == y97.pnu
              and r.subindex == y97.index]
    assert writes == [2, 0]                     # save, then the mode found (0) back
