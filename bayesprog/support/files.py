"""Files: written so that a reader (or an interrupted writer) never sees a partial one, and
the kinds of the project's YAML files, told apart by their first key before they are read."""

from __future__ import annotations

import errno
import os
import re
from pathlib import Path


def atomic_write(path: Path, data: bytes, *, parents: bool = True) -> None:
    """Write ``data`` to ``path`` so that a reader never sees a partial file.

    ``parents``: make the missing folders above ``path`` (an application's own folders, such
    as a results folder's chunks). A path the user names (``-o``) is written with
    ``parents=False``: a folder that does not exist is then a ``FileNotFoundError`` that names
    it, never a new tree made from a typing mistake."""
    path = Path(path)
    if parents:
        path.parent.mkdir(parents=True, exist_ok=True)
    elif not path.parent.is_dir():
        what = "not a folder" if path.parent.exists() else "no such folder"
        raise FileNotFoundError(errno.ENOENT, f"{what}: {path.parent} (make it first)",
                                str(path))
    # a new file beside it, of a name no other writer takes (O_EXCL), its mode that of an
    # ordinary new file (the umask applied)
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)
    while True:
        tmp = path.parent / f".{path.name}.{os.urandom(6).hex()}.tmp"
        try:
            fd = os.open(tmp, flags, 0o666)
            break
        except FileExistsError:
            continue
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


#: the top-level key that names each kind of file of the project
KINDS = {"bayesprog": "program", "experiment": "experiment", "scenario": "scenario",
         "sensor": "sensor model", "physics": "physics materials"}


def file_kind(path: str | os.PathLike[str]) -> str | None:
    """"program", "experiment", "scenario", "sensor model" or "physics materials" by the file's
    first-level key, or
    None (unreadable, not text, or none of these). Only the file's head is read, and not
    parsed: a hint must cost nothing, whatever the file's size."""
    try:
        with open(path, encoding="utf-8") as f:
            head = f.read(_HEAD)
    except (OSError, UnicodeDecodeError):
        return None
    block = re.findall(r"^([A-Za-z_][A-Za-z0-9_]*)[ \t]*:", head, re.M)
    if not block and head.lstrip().startswith("{"):  # a flow mapping: {bayesprog: 1, ...}
        block = re.findall(r"[{,]\s*([A-Za-z_][A-Za-z0-9_]*)\s*:", head)
    return next((KINDS[key] for key in block if key in KINDS), None)


#: how much of a file :func:`file_kind` reads
_HEAD = 64 * 1024


def wrong_kind(path: str | os.PathLike[str], expected: str, hint: str = "") -> str | None:
    """A message when the file at ``path`` is plainly another kind of file than ``expected``."""
    kind = file_kind(path)
    if kind is None or kind == expected:
        return None
    return (f"{path}: this is {a_or_an(kind)} {kind} file, not {a_or_an(expected)} {expected} file"
            + (f" ({hint})" if hint else ""))


def reference_problem(file: str | os.PathLike[str], expected: str,
                      written: str | None = None) -> str | None:
    """Why the file a document names cannot be read as ``expected`` ("program", "scenario",
    "experiment", "sensor model"), or None: missing, a folder, unreadable, not UTF-8 text, or
    plainly another kind of file. The caller reports it where the file is named; ``written``
    is the name as the document gives it (a relative one is said where it was looked for)."""
    path = Path(file)
    if not path.exists():
        relative = written is not None and not Path(written).is_absolute()
        return f"no such file (looked for {path.resolve()})" if relative else "no such file"
    if path.is_dir():
        return f"a folder, expected {a_or_an(expected)} {expected} file"
    try:
        with open(path, "rb") as f:
            head = f.read(_HEAD)
    except OSError as exc:
        return f"cannot read it: {exc.strerror or exc}"
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as exc:
        # a character cut at the end of what was read is not an error of the file
        if len(head) < _HEAD or exc.start < len(head) - 4:
            return f"cannot read it: expected UTF-8 text (byte {exc.start} is not)"
    kind = file_kind(path)
    if kind is not None and kind != expected:
        return f"{a_or_an(kind)} {kind} file, expected {a_or_an(expected)} {expected} file"
    return None


def a_or_an(word: str) -> str:
    """The article before ``word``."""
    return "an" if word[0] in "aeiou" else "a"
