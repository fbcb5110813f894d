"""The plan of one question: the program, the question, its bound evidence, and the terms that
matter for it; every method answers from a plan, and the cost model estimates from one."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
import opt_einsum

from bayesprog.expressions import Question
from bayesprog.inference.binding import Bound
from bayesprog.inference.core import contraction_path
from bayesprog.inference.factors import latent_continuous, relevant_terms
from bayesprog.inference.protocol import ProgramLike
from bayesprog.language.check import Term


@dataclass
class QuestionPlan:
    program: ProgramLike
    question: Question
    bound: Bound
    #: what the question asks of its method (``samples``, ``rng``, ``max_iterations``, ...)
    options: dict[str, Any] = field(default_factory=dict)

    @property
    def searched(self) -> tuple[str, ...]:
        return self.question.expression.left

    @cached_property
    def terms(self) -> list[Term]:
        """The relevant terms: ancestors of searched, observed and soft-evidence variables."""
        return relevant_terms(self.program, self.question, self.bound)

    @cached_property
    def latent(self) -> list[str]:
        """The unknown continuous variables that matter (searched, or parents of a relevant
        term): only the methods for continuous variables answer when there are some."""
        return latent_continuous(self.program, self.terms, self.bound)

    def card(self, name: str) -> int:
        return int(self.program.variables[name].card)  # type: ignore[union-attr]

    def free_size(self, axes: tuple[str, ...]) -> int:
        """Entries of a factor over ``axes`` once the observed discrete variables are sliced."""
        return int(np.prod([self.card(a) for a in axes if a not in self.bound.discrete]))

    def contraction_cost(self, output: tuple[str, ...], sliced: bool = True) -> tuple[float, float]:
        """Operations and largest intermediate (entries) of contracting the relevant factors
        down to ``output``, for one row of evidence, on the path opt_einsum would take.
        ``sliced``: the observed discrete variables are fixed (else the factors are whole)."""
        observed = set(self.bound.discrete) if sliced else set()
        operands = [tuple(a for a in t.axes if a not in observed) for t in self.terms]
        operands += [(name,) for name in self.bound.soft if name not in observed]
        present = {a for axes in operands for a in axes}
        operands += [(v,) for v in output if v not in present]
        names = sorted({a for axes in operands for a in axes})
        symbol = {n: opt_einsum.get_symbol(i) for i, n in enumerate(names)}
        equation = (",".join("".join(symbol[a] for a in axes) for axes in operands) + "->"
                    + "".join(symbol[a] for a in output))
        shapes = [tuple(self.card(a) for a in axes) for axes in operands]
        largest = max([float(np.prod(s)) for s in shapes]
                      + [float(np.prod([self.card(v) for v in output]))])
        if len(operands) < 2:
            return largest, largest
        _, info, cost = contraction_path(equation, shapes)
        return cost, max(float(info.largest_intermediate), largest)
