"""Errors raised for user mistakes: each names where, what was expected and what was found."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass


def short_repr(value: object, limit: int = 60) -> str:
    """``repr(value)``, cut to ``limit`` characters for an error message."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    """``: did you mean 'lung'?`` when one of ``choices`` is close to ``word`` (a misspelt
    variable, state or question), else nothing: the tail of a message that names ``word``.

    >>> did_you_mean("lugn", ["asia", "smoke", "lung"])
    ": did you mean 'lung'?"
    >>> did_you_mean("Smoke", ["smoke"]), did_you_mean("x", ["smoke"])
    (": did you mean 'smoke'?", '')
    """
    import difflib  # (only when a message is written)

    options = [str(c) for c in choices]
    near = [c for c in options if c.lower() == word.lower()] or difflib.get_close_matches(
        word, options, n=1, cutoff=0.6)
    return f": did you mean {near[0]!r}?" if near else ""


@dataclass(frozen=True)
class Diagnostic:
    """One problem in a program file, located by line and column (both 1-based)."""

    file: str
    line: int
    column: int
    message: str

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.column}: {self.message}"


class BayesprogError(Exception):
    """Base class of every error caused by user input (files, questions, evidence)."""


class ArgumentError(BayesprogError, TypeError):
    """An argument of the Python API of the wrong type: the message names the argument, what
    was expected and what was found."""


class SpecError(BayesprogError, ValueError):
    """A program file has one or more problems; all of them are listed."""

    def __init__(self, diagnostics: list[Diagnostic]):
        self.diagnostics = sorted(diagnostics, key=lambda d: (d.file, d.line, d.column))
        super().__init__("\n".join(str(d) for d in self.diagnostics))


class ProgramCycleError(BayesprogError, ValueError):
    """Programs that name each other (as sub-programs or soft evidence) in a circle."""

    def __init__(self, files: list):
        self.files = files
        super().__init__(" -> ".join(getattr(f, "name", str(f)) for f in files))


class QuestionError(BayesprogError, ValueError):
    """A question or its evidence does not fit the program (unknown variable, state, shape...)."""


class ZeroEvidenceError(QuestionError):
    """The evidence has probability zero under the program, so no posterior exists."""


def expect_mapping(value: object, argument: str, of: str) -> dict:
    """``value`` as a dict (None: empty), or an :class:`ArgumentError` naming ``argument``.

    >>> expect_mapping(None, "evidence", "variable names to values")
    {}
    >>> expect_mapping(["wet"], "evidence", "variable names to values")
    Traceback (most recent call last):
    ...
    bayesprog.errors.ArgumentError: evidence: expected a mapping of variable names to values (a dict), found list: ['wet']
    """
    from collections.abc import Mapping

    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise ArgumentError(f"{argument}: expected a mapping of {of} (a dict), found "
                            f"{type(value).__name__}: {short_repr(value)}")
    for key in value:
        if not isinstance(key, str):
            raise ArgumentError(f"{argument}: expected names (strings) as keys, found "
                                f"{short_repr(key)}")
    return dict(value)
