"""A line of drives (`pdrive param fleet`), at the station level of the API (api/station.py): dumps of
several stations as a station x code matrix, odd values against the majority of the same profile,
the golden file with its exceptions (session/fleet.py does the work)."""

from profidrive_cli.session.fleet import (FleetDiff, compare, dump_file_name, from_dump, load_dir,
                                          load_golden, parse_stations)

__all__ = ["FleetDiff", "compare", "dump_file_name", "from_dump", "load_dir", "load_golden",
           "parse_stations"]
