"""The plan of one question: the program, the question, its bound evidence, and the terms that
matter for it; every method answers from a plan, and the cost model estimates from one."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from bayesprog.expressions import Question
from bayesprog.inference.binding import Bound
from bayesprog.inference.factors import relevant_terms
from bayesprog.inference.protocol import ProgramLike
from bayesprog.language.check import Term


@dataclass
class QuestionPlan:
    program: ProgramLike
    question: Question
    bound: Bound

    @property
    def searched(self) -> tuple[str, ...]:
        return self.question.expression.left

    @cached_property
    def terms(self) -> list[Term]:
        """The relevant terms: ancestors of searched, observed and soft-evidence variables."""
        return relevant_terms(self.program, self.question, self.bound)

    def card(self, name: str) -> int:
        return int(self.program.variables[name].card)  # type: ignore[union-attr]

    def free_size(self, axes: tuple[str, ...]) -> int:
        """Entries of a factor over ``axes`` once the observed discrete variables are sliced."""
        return int(np.prod([self.card(a) for a in axes if a not in self.bound.discrete]))
