"""What every check of a program shares: the checker's state (the document, the variables and
inputs read so far, the problems found, each at its line and column) and the helpers the checks
of several sections use."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from bayesprog.errors import Diagnostic
from bayesprog.forms import Form, available_forms, get_form
from bayesprog.language.loader import Located
from bayesprog.language.loader import Path as YPath
from bayesprog.model import InputDecl
from bayesprog.vocabulary.expressions import ExpressionError, parse_expression
from bayesprog.vocabulary.variables import Variable

if TYPE_CHECKING:  # (pydantic's models are built only for a file the plain reader leaves)
    from bayesprog.language.document import Document
    from bayesprog.language.plain import PlainDocument

#: The most discrete variables a term may have: its table has one axis per variable and one
#: for a batch of evidence, and numpy's einsum takes arrays of at most 32 axes.
MAX_TERM_VARIABLES = 31


class Checker:
    """The state of one program's check; each section's checks are a class of their own over it
    (:mod:`~bayesprog.language.check.variables`, :mod:`~bayesprog.language.check.terms`,
    :mod:`~bayesprog.language.check.parameters`, :mod:`~bayesprog.language.check.questions`,
    :mod:`~bayesprog.language.check.time`), put together in :mod:`bayesprog.language.check`."""

    def __init__(self, located: Located, doc: Document | PlainDocument, base_dir: Path,
                 load_program: Callable[..., Any] | None = None):
        self.located = located
        #: pydantic's Document or the plain reader's: the same attributes, unrelated types
        self.doc: Any = doc
        self.base_dir = base_dir
        #: loads another program file (for ``program`` terms), with the names of the variables
        #: it shares with the term; given by the program layer
        self.load_program = load_program
        self.problems: list[Diagnostic] = []
        self.variables: dict[str, Variable] = {}
        self.inputs: dict[str, InputDecl] = {}
        #: the variables without a term (not one that failed to be read), and those of them
        #: that condition a term: every question gives them
        self.untermed: list[str] = []
        self.conditioning: tuple[str, ...] = ()

    def error(self, path: YPath, message: str, at_key: bool = False) -> None:
        self.problems.append(self.located.diagnostic(path, message, at_key=at_key))


def _child_of(text: str) -> str | None:
    try:
        left = parse_expression(text).left
    except ExpressionError:
        return None
    return left[0] if len(left) == 1 else None


def _form_named(name: str) -> Form:
    form = get_form(name)
    assert form is not None, name
    return form


def _forms_taking(option: str) -> str:
    """The forms whose estimator takes the ``learn:`` option, as a message lists them (over a
    variable of the kind each learns)."""
    from bayesprog.vocabulary.variables import Continuous, Discrete

    probes = (Discrete("X", ("a", "b")), Continuous("X", -np.inf, np.inf))
    names = [name for name in available_forms()
             if any((e := _form_named(name).estimator(v)) is not None and option in e.options
                    for v in probes)]
    return " and ".join(names) if len(names) <= 2 else ", ".join(names[:-1]) + " and " + names[-1]
