"""Whole-program checking: from a located, schema-valid document to checked program parts.

Every problem of a file is collected (with its line and column) before anything is raised, so a
user sees all of them at once. The checks go section by section, each in a module of its own
over the checker's state (:mod:`~bayesprog.language.check.base`): the variables and inputs
(:mod:`~bayesprog.language.check.variables`), the terms of the decomposition and soft evidence
(:mod:`~bayesprog.language.check.terms`) with their parameters
(:mod:`~bayesprog.language.check.parameters`), the questions and ablations
(:mod:`~bayesprog.language.check.questions`), and the time section
(:mod:`~bayesprog.language.check.time`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bayesprog.errors import Diagnostic
from bayesprog.language.check.base import MAX_TERM_VARIABLES
from bayesprog.language.check.questions import (
    QuestionsCheck,
    conditioning_problem,
    question_problem,
)
from bayesprog.language.check.terms import TermsCheck
from bayesprog.language.check.time import TimeCheck
from bayesprog.language.check.variables import VariablesCheck, build_variable
from bayesprog.language.loader import Located
from bayesprog.model import InputDecl, Term
from bayesprog.vocabulary.expressions import Expression
from bayesprog.vocabulary.variables import Variable

if TYPE_CHECKING:  # (pydantic's models are built only for a file the plain reader leaves)
    from bayesprog.language.document import Document
    from bayesprog.language.plain import PlainDocument

__all__ = ["MAX_TERM_VARIABLES", "Checked", "build_variable", "check_document",
           "conditioning_problem", "question_problem"]


@dataclass
class Checked:
    variables: dict[str, Variable]
    inputs: dict[str, InputDecl]
    terms: list[Term]
    questions: dict[str, tuple[Expression, str, str]]
    ablate: list[Expression]
    problems: list[Diagnostic]
    #: the (previous, state) pairs of a program that repeats per time step, else None
    time: tuple[tuple[str, str], ...] | None = None


class _Checker(VariablesCheck, TermsCheck, QuestionsCheck, TimeCheck):
    """Every section's checks over one program's state."""

def check_document(located: Located, doc: Document | PlainDocument, base_dir: Path,
                   load_program: Callable[..., Any] | None = None) -> Checked:
    """Check a validated document whole; ``load_program`` loads the files that ``program`` terms
    name (sub-programs), which this layer cannot do itself."""
    c = _Checker(located, doc, base_dir, load_program)
    c.check_variables()
    c.check_inputs()
    terms = c.check_terms()
    questions = c.check_questions()
    ablate = c.check_ablate(terms)
    time = c.check_time(terms, questions)
    return Checked(c.variables, c.inputs, terms, questions, ablate, c.problems, time)

