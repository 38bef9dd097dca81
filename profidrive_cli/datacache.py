"""The cache of parsed data files: a profile's YAML parsed once, read back in a tenth of the time.

Every command that talks to a drive loads its profile, and a line of five families loads five (the
Moeller one alone is 77 kB of YAML: 50 ms to parse on the project's machines, 3 ms to read back).
What is kept is the parse only -- the LineDict / LineList data with its line numbers, exactly what
datafile.load_yaml_text returns -- never anything validated: a profile is checked on every load as
before, and its errors still say file:line.

- Key: SHA-256 of the text, the loader (libyaml or pure) and this format's number. A changed file is a
  new key; nothing is trusted by name or date.
- Only texts that parsed are kept (an error is never cached).
- Where: $PDRIVE_CACHE_DIR, else $XDG_CACHE_HOME/pdrive/yaml, else ~/.cache/pdrive/yaml;
  PDRIVE_CACHE_DIR=off (or empty) turns it off.
- Bounded: at most MAX_ENTRIES files, the oldest removed first when a new one is written.
- Written to a temporary file and renamed: a reader never sees half a file; two writers are harmless.
- Read with an unpickler that builds only the data types YAML gives (LineDict, LineList, dates):
  anything else in a file is refused, and a file that does not read is parsed anew and replaced.
- Any failure of the cache itself (no home, a read-only or full disk) is silent: the file is parsed.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import os
import pickle
import tempfile
from pathlib import Path
from typing import Any

CACHE_FORMAT = 1
MAX_ENTRIES = 64
SUFFIX = ".pickle"

#: what a cache file may build besides the types pickle writes by value (str, int, float, bool, None,
#: bytes, list, dict, set): the YAML loader's own containers and its timestamps
_ALLOWED = frozenset({
    ("profidrive_cli.datafile", "LineDict"),
    ("profidrive_cli.datafile", "LineList"),
    ("datetime", "date"),
    ("datetime", "datetime"),
    ("datetime", "timezone"),
    ("datetime", "timedelta"),
})


class _Refused(pickle.UnpicklingError):
    pass


class _DataUnpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str) -> Any:
        if (module, name) in _ALLOWED:
            return super().find_class(module, name)
        raise _Refused(f"{module}.{name}")


def cache_dir() -> Path | None:
    """The cache's folder, or None when it is off (or there is no home to put it in)."""
    env = os.environ.get("PDRIVE_CACHE_DIR")
    if env is not None:
        return Path(env) if env.strip() and env.strip().lower() != "off" else None
    base = os.environ.get("XDG_CACHE_HOME") or ""
    if not base:
        home = os.path.expanduser("~")
        if home.startswith("~"):
            return None
        base = os.path.join(home, ".cache")
    return Path(base) / "pdrive" / "yaml"


def key(text: str, loader: str) -> str:
    h = hashlib.sha256(f"pdrive-yaml {CACHE_FORMAT} {loader}\n".encode())
    h.update(text.encode("utf-8", "surrogatepass"))
    return h.hexdigest()


MISS = object()


def get(text: str, loader: str) -> Any:
    """The data parsed before from this text with this loader, or MISS."""
    d = cache_dir()
    if d is None:
        return MISS
    try:
        blob = (d / (key(text, loader) + SUFFIX)).read_bytes()
        return _DataUnpickler(io.BytesIO(blob)).load()
    except Exception:                   # noqa: BLE001  (absent, unreadable, refused: parse anew)
        return MISS


def put(text: str, loader: str, data: Any) -> None:
    """Keep the data parsed from this text (silently nothing when the cache cannot be written)."""
    d = cache_dir()
    if d is None:
        return
    try:
        d.mkdir(parents=True, exist_ok=True)
        blob = pickle.dumps(data, protocol=pickle.HIGHEST_PROTOCOL)
        fd, tmp = tempfile.mkstemp(dir=d, prefix=".tmp-", suffix=SUFFIX)
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(blob)
            os.replace(tmp, d / (key(text, loader) + SUFFIX))
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise
        _prune(d)
    except Exception:                   # noqa: BLE001  (a cache that cannot be written is no cache)
        return


def _prune(d: Path) -> None:
    """At most MAX_ENTRIES files: the oldest (by modification time) go first."""
    entries = []
    for p in d.iterdir():
        if p.name.endswith(SUFFIX) and not p.name.startswith(".tmp-"):
            with contextlib.suppress(OSError):
                entries.append((p.stat().st_mtime_ns, p.name, p))
    if len(entries) <= MAX_ENTRIES:
        return
    entries.sort()
    for _, _, p in entries[:len(entries) - MAX_ENTRIES]:
        with contextlib.suppress(OSError):
            p.unlink()

