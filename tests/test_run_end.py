"""What a run says at its end after a trip (issue 34): the fault's code and its name, as `pdrive
faults` names them (the profile's alarm table), in the text lines and in the JSON end -- also where
the cyclic words carry no code (Moeller PPO: status word bit 3 only) and the stop reads it.

The trip: the simulator's drivetrip injection on station 6 (sim/faults.py) with a fixed seed on the
virtual clock, so it comes at the same exchange every time; station 6 trips with E01, which the
profile moeller-de6-net-dp names "Inverter overcurrent" (its alarms table, from the DE6 manual).
"""

from __future__ import annotations

import json

from test_run_safety import pdrive

TRIP = "sim://?timing=virtual&drivetrip=0.005&seed=5&only=6"
NAMED = "E01 (Inverter overcurrent)"


def test_after_a_trip_the_last_lines_name_the_fault_code_and_its_name():
    r = pdrive("run", "6", "--hz", "20", "--duration", "4", "--port", TRIP, timeout=300)
    assert r.returncode == 1, (r.stdout, r.stderr)
    last = r.stdout.strip().splitlines()[-1]
    assert last.endswith(f"FAULT {NAMED}"), last
    err = r.stderr.strip().splitlines()
    assert err[-1] == "pdrive: station 6: the drive tripped (E01): Inverter overcurrent; the drive is stopped"
    assert "Traceback" not in r.stderr


def test_after_a_trip_the_json_end_names_the_fault():
    r = pdrive("run", "6", "--hz", "20", "--duration", "4", "--json", "--port", TRIP, timeout=300)
    assert r.returncode == 1, r.stderr
    events = [json.loads(line) for line in r.stdout.splitlines()]
    end = next(e for e in events if e["event"] == "end")
    assert (end["fault"], end["fault_code"], end["fault_name"]) == (True, "E01", "Inverter overcurrent")
    assert end["failed"] and end["problem"] == "tripped (E01): Inverter overcurrent"
    updates = [e for e in events if e["event"] == "update"]
    assert updates[-1]["fault_code"] == "E01"


def test_several_drives_name_the_fault_of_the_one_that_tripped():
    r = pdrive("run", "6,3", "--hz", "20", "--duration", "4", "--json", "--port", TRIP, timeout=300)
    assert r.returncode == 1, r.stderr
    end = next(json.loads(line) for line in r.stdout.splitlines() if json.loads(line)["event"] == "end")
    six = next(s for s in end["stations"] if s["station"] == 6)
    assert (six["fault_code"], six["fault_name"]) == ("E01", "Inverter overcurrent")
    assert end["reason"] == "station 6 tripped (E01): Inverter overcurrent"
