"""The models that come with bayesprog: the example programs and their data, and the files of
the applications built on it (their programs, scenarios, experiments, sensor models).

They are package data of the installed wheel (``bayesprog/models``) and the ``models`` folder of
a checkout. On the command line a name that is not a file is looked up among them, so that
``bayesprog query student "P(I | G=A)"``, and an application's ``bayesprog run NAME``, work
wherever bayesprog is installed; ``bayesprog examples`` lists them and ``bayesprog examples copy
NAME DIR`` copies one, with every file it names, into a folder of one's own to edit.

>>> from bayesprog.support import bundled
>>> bundled.find("student", "program").name
'student.yaml'
>>> bundled.find("examples/rain").relative_to(bundled.bundled_root()).as_posix()
'examples/rain.yaml'
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass
from functools import cache
from pathlib import Path

from bayesprog.errors import BayesprogError
from bayesprog.support.files import file_kind

#: the folders of the models root where each kind of file is looked for, in order
FOLDERS = {"experiment": ("experiments",), "scenario": ("scenarios",),
           "program": ("examples", "."), "sensor model": ("sensors",), "data": ("data",)}

#: the order of the kinds when a short name is given without one (an experiment carries its
#: scenario and programs with it)
ORDER = ("experiment", "program", "scenario", "sensor model", "physics materials", "data")

#: the suffixes of the files that are models or their data
SUFFIXES = (".yaml", ".yml", ".csv", ".parquet")


@dataclass(frozen=True)
class Bundled:
    """One bundled file: ``name`` is its path under the models root without the ``.yaml``
    suffix (``examples/student``, ``scenarios/NAME``, ``data/NAME.csv``)."""

    name: str
    path: Path
    kind: str

    @property
    def description(self) -> str:
        """The model's ``description`` (or ``name``); a data file's rows and columns. Read when
        asked: finding a model by its name reads no description."""
        return _describe(self.path)

    @property
    def short(self) -> str:
        """The name without its folder (``student``), enough where the kind is known."""
        return self.name.rsplit("/", 1)[-1]


@cache
def bundled_root() -> Path:
    """The folder of the bundled models: ``bayesprog/models`` in an installed wheel, the
    checkout's ``models`` folder otherwise."""
    here = Path(__file__).resolve().parents[1]  # bayesprog/ (this is support/bundled.py)
    for candidate in (here / "models", here.parent / "models"):
        if (candidate / "examples").is_dir():
            return candidate
    raise BayesprogError("the bundled models are missing from this installation (expected "
                         f"{here / 'models'}): reinstall bayesprog")


def _name(path: Path) -> str:
    relative = path.relative_to(bundled_root()).as_posix()
    return relative[: -len(path.suffix)] if path.suffix in (".yaml", ".yml") else relative


def _describe(path: Path) -> str:
    """A model's ``description`` (or its ``name``); a data file's columns and rows."""
    if path.suffix == ".csv":
        with open(path, encoding="utf-8") as f:
            header = f.readline().strip()
            rows = sum(1 for line in f if line.strip())
        return f"{rows} rows of {header.replace(',', ', ')}"
    if path.suffix not in (".yaml", ".yml"):
        return "data"
    import yaml

    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
    try:
        with open(path, encoding="utf-8") as f:
            data = yaml.load(f, Loader=loader)
    except (OSError, yaml.YAMLError):
        return ""
    if not isinstance(data, dict):
        return ""
    return " ".join(str(data.get("description") or data.get("name") or "").split())


@cache
def listing() -> tuple[Bundled, ...]:
    """Every bundled file, experiments first, then programs, scenarios, sensor models, physics
    materials, data."""
    return _listed(_files())


@cache
def _files() -> tuple[Path, ...]:
    """The files under the models root that may be models or their data, by path."""
    return tuple(path for path in sorted(bundled_root().rglob("*"))
                 if path.suffix in SUFFIXES and path.is_file())


