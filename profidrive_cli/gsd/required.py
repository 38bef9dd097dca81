"""What a DP slave's GSD file must contain (reference §5): checked after a whole file has parsed, so
that a truncated or foreign file is an error listing what is missing instead of a device without
modules or baud rates that silently replaces a good library file.

Required: Vendor_Name, Model_Name, Ident_Number, Protocol_Ident, Station_Type, at least one
`<baud>_supp = 1`, and for a DP slave (Station_Type 0) at least one Module (a compact station
describes its fixed configuration as its single Module).

Decision: GSD_Revision is NOT required. It was introduced with GSD revision 1; files written to the
original DIN 19245-3 format have no such line and are still valid (the real Eurotherm TC3001 file in
the test data is one). A file without it is read as revision 0, with a warning.
"""

from __future__ import annotations

from profidrive_cli.datafile import DataFileError
from profidrive_cli.gsd.model import Gsd

_KEYWORDS = (("vendor_name", "Vendor_Name"), ("model_name", "Model_Name"), ("ident_number", "Ident_Number"),
             ("protocol_ident", "Protocol_Ident"), ("station_type", "Station_Type"))


def missing_keywords(g: Gsd) -> list[str]:
    """The required keywords (and "a supported baud rate", "a Module") the parsed file lacks."""
    missing = [name for key, name in _KEYWORDS if key not in g.values]
    if not g.supported_bauds():
        missing.append("a supported baud rate (<baud>_supp = 1)")
    if g.station_type in (0, None) and not g.modules:
        missing.append("a Module")
    return missing


def check_complete(g: Gsd, last_line: int) -> None:
    """DataFileError (path:last line) naming every missing keyword; a warning when GSD_Revision is absent."""
    missing = missing_keywords(g)
    if missing:
        raise DataFileError(g.path, last_line, "incomplete GSD file (truncated?): missing "
                            + ", ".join(missing))
    if "gsd_revision" not in g.values:
        g.warnings.append(f"{g.path}:{g.start_line}: no GSD_Revision line (a revision-0 file: accepted)")
