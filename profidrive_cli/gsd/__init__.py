"""GSD files: text stage (lexer.py), parser (parser.py: builds the model), data model and module lookup
(model.py), Set_Prm / Chk_Cfg / unit-diag interpreter (interp.py: reads the model) and the device
library lookup (library.py)."""

from profidrive_cli.gsd.interp import (
    PrmField, PrmResult, build_prm, chk_cfg, decode_unit_diag, user_params,
)
from profidrive_cli.gsd.model import BAUDS, ExtUserPrmData, Gsd, Module, PrmBlock, select_module, select_modules
from profidrive_cli.gsd.parser import parse_gsd, parse_gsd_bytes, parse_gsd_text

__all__ = [
    "BAUDS", "ExtUserPrmData", "Gsd", "Module", "PrmBlock", "PrmField", "PrmResult", "build_prm", "chk_cfg",
    "decode_unit_diag", "parse_gsd", "parse_gsd_bytes", "parse_gsd_text", "select_module", "select_modules",
    "user_params",
]
