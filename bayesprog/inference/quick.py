"""Questions asked again, one evidence set at a time: the warm path of ``Program.ask``.

A question asked with one state per known variable, by name or integer (``program.ask("P(A | B,
C)", {"B": "b0", "C": 1})``), is bound, planned and dispatched at its first call; what that
settles (the layout, the method, its compiled table or its one answer) does not change with
the evidence's values. A :class:`Kernel` keeps it for the question's text, method and known
variables: a later call looks the states up, reads the settled method's answer and builds the
answer object, and returns None for anything else (another kind of value, a method not settled
yet, a row the method declines), which the full path then answers. The answers are those of
the full path, value for value. A kernel answers under the limits the full path last checked
the question against: after :func:`~bayesprog.limits.set_limits`, the next call is checked
again.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from bayesprog.inference.answers import Posterior, check_zero
from bayesprog.inference.binding import Bound
from bayesprog.inference.dispatch import deferred_evidence, named, with_evidence
from bayesprog.inference.methods import registered_methods, registry_version
from bayesprog.inference.plan import Layout, QuestionPlan, layout_key
from bayesprog.inference.protocol import ProgramLike
from bayesprog.limits import generation, limit
from bayesprog.vocabulary.expressions import Question
from bayesprog.vocabulary.variables import Discrete

#: Kernels a program keeps (question texts, methods and sets of known variables).
KERNELS = 1024


def _states(variable: Any) -> dict[str | int, int]:
    """A discrete variable's states by name and by integer, as binding reads them: a range's
    integer is its value, another variable's the state's index (a discretised variable reads
    numbers as readings: by name only)."""
    found: dict[str | int, int] = dict(variable._lookup)
    if variable.edges is None:
        found.update({int(v): i for i, v in enumerate(variable.values)}
                     if variable.values is not None else {i: i for i in range(variable.card)})
    return found


class Kernel:
    """One question's warm path for one set of known variables (see the module)."""

    __slots__ = ("program", "question", "method", "lookups", "fixed", "layout", "template",
                 "cards", "settled", "checked", "constant")

    def __init__(self, program: ProgramLike, question: Question, method: str | None,
                 keys: tuple[str, ...], layout: Layout) -> None:
        variables = program.variables
        expr = question.expression
        self.program, self.question, self.method, self.layout = program, question, method, layout
        self.lookups = tuple((name, _states(variables[name])) for name in keys)
        self.fixed = {name: variables[name]._lookup[value]  # type: ignore[union-attr]
                      for name, value in expr.values.items()}
        states, values = layout.named_states
        self.cards = layout.cards
        # every field of the answer at its default, then this question's
        self.template: dict[str, Any] = {
            field.name: field.default for field in dataclasses.fields(Posterior)
            if field.default is not dataclasses.MISSING}
        self.template.update(question=str(expr), variables=expr.left, names=states,
                             values=values, batch_shape=(), ablated=program.ablated)
        self.settled: tuple[int, Any] | None = None  # (registry version, settled method)
        #: the generation of the limits the full path last checked this question against
        self.checked = generation()
        #: the layout's one answer (the schedule's, whatever the evidence) and its
        #: probabilities shaped as the answer's, copied at each call
        self.constant: tuple[Any, np.ndarray] | None = None

    @classmethod
    def make(cls, program: ProgramLike, question: Question, method: str | None,
             evidence: Mapping[str, Any]) -> Kernel | None:
        """The kernel of ``question`` asked with ``evidence`` (its first call has answered),
        or None when its calls need the full path."""
        expr = question.expression
        variables = program.variables
        if question.kind != "posterior" or not expr.left:
            return None
        if not all(isinstance(variables[v], Discrete) for v in expr.left):
            return None
        keys = tuple(evidence)
        if len(keys) + len(expr.values) != len(expr.right) or any(
                name not in expr.right or name in expr.values
                or not isinstance(variables.get(name), Discrete) for name in keys):
            return None
        if any(not isinstance(variables[n], Discrete) or not isinstance(value, str)
               or value not in variables[n]._lookup  # type: ignore[union-attr]
               for n, value in expr.values.items()):
            return None
        key = layout_key(question, Bound((), dict.fromkeys(keys + tuple(expr.values), 0)))
        layout = program.inference_cache.layouts.get(key)
        if layout is None or layout.latent:
            return None
        return cls(program, question, method, keys, layout)

    def __call__(self, evidence: Mapping[str, Any]) -> Posterior | None:
        found: dict[str, np.ndarray | int] = dict(self.fixed) if self.fixed else {}
        for name, lookup in self.lookups:
            value = evidence[name]
            kind = type(value)
            if kind is not str and kind is not int and not isinstance(value, np.integer):
                return None  # (a bool, a number, an array: the full path reads or refuses it)
            index = lookup.get(value)
            if index is None:
                return None
            found[name] = index
        if self.checked != generation():
            return None  # the limits changed: the full path checks against them again
        layout = self.layout
        schedule = layout.schedule
        fixed = schedule.fixed if self.method is None else schedule.fixed_by.get(self.method)
        if fixed is not None:
            constant = self.constant
            if constant is None or constant[0] is not fixed:
                constant = self.constant = (fixed, fixed[0][0].reshape(self.cards))
            return self._answer(constant[1].copy(), fixed[1], fixed[2], found, True)
        version = registry_version()
        if self.settled is None or self.settled[0] != version:
            # the method named, or the one the full path settled for one row (kept while no
            # method is registered: what it compiled is made)
            method = registered_methods().get(self.method) if self.method is not None \
                else schedule.settled.get((version, 1, limit("entries")))
            if method is None:
                return None
            self.settled = (version, method)
        method = self.settled[1]
        row = method.prepared_row(layout, found)
        if row is not None:
            return self._answer(row[0], row[1], method.name, found, method.exact)
        plan = self._plan(found)
        if self.method is not None:
            return _checked(named(plan, self.method))
        answer = method.posterior(plan)
        if answer is None:
            return None
        answer.method = answer.method or method.name
        return _checked(with_evidence(plan, answer, method.exact))

    def _plan(self, found: dict[str, np.ndarray | int]) -> QuestionPlan:
        plan = QuestionPlan(self.program, self.question, Bound((), found), {"rng": None})
        plan.__dict__["layout"] = self.layout
        return plan

    def _answer(self, probabilities: np.ndarray, normaliser: float, method: str,
                found: dict[str, np.ndarray | int], exact: bool) -> Posterior | None:
        """The answer object, as the full path makes it (the evidence's probability deferred
        where the plan left some out)."""
        if normaliser == -math.inf:
            return None  # the full path says why there is no answer
        template = self.template
        fields = template.copy()
        fields["names"] = template["names"].copy()
        fields["values"] = template["values"].copy()
        fields["probabilities"] = (probabilities if probabilities.shape == self.cards
                                   else probabilities.reshape(self.cards))
        fields["method"] = method
        if self.layout.pruned:
            program, expr = self.program, self.question.expression

            def log_evidence() -> np.ndarray:
                return deferred_evidence(program, expr, Bound((), found),
                                         None if exact else method, {"rng": None})()

            fields["impossible"] = np.False_
            fields["_log_evidence"] = log_evidence
        else:
            fields["_log_evidence"] = np.array(normaliser)
        answer = object.__new__(Posterior)
        answer.__dict__ = fields
        return answer


def answer(program: ProgramLike, key: tuple[Any, ...], evidence: Mapping[str, Any]
                 ) -> Posterior | None:
    """The warm path's answer for ``key`` (question text, kind, method, known variables), if it
    has a kernel that answers; None for the full path."""
    kernel = program.inference_cache.quick.get(key)
    if kernel is None:
        return None
    return kernel(evidence)


def learn(program: ProgramLike, key: tuple[Any, ...], question: Question,
          evidence: Mapping[str, Any]) -> None:
    """Keep a kernel for ``key`` after the full path answered ``question`` (at most
    ``KERNELS`` per program; a key that cannot have one is remembered as such)."""
    kernels = program.inference_cache.quick
    if key in kernels:
        kernel = kernels[key]
        if kernel is not None and kernel.checked != generation():
            kernel.checked, kernel.settled = generation(), None
        return
    if len(kernels) < KERNELS:
        kernels[key] = Kernel.make(program, question, key[2], evidence)


def _checked(answer: Any) -> Any:
    """``answer``, unless the evidence that bears on it has probability zero (then the
    error the full path raises)."""
    check_zero(answer)
    return answer