def _listed(paths: Iterable[Path]) -> tuple[Bundled, ...]:
    """``paths`` as bundled files of their kinds (a file of none left out), in the order of
    :func:`listing`."""
    found = []
    for path in paths:
        kind = "data" if path.suffix in (".csv", ".parquet") else file_kind(path)
        if kind is not None:
            found.append(Bundled(_name(path), path, kind))
    return tuple(sorted(found, key=lambda b: (ORDER.index(b.kind), b.name)))


def _called(path: Path, text: str) -> bool:
    """Whether ``text`` names the file at ``path``: its name under the root or its short name,
    a data file's also without its suffix (probes, probes.csv)."""
    name = _name(path)
    names = {name, name.rsplit("/", 1)[-1]}
    if path.suffix in (".csv", ".parquet"):
        names |= {n.rsplit(".", 1)[0] for n in names}
    return text in names


def find(name: str, kind: str | None = None) -> Path | None:
    """The bundled file called ``name`` (its short name, ``student``, or its name under the
    root, ``examples/student``, with or without ``.yaml``), of ``kind`` when given; None when
    there is none. A short name without a kind is looked for among the experiments first, then
    the programs, scenarios, sensor models and data."""
    text = name[:-5] if name.endswith(".yaml") else name
    kinds = [kind] if kind is not None else list(ORDER)
    # the files of that name alone are read for their kinds (a question asked of a bundled
    # program does not read the others' heads)
    named = _listed(path for path in _files() if _called(path, text))
    return next((entry.path for wanted in kinds for entry in named if entry.kind == wanted),
                None)


def bundled_path(text: str, kind: str | None = None) -> Path:
    """``text`` as a path when a file or folder of that name exists; otherwise the bundled
    file of that name (and ``kind``); otherwise the path as given (its reader then says that
    it is missing)."""
    path = Path(text)
    if path.exists():
        return path
    return find(text, kind) or path


def references(path: Path) -> list[Path]:
    """The files a bundled model names (its scenario, programs, sensor model, recordings), and
    the files those name, each once: every string of the file that is the relative path of a
    file under the root."""
    import yaml

    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
    seen: dict[Path, None] = {}
    todo = [path.resolve()]
    while todo:
        current = todo.pop()
        if current in seen:
            continue
        seen[current] = None
        if current.suffix not in (".yaml", ".yml"):
            continue
        with open(current, encoding="utf-8") as f:
            data = yaml.load(f, Loader=loader)
        for text in _strings(data):
            if not text.endswith(SUFFIXES) or "\n" in text:
                continue
            named = (current.parent / text).resolve()
            if named.is_file() and named.is_relative_to(bundled_root().resolve()):
                todo.append(named)
    return list(seen)


def _strings(data: object) -> list[str]:
    if isinstance(data, str):
        return [data]
    if isinstance(data, dict):
        return [s for value in data.values() for s in _strings(value)]
    if isinstance(data, list):
        return [s for value in data for s in _strings(value)]
    return []


def copy(name: str, folder: Path, *, force: bool = False) -> list[Path]:
    """Copy the bundled model ``name`` and every file it names into ``folder``; returns the
    written files, the model's own first. A model that is one file lands as that file in
    ``folder`` (``student`` as ``folder/student.yaml``); a model with the files it names keeps
    their layout from the folder that holds them all (so its relative references still hold:
    ``paper`` as ``experiments/paper.yaml`` beside ``scenarios/`` and its programs). An
    existing file is not overwritten unless ``force``."""
    source = find(name)
    if source is None:
        raise BayesprogError(f"no bundled model called {name!r} (bayesprog examples lists "
                             "them)")
    files = references(source)
    base = Path(os.path.commonpath([f.parent for f in files]))
    targets = [folder / f.relative_to(base) for f in files]
    existing = [str(t) for t in targets if t.exists()]
    if existing and not force:
        raise BayesprogError(f"{existing[0]} exists: not overwritten (--force overwrites"
                             + (f"; {len(existing)} files in all)" if len(existing) > 1 else ")"))
    import shutil

    for file, target in zip(files, targets, strict=True):
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(file, target)
    return targets
