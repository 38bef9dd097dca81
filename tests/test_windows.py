"""Windows as a first-class platform (issue 26), as far as a Linux machine can test it.

No POSIX-only module is imported at import time, read from the source as the layering tests read
imports: a module-level import of a standard module Windows does not have (termios, fcntl, pty, tty,
resource, grp, pwd) must sit under a platform test (`if os.name == "posix":`, `sys.platform`) or a
`try: ... except ImportError`; inside a function it is loaded only when that POSIX-only path runs (a
pty, a serial port's parity marking). And the user's config file is where Windows programs keep
theirs (%APPDATA%)."""

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parent.parent / "profidrive_cli"
POSIX_ONLY = {"termios", "fcntl", "pty", "tty", "resource", "grp", "pwd"}


def _guarded(test: ast.expr) -> bool:
    text = ast.unparse(test)
    return "os.name" in text or "sys.platform" in text or "platform.system" in text


def _unguarded_imports(body: list[ast.stmt]) -> list[tuple[int, str]]:
    out: list[tuple[int, str]] = []
    for node in body:
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names if a.name.split(".")[0] in POSIX_ONLY]
        elif isinstance(node, ast.ImportFrom):
            if (node.module or "").split(".")[0] in POSIX_ONLY:
                out.append((node.lineno, node.module or ""))
        elif isinstance(node, ast.If):
            if not _guarded(node.test):
                out += _unguarded_imports(node.body) + _unguarded_imports(node.orelse)
        elif isinstance(node, ast.Try):
            catches = {ast.unparse(h.type) for h in node.handlers if h.type is not None}
            if not catches & {"ImportError", "ModuleNotFoundError"}:
                out += _unguarded_imports(node.body)
        elif isinstance(node, ast.ClassDef):
            out += _unguarded_imports(node.body)        # a class body runs at import time
    return out


def test_no_module_imports_a_posix_only_module_at_import_time():
    bad = []
    for f in sorted(PKG.rglob("*.py")):
        tree = ast.parse(f.read_text(encoding="utf-8"))
        bad += [f"{f.relative_to(PKG.parent).as_posix()}:{line}: import {name}"
                for line, name in _unguarded_imports(tree.body)]
    assert bad == [], "\n".join(bad)


def test_the_check_finds_an_unguarded_import():
    # made-up modules: a bare `import tty` and one inside a class body are found; a guarded one,
    # one under try/except ImportError and one inside a function are not
    src = ("import tty\n"
           "class A:\n    import fcntl\n"
           "if os.name == 'posix':\n    import termios\n"
           "try:\n    import pty\nexcept ImportError:\n    pty = None\n"
           "def f():\n    import resource\n")
    assert _unguarded_imports(ast.parse(src).body) == [(1, "tty"), (3, "fcntl")]


# -- the config file where Windows programs keep theirs ---------------------------------------------

def test_the_user_config_file_on_windows_is_under_appdata():
    from profidrive_cli.config import user_config_path
    appdata = Path("/c/Users/u/AppData/Roaming")             # %APPDATA% (a Linux path stands in)
    assert user_config_path({"APPDATA": str(appdata)}, platform="win32") == appdata / "pdrive" / "config.yaml"
    # no APPDATA: the user profile's AppData\Roaming, as Windows sets APPDATA by default
    assert user_config_path({"USERPROFILE": "/c/Users/u"}, platform="win32") == \
        Path("/c/Users/u") / "AppData" / "Roaming" / "pdrive" / "config.yaml"
    # XDG_CONFIG_HOME, when set, wins everywhere; elsewhere ~/.config as before
    assert user_config_path({"XDG_CONFIG_HOME": "/x", "APPDATA": str(appdata)}, platform="win32") == \
        Path("/x/pdrive/config.yaml")
    assert user_config_path({"HOME": "/home/u", "APPDATA": str(appdata)}, platform="linux") == \
        Path("/home/u/.config/pdrive/config.yaml")
