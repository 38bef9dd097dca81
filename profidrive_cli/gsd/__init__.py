"""GSD files: text stage (lexer.py), parser (parser.py: builds the model), data model and module lookup
(model.py), Set_Prm / Chk_Cfg / unit-diag interpreter (interp.py: reads the model), the device
library lookup (library.py), the modules that give a configuration (match.py) and a slave's cyclic data
by module (slavedata.py).

The names below are loaded from their module on first use (PEP 562), so that `scan`, which only asks
the library for a station's name, does not import the parser and the interpreter.
"""

from __future__ import annotations

import importlib
from typing import Any

_WHERE = {
    "PrmField": "interp", "PrmResult": "interp", "build_prm": "interp", "chk_cfg": "interp",
    "decode_unit_diag": "interp", "user_params": "interp", "decode_user_prm": "interp",
    "match_cfg": "match", "explain_refusal": "match", "layout": "slavedata", "SlaveLayout": "slavedata",
    "BAUDS": "model", "ExtUserPrmData": "model", "Gsd": "model", "Module": "model",
    "PrmBlock": "model", "select_module": "model", "select_modules": "model",
    "parse_gsd": "parser", "parse_gsd_bytes": "parser", "parse_gsd_text": "parser",
}

__all__ = sorted(_WHERE)


def __getattr__(name: str) -> Any:     # whatever the submodule defines under that name
    mod = _WHERE.get(name)
    if mod is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{mod}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_WHERE))
