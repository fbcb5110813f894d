"""Results that survive: one file per (task, configuration, chunk of runs), written atomically.

``DIR/experiment.json`` records the experiment, its seed and start cells, the text of every
program and scenario file it resolved, and a hash of all of it; every chunk carries that hash.
Running again in the same folder skips the chunks already written whole; a chunk or manifest that
does not read back (a full disk, a crash) is set aside as ``NAME.damaged`` and computed again; a
different configuration is refused, never mixed in.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bayesprog import BayesprogError, atomic_write


class StoreError(BayesprogError):
    """An output folder that cannot take these results."""


@dataclass(frozen=True)
class Unit:
    """One piece of work: some runs of one task under one configuration, in one replication
    of the experiment (0: the experiment itself)."""

    task: str
    configuration: str
    chunk: int
    runs: tuple[int, ...]
    replication: int = 0

    @property
    def name(self) -> str:
        runs = f"runs_{self.runs[0]:04d}-{self.runs[-1]:04d}.npz"
        if self.replication:  # replication 0 is stored where an experiment always stored it
            runs = f"replication_{self.replication:03d}/{runs}"
        return f"{self.task}/{self.configuration}/{runs}"


def identity(manifest: dict) -> dict:
    """What the results depend on: the experiment's settings, its start cells and the text of
    every file it resolved, by role (not where the files are, nor how their paths were
    written)."""
    return {"experiment": manifest["experiment"], "start_cells": manifest["start_cells"],
            "files": {role: f["text"] for role, f in manifest["files"].items()}}


def config_hash(manifest: dict) -> str:
    return hashlib.sha256(json.dumps(identity(manifest), sort_keys=True).encode()).hexdigest()[:16]


def sweep_partial(folder: Path) -> list[Path]:
    """Remove what writes killed half-way left in ``folder``: the temporary files that a whole
    write renames over its target (``.NAME.XXXX.tmp``, ``.NAME.tmp.mp4``); returns them."""
    gone = []
    if folder.is_dir():
        for path in folder.iterdir():
            if path.name.startswith(".") and ".tmp" in path.name and path.is_file():
                path.unlink(missing_ok=True)
                gone.append(path)
    return gone


#: the lock file of a results folder, and the folders this process holds (with how many times
#: it took each: a run holds its folder, then its report takes it again)
LOCK = ".lock"
_HELD: dict[Path, list[int]] = {}


@contextmanager
def hold(folder: Path, what: str, make: bool = True) -> Iterator[None]:
    """Take ``folder`` for ``what`` (a run, a report, a search) while the block runs: an
    advisory lock on ``folder/.lock`` (made, with the folder when ``make``, when missing), which
    the kernel releases if the process dies. A second process asking for it is refused with one
    line that names the holder's command and pid; the same process may take it again. A folder
    that is not there and is not to be made is not held (the caller says what is missing)."""
    import fcntl

    folder = Path(folder)
    if not make and not folder.is_dir():
        yield
        return
    if folder.exists() and not folder.is_dir():
        raise StoreError(f"--out {folder}: cannot write results there: it is a file, expected "
                         "a folder")
    key = folder.resolve()
    if key in _HELD:
        _HELD[key][1] += 1
        try:
            yield
        finally:
            _HELD[key][1] -= 1
        return
    made = not folder.exists()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd = os.open(folder / LOCK, os.O_RDWR | os.O_CREAT, 0o666)
    except OSError as exc:
        raise StoreError(f"--out {folder}: cannot write results there "
                         f"({exc.strerror or exc}): expected a folder that can be created or "
                         "written") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.read(fd, 200).decode("utf-8", "replace").strip() or "another process"
        os.close(fd)
        raise StoreError(f"{folder} is in use by {holder}: wait for it to end, or give another "
                         "--out folder") from None
    os.ftruncate(fd, 0)
    os.write(fd, f"bayesprog {what} (pid {os.getpid()})".encode())
    _HELD[key] = [fd, 1]
    try:
        yield
    finally:
        _HELD[key][1] -= 1
        if not _HELD[key][1]:
            del _HELD[key]
            if made and [f.name for f in folder.iterdir()] == [LOCK]:
                # a folder made for a command that wrote nothing (a user error) is not left
                (folder / LOCK).unlink(missing_ok=True)
                with contextlib.suppress(OSError):
                    folder.rmdir()
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)


class ResultStore:
    def __init__(self, out: Path):
        self.out = Path(out)
        #: the configuration's hash once :meth:`open` has run (chunks carry it)
        self.hash: str | None = None
        #: what :meth:`open` and :meth:`done` set aside as damaged, for the user to read
        self.set_aside: list[str] = []

    @property
    def manifest_path(self) -> Path:
        return self.out / "experiment.json"

    def manifest(self) -> dict:
        try:
            found = json.loads(self.manifest_path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise StoreError(f"{self.out}: no experiment.json: not an experiment's output "
                             "folder") from None
        except (ValueError, OSError) as exc:
            raise StoreError(f"{self.manifest_path}: not a readable experiment manifest "
                             f"({exc})") from None
        try:
            identity(found)
            found["hash"]
        except (KeyError, TypeError, AttributeError):
            raise StoreError(f"{self.manifest_path}: not a readable experiment manifest "
                             "(expected keys experiment, start_cells, files and hash)") from None
        return found

    def open(self, manifest: dict) -> None:
        """Start or resume: refuse a folder that holds another configuration's results; a
        damaged manifest is set aside and written again (the chunks then prove, by the hash
        each carries, which configuration they belong to)."""
        manifest = dict(manifest, hash=config_hash(manifest))
        self.hash = manifest["hash"]
        self.set_aside = []
        if self.manifest_path.is_file():
            try:
                old = self.manifest()
            except StoreError:
                self._set_aside(self.manifest_path)
            else:
                if identity(old) != identity(manifest):
                    raise StoreError(
                        f"{self.out} holds results of another configuration (hash "
                        f"{old.get('hash')}, this one {manifest['hash']}): choose another "
                        "--out folder, or remove this one to start again"
                    )
                if old == manifest:
                    sweep_partial(self.out / "chunks")
                    return
                # the same configuration under the hash of an earlier version, or asked for
                # another number of replications (which the results do not depend on): the
                # manifest is written anew, the chunks kept
                sweep_partial(self.out / "chunks")
        try:
            self.out.mkdir(parents=True, exist_ok=True)
            atomic_write(self.manifest_path, json.dumps(manifest, indent=1).encode())
        except OSError as exc:
            raise StoreError(f"--out {self.out}: cannot write results there "
                             f"({exc.strerror or exc}): expected a folder that can be created "
                             "or written") from None

    def _set_aside(self, path: Path) -> None:
        """Rename a damaged file ``NAME.damaged`` (kept for the user, never read again)."""
        aside = path.with_name(path.name + ".damaged")
        path.replace(aside)
        self.set_aside.append(str(aside))

    def path(self, unit: Unit) -> Path:
        return self.out / "chunks" / unit.name

    def done(self, unit: Unit, iterations: int | None = None) -> bool:
        """Whether ``unit`` is stored whole: a chunk that does not read back (checksums of the
        archive, its runs, the configuration it carries, its number of steps) is set aside
        as damaged, to be computed again."""
        path = self.path(unit)
        if not path.exists():
            return False
        opened = self.hash is not None
        if not opened:
            self.hash = self.manifest()["hash"]
        problem = self._check(path, unit, iterations)
        if problem and opened:  # only a run that is about to compute it again moves it
            self._set_aside(path)
        return problem is None

    def _check(self, path: Path, unit: Unit, iterations: int | None) -> str | None:
        try:
            with open(path, "rb") as file, np.load(file) as data:
                arrays = {k: data[k] for k in data.files}  # reading checks each CRC
        except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError):
            return "unreadable"
        if "gamma" not in arrays or "runs" not in arrays:
            return "incomplete"
        if arrays["runs"].tolist() != list(unit.runs):
            return "other runs"
        stamp = arrays.get("config")
        if stamp is not None and str(stamp) != self.hash:
            return "another configuration"
        if stamp is None and not self._manifest_intact:
            return "no configuration"  # an earlier version's chunk, with no manifest to vouch
        rows = len(unit.runs)
        if any(a.shape[:1] != (rows,) for k, a in arrays.items() if k not in ("runs", "config")):
            return "truncated"
        if iterations is not None and arrays["gamma"].shape != (rows, iterations):
            return "truncated"
        return None

    @property
    def _manifest_intact(self) -> bool:
        return not any(p.endswith("experiment.json.damaged") for p in self.set_aside)

    def save(self, unit: Unit, result: dict[str, np.ndarray]) -> None:
        buffer = io.BytesIO()
        arrays: dict[str, Any] = {"runs": np.asarray(unit.runs)}
        if self.hash is not None:
            arrays["config"] = np.asarray(self.hash)
        np.savez(buffer, **(arrays | result))
        atomic_write(self.path(unit), buffer.getvalue())

    def load(self, task: str, configuration: str, units: list[Unit], replication: int = 0
             ) -> dict[str, np.ndarray]:
        """Every run of (task, configuration) in ``replication``, in run order."""
        parts = []
        for unit in units:
            if (unit.task != task or unit.configuration != configuration
                    or unit.replication != replication):
                continue
            path = self.path(unit)
            if not path.exists():
                raise StoreError(f"{self.out}: results of {unit.name} are missing: run the "
                                 "experiment again to finish it")
            try:
                with open(path, "rb") as file, np.load(file) as data:
                    parts.append({k: data[k] for k in data.files if k != "config"})
            except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
                raise StoreError(f"{path}: a damaged chunk ({exc}): run the experiment again "
                                 "to compute it anew") from None
        if not parts:
            raise StoreError(f"{self.out}: no results for {task}/{configuration}")
        keys = list(dict.fromkeys(k for p in parts for k in p))
        # a field that earlier versions did not store: NaN for their runs
        return {k: np.concatenate([p[k] if k in p else np.full(p["gamma"].shape, np.nan)
                                   for p in parts]) for k in keys}
