"""The program's data types: what a checked program is made of, below both the language that
reads it from YAML (:mod:`bayesprog.language`) and the inference and learning that use it.

A :class:`Term` is one factor of the decomposition (its variables, form and parameters), an
:class:`InputDecl` a runtime input a question binds and :class:`LearnOptions` how a term is
learned from data (defined beside the forms' estimators, which read it). The provenance of a
fit, as written into a fitted file, is in :mod:`bayesprog.model.records` (dataclasses, imported only
for a program that has one).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from bayesprog.forms import Form, FormulaParam, InputRef, ParamValue
from bayesprog.forms.estimators import LearnOptions
from bayesprog.vocabulary.expressions import Expression
from bayesprog.vocabulary.variables import Variable


@dataclass(frozen=True)
class InputDecl:
    """A declared runtime input: ``axes`` over discrete variables, then fixed or free dims."""

    name: str
    axes: tuple[str, ...]
    event: tuple[int | str, ...]
    description: str = ""

    @property
    def ndim(self) -> int:
        return len(self.axes) + len(self.event)


@dataclass
class Term:
    """A checked term of the decomposition (or a soft-evidence likelihood when ``soft``)."""

    expression: Expression
    child: Variable
    parents: tuple[Variable, ...]
    form: Form
    params: dict[str, ParamValue | InputRef | FormulaParam]
    position: tuple[str, int, int] = ("<python>", 0, 0)
    soft: bool = False
    extra: dict[str, Any] = field(default_factory=dict)
    description: str = ""
    #: how the term is learned from data; None keeps it as written (``learn: false``)
    learn: LearnOptions | None = field(default_factory=LearnOptions)

    @property
    def axes(self) -> tuple[str, ...]:
        """The term's discrete variables, child first when it is discrete."""
        own = (self.child.name,) if self.child.is_discrete else ()
        return own + tuple(p.name for p in self.parents if p.is_discrete)

    @property
    def label(self) -> str:
        return f"soft evidence on {self.child.name}" if self.soft else str(self.expression)
