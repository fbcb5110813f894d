"""Checked programs kept between processes, keyed by the bytes of their file.

Loading a large program file (an imported network of thousands of tables) is mostly reading and
checking its YAML. Once a file has loaded without a problem, the checked program is kept in a
cache folder under a key made of the file's bytes, its path, the limits in force and the
code that checked it (its modules' sizes and times); the next load of the same bytes, in any process, reads it
back instead. A file that changes, however little, has another key and is read and checked
again, with every diagnostic at its line and column; a file that names other files (a term's
``program:``) is never kept, since those could change without it.

Only files of :data:`MIN_BYTES` or more are kept (smaller ones load in milliseconds), at most
:data:`MAX_ENTRIES` programs and :data:`MAX_BYTES` in all (the least recently used go first).

``BAYESPROG_CACHE``: the folder (default ``$XDG_CACHE_HOME/bayesprog``, else
``~/.cache/bayesprog``); ``off`` turns the cache off. The folder is read as trusted, like the
program files themselves: give it a folder only you can write to.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path
from typing import Any

#: files smaller than this are always read (they load in a few milliseconds)
MIN_BYTES = 16_384
#: the most programs kept, and the most bytes
MAX_ENTRIES = 64
MAX_BYTES = 1 << 30
_OFF = {"off", "0", "no", "false", "none"}


def folder() -> Path | None:
    """Where checked programs are kept, or None when the cache is off."""
    chosen = os.environ.get("BAYESPROG_CACHE", "").strip()
    if chosen.lower() in _OFF:
        return None
    if chosen:
        return Path(chosen).expanduser() / "programs"
    base = os.environ.get("XDG_CACHE_HOME", "").strip() or Path.home() / ".cache"
    return Path(base) / "bayesprog" / "programs"


@functools.lru_cache(maxsize=1)
def _code() -> bytes:
    """What identifies the code that checks and compiles programs: the size and time of change
    of every module of the package (another version, or an edited module, makes new keys)."""
    root = Path(__file__).parents[1]  # bayesprog/, of which this is bayesprog/support/cache.py
    parts = []
    for directory, folders, files in os.walk(root):
        folders[:] = sorted(f for f in folders if not f.startswith((".", "__")))
        for name in sorted(files):
            if name.endswith(".py"):
                stat = os.stat(os.path.join(directory, name))
                parts.append(f"{directory[len(str(root)):]}/{name}:{stat.st_size}:"
                             f"{stat.st_mtime_ns}")
    return "\n".join(parts).encode()


def key(path: Path, data: bytes) -> str | None:
    """The key of the program file ``path`` holding ``data``, or None when such a file is not
    kept (too small, or the cache is off)."""
    if len(data) < MIN_BYTES or folder() is None:
        return None
    import hashlib  # (a program too small to keep loads without it)

    from bayesprog.limits import limit

    digest = hashlib.blake2b(_code(), digest_size=20)
    digest.update(f"\0{path.resolve()}\0{limit('states')}\0{limit('entries')}\0".encode())
    digest.update(data)
    return digest.hexdigest()


def get(name: str) -> Any:
    """The program kept under ``name``, or None (a damaged entry is removed)."""
    place = folder()
    if place is None:
        return None
    entry = place / f"{name}.pickle"
    try:
        data = entry.read_bytes()
    except OSError:
        return None
    import pickle

    try:
        program = pickle.loads(data)
    except Exception:  # written by another version, or cut short: read the file again
        entry.unlink(missing_ok=True)
        return None
    try:
        os.utime(entry)  # recently used
    except OSError:
        pass
    return program


def put(name: str, program: Any) -> None:
    """Keep ``program`` under ``name``; nothing happens when it cannot be kept (a program that
    does not pickle, a folder that cannot be written)."""
    place = folder()
    if place is None:
        return
    import pickle

    try:
        data = pickle.dumps(program, protocol=pickle.HIGHEST_PROTOCOL)
    except Exception:
        return
    if len(data) > MAX_BYTES // 4:
        return
    from bayesprog.support.files import atomic_write

    try:
        atomic_write(place / f"{name}.pickle", data)
        _prune(place)
    except OSError:
        return


def _prune(place: Path) -> None:
    entries = []
    for entry in place.glob("*.pickle"):
        try:
            stat = entry.stat()
        except OSError:
            continue
        entries.append((stat.st_mtime_ns, stat.st_size, entry))
    entries.sort(reverse=True)  # the most recently used first
    total = 0
    for count, (_, size, entry) in enumerate(entries):
        total += size
        if count >= MAX_ENTRIES or total > MAX_BYTES:
            entry.unlink(missing_ok=True)
