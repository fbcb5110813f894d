"""What the commands share: the user error (printed as ``bayesprog: ...``, exit status 2,
never a traceback), a program read from a file or a bundled name, the ``--ablate`` option, the
readers of options given as ``NAME=VALUE`` (``--evidence``, ``--input``, ``--soft``,
``--column``), numbers, ``.npy`` arrays and seeds, and the runner plugins found through the
``bayesprog.runners`` entry point group.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from bayesprog.errors import BayesprogError, SpecError

if TYPE_CHECKING:
    from bayesprog.program import Program

#: The exit status of a user error (a file that does not load, an option out of range).
EXIT_USER_ERROR = 2


class UserError(Exception):
    """A mistake in the command's arguments: printed as ``bayesprog: ...``, exit status 2."""


def output_file(text: str, option: str = "-o") -> Path:
    """The path of a file a command writes (``-o``): its folder must exist, so that a mistyped
    folder is said, not made."""
    path = Path(text)
    folder = path.parent
    if folder.exists() and not folder.is_dir():
        raise UserError(f"{option} {text}: {folder} is a file, not a folder")
    if not folder.is_dir():
        raise UserError(f"{option} {text}: the folder {folder} does not exist (make it first, "
                        "or write elsewhere)")
    if path.is_dir():
        raise UserError(f"{option} {text}: that is a folder; expected a file to write")
    return path


def load_program(name: str) -> Program:
    """The program file ``name``, or the bundled program of that name."""
    from bayesprog.program import load
    from bayesprog.support.bundled import bundled_path

    path = str(bundled_path(name, "program"))
    try:
        return load(path)
    except SpecError:
        hint = _kind_hint(path)
        if hint:
            raise UserError(hint) from None
        raise
    except FileNotFoundError:
        raise UserError(f"cannot read {path}: no such file, and no bundled program of that "
                        "name (bayesprog examples lists them)") from None
    except IsADirectoryError:
        raise UserError(f"cannot read {path}: it is a directory") from None
    except UnicodeDecodeError:
        raise UserError(f"cannot read {path}: expected UTF-8 text") from None


def ablated(program: Program, terms: Sequence[str]) -> Program:
    """``program`` with each ``--ablate`` term uniform."""
    for term in terms:
        try:
            program = program.ablate(term)
        except BayesprogError as exc:
            raise UserError(f"--ablate {term!r}: {exc}") from None
    return program


def _kind_hint(file: str) -> str | None:
    """Why a file is not a program, when it is plainly another kind of file."""
    from bayesprog.support.files import wrong_kind

    return wrong_kind(file, "program", "this command reads programs; `bayesprog run` reads "
                      "experiments and their scenarios")


def plugins(quiet: bool = False) -> Iterator[tuple[str, Any]]:
    """The runner plugins of the ``bayesprog.runners`` entry point group, by name, loaded; one
    that cannot be loaded is left out, and says why on stderr unless ``quiet``."""
    from importlib.metadata import entry_points

    for ep in sorted(entry_points(group="bayesprog.runners"), key=lambda ep: ep.name):
        try:
            plugin = ep.load()
        except Exception as exc:  # a broken plugin must not take the framework's CLI down
            if not quiet:
                print(f"bayesprog: runner {ep.name!r} not loaded: {exc}", file=sys.stderr)
            continue
        yield ep.name, plugin


def column_renames(items: Sequence[str]) -> dict[str, str]:
    """The ``--column COLUMN=VARIABLE`` options: the variable of each column renamed."""
    columns: dict[str, str] = {}
    for item in items:
        column, eq, variable = item.partition("=")
        if not eq or not column.strip() or not variable.strip():
            raise UserError(f"--column {item!r}: expected COLUMN=VARIABLE")
        if column.strip() in columns:
            raise UserError(f"--column {column.strip()} is given twice: expected each column "
                            "once")
        columns[column.strip()] = variable.strip()
    return columns


def named_values(items: Sequence[str], option: str) -> dict[str, str]:
    """The ``NAME=VALUE`` items of a repeatable ``option``, each name given once."""
    out: dict[str, str] = {}
    for item in items:
        name, eq, value = item.partition("=")
        if not eq or not name or not value:
            raise UserError(f"{option} {item!r}: expected NAME=VALUE")
        name = name.strip()
        if name in out:
            raise UserError(f"{option} {name} is given twice ({name}={out[name]} and "
                            f"{item.strip()}): expected each name once{_ONCE.get(option, '')}")
        out[name] = value.strip()
    return out


#: how to give several values where one option takes one value per name
_ONCE = {
    "--evidence": "; for a batch of rows, VAR=FILE.npy; for one value per step of a program "
                  "over time, VAR=v1,v2,... with --over-time",
    "--soft": " (one likelihood per variable: VAR=p1,p2,...)",
    "--input": " (one array per input: NAME=v1,v2,... for a vector, NAME=FILE.npy for any "
               "array, with a batch axis for several rows)",
}


def read_npy(path: str, option: str) -> np.ndarray:
    """The array in the ``.npy`` file ``path``, given to ``option``."""
    try:
        return np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise UserError(f"{option}: cannot read {path}: no such file") from None
    except IsADirectoryError:
        raise UserError(f"{option}: cannot read {path}: it is a directory") from None
    except (ValueError, OSError, EOFError):
        raise UserError(f"{option}: cannot read {path} as an array: expected a .npy file "
                        "of numbers written by numpy.save") from None


def input_values(items: Sequence[str]) -> dict[str, np.ndarray]:
    """The ``--input NAME=VALUE`` options: each a number (``dt=0.5``), numbers separated by
    commas (a vector, ``w=0.3,0.7``) or a ``.npy`` file (an array of any shape, batch axes
    first)."""
    out = {}
    for name, text in named_values(items, "--input").items():
        if text.endswith(".npy"):
            out[name] = read_npy(text, "--input")
            continue
        parts = [part.strip() for part in text.split(",")]
        try:
            numbers = [float(part) for part in parts]
        except ValueError:
            bad = next(part for part in parts if not _is_number(part))
            raise UserError(f"--input {name}={text}: expected a number, numbers separated by "
                            f"commas (a vector) or FILE.npy (an array), found {bad!r}"
                            ) from None
        out[name] = np.array(numbers[0] if len(parts) == 1 else numbers)
    return out


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def evidence_value(text: str) -> object:
    """A ``.npy`` file (arrays: fields, batches), else the text: a state, a value or an index,
    read by the engine according to the variable's kind."""
    if text.endswith(".npy"):
        return read_npy(text, "--evidence")
    return text


def check_seed(seed: int) -> int:
    """The ``--seed``, refused when negative."""
    if seed < 0:
        raise UserError(f"--seed: expected a non-negative integer, found {seed}")
    return seed
