"""The plan of one question: the program, the question, its bound evidence, and the terms that
matter for it; every method answers from a plan, and the cost model estimates from one.

What does not depend on the evidence's values (which terms matter, what a method compiles for
them) is a :class:`Layout`, kept per program for each combination of searched and known
variables: a question asked again with other values finds it ready."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

import numpy as np

from bayesprog.inference.binding import Bound
from bayesprog.inference.core import equation
from bayesprog.inference.factors import (
    is_static,
    latent_continuous,
    relevant_names,
    terms_of,
)
from bayesprog.inference.protocol import ProgramLike
from bayesprog.inference.relevance import family, requisite
from bayesprog.inference.schedule import Schedule
from bayesprog.model import Term
from bayesprog.vocabulary.expressions import Question

#: (searched, observed discrete, observed continuous, inputs, soft evidence, terms ablated on
#: some rows): names only
LayoutKey = tuple[tuple[str, ...], ...]


T = TypeVar("T")


class once(Generic[T]):  # noqa: N801  (used as a decorator, like cached_property)
    """A property computed at its first read, then a plain attribute of the instance: what
    ``functools.cached_property`` does, without the lock it takes at every read before
    Python 3.12 (a microsecond, which a warm question would pay several times)."""

    def __init__(self, compute: Callable[[Any], T]) -> None:
        self.compute = compute
        self.__doc__ = compute.__doc__

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, obj: Any, owner: type | None = None) -> T:
        if obj is None:
            return self  # type: ignore[return-value]
        value = obj.__dict__[self.name] = self.compute(obj)
        return value


def layout_key(question: Question, bound: Bound) -> LayoutKey:
    return (question.expression.left, tuple(sorted(bound.discrete)),
            tuple(sorted(bound.continuous)) if bound.continuous else (),
            tuple(sorted(bound.inputs)) if bound.inputs else (),
            tuple(sorted(bound.soft)) if bound.soft else (),
            tuple(sorted(bound.ablated)) if bound.ablated else ())


@dataclass
class Layout:
    """Which variables a question searches and which it knows (by name, not value), and what
    follows from that alone: the terms that matter, and what methods compile for them."""

    program: ProgramLike
    key: LayoutKey
    #: what the methods compile for this layout (a contraction's sliceable tables, ...)
    prepared: dict[str, Any] = field(default_factory=dict)
    #: how its questions are scheduled among the methods
    schedule: Schedule = field(default_factory=Schedule)

    @property
    def searched(self) -> tuple[str, ...]:
        return self.key[0]

    @once
    def ancestral_names(self) -> set[str]:
        """The searched, observed and soft-evidence variables and their ancestors
        (:func:`~bayesprog.inference.factors.relevant_names`)."""
        searched, observed, continuous, _, soft, _ = self.key
        return relevant_names(self.program, searched, observed + continuous, soft)

    @once
    def ancestral_terms(self) -> list[Term]:
        """The terms of :attr:`ancestral_names`, in the program's order."""
        return terms_of(self.program, self.ancestral_names)

    @once
    def latent(self) -> list[str]:
        """The unknown continuous variables that matter (searched, or parents of a relevant
        term): only the methods for continuous variables answer when there are some."""
        if not family(self.program).continuous:
            return []
        return latent_continuous(self.ancestral_terms, set(self.key[2]))

    @once
    def requisite_names(self) -> set[str] | None:
        """The variables whose terms the answer needs (:mod:`~bayesprog.inference.relevance`)
        when every unknown variable is discrete; None: those of :attr:`ancestral_names`."""
        searched, observed, continuous, _, soft, _ = self.key
        if self.latent or not searched:
            return None
        return requisite(self.program, searched, observed + continuous, soft)

    @once
    def terms(self) -> list[Term]:
        """The requisite terms when every unknown variable is discrete, else the ancestral
        ones, in the program's order (soft-evidence terms of the program with the variables
        they are on)."""
        names = self.requisite_names
        return self.ancestral_terms if names is None else terms_of(self.program, names)

    @once
    def touched(self) -> set[str]:
        """The variables the terms read (children and parents)."""
        return {v.name for t in self.terms for v in (t.child, *t.parents)}

    @once
    def pruned(self) -> bool:
        """Whether the requisite terms leave out some the evidence depends on: the answer's
        normaliser is then not the evidence's probability, which is computed when asked.
        (Fewer variables with a term are fewer terms; a variable without one, given by every
        question, adds nothing to the evidence's probability.)"""
        names = self.requisite_names
        if names is None:
            return False
        given = set(self.program.conditioning)
        return len(names - given) < len(self.ancestral_names - given) or any(
            name not in self.touched and name not in given
            for name in self.key[1] + self.key[2] + self.key[4])

    @once
    def constant(self) -> bool:
        """Whether the answer is the same whatever the evidence's values: no requisite term
        reads an observed variable, an input or soft evidence (the searched variables are
        independent of the evidence)."""
        searched, observed, continuous, inputs, soft, ablated = self.key
        if inputs or soft or ablated or not searched or self.latent:
            return False
        return all(is_static(t) for t in self.terms) and not any(
            name in self.touched for name in observed + continuous)

    @once
    def cards(self) -> tuple[int, ...]:
        """The number of states of each searched variable."""
        return tuple(int(self.program.variables[v].card)  # type: ignore[union-attr]
                     for v in self.searched)

    @once
    def named_states(self) -> tuple[dict[str, tuple[str, ...]], dict[str, tuple[Any, ...]]]:
        """The searched variables' state names and typed values, for the answers."""
        variables = self.program.variables
        return ({v: variables[v].states for v in self.searched},  # type: ignore[union-attr]
                {v: variables[v].typed_states for v in self.searched})  # type: ignore[union-attr]


def layout_of(program: ProgramLike, question: Question, bound: Bound) -> Layout:
    """The program's layout for ``question`` with ``bound``'s variables known (made once)."""
    key = layout_key(question, bound)
    layouts = program.inference_cache.layouts
    found = layouts.get(key)
    if found is None:
        found = layouts[key] = Layout(program, key)
    return found


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

    @once
    def layout(self) -> Layout:
        return layout_of(self.program, self.question, self.bound)

    @property
    def terms(self) -> list[Term]:
        """The terms that matter (see :attr:`Layout.terms`)."""
        return self.layout.terms

    @property
    def latent(self) -> list[str]:
        return self.layout.latent

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
        operands = [axes for axes in operands if axes]  # the others are numbers
        present = {a for axes in operands for a in axes}
        operands += [(v,) for v in output if v not in present]
        shapes = [tuple(self.card(a) for a in axes) for axes in operands]
        largest = max([float(np.prod(s)) for s in shapes]
                      + [float(np.prod([self.card(v) for v in output]))])
        if len(operands) < 2:
            return largest, largest
        _, info, cost = self.program.inference_cache.plans.path(equation(operands, output),
                                                                 shapes)
        return cost, max(float(info.largest_intermediate), largest)
